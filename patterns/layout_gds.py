"""Reading GDSII and OASIS files with gdstk (imported only when such a file is read).

The cell chosen (the single top cell, or ``--cell``) is priced from its hierarchy before it
is flattened (references, arrays, repetitions, paths as outlines); coordinates are whole
database units converted to micrometres with the file's database unit; gdstk's own
messages on stderr become the one-line refusal of an unreadable file.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from patterns.errors import InputError, positive
from patterns.layout_cell import Layout
from patterns.layout_formats import (
    _MAX_LISTED,
    BYTES_PER_POLYGON,
    BYTES_PER_VERTEX,
    MAX_DEPTH,
    NAMES,
    _count,
    _fmt_len,
)
from patterns.resources import require_fits


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
