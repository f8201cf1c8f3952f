"""Many starts at once: yields, outcome counts, error statistics and capture maps.

A batch runs the *same* stepper functions as one trajectory
(:func:`simulator.motion.stepper`: :func:`simulator.motion.greedy`,
:func:`simulator.motion.gradient_descent`, and the dynamics
:func:`simulator.motion.overdamped` and :func:`simulator.motion.inertial`, with
``record=False``) under ``jax.jit(jax.vmap(...))`` on one landscape built once, so every
start's final pose, step count and outcome are those of
``simulate(scene, start, method, landscape=ls)`` (tested: bit for bit for the steppers,
to 1e-6 um for the dynamics, which also give the same simulated time). The dynamics take
:class:`~simulator.motion.DynamicsParams` (default: from the scene, as
``simulate`` takes them) and the solver ``simulate`` would choose (the implicit one for a
stiff inertial run); a vmapped solver runs until its slowest lane stops, so their chunks
are smaller (:data:`DEFAULT_DYNAMICS_CHUNK`), and the solver's state per lane is priced
against the memory budget before anything is built (:func:`price_dynamics_lanes`).

The jit boundary is :func:`_run_chunk`: ``grid`` (the landscape's hashable :class:`~simulator.landscape.PoseGrid`),
``method``, ``max_steps`` and ``stiff`` are static (a new value recompiles); the landscape
field, the dynamics parameters and the (chunk, 3) start indices are traced. Starts are processed in chunks of a fixed size;
the last chunk is padded (with copies of its first start, whose results are dropped) so
one compiled program serves the whole run, and memory stays bounded by the chunk.
Starts run grouped by their distance from the global minimum (similar run lengths
share a chunk, so few lanes idle in the vmapped while loop) and, within a group, by
position (a chunk's look-ups share cache lines), chunks on a thread per CPU core;
results go back to the caller's order. Neither changes any result.

Conventions:

* Poses are ``(x_um, y_um, twist_deg)`` of the chip centre relative to the pattern's
  nominal centre, x right, y up, twist counter-clockwise positive (docs/physics.md §1).
  Greedy starts at the grid pose nearest the start (the landscape's pixel and twist
  step); gradient and the dynamics start at the start itself.
* Final twists are reported as the stepper turned (unwrapped, e.g. -90 degrees);
  twist *errors* are taken modulo the chip's symmetry period into
  ``[-period/2, period/2)``.
* "aligned" is :func:`simulator.motion.classify` against the landscape's global
  minimum (:mod:`simulator.landscape`), within the tolerance of
  :func:`simulator.physics.align_tolerance` (anywhere on the floor a chip floats on,
  with free contact lines), for every method alike, and the error statistics of a batch are measured
  from that same pose, the target the run reports (``error_target``). Pooled over
  random-jagged patterns (:func:`run_realizations`) they are measured from the nominal
  pose (0, 0, 0) instead: how far each pattern's minimum moves is what it measures.
* Time (dynamics): ``BatchResult.time_s`` is each run's simulated time at its end, and
  ``time_to_align_s`` that time for the starts that aligned (the run came to rest at
  the aligned pose), NaN for the others; summaries report its median and 90th
  percentile (:func:`time_stats`).
* Randomness: start poses are drawn on the host with ``numpy.random.default_rng(seed)``
  (:func:`random_starts`), all N at once, so the draws do not depend on the chunk size.

Modules: this one runs the batches (:func:`run_batch`, :func:`run_realizations`); the
result and its statistics (:class:`BatchResult`, :func:`summarize`, :func:`capture_map`,
...) are :mod:`simulator.batch`; the start poses are :mod:`simulator.batch`.
Every name is importable from here.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

from patterns.errors import InputError, require
from patterns.hold import hold
from patterns.mask import Mask
from simulator.batch._pricing import price_dynamics_lanes
from simulator.batch._starts import (
    BATCH_BYTES_PER_START,
    StartGrid,
    _as_poses,
    price_starts,
)
from simulator.batch._stats import (
    BatchResult,
    summarize,
)
from simulator.core import (
    BATCH_METHODS as METHODS,
    DEFAULT_CHUNK,
    DEFAULT_DYNAMICS_CHUNK,
    DEFAULT_MAX_STEPS,
    DYNAMIC_METHODS,
    MAX_CHUNK,
    MAX_STEPS_LIMIT,
    progress_bar,
    threads,
)
from simulator.landscape import Landscape, build_landscape, global_minimum
from simulator.motion import (
    Field,
    Grid,
    error_limit,
    field_and_grid,
    finish,
    is_stiff,
    stepper,
)
from simulator.physics import align_tolerance, pin_per_index
from simulator.scene import Scene

#: Peak bytes per start of a dynamics batch beyond :data:`BATCH_BYTES_PER_START`: its time.
TIME_BYTES_PER_START = 16


# --------------------------------------------------------------------- batch
def _one(field: Field, grid: Grid, params, start, method: str, max_steps: int, stiff: bool):
    """One start -> (final q, steps, status, outcome, energy, time_s); the single run vmap maps.

    ``params``: the :class:`~simulator.motion.DynamicsParams` of a dynamic method
    (None for greedy and gradient); ``time_s`` is the simulated time at the end of a
    dynamic run (NaN for the steppers)."""
    s = stepper(method, stiff)(field, grid, params, start, max_steps, record=False)
    status, out = finish(field, grid, s, max_steps)
    return s.q, s.step, status, out, s.energy, s.time_s


@functools.partial(jax.jit, static_argnames=("grid", "method", "max_steps", "stiff"))
def _run_chunk(
    field: Field,
    params,
    starts: jax.Array,
    grid: Grid,
    method: str,
    max_steps: int,
    stiff: bool = False,
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
    same value either way, so their lanes are independent and equal single runs."""

    def one(s):
        return _one(field, grid, params, s, method, max_steps, stiff)

    return jax.lax.map(one, starts) if stiff else jax.vmap(one)(starts)


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


def _distance_in_steps(q: np.ndarray, best: np.ndarray, grid: Grid) -> np.ndarray:
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


def _run_order(q: np.ndarray, best: np.ndarray, grid: Grid) -> np.ndarray:
    """The order starts are run in: by distance from the global minimum in bands of
    :data:`ORDER_BAND_STEPS` grid steps (a lower bound on greedy's step count, so a chunk
    holds runs of similar length and few lanes idle in the vmapped while loop), and
    within a band in Z-order (a chunk's lanes then read nearby landscape cells, which
    share cache lines: 25 % faster on the benchmark than distance order alone)."""
    band = np.floor(_distance_in_steps(q, best, grid) / ORDER_BAND_STEPS)
    return np.lexsort((_z_order(np.floor(q)), band))


def run_batch(
    scene: Scene,
    starts,
    method: str = "greedy",
    *,
    landscape: Landscape | None = None,
    chunk: int | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    progress: bool = True,
    workers: int | None = None,
    dynamics=None,
) -> BatchResult:
    """Run every start to its end on one landscape.

    Args:
        scene: what to simulate.
        starts: (N, 3) poses (x_um, y_um, twist_deg), or a :class:`StartGrid`.
        method: "greedy", "gradient", "overdamped" or "inertial" (the dynamics of
            :mod:`simulator.motion`, ``jax.vmap`` of the single-run solver).
        landscape: the landscape to run on; default ``build_landscape(scene)`` (the full
            landscape, built once).
        chunk: starts per compiled batch (at most N); memory is bounded by it. Default
            :data:`DEFAULT_CHUNK` for the steppers, :data:`DEFAULT_DYNAMICS_CHUNK` for
            the dynamics.
        max_steps: bound on moves per start (solver steps for the dynamics).
        progress: a tqdm bar over the starts, advanced per chunk (on stderr).
        workers: threads that run chunks at once (default: one per CPU core). Lanes
            are independent, so the results do not depend on it.
        dynamics: :class:`simulator.motion.DynamicsParams` of the dynamic
            methods (default: ``DynamicsParams.from_scene(scene)``, as
            :func:`simulator.motion.simulate` takes them); ignored by the steppers.

    Returns:
        A :class:`BatchResult`; ``stats`` holds seconds, starts and steps per second;
        for the dynamics ``time_s`` holds each start's simulated time at its end
        (:attr:`BatchResult.time_to_align_s`: that time for the aligned starts).
    """
    if scene.liquid.dispense is not None:
        raise InputError(
            "--dispense: batch runs do not carry the footprint state yet (simulate does, start by start); "
            "give a scene without dispense"
        )
    require(method in METHODS, f"method must be one of {', '.join(METHODS)}, got {method!r}")
    dynamic = method in DYNAMIC_METHODS
    if chunk is None:
        chunk = DEFAULT_DYNAMICS_CHUNK if dynamic else DEFAULT_CHUNK
    for name, v in (("chunk", chunk), ("max steps", max_steps)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
            raise InputError(f"{name} must be a whole number >= 1, got {v!r}")
    require(
        max_steps <= MAX_STEPS_LIMIT,
        f"max steps must be at most {MAX_STEPS_LIMIT:,} (the step counter is 32-bit), got {max_steps:,}",
    )
    require(chunk <= MAX_CHUNK, f"chunk must be at most {MAX_CHUNK:,} starts, got {chunk:,}")
    per_start = BATCH_BYTES_PER_START + (TIME_BYTES_PER_START if dynamic else 0)
    if isinstance(starts, StartGrid):
        price_starts(starts.size, scene.memory_budget_mb, per_start)
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1
    ):
        raise InputError(f"workers must be a whole number >= 1 or None, got {workers!r}")
    poses = _as_poses(starts)
    price_starts(len(poses), scene.memory_budget_mb, per_start)
    n, chunk = len(poses), int(min(chunk, len(poses)))
    workers = max(1, min(int(workers or threads()), -(-n // chunk)))
    if dynamic:
        # The solver's state per lane, for every chunk in flight: priced before the
        # landscape is built or anything compiled. The parameters as the single run takes them.
        price_dynamics_lanes(chunk * workers, scene.memory_budget_mb)
        if dynamics is None:
            from simulator.motion import DynamicsParams

            dynamics = DynamicsParams.from_scene(scene)
    else:
        dynamics = None
    t0 = time.perf_counter()
    ls = build_landscape(scene, progress=progress) if landscape is None else landscape
    t_land = time.perf_counter() - t0
    _check_starts_fit(ls, poses)
    pin = pin_per_index(scene, ls.um_per_px, ls.twist_step_deg)
    fld, grid = field_and_grid(
        ls, pin=pin, align_tol=align_tolerance(ls, pin, floats=scene.wall_profile is not None)
    )
    stiff = (
        bool(is_stiff(method, fld, grid, dynamics)) if dynamic else False
    )  # the solver simulate() would choose
    q0 = grid.to_index(poses)
    q0 = np.round(q0).astype(np.int32) if method == "greedy" else q0  # as simulate()
    # A vmapped while loop runs until its slowest lane stops: starts run grouped by run
    # length and position (_run_order) and are scattered back. Lanes are independent, so
    # the order changes no result.
    order = _run_order(q0, np.asarray(fld.best), grid)
    q0 = q0[order]
    final_q = np.empty((n, 3), np.float64)
    steps = np.empty(n, np.int32)
    outcome = np.empty(n, np.int8)
    energy = np.empty(n, np.float64)
    time_s = np.empty(n, np.float64) if dynamic else None

    def run(i: int) -> int:
        """Chunk starting at i: run, then scatter its results (disjoint rows per chunk)."""
        block = q0[i : i + chunk]
        m = len(block)
        if m < chunk:  # pad with the block's first start: one compiled shape
            block = np.concatenate([block, np.repeat(block[:1], chunk - m, axis=0)])
        q, st, _, out, e, ts = _run_chunk(
            fld,
            dynamics,
            jnp.asarray(block),
            grid=grid,
            method=method,
            max_steps=int(max_steps),
            stiff=stiff,
        )
        dest = order[i : i + m]
        final_q[dest] = np.asarray(q)[:m]
        steps[dest] = np.asarray(st)[:m]
        outcome[dest] = np.asarray(out)[:m]
        energy[dest] = np.asarray(e)[:m]
        if time_s is not None:
            time_s[dest] = np.asarray(ts)[:m]
        return m

    t1 = time.perf_counter()
    chunks = range(0, n, chunk)
    with progress_bar(progress, n, method, "start") as bar:
        if workers == 1:
            for i in chunks:
                bar.update(run(i))
                hold("batch")
        else:
            # XLA runs one vmapped loop on one core: a thread per core keeps each busy.
            ex = ThreadPoolExecutor(workers)
            try:
                for m in ex.map(run, chunks):
                    bar.update(m)
                    hold("batch")
            finally:
                ex.shutdown(wait=True, cancel_futures=True)
    dt = time.perf_counter() - t1
    x, y, t = global_minimum(scene, landscape=ls).pose  # the pose every command calls "aligned"
    return BatchResult(
        method=method,
        start=poses,
        final=grid.to_pose(final_q),
        outcome=outcome,
        steps=steps,
        energy_J=energy,
        period_deg=float(ls.period_deg),
        optimum=(x, y, t),
        stats={
            "landscape_s": t_land,
            "run_s": dt,
            "starts_per_s": n / dt,
            "steps_per_s": float(steps.sum()) / dt,
            "chunk": chunk,
            "landscape_shape": tuple(int(v) for v in ls.energy.shape),
            "stiff": stiff,  # dynamics: the implicit solver, starts mapped one after the other (_run_chunk)
        },
        time_s=time_s,
        error_limit=error_limit(scene, ls, pin=pin),
    )


# --------------------------------------------------------------------- pattern realizations
def run_realizations(
    sigmas: Sequence[float],
    seeds: Sequence[int],
    chip: Mask,
    starts,
    *,
    size_um: float = 200.0,
    pitch_um: float | None = None,
    margin_um: float = 10.0,
    method: str = "greedy",
    scene_options: dict | None = None,
    chunk: int | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    progress: bool = False,
) -> list[dict]:
    """Monte Carlo over random-jagged patterns (docs/physics.md §10): one landscape per seed.

    For each sigma and seed the pattern is ``patterns.geometry.random_jagged(size_um,
    sigma=sigma, seed=seed, pitch=pitch_um)`` rasterized at the chip's scale
    (``chip.um_per_px``) with ``margin_um`` of substrate around it, and every start is
    run on its own landscape. The error is relative to the *nominal* square's centre.

    Args:
        sigmas: edge-roughness standard deviations (um).
        seeds: pattern seeds (integers >= 0); the same seeds are used for every sigma.
        chip: the chip footprint (e.g. ``mask_from_geometry(square(200), um_per_px)``).
        starts: (N, 3) poses or a :class:`StartGrid`, the same for every pattern.
        scene_options: further :class:`~simulator.scene.Scene` fields (materials,
            twist, dtype, window_um, ...).

    Returns:
        One dict per sigma: ``sigma_um``, ``seeds``, the :func:`summarize` keys pooled
        over every seed and start, and ``optima`` (per seed, the global minimum's
        ``x_um``, ``y_um``, ``twist_deg``: where that pattern aligns a chip).
    """
    from patterns.geometry import random_jagged
    from patterns.raster import mask_from_geometry

    require(len(sigmas) >= 1 and len(seeds) >= 1, "give at least one sigma and one seed")
    poses = _as_poses(starts)
    out = []
    for sigma in sigmas:
        parts, optima = [], []
        for seed in seeds:
            geom = random_jagged(size_um, sigma=sigma, seed=seed, pitch=pitch_um)
            pattern = mask_from_geometry(
                geom,
                chip.um_per_px,
                margin_um=margin_um,
                params={"design": "random-jagged", "sigma_um": sigma, "seed": seed},
            )
            scene = Scene(pattern=pattern, chip=chip, **(scene_options or {}))
            r = run_batch(scene, poses, method, chunk=chunk, max_steps=max_steps, progress=progress)
            parts.append(r)
            optima.append(
                {
                    "seed": int(seed),
                    "x_um": r.optimum[0],
                    "y_um": r.optimum[1],
                    "twist_deg": r.optimum[2],
                }
            )
        pooled = BatchResult(
            method=method,
            start=np.concatenate([p.start for p in parts]),
            final=np.concatenate([p.final for p in parts]),
            outcome=np.concatenate([p.outcome for p in parts]),
            steps=np.concatenate([p.steps for p in parts]),
            energy_J=np.concatenate([p.energy_J for p in parts]),
            period_deg=parts[0].period_deg,
            optimum=(math.nan,) * 3,
            time_s=None if parts[0].time_s is None else np.concatenate([p.time_s for p in parts]),
            # the loosest of the patterns' limits bounds the pooled errors
            error_limit=max((p.error_limit for p in parts), key=lambda e: e["um"]),
        )
        summary = summarize(pooled, target="nominal")  # each pattern's own shift is the error
        summary.pop("optimum")
        out.append(
            {"sigma_um": float(sigma), "seeds": [int(s) for s in seeds]}
            | summary
            | {"optima": optima}
        )
    return out
