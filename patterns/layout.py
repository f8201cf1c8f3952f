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

Every failure is an :class:`~patterns.errors.InputError` with one line naming the file
and the fix; nothing is written on failure (:func:`patterns.outputs.atomic_output`).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import re
import sys
import tempfile
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely import affinity
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.base import BaseGeometry

from patterns.errors import InputError, positive, require_regular_file
from patterns.mask import Mask
from patterns.outputs import atomic_output
from patterns.resources import RASTER_BYTES_PER_PX, budget_bytes, fmt_bytes, require_fits

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

#: File extensions of the layout formats (used when the content does not tell).
SUFFIXES = {".gds": "gds", ".gdsii": "gds", ".gds2": "gds", ".oas": "oas", ".oasis": "oas", ".dxf": "dxf"}
NAMES = {"gds": "GDSII", "oas": "OASIS", "dxf": "DXF"}
#: Raster pixel size (um) of a layout when neither a resolution nor --um-per-px is given.
DEFAULT_UM_PER_PX = 1.0
#: GDS/OASIS layer and datatype that :func:`write_layout` draws on; the DXF layer name.
WRITE_LAYER = (1, 0)
WRITE_DXF_LAYER = "PATTERN"
#: Database unit of written layouts and snapping grid of DXF coordinates (um): 1 nm.
DBU_UM = 1e-3
#: ``--dxf-units`` choices, in um.
DXF_UNITS = {"um": 1.0, "mm": 1e3, "nm": 1e-3}
#: DXF $INSUNITS codes -> (name, um).
INSUNITS = {1: ("inch", 25400.0), 2: ("foot", 304800.0), 4: ("mm", 1e3), 5: ("cm", 1e4), 6: ("m", 1e6),
            8: ("microinch", 0.0254), 9: ("mil", 25.4), 11: ("angstrom", 1e-4), 12: ("nm", 1e-3), 13: ("um", 1.0),
            14: ("dm", 1e5)}
#: Peak bytes per flattened vertex and per polygon (gdstk/ezdxf copies, numpy rings, shapely).
BYTES_PER_VERTEX, BYTES_PER_POLYGON = 200, 2000
#: Peak bytes per byte of file while the parser holds it (gdstk; ezdxf keeps Python objects).
READ_FACTOR = {"gds": 4, "oas": 16, "dxf": 40}
#: Deepest reference nesting followed.
MAX_DEPTH = 64
_MAX_LISTED = 12


# --------------------------------------------------------------------------- format and selection
def layout_format(path: str | os.PathLike) -> str | None:
    """``"gds"``, ``"oas"`` or ``"dxf"`` from the file's first bytes, else its extension; None for other files."""
    path = Path(path)
    head = b""
    with contextlib.suppress(OSError):
        if path.is_file():  # never open a FIFO or a device
            with open(path, "rb") as f:
                head = f.read(256)
    if head.startswith(b"\x00\x06\x00\x02"):
        return "gds"
    if head.startswith(b"%SEMI-OASIS\r\n"):
        return "oas"
    if head.startswith(b"AutoCAD Binary DXF"):
        return "dxf"
    lines = [t.strip() for t in head.decode("latin-1").splitlines()[:6]]
    if lines and lines[0] in ("0", "999") and "SECTION" in lines:
        return "dxf"
    if head.startswith(b"\x89PNG"):
        return None
    return SUFFIXES.get(path.suffix.lower())


def is_layout(path: Any) -> bool:
    """True if ``path`` names a layout file (by content, else extension)."""
    return isinstance(path, str | os.PathLike) and layout_format(path) is not None


def _layer_key(text: Any, fmt: str, flag: str) -> Any:
    """``"1/0"`` -> (1, 0) for GDS/OASIS (``"1"`` -> (1, 0)); the name itself for DXF."""
    text = str(text).strip()
    if fmt == "dxf":
        if not text:
            raise InputError(f"{flag}: give a DXF layer name")
        return text
    m = re.fullmatch(r"(\d{1,9})\s*(?:/\s*(\d{1,9}))?", text)
    if not m:
        raise InputError(f"{flag} {text!r}: give a layer and datatype as L/D, e.g. 1/0 (whole numbers)")
    return (int(m[1]), int(m[2] or 0))


def _layer_text(key: Any, quote: bool = True) -> str:
    """``1/0`` for GDS/OASIS, ``'PADS'`` (or ``PADS`` unquoted) for DXF."""
    return f"{key[0]}/{key[1]}" if isinstance(key, tuple) else (repr(key) if quote else key)


@dataclass(frozen=True)
class LayoutSelection:
    """What to read from a layout (the ``--layer``, ``--cell``, ``--chip-layer``, ``--dxf-units`` flags).

    ``layer``/``chip_layer``: ``"L/D"`` for GDS/OASIS, a layer name for DXF; ``None`` takes the
    only layer (and no chip layer). ``cell``: None = the single top cell (DXF: model space).
    ``dxf_units``: ``"um"``, ``"mm"`` or ``"nm"``, used when a DXF file states no units.
    """

    layer: str | None = None
    cell: str | None = None
    chip_layer: str | None = None
    dxf_units: str | None = None

    def __post_init__(self) -> None:
        for name in ("layer", "cell", "chip_layer"):
            v = getattr(self, name)
            if v is not None and (not isinstance(v, str | int) or isinstance(v, bool) or not str(v).strip()):
                raise InputError(f"{name} must be a non-empty string (a layer L/D, a DXF layer or a cell name), got {v!r}")
        if self.dxf_units is not None and self.dxf_units not in DXF_UNITS:
            raise InputError(f"dxf_units must be one of {', '.join(DXF_UNITS)}, got {self.dxf_units!r}")

    @property
    def given(self) -> list[str]:
        """The flags that were set, as the command line spells them."""
        return [f"--{k.replace('_', '-')}" for k in ("layer", "cell", "chip_layer", "dxf_units") if getattr(self, k) is not None]

    def require_unused(self, what: str, units_ok: bool = False) -> None:
        """InputError if a layout flag is set for a pattern that is not a layout (``units_ok``: a DXF chip may use --dxf-units)."""
        given = [f for f in self.given if not (units_ok and f == "--dxf-units")]
        if given:
            raise InputError(f"{', '.join(given)} apply to layout patterns (.gds, .oas, .dxf); {what} is not one")


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
        items = [f"{_layer_text(k)} ({_count(len(self.rings.get(k, [])), 'polygon')}{', and a shape that is no closed outline' if k in self.problems else ''})"
                 for k in keys]
        more = f", ... ({len(items) - _MAX_LISTED} more)" if len(items) > _MAX_LISTED else ""
        return ", ".join(items[:_MAX_LISTED]) + more if items else "none"

    def key(self, layer: Any, flag: str = "--layer") -> Any:
        """The layer key of ``layer`` (text as the flags take it), checked to exist."""
        key = _layer_key(layer, self.format, flag)
        if isinstance(key, str) and key not in self.rings and key not in self.problems:  # DXF layer names ignore case
            key = next((k for k in (*self.rings, *self.problems) if k.casefold() == key.casefold()), key)
        if key not in self.rings and key not in self.problems:
            raise InputError(f"{self.path}: cell {self.cell} has nothing on layer {_layer_text(key)}; "
                             f"layers present: {self.layers_text()}; choose one with {flag}")
        return key

    def geometry(self, key: Any) -> BaseGeometry:
        """The merged (Multi)Polygon of one layer (um, layout frame), or InputError."""
        where = f"{self.path}: cell {self.cell}, layer {_layer_text(key)}"
        if key in self.problems:
            raise InputError(f"{where}: {self.problems[key]}")
        rings = self.rings.get(key, [])
        polys, nested = _polygons(rings, where), self.format == "dxf"
        if not polys:
            raise InputError(f"{where}: the layer is empty (no polygon with an area); choose another layer, present: {self.layers_text()}")
        return _merge(polys, nested)


def _count(n: int, word: str) -> str:
    return f"{n:,} {word}{'' if n == 1 else 's'}"


def _fmt_len(metres: float) -> str:
    for unit, k in (("m", 1.0), ("mm", 1e-3), ("um", 1e-6), ("nm", 1e-9), ("pm", 1e-12)):
        if metres >= k * (1 - 1e-9):
            return f"{metres / k:.6g} {unit}"
    return f"{metres:g} m"


def read_layout(path: str | os.PathLike, cell: str | None = None, dxf_units: str | None = None,
                budget_mb: float | None = None) -> Layout:
    """Read and flatten one cell of a GDSII, OASIS or DXF file (see the module notes).

    Raises:
        InputError: unreadable file, unknown cell or several top cells, missing or
            conflicting DXF units, or a flattened cell over the memory budget.
    """
    path = require_regular_file(path, "layout")
    fmt = layout_format(path)
    if fmt is None:
        raise InputError(f"{path}: not a layout file; give a .gds, .oas or .dxf file")
    size = path.stat().st_size
    require_fits(f"reading {path} ({fmt_bytes(size)} {NAMES[fmt]})", size * READ_FACTOR[fmt], "split the layout or export only the cell needed", budget_mb)
    if dxf_units is not None and dxf_units not in DXF_UNITS:
        raise InputError(f"--dxf-units must be one of {', '.join(DXF_UNITS)}, got {dxf_units!r}")
    if fmt == "dxf":
        return _read_dxf(path, cell, dxf_units, budget_mb)
    return _read_gdstk(path, fmt, cell, budget_mb)


# --------------------------------------------------------------------------- GDSII / OASIS
@contextlib.contextmanager
def _c_stderr() -> Iterator[list[str]]:
    """Capture what C code writes to file descriptor 2 (gdstk's ``[GDSTK] ...`` lines)."""
    out: list[str] = []
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all: nothing to capture
        yield out
        return
    with contextlib.suppress(Exception):
        sys.stderr.flush()
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield out
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            out.append(tmp.read(2000).decode("utf-8", "replace"))


def _read_gdstk(path: Path, fmt: str, cell: str | None, budget_mb: float | None) -> Layout:
    import gdstk

    failure = None
    with _c_stderr() as said, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Missing reference": refused below when the cell read needs it
        try:
            lib = gdstk.read_gds(str(path)) if fmt == "gds" else gdstk.read_oas(str(path))
        except (OSError, RuntimeError, ValueError, MemoryError) as err:
            failure = err
    notes = "; ".join(t.strip() for t in " ".join(said).replace("[GDSTK]", ".").split(".") if t.strip())
    if failure is not None:
        detail = notes or str(failure)
        raise InputError(f"{path}: not a readable {NAMES[fmt]} file ({detail}); export it again from the layout editor")
    cells = {c.name: c for c in lib.cells}
    counts: dict[str, int] = {}
    if cell is None:
        tops = lib.top_level()
        if len(tops) != 1:
            listed = ", ".join(f"{c.name} ({_cell_count(c, counts)})" for c in tops[:_MAX_LISTED]) or "none"
            raise InputError(f"{path}: {len(tops)} top cells ({listed}); choose one with --cell NAME")
        top = tops[0]
    elif cell in cells:
        top = cells[cell]
    else:
        listed = ", ".join(f"{n} ({_cell_count(c, counts)})" for n, c in list(cells.items())[:_MAX_LISTED]) or "none"
        raise InputError(f"{path}: no cell named {cell!r}; cells present: {listed}; choose one with --cell NAME")
    try:
        vertices, polygons = _flat_size(top, counts)
    except InputError as err:
        raise InputError(f"{path}: {err}") from None
    require_fits(f"flattening cell {top.name} of {path} ({polygons:,} polygons, {vertices:,} vertices)",
                 vertices * BYTES_PER_VERTEX + polygons * BYTES_PER_POLYGON, "choose a smaller --cell", budget_mb)
    db_per_user = lib.unit / lib.precision  # user coordinates x this = database units
    if abs(db_per_user - round(db_per_user)) < 1e-9 * db_per_user:
        db_per_user = float(round(db_per_user))
    rings: dict[Any, list[np.ndarray]] = {}
    for p in top.get_polygons(apply_repetitions=True, include_paths=True, depth=None):
        rings.setdefault((int(p.layer), int(p.datatype)), []).append(np.round(p.points * db_per_user))
    dbu_um, to_um = _db_to_um(lib.precision)
    rings = {k: [to_um(r) for r in v] for k, v in rings.items()}
    units = f"user unit {_fmt_len(lib.unit)}, database unit {_fmt_len(lib.precision)}"
    return Layout(path, fmt, top.name, units, dbu_um, rings)


def _db_to_um(precision_m: float) -> tuple[float, Any]:
    """(database unit in um, function: whole database units -> um, as exactly as floats allow)."""
    positive("the layout's database unit", precision_m, "m")
    per_um = 1e-6 / precision_m
    if abs(per_um - round(per_um)) < 1e-9 * per_um and round(per_um) >= 1:
        n = float(round(per_um))
        return 1 / n, lambda a: a / n  # 1 nm: n = 1000, exact decimal values
    return precision_m * 1e6, lambda a: a * (precision_m * 1e6)


def _cell_count(cell: Any, memo: dict) -> str:
    """'5 polygons' once flattened, or what keeps it from being counted."""
    try:
        return _count(_flat_size(cell, memo)[1], "polygon")
    except InputError:
        return "broken references"


def _flat_size(cell: Any, memo: dict, stack: tuple = ()) -> tuple[int, int]:
    """(vertices, polygons) of ``cell`` flattened, counted from the hierarchy without flattening it."""
    import gdstk

    if cell.name in memo:
        return memo[cell.name]
    if cell.name in stack or len(stack) > MAX_DEPTH:
        raise InputError(f"cell {cell.name} references itself or nests deeper than {MAX_DEPTH} levels; fix the layout's hierarchy")
    v = n = 0
    for p in cell.polygons:
        k = max(1, p.repetition.size)
        v, n = v + k * p.size, n + k
    for path in cell.paths:
        k = max(1, path.repetition.size) * path.num_paths
        v, n = v + k * (2 * path.size + 8), n + k
    for ref in cell.references:
        if not isinstance(ref.cell, gdstk.Cell):
            raise InputError(f"cell {cell.name} references cell {ref.cell}, which the file does not hold; "
                             "export the layout with every cell it uses")
        cv, cn = _flat_size(ref.cell, memo, (*stack, cell.name))
        k = max(1, ref.repetition.size)
        v, n = v + k * cv, n + k * cn
    memo[cell.name] = (v, n)
    return v, n


# --------------------------------------------------------------------------- DXF
def _read_dxf(path: Path, cell: str | None, dxf_units: str | None, budget_mb: float | None) -> Layout:
    import ezdxf

    log = logging.getLogger("ezdxf")
    disabled, log.disabled = log.disabled, True  # ezdxf logs repairs; the result speaks for itself
    try:
        doc = ezdxf.readfile(str(path))
    except Exception as err:  # noqa: BLE001 - any parser failure on user input is bad input
        raise InputError(f"{path}: not a readable DXF file ({type(err).__name__}: {' '.join(str(err).split())[:200]}); "
                         "export it again from the drawing program") from None
    finally:
        log.disabled = disabled
    code = doc.header.get("$INSUNITS", 0)
    if code:
        if code not in INSUNITS:
            raise InputError(f"{path}: $INSUNITS = {code} is not a length unit selfalign reads; save the drawing in um, mm or nm")
        name, factor = INSUNITS[code]
        if dxf_units is not None and not math.isclose(DXF_UNITS[dxf_units], factor):
            raise InputError(f"{path}: the file states its units ($INSUNITS {name}) and --dxf-units says {dxf_units}; drop --dxf-units")
        units = f"$INSUNITS {name}"
    elif dxf_units is None:
        raise InputError(f"{path}: the DXF file states no units ($INSUNITS); pass --dxf-units um, mm or nm")
    else:
        name, factor = dxf_units, DXF_UNITS[dxf_units]
        units = f"--dxf-units {name} (the file states none)"
    if cell is None:
        space, cell_name = doc.modelspace(), "modelspace"
    else:
        space, cell_name = doc.blocks.get(cell), cell
        if space is None:
            blocks = [b for b in doc.blocks if not b.name.startswith("*")]
            listed = ", ".join(f"{b.name} ({_count(len(b), 'entity')})".replace("entitys", "entities") for b in blocks[:_MAX_LISTED])
            raise InputError(f"{path}: no block named {cell!r}; blocks present: {listed or 'none'} (or omit --cell for the model space)")
    n = _dxf_size(space, doc, {}, ())
    require_fits(f"flattening {cell_name} of {path} ({n:,} entities)", n * BYTES_PER_POLYGON * 4, "choose a smaller --cell", budget_mb)
    rings: dict[str, list[np.ndarray]] = {layer.dxf.name: [] for layer in doc.layers if layer.dxf.name not in ("0", "Defpoints")}
    problems: dict[str, str] = {}
    try:
        for layer, entity in _dxf_entities(space, None, 0):
            ring, problem = _dxf_ring(entity, factor)
            if problem:
                problems.setdefault(layer, problem)
            else:
                rings.setdefault(layer, []).extend(_on_grid(r) for r in ring)
    except ezdxf.DXFError as err:
        raise InputError(f"{path}: cannot flatten {cell_name} ({err}); explode the block references in the drawing program") from None
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
            raise InputError(f"block {name} inserts itself or nests deeper than {MAX_DEPTH} levels; fix the drawing")
        if name not in memo:
            block = doc.blocks.get(name)
            memo[name] = 0 if block is None else _dxf_size(block, doc, memo, (*stack, name))
        total += max(1, e.mcount) * memo[name]
    return total


def _dxf_entities(entities: Any, layer0: str | None, depth: int) -> Iterator[tuple[str, Any]]:
    """(layer, entity) of every entity, INSERTs expanded; a block's layer-0 entities take the INSERT's layer."""
    for e in entities:
        layer = e.dxf.get("layer", "0")
        if layer0 is not None and layer == "0":
            layer = layer0
        if e.dxftype() == "INSERT":
            if depth > MAX_DEPTH:
                raise InputError(f"block {e.dxf.name} nests deeper than {MAX_DEPTH} levels; fix the drawing")
            for one in e.multi_insert():
                yield from _dxf_entities(one.virtual_entities(), layer, depth + 1)
        else:
            yield layer, e


_OPEN = ("LINE", "ARC", "SPLINE", "RAY", "XLINE")
_IGNORED = ("TEXT", "MTEXT", "POINT", "DIMENSION", "LEADER", "MLEADER", "ATTRIB", "ATTDEF", "VIEWPORT", "IMAGE", "WIPEOUT")


def _xy(points: Any) -> np.ndarray:
    return np.array([(v[0], v[1]) for v in points], dtype=np.float64).reshape(-1, 2)


def _bulged(xyb: np.ndarray, closed: bool, tol: float) -> np.ndarray:
    """Vertices (n, 2) of a polyline whose segments may be arcs (bulge = tan(sweep / 4), CCW > 0).

    Arcs are sampled on the true circle so that the chords stay within ``tol`` of it.
    """
    from ezdxf.math import bulge_center

    out = []
    n = len(xyb)
    for i in range(n if closed else n - 1):
        (x0, y0, b), (x1, y1) = xyb[i], xyb[(i + 1) % n][:2]
        out.append((x0, y0))
        if b == 0 or (x0 == x1 and y0 == y1):
            continue
        sweep = 4 * math.atan(b)
        r = math.hypot(x1 - x0, y1 - y0) / (2 * abs(math.sin(sweep / 2)))
        c = bulge_center((x0, y0), (x1, y1), b)
        a0 = math.atan2(y0 - c.y, x0 - c.x)
        steps = max(1, math.ceil(abs(sweep) / (2 * math.acos(max(-1.0, 1 - tol / r)))))
        a = a0 + sweep * np.arange(1, steps) / steps
        out.extend(zip((c.x + r * np.cos(a)).tolist(), (c.y + r * np.sin(a)).tolist(), strict=True))
    if not closed and n:
        out.append(tuple(xyb[-1][:2]))
    return np.array(out, dtype=np.float64).reshape(-1, 2)


def _to_wcs(e: Any, pts: np.ndarray) -> np.ndarray:
    """Points in the entity's object coordinate system -> world coordinates (x, y)."""
    ocs = e.ocs()
    if not ocs.transform:
        return pts
    return _xy(ocs.points_to_wcs([(x, y, 0.0) for x, y in pts]))


def _dxf_ring(e: Any, factor: float) -> tuple[list[np.ndarray], str | None]:
    """(rings in um, None), ([], the problem), or ([], None) for an entity that is no outline (text)."""
    kind, handle = e.dxftype(), e.dxf.get("handle", "?")
    tol = DBU_UM / factor  # curves sampled within one database unit
    if kind in _IGNORED:
        return [], None
    if kind in _OPEN:
        return [], f"a {kind} (handle {handle}) is not a closed outline; join the outline into one closed polyline"
    if kind == "LWPOLYLINE":
        xyb, closed = np.array(e.get_points("xyb"), dtype=np.float64).reshape(-1, 3), e.closed
    elif kind == "POLYLINE":
        if not (e.is_2d_polyline or e.is_3d_polyline):
            return [], f"a POLYLINE mesh (handle {handle}) is not an outline; draw the pad as a closed polyline"
        xyb = np.array([(*v.dxf.location[:2], v.dxf.get("bulge", 0.0)) for v in e.vertices], dtype=np.float64).reshape(-1, 3)
        closed = e.is_closed
    if kind in ("LWPOLYLINE", "POLYLINE"):
        ends_meet = len(xyb) > 1 and np.allclose(xyb[0, :2], xyb[-1, :2], rtol=0, atol=tol)
        if len(xyb) and not closed and not ends_meet:
            (x0, y0), (x1, y1) = _to_wcs(e, xyb[[0, -1], :2]) * factor
            return [], (f"{kind} (handle {handle}) is open: it ends at ({x1:g}, {y1:g}) um, not at its start ({x0:g}, {y0:g}) um; "
                        "close it (set its closed flag) in the drawing program")
        rings = [_to_wcs(e, _bulged(xyb, closed or ends_meet, tol)) if not (kind == "POLYLINE" and e.is_3d_polyline)
                 else xyb[:, :2]]
    elif kind == "CIRCLE":
        rings = [_xy(e.flattening(tol))]
    elif kind == "ELLIPSE":
        if not math.isclose(abs(e.dxf.end_param - e.dxf.start_param) % (2 * math.pi), 0, abs_tol=1e-12):
            return [], f"an elliptic arc (handle {handle}) is not a closed outline; draw a full ellipse or a closed polyline"
        rings = [_xy(e.flattening(tol))]
    elif kind in ("SOLID", "TRACE", "3DFACE"):
        rings = [_xy(e.wcs_vertices())]
    elif kind == "HATCH":  # every polyline boundary; nested ones become holes (even-odd, as hatches fill)
        rings = []
        for b in e.paths:
            if not hasattr(b, "vertices"):
                return [], f"a HATCH (handle {handle}) bounded by edges; draw its outline as a closed polyline"
            rings.append(_to_wcs(e, _bulged(np.array([(v[0], v[1], v[2] if len(v) > 2 else 0.0) for v in b.vertices]).reshape(-1, 3), True, tol)))
    else:
        return [], f"a {kind} (handle {handle}) is not an outline selfalign reads; draw the pad as a closed polyline"
    out = []
    for r in rings:
        if len(r) > 1 and np.allclose(r[0], r[-1], rtol=0, atol=tol):
            r = r[:-1]
        out.append(r * factor)
    return out, None


def _on_grid(a: np.ndarray, dbu_um: float = DBU_UM) -> np.ndarray:
    """Coordinates (um) rounded to the ``dbu_um`` grid, as exactly as floats allow (1 nm: n / 1000)."""
    n = 1 / dbu_um
    if abs(n - round(n)) < 1e-9 * n:
        return np.round(a * round(n)) / round(n)
    return np.round(a / dbu_um) * dbu_um


# --------------------------------------------------------------------------- rings -> geometry
def _shoelace(r: np.ndarray) -> float:
    x, y = r[:, 0], r[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _polygons(rings: list[np.ndarray], where: str) -> list[Polygon]:
    """Valid polygons of the rings with an area; keyholes become holes; crossings are refused."""
    out = []
    for i, r in enumerate(rings):
        if len(r) < 3 or not np.all(np.isfinite(r)):
            continue
        poly = Polygon(r)
        if not poly.is_valid:
            parts = [g for g in shapely.get_parts(shapely.make_valid(poly)) if isinstance(g, Polygon) and g.area > 0]
            area = sum(g.area for g in parts)
            if area == 0:
                continue  # a degenerate polygon (a line): no area
            if not math.isclose(area, abs(_shoelace(r)), rel_tol=1e-9, abs_tol=1e-12):  # a keyhole keeps its area, a crossing does not
                m = re.search(r"\[([-\d.e+]+) ([-\d.e+]+)\]", shapely.is_valid_reason(poly))
                near = f" near ({float(m[1]):.6g}, {float(m[2]):.6g}) um" if m else ""
                raise InputError(f"{where}: polygon {i + 1} of {len(rings)} crosses itself{near}; "
                                 "split it into simple polygons in the layout editor")
            out.extend(parts)
        else:
            out.append(poly)
    return out


def _merge(polys: list[Polygon], nested: bool) -> BaseGeometry:
    """Union of the polygons (DXF: an outline inside another outline is a hole, by nesting depth)."""
    if nested and len(polys) > 1:
        unique = list({shapely.normalize(p).wkb: p for p in polys}.values())  # the same outline drawn twice counts once
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
        geom = MultiPolygon(polys) if np.all(a == b) else shapely.union_all(polys)  # disjoint: vertices kept as drawn
    parts = [g for g in shapely.get_parts(geom) if isinstance(g, Polygon) and g.area > 0]
    geom = parts[0] if len(parts) == 1 else MultiPolygon(parts)
    return shapely.orient_polygons(geom)


# --------------------------------------------------------------------------- the scene's view
def layout_geometry(path: str | os.PathLike, selection: LayoutSelection | None = None,
                    budget_mb: float | None = None) -> tuple[BaseGeometry, BaseGeometry | None, dict]:
    """(pattern, chip or None, record): the selected layers, moved to the frame of the module notes.

    The record (JSON-ready, kept as ``Mask.params["layout"]``) names the file, cell,
    layers, units, polygon count, exact area and ``origin_um``: the layout point that is
    the origin, with ``origin`` saying what it is.
    """
    sel = selection or LayoutSelection()
    lay = read_layout(path, sel.cell, sel.dxf_units, budget_mb)
    chip_key = lay.key(sel.chip_layer, "--chip-layer") if sel.chip_layer is not None else None
    if sel.layer is not None:
        key = lay.key(sel.layer)
    else:
        others = [k for k in (*lay.rings, *lay.problems) if k != chip_key and (lay.rings.get(k) or k in lay.problems)]
        others = list(dict.fromkeys(others))
        if len(others) != 1:
            raise InputError(f"{lay.path}: cell {lay.cell} has {'no layer' if not others else 'several layers'} "
                             f"({lay.layers_text()}); choose the pattern with --layer {'L/D' if lay.format != 'dxf' else 'NAME'}")
        key = others[0]
    if key == chip_key:
        raise InputError(f"--layer and --chip-layer name the same layer {_layer_text(key)}; the chip outline needs its own layer")
    pattern = lay.geometry(key)
    chip = lay.geometry(chip_key) if chip_key is not None else None
    ref = (chip if chip is not None else pattern).bounds
    cx, cy = (ref[0] + ref[2]) / 2, (ref[1] + ref[3]) / 2
    record = {
        "file": lay.path.name, "format": lay.format, "cell": lay.cell, "layer": _layer_text(key, quote=False),
        "polygons": len(shapely.get_parts(pattern)), "area_um2": pattern.area, "units": lay.units,
        "database_unit_um": lay.dbu_um, "origin_um": [cx, cy],
        "origin": (f"the centre of the chip outline on layer {_layer_text(chip_key)}" if chip is not None
                   else "the centre of the pattern's bounding box (no chip layer)"),
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
        if c >= s and (2 * math.ceil(hw / c) + 2) * (2 * math.ceil(hh / c) + 2) * RASTER_BYTES_PER_PX <= budget_bytes(budget_mb):
            return c
    return 10 ** (k + 1) * 2


def layout_mask(geometry: BaseGeometry, um_per_px: float, what: str, params: dict, budget_mb: float | None) -> Mask:
    """Rasterize layout geometry; over the budget, the refusal says which scale would fit."""
    from patterns.raster import mask_from_geometry

    s = positive("the layout raster's pixel size (--resolution)", um_per_px, "um per px")
    x0, y0, x1, y1 = geometry.bounds
    w, h = 2 * math.ceil(max(abs(x0), abs(x1)) / s), 2 * math.ceil(max(abs(y0), abs(y1)) / s)
    need = float(w) * float(h) * RASTER_BYTES_PER_PX
    if not need <= budget_bytes(budget_mb):
        fit = _fitting_scale(geometry, budget_mb)
        raise InputError(f"{what} at {s:g} um/px would be {w:,} x {h:,} px, about {fmt_bytes(need)}, over the memory budget of "
                         f"{fmt_bytes(budget_bytes(budget_mb))}; --resolution {fit:g} (um/px) or coarser would fit (or raise --memory-budget)")
    return mask_from_geometry(geometry, s, params=params, budget_mb=budget_mb, what=what)


def layout_masks(path: str | os.PathLike, selection: LayoutSelection | None, um_per_px: float,
                 budget_mb: float | None = None) -> tuple[Mask, Mask | None]:
    """(pattern mask, chip mask or None) of a layout at ``um_per_px``, exact geometry kept."""
    pattern, chip, record = layout_geometry(path, selection, budget_mb)
    name = Path(path).name
    pm = layout_mask(pattern, um_per_px, f"the pattern raster of {name}", {"layout": record}, budget_mb)
    cm = None
    if chip is not None:
        cm = layout_mask(chip, um_per_px, f"the chip raster of {name} (layer {record['chip_layer']})",
                         {"design": "layout", "layout": dict(record, layer=record["chip_layer"])}, budget_mb)
    return pm, cm


def layout_chip_mask(path: str | os.PathLike, um_per_px: float, selection: LayoutSelection | None = None,
                     budget_mb: float | None = None) -> Mask:
    """A chip footprint drawn in a layout of its own (``--chip chip.gds``): its only layer, centred on its bounding box.

    Only ``selection.dxf_units`` applies (the cell is the single top cell).
    """
    units = selection.dxf_units if selection is not None else None
    chip, _, record = layout_geometry(path, LayoutSelection(dxf_units=units), budget_mb)
    return layout_mask(chip, um_per_px, f"the chip raster of {Path(path).name}", {"design": "layout", "layout": record}, budget_mb)


def frame_note(record: dict) -> str:
    """One line saying where the origin of the poses is in the layout."""
    x, y = record["origin_um"]
    return (f"frame: {record['file']} cell {record['cell']} layer {record['layer']} ({_count(record['polygons'], 'polygon')}, "
            f"{record['units']}); poses are relative to {record['origin']}, at layout ({x:.6g}, {y:.6g}) um")


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
    parts = [g for g in shapely.get_parts(shapely.orient_polygons(geometry)) if isinstance(g, Polygon) and not g.is_empty]
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
        outer = gdstk.Polygon(_rounded(p.exterior), layer=layer, datatype=datatype)
        if p.interiors:
            holes = [gdstk.Polygon(_rounded(r)) for r in p.interiors]
            cell.add(*gdstk.boolean(outer, holes, "not", precision=DBU_UM, layer=layer, datatype=datatype))
        else:
            cell.add(outer)
    if fmt == "gds":  # 8190 vertices: the most one GDSII XY record holds, so no polygon is fractured
        lib.write_gds(str(tmp), max_points=8190, timestamp=datetime.datetime(2000, 1, 1))
    else:
        lib.write_oas(str(tmp))


def _write_dxf(tmp: Path, parts: list[Polygon]) -> None:
    import ezdxf

    doc = ezdxf.new("R2010")
    doc.units = 13  # $INSUNITS micrometres
    doc.header["$MEASUREMENT"] = 1
    doc.layers.add(WRITE_DXF_LAYER)
    msp = doc.modelspace()
    for p in parts:
        for ring in (p.exterior, *p.interiors):
            msp.add_lwpolyline(_rounded(ring).tolist(), close=True, dxfattribs={"layer": WRITE_DXF_LAYER})
    doc.saveas(tmp)
