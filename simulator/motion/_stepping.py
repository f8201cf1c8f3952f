"""Steppers on the energy landscape: pure, jit-able, vmap-able functions.

Every stepper reads a :class:`Field` (the landscape arrays, a pytree) and the static
:class:`~simulator.landscape.PoseGrid` of the landscape (shape, spacing, periodicity:
hashable, so jit recompiles only when it changes), starts from one pose in *grid-index units* ``(it, iy, ix)`` and runs a
``lax.while_loop``. A batch is ``jax.vmap`` of the same function (see
:mod:`simulator.batch`), so one start and a batch run the same code.

Index units: ``ix``, ``iy`` are pixels from the window's first column/row;
``it`` counts twist steps from the first twist. On a periodic twist axis ``it``
is *unwrapped* (it may leave [0, T) and is wrapped only for look-ups), so a
trajectory reports the twist it actually turned through (e.g. -90 degrees).

Ties (docs/physics.md §5.2): energy differences at or below the landscape's
noise floor are equal. Greedy keeps the current pose when it ties for the best;
otherwise it takes the smallest move ``|dt| + |dy| + |dx|``, then the first in
lexicographic order of ``(dt, dy, dx)`` from -1 to +1 (:data:`GREEDY_MOVES`). A move
happens only when the current pose lies more than the floor above the best neighbour,
and the chosen one lies within the floor of that best, so each move lowers the energy
strictly (in practice by more than the floor: no exception in 9930 sampled moves, but
that is not guaranteed), no pose is visited twice (no cycles), and the run ends;
``max_steps`` bounds its length.

The landscape's arrays and every look-up on them (:class:`Field`, :func:`lookup`,
:func:`interpolate`, :func:`gradient`, ...) are :mod:`simulator.motion`; this module holds
the stop codes, the greedy and gradient steppers and the outcome classification, and
re-exports the field's names, so every stepper name is importable from here.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from simulator.landscape import PoseGrid
from simulator.motion._field import (
    Field,
    at_cut_edge,
    clamp_start,
    gradient,
    interpolate,
    lookup,
    neighbourhood,
    relay_changes,
)
from simulator.motion._pinning import pin_at

# Stop codes of a run (``status``), and the outcomes a trajectory reports. EVENT: the
# footprint state changes at the pose the run stopped at (a field with a relay,
# docs/physics.md §3.5): the run goes on from there on the new state's landscape.
RUNNING, CONVERGED, MAX_STEPS, EDGE, EVENT = 0, 1, 2, 3, 4


def _move_order() -> np.ndarray:
    moves = list(itertools.product((-1, 0, 1), repeat=3))  # lexicographic in (dt, dy, dx)
    moves.sort(key=lambda m: sum(map(abs, m)))  # stable: smallest move first
    return np.array(moves, dtype=np.int32)


#: The 27 greedy moves (dt, dy, dx) in tie-break order; row 0 is "stay".
GREEDY_MOVES = _move_order()
#: The same 27 moves in (dt, dy, dx) lexicographic order: the layout of
#: :func:`neighbourhood`'s (3, 3, 3) block; "stay" is BLOCK_MOVES[13].
BLOCK_MOVES = np.array(list(itertools.product((-1, 0, 1), repeat=3)), dtype=np.int32)
#: TIE_RANK[k]: the place of BLOCK_MOVES[k] in the tie-break order (0 = stay).
TIE_RANK = np.array(
    [[tuple(m) for m in GREEDY_MOVES].index(tuple(b)) for b in BLOCK_MOVES], dtype=np.int32
)
STAY = 13


# ----------------------------------------------------------------- greedy
class GreedyState(NamedTuple):
    idx: jax.Array  # (3,) int32 (it, iy, ix), it unwrapped
    energy: jax.Array  # current energy (J)
    step: jax.Array  # steps taken
    status: jax.Array  # RUNNING / CONVERGED / MAX_STEPS / EDGE
    path: jax.Array  # (max_steps + 1, 3) int32, or (1, 3) when not recorded
    path_energy: jax.Array  # (max_steps + 1,), or (1,)


def greedy(
    field: Field, grid: PoseGrid, start: ArrayLike, max_steps: int, record: bool = True
) -> GreedyState:
    """Greedy descent (docs/physics.md §5.2): move to the lowest of the 27 neighbours.

    Args:
        field, grid: the landscape (see :func:`field_and_grid`).
        start: (3,) integer grid indices (it, iy, ix).
        max_steps: at most this many moves (static).
        record: keep the path (static; off for large batches).

    Returns the final :class:`GreedyState`; ``path[:step + 1]`` is the path.
    """
    moves, rank = jnp.asarray(BLOCK_MOVES), jnp.asarray(TIE_RANK)
    pin_work = None
    m = np.abs(BLOCK_MOVES).astype(np.float64)
    if field.pinned and field.lines is None:
        # the pinning work of each move: the axes it moves along, summed in float64
        p = field.pin
        pin_work = (m[:, 0] * p[0] + m[:, 1] * p[1] + m[:, 2] * p[2]).astype(field.dtype)
    start = clamp_start(grid, jnp.asarray(start, jnp.int32))
    n = max_steps + 1 if record else 1
    e0 = lookup(field, grid, *start)
    path = jnp.zeros((n, 3), jnp.int32).at[0].set(start)
    path_e = jnp.full((n,), jnp.nan, field.dtype).at[0].set(e0)

    def cond(s: GreedyState) -> jax.Array:
        return s.status == RUNNING

    def body(s: GreedyState) -> GreedyState:
        at_edge = at_cut_edge(grid, s.idx)
        e_true = neighbourhood(field, grid, s.idx)  # block order
        # Hysteresis: a move is worth its energy plus the pinning work it costs, with the
        # lines that slide at the current pose (docs/physics.md §5.3).
        if field.lines is not None:
            p = pin_at(field, grid, s.idx)
            work = jnp.asarray(m, field.dtype) @ p
            e = e_true + work
        else:
            e = e_true + pin_work if pin_work is not None else e_true
        best = jnp.min(e)
        # the first tie for the best in the documented order: the smallest tie rank
        r = jnp.min(jnp.where(e <= best + field.floor, rank, len(rank)))
        choice = jnp.argmax(rank == r)
        moved = r != 0
        new_idx = jnp.where(moved, s.idx + moves[choice], s.idx)
        step = s.step + moved.astype(jnp.int32)
        status = jnp.where(
            at_edge,
            EDGE,
            jnp.where(~moved, CONVERGED, jnp.where(step >= max_steps, MAX_STEPS, RUNNING)),
        )
        new_idx = jnp.where(at_edge, s.idx, new_idx)
        step = jnp.where(at_edge, s.step, step)
        energy = jnp.where(at_edge, s.energy, e_true[choice])
        if field.relay is not None:  # static: the footprint state changes where the chip moved
            status = jnp.where(
                moved & ~at_edge & relay_changes(field, grid, new_idx), EVENT, status
            )
        if record:
            p = s.path.at[step].set(new_idx)
            pe = s.path_energy.at[step].set(energy)
        else:
            p, pe = s.path, s.path_energy
        return GreedyState(new_idx, energy, step, status.astype(jnp.int32), p, pe)

    init = GreedyState(
        start, e0, jnp.int32(0), jnp.int32(MAX_STEPS if max_steps <= 0 else RUNNING), path, path_e
    )
    return jax.lax.while_loop(cond, body, init)


def on_plateau(field: Field, grid: PoseGrid, idx: ArrayLike) -> jax.Array:
    """True where some greedy move leaves the energy unchanged (within the noise floor):
    the pose sits on a plateau (a flat direction), not in a strict local minimum."""
    e = neighbourhood(field, grid, jnp.asarray(idx, jnp.int32))
    others = np.arange(27) != STAY
    return jnp.any(jnp.abs(e[others] - e[STAY]) <= field.floor)


# ----------------------------------------------------------------- gradient
def reference_gradient(field: Field, grid: PoseGrid) -> jax.Array:
    """Typical |dE/dx| (J per px): a chip edge of length 2 rg + 1 px sliding over a pad,
    at least the noise floor. The force scale of the gradient stepper and the dynamics."""
    return jnp.maximum(field.scale / (2.0 * grid.rg_px + 1.0), field.floor)


class GradientState(NamedTuple):
    q: jax.Array  # (3,) fractional indices (it, iy, ix), it unwrapped
    energy: jax.Array
    step: jax.Array
    status: jax.Array
    path: jax.Array  # (max_steps + 1, 3) float, or (1, 3)
    path_energy: jax.Array
    flat: jax.Array  # stopped because the force is exactly zero


def gradient_descent(
    field: Field,
    grid: PoseGrid,
    start: ArrayLike,
    max_steps: int,
    record: bool = True,
    min_step_px: float = 1e-2,
) -> GradientState:
    """Steepest descent on the interpolated landscape with backtracking.

    Twist is measured as arc length at the chip's radius of gyration, so one metric
    covers (x, y, twist). The trial step is proportional to the force (docs/physics.md §5)
    and at most 1 px long; it is halved until the energy decreases. The run stops on
    zero force (``flat``: a plateau or a minimum at the noise floor), when no halving
    down to ``min_step_px`` lowers the energy (the V-shaped cusp at alignment ends
    here instead of chattering), or after ``max_steps``. Energy never increases.
    """
    dt = field.dtype
    start = clamp_start(grid, jnp.asarray(start, dt))
    # Metric: index units -> px. Twist index -> arc length in px.
    metric = jnp.asarray([grid.twist_px_per_step if grid.shape[0] > 1 else 1.0, 1.0, 1.0], dt)
    g_ref = reference_gradient(field, grid)
    pinned_run = field.pinned
    n = max_steps + 1 if record else 1
    e0 = interpolate(field, grid, start)
    path = jnp.zeros((n, 3), dt).at[0].set(start)
    path_e = jnp.full((n,), jnp.nan, dt).at[0].set(e0)

    def body(s: GradientState) -> GradientState:
        # Central differences and interpolation reach 2 indices out: stop short of a cut side.
        edge = at_cut_edge(grid, s.q, margin=2.0)
        g_index = gradient(field, grid, s.q)  # J per index step
        g = g_index / metric  # J per px
        # Hysteresis: pinned where no axis's force beats its pinning force.
        pinned = (
            jnp.all(jnp.abs(g_index) <= pin_at(field, grid, s.q))
            if pinned_run
            else jnp.asarray(False)
        )
        # Zero force is tested per axis: squaring g (joules per px) underflows to 0 in
        # float32 for weak landscapes (|g| < 1e-19 J/px, e.g. 1e-12 N/m) and overflows for
        # strong ones, which would call a real slope flat.
        flat = jnp.all(g == 0)
        d = -g / g_ref  # px, proportional to the force
        dlen = jnp.sqrt(jnp.sum(d * d))
        d = jnp.where(dlen > 1.0, d / jnp.maximum(dlen, 1e-30), d)
        dlen = jnp.minimum(dlen, 1.0)

        def try_cond(c: tuple[jax.Array, jax.Array]) -> jax.Array:
            scale, e_new = c
            return (e_new >= s.energy) & (scale * dlen >= min_step_px)

        def try_body(c: tuple[jax.Array, jax.Array]) -> tuple[jax.Array, jax.Array]:
            scale, _ = c
            scale = scale / 2
            return scale, interpolate(field, grid, s.q + scale * d / metric)

        e_try = interpolate(field, grid, s.q + d / metric)
        scale, e_new = jax.lax.while_loop(try_cond, try_body, (jnp.asarray(1.0, dt), e_try))
        accept = (e_new < s.energy) & ~flat & ~edge & ~pinned
        q = jnp.where(accept, s.q + scale * d / metric, s.q)
        energy = jnp.where(accept, e_new, s.energy)
        step = s.step + accept.astype(jnp.int32)
        status = jnp.where(
            edge,
            EDGE,
            jnp.where(~accept, CONVERGED, jnp.where(step >= max_steps, MAX_STEPS, RUNNING)),
        )
        if field.relay is not None:  # static: the footprint state changes where the chip moved
            status = jnp.where(accept & relay_changes(field, grid, q), EVENT, status)
        if record:
            p, pe = s.path.at[step].set(q), s.path_energy.at[step].set(energy)
        else:
            p, pe = s.path, s.path_energy
        return GradientState(
            q, energy, step, status.astype(jnp.int32), p, pe, flat & ~accept & ~edge & ~pinned
        )

    init = GradientState(
        start,
        e0,
        jnp.int32(0),
        jnp.int32(MAX_STEPS if max_steps <= 0 else RUNNING),
        path,
        path_e,
        jnp.asarray(False),
    )
    return jax.lax.while_loop(lambda s: s.status == RUNNING, body, init)


# ----------------------------------------------------------------- outcome
def classify(
    field: Field,
    grid: PoseGrid,
    q: ArrayLike,
    energy: ArrayLike,
    status: ArrayLike,
    flat: ArrayLike,
    timed_out: bool | jax.Array = False,
) -> jax.Array:
    """Outcome index into :data:`simulator.core.OUTCOMES` for a final pose q (fractional indices).

    aligned: within ``field.align_tol`` (twist steps, px) of the global minimum, twist
    compared modulo the chip's symmetry period. no_contact: zero overlap (|E| at or
    below the floor). plateau: stopped with zero force or a flat direction (a move
    that leaves the energy unchanged).
    local_minimum: stopped anywhere else. max_steps: ran out of steps (or, for the
    dynamics, of time), except where the tolerance is wider than a step (the floor a chip
    floats on, a hysteresis window) and the run ended inside it: there it is aligned, as
    a chip that creeps about on the floor is. ``timed_out``: a dynamic run whose simulated
    time ran out (not its steps) while it creeps, its kinetic energy at or below the
    landscape's noise floor (the callers' rule); ending on a plateau it is a plateau (the
    chip creeps on it), not max_steps. A chip that still carries more kinetic energy than
    that when its time runs out is passing over whatever it is on: max_steps, decided by
    that rule and not by whether the pose it was caught at happens to be flat.
    """
    q = jnp.asarray(q, field.dtype)
    period = grid.period_deg / grid.twist_step_deg
    dtw = q[0] - field.best[0]
    dtw = dtw - period * jnp.round(dtw / period)
    lim = field.align_lim.astype(field.dtype)  # the tolerance + 1e-6, rounded once
    near = (jnp.abs(dtw) <= lim[0]) & jnp.all(jnp.abs(q[1:] - field.best[1:]) <= lim[1])
    no_contact = jnp.abs(energy) <= field.floor
    ran_out = (status == MAX_STEPS) & ~(jnp.asarray(timed_out) & jnp.asarray(flat))
    if field.wide_tol:  # static: a floor or a hysteresis window
        ran_out = ran_out & ~near
    out = jnp.where(
        ran_out,
        4,
        jnp.where(no_contact, 3, jnp.where(near, 0, jnp.where(flat, 1, 2))),
    )
    return out.astype(jnp.int32)
