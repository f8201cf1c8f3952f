"""Types of ``simulator.testing``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._reference import (
    ExactOverlap as ExactOverlap,
    ReferenceRun as ReferenceRun,
    energy_J as energy_J,
    exact_gradient_descent as exact_gradient_descent,
    exact_greedy as exact_greedy,
    force_N as force_N,
    gradient_um2 as gradient_um2,
    overlap_um2 as overlap_um2,
    radius_of_gyration_um as radius_of_gyration_um,
    torque_Nm as torque_Nm,
)
