"""SIGTERM during a resumable run (``sweep``, ``design``'s search): the run ends at once,
saying what its output directory keeps."""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def sigterm_says_what_was_kept(out: str, command: str, noun: str, *kept: str) -> Iterator[None]:
    """While a resumable run (``sweep``, ``design``'s search) works into ``out``, SIGTERM ends it
    as the CLI's handler does (temporaries removed, at once), but says how many finished
    ``noun``s ``out`` keeps (a rerun resumes them), and leaves no semaphore of the Dask cluster
    behind (the resource tracker's warnings). ``kept``: the journal's name and its record's
    noun for :func:`simulator.sweep.kept_points`, when they are not the sweep's."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(signum, frame):
        from foundation import remove_pending
        from simulator.sweep import kept_points, release_semaphores

        remove_pending()
        n = kept_points(out, *kept) if os.path.isdir(out) else 0
        release_semaphores()
        said = (
            f"{n} finished {noun}{'s are' if n != 1 else ' is'} kept in {out} (rerun the same command to resume)"
            if n
            else f"no {noun} had finished, none was kept"
        )
        os.write(2, f"selfalign {command}: terminated; {said}\n".encode())
        os._exit(143)

    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
