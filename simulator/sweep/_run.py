"""Design sweeps: the assessment of :func:`simulator.batch.assess` over many designs, on Dask.

A sweep file (TOML) holds a base scene, optionally a generated pattern, the axes that
vary and how points are drawn::

    [scene]                       # the base scene: any scene-file key (simulator.scene)
    chip_size_um = 730            # default chip: the pattern's wettable bounding box
    resolution_um = 5
    [scene.twist]
    step_deg = 3

    [design]                      # a generated pattern (patterns.geometry), or give
    name = "four-pad"             # [scene] pattern = "file.png", or a `pattern` axis
    size = 730
    gap = 50
    margin_um = 10

    [axes]                        # a list of values, a range, or one fixed value
    gap = { from = 20, to = 200, num = 7 }      # also {from, to, step}; {from, to} for samples
    volume_nl = [5, 10, 20, 40]
    placement_sigma_um = 73

    [sweep]
    seed = 1                      # every point's explicit seed (point_seed) derives from it
    realizations = 1              # repeats of every point (random-jagged: seed + r)
    # independent_noise = false   # true: every point its own placement-noise draw (default:
                                  # common random numbers, one draw per realization for every design)
    # samples = 64                # Latin hypercube points in the ranges instead of the grid
    yield_starts = 2000           # as evaluate
    capture_grid = 25             # starts per side of the capture grid, as evaluate

Axes (:data:`AXES`): every parameter of the design (``gap``, ``size``, ``sigma``, ``seed``,
``height``, ``width``, ...), ``pattern`` (a list of pattern files), ``chip_size_um``,
``volume_nl``, ``pad_angle_deg``, ``substrate_angle_deg``, ``surface_tension_mN_m``,
``placement_sigma_um``, ``placement_sigma_deg``, ``method``, ``resolution_um`` and
``twist_step_deg``. A grid runs every combination; ``samples = N`` draws N points by Latin
hypercube (one per stratum of every axis; lists and stepped ranges are sampled as levels).

Each point is one call of :func:`run_point`: the scene is built as ``evaluate`` builds it
(the accuracy preset, then the automatic coarsening above 320 MB unless a resolution is
given), and :func:`~simulator.batch.assess` gives the numbers, the yield drawn with the
point's explicit seed ``point_seed``. By default the seed depends on the sweep seed and the
realization only (common random numbers: the designs of one realization meet the same
placement draws, so their differences are the designs'); ``independent_noise = true`` gives
every point a draw of its own. A failing point returns its one-line error; the sweep goes on.

Points run on Dask (``dask.distributed``): a :class:`~distributed.LocalCluster` of spawned
single-threaded worker processes by default (XLA's CPU thread pool switched off in each,
and each worker counts one core), or an existing cluster (``scheduler``). Every point is
submitted impure (``pure=False``) with its seed in its arguments: no two points are merged.

Results (:class:`_Store`) go into a directory as points finish: ``points.jsonl`` (one line
per point, appended and flushed as each finishes: what a rerun resumes from),
``points/NNNNN.json`` (each point's full summary), ``results.parquet`` and ``results.csv``
(one row per point, rewritten atomically every few seconds and at the end), pictures and
``report.html`` (:mod:`simulator.sweep`). ``sweep.json`` holds the sweep's hash: a
rerun of the same sweep into the same directory skips the points done; a different sweep
is refused.

The plan (the file, its axes, its points and seeds, the hash) is :mod:`simulator.sweep`
(the axes :mod:`simulator.sweep`); the pictures and the page are :mod:`simulator.sweep`.
One point is :mod:`simulator.sweep`, the table's columns :mod:`simulator.sweep`,
the results directory :mod:`simulator.sweep`, the cluster :mod:`simulator.sweep`;
this module is the entry :func:`run_sweep`.

Columns carry their units: the axis values (``gap_um``, ``volume_nl``, ``method``), the
point's ``point``, ``realization``, ``point_seed``, ``status`` ("ok" or "error"), ``error``,
``seconds``, and every number of the assessment's summary flattened by :func:`flatten`
(``max_bias_plus_x_um``, ``capture_fraction``, ``yield_fraction``, ``settings_um_per_px``,
...) with ``max_bias_x_um`` / ``max_bias_y_um`` (the smaller of the two directions),
``global_minimum_offset_um`` and, with free contact lines, ``floating_half_width_um``.
A point run with ``method`` "overdamped" or "inertial" (the dynamics, batched) also has
the distribution of the time to align of its aligned starts, in seconds of simulated time:
``yield_time_to_align_median_s``, ``yield_time_to_align_p90_s`` (and ``_mean_s``,
``_min_s``, ``_max_s``, ``_n``; the same with ``capture_`` for the capture grid); the
steppers have no time, so their rows leave these empty.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from pathlib import Path
from typing import Any

from foundation import require
from simulator.sweep._axes import HARD_MAX_POINTS
from simulator.sweep._cluster import check_where, run_tasks, start_workers
from simulator.sweep._spec import (
    DEFAULT_MAX_POINTS,
    SweepSpec,
    load_sweep,
)
from simulator.sweep._store import (
    FLUSH_S,
    _Store,
)
from simulator.sweep._task import PointTask

__all__ = ["run_sweep"]


def _bar(show: bool, total: int):
    """Progress on stderr: points done of the total, failed so far, rate and the time left (tqdm)."""
    if not show:
        from foundation import NoBar

        return NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc="sweep", unit="point", postfix="failed 0", dynamic_ncols=True)


#: Points priced before local workers start (the first, the last and each axis's extremes).
MAX_PRICED = 16


def _priced_points(tasks: list[PointTask]) -> list[PointTask]:
    """The tasks whose memory bounds the sweep's: the first and the last, and for each axis
    the points of its smallest and largest value (numbers; others by their first and last)."""
    picks = {0, len(tasks) - 1}
    names = dict.fromkeys(k for t in tasks for k in t.values)
    for name in names:
        vals: list[Any] = [t.values.get(name) for t in tasks]  # an axis's values, any kind
        nums = [
            i for i, v in enumerate(vals) if isinstance(v, int | float) and not isinstance(v, bool)
        ]
        if nums:
            picks |= {min(nums, key=lambda i: vals[i]), max(nums, key=lambda i: vals[i])}
    return [tasks[i] for i in sorted(picks)[:MAX_PRICED]]


def _price_workers(spec: SweepSpec, tasks: list[PointTask]) -> tuple[float | None, float]:
    """(the largest priced peak of one point with a worker's imports, the sweep's memory
    budget in bytes) for :func:`worker_cap`: its workers together must fit the budget. A
    point that cannot be built or priced here is left to its run (its error row)."""
    from foundation import InputError, budget_bytes
    from simulator.sweep._point import point_bytes

    peak = None
    for task in _priced_points(tasks):
        try:
            b = point_bytes(task)
        except (InputError, ValueError):
            continue
        peak = b if peak is None else max(peak, b)
    return peak, budget_bytes(spec.scene.get("memory_budget_mb"))


def run_sweep(
    spec: str | os.PathLike | dict | SweepSpec,
    out: str | os.PathLike | None = None,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    max_points: int = DEFAULT_MAX_POINTS,
    retry_failed: bool = False,
    quiet: bool = True,
    base: str | os.PathLike | None = None,
    pictures: bool = True,
    flush_s: float = FLUSH_S,
):
    """Run a design sweep and return its table (a pandas DataFrame, one row per point).

    Args:
        spec: a sweep file (TOML) or the same structure as a dict (see the module docstring).
        out: directory for the results (resumable: the points already in it are skipped);
            None keeps them in memory only.
        workers: local Dask worker processes (default: one per core, at most one per point);
            0 runs every point in this process, without Dask.
        scheduler: address of an existing Dask scheduler, instead of local workers.
        max_points: refuse a sweep with more points.
        retry_failed: run the points whose row is an error again.
        quiet: no progress bar.
        base: directory of relative paths when ``spec`` is a dict.
        pictures: write the pictures and report.html into ``out`` at the end.

    ``table.attrs["sweep"]`` holds the hash, the counts and the times.
    """
    spec = spec if isinstance(spec, SweepSpec) else load_sweep(spec, base)
    n = spec.n_points
    require(
        isinstance(max_points, int) and max_points >= 1,
        f"--max-points must be a whole number >= 1, got {max_points!r}",
    )
    require(
        n <= HARD_MAX_POINTS,
        f"the sweep has {n:,} points ({spec.shape_text()}); at most {HARD_MAX_POINTS:,}",
    )
    require(
        n <= max_points,
        f"the sweep has {n:,} points ({spec.shape_text()}), more than the cap of {max_points:,}; "
        f"pass --max-points {n} to run it, or use fewer values or [sweep] samples = N",
    )
    check_where(workers, scheduler)
    inputs = [Path(p) for p in spec.files] + ([Path(spec.source)] if spec.source != "sweep" else [])
    store = _Store(
        spec, out, inputs, flush_s
    )  # checks out; reads the points a previous run finished
    t0 = time.perf_counter()
    failed = [0]
    try:
        done = store.done(retry_failed)
        todo = [spec.task(p) for p in spec.points() if p.point not in done]
        with contextlib.ExitStack() as stack:
            client, t_cluster, where = start_workers(
                stack, workers, scheduler, len(todo), lambda: _price_workers(spec, todo)
            )
            store.open()  # only now: a scheduler that cannot be reached leaves no directory
            if todo and not quiet:
                print(
                    f"sweep {spec.digest[:12]}: {n} points ({spec.shape_text()}), {n - len(todo)} done before; running {len(todo)} on {where}",
                    file=sys.stderr,
                    flush=True,
                )
            with _bar(not quiet and bool(todo), len(todo)) as bar:

                def handle(task: PointTask, result: dict) -> None:
                    store.add(task, result)
                    failed[0] += result["status"] != "ok"
                    bar.set_postfix_str(f"failed {failed[0]}", refresh=False)
                    bar.update(1)

                if not todo:
                    stats = {"run_s": 0.0, "workers": 0, "threads": 0}
                else:
                    stats = run_tasks(client, todo, handle)
                stats["cluster_s"] = t_cluster
    finally:
        if store.out is not None and store._journal is not None:
            with contextlib.suppress(Exception):
                store.write_tables()
        store.close()
    table = store.table()
    stats |= {
        "hash": spec.digest,
        "points": n,
        "run_now": len(todo),
        "resumed": n - len(todo),
        # table["status"] is one column (a Series), its sum a number: pandas types it wider
        "failed": int((table["status"] != "ok").sum()) if len(table) else 0,  # pyright: ignore[reportArgumentType]
        "failed_now": failed[0],
        "seconds": time.perf_counter() - t0,
    }
    stats["points_per_s"] = len(todo) / stats["run_s"] if stats["run_s"] > 0 else None
    if store.out is not None:
        if pictures:
            from simulator.sweep._report import write_report

            write_report(store.out, spec, table, stats)
        store.write_marker()
    table.attrs["sweep"] = stats
    return table
