"""What a killed design run leaves behind, removed by the next run into the same place.

A run ended by SIGTERM or Ctrl-C removes its temporaries itself; one killed outright (SIGKILL,
the kernel's out-of-memory killer) cannot. Its leftovers carry the names the project's own
writers give their temporaries (:func:`foundation.atomic_output`), and only such names are removed:

* a file written atomically: ``.NAME.XXXXXXXX.EXT`` beside ``NAME.EXT`` (``tempfile``'s eight
  random characters, then the target's own suffix), e.g. ``.history.png.k2j4_x9q.png`` in a
  search's ``--out``, removed when the search that resumes there holds its lock (the
  results directory's, a sweep's too: :class:`simulator.sweep.ResultStore`);
* a directory filled before its rename: ``.NAME.XXXXXXXX.selfalign-tmp`` beside ``NAME``,
  removed by the next free-form run into ``NAME`` unless a live run holds it: each free-form
  run holds an exclusive ``flock`` on its temporary directory while it writes there, which
  the kernel releases when the process dies, so a temporary whose lock can be taken is dead.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
from pathlib import Path

__all__ = ["hold_directory", "remove_dead_directories"]

#: ``tempfile``'s random part of a temporary's name.
_RANDOM = r"[a-z0-9_]{8}"


def remove_dead_directories(target: Path) -> list[str]:
    """Remove the temporary directories of runs into ``target`` that died (``.NAME.XXXXXXXX
    .selfalign-tmp`` beside it whose lock can be taken); returns their names."""
    target = Path(target)
    parent = target.resolve().parent
    pattern = re.compile(rf"^\.{re.escape(target.name)}\.{_RANDOM}\.selfalign-tmp$")
    gone = []
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return gone
    for e in entries:
        if not (pattern.match(e.name) and e.is_dir(follow_symlinks=False)):
            continue
        with _try_lock(Path(e.path)) as free:
            if free:
                shutil.rmtree(e.path, ignore_errors=True)
                gone.append(e.name)
    return gone


@contextlib.contextmanager
def _try_lock(directory: Path):
    """Yield whether an exclusive lock on ``directory`` was taken (held in the block)."""
    import fcntl

    try:
        fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        yield False
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            yield False
            return
        yield True
    finally:
        os.close(fd)


@contextlib.contextmanager
def hold_directory(directory: Path):
    """Hold an exclusive lock on ``directory`` in the block: a live run's temporary is never
    taken for a dead one's (:func:`remove_dead_directories`)."""
    import fcntl

    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)
