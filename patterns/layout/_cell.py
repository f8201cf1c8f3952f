"""One flattened layout cell (:class:`Layout`) and its outline rings merged into exact geometry.

A reader (``_gds``, ``_dxf``) gives the closed rings of
every layer; :meth:`Layout.geometry` turns one layer's rings into valid polygons (a GDS
keyhole is a polygon with a hole, a polygon that crosses itself is refused) and merges
them (DXF: an outline inside another is a hole, by nesting depth).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from foundation import InputError
from patterns.layout._formats import _MAX_LISTED, _count, _layer_key, _layer_text


# --------------------------------------------------------------------------- the layout
@dataclass(frozen=True, eq=False)
class Layout:
    """One cell of a layout file, flattened: the outline rings of every layer.

    Attributes:
        path: the file.
        format: ``"gds"``, ``"oas"`` or ``"dxf"``.
        cell: the cell read (``"modelspace"`` or a block name for DXF).
        units: how the coordinates were converted, in words.
        dbu_um: the database unit (DXF: the snapping grid), um.
        rings: per layer key, the closed rings (n, 2) in um, layout frame, not repeated at the end.
        problems: per layer key, the first open or unsupported shape (raised when that layer is read).
    """

    path: Path
    format: str
    cell: str
    units: str
    dbu_um: float
    rings: dict = field(default_factory=dict)
    problems: dict = field(default_factory=dict)

    def layers_text(self) -> str:
        """``1/0 (4 polygons), 2/0 (1 polygon)``: every layer with its polygon count."""
        keys = sorted(set(self.rings) | set(self.problems), key=lambda k: (isinstance(k, str), k))
        items = [
            f"{_layer_text(k)} ({_count(len(self.rings.get(k, [])), 'polygon')}{', and a shape that is no closed outline' if k in self.problems else ''})"
            for k in keys
        ]
        more = f", ... ({len(items) - _MAX_LISTED} more)" if len(items) > _MAX_LISTED else ""
        return ", ".join(items[:_MAX_LISTED]) + more if items else "none"

    def key(self, layer: Any, flag: str = "--layer") -> Any:
        """The layer key of ``layer`` (text as the flags take it), checked to exist."""
        key = _layer_key(layer, self.format, flag)
        if (
            isinstance(key, str) and key not in self.rings and key not in self.problems
        ):  # DXF layer names ignore case
            key = next(
                (k for k in (*self.rings, *self.problems) if k.casefold() == key.casefold()), key
            )
        if key not in self.rings and key not in self.problems:
            raise InputError(
                f"{self.path}: cell {self.cell} has nothing on layer {_layer_text(key)}; "
                f"layers present: {self.layers_text()}; choose one with {flag}"
            )
        return key

    def geometry(self, key: Any) -> BaseGeometry:
        """The merged (Multi)Polygon of one layer (um, layout frame), or InputError."""
        where = f"{self.path}: cell {self.cell}, layer {_layer_text(key)}"
        if key in self.problems:
            raise InputError(f"{where}: {self.problems[key]}")
        rings = self.rings.get(key, [])
        polys, nested = _polygons(rings, where), self.format == "dxf"
        if not polys:
            raise InputError(
                f"{where}: the layer is empty (no polygon with an area); choose another layer, present: {self.layers_text()}"
            )
        return _merge(polys, nested)


# --------------------------------------------------------------------------- rings -> geometry
def _shoelace(r: np.ndarray) -> float:
    x, y = r[:, 0], r[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _polygons(rings: list[np.ndarray], where: str) -> list[Polygon]:
    """Valid polygons of the rings with an area; keyholes become holes; crossings are refused.

    Built vectorized (one shapely call for every ring of the layer; a layer of a million small
    polygons takes seconds, not minutes); only the rings that are not valid polygons as drawn
    are looked at one by one.
    """
    if not rings:
        return []
    sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=len(rings))
    coords = np.concatenate([np.asarray(r, dtype=np.float64).reshape(-1, 2) for r in rings])
    ring_of = np.repeat(np.arange(len(rings)), sizes)
    finite = np.ones(len(rings), dtype=bool)
    bad = ~np.isfinite(coords).all(axis=1)
    finite[ring_of[bad]] = False
    keep = np.ones(
        len(coords), dtype=bool
    )  # a ring that repeats its first vertex at its end: the repeat dropped
    ends = np.cumsum(sizes) - 1
    has = sizes > 1
    closed = np.zeros(len(rings), dtype=bool)
    closed[has] = (coords[ends[has]] == coords[ends[has] - sizes[has] + 1]).all(axis=1)
    keep[ends[closed]] = False
    use = np.flatnonzero((sizes - closed >= 3) & finite)
    if not use.size:
        return []
    pick = np.isin(ring_of, use) & keep
    # linearrings closes every ring (the rings are stored without their closing vertex).
    polys = cast(  # an array of polygons, one per ring in use
        "npt.NDArray[np.object_]",
        shapely.polygons(
            shapely.linearrings(coords[pick], indices=np.searchsorted(use, ring_of[pick]))
        ),
    )
    valid = shapely.is_valid(polys)
    if valid.all():
        return list(polys)
    out = []
    for i, poly, ok in zip(use.tolist(), polys, valid.tolist(), strict=True):
        if ok:
            out.append(poly)
            continue
        r = rings[i]
        parts = [
            g
            for g in shapely.get_parts(shapely.make_valid(poly))
            if isinstance(g, Polygon) and g.area > 0
        ]
        area = sum(g.area for g in parts)
        if area == 0:
            continue  # a degenerate polygon (a line): no area
        if not math.isclose(
            area, abs(_shoelace(r)), rel_tol=1e-9, abs_tol=1e-12
        ):  # a keyhole keeps its area, a crossing does not
            m = re.search(r"\[([-\d.e+]+) ([-\d.e+]+)\]", shapely.is_valid_reason(poly))
            near = f" near ({float(m[1]):.6g}, {float(m[2]):.6g}) um" if m else ""
            raise InputError(
                f"{where}: polygon {i + 1} of {len(rings)} crosses itself{near}; "
                "split it into simple polygons in the layout editor"
            )
        out.extend(parts)
    return out


def _merge(polys: list[Polygon], nested: bool) -> BaseGeometry:
    """Union of the polygons (DXF: an outline inside another outline is a hole, by nesting depth)."""
    if nested and len(polys) > 1:
        unique = list(
            {shapely.normalize(p).wkb: p for p in polys}.values()
        )  # the same outline drawn twice counts once
        outer, inner = shapely.STRtree(unique).query(unique, predicate="contains")
        keep = outer != inner
        depth = np.bincount(inner[keep], minlength=len(unique))  # how many outlines hold each one
        geom = shapely.union_all([p for p, d in zip(unique, depth, strict=True) if d == 0])
        for d in range(1, int(depth.max()) + 1):
            level = shapely.union_all([p for p, k in zip(unique, depth, strict=True) if k == d])
            geom = geom.difference(level) if d % 2 else geom.union(level)
    elif len(polys) == 1:
        geom = polys[0]
    else:
        a, b = shapely.STRtree(polys).query(polys, predicate="intersects")
        geom = (
            shapely.multipolygons(polys) if np.all(a == b) else shapely.union_all(polys)
        )  # disjoint: vertices kept as drawn
    parts = shapely.get_parts(geom)
    parts = parts[
        (shapely.get_type_id(parts) == shapely.GeometryType.POLYGON) & (shapely.area(parts) > 0)
    ]
    geom = parts[0] if len(parts) == 1 else shapely.multipolygons(parts)
    return cast(BaseGeometry, shapely.orient_polygons(geom))  # one geometry in, one out
