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

import math
import time
from collections.abc import Sequence

import numpy as np

from foundation import InputError, progress_bar, require
from patterns.geometry import Mask
from simulator.batch._lanes import (  # noqa: F401 - _one, _run_chunk: the benchmarks' and tests' handles
    _check_starts_fit,
    _one,
    _run_chunk,
    _run_order,
    run_lanes,
)
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
    threads,
)
from simulator.landscape import Landscape, build_landscape, global_minimum
from simulator.motion import (
    error_limit,
    field_and_grid,
    is_stiff,
)
from simulator.physics import align_tolerance, pin_per_index
from simulator.scene import Scene

#: Peak bytes per start of a dynamics batch beyond :data:`BATCH_BYTES_PER_START`: its time.
TIME_BYTES_PER_START = 16


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
    planes=None,
    lanes: int | None = None,
) -> BatchResult:
    """Run every start to its end on one landscape.

    Args:
        scene: what to simulate.
        starts: (N, 3) poses (x_um, y_um, twist_deg), or a :class:`StartGrid`.
        method: "greedy", "gradient", "overdamped" or "inertial" (the dynamics of
            :mod:`simulator.motion`, ``jax.vmap`` of the single-run solver).
        landscape: the landscape to run on; default ``build_landscape(scene)`` (the full
            landscape, built once), or the pads' planes of the footprint state where the
            scene has one (:attr:`simulator.scene.Scene.dispense`). A given landscape is run
            on as it is, stateless, as :func:`simulator.motion.simulate` does, unless the
            scene's liquid names a protocol itself (refused: the state needs the planes).
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
        planes: for a scene with ``dispense`` (the footprint as each start's state,
            docs/physics.md §3.5), its pads' planes
            (:func:`simulator.landscape.build_footprint_planes`) when several batches share
            them; default: built here.
        lanes: run fewer starts than this padded to this many lanes (at most ``chunk``;
            the padding lanes repeat a start and are dropped): batches of different sizes
            that pass the same ``lanes`` share one compiled shape (a compile takes
            seconds; :func:`simulator.batch.assess` runs its capture grid and its yield
            starts so). Default: the number of starts.

    Returns:
        A :class:`BatchResult`; ``stats`` holds seconds, starts and steps per second;
        for the dynamics ``time_s`` holds each start's simulated time at its end
        (:attr:`BatchResult.time_to_align_s`: that time for the aligned starts).
    """
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
    if lanes is not None:
        require(
            not isinstance(lanes, bool) and isinstance(lanes, int | np.integer) and lanes >= 1,
            f"lanes must be a whole number >= 1 or None, got {lanes!r}",
        )
    n, chunk = len(poses), int(min(chunk, max(len(poses), lanes or 0)))
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
    # the footprint as each lane's state (docs/physics.md §3.5), on the pads' planes; a given
    # landscape is run on as it is (stateless) unless the scene asked for a protocol itself
    if scene.dispense is not None and (landscape is None or scene.liquid.dispense is not None):
        require(
            landscape is None,
            "--dispense: a batch on a given landscape cannot carry the footprint state (it is built "
            "from the pads' planes); leave the landscape out",
        )
        from simulator.batch._footprint_batch import run_footprint_batch

        return run_footprint_batch(
            scene,
            poses,
            method,
            chunk=chunk,
            max_steps=max_steps,
            progress=progress,
            workers=workers,
            dynamics=dynamics,
            planes=planes,
        )
    t0 = time.perf_counter()
    ls = build_landscape(scene, progress=progress) if landscape is None else landscape
    t_land = time.perf_counter() - t0
    _check_starts_fit(ls, poses)
    from simulator.motion import pin_lines

    pin = pin_per_index(scene, ls.um_per_px, ls.twist_step_deg)
    fld, grid = field_and_grid(
        ls,
        pin=pin,
        align_tol=align_tolerance(ls, pin, floats=scene.wall_profile is not None),
        lines=pin_lines(scene, ls.energy.dtype),
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
    t1 = time.perf_counter()
    with progress_bar(progress, n, method, "start") as bar:
        got = run_lanes(
            fld,
            grid,
            dynamics,
            q0[order],
            method,
            max_steps,
            stiff,
            chunk,
            workers,
            bar.update,
            min_lanes=chunk,
        )
    # back to the caller's order: lanes are independent, so the order changes no result
    final_q, steps, outcome, energy, time_s = (np.empty_like(a) for a in got[:2] + got[3:])
    for dst, src in zip((final_q, steps, outcome, energy, time_s), got[:2] + got[3:], strict=True):
        dst[order] = src
    time_s = time_s if dynamic else None
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
    from patterns.geometry import mask_from_geometry, random_jagged

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
            optimum=(math.nan, math.nan, math.nan),
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
