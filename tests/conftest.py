"""Fixtures and settings the test files share.

``run_cli`` runs the command line in this process: the CLI tests ask for it instead of
keeping a runner of their own. What is not a fixture (the one-line refusal check,
directory listings, ``python -m`` with Ctrl-C restored) is in ``tests/cli_helpers.py``.

Hypothesis profiles (``SELFALIGN_HYPOTHESIS_PROFILE``, ``ci`` when unset):

- ``ci`` (``make test``, CI): derandomized, so every run draws the same examples and a
  failure reproduces; no example database (nothing written into the checkout); no deadline
  (a shared 2-core runner's timings say nothing). Example counts: each test's own.
- ``dev``: random examples, the database in ``.hypothesis/`` (a failing example is
  replayed first on the next run), no deadline.

Each property test states its own number of examples (``max_examples``), the same in both.

The ``fft`` marker: the numerical tests of the landscape and the energy whose correlations
take the default backend. ``make test`` runs them once more under each FFT backend
(``SELFALIGN_FFT_BACKEND=scipy``, ``opencv``, ``jax``; ``pytest -m fft``), so that a bound
tuned to one backend's round-off fails on this machine, not on the next.

The ``xdist_group`` marker (pytest-xdist): tests that share work too costly to repeat
(e.g. one stepper compiled per dtype, then a comparison of the two) carry one group name,
and ``make test`` (``--dist loadgroup``) runs a group on one worker, in order. Where the
installed pytest and pytest-xdist lose the groups, the run is refused
(:func:`pytest_collection_finish`) rather than left to repeat that work silently.

The suite runs in parallel (``pytest -n 2 --dist loadgroup``, pytest-xdist; ``make test`` does) and
serially (``pytest -p no:xdist``): every test writes only under its own ``tmp_path`` (or a
``tempfile`` directory), never into the checkout, and depends on no other test.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

import pytest
from hypothesis import settings

settings.register_profile("ci", deadline=None, derandomize=True, database=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
settings.load_profile(os.environ.get("SELFALIGN_HYPOTHESIS_PROFILE", "ci"))


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "fft: a numerical landscape or energy test that make test reruns under each FFT backend",
    )


def pytest_collection_finish(session):
    """On an xdist worker under ``--dist loadgroup``: every test with an ``xdist_group``
    mark must carry its group in its node id (how xdist sends a group to one worker)."""
    config = session.config
    if not getattr(config.option, "loadgroup", False):
        return
    lost = [
        it.nodeid
        for it in session.items
        if it.get_closest_marker("xdist_group") and "@" not in it.nodeid
    ]
    if lost:
        raise pytest.UsageError(
            f"pytest {pytest.__version__} and this pytest-xdist lose the xdist_group of "
            f"{len(lost)} tests (e.g. {lost[0]}); install the test extra's pytest (<9)"
        )


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
