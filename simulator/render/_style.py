"""The pictures' shared basics: colours, unit factors, the matplotlib backend and saving.

Owns what every picture module draws with (:mod:`simulator.render`,
:mod:`simulator.render`, :mod:`simulator.sweep`): the colours of the
chip, its path and plateaus, the factors from SI units to the units on the pictures
(nJ, uN, nN m, ms), :func:`pyplot` (matplotlib on the Agg backend, imported lazily,
only when a picture is drawn) and :func:`save_figure` (an atomic write, the format
from the suffix). Imports nothing heavy.
"""

from __future__ import annotations

import os

from foundation import InputError, atomic_output

__all__ = ["CHIP_COLOUR", "PATH_COLOUR", "PLATEAU_COLOUR", "pyplot", "save_figure"]

#: Colours shared by the pictures: the chip now, the path so far, plateaus.
CHIP_COLOUR = "#e8112d"
PATH_COLOUR = "#1f5fbf"
PLATEAU_COLOUR = "#f5b942"
J_TO_NJ, N_TO_UN, NM_TO_NNM, S_TO_MS = 1e9, 1e6, 1e9, 1e3


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend (what every picture here draws with)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | os.PathLike, dpi: int = 120) -> None:
    """Save a matplotlib figure atomically (format from the suffix)."""
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in (".png", ".svg", ".pdf"):
        raise InputError(f"output {path}: the picture must end in .png, .svg or .pdf")
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=suffix[1:], bbox_inches="tight")
    pyplot().close(fig)
