"""Writing exact pattern geometry as a GDSII, OASIS or DXF layout (:func:`write_layout`).

Vertices rounded to the 1 nm database unit, on GDS/OASIS layer :data:`WRITE_LAYER` (holes
as keyhole polygons) or the DXF layer :data:`WRITE_DXF_LAYER` (holes as inner closed
polylines), in one cell named after the design; written atomically
(:func:`foundation.atomic_output`). gdstk and ezdxf are imported only when writing.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from foundation import InputError, atomic_output
from patterns.layout._formats import DBU_UM, SUFFIXES, _on_grid

#: GDS/OASIS layer and datatype that :func:`write_layout` draws on; the DXF layer name.
WRITE_LAYER = (1, 0)
WRITE_DXF_LAYER = "PATTERN"


# --------------------------------------------------------------------------- writing
def snap(geometry: BaseGeometry, dbu_um: float = DBU_UM) -> BaseGeometry:
    """``geometry`` with every vertex rounded to the ``dbu_um`` grid (what a layout stores)."""
    return shapely.transform(geometry, lambda xy: _on_grid(xy, dbu_um))


def _cell_name(name: str) -> str:
    text = re.sub(r"[^A-Za-z0-9_?$]", "_", name or "PATTERN")[:32]
    return text or "PATTERN"


def write_layout(path: str | os.PathLike, geometry: BaseGeometry, cell: str = "PATTERN") -> Path:
    """Write ``geometry`` (um) as a ``.gds``, ``.oas`` or ``.dxf`` file, atomically (see the module notes).

    Returns the path. Polygons with holes are written to GDS/OASIS as keyhole polygons,
    to DXF as an outer and inner closed polylines.
    """
    path = Path(path)
    fmt = SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise InputError(f"output {path}: a layout file name must end in .gds, .oas or .dxf")
    parts = [
        g
        for g in shapely.get_parts(shapely.orient_polygons(geometry))
        if isinstance(g, Polygon) and not g.is_empty
    ]
    if not parts:
        raise InputError(f"output {path}: the geometry is empty; nothing to write")
    name = _cell_name(cell)
    with atomic_output(path) as tmp:
        if fmt == "dxf":
            _write_dxf(tmp, parts)
        else:
            _write_gdstk(tmp, fmt, parts, name)
    return path


def _rounded(ring: Any) -> np.ndarray:
    return _on_grid(np.asarray(ring.coords)[:-1])


def _write_gdstk(tmp: Path, fmt: str, parts: list[Polygon], name: str) -> None:
    import datetime

    import gdstk

    lib = gdstk.Library("SELFALIGN", unit=1e-6, precision=DBU_UM * 1e-6)
    cell = lib.new_cell(name)
    layer, datatype = WRITE_LAYER
    for p in parts:
        # gdstk takes an (n, 2) array; its stub names sequences of pairs only
        outer = gdstk.Polygon(_rounded(p.exterior), layer=layer, datatype=datatype)  # pyright: ignore[reportArgumentType]
        if p.interiors:
            holes = [gdstk.Polygon(_rounded(r)) for r in p.interiors]  # pyright: ignore[reportArgumentType]
            cell.add(
                *gdstk.boolean(
                    outer, holes, "not", precision=DBU_UM, layer=layer, datatype=datatype
                )
            )
        else:
            cell.add(outer)
    if (
        fmt == "gds"
    ):  # 8190 vertices: the most one GDSII XY record holds, so no polygon is fractured
        lib.write_gds(str(tmp), max_points=8190, timestamp=datetime.datetime(2000, 1, 1))
    else:
        lib.write_oas(str(tmp))


def _write_dxf(tmp: Path, parts: list[Polygon]) -> None:
    from ezdxf import filemanagement

    doc = filemanagement.new("R2010")
    doc.units = 13  # $INSUNITS micrometres
    doc.header["$MEASUREMENT"] = 1
    doc.layers.add(WRITE_DXF_LAYER)
    msp = doc.modelspace()
    for p in parts:
        for ring in (p.exterior, *p.interiors):
            msp.add_lwpolyline(
                _rounded(ring).tolist(), close=True, dxfattribs={"layer": WRITE_DXF_LAYER}
            )
    doc.saveas(tmp)
