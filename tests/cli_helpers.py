"""What the reliability suites share: run the CLI in-process, check a one-line refusal,
list what a directory holds."""

from __future__ import annotations

from pathlib import Path

from simulator.cli import main


def cli(args: list, capsys) -> tuple[int, str, str]:
    """``selfalign ARGS`` in this process: (exit code, stdout, stderr)."""
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


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
