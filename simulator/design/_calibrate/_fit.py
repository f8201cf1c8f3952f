"""``selfalign calibrate``: the scene's parameters fitted to a bench table of yields and times.

:func:`calibrate` fits the names of ``fit`` (:data:`FITTABLE`) to a bench table
(:func:`read_trials`): per row a nominal start, how many of its trials aligned and
optionally the median time to align. Each candidate runs a Monte Carlo batch
(:func:`simulator.batch.run_batch`) of ``draws`` placements per row, the nominal start plus
the row's placement noise times standard-normal draws that are the SAME for every candidate
(common random numbers, drawn once from ``seed``), so the objective changes with the
parameters and not with the draws.

The objective is a log-likelihood (docs/guide/calibrate.md):

* per row, beta-binomial: the probability of the bench's a aligned of its N trials when
  the model's yield p is known only from k of its ``draws`` placements aligned, p's
  distribution the Beta(k + 1/2, draws - k + 1/2) that k gives (Jeffreys' prior):
  ``log C(N, a) + log B(a + k + 1/2, N - a + draws - k + 1/2) - log B(k + 1/2, draws - k +
  1/2)``. A binomial with p = k / draws would take the model's Monte Carlo estimate as
  exact: a candidate whose draws happen to match the bench's counts would stand out by
  luck, and the ranges would shrink around it;
* per row with ``time_s``: a Gaussian on log time, ``-1/2 ((ln t_bench - ln t_model) /
  s)^2 - ln(s sqrt(2 pi))``, t_model the median time to align of the model's aligned
  placements and s = ``time_sigma`` (default 0.1: a 10 % scatter of the median); a model
  none of whose placements aligned counts as 5 s away.

Optuna's TPE sampler (seeded) proposes the candidates; trial 0 is the scene as given (the
baseline). After the search, each parameter's likelihood is profiled (:func:`_profile`): at
``profile`` values across its bounds, the best log-likelihood over the other parameters (a
short pattern search from the neighbouring value's best, along the valley two parameters
that trade against each other make). The run is priced before it starts (the landscape and the dynamics' lanes against
the memory budget) and is resumable from ``out`` as the design search is
(:class:`simulator.sweep.ResultStore`: ``calibrate.json`` holds the fit's hash, ``trials.jsonl``
the journal); a directory holding a different table, scene or fit is refused. The range of a
parameter is the span of the evaluated trials (search and profile) within 1/2 of the best
log-likelihood (a 1-sigma profile, not a fitted curvature), widened on each side to the
nearest evaluated trial outside it (or the bound): an outer bound of that set. A range over
most of the bounds says that the table does not tell that parameter (``identified`` false).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from foundation import InputError, require
from simulator.core import DYNAMIC_METHODS, METHODS
from simulator.design._calibrate._params import (
    FITTABLE,
    default_bounds,
    parse_bounds,
    parse_fit,
    prepared_document,
    scene_value,
    scene_with,
)
from simulator.design._calibrate._table import BenchTable, read_trials
from simulator.design._optuna import quiet_optuna
from simulator.sweep import ResultStore

__all__ = [
    "DRAWS",
    "PROFILE",
    "TIME_SIGMA",
    "TRIALS",
    "calibrate",
    "log_likelihood",
    "synthetic_trials",
]

#: Monte Carlo placements per row and candidate (the same draws for every candidate).
DRAWS = 32
#: Optuna trials of a fit (enough for two parameters, docs/guide/calibrate.md).
TRIALS = 40
MAX_TRIALS = 10_000
MAX_DRAWS = 4096
#: The width of the log-time term (natural log: a 10 % scatter of the median time).
TIME_SIGMA = 0.1
#: How far (in widths) a model with no aligned placement is from a bench time.
NO_TIME_PENALTY = 5.0
#: The log-likelihood drop that bounds a parameter's range (1 sigma for one parameter).
DELTA_LOG_L = 0.5
#: Points of each parameter's likelihood profile (:func:`_profile`; 0: none).
PROFILE = 6
#: The profile's trials are numbered from here (the search's from 1 to MAX_TRIALS).
PROFILE_BASE = 1_000_000


class _FitStore(ResultStore):
    """The trials of a calibration, in memory and in a resumable directory."""

    COMMAND = "calibrate"
    KEY = "trial"
    MANIFEST, JOURNAL, ROWS_DIR = "calibrate.json", "trials.jsonl", "trials"
    LOCK, TABLES = ".calibrate.lock", ("trials.parquet", "trials.csv")
    HOLD = "calibrate-trial"
    details: dict[int, dict]  # made by record (an instance attribute, absent before it)

    def _other(self, doc: dict) -> str:
        return f"{doc.get('source', '?')}, fitting {', '.join(doc.get('fit', [])) or '?'}"

    def record(self, i: int, row: dict, doc: dict) -> dict:
        """As the sweep's, and the trial's per-row numbers kept in memory too."""
        self.__dict__.setdefault("details", {})[i] = doc
        return super().record(i, row, doc)


# ----------------------------------------------------------------------- the model
def _log_binom(n: np.ndarray, k: np.ndarray) -> np.ndarray:
    from math import lgamma

    return np.array(
        [lgamma(a + 1) - lgamma(b + 1) - lgamma(a - b + 1) for a, b in zip(n, k, strict=True)]
    )


def log_likelihood(
    table: BenchTable,
    model_aligned: np.ndarray,
    model_time: np.ndarray,
    draws: int,
    time_sigma: float,
) -> tuple[float, float, np.ndarray]:
    """(yield term, time term, per-row total) of the log-likelihood (module docstring)."""
    from scipy.special import betaln

    n, a = table.trials.astype(float), table.aligned.astype(float)
    alpha = np.asarray(model_aligned, float) + 0.5
    beta = draws - np.asarray(model_aligned, float) + 0.5
    ly = (
        _log_binom(table.trials, table.aligned)
        + betaln(a + alpha, n - a + beta)
        - betaln(alpha, beta)
    )
    lt = np.zeros(table.n)
    has = np.isfinite(table.time_s)
    norm = -math.log(time_sigma * math.sqrt(2 * math.pi))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (np.log(table.time_s) - np.log(model_time)) / time_sigma
    r = np.where(np.isfinite(r), r, NO_TIME_PENALTY)
    lt[has] = -0.5 * r[has] ** 2 + norm
    return float(ly.sum()), float(lt.sum()), ly + lt


class _Model:
    """The Monte Carlo model of the bench: the scene, the common draws, the landscape cache."""

    def __init__(
        self, scene, table: BenchTable, sigma: np.ndarray, draws: int, seed: int, method: str
    ):
        self.scene, self.table, self.draws, self.method = scene, table, draws, method
        z = np.random.default_rng(seed).standard_normal((table.n, draws, 3))
        self.starts = (table.start[:, None, :] + z * sigma[:, None, :]).reshape(-1, 3)
        self._ls_key = None
        self._ls = None

    def _landscape(self, scene):
        """The landscape of ``scene``: rebuilt only when what it depends on changed (the pad's
        angle, the volume with a meniscus); None for a footprint-state scene (the batch builds
        its pads' planes)."""
        from simulator.landscape import build_landscape

        if scene.dispense is not None:
            return None
        key = (
            scene.materials.pad_angle_deg,
            scene.meniscus_height_um if scene.effects.meniscus else None,
        )
        if key != self._ls_key:
            self._ls, self._ls_key = None, None
            self._ls = build_landscape(scene, progress=False)
            self._ls_key = key
        return self._ls

    def run(self, values: dict) -> tuple[np.ndarray, np.ndarray]:
        """Per row: the model's aligned count of its draws and the median time to align (s;
        NaN where none aligned or the method has no time)."""
        from simulator.batch import run_batch

        scene = scene_with(self.scene, values)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = run_batch(
                scene, self.starts, self.method, landscape=self._landscape(scene), progress=False
            )
        ok = (np.asarray(r.outcome) == 0).reshape(self.table.n, self.draws)
        times = np.full(self.table.n, np.nan)
        if r.time_s is not None:
            t = np.asarray(r.time_to_align_s).reshape(self.table.n, self.draws)
            for i in range(self.table.n):
                if ok[i].any():
                    times[i] = float(np.median(t[i][ok[i]]))
        return ok.sum(axis=1).astype(np.int64), times


# ----------------------------------------------------------------------- Optuna


def _scene_document(scene, base, name: str | None = None) -> tuple[dict, Path, str]:
    """(document, base directory, source) of a scene given as a TOML path or a dict
    (``name``: what the dict came from, for the record)."""
    if isinstance(scene, dict):
        return scene, Path(base or "."), name or "scene (dict)"
    from simulator.scene import read_scene_file

    p = Path(scene)
    return read_scene_file(p), p.parent, str(p)


def _absolute(doc: dict, base: Path) -> dict:
    """The document with its pattern and chip files as absolute paths (a scene file
    written elsewhere, fitted.toml, reads them)."""
    doc = dict(doc)
    for key in ("pattern", "chip"):
        if isinstance(doc.get(key), str):
            doc[key] = str((base / doc[key]).resolve())
    return doc


def _file_digest(doc: dict) -> str:
    h = hashlib.sha256()
    for key in ("pattern", "chip"):
        if isinstance(doc.get(key), str) and Path(doc[key]).is_file():
            h.update(Path(doc[key]).read_bytes())
    return h.hexdigest()


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def calibrate(
    table: str | os.PathLike | BenchTable,
    scene: str | os.PathLike | dict,
    fit: str | list[str] | tuple[str, ...],
    out: str | os.PathLike | None = None,
    *,
    bounds: dict | list[str] | None = None,
    trials: int | None = None,
    draws: int = DRAWS,
    spread: tuple[float, float, float] | None = None,
    seed: int = 0,
    method: str | None = None,
    time_sigma: float = TIME_SIGMA,
    quiet: bool = True,
    base: str | os.PathLike | None = None,
    pictures: bool = True,
    profile: int = PROFILE,
    scene_name: str | None = None,
) -> dict:
    """Fit the scene's parameters ``fit`` to a bench table; return the fit (``fit.json``'s dict).

    Args:
        table: the bench table (a CSV path, :func:`read_trials`).
        scene: the scene: a TOML scene file or its document as a dict (relative paths
            against ``base``).
        fit: the names to fit (:data:`FITTABLE`), a list or ``"NAME,NAME"``.
        out: the results directory (resumable; None: in memory only, nothing written).
        bounds: NAME -> (LO, HI), or ``"NAME=LO:HI"`` strings; default per name (:data:`FITTABLE`).
        trials: Optuna's budget (default :data:`TRIALS`); trial 0, the scene as given, besides.
        draws: Monte Carlo placements per row and candidate.
        spread: placement noise (um, um, degrees; standard deviations) of the rows that give none.
        seed: seeds the common draws and the TPE sampler.
        method: the stepper (default: overdamped when the table gives times, else greedy).
        time_sigma: the width of the log-time term.
        quiet: no progress lines on stderr.
        pictures: with ``out``, write report.html and bench.png.
        profile: points of each parameter's likelihood profile after the search (0: none).
        scene_name: what a scene given as a dict came from (the command line: its scene
            file, which flags may override), as the record names it.

    Returns:
        ``best`` (NAME -> value), ``range`` (NAME -> [lo, hi] within Delta log L = 1/2),
        ``rows`` (bench against model per row), ``log_likelihood`` and the run's record.
    """
    t_start = time.perf_counter()
    tab = table if isinstance(table, BenchTable) else read_trials(table)
    names = parse_fit(fit)
    given = parse_bounds(bounds or {})
    extra = sorted(set(given) - set(names))
    require(
        not extra,
        f"--bounds {extra[0] if extra else ''}: not among the fitted names ({', '.join(names)}); add it to --fit or drop its bounds",
    )
    n = TRIALS if trials is None else trials
    require(
        isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_TRIALS,
        f"--trials must be a whole number from 1 to {MAX_TRIALS:,}, got {n!r}",
    )
    require(
        isinstance(draws, int) and not isinstance(draws, bool) and 1 <= draws <= MAX_DRAWS,
        f"--draws must be a whole number from 1 to {MAX_DRAWS:,}, got {draws!r}",
    )
    require(
        isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0,
        f"--seed must be a whole number >= 0, got {seed!r}",
    )
    require(
        isinstance(time_sigma, int | float) and math.isfinite(time_sigma) and time_sigma > 0,
        f"--time-sigma must be a finite number > 0 (natural log of time), got {time_sigma!r}",
    )
    require(
        isinstance(profile, int) and not isinstance(profile, bool) and 0 <= profile <= 100,
        f"--profile must be a whole number from 0 to 100, got {profile!r}",
    )
    method = method or ("overdamped" if tab.has_times else "greedy")
    require(method in METHODS, f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    if tab.has_times and method not in DYNAMIC_METHODS:
        raise InputError(
            f"{tab.source}: the table gives time_s, which only the dynamics have: use --method overdamped "
            f"or inertial (not {method}), or drop the time_s column"
        )
    if "damping" in names and method not in DYNAMIC_METHODS:
        raise InputError(
            "--fit damping: the damping sets only the times of the dynamics; give --method overdamped "
            "(and the bench's time_s) or fit something else"
        )
    sigma = tab.with_spread(spread)

    raw, base_dir, source = _scene_document(scene, base, scene_name)
    doc = prepared_document(_absolute(raw, base_dir), names)
    from simulator.scene import Scene

    scene0 = Scene.from_dict(doc, base=base_dir)
    bnd = {k: given.get(k, default_bounds(k, scene0)) for k in names}
    for k in names:
        f = FITTABLE[k]
        if f.log and bnd[k][0] <= 0:
            raise InputError(f"--bounds {k}: must be > 0 ({f.unit})")

    # ------------------------------------------------------------------ priced first
    from simulator.landscape import require_landscape_fits

    corners = [{}] + [
        {k: bnd[k][j] for k in names if k in ("volume_nl", "pad_angle_deg")} for j in (0, 1)
    ]
    for c in corners:
        try:
            s = scene_with(scene0, c)
        except InputError:
            continue
        require_landscape_fits(s)
    lanes = tab.n * draws
    if method in DYNAMIC_METHODS:
        from simulator.batch import price_dynamics_lanes
        from simulator.core import DEFAULT_DYNAMICS_CHUNK, threads

        chunk = min(DEFAULT_DYNAMICS_CHUNK, lanes)
        price_dynamics_lanes(
            chunk * max(1, min(threads(), -(-lanes // chunk))), scene0.memory_budget_mb
        )

    describe = {
        "source": tab.source,
        "scene": source,
        "fit": list(names),
        "bounds": {k: list(v) for k, v in bnd.items()},
        "draws": draws,
        "seed": seed,
        "method": method,
        "time_sigma": time_sigma,
    }
    digest = hashlib.sha256(
        json.dumps(
            describe
            | {
                "table": tab.digest,
                "sigma": sigma.tolist(),
                "doc": doc,
                "files": _file_digest(doc),
            },
            sort_keys=True,
            default=str,
        ).encode()
    ).hexdigest()
    inputs = [Path(tab.source)] + ([Path(source)] if Path(source).is_file() else [])
    store = _FitStore(out, digest, describe, inputs=inputs)
    model = _Model(scene0, tab, sigma, draws, seed, method)

    def evaluate(values: dict) -> tuple[dict, dict]:
        t0 = time.perf_counter()
        try:
            k, tm = model.run(values)
        except InputError as err:
            row = {"state": "fail", "error": str(err)[:300], "log_likelihood": None}
            return row, {}
        ly, lt, per_row = log_likelihood(tab, k, tm, draws, time_sigma)
        row = {
            "state": "complete",
            "error": None,
            "log_likelihood": ly + lt,
            "log_likelihood_yield": ly,
            "log_likelihood_time": lt,
        }
        detail = {
            "model_aligned": k.tolist(),
            "model_time_s": [None if not math.isfinite(v) else v for v in tm.tolist()],
            "log_likelihood_rows": per_row.tolist(),
        }
        row["seconds"] = round(time.perf_counter() - t0, 3)
        return row, detail

    baseline_values = {k: scene_value(k, scene0) for k in names}
    t_run = time.perf_counter()
    try:
        if 0 not in store.rows:  # the scene as given: run before anything is written
            row0, det0 = evaluate(baseline_values)
            if row0["state"] != "complete":
                raise InputError(f"the scene as given cannot run: {row0['error']}")
        store.open()
        if 0 not in store.rows:
            r = {"trial": 0, "kind": "baseline", **baseline_values, **row0}
            store.record(0, r, {"trial": 0, "row": r, **det0})
        with quiet_optuna() as optuna:
            from optuna.distributions import BaseDistribution, FloatDistribution
            from optuna.trial import create_trial

            dists: dict[str, BaseDistribution] = {
                k: FloatDistribution(bnd[k][0], bnd[k][1], log=FITTABLE[k].log) for k in names
            }
            sampler = optuna.samplers.TPESampler(
                seed=seed, n_startup_trials=max(4, min(10, n // 4))
            )
            study = optuna.create_study(sampler=sampler, direction="maximize")
            for i in sorted(store.rows):  # replay: the study learns what was evaluated
                row = store.rows[i]
                params = {k: row[k] for k in names}
                if row.get("state") != "complete" or not all(
                    bnd[k][0] <= params[k] <= bnd[k][1] for k in names
                ):
                    continue
                study.add_trial(
                    create_trial(value=row["log_likelihood"], params=params, distributions=dists)
                )
            done_before = sum(1 for i in store.rows if 0 < i < PROFILE_BASE)
            if not quiet and done_before < n:
                print(
                    f"calibrate {digest[:12]}: {n} trials (TPE, seed {seed}) over {', '.join(names)}; "
                    f"{tab.n} rows x {draws} draws ({method}); {done_before} done before",
                    file=sys.stderr,
                    flush=True,
                )
            best = max(
                (r for r in store.rows.values() if r.get("state") == "complete"),
                key=lambda r: r["log_likelihood"],
                default=None,
            )
            for i in range(1, n + 1):
                if i in store.rows:
                    continue
                ot = study.ask(dists)
                values = {k: float(ot.params[k]) for k in names}
                row, det = evaluate(values)
                r = {"trial": i, "kind": "search", **values, **row}
                store.record(i, r, {"trial": i, "row": r, **det})
                if row["state"] == "complete":
                    study.tell(ot, row["log_likelihood"])
                    if best is None or row["log_likelihood"] > best["log_likelihood"]:
                        best = r
                else:  # outside the model's domain (receding > advancing, ...): told as far worse
                    worst = min(
                        (
                            r["log_likelihood"]
                            for r in store.rows.values()
                            if r.get("state") == "complete"
                        ),
                        default=0.0,
                    )
                    study.tell(ot, worst - 1000.0)
                if not quiet:
                    got = (
                        f"log L = {row['log_likelihood']:.2f}"
                        if row["state"] == "complete"
                        else f"failed ({row['error']})"
                    )
                    b = (
                        f"best {best['log_likelihood']:.2f} (trial {best['trial']})"
                        if best
                        else "no best yet"
                    )
                    print(
                        f"calibrate trial {i}/{n}: "
                        + ", ".join(f"{k} = {_fmt(v)}" for k, v in values.items())
                        + f": {got}; {b}; {row.get('seconds', 0):.1f} s",
                        file=sys.stderr,
                        flush=True,
                    )
        if profile:
            _profile(store, names, bnd, profile, evaluate, quiet)
    finally:
        if store.out is not None and store._journal is not None:
            with contextlib.suppress(Exception):
                store.write_tables()
        store.close()
    run_s = time.perf_counter() - t_run
    result = _result(store, tab, names, bnd, describe, digest, draws, sigma, n)
    result["seconds"] = round(time.perf_counter() - t_start, 3)
    result["run_s"] = round(run_s, 3)
    if store.out is not None:
        from simulator.design._calibrate._report import write_outputs

        write_outputs(store.out, result, doc, pictures=pictures)
        store.write_tables()
        store.write_marker()
    return result


#: A range over at least this share of a parameter's bounds (log scale where the name is) is
#: "not identified".
IDENTIFIED_SHARE = 0.6


def _scaled(k: str, v: float, bnd: dict) -> float:
    """``v`` as a share of the bounds of ``k`` (on a log scale where :data:`FITTABLE` says)."""
    lo, hi = bnd[k]
    if FITTABLE[k].log:
        return math.log(v / lo) / math.log(hi / lo)
    return (v - lo) / (hi - lo)


def _unscaled(k: str, u: float, bnd: dict) -> float:
    lo, hi = bnd[k]
    if FITTABLE[k].log:
        return lo * (hi / lo) ** u
    return lo + u * (hi - lo)


def _profile(store: _FitStore, names, bnd: dict, points: int, evaluate, quiet: bool) -> None:
    """Each parameter's likelihood profile: at ``points`` values of it (the middles of equal
    shares of its bounds), the best log-likelihood over the other parameters, found by a
    short pattern search (steps of 1/8, then 1/16 and 1/32 of their bounds, each way) that
    starts from the best of the neighbouring value on the way out from the best trial: it
    follows a valley along which two parameters trade. One parameter: its likelihood at
    those values. Every point is a trial of the store (numbered from :data:`PROFILE_BASE`,
    kind ``profile``), so a resumed fit finds them again instead of running them twice."""
    seen: dict[tuple, float] = {}

    def key(values: dict) -> tuple:
        return tuple(round(_scaled(k, values[k], bnd), 9) for k in names)

    for r in store.rows.values():
        if r.get("state") == "complete":
            seen.setdefault(key(r), r["log_likelihood"])
        elif all(k in r for k in names):
            seen.setdefault(key(r), -math.inf)
    done = [max((i for i in store.rows if i >= PROFILE_BASE), default=PROFILE_BASE - 1)]
    total = points * len(names)

    def at(values: dict, label: str) -> float:
        kk = key(values)
        if kk in seen:
            return seen[kk]
        row, det = evaluate(values)
        done[0] += 1
        i = done[0]
        r = {"trial": i, "kind": "profile", **values, **row}
        store.record(i, r, {"trial": i, "row": r, **det})
        seen[kk] = row["log_likelihood"] if row["state"] == "complete" else -math.inf
        if not quiet:
            print(
                f"calibrate profile {label}: "
                + ", ".join(f"{k} = {_fmt(v)}" for k, v in values.items())
                + (
                    f": log L = {row['log_likelihood']:.2f}"
                    if row["state"] == "complete"
                    else f": failed ({row['error']})"
                ),
                file=sys.stderr,
                flush=True,
            )
        return seen[kk]

    ok = [r for r in store.rows.values() if r.get("state") == "complete"]
    if not ok:
        return
    best = max(ok, key=lambda r: (r["log_likelihood"], -r["trial"]))
    grid = [(j + 0.5) / points for j in range(points)]
    n = 0
    for k in names:
        others = [o for o in names if o != k]
        u0 = _scaled(k, best[k], bnd)
        up = [u for u in grid if u >= u0]
        down = [u for u in reversed(grid) if u < u0]
        for side in (up, down):
            cur = {o: _scaled(o, best[o], bnd) for o in others}
            for u in side:
                n += 1
                label = f"{n}/{total} ({k})"

                def value(c: dict, u=u, k=k, others=others, label=label) -> float:
                    return at(
                        {k: _unscaled(k, u, bnd)} | {o: _unscaled(o, c[o], bnd) for o in others},
                        label,
                    )

                here = value(cur)
                for step in (1 / 8, 1 / 16, 1 / 32):
                    for o in others:
                        for sgn in (1, -1):
                            c = dict(cur)
                            c[o] = min(1.0, max(0.0, cur[o] + sgn * step))
                            if c[o] == cur[o]:
                                continue
                            v = value(c)
                            if v > here:
                                here, cur = v, c
                                break


def _detail(store: _FitStore, i: int) -> dict:
    if i in store.__dict__.get("details", {}):
        return store.details[i]
    if store.out is None:
        return {}
    try:
        return json.loads((store.out / store.ROWS_DIR / f"{i:05d}.json").read_text())
    except (OSError, ValueError):
        return {}


def _result(store, tab: BenchTable, names, bnd, describe, digest, draws, sigma, n) -> dict:
    rows = [store.rows[i] for i in sorted(store.rows)]
    ok = [r for r in rows if r.get("state") == "complete"]
    require(bool(ok), "no trial of the fit completed; see the trials' errors in trials.csv")
    best = max(ok, key=lambda r: (r["log_likelihood"], -r["trial"]))
    near = [r for r in ok if r["log_likelihood"] >= best["log_likelihood"] - DELTA_LOG_L]
    rng = {}
    far = [r for r in ok if r["log_likelihood"] < best["log_likelihood"] - DELTA_LOG_L]
    for k in names:
        lo, hi = min(r[k] for r in near), max(r[k] for r in near)
        # bracketed by the nearest evaluated trials outside the set (else the bounds): an
        # outer bound of the 1-sigma set, which few trials near the best would understate
        lo = max((r[k] for r in far if r[k] < lo), default=bnd[k][0])
        hi = min((r[k] for r in far if r[k] > hi), default=bnd[k][1])
        span = bnd[k][1] - bnd[k][0]
        rng[k] = {
            "lo": lo,
            "hi": hi,
            "at_lower_bound": bool(lo - bnd[k][0] <= 0.02 * span),
            "at_upper_bound": bool(bnd[k][1] - hi <= 0.02 * span),
            # over most of its bounds: the table does not tell this parameter (alone)
            "identified": bool(_scaled(k, hi, bnd) - _scaled(k, lo, bnd) < IDENTIFIED_SHARE),
        }
    det = _detail(store, best["trial"])
    base = store.rows.get(0)
    base_det = _detail(store, 0) if base else {}
    per_row = []
    for j in range(tab.n):
        t = tab.time_s[j]
        per_row.append(
            {
                "row": int(tab.line[j]),
                "x_um": float(tab.start[j, 0]),
                "y_um": float(tab.start[j, 1]),
                "twist_deg": float(tab.start[j, 2]),
                "sigma_um_um_deg": [float(v) for v in sigma[j]],
                "trials": int(tab.trials[j]),
                "aligned": int(tab.aligned[j]),
                "bench_yield": float(tab.aligned[j] / tab.trials[j]),
                "model_yield": det["model_aligned"][j] / draws if det else None,
                "model_aligned_of_draws": det["model_aligned"][j] if det else None,
                "baseline_yield": base_det["model_aligned"][j] / draws if base_det else None,
                "bench_time_s": float(t) if math.isfinite(t) else None,
                "model_time_s": det["model_time_s"][j] if det else None,
                "baseline_time_s": base_det["model_time_s"][j] if base_det else None,
                "log_likelihood": det["log_likelihood_rows"][j] if det else None,
            }
        )
    units = {k: FITTABLE[k].unit for k in names}
    return {
        "tool": "selfalign",
        "command": "calibrate",
        "hash": digest,
        **describe,
        "units": units,
        "best": {k: best[k] for k in names},
        "best_trial": best["trial"],
        "log_likelihood": best["log_likelihood"],
        "log_likelihood_yield": best["log_likelihood_yield"],
        "log_likelihood_time": best["log_likelihood_time"],
        "baseline": ({k: base[k] for k in names} | {"log_likelihood": base.get("log_likelihood")})
        if base
        else None,
        "range": rng,
        "range_means": (
            f"the span of the evaluated trials whose log-likelihood is within {DELTA_LOG_L} of the best "
            "(search and profile: a 1-sigma profile likelihood), widened to the nearest evaluated trial outside "
            "it on each side (or the bound): an outer bound; at_*_bound: the range reaches a bound; "
            f"identified false: the range covers {IDENTIFIED_SHARE:.0%} or more of the bounds, the table does not "
            "tell this parameter (another fitted one trades against it, or the yields do not depend on it)"
        ),
        "trials": n,
        "done": sum(1 for r in rows if 0 < r["trial"] < PROFILE_BASE),
        "profiled": sum(1 for r in rows if r["trial"] >= PROFILE_BASE),
        "failed": sum(1 for r in rows if r.get("state") != "complete"),
        "trials_in_range": len(near),
        "rows": per_row,
    }


def synthetic_trials(
    scene: str | os.PathLike | dict,
    starts,
    values: dict[str, float],
    *,
    trials: int = 100,
    spread: tuple[float, float, float] = (20.0, 20.0, 2.0),
    seed: int = 1,
    method: str = "greedy",
    base: str | os.PathLike | None = None,
) -> list[dict]:
    """Bench rows the model itself generates: for each nominal start of ``starts`` ((R, 3)
    um, um, degrees), ``trials`` placements with normal noise ``spread`` drawn from ``seed``,
    run on the scene with ``values`` (:data:`FITTABLE` names); the rows' ``aligned`` counts
    (and, for the dynamics, ``time_s``: the median time to align), for :func:`write_trials`.
    A test of :func:`calibrate` fits them back (with another seed for its own draws)."""
    from simulator.scene import Scene

    raw, base_dir, _ = _scene_document(scene, base)
    doc = prepared_document(_absolute(raw, base_dir), tuple(values))
    s = Scene.from_dict(doc, base=base_dir)
    start = np.asarray(starts, dtype=float).reshape(-1, 3)
    r = len(start)
    sig = np.tile(np.asarray(spread, dtype=float), (r, 1))
    tab = BenchTable(
        "synthetic",
        start,
        np.full(r, trials),
        np.zeros(r, np.int64),
        np.full(r, np.nan),
        sig,
        tuple(range(2, r + 2)),
    )
    k, t = _Model(s, tab, sig, trials, seed, method).run(values)
    rows = []
    for j in range(r):
        row = {
            "x_um": float(start[j, 0]),
            "y_um": float(start[j, 1]),
            "twist_deg": float(start[j, 2]),
            "trials": int(trials),
            "aligned": int(k[j]),
            "sigma_x_um": float(spread[0]),
            "sigma_y_um": float(spread[1]),
            "sigma_twist_deg": float(spread[2]),
        }
        if method in DYNAMIC_METHODS and math.isfinite(t[j]):
            row["time_s"] = float(t[j])
        rows.append(row)
    return rows
