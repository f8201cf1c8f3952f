"""The pose grid's twist axis: the chip's symmetry, the twists computed, their bounds.

The twist axis covers one rotational-symmetry period of the chip by default (90 degrees
for a square) and is then periodic; a scene may bound it instead. Translation boxes
(:func:`_axis_box`) clamp a requested box of translations to the chip's reach.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely import affinity

from patterns.errors import InputError
from patterns.mask import Mask
from patterns.resources import fmt_bytes
from simulator.scene import Scene


def chip_symmetry(chip: Mask) -> tuple[float, bool]:
    """(rotational period in degrees, mirror-symmetric about the x axis) of a chip.

    From the exact geometry when known, else from the raster (exact comparison).
    """
    if chip.geometry is not None:
        g = chip.geometry
        tol = 1e-9 * max(g.area, 1e-12)

        def same(other) -> bool:
            return g.symmetric_difference(other).area <= tol

        period = next((p for p in (90.0, 180.0) if same(affinity.rotate(g, p, origin=(0, 0)))), 360.0)
        return period, same(affinity.scale(g, 1.0, -1.0, origin=(0, 0)))
    d = chip.data
    if d.shape[0] == d.shape[1] and np.array_equal(np.rot90(d), d):
        period = 90.0
    elif np.array_equal(d[::-1, ::-1], d):
        period = 180.0
    else:
        period = 360.0
    return period, bool(np.array_equal(d[::-1], d))


def axis_step(axis: np.ndarray) -> float:
    """Spacing of an evenly spaced axis, from its ends: ``axis[1] - axis[0]`` carries the
    round-off of both values (0.010000000000000009 for -0.5 + 0.01 k), which grows with the
    index and puts 50 steps of 0.01 degrees from -0.5 at 4e-16 instead of 0. 1.0 for one value."""
    n = len(axis)
    return float(axis[-1] - axis[0]) / (n - 1) if n > 1 else 1.0


#: Most twists a pose grid may have (0.0001 degree steps over a 90 degree period).
MAX_TWISTS = 2**20


def _require_twist_count(scene: Scene, span_deg: float) -> None:
    """Refuse a twist axis of more than MAX_TWISTS twists before any array is made."""
    tg = scene.twist
    n = span_deg / tg.step_deg
    if not n <= MAX_TWISTS:
        raise InputError(
            f"twist step {tg.step_deg:g} deg gives {n:.3g} twists over {span_deg:g} deg, more than {MAX_TWISTS:,} "
            f"(the landscape would need {fmt_bytes(n * 4)} for every translation); use a larger --twist-step or a narrower twist range"
        )


@dataclass(frozen=True)
class TwistAxis:
    """The twist axis of a scene's pose grid: built once (:meth:`from_scene`), frozen.

    Twist k is ``step_deg * (k + first)`` for k in ``range(count)`` on an axis centred on 0
    (``origin_deg`` None: the default axis of one symmetry period), and
    ``origin_deg + step_deg * k`` on a bounded one (``origin_deg`` = its ``min_deg``). ``periodic``: the axis covers one full period of the
    chip's rotational symmetry (``period_deg``) and wraps. ``mirror``: the chip is
    mirror-symmetric about the x axis.
    """

    origin_deg: float | None
    step_deg: float
    first: int
    count: int
    periodic: bool
    period_deg: float
    mirror: bool

    def values(self) -> np.ndarray:
        """The twists in degrees, ascending (one twist 0.0 when twist is off)."""
        if self.count == 1 and self.origin_deg is None and self.first == 0:
            return np.zeros(1)
        if self.origin_deg is None:
            return self.step_deg * (np.arange(self.count) + self.first)
        return self.origin_deg + self.step_deg * np.arange(self.count)

    @classmethod
    def from_scene(cls, scene: Scene) -> TwistAxis:
        """The axis of ``scene`` (its chip's symmetry is computed here, once per scene)."""
        period, mirror = chip_symmetry(scene.chip)
        if not scene.effects.twist:
            return cls(None, 1.0, 0, 1, False, period, mirror)
        tg = scene.twist
        _require_twist_count(scene, period if tg.min_deg is None else tg.max_deg - tg.min_deg)
        step = tg.step_deg
        n_period = period / step
        divides = abs(n_period - round(n_period)) < 1e-9
        if tg.min_deg is None or (divides and tg.max_deg - tg.min_deg + step >= period - 1e-9):
            if divides:
                n = round(n_period)  # one period, centred on and always containing 0
                return cls(None, step, -(n // 2), n, True, period, mirror)
            n = int(math.floor(period / step / 2 + 1e-9))
            return cls(None, step, -n, 2 * n + 1, False, period, mirror)
        n = int(math.floor((tg.max_deg - tg.min_deg) / step + 1e-9)) + 1
        return cls(tg.min_deg, step, 0, n, False, period, mirror)


def twist_axis(scene: Scene) -> tuple[np.ndarray, bool, float]:
    """(twists in degrees, periodic?, chip symmetry period) of the scene's pose grid
    (:attr:`Scene.twist_axis`, built once per scene)."""
    axis = scene.twist_axis
    return axis.values(), axis.periodic, axis.period_deg


def twists_around(scene: Scene, twist_values, margin_steps: int = 1) -> np.ndarray:
    """The contiguous part of the scene's twist axis that queries at ``twist_values`` need.

    Interpolation needs the two grid twists around a value, and a torque (central
    difference) one step more on each side. Returns the whole axis when the needed
    part wraps around a periodic axis.
    """
    axis, wrap, period = twist_axis(scene)
    if len(axis) == 1:
        return axis
    step = axis_step(axis)
    vals = np.atleast_1d(np.asarray(twist_values, float))
    if wrap:
        vals = (vals - axis[0]) % period + axis[0]
    k = (vals - axis[0]) / step
    lo = int(math.floor(k.min() + 1e-9)) - margin_steps
    hi = int(math.ceil(k.max() - 1e-9)) + margin_steps
    if lo < 0 or hi > len(axis) - 1:
        if wrap:
            return axis
        lo, hi = max(lo, 0), min(hi, len(axis) - 1)
        if not (axis[0] - 1e-9 <= vals.min() and vals.max() <= axis[-1] + 1e-9):
            raise InputError(
                f"twist {vals.min():g}..{vals.max():g} deg is outside the scene's twist range "
                f"{axis[0]:g}..{axis[-1]:g} deg; widen the twist range"
            )
    return axis[lo : hi + 1]


def _axis_box(full: int, limit: int | None, center: int, half: int | None) -> tuple[int, int, bool, bool]:
    """(centre, half-width, cut below, cut above) of a window on an axis of reach ``full``.

    ``limit`` caps the half-width about 0 (the scene's window); ``center``/``half`` ask
    for a box; the box is clamped to the reach and kept symmetric about its centre.
    """
    lim = full if limit is None else min(full, limit)
    center = min(max(center, -lim), lim)  # beyond the reach nothing touches: clamp
    lo, hi = (-lim, lim) if half is None else (max(center - half, -lim), min(center + half, lim))
    if (hi - lo) % 2:
        # An odd span has no centre pixel: grow it by one, on the side not at the reach.
        # (Shrinking the side at the reach cut it: a wall of +inf where the energy is 0,
        # so a start beyond the reach reported an infinite energy.)
        lo, hi = (lo - 1, hi) if hi == lim else (lo, hi + 1)
    return (lo + hi) // 2, (hi - lo) // 2, lo > -full, hi < full


def _twist_cut(axis: np.ndarray, wrap: bool, twists: np.ndarray) -> tuple[bool, bool]:
    """Which ends of ``twists`` cut a longer twist axis short."""
    if len(axis) == 1:
        return False, False
    if wrap:
        return (len(twists) < len(axis),) * 2
    eps = 1e-9 * max(1.0, abs(axis).max())
    return bool(twists[0] > axis[0] + eps), bool(twists[-1] < axis[-1] - eps)
