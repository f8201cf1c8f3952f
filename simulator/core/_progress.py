"""Progress messages for the terminal: on stderr, silenced by ``--quiet``.

Results go to stdout; everything that only explains a wait (JAX compiling a stepper,
a progress bar) goes to stderr, so ``selfalign ... > result.txt`` stays clean.
"""

from __future__ import annotations

import sys

#: Messages already shown in this process (see :func:`announce_once`).
_shown: set[str] = set()


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
    announce_once(f"compiling the {method} stepper with JAX ({seconds} seconds, once per process)...", quiet)


class NoBar:
    """Stands in for a progress bar that is not shown."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        return None

    def update(self, k: int) -> None:
        return None

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        return None


def progress_bar(show: bool, total: int, desc: str, unit: str):
    """A tqdm bar on stderr over ``total`` ``unit``s, or a stand-in that shows nothing.

    Use as a context manager and call ``update(k)`` as work is done.
    """
    if not show:
        return NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, unit_scale=True)
