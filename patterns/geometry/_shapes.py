"""The ideal pattern shapes as exact shapely geometry, and the helpers every builder shares.

Squares, rectangles, equal-area circles, the four-pad pattern and any simple polygon, in
micrometres, centred on the origin (``_designs`` states the conventions);
the exact quarter turn (:func:`rotate_quarter`) and the final orientation and validity
check of a builder's result.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import shapely
from shapely import affinity
from shapely.geometry import MultiPolygon, Polygon, box
from shapely.geometry.polygon import orient

from foundation import InputError, positive, require

EDGES = ("right", "top", "left", "bottom")  # counter-clockwise order; index = quarter turns


# ---------------------------------------------------------------------------- helpers


def _length(name: str, value: Any) -> float:
    return positive(name, value, "um")


def _choice(name: str, value: Any, allowed: Sequence[str]) -> str:
    if value not in allowed:
        raise InputError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")
    return str(value)


def rotate_quarter(geom: Any, quarter_turns: int) -> Any:
    """Rotate ``geom`` about the origin by ``90 * quarter_turns`` degrees counter-clockwise, exactly."""
    c, s = ((1, 0), (0, 1), (-1, 0), (0, -1))[quarter_turns % 4]
    return affinity.affine_transform(geom, [c, -s, s, c, 0, 0])


def _finish(geom: Any, what: str) -> Any:
    """Orient rings counter-clockwise and check validity (a bug guard for the builders)."""
    if isinstance(geom, Polygon):
        geom = orient(geom, 1.0)
    elif isinstance(geom, MultiPolygon):
        geom = MultiPolygon([orient(g, 1.0) for g in geom.geoms])
    if not geom.is_valid or geom.is_empty:
        raise InputError(
            f"{what}: the parameters give an invalid shape ({shapely.is_valid_reason(geom)})"
        )
    return geom


# ---------------------------------------------------------------------------- simple shapes


def rectangle(width: float, height: float) -> Polygon:
    """Axis-aligned rectangle ``width`` x ``height`` (um) centred on the origin."""
    w, h = _length("width", width), _length("height", height)
    return orient(box(-w / 2, -h / 2, w / 2, h / 2), 1.0)


def square(size: float) -> Polygon:
    """Square of side ``size`` (um) centred on the origin."""
    s = _length("size", size)
    return rectangle(s, s)


def circle(diameter: float, segments: int = 1024) -> Polygon:
    """Regular ``segments``-gon with the same area as the circle of ``diameter`` (um).

    Vertices sit at angles ``2 pi k / segments`` on radius
    ``r' = r sqrt(2 pi / (n sin(2 pi / n)))``, so the polygon's area equals ``pi r^2`` to
    rounding (no systematic area error). The boundary deviates from the true circle by less
    than ``r (pi/n)^2 / 3`` in radius: 3.2e-6 r for the default ``n = 1024``. ``segments``
    must be a multiple of 4 (>= 8) so the polygon keeps the square's symmetries.
    """
    r = _length("diameter", diameter) / 2
    n = segments
    require(
        isinstance(n, int | np.integer) and n >= 8 and n % 4 == 0,
        f"segments must be a multiple of 4 and >= 8, got {segments!r}",
    )
    r_eff = r * math.sqrt(2 * math.pi / (n * math.sin(2 * math.pi / n)))
    k = np.arange(n)
    # Quarter-turn-exact vertices: compute one quadrant and rotate it by swapping coordinates.
    ang = 2 * np.pi * k[: n // 4] / n
    q = np.column_stack([r_eff * np.cos(ang), r_eff * np.sin(ang)])
    quads = [q, np.column_stack([-q[:, 1], q[:, 0]]), -q, np.column_stack([q[:, 1], -q[:, 0]])]
    return orient(Polygon(np.vstack(quads)), 1.0)


def four_pad(size: float, gap: float) -> MultiPolygon:
    """Four square pads of side ``p = (size - gap)/2`` (docs/physics.md §6).

    The outer square has side ``size`` and includes the cross-shaped gap of width ``gap``;
    pads occupy ``[-L/2, -g/2] U [g/2, L/2]`` in x and in y; there is no border gap.
    """
    L, g = _length("size", size), _length("gap", gap)
    require(g < L, f"gap={g:g} um must be smaller than size={L:g} um (pads of side (size - gap)/2)")
    lo, hi = g / 2, L / 2
    pads = [
        box(x0, y0, x1, y1)
        for (x0, x1) in ((-hi, -lo), (lo, hi))
        for (y0, y1) in ((-hi, -lo), (lo, hi))
    ]
    return _finish(MultiPolygon(pads), "four-pad")


def polygon(points: Sequence[Sequence[float]]) -> Polygon:
    """Simple polygon through ``points`` [(x, y), ...] in um, in the pattern frame (not re-centred).

    Needs at least 3 finite points, no self-intersection and a positive area. The ring is
    closed automatically and oriented counter-clockwise.
    """
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"points must be a list of (x, y) pairs in um, got {points!r}") from None
    require(
        pts.ndim == 2 and pts.shape[1] == 2,
        f"points must be (x, y) pairs, got array of shape {pts.shape}",
    )
    require(bool(np.all(np.isfinite(pts))), "points must be finite numbers (um)")
    if len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
        pts = pts[:-1]
    require(len(pts) >= 3, f"points: a polygon needs at least 3 distinct points, got {len(pts)}")
    poly = Polygon(pts)
    require(
        poly.is_valid,
        f"points: the polygon is not simple ({shapely.is_valid_reason(poly)}); "
        "give the vertices in order along the boundary, without crossings",
    )
    require(poly.area > 0, "points: the polygon has zero area")
    return orient(poly, 1.0)
