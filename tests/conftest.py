"""Fixtures the test files share.

``run_cli`` runs the command line in this process: the CLI tests ask for it instead of
keeping a runner of their own. What is not a fixture (the one-line refusal check,
directory listings, ``python -m`` with Ctrl-C restored) is in ``tests/cli_helpers.py``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import pytest


@pytest.fixture
def run_cli(capsys) -> Callable[[Sequence], tuple[int, str, str]]:
    """``run_cli(args)``: ``selfalign ARGS`` in this process -> (exit code, stdout, stderr).

    The arguments are turned into strings (paths may be passed as they are); argparse's
    own exits (a usage error, ``--help``) give their exit code instead of raising.
    What the run printed is read from ``capsys`` and not printed again.
    """
    from simulator.cli import main

    def run(args: Sequence) -> tuple[int, str, str]:
        try:
            rc = main([str(a) for a in args])
        except SystemExit as exc:  # argparse exits on a usage error
            rc = exc.code
        out, err = capsys.readouterr()
        return rc, out, err

    return run
