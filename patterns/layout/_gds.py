"""Reading GDSII and OASIS files with gdstk (imported only when such a file is read).

The cell chosen (the single top cell, or ``--cell``) is priced from its hierarchy before it
is flattened (references, arrays, repetitions, paths as outlines); coordinates are whole
database units converted to micrometres with the file's database unit; gdstk's own
messages on stderr become the one-line refusal of an unreadable file.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
import warnings
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import numpy as np

from foundation import InputError, positive, require_fits
from patterns.layout._cell import Layout
from patterns.layout._formats import (
    _MAX_LISTED,
    BYTES_PER_POLYGON,
    BYTES_PER_VERTEX,
    MAX_DEPTH,
    NAMES,
    _count,
    _fmt_len,
    layout_wait_line,
    require_polygon_count,
)


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


#: Length of an OASIS file's END record (SEMI P39: the last 256 bytes of every complete file).
OASIS_END_BYTES = 256


def _varint(b: bytes, i: int) -> tuple[int, int]:
    """An OASIS unsigned integer at ``b[i]`` (7 bits a byte, low first): (value, next index); IndexError past the end."""
    v = shift = 0
    while True:
        c = b[i]
        i += 1
        v |= (c & 0x7F) << shift
        shift += 7
        if c < 0x80:
            return v, i
        if shift > 63:
            raise ValueError("an integer longer than 64 bits")


def _oasis_incomplete(path: Path) -> str | None:
    """Why an OASIS file is not complete (cut short, or its validation signature does not match), or None.

    gdstk reads the records it can and stops without a word at a cut (or crashes): a truncated
    file must be refused before it sees it. A complete file ends in its 256-byte END record:
    the table offsets (when START says so), a padding string, the validation scheme and,
    for CRC32 or checksum, the signature, which is checked too.
    """
    data = path.read_bytes()
    start = len(b"%SEMI-OASIS\r\n")
    try:
        if data[start] != 1:
            return "no START record after the magic"
        n, i = _varint(data, start + 1)  # version a-string
        i += n
        kind, i = _varint(data, i)  # unit: a real
        if kind in (0, 1, 2, 3):
            _, i = _varint(data, i)
        elif kind in (4, 5):
            _, i = _varint(data, i)
            _, i = _varint(data, i)
        elif kind in (6, 7):
            i += 4 if kind == 6 else 8
        else:
            return f"a START record with a unit of unknown real type {kind}"
        offsets_in_end, i = _varint(data, i)
        if len(data) < i + OASIS_END_BYTES:
            return f"it is cut short at {len(data):,} bytes, too short to hold its {OASIS_END_BYTES}-byte END record"
        j = len(data) - OASIS_END_BYTES
        if data[j] != 2:
            return f"it is cut short or damaged (its last {OASIS_END_BYTES} bytes are not an END record)"
        j += 1
        if offsets_in_end:
            for _ in range(12):
                _, j = _varint(data, j)
        pad, j = _varint(data, j)
        scheme, j = _varint(data, j + pad)
        sig = 4 if scheme in (1, 2) else 0
        if scheme not in (0, 1, 2) or j + sig != len(data):
            return f"it is cut short or damaged (its last {OASIS_END_BYTES} bytes are not an END record)"
    except (IndexError, ValueError):
        return "it is cut short or damaged (a record runs past the end of the file)"
    if scheme == 1 and zlib.crc32(data[:-4]) != int.from_bytes(data[-4:], "little"):
        return "its CRC32 signature does not match its content (damaged or cut and padded)"
    if scheme == 2 and sum(data[:-4]) % 2**32 != int.from_bytes(data[-4:], "little"):
        return "its checksum does not match its content (damaged or cut and padded)"
    return None


def _read_gdstk(
    path: Path, fmt: str, cell: str | None, budget_mb: float | None, max_polygons: int | None = None
) -> Layout:
    import gdstk

    if fmt == "oas":
        why = _oasis_incomplete(path)
        if why:
            raise InputError(f"{path}: not a complete OASIS file ({why}); copy or export it again")
    failure = None
    with _c_stderr() as said, warnings.catch_warnings():
        warnings.simplefilter(
            "ignore"
        )  # "Missing reference": refused below when the cell read needs it
        try:
            lib = gdstk.read_gds(str(path)) if fmt == "gds" else gdstk.read_oas(str(path))
        except (OSError, RuntimeError, ValueError, MemoryError) as err:
            failure = err
    notes = "; ".join(
        t.strip() for t in " ".join(said).replace("[GDSTK]", ".").split(".") if t.strip()
    )
    if failure is not None:
        detail = notes or str(failure)
        raise InputError(
            f"{path}: not a readable {NAMES[fmt]} file ({detail}); export it again from the layout editor"
        )
    cells = {c.name: c for c in lib.cells}
    counts: dict[str, int] = {}
    if cell is None:
        tops = lib.top_level()
        if len(tops) != 1:
            listed = (
                ", ".join(f"{c.name} ({_cell_count(c, counts)})" for c in tops[:_MAX_LISTED])
                or "none"
            )
            raise InputError(
                f"{path}: {len(tops)} top cells ({listed}); choose one with --cell NAME"
            )
        top = tops[0]
    elif cell in cells:
        top = cells[cell]
    else:
        listed = (
            ", ".join(
                f"{n} ({_cell_count(c, counts)})" for n, c in list(cells.items())[:_MAX_LISTED]
            )
            or "none"
        )
        raise InputError(
            f"{path}: no cell named {cell!r}; cells present: {listed}; choose one with --cell NAME"
        )
    try:
        vertices, polygons = _flat_size(top, counts)
    except InputError as err:
        raise InputError(f"{path}: {err}") from None
    require_polygon_count(polygons, f"{path}: cell {top.name}", max_polygons)
    require_fits(
        f"flattening cell {top.name} of {path} ({polygons:,} polygons, {vertices:,} vertices)",
        vertices * BYTES_PER_VERTEX + polygons * BYTES_PER_POLYGON,
        "choose a smaller --cell",
        budget_mb,
    )
    layout_wait_line(polygons, f"cell {top.name} of {path.name}")
    for name, v in (("database unit", lib.precision), ("user unit", lib.unit)):
        if not (math.isfinite(v) and v > 0):  # a zero unit would divide by zero below
            raise InputError(
                f"{path}: the file's UNITS record gives a {name} of {v:g} m, not a length > 0; export it again from the layout editor"
            )
    db_per_user = lib.unit / lib.precision  # user coordinates x this = database units
    if abs(db_per_user - round(db_per_user)) < 1e-9 * db_per_user:
        db_per_user = float(round(db_per_user))
    rings: dict[Any, list[np.ndarray]] = {}
    # read_gds and read_oas make Cells (a RawCell comes from read_rawcells only)
    flat = cast("gdstk.Cell", top).get_polygons(
        apply_repetitions=True, include_paths=True, depth=None
    )
    for p in flat:
        rings.setdefault((int(p.layer), int(p.datatype)), []).append(
            # points is an (n, 2) array; gdstk's stub says a list of pairs
            np.round(p.points * db_per_user)  # pyright: ignore[reportOperatorIssue]
        )
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
        raise InputError(
            f"cell {cell.name} references itself or nests deeper than {MAX_DEPTH} levels; fix the layout's hierarchy"
        )
    v = n = 0
    for p in cell.polygons:
        k = max(1, p.repetition.size)
        v, n = v + k * p.size, n + k
    for path in cell.paths:
        k = max(1, path.repetition.size) * path.num_paths
        v, n = v + k * (2 * path.size + 8), n + k
    for ref in cell.references:
        if not isinstance(ref.cell, gdstk.Cell):
            raise InputError(
                f"cell {cell.name} references cell {ref.cell}, which the file does not hold; "
                "export the layout with every cell it uses"
            )
        cv, cn = _flat_size(ref.cell, memo, (*stack, cell.name))
        k = max(1, ref.repetition.size)
        v, n = v + k * cv, n + k * cn
    memo[cell.name] = (v, n)
    return v, n
