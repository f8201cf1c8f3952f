"""Reading DXF drawings with ezdxf (imported only when such a file is read).

The model space or a block (``--cell``), INSERT and MINSERT expanded (a block's layer-0
entities take the INSERT's layer), priced before it is flattened; units from
``$INSUNITS`` or ``--dxf-units``; closed polylines (bulges sampled on the true arcs),
circles, full ellipses, solids, traces, 3D faces and polyline-bounded hatches as outline
rings snapped to the 1 nm grid; open or unsupported shapes recorded as the layer's problem.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from foundation import InputError, require_fits
from patterns.layout._cell import Layout
from patterns.layout._formats import (
    _MAX_LISTED,
    BYTES_PER_POLYGON,
    BYTES_PER_VERTEX,
    DBU_UM,
    DXF_UNITS,
    INSUNITS,
    MAX_COORD_UM,
    MAX_DEPTH,
    _count,
    _on_grid,
    require_polygon_count,
)


# --------------------------------------------------------------------------- DXF
def _read_dxf(
    path: Path,
    cell: str | None,
    dxf_units: str | None,
    budget_mb: float | None,
    max_polygons: int | None = None,
) -> Layout:
    from ezdxf import filemanagement
    from ezdxf.lldxf.const import DXFError

    log = logging.getLogger("ezdxf")
    disabled, log.disabled = log.disabled, True  # ezdxf logs repairs; the result speaks for itself
    try:
        doc = filemanagement.readfile(str(path))
    except Exception as err:  # noqa: BLE001 - any parser failure on user input is bad input
        raise InputError(
            f"{path}: not a readable DXF file ({type(err).__name__}: {' '.join(str(err).split())[:200]}); "
            "export it again from the drawing program"
        ) from None
    finally:
        log.disabled = disabled
    code = doc.header.get("$INSUNITS", 0)
    if code:
        if code not in INSUNITS:
            raise InputError(
                f"{path}: $INSUNITS = {code} is not a length unit selfalign reads; save the drawing in um, mm or nm"
            )
        name, factor = INSUNITS[code]
        if dxf_units is not None and not math.isclose(DXF_UNITS[dxf_units], factor):
            raise InputError(
                f"{path}: the file states its units ($INSUNITS {name}) and --dxf-units says {dxf_units}; drop --dxf-units"
            )
        units = f"$INSUNITS {name}"
    elif dxf_units is None:
        raise InputError(
            f"{path}: the DXF file states no units ($INSUNITS); pass --dxf-units um, mm or nm"
        )
    else:
        name, factor = dxf_units, DXF_UNITS[dxf_units]
        units = f"--dxf-units {name} (the file states none)"
    if cell is None:
        space, cell_name = doc.modelspace(), "modelspace"
    else:
        space, cell_name = doc.blocks.get(cell), cell
        if space is None:
            blocks = [b for b in doc.blocks if not b.name.startswith("*")]
            listed = ", ".join(
                f"{b.name} ({_count(len(b), 'entity')})".replace("entitys", "entities")
                for b in blocks[:_MAX_LISTED]
            )
            raise InputError(
                f"{path}: no block named {cell!r}; blocks present: {listed or 'none'} (or omit --cell for the model space)"
            )
    n = _dxf_size(space, doc, {}, ())
    require_polygon_count(n, f"{path}: {cell_name} (counting its entities)", max_polygons)
    require_fits(
        f"flattening {cell_name} of {path} ({n:,} entities)",
        n * BYTES_PER_POLYGON * 4,
        "choose a smaller --cell",
        budget_mb,
    )
    rings: dict[str, list[np.ndarray]] = {
        layer.dxf.name: [] for layer in doc.layers if layer.dxf.name not in ("0", "Defpoints")
    }
    problems: dict[str, str] = {}
    try:
        for layer, entity in _dxf_entities(space, None, 0, f"{path}: {cell_name}"):
            ring, problem = _dxf_ring(entity, factor, budget_mb)
            if problem:
                problems.setdefault(layer, problem)
            else:
                rings.setdefault(layer, []).extend(_on_grid(r) for r in ring)
    except DXFError as err:
        raise InputError(
            f"{path}: cannot flatten {cell_name} ({err}); explode the block references in the drawing program"
        ) from None
    return Layout(path, "dxf", cell_name, units, DBU_UM, rings, problems)


def _dxf_size(space: Any, doc: Any, memo: dict, stack: tuple) -> int:
    """Entities of ``space`` once every INSERT is expanded, counted without expanding them."""
    total = 0
    for e in space:
        if e.dxftype() != "INSERT":
            total += 1
            continue
        name = e.dxf.name
        if name in stack or len(stack) > MAX_DEPTH:
            raise InputError(
                f"block {name} inserts itself or nests deeper than {MAX_DEPTH} levels; fix the drawing"
            )
        if name not in memo:
            block = doc.blocks.get(name)
            memo[name] = 0 if block is None else _dxf_size(block, doc, memo, (*stack, name))
        total += max(1, e.mcount) * memo[name]
    return total


def _dxf_entities(
    entities: Any, layer0: str | None, depth: int, where: str = "the drawing"
) -> Iterator[tuple[str, Any]]:
    """(layer, entity) of every entity, INSERTs expanded; a block's layer-0 entities take the INSERT's layer.

    An INSERT whose scale is zero or not a number, or whose transform cannot be applied (a
    scale so small its inverse overflows), is refused naming ``where`` (the layout and the
    space read) and the block."""
    for e in entities:
        layer = e.dxf.get("layer", "0")
        if layer0 is not None and layer == "0":
            layer = layer0
        if e.dxftype() == "INSERT":
            name = e.dxf.name
            if depth > MAX_DEPTH:
                raise InputError(
                    f"block {name} nests deeper than {MAX_DEPTH} levels; fix the drawing"
                )
            scale = tuple(float(e.dxf.get(k, 1.0)) for k in ("xscale", "yscale", "zscale"))
            fix = "give the block reference a non-zero scale in the drawing program (or delete it)"
            if not all(math.isfinite(v) and v != 0 for v in scale):
                shown = ", ".join(f"{v:g}" for v in scale)
                raise InputError(
                    f"{where}: the INSERT of block {name} on layer {layer} has scale ({shown}), "
                    f"which flattens or breaks the block; {fix}"
                )
            try:
                for one in e.multi_insert():
                    yield from _dxf_entities(one.virtual_entities(), layer, depth + 1, where)
            except ArithmeticError:  # ZeroDivisionError, OverflowError of a degenerate transform
                shown = ", ".join(f"{v:g}" for v in scale)
                raise InputError(
                    f"{where}: the INSERT of block {name} on layer {layer} (scale {shown}) cannot be "
                    f"expanded: its transform is degenerate; {fix}"
                ) from None
        else:
            yield layer, e


_OPEN = ("LINE", "ARC", "SPLINE", "RAY", "XLINE")
_IGNORED = (
    "TEXT",
    "MTEXT",
    "POINT",
    "DIMENSION",
    "LEADER",
    "MLEADER",
    "ATTRIB",
    "ATTDEF",
    "VIEWPORT",
    "IMAGE",
    "WIPEOUT",
)


def _xy(points: Any) -> np.ndarray:
    return np.array([(v[0], v[1]) for v in points], dtype=np.float64).reshape(-1, 2)


class _BadShape(InputError):
    """A shape that cannot be read (its message continues "a LWPOLYLINE (handle 2A) ...")."""


def _arc_steps(
    xyb: np.ndarray, closed: bool, tol: float, factor: float
) -> list[tuple[int, float, float, float, float, int]]:
    """The arcs of a polyline, priced before any is sampled: (segment, centre x, centre y, radius,
    start angle, chords) per bulged segment. An arc wider than :data:`MAX_COORD_UM` (a bulge near
    +-inf, a full turn) or a bulge that is not a number is refused (InputError, the caller names the entity).
    """
    from ezdxf.math import bulge_center

    out = []
    n = len(xyb)
    for i in range(n if closed else n - 1):
        (x0, y0, b), (x1, y1) = xyb[i], xyb[(i + 1) % n][:2]
        if b == 0 or (x0 == x1 and y0 == y1):
            continue
        if not math.isfinite(b):
            raise _BadShape(
                f"has a bulge of {b:g} at vertex {i + 1}; give every arc a finite bulge (tan of a quarter of its sweep)"
            )
        sweep = 4 * math.atan(b)
        half = abs(math.sin(sweep / 2))
        r = math.hypot(x1 - x0, y1 - y0) / (2 * half) if half > 0 else math.inf
        if not r * factor <= MAX_COORD_UM:
            raise _BadShape(
                f"has an arc of radius {r * factor:.3g} um (bulge {b:g}) at vertex {i + 1}, beyond the "
                f"{MAX_COORD_UM:,.0f} um (1 m) a layout may span; redraw the arc (its bulge is near a full turn) or check the units"
            )
        c = bulge_center((x0, y0), (x1, y1), b)
        steps = max(1, math.ceil(abs(sweep) / (2 * math.acos(max(-1.0, 1 - tol / r)))))
        out.append((i, c.x, c.y, r, math.atan2(y0 - c.y, x0 - c.x), steps))
    return out


def _require_radius(r: float, factor: float) -> None:
    """A circle's or ellipse's radius (drawing units) that can be sampled, else :class:`_BadShape` (before any sample)."""
    if not abs(r) * factor <= MAX_COORD_UM:
        raise _BadShape(
            f"has a radius of {abs(r) * factor:.3g} um, beyond the {MAX_COORD_UM:,.0f} um (1 m) a layout may span; check the drawing's units"
        )


def _bulged(
    xyb: np.ndarray, closed: bool, tol: float, factor: float = 1.0, budget_mb: float | None = None
) -> np.ndarray:
    """Vertices (n, 2) of a polyline whose segments may be arcs (bulge = tan(sweep / 4), CCW > 0).

    Arcs are sampled on the true circle so that the chords stay within ``tol`` of it; the
    samples are counted and priced against the memory budget before any is made.
    """
    arcs = {a[0]: a for a in _arc_steps(xyb, closed, tol, factor)}
    total = len(xyb) + sum(a[5] for a in arcs.values())
    require_fits(
        f"sampling the arcs of a polyline ({total:,} vertices within {tol * factor:g} um of the true arcs)",
        total * BYTES_PER_VERTEX,
        "draw the arcs as fewer or smaller arcs",
        budget_mb,
    )
    out = []
    n = len(xyb)
    for i in range(n if closed else n - 1):
        x0, y0 = xyb[i][:2]
        out.append((x0, y0))
        if i not in arcs:
            continue
        _, cx, cy, r, a0, steps = arcs[i]
        sweep = 4 * math.atan(xyb[i][2])
        a = a0 + sweep * np.arange(1, steps) / steps
        out.extend(zip((cx + r * np.cos(a)).tolist(), (cy + r * np.sin(a)).tolist(), strict=True))
    if not closed and n:
        out.append(tuple(xyb[-1][:2]))
    return np.array(out, dtype=np.float64).reshape(-1, 2)


def _to_wcs(e: Any, pts: np.ndarray) -> np.ndarray:
    """Points in the entity's object coordinate system -> world coordinates (x, y)."""
    ocs = e.ocs()
    if not ocs.transform:
        return pts
    return _xy(ocs.points_to_wcs([(x, y, 0.0) for x, y in pts]))


def _dxf_ring(
    e: Any, factor: float, budget_mb: float | None = None
) -> tuple[list[np.ndarray], str | None]:
    """(rings in um, None), ([], the problem), or ([], None) for an entity that is no outline (text).

    A ring that reaches beyond +-:data:`MAX_COORD_UM` or an arc that cannot be sampled is the
    layer's problem (refused, one line, when that layer is read)."""
    kind, handle = e.dxftype(), e.dxf.get("handle", "?")
    try:
        rings, problem = _dxf_ring_of(e, kind, handle, factor, budget_mb)
    except _BadShape as err:
        return [], f"a {kind} (handle {handle}) {err}"
    for r in rings:
        big = np.abs(r[np.isfinite(r)])
        if big.size and big.max() > MAX_COORD_UM:
            return [], (
                f"a {kind} (handle {handle}) reaches {big.max():.3g} um from the origin, beyond the {MAX_COORD_UM:,.0f} um (1 m) "
                "a layout may span; check the drawing's units ($INSUNITS or --dxf-units) and coordinates"
            )
    return rings, problem


def _dxf_ring_of(
    e: Any, kind: str, handle: str, factor: float, budget_mb: float | None
) -> tuple[list[np.ndarray], str | None]:
    tol = DBU_UM / factor  # curves sampled within one database unit
    if kind in _IGNORED:
        return [], None
    if kind in _OPEN:
        return (
            [],
            f"a {kind} (handle {handle}) is not a closed outline; join the outline into one closed polyline",
        )
    if kind == "LWPOLYLINE":
        xyb, closed = np.array(e.get_points("xyb"), dtype=np.float64).reshape(-1, 3), e.closed
    elif kind == "POLYLINE":
        if not (e.is_2d_polyline or e.is_3d_polyline):
            return (
                [],
                f"a POLYLINE mesh (handle {handle}) is not an outline; draw the pad as a closed polyline",
            )
        xyb = np.array(
            [(*v.dxf.location[:2], v.dxf.get("bulge", 0.0)) for v in e.vertices], dtype=np.float64
        ).reshape(-1, 3)
        closed = e.is_closed
    if kind in ("LWPOLYLINE", "POLYLINE"):
        ends_meet = len(xyb) > 1 and np.allclose(xyb[0, :2], xyb[-1, :2], rtol=0, atol=tol)
        if len(xyb) and not closed and not ends_meet:
            (x0, y0), (x1, y1) = _to_wcs(e, xyb[[0, -1], :2]) * factor
            return [], (
                f"{kind} (handle {handle}) is open: it ends at ({x1:g}, {y1:g}) um, not at its start ({x0:g}, {y0:g}) um; "
                "close it (set its closed flag) in the drawing program"
            )
        rings = [
            _to_wcs(e, _bulged(xyb, closed or ends_meet, tol, factor, budget_mb))
            if not (kind == "POLYLINE" and e.is_3d_polyline)
            else xyb[:, :2]
        ]
    elif kind == "CIRCLE":
        _require_radius(e.dxf.radius, factor)
        rings = [_xy(e.flattening(tol))]
    elif kind == "ELLIPSE":
        _require_radius(e.dxf.major_axis.magnitude, factor)
        if not math.isclose(
            abs(e.dxf.end_param - e.dxf.start_param) % (2 * math.pi), 0, abs_tol=1e-12
        ):
            return (
                [],
                f"an elliptic arc (handle {handle}) is not a closed outline; draw a full ellipse or a closed polyline",
            )
        rings = [_xy(e.flattening(tol))]
    elif kind in ("SOLID", "TRACE", "3DFACE"):
        rings = [_xy(e.wcs_vertices())]
    elif (
        kind == "HATCH"
    ):  # every polyline boundary; nested ones become holes (even-odd, as hatches fill)
        rings = []
        for b in e.paths:
            if not hasattr(b, "vertices"):
                return (
                    [],
                    f"a HATCH (handle {handle}) bounded by edges; draw its outline as a closed polyline",
                )
            xyb = np.array(
                [(v[0], v[1], v[2] if len(v) > 2 else 0.0) for v in b.vertices], dtype=np.float64
            ).reshape(-1, 3)
            rings.append(_to_wcs(e, _bulged(xyb, True, tol, factor, budget_mb)))
    else:
        return (
            [],
            f"a {kind} (handle {handle}) is not an outline selfalign reads; draw the pad as a closed polyline",
        )
    out = []
    for r in rings:
        if len(r) > 1 and np.allclose(r[0], r[-1], rtol=0, atol=tol):
            r = r[:-1]
        out.append(r * factor)
    return out, None
