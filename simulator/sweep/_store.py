"""The results of a sweep: rows in memory and the resumable results directory.

Owns ``_Store``: the directory's checks (a non-empty directory is resumed only when its
``sweep.json`` holds this very sweep's hash; never the working directory or one that
holds an input), its lock, the journal ``points.jsonl`` (appended and flushed as each
point finishes, read back on a rerun), each point's ``points/NNNNN.json``, the tables
``results.parquet`` and ``results.csv`` (rewritten atomically every few seconds and at
the end) and the ownership marker. pandas and pyarrow are imported when a table is built.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Iterable
from pathlib import Path

from patterns.errors import InputError, require
from patterns.hold import hold
from simulator.sweep._columns import STATUS_COLUMNS, flatten
from simulator.sweep._spec import SweepSpec

#: Seconds between rewrites of results.parquet / results.csv while a sweep runs.
FLUSH_S = 2.0

MANIFEST = "sweep.json"
JOURNAL = "points.jsonl"
POINTS_DIR = "points"
LOCK = ".sweep.lock"
TABLES = ("results.parquet", "results.csv")


# ----------------------------------------------------------------------- the store
def _write_text(path: Path, text: str) -> None:
    from patterns.outputs import atomic_output

    with atomic_output(path) as tmp:
        tmp.write_text(text)


def _version() -> str:
    """selfalign's version, for the record (not part of a sweep's hash)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("selfalign")
    except PackageNotFoundError:
        return "unknown"


class _Store:
    """The rows of a sweep, in memory and (with ``out``) in a resumable directory."""

    def __init__(
        self,
        spec: SweepSpec,
        out: str | os.PathLike | None,
        inputs: Iterable[Path] = (),
        flush_s: float = FLUSH_S,
    ):
        """Check ``out`` (and, for a sweep already there, take its lock and read its rows); create nothing."""
        from patterns.outputs import check_output_dir

        self.spec, self.flush_s = spec, flush_s
        self.out = Path(out) if out is not None else None
        self.inputs = list(inputs)
        self.rows: dict[int, dict] = {}
        self._lock = None
        self._journal = None
        self._next_flush = 0.0
        self.existing = False
        if self.out is None:
            return
        if self.out.is_dir() and not self.out.is_symlink() and any(self.out.iterdir()):
            self._check_same(self.out, self.inputs)
            self.existing = True
            self._take_lock()
            self._read_journal()
        else:
            check_output_dir(self.out, "--out", False, self.inputs)

    # .................................................................. directory
    def open(self) -> None:
        """Create the directory (when new) and its manifest; open the journal for appending."""
        from patterns.outputs import check_output_dir

        out = self.out
        if out is None:
            return
        if not self.existing:
            check_output_dir(out, "--out", False, self.inputs)  # nothing changed meanwhile
            out.mkdir(exist_ok=True)
            self._take_lock()
        (out / POINTS_DIR).mkdir(exist_ok=True)
        if not (out / MANIFEST).exists():
            _write_text(
                out / MANIFEST,
                json.dumps(
                    {
                        "tool": "selfalign",
                        "version": _version(),
                        "command": "sweep",
                        "hash": self.spec.digest,
                        **self.spec.describe(),
                    },
                    indent=1,
                    default=str,
                )
                + "\n",
            )
        self._journal = open(out / JOURNAL, "a", encoding="utf-8")  # noqa: SIM115 (closed in close())

    def _check_same(self, out: Path, inputs: list[Path]) -> None:
        """A non-empty ``out`` is resumed only when it holds this very sweep."""
        flag = "--out"
        man = out / MANIFEST
        r = out.resolve()
        cwd = Path.cwd().resolve()
        require(
            not (r == cwd or r in cwd.parents),
            f"{flag} {out}: is the working directory or holds it; give a new directory name",
        )
        for inp in inputs:
            ri = inp.resolve()
            require(
                not (r == ri or r in ri.parents),
                f"{flag} {out}: holds an input of this sweep ({inp.name}); give a new directory name",
            )
        if not man.is_file():
            raise InputError(
                f"{flag} {out}: holds files that are not a selfalign sweep; choose a new or empty directory"
            )
        try:
            doc = json.loads(man.read_text())
            theirs = doc["hash"]
        except (OSError, ValueError, KeyError, TypeError):
            raise InputError(
                f"{flag} {out}: its {MANIFEST} cannot be read; choose a new or empty directory"
            ) from None
        if theirs != self.spec.digest:
            raise InputError(
                f"{flag} {out}: holds a different sweep ({doc.get('source', '?')}, {doc.get('points', '?')} points, hash {str(theirs)[:12]}; "
                f"this one is {self.spec.digest[:12]}); choose another --out (sweeps are never mixed)"
            )
        require(os.access(out, os.W_OK), f"{flag} {out}: directory is not writable")

    def _take_lock(self) -> None:
        import fcntl

        f = open(self.out / LOCK, "a+")  # noqa: SIM115 (held until close())
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            raise InputError(
                f"--out {self.out}: another selfalign sweep is writing into it; wait for it to end or choose another --out"
            ) from None
        self._lock = f

    def _read_journal(self) -> None:
        path = self.out / JOURNAL
        if not path.exists():
            return
        data = path.read_bytes()
        end = data.rfind(b"\n") + 1
        if end < len(data):  # a line cut short by a kill: dropped, so the next line starts clean
            with open(path, "rb+") as f:
                f.truncate(end)
        n = self.spec.n_points
        for line in data[:end].splitlines():
            try:
                row = json.loads(line)
                i = int(row["point"])
            except (ValueError, KeyError, TypeError):
                continue
            if 0 <= i < n:
                self.rows[i] = row

    # .................................................................. rows
    def done(self, retry_failed: bool) -> set[int]:
        return {i for i, r in self.rows.items() if r.get("status") == "ok" or not retry_failed}

    def add(self, point: dict, result: dict) -> dict:
        row = self.spec.columns(point) | {k: result.get(k) for k in STATUS_COLUMNS}
        if result.get("summary") is not None:
            row |= flatten(result["summary"])
        i = point["point"]
        self.rows[i] = row
        if self.out is not None:
            width = max(5, len(str(self.spec.n_points - 1)))
            doc = {
                "point": i,
                "settings": point["values"],
                "row": row,
                "summary": result.get("summary"),
            }
            _write_text(
                self.out / POINTS_DIR / f"{i:0{width}d}.json",
                json.dumps(doc, indent=1, allow_nan=False) + "\n",
            )
            self._journal.write(json.dumps(row, allow_nan=False) + "\n")
            self._journal.flush()
            hold("sweep-point")
            if time.monotonic() >= self._next_flush:
                self.write_tables()
        return row

    def table(self):
        """All rows, by point, as a pandas DataFrame (columns: identity, settings, status, metrics)."""
        import pandas as pd

        rows = [self.rows[i] for i in sorted(self.rows)]
        cols: dict[str, None] = {}
        for r in (
            rows
        ):  # rows are built identity, settings, status, metrics: their union keeps that order
            cols.update(dict.fromkeys(r))
        return pd.DataFrame(rows, columns=list(cols)) if rows else pd.DataFrame(columns=list(cols))

    def write_tables(self) -> None:
        if self.out is None:
            return
        import pyarrow as pa
        import pyarrow.parquet as pq

        t0 = time.monotonic()
        df = self.table()
        from patterns.outputs import atomic_output

        with atomic_output(self.out / TABLES[0]) as tmp:
            pq.write_table(pa.Table.from_pandas(df, preserve_index=False), tmp)
        with atomic_output(self.out / TABLES[1]) as tmp:
            df.to_csv(tmp, index=False)
        now = time.monotonic()
        self._next_flush = now + max(
            self.flush_s, 10 * (now - t0)
        )  # a large table: at most a tenth of the time on rewriting it

    def write_marker(self) -> None:
        from patterns.outputs import MARKER, _listing

        files = [
            e
            for e in _listing(self.out)
            if not e.endswith("/") and e != MARKER and not e.startswith(".") and "/." not in e
        ]
        _write_text(
            self.out / MARKER,
            json.dumps(
                {"tool": "selfalign", "command": "sweep", "files": sorted(files + [LOCK])}, indent=1
            )
            + "\n",
        )

    def close(self) -> None:
        if self._journal is not None:
            with contextlib.suppress(OSError):
                self._journal.flush()
                os.fsync(self._journal.fileno())
            self._journal.close()
            self._journal = None
        if self._lock is not None:
            self._lock.close()
            self._lock = None


def kept_points(out: str | os.PathLike) -> int:
    """How many points the journal of the results directory ``out`` holds (finished, ok or
    failed; a line cut short does not count): what a rerun resumes from."""
    try:
        data = (Path(out) / JOURNAL).read_bytes()
    except OSError:
        return 0
    seen = set()
    for line in data[: data.rfind(b"\n") + 1].splitlines():
        try:
            seen.add(int(json.loads(line)["point"]))
        except (ValueError, KeyError, TypeError):
            continue
    return len(seen)
