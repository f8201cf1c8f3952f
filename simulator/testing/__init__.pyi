"""Types of ``simulator.testing``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._reference import (
    ExactOverlap as ExactOverlap,
    ReferenceRun as ReferenceRun,
    energy_J as energy_J,
    force_N as force_N,
    gradient_descent as gradient_descent,
    gradient_um2 as gradient_um2,
    greedy as greedy,
    overlap_um2 as overlap_um2,
    radius_of_gyration_um as radius_of_gyration_um,
    torque_Nm as torque_Nm,
)
