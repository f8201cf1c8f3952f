"""The free-form objective: smooth terms of the overlap planes, each to be made large.

All in overlap units (px^2 of chip over wettable pattern), normalised so that every term is
of order one: energies by the chip's area ``A_c`` (the deepest well, docs/physics.md C8),
forces and stiffnesses by its side ``L = sqrt(A_c)``. With ``Delta_gamma < 0`` (pads wet
better than the substrate, docs/physics.md §2), a larger overlap is a lower energy and the
force ``-grad E = |Delta_gamma| grad A`` points up the overlap (docs/physics.md §3.4):

* ``capture``: the soft minimum, over the ring of start poses ``r0 <= |p| <= r1`` around
  the target at its twist, of the inward force component ``-grad A . p / |p|`` (central
  differences over one pixel): a chip started anywhere on the ring is pulled inwards;
* ``gap``: the soft minimum over the poses outside the ball ``|p| > r`` (target twist) of
  ``A(target) - A(p)``: the target is the deepest well by that margin, no other local
  minimum comes near it;
* ``orientation``: the soft minimum over every translation at each other twist asked for
  (90, 180, 270 degrees by default) of ``A(target) - A(p, twist)``: the chip turned has no
  well as deep as the target's. A chip whose wettable underside repeats under a turn has
  the same energy there for every pattern; :func:`simulator.design.load_freeform` refuses
  such a twist;
* ``stiffness``: ``-(A(+d) + A(-d) - 2 A(0))`` along x plus along y at the target, over the
  step ``d``: the well's curvature (the overlap cusp measured over ``d``);
* ``depth``: ``A(target)``; ``area``: minus the pattern's wettable area (a cost).

The soft minimum ``-T log(mean exp(-v / T))`` lies between the minimum and the mean and
tends to the minimum as the temperature ``T`` falls; the temperatures are given in J (or N)
and divided by the same scales.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simulator.core import UM, UM2

__all__ = ["Objective", "make_objective", "softmin"]


def softmin(v, temperature):
    """``-T log(mean(exp(-v / T)))``: between min(v) and mean(v), smooth in v."""
    import jax.numpy as jnp
    from jax.scipy.special import logsumexp

    v = jnp.ravel(v)
    return -temperature * (logsumexp(-v / temperature) - jnp.log(v.size))


@dataclass(frozen=True, eq=False)
class Objective:
    """The objective's fixed parts (:func:`make_objective`): weights, temperatures (in the
    normalised units) and the pose sets as static index arrays into a plane.

    scales: each term's normalised unit in physical units (``capture`` N, ``gap`` and
    ``orientation`` and ``depth`` J, ``stiffness`` N/m, ``area`` um^2), for the history.
    """

    weights: dict
    temperatures: dict
    ry: int
    rx: int
    ring: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None
    outside: np.ndarray | None
    step_px: int
    area_px2: float
    side_px: float
    scales: dict

    def terms(self, planes, w, hard: bool = False) -> dict:
        """{term: normalised value} of the overlap ``planes`` (T, Ny, Nx; plane 0 the target
        twist, then the orientation twists) of the pattern ``w``; weighted terms only.
        ``hard``: the plain minima instead of the soft ones (for reports, not gradients)."""
        import jax.numpy as jnp

        def low(v, name):
            return jnp.min(v) if hard else softmin(v, self.temperatures[name])

        a0 = planes[0]
        at = a0[self.ry, self.rx]
        out = {}
        wt = self.weights
        if wt["depth"] > 0:
            out["depth"] = at / self.area_px2
        if wt["capture"] > 0:
            assert self.ring is not None  # made whenever capture is weighted (make_objective)
            iy, ix, ux, uy = self.ring
            gx = 0.5 * (a0[iy, ix + 1] - a0[iy, ix - 1])
            gy = 0.5 * (a0[iy + 1, ix] - a0[iy - 1, ix])
            inward = -(gx * ux + gy * uy) / self.side_px
            out["capture"] = low(inward, "capture")
        if wt["gap"] > 0:
            v = (at - a0.ravel()[self.outside]) / self.area_px2
            out["gap"] = low(v, "gap")
        if wt["orientation"] > 0:
            v = (at - planes[1:]) / self.area_px2
            out["orientation"] = low(v, "orientation")
        if wt["stiffness"] > 0:
            d, y, x = self.step_px, self.ry, self.rx
            kx = -(a0[y, x + d] + a0[y, x - d] - 2 * at) / d**2
            ky = -(a0[y + d, x] + a0[y - d, x] - 2 * at) / d**2
            out["stiffness"] = (kx + ky) / self.side_px
        if wt["area"] > 0:
            out["area"] = -jnp.sum(w) / self.area_px2
        return out

    def total(self, terms: dict):
        """The weighted sum of the terms (to be made large)."""
        return sum(self.weights[k] * v for k, v in terms.items())

    def physical(self, terms: dict) -> dict:
        """{name_unit: value}: the terms in physical units (floats)."""
        units = {
            "capture": "capture_N",
            "gap": "gap_J",
            "orientation": "orientation_J",
            "stiffness": "stiffness_N_per_m",
            "depth": "depth_J",
            "area": "area_um2",
        }
        return {units[k]: float(v) * self.scales[k] for k, v in terms.items()}


def make_objective(terms: dict, side, scene) -> Objective:
    """The objective of the spec's ``terms`` (:class:`simulator.design.FreeformSpec`) on the
    planes of ``side`` (:class:`simulator.design.ChipSide`)."""
    s = side.um_per_px
    ry, rx = side.ry, side.rx
    area = side.chip_area_px2
    length = float(np.sqrt(area))
    dg = abs(scene.delta_gamma_N_m)
    e_unit = dg * area * s * s * UM2  # J per normalised energy
    f_unit = dg * length * s * UM  # N per normalised force
    k_unit = dg * length  # N/m per normalised stiffness (overlap px^2 per px^2 is N/m / |dg|)
    weights = {k: v["weight"] for k, v in terms.items()}
    temps = {
        "capture": terms["capture"].get("temperature_N", 0.02 * f_unit) / f_unit,
        "gap": terms["gap"].get("temperature_J", 0.01 * e_unit) / e_unit,
        "orientation": terms["orientation"].get("temperature_J", 0.01 * e_unit) / e_unit,
    }
    Y, X = np.meshgrid(np.arange(-ry, ry + 1), np.arange(-rx, rx + 1), indexing="ij")
    r_px = np.hypot(X, Y)
    ring = None
    if weights["capture"] > 0:
        r0, r1 = (v / s for v in terms["capture"]["radius_um"])
        sel = (r_px >= r0) & (r_px <= r1) & (r_px > 0)
        sel[[0, -1], :] = False
        sel[:, [0, -1]] = False
        iy, ix = np.nonzero(sel)
        rr = r_px[iy, ix]
        ring = (iy, ix, X[iy, ix] / rr, Y[iy, ix] / rr)
    outside = None
    if weights["gap"] > 0:
        outside = np.flatnonzero((r_px > terms["gap"]["radius_um"] / s).ravel())
    step = max(1, int(round(terms["stiffness"]["step_um"] / s)))
    return Objective(
        weights=weights,
        temperatures=temps,
        ry=ry,
        rx=rx,
        ring=ring,
        outside=outside,
        step_px=step,
        area_px2=area,
        side_px=length,
        scales={
            "capture": f_unit,
            "gap": e_unit,
            "orientation": e_unit,
            "stiffness": k_unit,
            "depth": e_unit,
            "area": area * s * s,
        },
    )
