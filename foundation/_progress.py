"""Progress messages for the terminal: on stderr, silenced by ``--quiet``.

Results go to stdout; everything that only explains a wait (JAX compiling a stepper,
a progress bar) goes to stderr, so ``selfalign ... > result.txt`` stays clean.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys

#: Messages already shown in this process (see :func:`announce_once`).
_shown: set[str] = set()

#: Estimated seconds of work from which a step deep in the engine says what it waits for
#: (:func:`wait_line`, :func:`shows_wait`): the meniscus footprint, the global minimum's
#: proof, the boxes of a long run.
WAIT_S = 3.0
#: Environment variable that sets :data:`WAIT_S` (seconds; 0 shows every such line).
WAIT_ENV = "SELFALIGN_WAIT_S"
#: Whether waiting lines are silenced (``--quiet``; :func:`quiet_waits`).
_quiet_waits = [False]


@contextlib.contextmanager
def quiet_waits(quiet: bool = True):
    """Within the block, :func:`wait_line` and :func:`shows_wait` stay silent when ``quiet``
    (a command's ``--quiet``: the engine below it has no flag of its own)."""
    before = _quiet_waits[0]
    _quiet_waits[0] = bool(quiet) or before
    try:
        yield
    finally:
        _quiet_waits[0] = before


def wait_threshold_s() -> float:
    """Seconds from which a wait is shown: ``SELFALIGN_WAIT_S``, else :data:`WAIT_S`."""
    text = os.environ.get(WAIT_ENV)
    if text:
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        if math.isfinite(v) and v >= 0:
            return v
    return WAIT_S


def shows_wait(seconds: float) -> bool:
    """Whether a step estimated to take ``seconds`` shows a waiting line or a progress bar."""
    return not _quiet_waits[0] and seconds >= wait_threshold_s()


def wait_line(message: str, seconds: float) -> bool:
    """Say on stderr what a step estimated to take ``seconds`` is doing (``message...``), when
    it is long enough (:func:`shows_wait`); returns whether it was shown."""
    show = shows_wait(seconds)
    if show:
        announce(f"{message}...")
    return show


def announce(message: str, quiet: bool = False) -> None:
    """Print ``message`` on stderr unless ``quiet``."""
    if not quiet:
        print(message, file=sys.stderr, flush=True)


def announce_once(message: str, quiet: bool = False) -> None:
    """:func:`announce`, at most once per process for the same message.

    For waits that happen only the first time, like JAX compiling a jitted stepper.
    A quiet call does not count as shown.
    """
    if not quiet and message not in _shown:
        _shown.add(message)
        announce(message, quiet)


def compiling(method: str, quiet: bool = False) -> None:
    """Explain the pause before the first trajectory: JAX compiles the stepper."""
    seconds = "a few" if method in ("greedy", "gradient") else "5-10"
    announce_once(
        f"compiling the {method} stepper with JAX ({seconds} seconds, once per process)...", quiet
    )


class NoBar:
    """Stands in for a progress bar that is not shown."""

    n: int = 0
    total: int = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        return None

    def update(self, k: int) -> None:
        return None

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        return None

    def refresh(self) -> None:
        return None


def progress_bar(show: bool, total: int, desc: str, unit: str):
    """A tqdm bar on stderr over ``total`` ``unit``s, or a stand-in that shows nothing.

    Use as a context manager and call ``update(k)`` as work is done.
    """
    if not show:
        return NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, unit_scale=True)


def counter_bar(desc: str, unit: str):
    """A tqdm counter on stderr for work of unknown length (the boxes of a long run): it
    appears once the work has taken :func:`wait_threshold_s` seconds, and not at all when
    waits are quiet (``--quiet``). Use as a context manager; ``update(k)`` and
    ``set_postfix_str`` as the work goes."""
    if _quiet_waits[0]:
        return NoBar()
    from tqdm import tqdm

    return tqdm(desc=desc, unit=f" {unit}", delay=wait_threshold_s())
