"""Design sweeps: the assessment of :func:`simulator.evaluate.assess` over many designs, on Dask.

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
given), and :func:`~simulator.evaluate.assess` gives the numbers, the yield drawn with the
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
``report.html`` (:mod:`simulator.sweep_render`). ``sweep.json`` holds the sweep's hash: a
rerun of the same sweep into the same directory skips the points done; a different sweep
is refused.

The plan (the file, its axes, its points and seeds, the hash) is :mod:`simulator.sweep_spec`;
the pictures and the page are :mod:`simulator.sweep_render`.

Columns carry their units: the axis values (``gap_um``, ``volume_nl``, ``method``), the
point's ``point``, ``realization``, ``point_seed``, ``status`` ("ok" or "error"), ``error``,
``seconds``, and every number of the assessment's summary flattened by :func:`flatten`
(``max_bias_plus_x_um``, ``capture_fraction``, ``yield_fraction``, ``settings_um_per_px``,
...) with ``max_bias_x_um`` / ``max_bias_y_um`` (the smaller of the two directions) and
``global_minimum_offset_um``.
"""

from __future__ import annotations

import contextlib
import copy
import json
import math
import os
import sys
import time
import types
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from patterns.errors import InputError, require
from simulator.sweep_spec import (  # noqa: F401  (the plan lives in simulator.sweep_spec; importable from here)
    AXES,
    DEFAULT_MAX_POINTS,
    HARD_MAX_POINTS,
    ID_COLUMNS,
    Axis,
    SweepSpec,
    _design_axes,
    _design_seed,
    axis_kinds,
    load_sweep,
)

__all__ = [
    "AXES",
    "DEFAULT_MAX_POINTS",
    "Axis",
    "SweepSpec",
    "assess_point",
    "flatten",
    "load_sweep",
    "run_point",
    "sweep",
]

#: Seconds between rewrites of results.parquet / results.csv while a sweep runs.
FLUSH_S = 2.0
#: Seconds to wait for a Dask scheduler given with ``scheduler``.
CONNECT_TIMEOUT_S = 3.0
#: XLA flag that keeps a worker's JAX on one thread (set before JAX is imported there).
XLA_ONE_THREAD = "--xla_cpu_multi_thread_eigen=false"

#: Why spawned workers fail to start from a script, and the fix.
MAIN_GUARD = ("worker processes are spawned and import the main script, so a script that calls simulator.sweep must do so "
              "under `if __name__ == \"__main__\":`")

MANIFEST = "sweep.json"
JOURNAL = "points.jsonl"
POINTS_DIR = "points"
LOCK = ".sweep.lock"
TABLES = ("results.parquet", "results.csv")

STATUS_COLUMNS = ("status", "error", "seconds")


# ----------------------------------------------------------------------- one point
def _cap_threads() -> None:
    """In a Dask worker: JAX and the FFTs on one core (before JAX is imported there)."""
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return  # not in a worker: this process's own settings stand
    if "jax" not in sys.modules and XLA_ONE_THREAD not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {XLA_ONE_THREAD}".strip()
    # The correlator's FFTs and the batch threads size themselves by os.cpu_count(): a worker counts one core.
    os.cpu_count = lambda: 1


def point_scene(task: dict):
    """The scene of one point, built as ``selfalign evaluate`` builds it; also whether to coarsen automatically."""
    from patterns.geometry import build, design_record
    from patterns.raster import mask_from_geometry
    from simulator.scene import Scene

    doc = copy.deepcopy(task["scene"])
    v = task["values"]
    design = task["design"]
    if "chip_size_um" in v:
        for k in ("chip", "chip_layer"):
            doc.pop(k, None)
        doc["chip_size_um"] = v["chip_size_um"]
    for key, table, name in (("volume_nl", "liquid", "volume_nl"), ("pad_angle_deg", "materials", "pad_angle_deg"),
                             ("substrate_angle_deg", "materials", "substrate_angle_deg"),
                             ("surface_tension_mN_m", "materials", "surface_tension_mN_m"), ("twist_step_deg", "twist", "step_deg")):
        if key in v:
            doc.setdefault(table, {})[name] = v[key]
    if "resolution_um" in v:
        doc["resolution_um"] = v["resolution_um"]
    if "pattern" in v:
        doc["pattern"] = str((Path(task["base"]) / v["pattern"]).resolve())
    if design is not None:
        params = dict(design["params"])
        params.update({k: x for k, x in v.items() if k not in AXES})
        if "seed" in {p for p in _design_axes(design["name"])}:
            params["seed"] = _design_seed(design, task)
        geometry = build(design["name"], **params)
        record = design_record(design["name"], **params)
        record.update(margin_um=design["margin_um"], area_um2=geometry.area)
        um = doc.get("resolution_um") or doc.get("um_per_px") or 1.0
        doc["pattern"] = mask_from_geometry(geometry, um, margin_um=design["margin_um"], params=record,
                                            budget_mb=doc.get("memory_budget_mb"), what="the pattern raster")
        if not any(k in doc for k in ("chip", "chip_size_um", "chip_layer")):
            x0, y0, x1, y1 = geometry.bounds  # evaluate's default chip: the pattern's wettable bounding box
            doc["chip_size_um"] = [x1 - x0, y1 - y0]
    elif not any(k in doc for k in ("chip", "chip_size_um", "chip_layer")):
        # evaluate's default chip: the pattern's wettable bounding box (the pattern read once with a stand-in chip)
        from simulator.evaluate import footprint_um

        probe = Scene.from_dict(doc | {"chip_size_um": [1.0, 1.0]}, base=Path(task["base"]))
        doc["chip_size_um"] = list(footprint_um(probe.pattern))
    auto = "resolution_um" not in doc
    return Scene.from_dict(doc, base=Path(task["base"])), auto


def assess_point(task: dict) -> dict:
    """The summary of one point: :func:`simulator.evaluate.assess` on its scene, as ``evaluate`` runs it.

    The yield's placement noise is drawn with the point's ``point_seed``; ``settings`` also
    records ``source_um_per_px``, ``resolution_auto`` (as evaluate) and ``volume_nl``.
    """
    from simulator.evaluate import (
        NOISE_FRACTION,
        NOISE_TWIST_DEG,
        assess,
        auto_resolution,
        chip_size,
    )
    from simulator.finite import require_finite

    scene, auto = point_scene(task)
    native = scene.um_per_px
    if auto:
        scene = auto_resolution(scene)
    v = task["values"]
    sigma = None
    if "placement_sigma_um" in v or "placement_sigma_deg" in v:
        w, h = chip_size(scene)
        sx, sy = (v["placement_sigma_um"],) * 2 if "placement_sigma_um" in v else (NOISE_FRACTION * w, NOISE_FRACTION * h)
        sigma = (sx, sy, v.get("placement_sigma_deg", NOISE_TWIST_DEG))
    summary = assess(scene, quiet=True, method=v.get("method", "greedy"), seed=task["point_seed"], placement_sigma=sigma,
                     yield_starts=task["yield_starts"], grid_cells=task["capture_grid"])
    summary["settings"] |= {"source_um_per_px": native, "resolution_auto": bool(auto and scene.um_per_px != native),
                            "volume_nl": scene.liquid.volume_nl}
    if "layout" in scene.pattern.params:
        summary["layout"] = scene.pattern.params["layout"]
    return require_finite(summary, f"point {task['point']}")


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split()) or "(no message)"
    return (text if isinstance(err, InputError) else f"{type(err).__name__}: {text}")[:500]


def run_point(task: dict) -> dict:
    """Run one point; never raises for the point's own failure: ``status`` "ok" with the
    ``summary``, or "error" with the one-line ``error``. What each Dask task runs."""
    _cap_threads()
    t0 = time.perf_counter()
    try:
        summary = assess_point(task)
    except Exception as err:  # the point's failure is its row; the sweep goes on
        return {"point": task["point"], "status": "error", "error": _one_line(err), "seconds": round(time.perf_counter() - t0, 3), "summary": None}
    return {"point": task["point"], "status": "ok", "error": None, "seconds": round(time.perf_counter() - t0, 3), "summary": summary}


# ----------------------------------------------------------------------- flattening
#: Unit suffixes of summary keys, longest first; a key ``name_UNIT`` puts UNIT at the end of its column.
UNITS = ("um_per_px", "Nm_per_rad", "N_per_m", "mN_m", "N_m", "kg_m3", "mPa_s", "Pa_s", "um2", "um", "deg", "Nm", "nl", "MB", "J", "N", "s", "px")
#: Names of list components, by key (default x, y, twist).
COMPONENTS = {"pattern_px": ("rows", "cols"), "chip_um": ("width", "height")}


def _split_unit(key: str) -> tuple[str, str | None]:
    for u in UNITS:
        if key.endswith("_" + u) and len(key) > len(u) + 1:
            return key[: -len(u) - 1], u
    return key, None


def _name(key: str) -> str:
    key = str(key)
    if key[:1] in "+-" and len(key) > 1:
        key = ("plus_" if key[0] == "+" else "minus_") + key[1:]
    return key.replace(" ", "_")


def flatten(summary: dict) -> dict[str, Any]:
    """Every number (and boolean) of a nested summary as one column, the unit at the end.

    ``{"max_bias_um": {"+x": 90}}`` gives ``max_bias_plus_x_um``; ``{"global_minimum":
    {"x_um": 0}}`` gives ``global_minimum_x_um``; ``{"restoring_force_N": {"+x": [fx, fy]}}``
    gives ``restoring_force_plus_x_x_N`` and ``..._y_N``; a new key such as
    ``{"stiffness": {"x_N_per_m": k}}`` gives ``stiffness_x_N_per_m``. Strings, None and
    lists of lists (plateaus) are left out.
    """
    out: dict[str, Any] = {}

    def emit(parts: tuple[str, ...], unit: str | None, v: Any) -> None:
        col = "_".join(p for p in parts if p) + (f"_{unit}" if unit else "")
        if isinstance(v, bool | np.bool_):
            out[col] = bool(v)
        elif isinstance(v, int | np.integer):
            out[col] = int(v)
        else:
            out[col] = float(v)

    def walk(d: dict, parts: tuple[str, ...], unit: str | None) -> None:
        for k, v in d.items():
            name, u = _split_unit(str(k))
            name, u = _name(name), u or unit
            if isinstance(v, dict):
                walk(v, (*parts, name), u)
            elif isinstance(v, list | tuple):
                if v and all(isinstance(x, int | float | np.number) and not isinstance(x, bool) for x in v):
                    comps = COMPONENTS.get(str(k)) or (("x", "y", "twist") if len(v) <= 3 else tuple(str(i) for i in range(len(v))))
                    for c, x in zip(comps, v, strict=False):
                        emit((*parts, name, c), u, x)
            elif isinstance(v, bool | int | float | np.number):
                emit((*parts, name), u, v)

    walk(summary, (), None)
    b = summary.get("max_bias_um") or {}
    for axis in ("x", "y"):
        ends = [b.get(f"+{axis}"), b.get(f"-{axis}")]
        if all(isinstance(e, int | float) for e in ends):
            out[f"max_bias_{axis}_um"] = float(min(ends))
    g = summary.get("global_minimum") or {}
    if isinstance(g.get("x_um"), int | float) and isinstance(g.get("y_um"), int | float):
        out["global_minimum_offset_um"] = float(math.hypot(g["x_um"], g["y_um"]))
    return out


# ----------------------------------------------------------------------- the store
def _write_text(path: Path, text: str) -> None:
    from patterns.outputs import atomic_output

    with atomic_output(path) as tmp:
        tmp.write_text(text)


def _version() -> str:
    """selfalign's version, for the record (not part of a sweep's hash)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("selfalign")
    except PackageNotFoundError:
        return "unknown"


class _Store:
    """The rows of a sweep, in memory and (with ``out``) in a resumable directory."""

    def __init__(self, spec: SweepSpec, out: str | os.PathLike | None, inputs: Iterable[Path] = (), flush_s: float = FLUSH_S):
        """Check ``out`` (and, for a sweep already there, take its lock and read its rows); create nothing."""
        from patterns.outputs import check_output_dir

        self.spec, self.flush_s = spec, flush_s
        self.out = Path(out) if out is not None else None
        self.inputs = list(inputs)
        self.rows: dict[int, dict] = {}
        self._lock = None
        self._journal = None
        self._next_flush = 0.0
        self.existing = False
        if self.out is None:
            return
        if self.out.is_dir() and not self.out.is_symlink() and any(self.out.iterdir()):
            self._check_same(self.out, self.inputs)
            self.existing = True
            self._take_lock()
            self._read_journal()
        else:
            check_output_dir(self.out, "--out", False, self.inputs)

    # .................................................................. directory
    def open(self) -> None:
        """Create the directory (when new) and its manifest; open the journal for appending."""
        from patterns.outputs import check_output_dir

        out = self.out
        if out is None:
            return
        if not self.existing:
            check_output_dir(out, "--out", False, self.inputs)  # nothing changed meanwhile
            out.mkdir(exist_ok=True)
            self._take_lock()
        (out / POINTS_DIR).mkdir(exist_ok=True)
        if not (out / MANIFEST).exists():
            _write_text(out / MANIFEST, json.dumps({"tool": "selfalign", "version": _version(), "command": "sweep", "hash": self.spec.digest,
                                                    **self.spec.describe()}, indent=1, default=str) + "\n")
        self._journal = open(out / JOURNAL, "a", encoding="utf-8")  # noqa: SIM115 (closed in close())

    def _check_same(self, out: Path, inputs: list[Path]) -> None:
        """A non-empty ``out`` is resumed only when it holds this very sweep."""
        flag = "--out"
        man = out / MANIFEST
        r = out.resolve()
        cwd = Path.cwd().resolve()
        require(not (r == cwd or r in cwd.parents), f"{flag} {out}: is the working directory or holds it; give a new directory name")
        for inp in inputs:
            ri = inp.resolve()
            require(not (r == ri or r in ri.parents), f"{flag} {out}: holds an input of this sweep ({inp.name}); give a new directory name")
        if not man.is_file():
            raise InputError(f"{flag} {out}: holds files that are not a selfalign sweep; choose a new or empty directory")
        try:
            doc = json.loads(man.read_text())
            theirs = doc["hash"]
        except (OSError, ValueError, KeyError, TypeError):
            raise InputError(f"{flag} {out}: its {MANIFEST} cannot be read; choose a new or empty directory") from None
        if theirs != self.spec.digest:
            raise InputError(
                f"{flag} {out}: holds a different sweep ({doc.get('source', '?')}, {doc.get('points', '?')} points, hash {str(theirs)[:12]}; "
                f"this one is {self.spec.digest[:12]}); choose another --out (sweeps are never mixed)"
            )
        require(os.access(out, os.W_OK), f"{flag} {out}: directory is not writable")

    def _take_lock(self) -> None:
        import fcntl

        f = open(self.out / LOCK, "a+")  # noqa: SIM115 (held until close())
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            raise InputError(f"--out {self.out}: another selfalign sweep is writing into it; wait for it to end or choose another --out") from None
        self._lock = f

    def _read_journal(self) -> None:
        path = self.out / JOURNAL
        if not path.exists():
            return
        data = path.read_bytes()
        end = data.rfind(b"\n") + 1
        if end < len(data):  # a line cut short by a kill: dropped, so the next line starts clean
            with open(path, "rb+") as f:
                f.truncate(end)
        n = self.spec.n_points
        for line in data[:end].splitlines():
            try:
                row = json.loads(line)
                i = int(row["point"])
            except (ValueError, KeyError, TypeError):
                continue
            if 0 <= i < n:
                self.rows[i] = row

    # .................................................................. rows
    def done(self, retry_failed: bool) -> set[int]:
        return {i for i, r in self.rows.items() if r.get("status") == "ok" or not retry_failed}

    def add(self, point: dict, result: dict) -> dict:
        row = self.spec.columns(point) | {k: result.get(k) for k in STATUS_COLUMNS}
        if result.get("summary") is not None:
            row |= flatten(result["summary"])
        i = point["point"]
        self.rows[i] = row
        if self.out is not None:
            width = max(5, len(str(self.spec.n_points - 1)))
            doc = {"point": i, "settings": point["values"], "row": row, "summary": result.get("summary")}
            _write_text(self.out / POINTS_DIR / f"{i:0{width}d}.json", json.dumps(doc, indent=1, allow_nan=False) + "\n")
            self._journal.write(json.dumps(row, allow_nan=False) + "\n")
            self._journal.flush()
            if time.monotonic() >= self._next_flush:
                self.write_tables()
        return row

    def table(self):
        """All rows, by point, as a pandas DataFrame (columns: identity, settings, status, metrics)."""
        import pandas as pd

        rows = [self.rows[i] for i in sorted(self.rows)]
        cols: dict[str, None] = {}
        for r in rows:  # rows are built identity, settings, status, metrics: their union keeps that order
            cols.update(dict.fromkeys(r))
        return pd.DataFrame(rows, columns=list(cols)) if rows else pd.DataFrame(columns=list(cols))

    def write_tables(self) -> None:
        if self.out is None:
            return
        import pyarrow as pa
        import pyarrow.parquet as pq

        t0 = time.monotonic()
        df = self.table()
        from patterns.outputs import atomic_output

        with atomic_output(self.out / TABLES[0]) as tmp:
            pq.write_table(pa.Table.from_pandas(df, preserve_index=False), tmp)
        with atomic_output(self.out / TABLES[1]) as tmp:
            df.to_csv(tmp, index=False)
        now = time.monotonic()
        self._next_flush = now + max(self.flush_s, 10 * (now - t0))  # a large table: at most a tenth of the time on rewriting it

    def write_marker(self) -> None:
        from patterns.outputs import MARKER, _listing

        files = [e for e in _listing(self.out) if not e.endswith("/") and e != MARKER and not e.startswith(".") and "/." not in e]
        _write_text(self.out / MARKER, json.dumps({"tool": "selfalign", "command": "sweep", "files": sorted(files + [LOCK])}, indent=1) + "\n")

    def close(self) -> None:
        if self._journal is not None:
            with contextlib.suppress(OSError):
                self._journal.flush()
                os.fsync(self._journal.fileno())
            self._journal.close()
            self._journal = None
        if self._lock is not None:
            self._lock.close()
            self._lock = None


# ----------------------------------------------------------------------- running
def _worker_env() -> dict[str, str]:
    flags = os.environ.get("XLA_FLAGS", "")
    if XLA_ONE_THREAD not in flags:
        flags = f"{flags} {XLA_ONE_THREAD}".strip()
    return {"XLA_FLAGS": flags, "XLA_PYTHON_CLIENT_PREALLOCATE": "false", "OMP_NUM_THREADS": "1"}


def _check_address(address: str) -> None:
    """A scheduler address Dask can parse (scheme://HOST:PORT), else one line; nothing is contacted."""
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, loc = parse_address(address)
        get_backend(scheme)
        if scheme in ("tcp", "tls"):
            parse_host_port(loc)
    except (ValueError, TypeError) as err:
        raise InputError(f"--scheduler {address}: not a Dask scheduler address ({' '.join(str(err).split())[:200]}); "
                         "write it as tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786") from None


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A Dask client: on ``scheduler`` (an existing cluster), else on a new LocalCluster of
    ``workers`` spawned single-threaded worker processes. Closed (cluster too) on exit."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    config = {"distributed.worker.multiprocessing-method": "spawn", "distributed.comm.timeouts.connect": f"{CONNECT_TIMEOUT_S}s",
              "distributed.scheduler.allowed-failures": 1, "distributed.worker.daemon": True,
              "distributed.worker.profile.enabled": False,  # the statistical profiler costs ~15 % of a point; no dashboard shows it
              # Dask's default environment of a new worker, less MALLOC_TRIM_THRESHOLD_=65536: with it every large
              # array is mapped and unmapped afresh, which doubled the time of a point (measured).
              "distributed.nanny.pre-spawn-environ": {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1}}
    cluster = client = None
    with dask.config.set(config):
        try:
            if scheduler:
                _check_address(scheduler)
                try:
                    client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
                except (OSError, TimeoutError, ValueError, TypeError) as err:
                    reason = " ".join(str(err).split())[:200] or type(err).__name__
                    raise InputError(f"--scheduler {scheduler}: cannot reach a Dask scheduler within {CONNECT_TIMEOUT_S:g} s ({reason}); "
                                     "check the address (tcp://HOST:PORT), or leave out --scheduler to start local workers") from None
            else:
                import multiprocessing

                if getattr(multiprocessing.current_process(), "_inheriting", False):
                    # A spawned worker is importing the script that called sweep(): the call lacks the main guard.
                    raise SystemExit(f"selfalign sweep: error: {MAIN_GUARD}")
                try:
                    cluster = LocalCluster(n_workers=int(workers or 1), threads_per_worker=1, processes=True, dashboard_address=None,
                                           silence_logs=logging.ERROR, env=_worker_env())
                except RuntimeError as err:
                    raise InputError(f"the local Dask workers did not start ({' '.join(str(err).split())[:120]}); {MAIN_GUARD}") from None
                client = Client(cluster, set_as_default=False)
            yield client
        finally:
            with contextlib.suppress(Exception):
                if client is not None:
                    client.close(timeout=10)
            with contextlib.suppress(Exception):
                if cluster is not None:
                    cluster.close(timeout=10)


def _run_dask(client: Any, tasks: list[dict], handle: Callable[[dict, dict], None]) -> dict:
    """Every task on ``client``'s cluster, at most two per worker thread in flight, results handled as they come."""
    from distributed import as_completed

    t0 = time.perf_counter()
    threads = max(1, sum(client.nthreads().values()))
    pending = iter(tasks)
    by_key: dict[str, dict] = {}
    ac = as_completed(loop=client.loop)

    def submit() -> None:
        t = next(pending, None)
        if t is not None:
            f = client.submit(run_point, t, pure=False)  # impure: no two points are merged
            by_key[f.key] = t
            ac.add(f)

    for _ in range(2 * threads):
        submit()
    for f in ac:
        t = by_key.pop(f.key)
        try:
            result = f.result()
        except Exception as err:  # the worker died (memory, a crash): the point's error row
            result = {"point": t["point"], "status": "error", "error": _one_line(err), "seconds": None, "summary": None}
        f.release()
        handle(t, result)
        submit()
    return {"run_s": time.perf_counter() - t0, "workers": len(client.nthreads()), "threads": threads}


def _run_here(tasks: list[dict], handle: Callable[[dict, dict], None]) -> dict:
    t0 = time.perf_counter()
    for t in tasks:
        handle(t, run_point(t))
    return {"run_s": time.perf_counter() - t0, "workers": 0, "threads": 1}


def _bar(show: bool, total: int):
    """Progress on stderr: points done of the total, failed so far, rate and the time left (tqdm)."""
    if not show:
        from simulator.feedback import _NoBar

        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc="sweep", unit="point", postfix="failed 0", dynamic_ncols=True)


def sweep(spec: str | os.PathLike | dict, out: str | os.PathLike | None = None, *, workers: int | None = None,
          scheduler: str | None = None, max_points: int = DEFAULT_MAX_POINTS, retry_failed: bool = False, quiet: bool = True,
          base: str | os.PathLike | None = None, pictures: bool = True, flush_s: float = FLUSH_S):
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
    require(isinstance(max_points, int) and max_points >= 1, f"--max-points must be a whole number >= 1, got {max_points!r}")
    require(n <= HARD_MAX_POINTS, f"the sweep has {n:,} points ({spec.shape_text()}); at most {HARD_MAX_POINTS:,}")
    require(n <= max_points, f"the sweep has {n:,} points ({spec.shape_text()}), more than the cap of {max_points:,}; "
            f"pass --max-points {n} to run it, or use fewer values or [sweep] samples = N")
    if workers is not None:
        require(isinstance(workers, int) and not isinstance(workers, bool) and 0 <= workers <= 4096, f"--workers must be a whole number >= 0, got {workers!r}")
        require(not scheduler, "give --workers or --scheduler, not both (the cluster at --scheduler has its own workers)")
    inputs = [Path(p) for p in spec.files] + ([Path(spec.source)] if spec.source != "sweep" else [])
    store = _Store(spec, out, inputs, flush_s)  # checks out; reads the points a previous run finished
    t0 = time.perf_counter()
    failed = [0]
    try:
        done = store.done(retry_failed)
        todo = [spec.task(p) for p in spec.points() if p["point"] not in done]
        n_workers = None if scheduler else min(workers or os.cpu_count() or 1, max(len(todo), 1))
        with contextlib.ExitStack() as stack:
            t_cluster = time.perf_counter()
            client = stack.enter_context(dask_client(n_workers, scheduler)) if todo and workers != 0 else None
            t_cluster = time.perf_counter() - t_cluster
            store.open()  # only now: a scheduler that cannot be reached leaves no directory
            if todo and not quiet:
                where = f"the Dask cluster at {scheduler}" if scheduler else "this process" if client is None else f"{n_workers} local Dask workers"
                print(f"sweep {spec.digest[:12]}: {n} points ({spec.shape_text()}), {n - len(todo)} done before; running {len(todo)} on {where}",
                      file=sys.stderr, flush=True)
            with _bar(not quiet and bool(todo), len(todo)) as bar:
                def handle(task: dict, result: dict) -> None:
                    store.add(task, result)
                    failed[0] += result["status"] != "ok"
                    bar.set_postfix_str(f"failed {failed[0]}", refresh=False)
                    bar.update(1)

                if not todo:
                    stats = {"run_s": 0.0, "workers": 0, "threads": 0}
                elif client is None:
                    stats = _run_here(todo, handle)
                else:
                    stats = _run_dask(client, todo, handle)
                stats["cluster_s"] = t_cluster
    finally:
        if store.out is not None and store._journal is not None:
            with contextlib.suppress(Exception):
                store.write_tables()
        store.close()
    table = store.table()
    stats |= {"hash": spec.digest, "points": n, "run_now": len(todo), "resumed": n - len(todo),
              "failed": int((table["status"] != "ok").sum()) if len(table) else 0, "failed_now": failed[0],
              "seconds": time.perf_counter() - t0}
    stats["points_per_s"] = len(todo) / stats["run_s"] if stats["run_s"] > 0 else None
    if store.out is not None:
        if pictures:
            from simulator.sweep_render import write_report

            write_report(store.out, spec, table, stats)
        store.write_marker()
    table.attrs["sweep"] = stats
    return table


class _CallableModule(types.ModuleType):
    """``simulator.sweep(...)`` works whether ``simulator.sweep`` is this module or its function."""

    def __call__(self, *args: Any, **kwargs: Any):
        return sweep(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
