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
and ``make test`` (``--dist loadgroup``) runs a group on one worker, in order. Most modules
whose tests run the steppers in this process are one group each (a ``pytestmark``): a
stepper compiles per grid shape, in seconds, and a module's tests share a few shapes (and its
module fixtures), which each worker would otherwise compile again. The groups go out first,
largest first; the modules left ungrouped (tests that run commands in subprocesses, or that
compile nothing) fill in around them and even out the two workers' ends. Where the
installed pytest and pytest-xdist lose the groups, the run is refused
(:func:`pytest_collection_finish`) rather than left to repeat that work silently.

The suite runs in parallel (``pytest -n 2 --dist loadgroup``, pytest-xdist; ``make test`` does) and
serially (``pytest -p no:xdist``): every test writes only under its own ``tmp_path`` (or a
``tempfile`` directory), never into the checkout, and depends on no other test.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from typing import cast

import pytest
from hypothesis import settings

settings.register_profile("ci", deadline=None, derandomize=True, database=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
settings.load_profile(os.environ.get("SELFALIGN_HYPOTHESIS_PROFILE", "ci"))


#: JAX's persistent compilation cache, one directory for the whole run: the pytest processes
#: (the xdist workers, or the one serial process) share what any of them compiled, so the same
#: stepper on the same grid compiles once per run, not once per worker. A fresh temporary
#: directory per run (nothing is read from an earlier run, nothing written into the checkout),
#: made by the first process (the xdist controller), named to the workers by an environment
#: variable of the suite's own, and removed by its maker at the end (``make test`` makes one
#: for all its pytest stages and removes it itself). The commands the tests start in
#: subprocesses never see it (JAX reads only its own variables): they compile as a user's run
#: does, and a child killed mid-write or held under a file-size limit cannot leave half an
#: entry for the others; the benchmarks' smoke runs alone are handed it in JAX's own
#: variables (tests/test_benchmarks_smoke.py: nothing kills or limits them). Two workers writing and reading the same entry at once read
#: a truncated entry as a miss and compile (the "persistent compilation cache" warnings are
#: not errors here: pyproject.toml's filterwarnings); nothing else changes what runs.
_JAX_CACHE_VAR = "SELFALIGN_TEST_JAX_CACHE"
_made_jax_cache: str | None = None


def _share_jax_compilations() -> None:
    global _made_jax_cache
    path = os.environ.get(_JAX_CACHE_VAR)
    if path is None:
        path = _made_jax_cache = tempfile.mkdtemp(prefix="selfalign-jax-cache-")
        os.environ[_JAX_CACHE_VAR] = path
    import jax

    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


def pytest_unconfigure(config):
    if _made_jax_cache is not None:
        shutil.rmtree(_made_jax_cache, ignore_errors=True)


def pytest_configure(config):
    _share_jax_compilations()
    config.addinivalue_line(
        "markers",
        "fft: a numerical landscape or energy test that make test reruns under each FFT backend",
    )
    # registered here too: pytest-xdist registers it, but a serial run (-p no:xdist) would
    # otherwise fail on an unknown mark (filterwarnings = error)
    config.addinivalue_line(
        "markers", "xdist_group(name): tests that run on one xdist worker, in order"
    )
    config.addinivalue_line(
        "markers",
        "xla_exact: compares two compiled programs bit for bit; make test runs it as XLA "
        "compiles for users (its other stages compile at optimisation level 0)",
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
            rc = cast(int, exc.code)  # argparse exits with a status number
        out, err = capsys.readouterr()
        return rc, out, err

    return run
