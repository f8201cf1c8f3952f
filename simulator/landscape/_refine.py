"""Poses below the grid: a continuous minimum of the interpolated landscape, and the
stiffness of the well there.

With a finite meniscus (:mod:`simulator.physics`) the energy is smooth on the scale of
the meniscus height, so its minimum lies between grid poses and can be found by a
continuous minimization: the landscape around a grid pose is interpolated by cubic
splines (a block of 9 x 9 poses and up to 7 twists; periodic twists wrap) and the
interpolant is minimized by L-BFGS-B within 1.5 grid steps of that pose. For the
overlap model (a V-shaped cusp at alignment) this refinement would only move the pose
by round-off and is not used.

The stiffness is the curvature of the interpolant at the refined pose, by central
differences of one grid step: ``k_x = d2E/dx2`` (N/m), ``k_y`` and ``k_twist =
d2E/dtwist2`` (N m/rad).
"""

from __future__ import annotations

import math

import numpy as np

from simulator.core import UM

#: Half-size (grid steps) of the block interpolated around a pose: translations, twists.
BLOCK_XY, BLOCK_T = 4, 3
#: The refined pose stays within this many grid steps of the grid pose it started from.
REACH_STEPS = 1.5
#: L-BFGS-B settings of :func:`refine_minimum`, on energies scaled to one grid step's change
#: (about 1) and grid-index coordinates: stop when the scaled energy drops by under 1e-14
#: relative (ftol) or its largest projected gradient is under 1e-10 (gtol); finite-difference
#: step 1e-6 grid steps (eps).
LBFGS_OPTIONS = {"ftol": 1e-14, "gtol": 1e-10, "eps": 1e-6}


class _Local:
    """Cubic-spline interpolant of a landscape block around grid index (it, iy, ix)."""

    def __init__(self, ls, it: int, iy: int, ix: int):
        from scipy import ndimage

        nt, ny, nx = ls.energy.shape
        self.ls = ls
        ys = np.clip(np.arange(iy - BLOCK_XY, iy + BLOCK_XY + 1), 0, ny - 1)
        xs = np.clip(np.arange(ix - BLOCK_XY, ix + BLOCK_XY + 1), 0, nx - 1)
        if nt == 1:
            ts = np.array([0])
        elif ls.wrap:
            ts = np.mod(np.arange(it - BLOCK_T, it + BLOCK_T + 1), nt)
        else:
            ts = np.clip(np.arange(it - BLOCK_T, it + BLOCK_T + 1), 0, nt - 1)
        block = np.asarray(ls.energy, np.float64)[np.ix_(ts, ys, xs)]
        self.origin = (it - (BLOCK_T if nt > 1 else 0), iy - BLOCK_XY, ix - BLOCK_XY)
        self.scale = float(np.abs(block).max()) or 1.0
        self.coeffs = (
            ndimage.spline_filter(block / self.scale, order=3, mode="nearest")
            if block.size > 1
            else block / self.scale
        )
        self.nt = nt
        self.bounds = (
            (it - REACH_STEPS, it + REACH_STEPS) if nt > 1 else (it, it),
            (max(iy - REACH_STEPS, 0), min(iy + REACH_STEPS, ny - 1)),
            (max(ix - REACH_STEPS, 0), min(ix + REACH_STEPS, nx - 1)),
        )

    def __call__(self, idx) -> float:
        from scipy import ndimage

        it, iy, ix = idx
        c = np.array(
            [
                [it - self.origin[0] if self.nt > 1 else 0.0],
                [iy - self.origin[1]],
                [ix - self.origin[2]],
            ]
        )
        return (
            float(
                ndimage.map_coordinates(self.coeffs, c, order=3, mode="nearest", prefilter=False)[0]
            )
            * self.scale
        )

    def pose(self, idx) -> tuple[float, float, float]:
        it, iy, ix = idx
        ls = self.ls
        x = float(ls.x_um[0] + ix * ls.um_per_px)
        y = float(ls.y_um[0] + iy * ls.um_per_px)
        t = (
            float(ls.twist_deg[0] + it * ls.twist_step_deg)
            if self.nt > 1
            else float(ls.twist_deg[0])
        )
        if ls.wrap and self.nt > 1:
            p = ls.period_deg
            t = (t - ls.twist_deg[0]) % p + ls.twist_deg[0]
        return x, y, t


def _grid_index(ls, x_um: float, y_um: float, twist_deg: float) -> tuple[int, int, int]:
    ix = int(np.argmin(np.abs(ls.x_um - x_um)))
    iy = int(np.argmin(np.abs(ls.y_um - y_um)))
    d = np.asarray(ls.twist_deg) - twist_deg
    if ls.wrap:
        d = (d + ls.period_deg / 2) % ls.period_deg - ls.period_deg / 2
    return int(np.argmin(np.abs(d))), iy, ix


def refine_minimum(ls, x_um: float, y_um: float, twist_deg: float) -> dict:
    """The minimum of the interpolated landscape within 1.5 grid steps of the grid pose
    nearest (x, y, twist): ``{"x_um", "y_um", "twist_deg", "energy_J"}``."""
    from scipy.optimize import minimize

    it, iy, ix = _grid_index(ls, x_um, y_um, twist_deg)
    f = _Local(ls, it, iy, ix)
    x0 = np.array([it, iy, ix], float)
    e0 = f(x0)
    span = max(abs(e0 - f(x0 + d)) for d in np.eye(3)) or 1.0  # the energy scale of one grid step

    def g(v):
        return (f(v) - e0) / span

    res = minimize(g, x0, method="L-BFGS-B", bounds=f.bounds, options=dict(LBFGS_OPTIONS))  # pyright: ignore[reportCallIssue, reportArgumentType]  (scipy-stubs wants its private TypedDict)
    best = res.x if res.fun <= 0 else x0
    x, y, t = f.pose(best)
    return {"x_um": x, "y_um": y, "twist_deg": t, "energy_J": float(f(best))}


def stiffness(ls, x_um: float, y_um: float, twist_deg: float) -> dict:
    """Curvature of the interpolated energy at a pose: ``{"x_N_per_m", "y_N_per_m",
    "twist_Nm_per_rad"}`` (twist None on a twist-free grid)."""
    it, iy, ix = _grid_index(ls, x_um, y_um, twist_deg)
    f = _Local(ls, it, iy, ix)
    s_m = ls.um_per_px * UM
    dt = twist_deg - float(ls.twist_deg[it])
    if ls.wrap:
        dt = (dt + ls.period_deg / 2) % ls.period_deg - ls.period_deg / 2
    c = np.array(
        [
            it + dt / ls.twist_step_deg if len(ls.twist_deg) > 1 else it,
            iy + (y_um - float(ls.y_um[iy])) / ls.um_per_px,
            ix + (x_um - float(ls.x_um[ix])) / ls.um_per_px,
        ]
    )
    e0 = f(c)

    def second(axis: int) -> float:
        d = np.zeros(3)
        d[axis] = 1.0
        return f(c + d) + f(c - d) - 2 * e0

    out = {
        "x_N_per_m": second(2) / s_m**2,
        "y_N_per_m": second(1) / s_m**2,
        "twist_Nm_per_rad": None,
    }
    if len(ls.twist_deg) > 1:
        out["twist_Nm_per_rad"] = second(0) / math.radians(ls.twist_step_deg) ** 2
    return out
