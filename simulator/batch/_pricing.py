"""What a dynamics batch holds beyond its landscape, priced before JAX is imported.

A vmapped dynamics chunk keeps every lane's solver state until its slowest lane stops
(:mod:`simulator.batch._montecarlo`); :func:`price_dynamics_lanes` refuses a batch whose
lanes in flight would not fit the memory budget. The module imports no JAX, so a command
refuses such a batch in the time it takes to read its inputs.
"""

from __future__ import annotations

from foundation import require_fits

#: Peak bytes per lane of a vmapped dynamics chunk (the solver's state, stages, controller
#: and event; XLA's temporaries): measured with JAX's compiled memory analysis at 0.6-1.5 KB
#: (explicit solver) and 3-6 KB (the implicit one of stiff inertial runs), float32-float64.
DYNAMICS_BYTES_PER_LANE = 16384


def price_dynamics_lanes(lanes: int, budget_mb: float | None) -> None:
    """Refuse a dynamics batch whose solver states (``lanes`` = chunk x threads in flight,
    :data:`DYNAMICS_BYTES_PER_LANE` each) would not fit the memory budget."""
    require_fits(
        f"the solver states of {lanes:,} dynamics runs at once",
        float(lanes) * DYNAMICS_BYTES_PER_LANE,
        "use a smaller --chunk",
        budget_mb,
    )
