"""The twist axis of a scene: which twists its pose grids hold, decided once per scene.

:class:`TwistAxis` covers one rotational-symmetry period of the chip by default (90 degrees
for a square), then it is periodic, or a bounded range the scene asks for.
:func:`chip_symmetry` finds the chip's period and mirror symmetry (exactly from its polygon
when known). :attr:`simulator.scene.Scene.twist_axis` builds the axis once per scene; the
landscape's :class:`~simulator.landscape.PoseGrid` takes its part of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from shapely import affinity

from foundation import InputError, fmt_bytes
from patterns.geometry import Mask
from simulator.core import AREA_REL_TOL, DEG_TOL, floor_whole, is_whole, tiny
from simulator.scene._parts import Effects, TwistGrid


def chip_symmetry(chip: Mask) -> tuple[float, bool]:
    """(rotational period in degrees, mirror-symmetric about the x axis) of a chip.

    From the exact geometry when known, else from the raster (exact comparison).
    """
    if chip.geometry is not None:
        g = chip.geometry
        tol = AREA_REL_TOL * max(g.area, tiny())

        def same(other) -> bool:
            return g.symmetric_difference(other).area <= tol

        period = next(
            (p for p in (90.0, 180.0) if same(affinity.rotate(g, p, origin=(0, 0)))), 360.0
        )
        return period, same(affinity.scale(g, 1.0, -1.0, origin=(0, 0)))
    d = chip.data
    if d.shape[0] == d.shape[1] and np.array_equal(np.rot90(d), d):
        period = 90.0
    elif np.array_equal(d[::-1, ::-1], d):
        period = 180.0
    else:
        period = 360.0
    return period, bool(np.array_equal(d[::-1], d))


#: Most twists a pose grid may have (0.0001 degree steps over a 90 degree period).
MAX_TWISTS = 2**20


def _require_twist_count(tg: TwistGrid, span_deg: float) -> None:
    """Refuse a twist axis of more than MAX_TWISTS twists before any array is made."""
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

    def step_deg_for(self, count: int) -> float:
        """The twist step (degrees) of a pose grid of ``count`` twists of this axis: the
        axis's step, or 1.0 for a grid of one twist (no twist direction). The one rule:
        :attr:`grid_step_deg` and :attr:`simulator.landscape.PoseGrid.twist_step_deg` ask it."""
        return float(self.step_deg) if count > 1 else 1.0

    @property
    def grid_step_deg(self) -> float:
        """The twist step (degrees) a pose grid on the whole axis uses (:meth:`step_deg_for`)."""
        return self.step_deg_for(self.count)

    def values(self) -> np.ndarray:
        """The twists in degrees, ascending (one twist 0.0 when twist is off)."""
        return self.values_at(np.arange(self.count))

    def values_at(self, k) -> np.ndarray:
        """Twists (degrees) at axis indices ``k``: the same formula as :meth:`values`, also for
        indices beyond the axis (a periodic axis continued: a run's unwrapped twist)."""
        k = np.asarray(k)
        if self.count == 1 and self.origin_deg is None and self.first == 0:
            return np.zeros(k.shape)
        if self.origin_deg is None:
            return self.step_deg * (k + self.first)
        return self.origin_deg + self.step_deg * k

    def cut_of(self, first: int, count: int) -> tuple[bool, bool]:
        """Which ends of the run of ``count`` twists from index ``first`` cut this axis short."""
        if self.count == 1:
            return False, False
        if self.periodic:
            short = count < self.count
            return short, short
        return first > 0, first + count < self.count

    def locate(self, twists) -> int | None:
        """Axis index of ``twists[0]`` when ``twists`` is a run of consecutive twists of this
        axis (continued beyond its ends when periodic), else None."""
        tw = np.asarray(twists, float)
        if tw.ndim != 1 or tw.size == 0 or tw.size > max(self.count, 1):
            return None
        if self.count == 1:
            return 0 if tw.size == 1 and abs(tw[0] - self.values()[0]) <= DEG_TOL else None
        k0 = round(float(tw[0] - self.values_at(0)) / self.step_deg)
        if not self.periodic and not (0 <= k0 and k0 + tw.size <= self.count):
            return None
        tol = DEG_TOL * max(1.0, self.step_deg)
        return k0 if np.all(np.abs(self.values_at(k0 + np.arange(tw.size)) - tw) <= tol) else None

    @classmethod
    def from_scene(cls, chip: Mask, effects: Effects, tg: TwistGrid) -> TwistAxis:
        """The axis of a scene with this chip, effects and twist grid (the chip's symmetry is
        computed here, once per scene: :attr:`simulator.scene.Scene.twist_axis`)."""
        period, mirror = chip_symmetry(chip)
        if not effects.twist:
            return cls(None, 1.0, 0, 1, False, period, mirror)
        # the twist range's span, or None without one (TwistGrid gives both ends or neither)
        span = None if tg.min_deg is None or tg.max_deg is None else tg.max_deg - tg.min_deg
        _require_twist_count(tg, period if span is None else span)
        step = tg.step_deg
        n_period = period / step
        divides = is_whole(n_period)
        if span is None or (divides and span + step >= period - DEG_TOL):
            if divides:
                n = round(n_period)  # one period, centred on and always containing 0
                return cls(None, step, -(n // 2), n, True, period, mirror)
            n = floor_whole(period / step / 2)
            return cls(None, step, -n, 2 * n + 1, False, period, mirror)
        n = floor_whole(span / step) + 1
        return cls(tg.min_deg, step, 0, n, False, period, mirror)
