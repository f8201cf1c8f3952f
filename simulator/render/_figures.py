"""Pictures: energy curves, landscapes, force curves, trajectory GIFs.

Every picture is drawn in the physical frame (um, x right, y up, origin at the
pattern centre, twist counter-clockwise positive) and written atomically (no
half-written file on failure). Plotting stays out of the numerical core: the
simulator never imports this module, and matplotlib is imported lazily.

Units on the pictures: energy in nJ, force in uN, torque in nN m, time in ms.

The basics every picture shares (colours, units, :func:`pyplot`, :func:`save_figure`)
are :mod:`simulator.render`; the chip outline and the trajectory animation and
GIF are :mod:`simulator.render`. This module draws the still pictures
(pattern, energy curve, landscape, forces, capture maps) and re-exports the others'
names, so ``simulator.render`` stays the one place every picture is imported from.
"""

from __future__ import annotations

import math
import os

import numpy as np

from foundation import InputError
from patterns.geometry import Mask
from simulator.landscape import axis_step
from simulator.render._style import (
    CHIP_COLOUR,
    J_TO_NJ,
    N_TO_UN,
    NM_TO_NNM,
    PATH_COLOUR,
    PLATEAU_COLOUR,
    S_TO_MS,
    pyplot,
    save_figure,
)

__all__ = ["plot_energy_curve", "plot_forces", "plot_landscape"]


def plot_pattern(mask: Mask, path: str | os.PathLike, title: str = "pattern as simulated") -> None:
    """The wettability mask in the physical frame (um, y up), white = pad."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.6, 4.4))
    im = ax.imshow(
        mask.data, extent=mask.extent_um, cmap="gray", vmin=0, vmax=1, interpolation="nearest"
    )
    ax.plot([0], [0], "+", color="C3", ms=10, mew=1.5)
    ax.set(xlabel="x (µm)", ylabel="y (µm)", title=f"{title} ({mask.um_per_px:g} µm/px)")
    fig.colorbar(im, ax=ax, shrink=0.8, label="wettability (1 = pad)")
    save_figure(fig, path)


def plot_energy_curve(traj, path: str | os.PathLike) -> None:
    """Energy (nJ) and twist (deg) versus step (stepping methods) or time in ms (dynamics)."""
    plt = pyplot()
    fig, (ax, ax_t) = plt.subplots(
        2, 1, figsize=(6.4, 4.6), sharex=True, height_ratios=(2, 1), layout="constrained"
    )
    e_nj = np.asarray(traj.energy_J) * J_TO_NJ
    twist = np.asarray(traj.path)[:, 2]
    if traj.t_s is not None:
        x, xlabel = np.asarray(traj.t_s) * S_TO_MS, "time (ms)"
    else:
        x, xlabel = np.arange(len(e_nj)), "step"
    for a, ys in ((ax, e_nj), (ax_t, twist)):
        a.plot(x, ys, color=PATH_COLOUR, lw=1.6)
        a.plot(x[[0, -1]], ys[[0, -1]], "o", color=CHIP_COLOUR, ms=4)
        a.grid(alpha=0.3)
    ax.annotate(
        "start", (x[0], e_nj[0]), xytext=(7, 3), textcoords="offset points", fontsize=8, va="bottom"
    )
    ax.annotate(
        traj.outcome,
        (x[-1], e_nj[-1]),
        xytext=(-6, 4),
        textcoords="offset points",
        fontsize=8,
        ha="right",
    )
    ax.set_ylabel("energy (nJ)")
    ax_t.set_ylabel("twist (°)")
    ax_t.set_xlabel(xlabel)
    s, f = traj.start, [round(v, 2) + 0.0 for v in traj.final]
    ax.set_title(
        f"{traj.method}: ({s[0]:g} µm, {s[1]:g} µm, {s[2]:g}°) → ({f[0]:g} µm, {f[1]:g} µm, {f[2]:g}°), "
        f"{traj.outcome}",
        fontsize=9,
    )
    save_figure(fig, path)


# ------------------------------------------------------------------ landscape plots
def _nearest_twist(ls, twist_deg: float = 0.0) -> int:
    t = np.asarray(ls.twist_deg, float)
    d = np.abs(t - twist_deg)
    if ls.wrap:
        d = np.minimum(d, ls.period_deg - d)
    return int(np.argmin(d))


def plot_landscape(ls, path: str | os.PathLike, pattern: Mask | None = None) -> None:
    """Energy over the chip-centre position (x, y): at zero twist, and the lowest over all twists.

    Axes in um (y up), colour in nJ (dark = low energy = more overlap), a few
    contour lines, the global minimum marked, and the pattern's outline (the 0.5
    level of its mask) when ``pattern`` is given. A landscape with one twist gets
    one panel.
    """
    plt = pyplot()
    e = np.asarray(ls.energy, float) * J_TO_NJ
    k0 = _nearest_twist(ls)
    panels = [(e[k0], f"at twist {ls.twist_deg[k0]:g}°")]
    if e.shape[0] > 1:
        panels.append(
            (e.min(axis=0), f"minimised over twist ({ls.twist_deg[0]:g}..{ls.twist_deg[-1]:g}°)")
        )
    vmin, vmax = float(e.min()), float(max(e.max(), 0.0))
    s = ls.um_per_px
    extent = (ls.x_um[0] - s / 2, ls.x_um[-1] + s / 2, ls.y_um[0] - s / 2, ls.y_um[-1] + s / 2)
    gx, gy, gt, ge = ls.global_minimum()
    # The star marks the global minimum where it is drawn: on the panel minimised over
    # twist, and on the fixed-twist panel only when the minimum lies at that twist.
    d = abs(gt - float(ls.twist_deg[k0]))
    d = min(d % ls.period_deg, ls.period_deg - d % ls.period_deg)
    stars = [d <= 1e-9] + [True] * (len(panels) - 1)
    if not stars[0]:
        panels[0] = (
            panels[0][0],
            f"{panels[0][1]} (the global minimum, at {gt:g}°, is on the right)",
        )
    fig, axes = plt.subplots(
        1, len(panels), figsize=(5.2 * len(panels) + 1.2, 5.0), squeeze=False, layout="constrained"
    )
    for ax, (img, label), star in zip(axes[0], panels, stars, strict=True):
        im = ax.imshow(
            img,
            origin="lower",
            extent=extent,
            cmap="viridis",
            vmin=vmin,
            vmax=vmax,
            interpolation="antialiased",
        )
        if vmax > vmin:
            levels = np.linspace(vmin, vmax, 9)[1:-1]
            ax.contour(
                ls.x_um,
                ls.y_um,
                img,
                levels=levels,
                colors="white",
                linewidths=0.5,
                alpha=0.6,
                linestyles="solid",
            )
        if pattern is not None:
            ax.contour(*_outline(pattern), levels=[0.5], colors="#ff9f1c", linewidths=1.0)
        if star:
            ax.plot(
                gx,
                gy,
                marker="*",
                ms=14,
                mfc=CHIP_COLOUR,
                mec="white",
                mew=1.0,
                ls="none",
                label=f"global minimum ({gx:g} µm, {gy:g} µm, {gt:g}°), {ge * J_TO_NJ:.3g} nJ",
            )
        ax.set_title(f"energy {label}", fontsize=10)
        ax.set_xlabel("chip centre x (µm)")
        ax.set_ylabel("chip centre y (µm)")
        ax.set_aspect("equal")
    axes[0][stars.index(True)].legend(loc="upper left", fontsize=8, framealpha=0.85)
    cb = fig.colorbar(im, ax=axes[0].tolist(), shrink=0.85)
    cb.set_label("energy (nJ); lower = more overlap")
    note = "; orange = pattern outline" if pattern is not None else ""
    fig.suptitle(f"Energy landscape over the chip position (x right, y up{note})", fontsize=11)
    save_figure(fig, path)


def _mask_grid(mask: Mask) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) um of the pixel centres of ``mask``, matching ``mask.data`` (row 0 = top)."""
    h, w = mask.shape
    s = mask.um_per_px
    return (np.arange(w) + 0.5 - w / 2) * s, (h / 2 - np.arange(h) - 0.5) * s


def _outline(mask: Mask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, data) for contouring a mask's 0.5 outline: padded by one substrate pixel,
    so that the outline closes at the image border and a 1 x 1 px mask can be drawn."""
    x, y = _mask_grid(mask)
    s = mask.um_per_px
    return np.r_[x[0] - s, x, x[-1] + s], np.r_[y[0] + s, y, y[-1] - s], np.pad(mask.data, 1)


def _line_range(
    values: np.ndarray, step: float, centre: float, span: float | None
) -> tuple[float, float]:
    """The range of a force curve along one pose-grid axis (``values``, spaced ``step``): one
    step inside its ends (central differences), within ``span`` of ``centre``."""
    lo, hi = float(values[0]) + step, float(values[-1]) - step
    if span is not None:
        lo, hi = max(lo, centre - span), min(hi, centre + span)
    if not hi > lo:
        raise InputError(
            f"the landscape is too small to draw a curve through {centre:g} (grid {values[0]:g}..{values[-1]:g})"
        )
    return lo, hi


def plot_forces(
    ls,
    path: str | os.PathLike,
    through: tuple[float, float, float] = (0.0, 0.0, 0.0),
    span_um: float | None = None,
    compare=None,
) -> None:
    """Energy and restoring force along x, along y (uN) and torque along twist (nN m) through a pose.

    Top row: energy (nJ); bottom row: force F = -dE/dx, -dE/dy (uN) and torque
    tau = -dE/dtwist (nN m, twist in radians). Shaded: plateaus, where the force is
    zero (energy changes below the noise floor: :meth:`Landscape.curve`); grey where
    the chip no longer touches the pattern. ``span_um`` limits the x and y lines to
    ``through +- span_um`` (default: the whole landscape). ``compare``: a second landscape
    (the overlap model beside a finite meniscus) drawn dashed along the same lines.
    """
    plt = pyplot()
    if span_um is not None and not (np.isfinite(span_um) and span_um > 0):
        raise InputError(f"span_um must be a finite number > 0 um, got {span_um!r}")
    tx, ty, tt = (float(v) for v in through)
    # Labels to 0.1 um and 0.1 degree (a refined minimum carries round-off digits).
    lx, ly, lt = (round(v, 1) + 0.0 for v in (tx, ty, tt))
    curves = [
        ls.curve("x", through, *_line_range(ls.x_um, ls.um_per_px, tx, span_um)),
        ls.curve("y", through, *_line_range(ls.y_um, ls.um_per_px, ty, span_um)),
    ]
    if len(ls.twist_deg) > 1:
        if ls.wrap:
            lo, hi = tt - ls.period_deg / 2, tt + ls.period_deg / 2
        else:
            lo, hi = _line_range(ls.twist_deg, ls.twist_step_deg, tt, None)
        curves.append(ls.curve("twist", through, lo, hi))
    fig, axes = plt.subplots(
        2,
        len(curves),
        figsize=(4.3 * len(curves), 5.6),
        sharex="col",
        squeeze=False,
        layout="constrained",
    )
    floor = ls.noise_floor_J
    kinds: set[str] = set()
    for col, cur in enumerate(curves):
        twist = cur["axis"] == "twist"
        v, e_nj = cur["values"], cur["energy_J"] * J_TO_NJ
        f = cur["force"] * (NM_TO_NNM if twist else N_TO_UN)
        ax_e, ax_f = axes[0, col], axes[1, col]
        for ax in (ax_e, ax_f):
            for a, b in cur["plateaus"]:
                sel = (v >= a) & (v <= b)
                no_contact = bool(np.all(np.abs(cur["energy_J"][sel]) <= floor))
                kinds.add("no contact" if no_contact else "plateau")
                ax.axvspan(
                    a,
                    b,
                    color="0.85" if no_contact else PLATEAU_COLOUR,
                    alpha=0.6 if no_contact else 0.35,
                    lw=0,
                )
            ax.grid(alpha=0.3)
        h = getattr(ls, "meniscus_height_um", None)
        label = f"meniscus h = {h:.3g} µm" if h else None
        if compare is not None and (not twist or len(compare.twist_deg) > 1):
            lo, hi = float(v[0]), float(v[-1])
            ref = compare.curve(cur["axis"], through, lo, hi)
            ax_e.plot(
                ref["values"],
                ref["energy_J"] * J_TO_NJ,
                color="0.35",
                lw=1.1,
                ls="--",
                label="overlap model (h → 0)",
            )
            ax_f.plot(
                ref["values"],
                ref["force"] * (NM_TO_NNM if twist else N_TO_UN),
                color="0.35",
                lw=1.1,
                ls="--",
            )
        ax_e.plot(v, e_nj, color=PATH_COLOUR, lw=1.5, label=label)
        ax_f.plot(v, f, color=CHIP_COLOUR, lw=1.5)
        if compare is not None and col == min(1, len(curves) - 1):
            ax_e.legend(loc="upper right", fontsize=8, framealpha=0.85)
        ax_f.axhline(0, color="k", lw=0.6)
        name = {"x": "x (µm)", "y": "y (µm)", "twist": "twist (°)"}[cur["axis"]]
        fixed = {
            "x": f"y = {ly:g} µm, twist {lt:g}°",
            "y": f"x = {lx:g} µm, twist {lt:g}°",
            "twist": f"x = {lx:g} µm, y = {ly:g} µm",
        }[cur["axis"]]
        ax_e.set_title(f"along {cur['axis']} ({fixed})", fontsize=10)
        ax_f.set_xlabel(f"chip {name}")
        ax_e.set_ylabel("energy (nJ)")
        ax_f.set_ylabel("torque τ (nN·m)" if twist else f"force F{cur['axis']} (µN)")
    from matplotlib.patches import Patch

    handles = (
        [Patch(color=PLATEAU_COLOUR, alpha=0.35, label="plateau (zero force)")]
        if "plateau" in kinds
        else []
    )
    handles += [Patch(color="0.85", alpha=0.6, label="no contact")] if "no contact" in kinds else []
    if handles:
        axes[0, 0].legend(handles=handles, loc="lower left", fontsize=8, framealpha=0.85)
    fig.suptitle(
        f"Energy and restoring force through ({lx:g} µm, {ly:g} µm, {lt:g}°); "
        "force points towards lower energy",
        fontsize=11,
    )
    save_figure(fig, path)


# --------------------------------------------------------------------- capture maps
#: Outcome colours of capture maps, in the order of :data:`simulator.core.OUTCOMES`.
OUTCOME_COLORS = ("#2ca02c", "#ff7f0e", "#d62728", "#7f7f7f", "#9467bd")
MAX_PANELS = 16


def plot_capture_map(cmap: np.ndarray, grid, scene, path, title: str = "") -> None:
    """The outcome of every grid start, one panel per twist (at most 16, evenly picked).

    Axes are the chip-centre start position in um (x right, y up, origin at the pattern
    centre); the pattern's outline (wettability 0.5) is drawn for orientation. Written
    atomically with :func:`simulator.render.save_figure`.
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from simulator.core import OUTCOMES

    plt = pyplot()
    t, ny, nx = cmap.shape
    show = np.unique(np.round(np.linspace(0, t - 1, min(t, MAX_PANELS))).astype(int))
    line = (nx == 1) != (ny == 1)  # a 1-D grid: a strip per twist, not a square map
    ncol = 1 if line else min(len(show), 4)
    nrow = math.ceil(len(show) / ncol)
    size = (7.5, 0.9 * nrow + 1.4) if line else (3.6 * ncol + 1.8, 3.6 * nrow + 0.6)
    fig, axes = plt.subplots(nrow, ncol, figsize=size, squeeze=False, constrained_layout=True)
    xs, ys = np.asarray(grid.x_um), np.asarray(grid.y_um)
    dx = axis_step(xs) if nx > 1 else scene.um_per_px
    dy = axis_step(ys) if ny > 1 else scene.um_per_px
    extent = (xs[0] - dx / 2, xs[-1] + dx / 2, ys[0] - dy / 2, ys[-1] + dy / 2)
    colors = ListedColormap(OUTCOME_COLORS)
    norm = BoundaryNorm(np.arange(len(OUTCOMES) + 1) - 0.5, len(OUTCOMES))
    px, py, outline = _outline(scene.pattern)
    for ax in axes.ravel()[len(show) :]:
        ax.set_visible(False)
    for ax, k in zip(axes.ravel(), show, strict=False):
        panel = f"start twist {grid.twist_deg[k]:g}°"
        if line:
            along, fixed, cells = (
                ("x", f"y = {ys[0]:g} µm", cmap[k])
                if ny == 1
                else ("y", f"x = {xs[0]:g} µm", cmap[k].T)
            )
            lo, hi = extent[:2] if ny == 1 else extent[2:]
            ax.imshow(
                cells,
                extent=(lo, hi, 0, 1),
                cmap=colors,
                norm=norm,
                interpolation="nearest",
                aspect="auto",
            )
            ax.set_yticks([])
            ax.set_xlabel(f"start {along} (µm)")
            ax.set_title(f"{panel}, {fixed}", fontsize=10)
            continue
        ax.imshow(
            cmap[k],
            origin="lower",
            extent=extent,
            cmap=colors,
            norm=norm,
            interpolation="nearest",
            aspect="equal",
        )
        ax.contour(px, py, outline, levels=[0.5], colors="black", linewidths=0.7, alpha=0.6)
        ax.plot([0], [0], marker="+", color="black", ms=8, mew=1.2)
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.set_title(panel, fontsize=10)
        ax.set_xlabel("start x (µm)")
        ax.set_ylabel("start y (µm)")
    counts = np.bincount(cmap.ravel().astype(np.int64), minlength=len(OUTCOMES))
    handles: list[Patch | Line2D] = [
        Patch(color=OUTCOME_COLORS[k], label=f"{name} ({counts[k]:,})")
        for k, name in enumerate(OUTCOMES)
        if counts[k]
    ]
    if not line:
        handles.append(Line2D([], [], color="black", lw=0.7, alpha=0.6, label="pattern edge"))
    legend_title = "outcome (starts)" if t == 1 else f"outcome (starts,\nall {t} twists)"
    fig.legend(
        handles=handles,
        loc="outside right center",
        fontsize=9,
        title=legend_title,
        title_fontsize=9,
    )
    shown = f" ({len(show)} of {t} twists shown)" if len(show) < t else ""
    fig.suptitle(
        f"{title}{shown}\neach cell: the chip centre's start position; colour: how the run from there ended",
        fontsize=10,
    )
    save_figure(fig, path)


def plot_time_to_align(
    hist: dict | None, st: dict | None, path: str | os.PathLike, title: str = ""
) -> None:
    """Histogram of the time to align (ms) of a dynamics batch's aligned starts, with the
    median and the 90th percentile marked. ``hist`` and ``st`` are the batch's
    :func:`simulator.batch.time_histogram` (None: no start aligned) and
    :func:`simulator.batch.time_stats`, in seconds. Written atomically."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.8), constrained_layout=True)
    if hist is None:
        ax.text(0.5, 0.5, "no start aligned", ha="center", va="center", transform=ax.transAxes)
    else:
        assert st is not None  # the same times as hist: None together
        edges = 1e3 * np.asarray(hist["edges_s"])
        ax.bar(
            edges[:-1],
            hist["counts"],
            width=np.diff(edges),
            align="edge",
            color="#4c72b0",
            edgecolor="white",
            linewidth=0.5,
        )
        for v, label, style in (
            (st["median"], "median", "-"),
            (st["p90"], "90th percentile", "--"),
        ):
            ax.axvline(1e3 * v, color="black", ls=style, lw=1, label=f"{label} {1e3 * v:.3g} ms")
        ax.legend(fontsize=9)
    ax.set_xlabel("time to align (ms, simulated)")
    ax.set_ylabel("aligned starts")
    ax.set_title(title, fontsize=10)
    save_figure(fig, path)
