"""Errors a user can fix, and checks of the inputs named on the command line.

Every function that takes user input raises :class:`InputError` with a one-line
message that names the input, shows the value and says what is allowed. The CLI
prints that line and exits with code 2 (no traceback). Output files and directories
are written by ``_outputs``.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import SupportsFloat, SupportsIndex


class InputError(ValueError):
    """Bad user input: the message names the input and the fix."""


def require(condition: bool, message: str) -> None:
    """Raise :class:`InputError` with ``message`` unless ``condition`` holds."""
    if not condition:
        raise InputError(message)


def positive(name: str, value: SupportsFloat | SupportsIndex | str, unit: str = "") -> float:
    """Return ``value`` as float if it is finite and > 0, else raise InputError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not (v > 0 and v < float("inf")):
        raise InputError(
            f"{name} must be a finite number > 0{' ' + unit if unit else ''}, got {value!r}"
        )
    return v


def require_regular_file(path: str | os.PathLike, what: str = "file") -> Path:
    """``path`` if it is an existing regular file (not a directory, FIFO or device), else InputError.

    Checked with ``stat`` before anything opens the file, so a FIFO never blocks.
    """
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{path}: file does not exist") from None
    except OSError as err:
        raise InputError(f"{path}: cannot read the {what} file ({err.strerror or err})") from None
    if stat.S_ISDIR(st.st_mode):
        article = "an" if what[0] in "aeiou" else "a"
        raise InputError(f"{path}: is a directory, not {article} {what} file")
    if not stat.S_ISREG(st.st_mode):
        kind = "a FIFO (named pipe)" if stat.S_ISFIFO(st.st_mode) else "a device or socket"
        raise InputError(
            f"{path}: is {kind}, not a regular {what} file; save the {what} to a file and give that"
        )
    return path
