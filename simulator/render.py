"""Pictures: energy curves, landscapes, trajectory GIFs. Plotting stays out of the core.

Every picture is drawn in the physical frame (um, y up, origin at the pattern centre)
and written atomically (no half-written file on failure).
"""

from __future__ import annotations

import os

import numpy as np

from patterns.errors import InputError, atomic_output


def _pyplot():
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
    _pyplot().close(fig)


def plot_energy_curve(traj, path: str | os.PathLike) -> None:
    """Energy versus step (stepping methods) or time in ms (dynamics), with the outcome."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    e_nj = np.asarray(traj.energy_J) * 1e9
    if traj.t_s is not None:
        x, xlabel = np.asarray(traj.t_s) * 1e3, "time (ms)"
    else:
        x, xlabel = np.arange(len(e_nj)), "step"
    ax.plot(x, e_nj, color="C0", lw=1.6)
    ax.plot(x[[0, -1]], e_nj[[0, -1]], "o", color="C3", ms=4)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("energy (nJ)")
    s, f = traj.start, [round(v, 2) + 0.0 for v in traj.final]
    ax.set_title(f"{traj.method}: ({s[0]:g}, {s[1]:g} um, {s[2]:g} deg) -> ({f[0]:g}, {f[1]:g} um, {f[2]:g} deg), {traj.outcome}", fontsize=9)
    ax.grid(alpha=0.3)
    save_figure(fig, path)
