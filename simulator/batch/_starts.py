"""Start poses for batches: regular grids (capture maps, maximum bias) and random
placements around a nominal pose (placement noise), priced before they are drawn."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from foundation import InputError, require, require_fits
from simulator.core import DISTRIBUTIONS, MAX_STARTS, MAX_TWIST_DEG, floor_whole

#: Largest |x|, |y| of a start (um): keeps grid indices in int32 (|twist|: simulator.core's
#: MAX_TWIST_DEG).
MAX_OFFSET_UM = 1e7


def _axis(name: str, spec: Any, unit: str) -> tuple[float, ...]:
    """A number, or (start, stop, step) with stop included, -> tuple of values."""
    if np.isscalar(spec):
        v = float(cast(float, spec))  # a number (np.isscalar's guard names complex too)
        require(math.isfinite(v), f"{name} must be finite, got {spec!r} {unit}")
        return (v,)
    require(
        len(spec) == 3, f"{name} must be one value or (start, stop, step) in {unit}, got {spec!r}"
    )
    a, b, d = (float(v) for v in spec)
    require(
        all(math.isfinite(v) for v in (a, b, d)),
        f"{name} must be finite numbers, got {spec!r} {unit}",
    )
    require(d > 0, f"{name} step must be > 0 {unit}, got {d:g}")
    require(b >= a, f"{name} stop ({b:g}) must be >= start ({a:g}) {unit}")
    n = floor_whole((b - a) / d) + 1
    require(n <= MAX_STARTS, f"{name} has {n:,} values; at most {MAX_STARTS:,}")
    return tuple(float(v) for v in a + d * np.arange(n))


@dataclass(frozen=True)
class StartGrid:
    """A regular grid of start poses (hashable).

    x_um, y_um: ascending translations (um); twist_deg: ascending twists (degrees).
    :meth:`poses` orders the starts with twist slowest, then y, then x, so outcomes
    reshape to a capture map ``[twist, y, x]`` (:func:`capture_map`).
    """

    x_um: tuple[float, ...]
    y_um: tuple[float, ...]
    twist_deg: tuple[float, ...] = (0.0,)

    @classmethod
    def from_ranges(
        cls,
        x_um: float | tuple[float, ...],
        y_um: float | tuple[float, ...],
        twist_deg: float | tuple[float, ...] = 0.0,
    ) -> StartGrid:
        """Each axis one value or (start, stop, step), stop included (um, um, degrees)."""
        g = cls(
            _axis("grid x", x_um, "um"),
            _axis("grid y", y_um, "um"),
            _axis("grid twist", twist_deg, "degrees"),
        )
        require(
            g.size <= MAX_STARTS, f"the start grid has {g.size:,} starts; at most {MAX_STARTS:,}"
        )
        price_starts(g.size, None, DRAW_BYTES_PER_START)
        return g

    @property
    def shape(self) -> tuple[int, int, int]:
        return len(self.twist_deg), len(self.y_um), len(self.x_um)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    def poses(self) -> np.ndarray:
        """(T * Ny * Nx, 3) poses (x_um, y_um, twist_deg), twist slowest, x fastest."""
        t, y, x = np.meshgrid(self.twist_deg, self.y_um, self.x_um, indexing="ij")
        return np.stack([x.ravel(), y.ravel(), t.ravel()], axis=1)


def _triple(name: str, v, unit: str) -> np.ndarray:
    a = np.asarray(v, dtype=float).reshape(-1)
    require(
        a.size == 3 and bool(np.all(np.isfinite(a))),
        f"{name} must be three finite numbers ({unit}), got {v!r}",
    )
    return a


#: Peak bytes per start of a batch: the start, its index, run order and sort keys, the
#: final pose, energy, steps and outcome, and the summary's copies.
BATCH_BYTES_PER_START = 192

#: Peak bytes per start while random starts are drawn (draws, scaling, the result).
DRAW_BYTES_PER_START = 96


def price_starts(n: int, budget_mb: float | None, per_start: int = BATCH_BYTES_PER_START) -> None:
    """Refuse ``n`` starts whose arrays would not fit the memory budget (before allocating)."""
    require_fits(
        f"{n:,} starts",
        float(n) * per_start,
        "use fewer starts (--random N or a coarser --grid)",
        budget_mb,
    )


def random_starts(
    n: int,
    spread,
    seed: int,
    around=(0.0, 0.0, 0.0),
    distribution: str = "normal",
    budget_mb: float | None = None,
) -> np.ndarray:
    """``n`` start poses drawn around a nominal pose (placement noise).

    Args:
        n: number of starts (>= 1).
        spread: (sx_um, sy_um, stwist_deg), each >= 0: standard deviations for
            ``"normal"``, half-widths for ``"uniform"``; 0 keeps that coordinate at
            its nominal value.
        seed: integer >= 0 for ``numpy.random.default_rng``; the draws are one
            ``(n, 3)`` array (x, y, twist per row), so the same seed and n give the
            same starts whatever the chunk size.
        around: the nominal pose (x_um, y_um, twist_deg) a gripper aims at.
        distribution: "normal" (default) or "uniform", independently per coordinate.
        budget_mb: memory budget the draws must fit (default: the default budget).

    Returns:
        (n, 3) float64 poses (x_um, y_um, twist_deg).
    """
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= MAX_STARTS:
        raise InputError(
            f"number of random starts must be a whole number from 1 to {MAX_STARTS:,}, got {n!r}"
        )
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be a whole number >= 0, got {seed!r}")
    require(
        distribution in DISTRIBUTIONS,
        f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}",
    )
    price_starts(int(n), budget_mb, DRAW_BYTES_PER_START)
    s = _triple("spread", spread, "um, um, degrees")
    require(bool(np.all(s >= 0)), f"spread must be >= 0 (um, um, degrees), got {tuple(s.tolist())}")
    c = _triple("around", around, "um, um, degrees")
    rng = np.random.default_rng(int(seed))
    u = (
        rng.standard_normal((int(n), 3))
        if distribution == "normal"
        else rng.uniform(-1.0, 1.0, (int(n), 3))
    )
    return c + s * u


def _as_poses(starts) -> np.ndarray:
    poses = starts.poses() if isinstance(starts, StartGrid) else np.asarray(starts, dtype=float)
    if poses.ndim == 1 and poses.size == 3:
        poses = poses[None]
    require(
        poses.ndim == 2 and poses.shape[1] == 3 and len(poses) >= 1,
        f"starts must be an (N, 3) array of poses (um, um, degrees) with N >= 1, got shape {poses.shape}",
    )
    require(bool(np.all(np.isfinite(poses))), "starts must be finite poses (um, um, degrees)")
    require(
        bool(
            np.all(np.abs(poses[:, :2]) <= MAX_OFFSET_UM)
            and np.all(np.abs(poses[:, 2]) <= MAX_TWIST_DEG)
        ),
        f"start poses must lie within +-{MAX_OFFSET_UM:g} um and +-{MAX_TWIST_DEG:g} degrees",
    )
    return poses
