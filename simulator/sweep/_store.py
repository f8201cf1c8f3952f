"""The results of a sweep: rows in memory and the resumable results directory.

Owns :class:`ResultStore` (a resumable directory of rows, also a search's) and
``_Store``, the sweep's: the directory's checks (a non-empty directory is resumed only when its
``sweep.json`` holds this very sweep's hash; never the working directory or one that
holds an input), its lock (removed at the end; a killed run's lock and temporaries are
removed by the next run there), the journal ``points.jsonl`` (appended and flushed as each
point finishes, read back on a rerun), each point's ``points/NNNNN.json``, the tables
``results.parquet`` and ``results.csv`` (rewritten atomically every few seconds and at
the end) and the ownership marker. pandas and pyarrow are imported when a table is built.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import time
from collections.abc import Iterable
from pathlib import Path
from typing import TextIO

from foundation import InputError, hold, json_text, require
from simulator.sweep._columns import STATUS_COLUMNS, flatten
from simulator.sweep._spec import SweepSpec
from simulator.sweep._task import SweepPoint

#: Seconds between rewrites of results.parquet / results.csv while a sweep runs.
FLUSH_S = 2.0

MANIFEST = "sweep.json"
JOURNAL = "points.jsonl"
POINTS_DIR = "points"
LOCK = ".sweep.lock"
TABLES = ("results.parquet", "results.csv")


__all__ = ["ResultStore", "kept_points"]


# ----------------------------------------------------------------------- leftovers
#: A file written atomically (:func:`foundation.atomic_output`): ``.NAME.XXXXXXXX.EXT``
#: beside ``NAME.EXT`` (``tempfile``'s eight random characters, then the target's suffix).
_TEMP_FILE = re.compile(r"^\.(?P<name>.+)\.[a-z0-9_]{8}(?P<ext>\.[^./]+)?$")


def _is_temp_file(name: str) -> bool:
    m = _TEMP_FILE.match(name)
    return bool(m) and Path(m["name"]).suffix == (m["ext"] or "")


def remove_dead_files(directory: Path, subdirs: tuple[str, ...] = ()) -> list[str]:
    """Remove the atomic-write temporaries a killed run (SIGKILL, the out-of-memory killer: no
    handler ran) left in ``directory`` (and its ``subdirs``), for a caller that holds the
    directory's lock (nothing else writes there); only such names are removed. Returns them."""
    gone = []
    for d in (directory, *(directory / s for s in subdirs)):
        try:
            entries = list(os.scandir(d))
        except OSError:
            continue
        for e in entries:
            if _is_temp_file(e.name) and e.is_file(follow_symlinks=False):
                with contextlib.suppress(OSError):
                    os.unlink(e.path)
                    gone.append(str(Path(e.path).relative_to(directory)))
    return gone


# ----------------------------------------------------------------------- the store
def _write_text(path: Path, text: str) -> None:
    from foundation import atomic_output

    with atomic_output(path) as tmp:
        tmp.write_text(text)


def _version() -> str:
    """selfalign's version, for the record (not part of a sweep's hash)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("selfalign")
    except PackageNotFoundError:
        return "unknown"


class ResultStore:
    """A resumable results directory of rows, one per key (a sweep's point, a search's trial).

    Owns the directory's checks (a non-empty directory is resumed only when its manifest
    holds this very run's hash; never the working directory or one that holds an input),
    its lock, the journal (one JSON row per line, appended and flushed as each finishes,
    read back on a rerun), each row's ``ROWS_DIR/NNNNN.json``, the tables (rewritten
    atomically every ``flush_s`` seconds and at the end) and the ownership marker. The
    class attributes name the files and the words of its messages; :class:`_Store` is the
    sweep's, :mod:`simulator.design` has the search's.
    """

    COMMAND = "sweep"  # the command, in the manifest, the marker and the messages
    KEY = "point"  # the column that numbers the rows
    MANIFEST, JOURNAL, ROWS_DIR, LOCK, TABLES = MANIFEST, JOURNAL, POINTS_DIR, LOCK, TABLES
    HOLD = "sweep-point"  # the hold point after each row (foundation)

    def __init__(
        self,
        out: str | os.PathLike | None,
        digest: str,
        describe: dict,
        *,
        n: int | None = None,
        inputs: Iterable[Path] = (),
        flush_s: float = FLUSH_S,
    ):
        """Check ``out`` (and, for a run already there, take its lock and read its rows); create nothing.

        ``digest``: the run's hash (what a rerun must match); ``describe``: what the manifest
        records beside it; ``n``: rows are numbered below it (None: any number from 0).
        """
        from foundation import check_output_dir

        self.digest, self.describe, self.n, self.flush_s = digest, describe, n, flush_s
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
        from foundation import check_output_dir

        out = self.out
        if out is None:
            return
        if not self.existing:
            check_output_dir(out, "--out", False, self.inputs)  # nothing changed meanwhile
            out.mkdir(exist_ok=True)
            self._take_lock()
        (out / self.ROWS_DIR).mkdir(exist_ok=True)
        if not (out / self.MANIFEST).exists():
            _write_text(
                out / self.MANIFEST,
                json.dumps(
                    {
                        "tool": "selfalign",
                        "version": _version(),
                        "command": self.COMMAND,
                        "hash": self.digest,
                        **self.describe,
                    },
                    indent=1,
                    default=str,
                )
                + "\n",
            )
        self._journal = open(out / self.JOURNAL, "a", encoding="utf-8")  # noqa: SIM115 (closed in close())

    def _other(self, doc: dict) -> str:
        """How a refusal names the run another manifest holds."""
        return f"{doc.get('source', '?')}, {doc.get('points', '?')} points"

    def _check_same(self, out: Path, inputs: list[Path]) -> None:
        """A non-empty ``out`` is resumed only when it holds this very run."""
        flag, what = "--out", self.COMMAND
        man = out / self.MANIFEST
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
                f"{flag} {out}: holds an input of this {what} ({inp.name}); give a new directory name",
            )
        if not man.is_file():
            raise InputError(
                f"{flag} {out}: holds files that are not a selfalign {what}; choose a new or empty directory"
            )
        try:
            doc = json.loads(man.read_text())
            theirs = doc["hash"]
        except (OSError, ValueError, KeyError, TypeError):
            raise InputError(
                f"{flag} {out}: its {self.MANIFEST} cannot be read; choose a new or empty directory"
            ) from None
        if theirs != self.digest:
            raise InputError(
                f"{flag} {out}: holds a different {what} ({self._other(doc)}, hash {str(theirs)[:12]}; "
                f"this one is {self.digest[:12]}); choose another --out (the results of two runs are never mixed)"
            )
        require(os.access(out, os.W_OK), f"{flag} {out}: directory is not writable")

    def _take_lock(self) -> None:
        """The lock, then what a killed run left in the directory removed: its atomic writes'
        temporaries (``.NAME.XXXXXXXX.EXT``, :func:`remove_dead_files`), in the directory and
        in ``ROWS_DIR``. The lock file is removed when the run ends
        (:meth:`close`), so the lock taken is checked to be the file's that the path names now
        (a run that ended meanwhile removed it)."""
        assert self.out is not None  # (a store with a directory)
        for _ in range(10):
            lock = self._lock_once()
            try:
                same = os.path.samestat(os.fstat(lock.fileno()), os.stat(self.out / self.LOCK))
            except OSError:
                same = False
            if same:
                break
            lock.close()
            self._lock = None
        else:
            raise InputError(
                f"--out {self.out}: another selfalign {self.COMMAND} keeps taking its lock; wait for it to end"
            )
        remove_dead_files(self.out, (self.ROWS_DIR,))

    def _lock_once(self) -> TextIO:
        import fcntl

        assert self.out is not None  # (a store with a directory)
        f = open(self.out / self.LOCK, "a+")  # noqa: SIM115 (held until close())
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            raise InputError(
                f"--out {self.out}: another selfalign {self.COMMAND} is writing into it; wait for it to end or choose another --out"
            ) from None
        self._lock = f
        return f

    def _read_journal(self) -> None:
        assert self.out is not None  # (a store with a directory)
        path = self.out / self.JOURNAL
        if not path.exists():
            return
        data = path.read_bytes()
        end = data.rfind(b"\n") + 1
        if end < len(data):  # a line cut short by a kill: dropped, so the next line starts clean
            with open(path, "rb+") as f:
                f.truncate(end)
        for line in data[:end].splitlines():
            try:
                row = json.loads(line)
                i = int(row[self.KEY])
            except (ValueError, KeyError, TypeError):
                continue
            if 0 <= i and (self.n is None or i < self.n):
                self.rows[i] = row

    # .................................................................. rows
    def record(self, i: int, row: dict, doc: dict) -> dict:
        """Keep ``row`` as row ``i``; with a directory, write ``doc`` (the row's full numbers) as
        ``ROWS_DIR/NNNNN.json``, append the row to the journal and flush it, and rewrite the
        tables when they are due."""
        self.rows[i] = row
        if self.out is not None:
            width = max(5, len(str((self.n or 1) - 1)))
            _write_text(
                self.out / self.ROWS_DIR / f"{i:0{width}d}.json",
                json_text(doc, indent=1),
            )
            assert self._journal is not None  # opened with the directory
            self._journal.write(json_text(row, indent=None))
            self._journal.flush()
            hold(self.HOLD)
            if time.monotonic() >= self._next_flush:
                self.write_tables()
        return row

    def table(self):
        """All rows, by key, as a pandas DataFrame (the columns in the order the rows give them)."""
        import pandas as pd

        rows = [self.rows[i] for i in sorted(self.rows)]
        cols: dict[str, None] = {}
        for r in (
            rows
        ):  # rows are built identity, settings, status, metrics: their union keeps that order
            cols.update(dict.fromkeys(r))
        return pd.DataFrame(rows, columns=list(cols)) if rows else pd.DataFrame(columns=list(cols))

    def write_tables(self, df=None) -> None:
        """Rewrite the tables atomically: the rows, or the DataFrame ``df`` made of them."""
        if self.out is None:
            return
        import pyarrow as pa
        import pyarrow.parquet as pq

        t0 = time.monotonic()
        df = self.table() if df is None else df
        from foundation import atomic_output

        with atomic_output(self.out / self.TABLES[0]) as tmp:
            pq.write_table(pa.Table.from_pandas(df, preserve_index=False), tmp)
        with atomic_output(self.out / self.TABLES[1]) as tmp:
            df.to_csv(tmp, index=False)
        now = time.monotonic()
        self._next_flush = now + max(
            self.flush_s, 10 * (now - t0)
        )  # a large table: at most a tenth of the time on rewriting it

    def write_marker(self) -> None:
        from foundation import MARKER, tree_listing

        assert self.out is not None  # (a store with a directory)
        files = [
            e
            for e in tree_listing(self.out)
            if not e.endswith("/") and e != MARKER and not e.startswith(".") and "/." not in e
        ]
        _write_text(
            self.out / MARKER,
            json.dumps(
                {
                    "tool": "selfalign",
                    "command": self.COMMAND,
                    "files": sorted(files + [self.LOCK]),
                },
                indent=1,
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
            assert self.out is not None  # the lock is a file in the directory
            with contextlib.suppress(OSError):
                os.unlink(self.out / self.LOCK)  # while held: no other run holds this file
            self._lock.close()
            self._lock = None


class _Store(ResultStore):
    """The rows of a sweep, in memory and (with ``out``) in a resumable directory."""

    def __init__(
        self,
        spec: SweepSpec,
        out: str | os.PathLike | None,
        inputs: Iterable[Path] = (),
        flush_s: float = FLUSH_S,
    ):
        self.spec = spec
        super().__init__(
            out, spec.digest, spec.describe(), n=spec.n_points, inputs=inputs, flush_s=flush_s
        )

    def done(self, retry_failed: bool) -> set[int]:
        return {i for i, r in self.rows.items() if r.get("status") == "ok" or not retry_failed}

    def add(self, point: SweepPoint, result: dict) -> dict:
        row = self.spec.columns(point) | {k: result.get(k) for k in STATUS_COLUMNS}
        if result.get("summary") is not None:
            row |= flatten(result["summary"])
        i = point.point
        doc = {
            "point": i,
            "settings": dict(point.values),
            "row": row,
            "summary": result.get("summary"),
        }
        return self.record(i, row, doc)


def kept_points(out: str | os.PathLike, journal: str = JOURNAL, key: str = "point") -> int:
    """How many rows the journal of the results directory ``out`` holds (a sweep's finished
    points, ok or failed; with ``journal`` "trials.jsonl" and ``key`` "trial", a search's
    trials; a line cut short does not count): what a rerun resumes from."""
    try:
        data = (Path(out) / journal).read_bytes()
    except OSError:
        return 0
    seen = set()
    for line in data[: data.rfind(b"\n") + 1].splitlines():
        try:
            seen.add(int(json.loads(line)[key]))
        except (ValueError, KeyError, TypeError):
            continue
    return len(seen)
