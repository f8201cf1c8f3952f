"""The pose grid: which poses (twist, y, x) a landscape holds, owned by one object.

:class:`TwistAxis` is the scene's twist axis, built once per scene (:attr:`Scene.twist_axis`):
one rotational-symmetry period of the chip by default (90 degrees for a square), then
periodic, or a bounded range. :class:`PoseGrid` is the grid of one landscape (the
scene's whole window, or a box or band of it): its shape, translation step and origin,
its part of the twist axis, periodicity, cut sides, the chip's symmetry period and its
radius of gyration (the metric that turns a twist step into a length). A
:class:`~simulator.landscape.Landscape` carries its PoseGrid, and the steppers take it as
their static (hashable) grid. Its axes are methods (:meth:`PoseGrid.x_um`, ...):
nothing re-derives a step from an array's ends. Translation boxes (:func:`_axis_box`)
clamp a requested box of translations to the chip's reach.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from foundation import InputError
from simulator.core import DEG_TOL, ceil_whole, floor_whole
from simulator.scene import Scene, TwistAxis


def axis_step(axis: np.ndarray) -> float:
    """Spacing of an evenly spaced list of values a user gave (start grids), from its ends; a
    pose grid knows its steps (:class:`PoseGrid`) and never needs this. ``axis[1] - axis[0]`` carries the
    round-off of both values (0.010000000000000009 for -0.5 + 0.01 k), which grows with the
    index and puts 50 steps of 0.01 degrees from -0.5 at 4e-16 instead of 0. 1.0 for one value."""
    n = len(axis)
    return float(axis[-1] - axis[0]) / (n - 1) if n > 1 else 1.0


def consecutive_runs(indices) -> list[list[int]]:
    """Sorted distinct axis indices split into runs of consecutive ones: each run is the
    twist axis of one landscape (one pose grid)."""
    out: list[list[int]] = []
    for k in sorted({int(i) for i in indices}):
        if out and k == out[-1][-1] + 1:
            out[-1].append(k)
        else:
            out.append([k])
    return out


#: Relative slack (fraction of the step) in the spacings of given twists for them to count
#: as evenly spaced (one pose grid): round-off of decimal twists passes, an uneven list does not.
EVEN_SPACING_REL = 1e-6


def evenly_spaced_axis(twists, scene_axis: TwistAxis, what: str = "twists") -> TwistAxis:
    """A bounded twist axis through ``twists`` (degrees): they must be evenly spaced and
    ascending. Its step is the scene's for a single twist (1 degree when twist is off)."""
    tw = np.asarray(twists, float)
    if tw.ndim != 1 or tw.size == 0 or not np.all(np.isfinite(tw)):
        raise InputError(
            f"{what} must be a non-empty list of finite twists in degrees, got {twists!r}"
        )
    step = scene_axis.step_deg if tw.size == 1 else float(tw[-1] - tw[0]) / (tw.size - 1)
    if tw.size > 1 and not (
        step > 0 and np.all(np.abs(np.diff(tw) - step) <= EVEN_SPACING_REL * step)
    ):
        raise InputError(
            f"{what} must be evenly spaced and ascending (one pose grid), got {tw[:4].tolist()}..."
        )
    return TwistAxis(
        float(tw[0]), step, 0, int(tw.size), False, scene_axis.period_deg, scene_axis.mirror
    )


#: Where the cut sides of a grid are: ((twist low, high), (y low, high), (x low, high)).
Cut = tuple[tuple[bool, bool], tuple[bool, bool], tuple[bool, bool]]
NO_CUT: Cut = ((False, False), (False, False), (False, False))


@dataclass(frozen=True)
class PoseGrid:
    """The poses of one landscape: node (it, iy, ix) is the pose
    ``(x_um()[ix], y_um()[iy], twist_deg()[it])``. Frozen, validated and hashable: the
    steppers' static grid (jit recompiles only when a compared field changes).

    Attributes:
        shape: (T, Ny, Nx) nodes.
        um_per_px: translation step (um).
        twist: the twist axis this grid takes its twists from (the scene's, or one built
            for a given list of twists); its step and the chip's symmetry period live there.
        wrap: the grid holds the whole periodic twist axis and wraps around.
        cut: True where the grid is a box or band cut from a larger one (see
            :class:`~simulator.landscape.Landscape`).
        rg_px: the chip's radius of gyration (px): one twist step is an arc of
            ``radians(step) * rg_px`` px (the steppers' metric; 0 where no stepper runs).
        x_first_px, y_first_px: px from the pattern centre of column 0 and row 0.
        t_first: twist-axis index of plane 0 (unwrapped on a periodic axis).

    The origins are host-side only (``compare=False``): boxes of one shape share a
    compiled stepper.
    """

    shape: tuple[int, int, int]
    um_per_px: float
    twist: TwistAxis
    wrap: bool = False
    cut: Cut = NO_CUT
    rg_px: float = 0.0
    x_first_px: int = field(default=0, compare=False)
    y_first_px: int = field(default=0, compare=False)
    t_first: int = field(default=0, compare=False)

    def __post_init__(self) -> None:
        if len(self.shape) != 3 or not all(
            isinstance(n, int | np.integer) and n >= 1 for n in self.shape
        ):
            raise ValueError(f"PoseGrid shape must be three whole numbers >= 1, got {self.shape!r}")
        object.__setattr__(self, "shape", tuple(int(n) for n in self.shape))
        if not (math.isfinite(self.um_per_px) and self.um_per_px > 0):
            raise ValueError(f"PoseGrid um_per_px must be finite and > 0, got {self.um_per_px!r}")
        if not (math.isfinite(self.rg_px) and self.rg_px >= 0):
            raise ValueError(f"PoseGrid rg_px must be finite and >= 0, got {self.rg_px!r}")
        if self.wrap and not (self.twist.periodic and self.shape[0] == self.twist.count):
            raise ValueError("a PoseGrid wraps only when it holds the whole periodic twist axis")
        if not self.twist.periodic and not (
            0 <= self.t_first and self.t_first + self.shape[0] <= self.twist.count
        ):
            raise ValueError(
                f"twists {self.t_first}..{self.t_first + self.shape[0] - 1} lie outside the bounded axis of {self.twist.count}"
            )
        object.__setattr__(self, "cut", tuple((bool(a), bool(b)) for a, b in self.cut))

    # -- axes
    def x_um(self) -> np.ndarray:
        """(Nx,) chip-centre x of the columns (um), ascending."""
        return (np.arange(self.shape[2]) + self.x_first_px) * self.um_per_px

    def y_um(self) -> np.ndarray:
        """(Ny,) chip-centre y of the rows (um), ascending (y up)."""
        return (np.arange(self.shape[1]) + self.y_first_px) * self.um_per_px

    def twist_deg(self) -> np.ndarray:
        """(T,) twists of the planes (degrees), ascending, evenly spaced."""
        return self.twist.values_at(self.t_first + np.arange(self.shape[0]))

    # -- steps and origin
    @property
    def twist_step_deg(self) -> float:
        """Twist step (degrees); 1.0 for a grid of one twist (no twist direction):
        :meth:`TwistAxis.step_deg_for`, the rule of its axis."""
        return self.twist.step_deg_for(self.shape[0])

    @property
    def period_deg(self) -> float:
        """The chip's rotational symmetry period (degrees)."""
        return float(self.twist.period_deg)

    @property
    def x0_um(self) -> float:
        return float(self.x_first_px * self.um_per_px)

    @property
    def y0_um(self) -> float:
        return float(self.y_first_px * self.um_per_px)

    @property
    def t0_deg(self) -> float:
        return float(self.twist.values_at(self.t_first))

    @property
    def twist_px_per_step(self) -> float:
        """Arc length (px) at the radius of gyration for one twist step."""
        return math.radians(self.twist_step_deg) * self.rg_px

    # -- conversions
    def to_pose(self, idx) -> np.ndarray:
        """Grid indices (..., 3) (it, iy, ix) -> physical poses (..., 3) (x_um, y_um, twist_deg)."""
        idx = np.asarray(idx, dtype=float)
        return np.stack(
            [
                self.x0_um + idx[..., 2] * self.um_per_px,
                self.y0_um + idx[..., 1] * self.um_per_px,
                self.t0_deg + idx[..., 0] * self.twist_step_deg,
            ],
            axis=-1,
        )

    def to_index(self, pose) -> np.ndarray:
        """Physical poses (..., 3) (x_um, y_um, twist_deg) -> fractional grid indices (..., 3)."""
        pose = np.asarray(pose, dtype=float)
        return np.stack(
            [
                (pose[..., 2] - self.t0_deg) / self.twist_step_deg,
                (pose[..., 1] - self.y0_um) / self.um_per_px,
                (pose[..., 0] - self.x0_um) / self.um_per_px,
            ],
            axis=-1,
        )

    @classmethod
    def uniform(
        cls,
        shape,
        um_per_px: float = 1.0,
        twist_step_deg: float = 1.0,
        wrap: bool = False,
        cut: Cut = NO_CUT,
        period_deg: float = 90.0,
        rg_px: float = 0.0,
        x_first_px: int = 0,
        y_first_px: int = 0,
        t0_deg: float = 0.0,
    ) -> PoseGrid:
        """A grid of ``shape`` on its own twist axis (for tests and hand-made landscapes):
        twists ``t0_deg + twist_step_deg * k``; ``wrap``: the axis is periodic (T steps)."""
        t = int(shape[0])
        axis = TwistAxis(
            None if wrap else float(t0_deg),
            float(twist_step_deg),
            round(t0_deg / twist_step_deg) if wrap else 0,
            t,
            bool(wrap),
            float(period_deg),
            False,
        )
        return cls(
            tuple(shape),
            float(um_per_px),
            axis,
            bool(wrap),
            cut,
            float(rg_px),
            int(x_first_px),
            int(y_first_px),
        )


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
    ta = scene.twist_axis
    axis, wrap, period = ta.values(), ta.periodic, ta.period_deg
    if len(axis) == 1:
        return axis
    step = ta.step_deg
    vals = np.atleast_1d(np.asarray(twist_values, float))
    if wrap:
        vals = (vals - axis[0]) % period + axis[0]
    k = (vals - axis[0]) / step
    lo = floor_whole(k.min()) - margin_steps
    hi = ceil_whole(k.max()) + margin_steps
    if lo < 0 or hi > len(axis) - 1:
        if wrap:
            return axis
        lo, hi = max(lo, 0), min(hi, len(axis) - 1)
        if not (axis[0] - DEG_TOL <= vals.min() and vals.max() <= axis[-1] + DEG_TOL):
            raise InputError(
                f"twist {vals.min():g}..{vals.max():g} deg is outside the scene's twist range "
                f"{axis[0]:g}..{axis[-1]:g} deg; widen the twist range"
            )
    return axis[lo : hi + 1]


def _axis_box(
    full: int, limit: int | None, center: int, half: int | None
) -> tuple[int, int, bool, bool]:
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
        cut = len(twists) < len(axis)
        return cut, cut
    eps = DEG_TOL * max(1.0, abs(axis).max())
    return bool(twists[0] > axis[0] + eps), bool(twists[-1] < axis[-1] - eps)
