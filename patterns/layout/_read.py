"""Mask layouts (GDSII, OASIS, DXF) as exact pattern geometry, and the geometry written as layouts.

Reading (:func:`read_layout`, then :meth:`Layout.geometry`; :func:`layout_geometry` and
:func:`layout_masks` for the scene):

* **Format** from the file's content (a GDSII HEADER record, the ``%SEMI-OASIS`` magic, a
  DXF ``0 / SECTION`` or binary sentinel), else from its extension (:data:`SUFFIXES`).
  GDSII and OASIS are read with gdstk, DXF with ezdxf.
* **Cell.** ``cell=None`` takes the single top cell (several -> InputError listing them);
  for DXF, the model space, or a block by name.
* **Hierarchy flattened**: references and arrays (GDS AREF, OASIS repetitions, DXF INSERT and
  MINSERT) with their rotation, magnification and reflection. Boxes and paths count as
  their outline polygons. In DXF, block entities on layer ``0`` take the layer of their
  INSERT (the DXF rule). Text, labels and points are ignored.
* **Layers**: GDS/OASIS ``"L/D"`` (layer/datatype; ``"L"`` means ``L/0``), DXF the layer
  name. ``layer=None`` takes the cell's only layer (besides the chip layer).
* **Units.** GDS/OASIS coordinates are whole database units; they are converted to
  micrometres with the file's database unit (GDS: user unit x user units per database
  unit). DXF coordinates are in the header's ``$INSUNITS`` (or ``dxf_units`` when the file
  states none), converted to micrometres and snapped to a 1 nm grid. Flattened
  coordinates (rotated references) are snapped to the database grid as well.
* **Merging.** Overlapping or abutting polygons of the layer are merged (union); holes are
  kept: a GDS keyhole polygon (the hole joined to its outline by a cut line) is a polygon
  with a hole, and in DXF a closed outline that lies inside another is a hole (nesting
  depth even = pad, odd = hole). A polygon that crosses itself (its signed area differs
  from its area) is refused, naming where.
* **Frame.** Layout coordinates are kept until :func:`layout_geometry` moves the origin:
  with a chip layer to the centre of the chip outline's bounding box (the chip's position
  in the layout is then the aligned pose, and the pattern keeps its placement relative to
  the chip); without one to the centre of the pattern's bounding box, as for PNGs.

Writing (:func:`write_layout`): the exact polygon, its vertices rounded to the 1 nm
database unit, on GDS/OASIS layer :data:`WRITE_LAYER` (1/0; user unit 1 um) or the DXF
layer :data:`WRITE_DXF_LAYER` (``$INSUNITS`` micrometres; holes as inner closed
polylines), in one cell named after the design. Reading it back gives the same polygon
to the database unit.

Every failure is an :class:`~foundation.InputError` with one line naming the file
and the fix; nothing is written on failure (:func:`foundation.atomic_output`).

The family's modules (their names are :mod:`patterns.layout`'s): ``_formats`` (formats,
units, layer names, the selection), ``_gds`` and ``_dxf`` (the readers), ``_cell`` (the
flattened cell and its merged geometry), ``_write`` (writing); this module reads a layout
and gives the scene its view (frame, masks).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import shapely
from shapely import affinity
from shapely.geometry.base import BaseGeometry

from foundation import (
    RASTER_BYTES_PER_PX,
    InputError,
    budget_bytes,
    fmt_bytes,
    positive,
    require_fits,
    require_regular_file,
)
from patterns.geometry import Mask
from patterns.layout._cell import Layout
from patterns.layout._dxf import _read_dxf
from patterns.layout._formats import (
    DXF_UNITS,
    NAMES,
    READ_FACTOR,
    SUFFIXES,
    LayoutSelection,
    _count,
    _layer_text,
    is_layout,
    layout_format,
)
from patterns.layout._gds import _read_gdstk
from patterns.layout._write import WRITE_DXF_LAYER, WRITE_LAYER, snap, write_layout

__all__ = [
    "DEFAULT_UM_PER_PX",
    "DXF_UNITS",
    "SUFFIXES",
    "WRITE_DXF_LAYER",
    "WRITE_LAYER",
    "Layout",
    "LayoutSelection",
    "frame_note",
    "is_layout",
    "layout_format",
    "layout_chip_mask",
    "layout_geometry",
    "layout_mask",
    "layout_masks",
    "read_layout",
    "snap",
    "write_layout",
]

#: Raster pixel size (um) of a layout when neither a resolution nor --um-per-px is given.
DEFAULT_UM_PER_PX = 1.0


def read_layout(
    path: str | os.PathLike,
    cell: str | None = None,
    dxf_units: str | None = None,
    budget_mb: float | None = None,
    max_polygons: int | None = None,
) -> Layout:
    """Read and flatten one cell of a GDSII, OASIS or DXF file (see the module notes).

    Raises:
        InputError: unreadable file, unknown cell or several top cells, missing or
            conflicting DXF units, or a flattened cell over the memory budget or over
            ``max_polygons`` polygons (default :data:`DEFAULT_MAX_POLYGONS`).
    """
    path = require_regular_file(path, "layout")
    fmt = layout_format(path)
    if fmt is None:
        raise InputError(f"{path}: not a layout file; give a .gds, .oas or .dxf file")
    size = path.stat().st_size
    require_fits(
        f"reading {path} ({fmt_bytes(size)} {NAMES[fmt]})",
        size * READ_FACTOR[fmt],
        "split the layout or export only the cell needed",
        budget_mb,
    )
    if dxf_units is not None and dxf_units not in DXF_UNITS:
        raise InputError(f"--dxf-units must be one of {', '.join(DXF_UNITS)}, got {dxf_units!r}")
    if fmt == "dxf":
        return _read_dxf(path, cell, dxf_units, budget_mb, max_polygons)
    return _read_gdstk(path, fmt, cell, budget_mb, max_polygons)


# --------------------------------------------------------------------------- the scene's view
def layout_geometry(
    path: str | os.PathLike,
    selection: LayoutSelection | None = None,
    budget_mb: float | None = None,
) -> tuple[BaseGeometry, BaseGeometry | None, dict]:
    """(pattern, chip or None, record): the selected layers, moved to the frame of the module notes.

    The record (JSON-ready, kept as ``Mask.params["layout"]``) names the file, cell,
    layers, units, polygon count, exact area and ``origin_um``: the layout point that is
    the origin, with ``origin`` saying what it is.
    """
    sel = selection or LayoutSelection()
    lay = read_layout(path, sel.cell, sel.dxf_units, budget_mb, sel.max_polygons)
    chip_key = lay.key(sel.chip_layer, "--chip-layer") if sel.chip_layer is not None else None
    if sel.layer is not None:
        key = lay.key(sel.layer)
    else:
        others = [
            k
            for k in (*lay.rings, *lay.problems)
            if k != chip_key and (lay.rings.get(k) or k in lay.problems)
        ]
        others = list(dict.fromkeys(others))
        if len(others) != 1:
            raise InputError(
                f"{lay.path}: cell {lay.cell} has {'no layer' if not others else 'several layers'} "
                f"({lay.layers_text()}); choose the pattern with --layer {'L/D' if lay.format != 'dxf' else 'NAME'}"
            )
        key = others[0]
    if key == chip_key:
        raise InputError(
            f"--layer and --chip-layer name the same layer {_layer_text(key)}; the chip outline needs its own layer"
        )
    pattern = lay.geometry(key)
    chip = lay.geometry(chip_key) if chip_key is not None else None
    ref = (chip if chip is not None else pattern).bounds
    cx, cy = (ref[0] + ref[2]) / 2, (ref[1] + ref[3]) / 2
    record = {
        "file": lay.path.name,
        "format": lay.format,
        "cell": lay.cell,
        "layer": _layer_text(key, quote=False),
        "polygons": len(shapely.get_parts(pattern)),
        "area_um2": pattern.area,
        "units": lay.units,
        "database_unit_um": lay.dbu_um,
        "origin_um": [cx, cy],
        "origin": (
            f"the centre of the chip outline on layer {_layer_text(chip_key)}"
            if chip is not None
            else "the centre of the pattern's bounding box (no chip layer)"
        ),
        "chip_layer": _layer_text(chip_key, quote=False) if chip is not None else None,
    }
    move = lambda g: affinity.translate(g, -cx, -cy)  # noqa: E731
    return move(pattern), (move(chip) if chip is not None else None), record


def _fitting_scale(geometry: BaseGeometry, budget_mb: float | None) -> float:
    """The finest 1, 2, 2.5 or 5 x 10^k um/px at which the symmetric canvas of ``geometry`` fits the budget."""
    x0, y0, x1, y1 = geometry.bounds
    hw, hh = max(abs(x0), abs(x1)), max(abs(y0), abs(y1))
    s = math.sqrt(4 * hw * hh * RASTER_BYTES_PER_PX / budget_bytes(budget_mb))
    k = math.floor(math.log10(s))
    for m in (1, 2, 2.5, 5, 10):
        c = m * 10**k
        if c >= s and (2 * math.ceil(hw / c) + 2) * (
            2 * math.ceil(hh / c) + 2
        ) * RASTER_BYTES_PER_PX <= budget_bytes(budget_mb):
            return c
    return 10 ** (k + 1) * 2


def layout_mask(
    geometry: BaseGeometry, um_per_px: float, what: str, params: dict, budget_mb: float | None
) -> Mask:
    """Rasterize layout geometry; over the budget, the refusal says which scale would fit."""
    from patterns.geometry import mask_from_geometry

    s = positive("the layout raster's pixel size (--resolution)", um_per_px, "um per px")
    x0, y0, x1, y1 = geometry.bounds
    w, h = 2 * math.ceil(max(abs(x0), abs(x1)) / s), 2 * math.ceil(max(abs(y0), abs(y1)) / s)
    need = float(w) * float(h) * RASTER_BYTES_PER_PX
    if not need <= budget_bytes(budget_mb):
        fit = _fitting_scale(geometry, budget_mb)
        raise InputError(
            f"{what} at {s:g} um/px would be {w:,} x {h:,} px, about {fmt_bytes(need)}, over the memory budget of "
            f"{fmt_bytes(budget_bytes(budget_mb))}; --resolution {fit:g} (um/px) or coarser would fit (or raise --memory-budget)"
        )
    return mask_from_geometry(geometry, s, params=params, budget_mb=budget_mb, what=what)


def layout_masks(
    path: str | os.PathLike,
    selection: LayoutSelection | None,
    um_per_px: float,
    budget_mb: float | None = None,
) -> tuple[Mask, Mask | None]:
    """(pattern mask, chip mask or None) of a layout at ``um_per_px``, exact geometry kept."""
    pattern, chip, record = layout_geometry(path, selection, budget_mb)
    name = Path(path).name
    pm = layout_mask(
        pattern, um_per_px, f"the pattern raster of {name}", {"layout": record}, budget_mb
    )
    cm = None
    if chip is not None:
        cm = layout_mask(
            chip,
            um_per_px,
            f"the chip raster of {name} (layer {record['chip_layer']})",
            {"design": "layout", "layout": dict(record, layer=record["chip_layer"])},
            budget_mb,
        )
    return pm, cm


def layout_chip_mask(
    path: str | os.PathLike,
    um_per_px: float,
    selection: LayoutSelection | None = None,
    budget_mb: float | None = None,
) -> Mask:
    """A chip footprint drawn in a layout of its own (``--chip chip.gds``): its only layer, centred on its bounding box.

    Only ``selection.dxf_units`` and ``selection.max_polygons`` apply (the cell is the single top cell).
    """
    units = selection.dxf_units if selection is not None else None
    limit = selection.max_polygons if selection is not None else None
    chip, _, record = layout_geometry(
        path, LayoutSelection(dxf_units=units, max_polygons=limit), budget_mb
    )
    return layout_mask(
        chip,
        um_per_px,
        f"the chip raster of {Path(path).name}",
        {"design": "layout", "layout": record},
        budget_mb,
    )


def frame_note(record: dict) -> str:
    """One line saying where the origin of the poses is in the layout."""
    x, y = record["origin_um"]
    return (
        f"frame: {record['file']} cell {record['cell']} layer {record['layer']} ({_count(record['polygons'], 'polygon')}, "
        f"{record['units']}); poses are relative to {record['origin']}, at layout ({x:.6g}, {y:.6g}) um"
    )
