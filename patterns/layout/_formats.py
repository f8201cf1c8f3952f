"""Layout formats, their units and layer names, and what to read (:class:`LayoutSelection`).

Owns the format of a file (from its content, else its extension: :data:`SUFFIXES`), the
constants the readers share (database unit, ``--dxf-units``, DXF ``$INSUNITS``, the memory
prices of reading and flattening, the deepest nesting), layer keys as the flags spell them
(``"L/D"`` for GDS/OASIS, a name for DXF), the 1 nm grid coordinates are snapped to, and
the counts and lengths the messages print. ``_read`` tells the whole story.
"""

from __future__ import annotations

import contextlib
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np

from foundation import InputError

#: File extensions of the layout formats (used when the content does not tell).
SUFFIXES = {
    ".gds": "gds",
    ".gdsii": "gds",
    ".gds2": "gds",
    ".oas": "oas",
    ".oasis": "oas",
    ".dxf": "dxf",
}
NAMES = {"gds": "GDSII", "oas": "OASIS", "dxf": "DXF"}
#: Database unit of written layouts and snapping grid of DXF coordinates (um): 1 nm.
DBU_UM = 1e-3
#: ``--dxf-units`` choices, in um.
DXF_UNITS = {"um": 1.0, "mm": 1e3, "nm": 1e-3}
#: DXF $INSUNITS codes -> (name, um).
INSUNITS = {
    1: ("inch", 25400.0),
    2: ("foot", 304800.0),
    4: ("mm", 1e3),
    5: ("cm", 1e4),
    6: ("m", 1e6),
    8: ("microinch", 0.0254),
    9: ("mil", 25.4),
    11: ("angstrom", 1e-4),
    12: ("nm", 1e-3),
    13: ("um", 1.0),
    14: ("dm", 1e5),
}
#: Peak bytes per flattened vertex and per polygon (gdstk/ezdxf copies, numpy rings, shapely).
BYTES_PER_VERTEX, BYTES_PER_POLYGON = 200, 2000
#: Peak bytes per byte of file while the parser holds it (gdstk; ezdxf keeps Python objects).
READ_FACTOR = {"gds": 4, "oas": 16, "dxf": 40}
#: Deepest reference nesting followed.
MAX_DEPTH = 64
#: Most polygons (DXF: entities) a cell may hold once flattened, unless ``--max-polygons``
#: (``max_polygons``) raises it: about 20 s of reading, merging and rasterizing per 100,000.
DEFAULT_MAX_POLYGONS = 100_000
#: Largest coordinate (and arc radius) a layout may have, um: 1 m. Beyond it a drawing's units
#: are wrong (a chip pattern spans millimetres), and floats overflow on the way to a raster.
MAX_COORD_UM = 1e6
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


def is_layout(path: Any) -> TypeGuard[str | os.PathLike]:
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
        raise InputError(
            f"{flag} {text!r}: give a layer and datatype as L/D, e.g. 1/0 (whole numbers)"
        )
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
    ``max_polygons``: the most polygons the cell may hold once flattened (None:
    :data:`DEFAULT_MAX_POLYGONS`); a limit, not a selection (:attr:`given` leaves it out).
    """

    layer: str | None = None
    cell: str | None = None
    chip_layer: str | None = None
    dxf_units: str | None = None
    max_polygons: int | None = None

    def __post_init__(self) -> None:
        for name in ("layer", "cell", "chip_layer"):
            v = getattr(self, name)
            if v is not None and (
                not isinstance(v, str | int) or isinstance(v, bool) or not str(v).strip()
            ):
                raise InputError(
                    f"{name} must be a non-empty string (a layer L/D, a DXF layer or a cell name), got {v!r}"
                )
        if self.dxf_units is not None and self.dxf_units not in DXF_UNITS:
            raise InputError(
                f"dxf_units must be one of {', '.join(DXF_UNITS)}, got {self.dxf_units!r}"
            )
        m = self.max_polygons
        if m is not None and (isinstance(m, bool) or not isinstance(m, int) or m < 1):
            raise InputError(
                f"max_polygons (--max-polygons) must be a whole number >= 1, got {m!r}"
            )

    @property
    def given(self) -> list[str]:
        """The flags that were set, as the command line spells them."""
        return [
            f"--{k.replace('_', '-')}"
            for k in ("layer", "cell", "chip_layer", "dxf_units")
            if getattr(self, k) is not None
        ]

    def require_unused(self, what: str, units_ok: bool = False) -> None:
        """InputError if a layout flag is set for a pattern that is not a layout (``units_ok``: a DXF chip may use --dxf-units)."""
        given = [f for f in self.given if not (units_ok and f == "--dxf-units")]
        if given:
            raise InputError(
                f"{', '.join(given)} apply to layout patterns (.gds, .oas, .dxf); {what} is not one"
            )


#: Seconds of reading, merging and rasterizing per flattened polygon (20 s per 100,000),
#: for the waiting line of :func:`layout_wait_line`.
S_PER_POLYGON = 2e-4


def layout_wait_line(n: int, what: str) -> bool:
    """Say on stderr that ``n`` flattened polygons of ``what`` are being read, merged and
    rasterized, when that takes long: the command line's waiting line (its threshold,
    ``SELFALIGN_WAIT_S``, and ``--quiet``), through the simulator's progress module when the
    process has loaded it; silent for a library caller without it. Returns whether shown."""
    import sys

    progress = sys.modules.get("foundation")
    if progress is None:
        return False
    seconds = n * S_PER_POLYGON
    return progress.wait_line(
        f"reading, merging and rasterizing the {n:,} polygons of {what} (about {seconds:,.0f} s)",
        seconds,
    )


def require_polygon_count(n: int, what: str, limit: int | None) -> None:
    """InputError unless ``n`` flattened polygons (counted from the hierarchy, before flattening) are within ``limit``."""
    limit = DEFAULT_MAX_POLYGONS if limit is None else int(limit)
    if n > limit:
        raise InputError(
            f"{what} holds {n:,} polygons once flattened, over the limit of {limit:,} (reading, merging and "
            f"rasterizing take about 20 s per 100,000); choose a smaller --cell, or raise the limit with --max-polygons {n}"
        )


# --------------------------------------------------------------------------- units and counts
def _count(n: int, word: str) -> str:
    return f"{n:,} {word}{'' if n == 1 else 's'}"


def _fmt_len(metres: float) -> str:
    for unit, k in (("m", 1.0), ("mm", 1e-3), ("um", 1e-6), ("nm", 1e-9), ("pm", 1e-12)):
        if metres >= k * (1 - 1e-9):
            return f"{metres / k:.6g} {unit}"
    return f"{metres:g} m"


def _on_grid(a: np.ndarray, dbu_um: float = DBU_UM) -> np.ndarray:
    """Coordinates (um) rounded to the ``dbu_um`` grid, as exactly as floats allow (1 nm: n / 1000)."""
    n = 1 / dbu_um
    if abs(n - round(n)) < 1e-9 * n:
        return np.round(a * round(n)) / round(n)
    return np.round(a / dbu_um) * dbu_um
