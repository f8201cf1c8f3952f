"""A search over a generated design's parameters: Optuna trials, each evaluated as sweep points are.

:func:`search` runs a :class:`SearchSpec` (:func:`load_search`): an Optuna study (TPE,
CMA-ES, random or NSGA-II, seeded) asks for a design, the design's points (one per
realization) run exactly as a sweep's points run (:func:`simulator.sweep.run_point`, on
the sweep's Dask client or in this process, :func:`simulator.sweep.run_tasks`), and the
study is told the objectives and the constraints' violations (Optuna's constraints: an
infeasible trial is recorded, never best). Up to one point per worker thread is in flight,
the next asked for as each result comes (ask and tell; TPE's constant liar keeps the
designs in flight apart).

The run is priced first (:func:`simulator.sweep.price_point` on the baseline and the corners
of the search space: a trial that would not fit the memory budget refuses the search before
any Dask start), then the results directory is checked (:class:`simulator.sweep.ResultStore`:
``search.json`` holds the search's hash, ``trials.jsonl`` the journal, ``trials/NNNNN.json``
each trial's points, ``trials.parquet`` and ``trials.csv`` the table). A rerun of the same
search into the same directory replays the finished trials into the study and runs only the
remaining ones; a different search is refused. The file's ``[design]`` values are evaluated
too, as trial 0, the baseline. Without ``independent_noise`` a design asked for again is
not run again: its trial reuses the first evaluation (``same_as``), and a search over
discrete axes stops once every design of the space was tried.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from foundation import InputError, require
from simulator.design._optuna import quiet_optuna
from simulator.design._search._spec import MAX_TRIALS, SearchSpec, load_search
from simulator.sweep import ID_COLUMNS, PointTask, ResultStore

__all__ = ["best_trials", "search"]

#: Seconds between rewrites of trials.parquet / trials.csv while a search runs.
FLUSH_S = 2.0
#: Points of the search space priced before a search runs (its corners, at most).
MAX_PRICED = 64


class _TrialStore(ResultStore):
    """The rows of a search (one per trial), in memory and in a resumable directory."""

    COMMAND = "search"
    KEY = "trial"
    MANIFEST, JOURNAL, ROWS_DIR = "search.json", "trials.jsonl", "trials"
    LOCK, TABLES = ".search.lock", ("trials.parquet", "trials.csv")
    HOLD = "search-trial"

    def _other(self, doc: dict) -> str:
        objs = "; ".join(f"{o['direction']} {o['expression']}" for o in doc.get("objectives", []))
        return f"{doc.get('source', '?')}: {objs or '?'}"


# ----------------------------------------------------------------------- Optuna


def _study(spec: SearchSpec, trials: int):
    """A new in-memory study with the spec's sampler and directions (InputError when the
    sampler's package is missing)."""
    with quiet_optuna() as optuna:
        s = optuna.samplers
        if spec.sampler == "cmaes":
            try:
                import cmaes  # noqa: F401  (Optuna's CMA-ES needs it)
            except ImportError:
                raise InputError(
                    '[search] sampler = "cmaes" needs the cmaes package: pip install cmaes '
                    '(or use sampler = "tpe")'
                ) from None
            sampler = s.CmaEsSampler(seed=spec.seed, warn_independent_sampling=False)
        elif spec.sampler == "random":
            sampler = s.RandomSampler(seed=spec.seed)
        elif spec.sampler == "nsga2":
            sampler = s.NSGAIISampler(seed=spec.seed, population_size=max(4, min(50, trials // 4)))
        else:
            sampler = s.TPESampler(seed=spec.seed, constant_liar=True)
        directions: list[Any] = [o.direction for o in spec.objectives]  # "minimize" | "maximize"
        return optuna.create_study(sampler=sampler, directions=directions)


def _key(values: dict) -> str:
    return json.dumps(values, sort_keys=True, default=str)


# ----------------------------------------------------------------------- pricing
def _corners(spec: SearchSpec) -> list[dict]:
    """The search space's corners (each searched axis at its ends; names all), at most
    :data:`MAX_PRICED`, else the two opposite corners."""
    import itertools

    ends = []
    for a in spec.searched:
        if a.values is None:
            ends.append((a.lo, a.hi) if a.kind != "int" else (int(a.lo), int(a.hi)))
        elif a.kind in ("number", "int"):
            ends.append((min(a.values), max(a.values)))
        else:
            ends.append(tuple(a.values))
    names = [a.name for a in spec.searched]
    if math.prod(len(e) for e in ends) <= MAX_PRICED:
        combos = list(itertools.product(*ends))
    else:
        combos = [tuple(e[0] for e in ends), tuple(e[-1] for e in ends)]
    return [spec.fixed | dict(zip(names, c, strict=True)) for c in combos]


def _price(spec: SearchSpec) -> int | None:
    """Refuse (one line) a search one of whose trials would not fit the memory budget: the
    baseline and the corners of the space, each built and priced as a point is; a corner
    that cannot be built (a gap wider than the pattern) is a trial's error row, not a refusal.
    Returns the largest point's priced peak with a worker's imports (None: none priced), for
    the local workers to fit the budget together (:func:`simulator.sweep.worker_cap`)."""
    from simulator.sweep import point_bytes

    sw = spec.sweep
    base = spec.baseline_values()
    candidates = [base] if base is not None else []
    peak = None
    for values in candidates + _corners(spec):
        task = sw.task(sw.point(values, 0, 0))
        try:
            b = point_bytes(task)
            peak = b if peak is None else max(peak, b)
        except InputError as err:
            if "memory budget" not in str(err):
                continue
            searched = {a.name for a in spec.searched}
            at = ", ".join(
                f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}"
                for k, v in values.items()
                if k in searched
            )
            raise InputError(
                f"{spec.source}: a trial at {at or 'the baseline'} would not fit: {err}"
            ) from None
    return peak


# ----------------------------------------------------------------------- rows
def _mean_rows(rows: list[dict]) -> dict:
    """One row of several realizations' rows: a value they share, else the mean of numbers."""
    out: dict = {}
    keys = dict.fromkeys(k for r in rows for k in r)
    for k in keys:
        vals = [r[k] for r in rows if r.get(k) is not None]
        if not vals:
            continue
        if all(v == vals[0] for v in vals):
            out[k] = vals[0]
        elif all(isinstance(v, int | float | bool) for v in vals):
            out[k] = float(np.mean(vals))
        else:
            out[k] = vals[0]
    return out


def _data(flat: list[dict], columns) -> dict:
    """Column -> its values over the realizations, for the expressions (KeyError when missing)."""
    return {c: np.array([f[c] for f in flat], dtype=float) for c in columns}


class _Run:
    """One run of a search: the study, the trials in flight, the rows as trials finish."""

    def __init__(self, spec: SearchSpec, store: _TrialStore, trials: int, bar):
        from optuna.trial import TrialState, create_trial

        self.spec, self.store, self.trials, self.bar = spec, store, trials, bar
        self.R = spec.sweep.realizations
        self.dedupe = not spec.sweep.independent_noise
        self.study = _study(spec, trials)
        self.dists = spec.distributions()
        self.pending: dict[int, dict] = {}
        self.by_key: dict[str, int] = {}  # a design -> the trial that evaluates it
        self.waiting: dict[int, list] = {}  # a trial in flight -> trials that reuse it
        self.evaluated = self.reused = self.failed_now = 0
        self.best: tuple[float, int, float] | None = None  # (signed value, trial, value) of the bar
        self._state, self._create = TrialState, create_trial
        # Replay what a previous run finished: the study learns it, the designs are known.
        for i in sorted(store.rows):
            row = store.rows[i]
            values = {a.name: row[a.column] for a in spec.sweep.axes if a.column in row}
            if row.get("kind") == "search" and row.get("same_as") is None and self.dedupe:
                self.by_key.setdefault(_key(values), i)
            self._add(
                row, spec.params(values) if row.get("kind") == "search" else self._base_params()
            )
        self.free = [i for i in range(1, trials + 1) if i not in store.rows]
        self.baseline = 0 not in store.rows and spec.baseline_values() is not None

    # .................................................................. the study
    def _base_params(self) -> dict | None:
        return self.spec.params(self.spec.fixed | self.spec.baseline_settings())

    def _add(self, row: dict, params: dict | None) -> None:
        """Tell the study a finished row it did not ask for (a replayed trial, the baseline)."""
        if params is None or row.get("state") != "complete":
            return
        k = len(self.spec.objectives)
        cons = len(self.spec.constraints) if self.spec.sampler != "cmaes" else 0
        with quiet_optuna():
            self.study.add_trial(
                self._create(
                    values=[row[f"objective_{j + 1}"] for j in range(k)],
                    params=params,
                    distributions={n: self.dists[n] for n in params},
                    constraints={str(j): row[f"constraint_{j + 1}"] for j in range(cons)},
                )
            )

    def _tell(self, ot, row: dict) -> None:
        k = len(self.spec.objectives)
        with quiet_optuna():
            if row["state"] != "complete":
                self.study.tell(ot, state=self._state.FAIL)
                return
            # CMA-ES does not use constraints (and warns when given them): feasibility, and so
            # the best, is decided from the rows (best_trials) whatever the sampler.
            for j in range(len(self.spec.constraints) if self.spec.sampler != "cmaes" else 0):
                ot.set_constraint(str(j), row[f"constraint_{j + 1}"])
            self.study.tell(ot, [row[f"objective_{j + 1}"] for j in range(k)])

    @property
    def exhausted(self) -> bool:
        """Every design of a discrete space asked for (only when designs are not repeated)."""
        size = self.spec.space_size
        return self.dedupe and size is not None and len(self.by_key) >= size

    # .................................................................. tasks
    def tasks(self):
        """The points to run, decided one at a time: the baseline's, then each new trial's."""
        if self.baseline:
            base = self.spec.baseline_values()
            assert base is not None  # a baseline is run only where there is one
            self._start(0, "baseline", base, None)
            yield from self._points(0)
        for i in self.free:
            if self.exhausted:
                return
            with quiet_optuna():
                ot = self.study.ask(self.dists)
            values = self.spec.values(ot.params)
            key = _key(values)
            src = self.by_key.get(key) if self.dedupe else None
            if src is not None:
                if src in self.pending:  # in flight: told with it; no new design until a result
                    self.waiting.setdefault(src, []).append((i, ot))
                    yield None
                else:
                    self._copy(i, ot, src)
                continue
            if self.dedupe:
                self.by_key[key] = i
            self._start(i, "search", values, ot)
            yield from self._points(i)

    def _start(self, i: int, kind: str, values: dict, ot) -> None:
        self.pending[i] = {"kind": kind, "values": values, "optuna": ot, "results": {}}

    def _points(self, i: int) -> Iterator[PointTask]:
        """Trial ``i``'s points, one per realization ``r``: the sweep's point ``i * R + r``
        (so a point's trial is its index // R, :meth:`handle`)."""
        sw, values = self.spec.sweep, self.pending[i]["values"]
        for r in range(self.R):
            point = sw.point(values, i * self.R + r, r)
            self.pending[i].setdefault("points", []).append(point)
            yield sw.task(point)

    def handle(self, task: PointTask, result: dict) -> None:
        i = task.point // self.R  # the trial whose point it is (_points)
        p = self.pending[i]
        p["results"][task.realization] = result
        if len(p["results"]) == self.R:
            self._finish(i)

    # .................................................................. rows
    def _row(self, i: int, p: dict) -> tuple[dict, list]:
        from simulator.sweep import flatten

        spec = self.spec
        results = [p["results"][r] for r in range(self.R)]
        ident = {k: v for k, v in spec.sweep.columns(p["points"][0]).items() if k not in ID_COLUMNS}
        row = {"trial": i, "kind": p["kind"], **ident, "realizations": self.R}
        errors = [
            (f"realization {r}: " if self.R > 1 else "") + str(res["error"])
            for r, res in enumerate(results)
            if res["status"] != "ok"
        ]
        flat, own = [], []  # each realization's numbers; and with its own settings (seed + r)
        for pt, res in zip(p["points"], results, strict=True):
            if res["status"] == "ok":
                f = flatten(res["summary"])
                f.setdefault("volume_nl", f.get("settings_volume_nl"))
                flat.append(f)
                own.append(spec.sweep.columns(pt) | f)
        objs, cons = [], []
        if not errors:
            try:
                data = _data(own, spec.columns_used)
                objs = [o.expression(data) for o in spec.objectives]
                cons = [c.violation(data) for c in spec.constraints]
            except KeyError as err:
                errors.append(f"column {err.args[0]} is not in this trial's assessment")
            bad = [
                o.text for o, v in zip(spec.objectives, objs, strict=False) if not math.isfinite(v)
            ]
            bad += [
                c.text for c, v in zip(spec.constraints, cons, strict=False) if not math.isfinite(v)
            ]
            if bad and not errors:
                errors.append(f"{bad[0]} is not a finite number for this trial")
        seconds = sum(res["seconds"] or 0.0 for res in results)
        row |= {
            "state": "fail" if errors else "complete",
            "status": "error" if errors else "ok",
            "error": errors[0][:500] if errors else None,
            "seconds": round(seconds, 3),
            "same_as": None,
        }
        ok = not errors
        for j in range(len(spec.objectives)):
            row[f"objective_{j + 1}"] = objs[j] if ok else None
        for j in range(len(spec.constraints)):
            row[f"constraint_{j + 1}"] = cons[j] if ok else None
        row["feasible"] = bool(ok and all(v <= 0 for v in cons))
        row |= _mean_rows(flat)
        return row, results

    def _finish(self, i: int) -> None:
        p = self.pending.pop(i)
        row, results = self._row(i, p)
        doc = {
            "trial": i,
            "kind": p["kind"],
            "values": p["values"],
            "row": row,
            "realizations": [
                {"realization": pt.realization, "point_seed": pt.point_seed}
                | {k: res.get(k) for k in ("status", "error", "seconds", "summary")}
                for pt, res in zip(p["points"], results, strict=True)
            ],
        }
        self.store.record(i, row, doc)
        self.evaluated += 1
        self.failed_now += row["state"] != "complete"
        if p["optuna"] is not None:
            self._tell(p["optuna"], row)
        elif p["kind"] == "baseline":
            self._add(row, self._base_params())
        self._progress(row)
        for j, ot in self.waiting.pop(i, []):
            self._copy(j, ot, i)

    def _copy(self, j: int, ot, src: int) -> None:
        """Trial ``j`` asked for the design trial ``src`` evaluated: its row, reused."""
        row = dict(self.store.rows[src]) | {"trial": j, "seconds": 0.0, "same_as": src}
        self.store.record(j, row, {"trial": j, "kind": "search", "same_as": src, "row": row})
        self.reused += 1
        self._tell(ot, row)
        self._progress(row)

    def _progress(self, row: dict) -> None:
        """The bar one trial on, with the best feasible objective so far (one objective)."""
        self.bar.update(1)
        first = self.spec.objectives[0]  # a search has one objective at least
        if len(self.spec.objectives) > 1 or row["kind"] != "search" or not row["feasible"]:
            return
        v = row["objective_1"] * (1 if first.direction == "maximize" else -1)
        if self.best is None or v > self.best[0]:
            self.best = (v, row["trial"], row["objective_1"])
            self.bar.set_postfix_str(
                f"best {self.best[2]:.4g} (trial {self.best[1]})", refresh=False
            )


# ----------------------------------------------------------------------- the best
def best_trials(spec: SearchSpec, table) -> list[int]:
    """The best trials of a search's ``table``: among the complete, feasible search trials
    (never the baseline), the one best on the objective (the lowest trial number of a tie),
    or with several objectives the Pareto front (no other trial at least as good on every
    objective and better on one), in trial order. Empty when no trial qualifies."""
    if not len(table) or "feasible" not in table.columns:
        return []
    ok = table[
        (table["kind"] == "search")
        & (table["state"] == "complete")
        & table["feasible"].astype(bool)
    ]
    if not len(ok):
        return []
    sign = np.array([1.0 if o.direction == "minimize" else -1.0 for o in spec.objectives])
    cols = [f"objective_{j + 1}" for j in range(len(spec.objectives))]
    v = ok[cols].to_numpy(dtype=float) * sign  # to minimise
    trials = ok["trial"].to_numpy()
    if len(cols) == 1:
        order = np.lexsort((trials, v[:, 0]))
        return [int(trials[order[0]])]
    front = []
    for k in range(len(v)):
        dominated = np.any(np.all(v <= v[k], axis=1) & np.any(v < v[k], axis=1))
        if not dominated:
            front.append(int(trials[k]))
    return sorted(front)


# ----------------------------------------------------------------------- the entry
def _bar(show: bool, total: int):
    if not show:
        from foundation import NoBar

        return NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc="search", unit="trial", dynamic_ncols=True)


def search(
    spec: str | os.PathLike | dict | SearchSpec,
    out: str | os.PathLike | None = None,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    trials: int | None = None,
    quiet: bool = True,
    base: str | os.PathLike | None = None,
    pictures: bool = True,
    flush_s: float = FLUSH_S,
):
    """Run a design search and return its trial table (a pandas DataFrame, one row per trial).

    Args:
        spec: a search file (TOML: a sweep file with a ``[search]`` table, see
            :func:`load_search`) or the same structure as a dict.
        out: directory for the results (resumable: a rerun replays the trials in it and runs
            the rest); None keeps them in memory only.
        workers: local Dask worker processes (default: one per core); 0 runs every trial in
            this process, without Dask (and the same seed gives the same trials).
        scheduler: address of an existing Dask scheduler, instead of local workers.
        trials: the number of trials (default: the file's ``[search] trials``).
        quiet: no progress bar.
        base: directory of relative paths when ``spec`` is a dict.
        pictures: write the pictures, the best design and report.html into ``out`` at the end.

    Row 0 is the baseline (the file's ``[design]``), rows 1.. the trials: the axis values,
    ``state`` ("complete" or "fail"), ``error``, ``seconds``, ``same_as``, the objectives
    ``objective_1``..., the constraints' violations ``constraint_1``... (<= 0: met),
    ``feasible``, ``best`` and every column of the assessment (the mean over the
    realizations). ``table.attrs["search"]`` holds the hash, the counts, the best trials
    and the times.
    """
    from foundation import budget_bytes
    from simulator.sweep import check_where, run_tasks, start_workers

    spec = spec if isinstance(spec, SearchSpec) else load_search(spec, base)
    n = spec.trials if trials is None else trials
    require(
        isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_TRIALS,
        f"--trials must be a whole number from 1 to {MAX_TRIALS:,}, got {n!r}",
    )
    check_where(workers, scheduler)
    _study(spec, n)  # the sampler's package, before any work
    peak = _price(spec)
    sw = spec.sweep
    inputs = [Path(p) for p in sw.files] + (
        [Path(spec.source)] if Path(spec.source).is_file() else []
    )
    store = _TrialStore(out, spec.digest, spec.describe(), inputs=inputs, flush_s=flush_s)
    t0 = time.perf_counter()
    run = None
    try:
        from foundation import NoBar

        run = _Run(spec, store, n, NoBar())
        todo = (0 if run.exhausted else len(run.free)) + run.baseline
        points = todo * sw.realizations
        with contextlib.ExitStack() as stack:
            budget = budget_bytes(sw.scene.get("memory_budget_mb"))
            client, t_cluster, where = start_workers(
                stack, workers, scheduler, points, lambda: (peak, budget)
            )
            store.open()  # only now: a scheduler that cannot be reached leaves no directory
            if todo and not quiet:
                print(
                    f"search {spec.digest[:12]}: {n} trials ({spec.sampler}) over "
                    f"{', '.join(a.name for a in spec.searched)}, {len(store.rows)} done before; "
                    f"running on {where}",
                    file=sys.stderr,
                    flush=True,
                )
            run.bar = stack.enter_context(_bar(not quiet and todo > 0, todo))
            if todo:
                stats = run_tasks(client, run.tasks(), run.handle, per_thread=1)
                if getattr(run.bar, "total", None) and run.bar.n < run.bar.total:
                    run.bar.total = run.bar.n  # the space ran out of new designs first
                    run.bar.refresh()
            else:
                stats = {"run_s": 0.0, "workers": 0, "threads": 0}
            stats["cluster_s"] = t_cluster
    finally:
        if store.out is not None and store._journal is not None:
            with contextlib.suppress(Exception):
                store.write_tables()
        store.close()
    table = store.table()
    best = best_trials(spec, table)
    if len(table):
        table["best"] = table["trial"].isin(best)
    stats |= {
        "hash": spec.digest,
        "trials": n,
        "done": int(np.count_nonzero(table["kind"] == "search")) if len(table) else 0,
        "baseline": bool(len(table) and (table["trial"] == 0).any()),
        "evaluated_now": run.evaluated if run else 0,
        "reused_now": run.reused if run else 0,
        "failed": int(np.count_nonzero(table["state"] != "complete")) if len(table) else 0,
        "failed_now": run.failed_now if run else 0,
        "exhausted": bool(run and run.exhausted),
        "space_size": spec.space_size,
        "best": best,
        "seconds": time.perf_counter() - t0,
    }
    if store.out is not None:
        store.write_tables(table)
        if pictures:
            from simulator.design._search._report import write_search_report

            write_search_report(store.out, spec, table, stats)
        store.write_marker()
    table.attrs["search"] = stats
    return table
