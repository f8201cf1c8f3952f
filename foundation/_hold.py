"""Known points where a test can hold the process, instead of racing its clock.

A test that interrupts a run (SIGTERM, Ctrl-C, a kill) must send its signal while the
run is at a known stage: after its temporary output exists, while its batch works,
after two sweep points are journalled. Sleeping "long enough" first races the machine's
speed. Instead the test sets ``SELFALIGN_HOLD_AT=POINT`` (or ``POINT:N`` for the N-th
arrival); when the process reaches that point it writes one line on stderr::

    selfalign: holding at POINT (SELFALIGN_HOLD_AT)

and waits there until a signal ends it (at most :data:`HOLD_S` seconds, then it goes
on). The test reads stderr up to that line, then signals. Without the variable,
:func:`hold` costs one dictionary lookup.

Points (each named where it is called):

* ``startup``: the CLI's signal handlers are installed, no command module is imported;
* ``output``: a command's temporary output directory exists (``_outputs``: :func:`~foundation.output_directory`);
* ``batch``: a Monte Carlo batch has run its first chunk of starts;
* ``sweep-point``: a sweep point's row is in the journal (flushed);
* ``search-trial``: a design search's trial row is in its journal (flushed).
"""

from __future__ import annotations

import os
import time

#: The environment variable that names the point to hold at.
ENV = "SELFALIGN_HOLD_AT"
#: The longest hold (s): a test that never signals does not leave the process behind forever.
HOLD_S = 600.0

_arrivals: dict[str, int] = {}


def hold(point: str) -> None:
    """Hold here if ``SELFALIGN_HOLD_AT`` names ``point`` (and this is its N-th arrival)."""
    wanted = os.environ.get(ENV)
    if not wanted:
        return
    name, _, nth = wanted.partition(":")
    if name != point:
        return
    _arrivals[point] = _arrivals.get(point, 0) + 1
    if _arrivals[point] != (int(nth) if nth.isdigit() else 1):
        return
    # os.write: unbuffered, and safe while another thread prints.
    os.write(2, f"selfalign: holding at {point} ({ENV})\n".encode())
    end = time.monotonic() + HOLD_S
    while time.monotonic() < end:  # a signal's handler runs between these sleeps
        time.sleep(0.05)
