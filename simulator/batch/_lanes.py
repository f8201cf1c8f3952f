"""Lanes of a batch: the single run vmapped over a chunk of starts, chunks on threads.

The jit boundary of every batch (:func:`_run_chunk`, documented in
:mod:`simulator.batch`), the runner of a set of starts on one field (:func:`run_lanes`),
the checks that the starts fit the landscape and the order they run in. Shared by the
stateless batch and the footprint-state batch (:mod:`simulator.batch`).
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

from foundation import hold, require
from simulator.landscape import Landscape, PoseGrid
from simulator.motion import Field, finish, stepper


# --------------------------------------------------------------------- batch
def _one(field: Field, grid: PoseGrid, params, start, method: str, max_steps: int, stiff: bool):
    """One start -> (final q, steps, status, outcome, energy, time_s); the single run vmap maps.

    ``params``: the :class:`~simulator.motion.DynamicsParams` of a dynamic method
    (None for greedy and gradient); ``time_s`` is the simulated time at the end of a
    dynamic run (NaN for the steppers)."""
    s = stepper(method, stiff)(field, grid, params, start, max_steps, record=False)
    status, out = finish(field, grid, s, max_steps)
    return s.q, s.step, status, out, s.energy, s.time_s


@functools.partial(jax.jit, static_argnames=("grid", "method", "max_steps", "stiff", "per_lane"))
def _run_chunk(
    field: Field,
    params,
    starts: jax.Array,
    grid: PoseGrid,
    method: str,
    max_steps: int,
    stiff: bool = False,
    per_lane: bool = False,
):
    """The jit boundary: vmap of :func:`_one` over a (chunk, 3) array of start indices
    (``params`` traced and shared by every lane).

    A stiff inertial run (the implicit solver, diffrax Kvaerno5) is mapped one start after
    the other (``jax.lax.map``) instead: under vmap diffrax re-evaluates the first stage
    of every lane while any lane is still on its first step
    (``eqxi.unvmap_any(first_step | made_jump)`` in its Runge-Kutta step), and for an
    implicit solver that fresh value differs from the carried first-same-as-last one by
    the root finder's tolerance, so a lane's path would depend on its neighbours
    (measured: up to 4e-4 um and 3x the steps after 1 s). Explicit solvers carry the
    same value either way, so their lanes are independent and equal single runs.

    ``per_lane``: ``params`` holds one value per lane along a leading axis (a footprint
    run's stretches each have the time left to their own run, :mod:`simulator.batch`)."""

    if not per_lane:

        def one(s):
            return _one(field, grid, params, s, method, max_steps, stiff)

        return jax.lax.map(one, starts) if stiff else jax.vmap(one)(starts)

    def lane(a):
        s, p = a
        return _one(field, grid, p, s, method, max_steps, stiff)

    return jax.lax.map(lane, (starts, params)) if stiff else jax.vmap(lane)((starts, params))


def run_lanes(
    fld: Field,
    grid: PoseGrid,
    params,
    q0: np.ndarray,
    method: str,
    max_steps: int,
    stiff: bool,
    chunk: int,
    workers: int,
    on_chunk=None,
    per_lane: bool = False,
    min_lanes: int = 1,
):
    """Every start of ``q0`` ((n, 3) grid indices, in the order to run them) on one field:
    chunks of ``chunk`` lanes (the last padded with copies of its first start, whose
    results are dropped: one compiled shape) on ``workers`` threads. Fewer than ``chunk``
    starts run as one chunk of at least ``min_lanes`` lanes (padded likewise), so that
    callers running several small sets of starts can keep to a few compiled shapes. ``on_chunk(m)``
    after each chunk of m starts. ``per_lane``: ``params`` has one value per start along
    a leading axis (:func:`_run_chunk`). Returns (q, steps, status, outcome, energy,
    time_s) arrays in q0's order."""
    n = len(q0)
    chunk = int(min(chunk, max(n, min_lanes)))
    final_q = np.empty((n, 3), np.float64)
    steps = np.empty(n, np.int32)
    status = np.empty(n, np.int32)
    outcome = np.empty(n, np.int8)
    energy = np.empty(n, np.float64)
    time_s = np.empty(n, np.float64)

    def run(i: int) -> int:
        """Chunk starting at i: run, then scatter its results (disjoint rows per chunk)."""
        block = q0[i : i + chunk]
        m = len(block)
        lane_params = params
        if per_lane:
            pick = np.minimum(np.arange(i, i + chunk), n - 1)
            pick[m:] = i  # padding lanes repeat the block's first start
            lane_params = jax.tree_util.tree_map(lambda a: jnp.asarray(np.asarray(a)[pick]), params)
        if m < chunk:  # pad with the block's first start: one compiled shape
            block = np.concatenate([block, np.repeat(block[:1], chunk - m, axis=0)])
        q, st, stat, out, e, ts = _run_chunk(
            fld,
            lane_params,
            jnp.asarray(block),
            grid=grid,
            method=method,
            max_steps=int(max_steps),
            stiff=stiff,
            per_lane=per_lane,
        )
        rows = slice(i, i + m)
        final_q[rows] = np.asarray(q)[:m]
        steps[rows] = np.asarray(st)[:m]
        status[rows] = np.asarray(stat)[:m]
        outcome[rows] = np.asarray(out)[:m]
        energy[rows] = np.asarray(e)[:m]
        time_s[rows] = np.asarray(ts)[:m]
        return m

    chunks = range(0, n, chunk)
    workers = max(1, min(int(workers), -(-n // chunk)))
    if workers == 1:
        for i in chunks:
            m = run(i)
            if on_chunk is not None:
                on_chunk(m)
            hold("batch")
    else:
        # XLA runs one vmapped loop on one core: a thread per core keeps each busy.
        ex = ThreadPoolExecutor(workers)
        try:
            for m in ex.map(run, chunks):
                if on_chunk is not None:
                    on_chunk(m)
                hold("batch")
        finally:
            ex.shutdown(wait=True, cancel_futures=True)
    return final_q, steps, status, outcome, energy, time_s


def _check_starts_fit(ls: Landscape, poses: np.ndarray) -> None:
    """Starts the landscape cannot hold: twist outside a bounded axis, pose outside a cut window."""
    t = ls.twist_deg
    if len(t) == 1:
        require(
            bool(np.all(np.abs(poses[:, 2] - t[0]) <= 1e-9)),
            f"the landscape has one twist ({t[0]:g} deg, no twisting); every start twist must be {t[0]:g} degrees",
        )
    elif not ls.wrap:
        half = ls.twist_step_deg / 2
        lo, hi = poses[:, 2].min(), poses[:, 2].max()
        require(
            t[0] - half <= lo and hi <= t[-1] + half,
            f"start twists {lo:g}..{hi:g} deg are outside the twist range {t[0]:g}..{t[-1]:g} deg; widen the twist range",
        )
    s = ls.um_per_px
    for k, (axis, (cut_lo, cut_hi)) in enumerate(((ls.x_um, ls.cut[2]), (ls.y_um, ls.cut[1]))):
        v = poses[:, k]
        bad = (cut_lo and v.min() < axis[0] - s / 2) or (cut_hi and v.max() > axis[-1] + s / 2)
        require(
            not bad,
            f"start {'xy'[k]} values {v.min():g}..{v.max():g} um leave the translation window {axis[0]:g}..{axis[-1]:g} um; widen the window (--window / window_um)",
        )


def _distance_in_steps(q: np.ndarray, best: np.ndarray, grid: PoseGrid) -> np.ndarray:
    """max over axes of |q - best| in grid steps (twist modulo the period): a lower bound
    on greedy's step count from q (docs/physics.md C10), a rough one for gradient."""
    d = np.abs(np.asarray(q, float) - best)
    period = grid.period_deg / grid.twist_step_deg
    d[:, 0] = np.abs(d[:, 0] - period * np.round(d[:, 0] / period))
    return d.max(axis=1)


def _z_order(q: np.ndarray) -> np.ndarray:
    """Morton (Z-order) codes of integer grid indices (N, 3): sorting by them puts starts
    that lie close together in the pose grid next to each other."""
    q = np.asarray(q, np.int64)
    q = np.clip(q - q.min(axis=0), 0, 2**21 - 1)
    code = np.zeros(len(q), np.int64)
    for b in range(21):
        for k in range(3):
            code |= ((q[:, k] >> b) & 1) << (3 * b + k)
    return code


#: Width (grid steps) of the distance classes that :func:`_run_order` groups starts by.
ORDER_BAND_STEPS = 8


def _run_order(q: np.ndarray, best: np.ndarray, grid: PoseGrid) -> np.ndarray:
    """The order starts are run in: by distance from the global minimum in bands of
    :data:`ORDER_BAND_STEPS` grid steps (a lower bound on greedy's step count, so a chunk
    holds runs of similar length and few lanes idle in the vmapped while loop), and
    within a band in Z-order (a chunk's lanes then read nearby landscape cells, which
    share cache lines: 25 % faster on the benchmark than distance order alone)."""
    band = np.floor(_distance_in_steps(q, best, grid) / ORDER_BAND_STEPS)
    return np.lexsort((_z_order(np.floor(q)), band))
