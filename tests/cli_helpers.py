"""What the bad-input and interruption suites share besides the ``run_cli`` fixture
(``tests/conftest.py``): check a one-line refusal, list what a directory holds, run
``python -m`` with Ctrl-C restored."""

from __future__ import annotations

import sys
from pathlib import Path


def one_line_error(rc: int, err: str, *needles: str) -> None:
    """Exit code 2 and one stderr line holding every needle, no traceback or warning."""
    assert rc == 2, err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err and "internal error" not in err and "warning" not in err, err
    for n in needles:
        assert n in err, err


def listing(d: Path) -> list[str]:
    """Every path below ``d``, relative and sorted (hidden temporaries included)."""
    return sorted(str(p.relative_to(d)) for p in d.rglob("*"))


#: ``python -m MODULE ARGS`` with Ctrl-C restored: a test suite started in the background
#: (``make test &``, some CI runners) hands its children SIGINT ignored, and Python keeps an
#: ignored SIGINT ignored, so a test that presses Ctrl-C would wait forever. A user's Ctrl-C
#: in a terminal reaches a process whose SIGINT is the default; this reproduces that.
WITH_CTRL_C = [
    sys.executable,
    "-c",
    "import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "sys.argv = sys.argv[1:]; runpy.run_module(sys.argv[0], run_name='__main__', alter_sys=True)",
]


def python_m(module: str, *args) -> list[str]:
    """argv of ``python -m module args`` whose SIGINT is the default (see :data:`WITH_CTRL_C`)."""
    return [*WITH_CTRL_C, module, *(str(a) for a in args)]
