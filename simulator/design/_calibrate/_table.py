"""The bench table of ``selfalign calibrate``: nominal starts, how many of their trials
aligned, and optionally the median time to align and the placement noise of each row.

:func:`read_trials` reads and checks a CSV file before any work: every refusal is one line
naming the file, the row (the file's line number, the header being line 1) and the column,
and the fix.
"""

from __future__ import annotations

import csv
import difflib
import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from foundation import InputError, require_regular_file

#: The columns every row gives: the nominal start (um, um, degrees) and its counts.
REQUIRED = ("x_um", "y_um", "twist_deg", "trials", "aligned")
#: Columns a row may give: the median time to align (s) and the placement noise (standard
#: deviations, um, um, degrees) of that row (else ``--spread``).
OPTIONAL = ("time_s", "sigma_x_um", "sigma_y_um", "sigma_twist_deg")
SIGMAS = ("sigma_x_um", "sigma_y_um", "sigma_twist_deg")
#: The most rows a table may hold.
MAX_ROWS = 10_000
#: The largest file read (bytes).
MAX_BYTES = 16 * 2**20


@dataclass(frozen=True, eq=False)
class BenchTable:
    """A bench table, checked: per row the nominal start ``start`` (R, 3: x_um, y_um,
    twist_deg), ``trials`` and ``aligned`` (R,) counts, ``time_s`` (R,; NaN where the row
    gives none) and ``sigma`` (R, 3; NaN where the row gives none). ``line``: each row's
    line in the file; ``digest``: the hash of the numbers (what a resumed fit must match)."""

    source: str
    start: np.ndarray
    trials: np.ndarray
    aligned: np.ndarray
    time_s: np.ndarray
    sigma: np.ndarray
    line: tuple[int, ...]

    @property
    def n(self) -> int:
        return len(self.trials)

    @property
    def has_times(self) -> bool:
        return bool(np.isfinite(self.time_s).any())

    @property
    def digest(self) -> str:
        h = hashlib.sha256()
        for a in (self.start, self.trials, self.aligned, self.time_s, self.sigma):
            h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
        return h.hexdigest()

    def with_spread(self, spread: tuple[float, float, float] | None) -> np.ndarray:
        """(R, 3) placement noise: each row's own, else ``spread`` (InputError when a row
        has neither)."""
        sig = self.sigma.copy()
        missing = ~np.isfinite(sig)
        if missing.any():
            if spread is None:
                r, c = np.argwhere(missing)[0]
                raise InputError(
                    f"{self.source} row {self.line[r]}, column {SIGMAS[c]}: no placement noise for this row; "
                    f"give --spread SX,SY,STWIST (um, um, degrees) or a {SIGMAS[c]} value"
                )
            sig[missing] = np.broadcast_to(np.asarray(spread, dtype=float), sig.shape)[missing]
        return sig


def _fail(source: str, line: int, column: str, text: str) -> InputError:
    return InputError(f"{source} row {line}, column {column}: {text}")


def read_trials(path: str | os.PathLike) -> BenchTable:
    """Read and check a bench table (CSV, a header line then one row per nominal start).

    Refused (:class:`InputError`, one line naming the file, row and column and the fix): a
    file that cannot be read, a missing or unknown column, an empty table, a cell that is
    not a finite number (NaN, inf, text), negative or fractional counts, ``trials`` of 0 or
    below ``aligned``, a ``time_s`` that is not > 0 or given for a row none of whose trials
    aligned, a negative placement noise.
    """
    p = require_regular_file(path, "trials")
    src = str(path)
    if p.stat().st_size > MAX_BYTES:
        raise InputError(
            f"{src}: the trials file is over {MAX_BYTES // 2**20} MB; a bench table is a few rows"
        )
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{src}: not a text (UTF-8) CSV file; save the table as CSV") from None
    rows = list(csv.reader(text.splitlines()))
    lines = [i + 1 for i, r in enumerate(rows) if any(c.strip() for c in r)]
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise InputError(
            f"{src}: the trials file is empty; give a header {','.join(REQUIRED)} and one row per nominal start"
        )
    header = [c.strip() for c in rows[0]]
    known = REQUIRED + OPTIONAL
    for c in header:
        if c not in known:
            near = difflib.get_close_matches(c, known, n=1, cutoff=0.6)
            hint = f"did you mean {near[0]}? " if near else ""
            raise InputError(
                f"{src} row {lines[0]} (header): unknown column {c!r}; {hint}the columns are "
                f"{', '.join(REQUIRED)} (required) and {', '.join(OPTIONAL)} (optional)"
            )
    dup = [c for c in header if header.count(c) > 1]
    if dup:
        raise InputError(f"{src} row {lines[0]} (header): column {dup[0]} is given twice")
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise InputError(
            f"{src} row {lines[0]} (header): missing column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(missing)}; the header must name {','.join(REQUIRED)} (optional: {', '.join(OPTIONAL)})"
        )
    body = list(zip(lines[1:], rows[1:], strict=True))
    if not body:
        raise InputError(
            f"{src}: the table has a header but no rows; give one row per nominal start ({','.join(REQUIRED)})"
        )
    if len(body) > MAX_ROWS:
        raise InputError(
            f"{src}: {len(body):,} rows; at most {MAX_ROWS:,} (merge rows of the same nominal start)"
        )
    col = {c: header.index(c) for c in header}
    out = {c: np.full(len(body), np.nan) for c in known}
    for k, (line, row) in enumerate(body):
        if len(row) > len(header):
            raise InputError(
                f"{src} row {line}: {len(row)} cells for {len(header)} columns; remove the extra cells"
            )
        for c, j in col.items():
            cell = row[j].strip() if j < len(row) else ""
            if cell == "":
                if c in REQUIRED:
                    raise _fail(src, line, c, "empty; every row gives " + ", ".join(REQUIRED))
                continue
            try:
                v = float(cell)
            except ValueError:
                raise _fail(src, line, c, f"{cell!r} is not a number") from None
            if not math.isfinite(v):
                raise _fail(src, line, c, f"{cell!r} is not a finite number; give a value")
            out[c][k] = v
        for c in ("trials", "aligned"):
            v = out[c][k]
            if v < 0:
                raise _fail(src, line, c, f"{v:g} is negative; a count is a whole number >= 0")
            if v != int(v):
                raise _fail(src, line, c, f"{v:g} is not a whole number; give a count")
        if out["trials"][k] < 1:
            raise _fail(src, line, "trials", "0 trials; a row needs at least one trial")
        if out["trials"][k] < out["aligned"][k]:
            raise _fail(
                src,
                line,
                "aligned",
                f"{out['aligned'][k]:g} aligned of {out['trials'][k]:g} trials; aligned cannot exceed trials",
            )
        t = out["time_s"][k]
        if math.isfinite(t):
            if t <= 0:
                raise _fail(src, line, "time_s", f"{t:g} s; a time to align is > 0 s")
            if out["aligned"][k] == 0:
                raise _fail(
                    src,
                    line,
                    "time_s",
                    "a time to align for a row none of whose trials aligned; leave it empty",
                )
        for c in SIGMAS:
            if out[c][k] < 0:
                raise _fail(src, line, c, f"{out[c][k]:g}; a placement noise is >= 0")
        if abs(out["twist_deg"][k]) > 180 or max(abs(out["x_um"][k]), abs(out["y_um"][k])) > 1e6:
            bad = "twist_deg" if abs(out["twist_deg"][k]) > 180 else "x_um"
            raise _fail(src, line, bad, f"{out[bad][k]:g} is out of range (|twist| <= 180 deg)")
    return BenchTable(
        source=src,
        start=np.stack([out["x_um"], out["y_um"], out["twist_deg"]], axis=1),
        trials=out["trials"].astype(np.int64),
        aligned=out["aligned"].astype(np.int64),
        time_s=out["time_s"],
        sigma=np.stack([out[c] for c in SIGMAS], axis=1),
        line=tuple(line for line, _ in body),
    )


def write_trials(path: str | os.PathLike, rows: list[dict]) -> Path:
    """Write a bench table (the columns the rows give, required first) atomically: what a
    synthetic example or a test hands to :func:`read_trials`."""
    from foundation import atomic_output

    cols = [c for c in REQUIRED + OPTIONAL if any(c in r for r in rows)]
    with atomic_output(path) as tmp:
        lines = [",".join(cols)]
        for r in rows:
            lines.append(",".join("" if r.get(c) is None else f"{r[c]:.10g}" for c in cols))
        Path(tmp).write_text("\n".join(lines) + "\n")
    return Path(path)
