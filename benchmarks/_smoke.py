"""The benchmarks' smoke mode: ``--smoke OUT`` runs a script on its smallest sizes with one
repeat and writes its table (or JSON) to ``OUT`` only, never into ``benchmarks/results/``
or the documentation. The test suite runs every script so (tests/test_benchmarks_smoke.py):
the code the figures come from keeps running, in seconds."""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Where a smoke run must never write: the measured results and the pages they go into.
KEPT = (ROOT / "benchmarks" / "results", ROOT / "docs", ROOT / "validation")


def add_smoke_arg(ap: argparse.ArgumentParser, what: str = "its table") -> None:
    ap.add_argument(
        "--smoke",
        type=Path,
        default=None,
        metavar="OUT",
        help=f"smallest sizes, one repeat, in seconds: write {what} to OUT only (for the test suite)",
    )


def smoke_out(ap: argparse.ArgumentParser, path: Path | None) -> Path | None:
    """``path`` checked for a smoke run: a file in an existing directory outside the kept
    results (argparse's one-line error otherwise). None when there is no smoke run."""
    if path is None:
        return None
    r = path.resolve()
    if any(r == k or k in r.parents for k in KEPT):
        ap.error(f"--smoke {path}: a smoke run never writes into {', '.join(map(str, KEPT))}")
    if not r.parent.is_dir():
        ap.error(f"--smoke {path}: directory {path.parent} does not exist")
    if r.is_dir():
        ap.error(f"--smoke {path}: is a directory; give a file name")
    return path


class _Tee:
    def __init__(self, *streams):
        self.streams = streams

    def write(self, text: str) -> int:
        for s in self.streams:
            s.write(text)
        return len(text)

    def flush(self) -> None:
        for s in self.streams:
            s.flush()


@contextlib.contextmanager
def tee_stdout(path: Path | None) -> Iterator[None]:
    """Standard output also written to ``path`` (a smoke run's table), when ``path`` is given."""
    if path is None:
        yield
        return
    buf = io.StringIO()
    with contextlib.redirect_stdout(_Tee(sys.stdout, buf)):
        yield
    path.write_text(buf.getvalue())
