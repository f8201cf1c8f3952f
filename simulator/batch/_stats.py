"""The result of a Monte Carlo batch, and the statistics read off it.

Owns :class:`BatchResult` (per-start requested and final poses, outcomes, steps,
energies, for the dynamics the simulated time of each run, the optimum "aligned" is
measured from) and what the commands report from one: twist errors modulo the symmetry
period (:func:`twist_error`), error statistics (:func:`error_stats`), outcome counts
(:func:`outcome_counts`), the distribution of the time to align (:func:`time_stats`,
:func:`time_histogram`), the capture map of a start grid (:func:`capture_map`), the
largest bias that still aligns (:func:`max_bias`) and the JSON-ready summary
(:func:`summarize`). Conventions as in
:mod:`simulator.batch`, which runs the batches and re-exports every name here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from foundation import require
from simulator.batch._starts import StartGrid
from simulator.core import OUTCOMES


@dataclass(frozen=True)
class BatchResult:
    """Per-start results of a batch, in the order of the starts.

    start: (N, 3) requested poses (x_um, y_um, twist_deg).
    final: (N, 3) final poses (twist unwrapped: as the chip turned).
    outcome: (N,) int8 index into :data:`simulator.core.OUTCOMES`.
    steps: (N,) int32 moves (greedy) or accepted steps (gradient).
    energy_J: (N,) final energy.
    period_deg: the chip's rotational symmetry period (twist errors are modulo it).
    optimum: (x_um, y_um, twist_deg) of the landscape's global minimum ("aligned").
    time_s: (N,) simulated time (s) at the end of each run, for the dynamic methods
        (overdamped, inertial); None for greedy and gradient, which have no time.
    """

    method: str
    start: np.ndarray
    final: np.ndarray
    outcome: np.ndarray
    steps: np.ndarray
    energy_J: np.ndarray
    period_deg: float
    optimum: tuple[float, float, float]
    stats: dict = field(default_factory=dict)
    time_s: np.ndarray | None = None
    #: What limits the final poses' errors (:func:`simulator.motion.error_limit`):
    #: ``{"by": "grid" | "floor", "um": ...}`` (a batch does not refine below the grid).
    error_limit: dict | None = None

    @property
    def n(self) -> int:
        return len(self.outcome)

    @property
    def time_to_align_s(self) -> np.ndarray | None:
        """(N,) time to align, s: the simulated time at which an aligned run came to rest
        (the solver's stop test: force and kinetic energy below the landscape's noise
        floor, or on the floor a chip floats on), NaN for the starts that did not align;
        None for the steppers."""
        if self.time_s is None:
            return None
        return np.where(self.outcome == OUTCOMES.index("aligned"), self.time_s, np.nan)

    def outcome_names(self) -> np.ndarray:
        return np.asarray(OUTCOMES)[self.outcome]


# --------------------------------------------------------------------- statistics
def twist_error(twist_deg, period_deg: float) -> np.ndarray:
    """Twist relative to 0 modulo the symmetry period, in [-period/2, period/2) degrees."""
    p = float(period_deg)
    return np.mod(np.asarray(twist_deg, float) + p / 2, p) - p / 2


def _stats(v: np.ndarray) -> dict | None:
    """mean, mean |v|, standard deviation (population, ddof 0) and max |v|; None if empty."""
    if v.size == 0:
        return None
    a = np.abs(v)
    return {
        "mean": float(v.mean()),
        "mean_abs": float(a.mean()),
        "std": float(v.std()),
        "max_abs": float(a.max()),
    }


#: Percentiles of the time to align that the summaries report (median and 90th).
TIME_PERCENTILES = (50, 90)


def time_stats(times_s) -> dict | None:
    """Distribution of the times to align (s) of the starts that aligned (NaN entries are
    the others): ``n``, ``median``, ``p90`` (90th percentile, numpy's linear
    interpolation), ``mean``, ``min``, ``max``; None when none aligned."""
    t = np.asarray(times_s, float)
    t = t[np.isfinite(t)]
    if t.size == 0:
        return None
    med, p90 = np.percentile(t, TIME_PERCENTILES)
    return {
        "n": int(t.size),
        "median": float(med),
        "p90": float(p90),
        "mean": float(t.mean()),
        "min": float(t.min()),
        "max": float(t.max()),
    }


def time_histogram(times_s, bins: int = 20) -> dict | None:
    """Histogram of the times to align (s) of the aligned starts: ``edges_s`` (bins + 1
    edges from 0 to the largest time) and ``counts``; None when none aligned."""
    t = np.asarray(times_s, float)
    t = t[np.isfinite(t)]
    if t.size == 0:
        return None
    hi = float(t.max()) if t.max() > 0 else 1.0
    counts, edges = np.histogram(t, bins=bins, range=(0.0, hi))
    return {"edges_s": [float(v) for v in edges], "counts": [int(v) for v in counts]}


def error_stats(final: np.ndarray, period_deg: float, target=(0.0, 0.0, 0.0)) -> tuple[dict, dict]:
    """Final-pose error relative to ``target`` (x_um, y_um, twist_deg; default the nominal
    pose): ({"x": .., "y": ..} in um, {"twist": ..} in degrees, modulo the symmetry period)."""
    final = np.asarray(final, float).reshape(-1, 3) - np.asarray(target, float)
    return {"x": _stats(final[:, 0]), "y": _stats(final[:, 1])}, {
        "twist": _stats(twist_error(final[:, 2], period_deg))
    }


def outcome_counts(outcome: np.ndarray) -> dict[str, int]:
    """Counts per outcome name, every name of :data:`simulator.core.OUTCOMES` present."""
    c = np.bincount(np.asarray(outcome, np.int64), minlength=len(OUTCOMES))
    return {name: int(c[k]) for k, name in enumerate(OUTCOMES)}


def capture_map(result: BatchResult, grid: StartGrid) -> np.ndarray:
    """(T, Ny, Nx) outcome indices of a batch run on ``grid.poses()``, ``[twist, y, x]``."""
    require(result.n == grid.size, f"the result has {result.n} starts but the grid {grid.size}")
    return result.outcome.reshape(grid.shape)


def max_bias(result: BatchResult, grid: StartGrid) -> tuple[dict, dict]:
    """Largest bias along +x, -x, +y, -y (at twist 0) from which every start aligns.

    On each half-axis through the origin (the grid row y = 0 for x, the column x = 0
    for y), the starts are walked outward from the origin (the origin included when on
    the grid): the bias is the largest |coordinate| up to which every start aligned, 0
    if the nearest one failed, None if the grid has no start on that half-axis or no
    twist 0. Returns (bias_um, limited_by_grid), the latter True where every start on
    the half-axis aligned, so the true bias may be larger than the grid reaches.
    """
    cmap = capture_map(result, grid)
    keys = ("+x", "-x", "+y", "-y")
    bias: dict = dict.fromkeys(keys)
    limited: dict = dict.fromkeys(keys)
    tw, ys, xs = (np.asarray(a) for a in (grid.twist_deg, grid.y_um, grid.x_um))
    k0 = np.flatnonzero(np.abs(tw) <= 1e-9)
    if not k0.size:
        return bias, limited
    for key in keys:
        along, across = (xs, ys) if key[1] == "x" else (ys, xs)
        j = np.flatnonzero(np.abs(across) <= 1e-9)
        if not j.size:
            continue
        line = cmap[k0[0], j[0], :] if key[1] == "x" else cmap[k0[0], :, j[0]]
        sel = np.flatnonzero(along >= 0) if key[0] == "+" else np.flatnonzero(along <= 0)
        if not np.any(np.abs(along[sel]) > 1e-9):
            continue
        sel = sel[np.argsort(np.abs(along[sel]))]
        ok = line[sel] == OUTCOMES.index("aligned")
        first_bad = int(np.argmin(ok)) if not ok.all() else len(ok)
        bias[key] = float(np.abs(along[sel[first_bad - 1]])) if first_bad > 0 else 0.0
        limited[key] = bool(ok.all())
    return bias, limited


def summarize(
    result: BatchResult, grid: StartGrid | None = None, target: str = "global_minimum"
) -> dict:
    """The statistics of a batch, JSON-ready (units in the key names).

    Keys: ``n``, ``method``, ``yield`` (fraction aligned), ``outcomes`` (counts),
    ``error_um`` / ``error_deg`` (over all starts), ``aligned_error_um`` /
    ``aligned_error_deg`` (over the aligned starts; None if none), ``optimum``
    (the global minimum, where "aligned" is measured), ``error_target`` (the pose the
    errors are measured from: ``kind`` "global_minimum", the optimum, or "nominal",
    (0, 0, 0), with ``x_um``, ``y_um``, ``twist_deg``), for a grid
    ``max_bias_um`` / ``max_bias_limited_by_grid`` (:func:`max_bias`), ``error_limit``
    (what limits the final-pose errors, :attr:`BatchResult.error_limit`), and for the
    dynamic methods ``time_to_align_s``: :func:`time_stats` of the aligned starts' times
    (seconds of simulated time; None if none aligned).
    """
    require(
        target in ("global_minimum", "nominal"),
        f"target must be 'global_minimum' or 'nominal', got {target!r}",
    )
    counts = outcome_counts(result.outcome)
    goal = tuple(result.optimum) if target == "global_minimum" else (0.0, 0.0, 0.0)
    err_um, err_deg = error_stats(result.final, result.period_deg, goal)
    ok = result.outcome == OUTCOMES.index("aligned")
    al_um, al_deg = error_stats(result.final[ok], result.period_deg, goal)
    x, y, t = result.optimum
    out = {
        "n": result.n,
        "method": result.method,
        "yield": counts["aligned"] / result.n,
        "outcomes": counts,
        "error_um": err_um,
        "error_deg": err_deg,
        "aligned_error_um": al_um,
        "aligned_error_deg": al_deg,
        "optimum": {"x_um": x, "y_um": y, "twist_deg": t},
        "error_target": {"kind": target, "x_um": goal[0], "y_um": goal[1], "twist_deg": goal[2]},
        "period_deg": result.period_deg,
        "error_limit": result.error_limit,
    }
    if result.time_s is not None:
        out["time_to_align_s"] = time_stats(result.time_to_align_s)
    if grid is not None:
        out["max_bias_um"], out["max_bias_limited_by_grid"] = max_bias(result, grid)
    return out
