"""Exact answers without rasterization: the yardstick for the raster engine.

Everything here works on the exact shapely geometry of pattern and chip (micrometres,
origin at the nominal pattern centre, x right, y up, twist counter-clockwise positive in
degrees, docs/physics.md §1), in float64:

* :func:`overlap_um2` -- A_ol(x, y, twist) by polygon clipping, vectorized over poses
  (shapely 2: one ``shapely.intersection`` of an array of moved chips with the pattern);
  :func:`energy_J` is ``Delta_gamma * A_ol`` (docs/physics.md §3.2, Eq. 9).
* :func:`gradient_um2` -- dA/dx, dA/dy (um^2 per um) and dA/dtwist (um^2 per radian) by
  central differences of the exact overlap with small steps (default 1e-3 um and
  1e-3 degrees); :func:`force_N` and :func:`torque_Nm` are minus the energy gradient
  (docs/physics.md §3.4). At a kink (e.g. the V-shaped cusp of the twist well at 0,
  docs/physics.md C5) the central difference is the mean of the two one-sided slopes.
* :func:`exact_greedy` and :func:`exact_gradient_descent` -- the steppers of
  :mod:`simulator.motion` on the exact overlap, with the grid spacing as parameters
  (``step_um``, ``step_deg``) so the reference matches a raster's pose grid. Slow (a few
  thousand overlaps per second) but exact up to float64 round-off: this is the
  yardstick for final poses.

Tie rule (docs/physics.md §5, as :mod:`simulator.motion`): overlaps within ``tie_um2``
(default 1e-9 um^2 per 40 000 um^2 of chip: above float64 clipping round-off -- the
730/50 four-pad's plateau comes out flat to the last bit -- and far below any real change
of one step) are equal; greedy keeps the
current pose when it ties for the best, else takes the smallest move
``|dt| + |dy| + |dx|``, then the first in lexicographic order of ``(dt, dy, dx)`` from -1
to +1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from foundation import InputError, positive
from simulator.core import UM, UM2
from simulator.motion import GREEDY_MOVES
from simulator.physics import Materials

__all__ = [
    "ExactOverlap",
    "ReferenceRun",
    "energy_J",
    "exact_gradient_descent",
    "exact_greedy",
    "force_N",
    "gradient_um2",
    "overlap_um2",
    "radius_of_gyration_um",
    "torque_Nm",
]

#: Tie tolerance per um^2 of chip area (1e-9 um^2 for a 200 um chip).
TIE_PER_UM2 = 1e-9 / 4e4
#: Default central-difference steps of :func:`gradient_um2`: um for x, y; radians for twist.
H_DIFF = np.array([1e-3, 1e-3, math.radians(1e-3)])


def _as_poses(poses) -> np.ndarray:
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim == 1:
        p = p[None]
    if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
        raise InputError(
            f"poses must be finite (N, 3) rows (x_um, y_um, twist_deg), got shape {p.shape}"
        )
    return p


def _polygon_parts(geom: BaseGeometry) -> list:
    parts = [g for g in shapely.get_parts(geom) if g.geom_type == "Polygon" and g.area > 0]
    if not parts:
        raise InputError("chip geometry has no polygon with positive area")
    return parts


def moved_chips(chip: BaseGeometry, poses) -> list[np.ndarray]:
    """The chip rotated by twist about its centre (the origin), then moved by (x, y).

    Returns one (N,) array of shapely Polygons per polygon part of ``chip`` (the parts
    are disjoint, so overlaps add up over them).
    """
    p = _as_poses(poses)
    a = np.radians(p[:, 2])
    c, s = np.cos(a)[:, None], np.sin(a)[:, None]
    out = []
    for part in _polygon_parts(chip):
        rings = [part.exterior, *part.interiors]
        moved = []
        for ring in rings:
            xy = shapely.get_coordinates(ring)  # closed ring, (k, 2)
            x = xy[:, 0][None] * c - xy[:, 1][None] * s + p[:, :1]
            y = xy[:, 0][None] * s + xy[:, 1][None] * c + p[:, 1:2]
            moved.append(shapely.linearrings(np.stack([x, y], axis=-1)))
        holes = np.stack(moved[1:], axis=1) if len(moved) > 1 else None
        out.append(shapely.polygons(moved[0], holes=holes))
    return out


def overlap_um2(pattern: BaseGeometry, chip: BaseGeometry, poses) -> np.ndarray:
    """Exact overlap area A_ol (um^2) of the moved chip with the pattern, shape (N,).

    Args:
        pattern: wettable pad area, shapely (Multi)Polygon in um, centred.
        chip: wettable chip footprint in um, centred on the chip's centre.
        poses: (N, 3) or (3,) poses (x_um, y_um, twist_deg).
    """
    shapely.prepare(pattern)
    total = np.zeros(len(_as_poses(poses)))
    for moved in moved_chips(chip, poses):
        total += shapely.area(shapely.intersection(moved, pattern))
    return total


def energy_J(
    pattern: BaseGeometry, chip: BaseGeometry, poses, materials: Materials | None = None
) -> np.ndarray:
    """E = Delta_gamma * A_ol (J) at each pose (docs/physics.md Eq. 9), shape (N,)."""
    dg = (materials or Materials()).delta_gamma_N_m
    return dg * overlap_um2(pattern, chip, poses) * UM2


def gradient_um2(
    pattern: BaseGeometry, chip: BaseGeometry, poses, h_um: float = 1e-3, h_deg: float = 1e-3
) -> np.ndarray:
    """(N, 3) exact dA/dx (um), dA/dy (um) and dA/dtwist (um^2 per radian).

    Central differences of the exact overlap with steps ``h_um`` and ``h_deg``; the
    six shifted poses of every pose are clipped in one vectorized call.
    """
    p = _as_poses(poses)
    h = np.array(
        [
            positive("h_um", h_um, "um"),
            positive("h_um", h_um, "um"),
            positive("h_deg", h_deg, "degrees"),
        ]
    )
    shifts = np.concatenate([np.diag(h), -np.diag(h)])  # (6, 3): +x, +y, +t, -x, -y, -t
    a = overlap_um2(pattern, chip, (p[:, None, :] + shifts[None]).reshape(-1, 3)).reshape(len(p), 6)
    g = (a[:, :3] - a[:, 3:]) / (2 * h)
    g[:, 2] *= 180.0 / math.pi  # per degree -> per radian
    return g


def force_N(
    pattern: BaseGeometry, chip: BaseGeometry, poses, materials: Materials | None = None, **steps
) -> np.ndarray:
    """(N, 2) restoring force (Fx, Fy) in N: F = -grad E (docs/physics.md §3.4)."""
    dg = (materials or Materials()).delta_gamma_N_m
    g = gradient_um2(pattern, chip, poses, **steps)
    return -dg * g[:, :2] * UM2 / UM


def torque_Nm(
    pattern: BaseGeometry, chip: BaseGeometry, poses, materials: Materials | None = None, **steps
) -> np.ndarray:
    """(N,) restoring torque about z in N m: tau = -dE/dtwist (twist in radians, CCW +)."""
    dg = (materials or Materials()).delta_gamma_N_m
    return -dg * gradient_um2(pattern, chip, poses, **steps)[:, 2] * UM2


def radius_of_gyration_um(chip: BaseGeometry) -> float:
    """sqrt(polar moment / area) of the chip footprint about its centre (the origin), um."""
    j = 0.0
    for part in _polygon_parts(chip):
        part = shapely.orient_polygons(part)
        for ring in [part.exterior, *part.interiors]:
            xy = shapely.get_coordinates(ring)
            x0, y0, x1, y1 = xy[:-1, 0], xy[:-1, 1], xy[1:, 0], xy[1:, 1]
            cross = x0 * y1 - x1 * y0
            jr = np.sum(cross * (x0 * x0 + x0 * x1 + x1 * x1 + y0 * y0 + y0 * y1 + y1 * y1)) / 12
            j += jr  # interior rings are clockwise after orient: negative moment
    return math.sqrt(j / chip.area)


# --------------------------------------------------------------------- steppers
@dataclass(frozen=True)
class ReferenceRun:
    """A reference trajectory.

    path: (N, 3) poses (x_um, y_um, twist_deg), start first; overlap_um2: (N,) overlaps.
    steps: moves taken. status: "converged" (no move improves) or "max_steps".
    evaluations: exact overlaps computed (memoized for greedy).
    """

    path: np.ndarray
    overlap_um2: np.ndarray
    steps: int
    status: str
    evaluations: int

    @property
    def final(self) -> tuple[float, float, float]:
        x, y, t = (float(v) for v in self.path[-1])
        return x, y, t


class ExactOverlap:
    """Exact overlap on the pose grid ``(ix step_um, iy step_um, it step_deg)``, memoized.

    ``self(idx)`` takes an (M, 3) integer array of (it, iy, ix) and returns (M,) overlaps
    (um^2), clipping only the poses not seen before (docs/physics.md §5.2, step 3).
    """

    def __init__(
        self, pattern: BaseGeometry, chip: BaseGeometry, step_um: float = 1.0, step_deg: float = 1.0
    ):
        self.pattern, self.chip = pattern, chip
        self.step_um = positive("step_um", step_um, "um")
        self.step_deg = positive("step_deg", step_deg, "degrees")
        self.memo: dict[tuple[int, ...], float] = {}  # (it, iy, ix) -> um^2

    def pose(self, idx) -> np.ndarray:
        idx = np.asarray(idx, dtype=np.float64)
        return np.stack(
            [idx[..., 2] * self.step_um, idx[..., 1] * self.step_um, idx[..., 0] * self.step_deg],
            axis=-1,
        )

    def __call__(self, idx) -> np.ndarray:
        keys = [tuple(int(v) for v in row) for row in np.atleast_2d(idx)]
        missing = list(dict.fromkeys(k for k in keys if k not in self.memo))
        if missing:
            vals = overlap_um2(self.pattern, self.chip, self.pose(np.array(missing)))
            self.memo.update(zip(missing, vals.tolist(), strict=True))
        return np.array([self.memo[k] for k in keys])


def exact_greedy(
    pattern: BaseGeometry,
    chip: BaseGeometry,
    start,
    step_um: float = 1.0,
    step_deg: float = 1.0,
    max_steps: int = 5000,
    tie_um2: float | None = None,
    evaluator: ExactOverlap | None = None,
) -> ReferenceRun:
    """Greedy ascent on the exact overlap (docs/physics.md §5.2) with its tie rule.

    Args:
        start: (x_um, y_um, twist_deg), snapped to the nearest grid pose (``np.round``,
            as :func:`simulator.motion.simulate` does).
        step_um, step_deg: the move of one step (match a raster's um_per_px and twist step).
        max_steps: at most this many moves.
        tie_um2: overlaps within this are ties (default ``TIE_PER_UM2 * chip area``).
        evaluator: a shared :class:`ExactOverlap` (its memo carries over between runs).
    """
    ev = evaluator or ExactOverlap(pattern, chip, step_um, step_deg)
    tie = TIE_PER_UM2 * chip.area if tie_um2 is None else float(tie_um2)
    s = np.asarray(start, float)
    idx = np.round([s[2] / ev.step_deg, s[1] / ev.step_um, s[0] / ev.step_um]).astype(np.int64)
    path, areas = [idx.copy()], [float(ev(idx[None])[0])]
    status = "max_steps"
    for _ in range(max_steps):
        nb = idx[None] + GREEDY_MOVES
        a = ev(nb)
        choice = int(np.argmax(a >= a.max() - tie))  # first tie in the documented order
        if choice == 0:
            status = "converged"
            break
        idx = nb[choice]
        path.append(idx.copy())
        areas.append(float(a[choice]))
    else:
        if not np.any(ev(idx[None] + GREEDY_MOVES[1:]) > ev(idx[None])[0] + tie):
            status = "converged"
    return ReferenceRun(
        ev.pose(np.array(path)), np.array(areas), len(path) - 1, status, len(ev.memo)
    )


def exact_gradient_descent(
    pattern: BaseGeometry,
    chip: BaseGeometry,
    start,
    step_um: float = 1.0,
    step_deg: float = 1.0,
    max_steps: int = 5000,
    min_step_px: float = 1e-2,
    rg_um: float | None = None,
    force_scale_um2: float | None = None,
    tie_um2: float | None = None,
) -> ReferenceRun:
    """Steepest descent of :func:`simulator.motion.gradient_descent` on the exact overlap.

    The same algorithm in the same units: a "px" is ``step_um``, twist is measured as arc
    length at the chip's radius of gyration, the trial step is ``-grad / g_ref`` (at most
    1 px) with ``g_ref = A_max / (2 rg + 1)`` (px^2 per px) and is halved until the overlap
    grows, down to ``min_step_px``. The gradient is exact (central differences of 1e-3 um
    and 1e-3 degrees instead of one grid step of an interpolated landscape).

    Args:
        rg_um: radius of gyration (default: exact, :func:`radius_of_gyration_um`).
        force_scale_um2: A_max, the largest overlap (default min(|pattern|, |chip|)).
    """
    s_um = positive("step_um", step_um, "um")
    s_deg = positive("step_deg", step_deg, "degrees")
    tie = TIE_PER_UM2 * chip.area if tie_um2 is None else float(tie_um2)
    rg_px = (radius_of_gyration_um(chip) if rg_um is None else float(rg_um)) / s_um
    metric = np.array([math.radians(s_deg) * rg_px, 1.0, 1.0])  # index units -> px
    a_max = (
        min(pattern.area, chip.area) if force_scale_um2 is None else float(force_scale_um2)
    ) / s_um**2
    g_ref = a_max / (2 * rg_px + 1)
    to_idx = np.array([1 / s_deg, 1 / s_um, 1 / s_um])  # (twist, y, x) physical -> index

    def area(q: np.ndarray) -> np.ndarray:  # q: (M, 3) index units (it, iy, ix) -> px^2
        return (
            overlap_um2(
                pattern, chip, np.stack([q[:, 2] * s_um, q[:, 1] * s_um, q[:, 0] * s_deg], axis=1)
            )
            / s_um**2
        )

    s0 = np.asarray(start, float)
    q = np.array([s0[2], s0[1], s0[0]]) * to_idx
    a = float(area(q[None])[0])
    path, areas, evals = [q.copy()], [a], 1
    status = "max_steps"
    for _ in range(max_steps):
        pose = np.array([[q[2] * s_um, q[1] * s_um, q[0] * s_deg]])
        g = gradient_um2(pattern, chip, pose)[0]  # dA/dx, dA/dy (um), dA/dtwist (per rad)
        g = np.where(np.abs(g) * 2 * H_DIFF <= tie, 0.0, g)  # differences at round-off: flat
        g_idx = (
            np.array([g[2] * math.radians(s_deg), g[1] * s_um, g[0] * s_um]) / s_um**2
        )  # px^2 per index
        evals += 6
        d = g_idx / metric / g_ref  # ascent on A = descent on E, in px
        dlen = float(np.sqrt(np.sum(d * d)))
        if dlen == 0:
            status = "converged"
            break
        if dlen > 1:
            d, dlen = d / dlen, 1.0
        scale = 1.0
        a_new = float(area((q + d / metric)[None])[0])
        evals += 1
        while a_new <= a and scale * dlen >= min_step_px:
            scale /= 2
            a_new = float(area((q + scale * d / metric)[None])[0])
            evals += 1
        if a_new <= a:
            status = "converged"
            break
        q = q + scale * d / metric
        a = a_new
        path.append(q.copy())
        areas.append(a)
    p = np.array(path)
    poses = np.stack([p[:, 2] * s_um, p[:, 1] * s_um, p[:, 0] * s_deg], axis=1)
    return ReferenceRun(poses, np.array(areas) * s_um**2, len(path) - 1, status, evals)
