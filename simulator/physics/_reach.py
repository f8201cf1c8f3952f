"""The reach of a curved liquid wall: how far beyond the chip's edge its contact line stands.

docs/physics.md §3.3 takes the wall that joins the chip's edge (height h) to the substrate as
flat, so its foot stands ``h cot(theta)`` beyond the edge. A free-height bridge (the chip
floats on the liquid, no load) has a positive pressure: the walls pull the chip down with
``gamma sin(phi)`` per unit length (``phi`` the wall's angle below the horizontal at the
chip's edge), and the liquid under the chip pushes it up with ``p A``. A wall along a
straight edge is then a circular arc of curvature ``kappa = p / gamma`` (constant mean
curvature, no curvature along the edge): from its foot at the Young angle ``theta`` it
turns flatter as it rises, so it reaches further than the flat wall.

For one straight wall (an arc from ``(-c, 0)``, where it meets the surface at ``theta``, to
the chip's edge ``(0, h)``, where its angle is ``phi``)::

    cos(phi) = cos(theta) + kappa h
    c = (sin(theta) - sin(phi)) / kappa                        (-> h cot(theta) as kappa -> 0)
    a = [(theta - phi)/2 - (sin 2theta - sin 2phi)/4 + sin(phi)(cos(theta) - cos(phi))] / kappa^2

with ``a`` the liquid's cross-section beyond the edge (-> h^2 cot(theta) / 2). A wall exists
only while ``cos(theta) + kappa h <= 1``: a steeper pressure makes the arc horizontal below
the chip's height.

The bridge's height and pressure follow from the volume, for a chip of area ``A`` whose edges
(lengths ``l_i``) stand on surfaces of angles ``theta_i``::

    kappa A = sum_i l_i sin(phi_i)          (the chip's vertical balance, no load)
    V = A h + sum_i l_i a_i                 (the volume)

Assumptions: the chip's edges pin the walls' tops (the Surface Evolver runs' condition;
the top angle is not checked against the edge's Gibbs window), straight edges, the corners
left out (their share of the perimeter is of order c / L), no gravity.

Against Surface Evolver (validation/FOURPAD.md, "The reach of a curved wall"): the 730 um
chip with 20 nl on its 60 deg substrate: h = 35.02 um, kappa = 0.00418 /um, substrate
reach 24.6 um (Surface Evolver aligned: 35.21, 0.00429, 24.9); the 200 um chip with 0.5 nl:
11.47, 0.01484, 8.35 (11.56, 0.0153, 8.5). The pad reach with one side of the chip on a
30 deg pad: 91.8 um (730/50) and 93.3 um (730/100), where the flat wall gives 65 um: the far
pads dry at 432 and 408 um, Surface Evolver's between 420 and 430 and between 390 and 400.
A bridged pad's walls still pull gamma (cos(theta_p) - cos(theta_s)) per unit length at any
pressure: the curvature moves where the pads dry, not the force while they are wet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.optimize import brentq


@dataclass(frozen=True)
class ArcWall:
    """One curved wall: ``reach_um`` (c), ``top_deg`` (phi, below the horizontal at the chip's
    edge), ``area_um2`` (a, the liquid's cross-section beyond the edge per unit length)."""

    reach_um: float
    top_deg: float
    area_um2: float


def arc_wall(h_um: float, curvature_per_um: float, angle_deg: float) -> ArcWall | None:
    """The arc of curvature ``curvature_per_um`` (the pressure over gamma; > 0 bulges out)
    from a surface of contact angle ``angle_deg`` up to the chip's edge at ``h_um`` (module
    docstring), or None where no such wall exists (``cos(theta) + kappa h > 1``)."""
    t = math.radians(angle_deg)
    k = float(curvature_per_um)
    if abs(k) * h_um < 1e-9:  # the flat wall (the series' first term)
        c = h_um / math.tan(t)
        return ArcWall(c, angle_deg, 0.5 * h_um * c)
    cp = math.cos(t) + k * h_um
    if cp > 1.0 or cp < -1.0:
        return None
    p = math.acos(cp)
    c = (math.sin(t) - math.sin(p)) / k
    a = (
        (t - p) / 2
        - (math.sin(2 * t) - math.sin(2 * p)) / 4
        + math.sin(p) * (math.cos(t) - math.cos(p))
    ) / k**2
    return ArcWall(c, math.degrees(p), a)


@dataclass(frozen=True)
class FreeBridge:
    """A free-height bridge under a chip (module docstring): ``h_um``, ``curvature_per_um``
    (the pressure over gamma), and its walls (``(length_um, angle_deg)`` each)."""

    h_um: float
    curvature_per_um: float
    walls: tuple[tuple[float, float], ...]

    def reach_um(self, angle_deg: float) -> float | None:
        """The reach of a wall at ``angle_deg`` at this bridge's height and pressure (None
        where no wall at that angle joins the chip's edge)."""
        w = arc_wall(self.h_um, self.curvature_per_um, angle_deg)
        return None if w is None else w.reach_um


def free_bridge(volume_um3: float, chip_area_um2: float, walls) -> FreeBridge:
    """The height and pressure of ``volume_um3`` under a chip of ``chip_area_um2`` floating
    free (no load), its edges' walls ``walls`` = ``[(length_um, angle_deg), ...]``: the root
    of the vertical balance and the volume (module docstring). Raises ValueError where no
    state with every wall joining the chip's edge exists."""
    walls = tuple((float(length), float(angle)) for length, angle in walls)
    A, V = float(chip_area_um2), float(volume_um3)
    if A <= 0 or V <= 0 or not walls:
        raise ValueError("free_bridge needs a positive volume, a chip area and walls")

    def pressure(h: float) -> float | None:
        # kappa A = sum l sin(phi(kappa)); no wall exists beyond kappa_max
        k_max = min((1 - math.cos(math.radians(t))) / h for _, t in walls)

        def balance(k: float) -> float:
            s = 0.0
            for length, t in walls:
                w = arc_wall(h, k, t)
                s += length * math.sin(math.radians(w.top_deg if w else 0.0))
            return k * A - s

        if balance(k_max) < 0:
            return None
        return brentq(balance, 0.0, k_max, xtol=1e-15, rtol=1e-13)

    def excess(h: float) -> float:
        k = pressure(h)
        assert k is not None
        held = 0.0
        for length, t in walls:
            w = arc_wall(h, k, t)
            held += length * (w.area_um2 if w is not None else 0.0)  # None: only at round-off
        return A * h + held - V

    h_hi = V / A  # the walls hold liquid: the height is below the volume over the area
    if pressure(h_hi) is None:
        # the balance has a root only below some height (a flat wall's arc turns horizontal
        # below the chip at higher ones): the highest height that has one, by bisection
        lo, hi = 0.0, h_hi
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if pressure(mid) is not None else (lo, mid)
        if lo <= 0.0:
            raise ValueError("no free-height bridge with every wall joining the chip's edge")
        h_hi = lo
    if excess(h_hi) < 0:
        raise ValueError("no free-height bridge with every wall joining the chip's edge")
    h = brentq(excess, 1e-9 * h_hi, h_hi, xtol=1e-12, rtol=1e-13)
    k = pressure(h)
    if k is None:
        raise ValueError("no free-height bridge with every wall joining the chip's edge")
    return FreeBridge(h, k, walls)


def curved_reaches(
    volume_um3: float,
    chip_side_um: float,
    pad_side_um: float,
    pad_deg: float,
    substrate_deg: float,
    receding_deg: float | None = None,
) -> tuple[float, float | None]:
    """The footprint relay's two reaches (um) with curved walls, for a square chip of side
    ``chip_side_um`` (docs/physics.md §3.5; validation/FOURPAD.md):

    * ``d_s``, where a dry pad is reached: the substrate wall's reach with every edge on the
      substrate;
    * ``d_r``, where a wet pad the chip has left dries: the reach of the wall at the pads'
      receding angle (their Young angle without hysteresis) with ``pad_side_um`` of one side
      on the pad and the rest of the edges on the substrate; None where no wall at that angle
      joins the chip's edge at that pressure (a receding angle below the bridge's flattest
      wall: the line cannot recede by a wall, and Surface Evolver's held runs instead draw a
      dome on the far pads, validation/FOURPAD_BENCH.md).
    """
    L = float(chip_side_um)
    rec = float(pad_deg if receding_deg is None else receding_deg)
    sub = free_bridge(volume_um3, L * L, [(4 * L, substrate_deg)])
    d_s = sub.reach_um(substrate_deg)
    assert d_s is not None  # the bridge's own walls join the edge by construction
    walls = [(4 * L - pad_side_um, substrate_deg), (pad_side_um, rec)]
    try:
        on_pad = free_bridge(volume_um3, L * L, walls)
    except ValueError:
        return d_s, None
    return d_s, on_pad.reach_um(rec)
