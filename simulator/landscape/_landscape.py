"""The energy landscape E[twist, y, x] by FFT cross-correlation.

Model (docs/physics.md §3.2): ``E(x, y, a) = Delta_gamma * sum_p chip_a(p - (x, y)) * w(p)``
with ``w`` the pattern mask (1 on pads, grey levels graded, 0 on substrate), so that
``E = Delta_gamma * A_ol`` in joules. For each twist the whole translation plane is
one linear (zero-padded, never circular) cross-correlation.

Conventions:

* Landscape arrays are indexed ``[twist, y, x]`` with y *ascending* (physics frame,
  y up); ``x_um[ix] = (ix - rx) * um_per_px``, ``y_um[iy] = (iy - ry) * um_per_px``.
  The chip pose is its centre relative to the pattern's nominal centre (the image
  centre), twist counter-clockwise positive, in degrees.
* A chip given as exact geometry is rasterized anew at every twist (exact area
  coverage); a chip PNG is rotated by bilinear resampling (OpenCV ``warpAffine``),
  which keeps its area to within 1 % for chips of 5 px and more (a 120 x 60 px chip: 0.5 %,
  tested) but not for tiny ones (measured: +12.5 % for 1 px, -8 % for 2 px, -3 % for 3 px);
  give tiny chips as geometry.
* The twist axis covers one rotational-symmetry period of the chip by default
  (90 degrees for a square) and is then periodic (``wrap=True``).

The modules behind it, one concept each: :mod:`simulator.landscape` (twist axis and
symmetry), :mod:`simulator.landscape` (chip rasters per twist),
:mod:`simulator.landscape` (the FFT correlation) and :mod:`simulator.landscape` (plan,
budget and build: :func:`build_landscape`). This module holds the
:class:`Landscape` and its queries, and re-exports the names users call.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from foundation import InputError, fmt_bytes
from simulator.core import UM, UM2, WHOLE_TOL, floor_whole
from simulator.landscape._correlator import NOISE_FACTOR
from simulator.landscape._posegrid import PoseGrid


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


#: Most samples of one energy curve.
MAX_CURVE_SAMPLES = 10**7


@dataclass(frozen=True, eq=False)
class Landscape:
    """Energy on the pose grid, with the grid and what it cost.

    Attributes:
        energy: (T, Ny, Nx) joules, ``[twist, y, x]``, y ascending.
        grid: the :class:`~simulator.landscape.PoseGrid` of the energy: its axes
            (``x_um``, ``y_um``, ``twist_deg`` below), steps, periodicity (``wrap``), the
            chip's symmetry period (``period_deg``) and cut sides (``cut``: True where the
            grid was cut short on that side, a box or band of a larger grid, so the energy
            beyond it is unknown; beyond an uncut x/y side the chip no longer touches the
            pattern and the energy is exactly 0; beyond an uncut end of a non-periodic
            twist axis lies the end of the twist range the scene asked for).
        delta_gamma: pad minus substrate wetting energy (N/m, negative).
        energy_scale_J: the largest |E| the scene can reach, |Delta_gamma| min(|P|, |C|)
            (docs/physics.md C8); the noise floor scales with it, so every box or band of one
            scene shares one floor (0 = take max|E| of this grid).
        stats: what the build did (rotations, seconds, bytes, backend, FFT size).
        meniscus_height_um: the finite meniscus's height (um) the energy was built with,
            None for the overlap model (:mod:`simulator.physics`).
    """

    energy: np.ndarray
    grid: PoseGrid
    delta_gamma: float
    energy_scale_J: float = 0.0
    stats: dict = field(default_factory=dict)
    meniscus_height_um: float | None = None

    def __post_init__(self) -> None:
        if tuple(np.shape(self.energy)) != self.grid.shape:
            raise ValueError(
                f"energy of shape {np.shape(self.energy)} on a pose grid of shape {self.grid.shape}"
            )

    # -- the pose grid's axes (read-only arrays, computed from the grid on each access)
    @property
    def x_um(self) -> np.ndarray:
        """(Nx,) translations of the chip centre along x (um), ascending."""
        return _frozen(self.grid.x_um())

    @property
    def y_um(self) -> np.ndarray:
        """(Ny,) translations along y (um), ascending."""
        return _frozen(self.grid.y_um())

    @property
    def twist_deg(self) -> np.ndarray:
        """(T,) twists (degrees), ascending, evenly spaced."""
        return _frozen(self.grid.twist_deg())

    @property
    def wrap(self) -> bool:
        return self.grid.wrap

    @property
    def cut(self) -> tuple:
        return self.grid.cut

    @property
    def period_deg(self) -> float:
        return self.grid.period_deg

    @property
    def um_per_px(self) -> float:
        return self.grid.um_per_px

    @property
    def twist_step_deg(self) -> float:
        return self.grid.twist_step_deg

    @property
    def full_reach(self) -> bool:
        """The translation window holds every pose where the chip touches the pattern."""
        return not any(self.cut[1] + self.cut[2])

    # -- scales
    @property
    def joules_per_px2(self) -> float:
        return self.delta_gamma * self.um_per_px**2 * UM2

    @property
    def noise_floor_J(self) -> float:
        """Energy differences at or below this are round-off: steppers treat them as ties.

        ``NOISE_FACTOR * eps(dtype) * energy_scale_J``: FFT round-off is bounded by a few
        eps times the largest value (measured 3.3 eps in float32), so 32 eps leaves a
        10x margin while staying far below any real one-pixel energy change.
        """
        eps = np.finfo(self.energy.dtype).eps
        scale = self.energy_scale_J or float(np.abs(self.energy).max())
        return float(NOISE_FACTOR * eps * max(scale, np.finfo(float).tiny))

    def overlap_um2(self, energy_J: ArrayLike) -> np.ndarray:
        """Overlap area (um^2) for an energy (J): A = E / Delta_gamma (an array of the
        energy's shape, 0-d for one energy)."""
        return np.asarray(energy_J) / (self.delta_gamma * UM2)

    # -- grid coordinates
    def fractional_index(self, x_um, y_um, twist_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Continuous (it, iy, ix) grid coordinates of poses (twist wrapped if periodic)."""
        g = self.grid  # as PoseGrid.to_index, for poses given as separate (broadcasting) arrays
        ix = (np.asarray(x_um, float) - g.x0_um) / g.um_per_px
        iy = (np.asarray(y_um, float) - g.y0_um) / g.um_per_px
        it = (np.asarray(twist_deg, float) - g.t0_deg) / g.twist_step_deg
        if self.wrap:
            it = np.mod(it, g.shape[0])
        return it, iy, ix

    def energy_at(self, x_um, y_um, twist_deg) -> np.ndarray:
        """Energy (J) at continuous poses by trilinear interpolation on the grid.

        Along a periodic twist axis the interpolation wraps. Outside the window the
        energy is 0 (no contact) when the window has full reach, else InputError.
        """
        it, iy, ix = self.fractional_index(x_um, y_um, twist_deg)
        return trilinear(self.energy, it, iy, ix, self.wrap, self.cut)

    def gradient_at(self, x_um, y_um, twist_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dE/dx, dE/dy) in J/m and dE/dtwist in J/rad, by central differences of one grid step.

        Energy differences below the noise floor are round-off and give exactly 0
        (a plateau is flat, not noisy).
        """
        s, dt = self.um_per_px, self.twist_step_deg
        e, floor = self.energy_at, self.noise_floor_J
        x, y, t = (np.asarray(v, float) for v in (x_um, y_um, twist_deg))

        def diff(a, b, h):
            d = a - b
            return np.where(np.abs(d) <= floor, 0.0, d) / h

        gx = diff(e(x + s, y, t), e(x - s, y, t), 2 * s * UM)
        gy = diff(e(x, y + s, t), e(x, y - s, t), 2 * s * UM)
        if len(self.twist_deg) > 1:
            gt = diff(e(x, y, t + dt), e(x, y, t - dt), 2 * math.radians(dt))
        else:
            gt = np.zeros_like(gx)
        return gx, gy, gt

    def force_at(self, x_um, y_um, twist_deg) -> tuple[np.ndarray, np.ndarray]:
        """Restoring force (Fx, Fy) in N: F = -grad E (docs/physics.md §3.4)."""
        gx, gy, _ = self.gradient_at(x_um, y_um, twist_deg)
        return -gx, -gy

    def torque_at(self, x_um, y_um, twist_deg) -> np.ndarray:
        """Restoring torque about z in N m: tau = -dE/dtwist (twist in radians, CCW +)."""
        return -self.gradient_at(x_um, y_um, twist_deg)[2]

    def minimum_index(self) -> tuple[int, int, int]:
        """Grid indices (it, iy, ix) of the global minimum: of the grid poses within the noise
        floor of the lowest energy (ties), the one nearest the nominal pose (:func:`nominal_order`).

        A tie is decided by where it lies, not by round-off, so a landscape and any set of
        its boxes that holds every tie name the same pose (:mod:`simulator.landscape`).
        """
        e = self.energy
        cand = np.flatnonzero(e <= float(e.min()) + self.noise_floor_J)
        it, iy, ix = np.unravel_index(cand, e.shape)
        if cand.size > 1:
            k = nominal_order(
                self.x_um[ix],
                self.y_um[iy],
                self.twist_deg[it],
                self.um_per_px,
                self.twist_step_deg,
                self.period_deg,
            )[0]
            it, iy, ix = it[k : k + 1], iy[k : k + 1], ix[k : k + 1]
        return int(it[0]), int(iy[0]), int(ix[0])

    def floor_extent(self) -> tuple[tuple[int, int], tuple[int, int], tuple[int, int]]:
        """Index ranges ((t0, t1), (y0, y1), (x0, x1)) of the global minimum's floor: the poses
        within the noise floor of its energy, connected to it (faces of the grid cells).

        A single pose for a cusp or a smooth well; a flat floor where the chip floats, as it
        does within the reach of free contact lines (:class:`simulator.physics.WallProfile`).
        """
        return self._floor

    @property
    def floor_labelled(self) -> bool:
        """Whether :meth:`floor_extent` is already known (its labelling is done once per
        landscape and takes seconds on a large one: a caller says so before asking)."""
        return "_floor" in vars(self)

    @functools.cached_property
    def _floor(self) -> tuple[tuple[int, int], tuple[int, int], tuple[int, int]]:
        """:meth:`floor_extent`, labelled once per landscape (1.6 s on a 90 x 985 x 985 one;
        evaluate asks for it four times)."""
        from scipy import ndimage

        it, iy, ix = self.minimum_index()
        e = self.energy
        low = e <= float(e[it, iy, ix]) + self.noise_floor_J
        # labelled on the box of every low pose (the floor is one of them: its connections
        # all lie inside), not the whole grid
        box = tuple(slice(int(a.min()), int(a.max()) + 1) for a in np.nonzero(low))
        lab, _ = ndimage.label(low[box])
        sel = np.nonzero(lab == lab[it - box[0].start, iy - box[1].start, ix - box[2].start])
        return tuple(  # type: ignore[return-value]
            (int(a.min()) + b.start, int(a.max()) + b.start) for a, b in zip(sel, box, strict=True)
        )

    def floor_range(self) -> dict:
        """The floor of :meth:`floor_extent` in physical units: ``x_um``, ``y_um`` and
        ``twist_deg`` as [first, last] pose."""
        (t0, t1), (y0, y1), (x0, x1) = self.floor_extent()
        return {
            "x_um": [float(self.x_um[x0]), float(self.x_um[x1])],
            "y_um": [float(self.y_um[y0]), float(self.y_um[y1])],
            "twist_deg": [float(self.twist_deg[t0]), float(self.twist_deg[t1])],
        }

    def global_minimum(self) -> tuple[float, float, float, float]:
        """(x_um, y_um, twist_deg, energy_J) of the global minimum on this grid (:meth:`minimum_index`)."""
        it, iy, ix = self.minimum_index()
        return (
            float(self.x_um[ix]),
            float(self.y_um[iy]),
            float(self.twist_deg[it]),
            float(self.energy[it, iy, ix]),
        )

    def curve(
        self, axis: str, through: tuple[float, float, float], start: float, stop: float
    ) -> dict:
        """Energy, force and plateaus along one axis through a pose.

        Args:
            axis: "x", "y" (um) or "twist" (degrees).
            through: the pose (x_um, y_um, twist_deg) the line passes through.
            start, stop: range along the axis, sampled at the grid step.

        Returns:
            dict with ``values`` (the axis samples), ``energy_J``, ``force`` (N along x/y,
            N m for twist: minus the derivative along the axis), ``plateaus`` (list of
            [start, end] ranges where the chip touches the pattern but the force is zero:
            energy differences below the noise floor, see :meth:`gradient_at`) and
            ``no_contact`` (ranges where the chip does not touch the pattern at all).
        """
        if axis not in ("x", "y", "twist"):
            raise InputError(f"curve axis must be x, y or twist, got {axis!r}")
        step = self.twist_step_deg if axis == "twist" else self.um_per_px
        if not (math.isfinite(start) and math.isfinite(stop) and stop > start):
            raise InputError(
                f"curve range must be finite with --to > --from, got {start} .. {stop}"
            )
        samples = (stop - start) / step + 1
        if not samples <= MAX_CURVE_SAMPLES:
            raise InputError(
                f"the curve from {start:g} to {stop:g} at steps of {step:g} would have {samples:.3g} samples "
                f"(about {fmt_bytes(samples * 96)}), more than {MAX_CURVE_SAMPLES:,}; narrow --from/--to"
            )
        n = floor_whole((stop - start) / step) + 1
        v = start + step * np.arange(n)
        x, y, t = (np.full(n, float(c)) for c in through)
        {"x": x, "y": y, "twist": t}[axis][:] = v
        e = self.energy_at(x, y, t)
        gx, gy, gt = self.gradient_at(x, y, t)
        force = -{"x": gx, "y": gy, "twist": gt}[axis]
        return curve_of(axis, v, e, force, self.noise_floor_J)


#: The nominal ball of :func:`nominal_order`: poses within NOMINAL_BALL_PX px in x and y
#: and NOMINAL_BALL_PX / NOMINAL_PX_PER_STEP twist steps of (0, 0, 0), the box that
#: :func:`simulator.landscape.nominal_box` builds.
NOMINAL_BALL_PX, NOMINAL_PX_PER_STEP = 16, 8


def nominal_distance(
    x_um, y_um, twist_deg, um_per_px: float, twist_step_deg: float, period_deg: float
):
    """(r, twist steps) of poses from the nominal pose (0, 0, 0): r = max(|x|, |y|, 8 |twist|)
    with x, y in px and the twist in steps, taken modulo the chip's symmetry period."""
    p = float(period_deg)
    tw = np.asarray(twist_deg, float)
    ts = np.abs(np.mod(tw + p / 2, p) - p / 2) / twist_step_deg
    xp, yp = (
        np.abs(np.asarray(x_um, float)) / um_per_px,
        np.abs(np.asarray(y_um, float)) / um_per_px,
    )
    r = np.maximum(np.maximum(xp, yp), NOMINAL_PX_PER_STEP * ts)
    return np.round(r, 6), np.round(ts, 6)


def nominal_order(
    x_um, y_um, twist_deg, um_per_px: float, twist_step_deg: float, period_deg: float
) -> np.ndarray:
    """Indices that sort poses by their distance from the nominal pose (0, 0, 0): by r of
    :func:`nominal_distance`, then twist steps, then x^2 + y^2, then |twist|, twist, y, x."""
    x, y, t = (np.asarray(v, float) for v in (x_um, y_um, twist_deg))
    r, ts = nominal_distance(x, y, t, um_per_px, twist_step_deg, period_deg)
    d2 = np.round((x / um_per_px) ** 2 + (y / um_per_px) ** 2, 6)
    return np.lexsort((x, y, t, np.abs(t), d2, ts, r))


def curve_of(axis: str, values, energy_J, force, floor_J: float, linked=None) -> dict:
    """A curve's samples with their plateaus (zero force in contact), their flat steps
    (:func:`flat_steps`) and the stretches out of contact (``|E|`` at or below the noise
    floor ``floor_J``), as :meth:`Landscape.curve`. ``linked``: which neighbouring samples'
    energies may be compared (default all; a released curve's on one state only)."""
    detached = np.abs(energy_J) <= floor_J  # the chip no longer touches the pattern
    plateaus = runs(values, (force == 0) & ~detached)
    return {
        "axis": axis,
        "values": values,
        "energy_J": energy_J,
        "force": force,
        "plateaus": plateaus,
        "flat_steps": flat_steps(values, energy_J, floor_J, ~detached, plateaus, linked),
        "no_contact": runs(values, detached),
    }


def flat_steps(values, energy_J, floor_J: float, contact, plateaus, linked=None) -> list:
    """[start, end] ranges of neighbouring samples in contact whose energies differ by no
    more than the noise floor ``floor_J``, away from the ``plateaus``: flat to a stepper,
    which stops there (its moves must lower the energy by more than the floor), though the
    central-difference force across them is not zero (a flat part one sample long: 730/50
    at 5 um/px with free lines, 405-410 um). ``linked``: (n - 1,) booleans, which neighbours
    may be compared (default all)."""
    e = np.asarray(energy_J, float)
    contact = np.asarray(contact, bool)
    tie = (np.abs(np.diff(e)) <= floor_J) & contact[:-1] & contact[1:]
    if linked is not None:
        tie &= np.asarray(linked, bool)
    out = []
    for i, j in runs(np.arange(len(tie)), tie, min_points=1):  # runs of tied steps
        a, b = float(values[int(i)]), float(values[int(j) + 1])
        if not any(a <= p1 and p0 <= b for p0, p1 in plateaus):  # a plateau's own ties
            out.append([a, b])
    return out


def runs(values: np.ndarray, flat: np.ndarray, min_points: int = 3) -> list[list[float]]:
    """[start, end] ranges of ``values`` where ``flat`` holds for >= ``min_points`` samples in a row."""
    out, i, n = [], 0, len(values)
    while i < n:
        if flat[i]:
            j = i
            while j + 1 < n and flat[j + 1]:
                j += 1
            if j - i + 1 >= min_points:
                out.append([float(values[i]), float(values[j])])
            i = j + 1
        else:
            i += 1
    return out


def trilinear(e: np.ndarray, it, iy, ix, wrap: bool, cut=((False, False),) * 3) -> np.ndarray:
    """Trilinear interpolation of ``e[t, y, x]`` at fractional indices (numpy, host side).

    Beyond an uncut x/y side the value is 0 (no contact); beyond a cut side, or past
    the ends of a non-periodic twist axis, InputError.
    """
    nt, ny, nx = e.shape
    it, iy, ix = np.broadcast_arrays(*(np.asarray(a, float) for a in (it, iy, ix)))
    inside = (iy >= 0) & (iy <= ny - 1) & (ix >= 0) & (ix <= nx - 1)
    unknown = (
        (cut[1][0] & (iy < 0))
        | (cut[1][1] & (iy > ny - 1))
        | (cut[2][0] & (ix < 0))
        | (cut[2][1] & (ix > nx - 1))
    )
    if not wrap and nt > 1:
        unknown |= (it < -WHOLE_TOL) | (it > nt - 1 + WHOLE_TOL)
    if np.any(unknown):
        raise InputError(
            "pose outside the landscape's pose grid; widen the window (window_um) or the twist range"
        )
    x0 = np.clip(np.floor(ix), 0, max(nx - 2, 0)).astype(int)
    y0 = np.clip(np.floor(iy), 0, max(ny - 2, 0)).astype(int)
    fx, fy = np.clip(ix - x0, 0, 1), np.clip(iy - y0, 0, 1)
    x1, y1 = np.minimum(x0 + 1, nx - 1), np.minimum(y0 + 1, ny - 1)
    if nt == 1:
        t0 = t1 = np.zeros_like(x0)
        ft = np.zeros_like(fx)
    elif wrap:
        t0 = np.floor(it).astype(int) % nt
        ft = it - np.floor(it)
        t1 = (t0 + 1) % nt
    else:
        t0 = np.clip(np.floor(it), 0, nt - 2).astype(int)
        ft = np.clip(it - t0, 0, 1)
        t1 = t0 + 1

    def plane(t):
        return (
            e[t, y0, x0] * (1 - fx) * (1 - fy)
            + e[t, y0, x1] * fx * (1 - fy)
            + e[t, y1, x0] * (1 - fx) * fy
            + e[t, y1, x1] * fx * fy
        )

    val = plane(t0) * (1 - ft) + plane(t1) * ft
    return np.where(inside, val, 0.0)


__all__ = [
    "Landscape",
    "MAX_CURVE_SAMPLES",
    "NOMINAL_BALL_PX",
    "NOMINAL_PX_PER_STEP",
    "nominal_distance",
    "nominal_order",
    "runs",
    "trilinear",
]
