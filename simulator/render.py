"""Pictures: energy curves, landscapes, force curves, trajectory GIFs.

Every picture is drawn in the physical frame (um, x right, y up, origin at the
pattern centre, twist counter-clockwise positive) and written atomically (no
half-written file on failure). Plotting stays out of the numerical core: the
simulator never imports this module, and matplotlib is imported lazily.

Units on the pictures: energy in nJ, force in uN, torque in nN m, time in ms.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator

import numpy as np

from patterns.errors import InputError
from patterns.mask import Mask
from patterns.outputs import atomic_output
from simulator.posegrid import axis_step

__all__ = [
    "TrajectoryAnimation",
    "chip_outline",
    "frame_indices",
    "plot_energy_curve",
    "plot_forces",
    "plot_landscape",
    "save_figure",
    "write_trajectory_gif",
]

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


def plot_pattern(mask: Mask, path: str | os.PathLike, title: str = "pattern as simulated") -> None:
    """The wettability mask in the physical frame (um, y up), white = pad."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.6, 4.4))
    im = ax.imshow(mask.data, extent=mask.extent_um, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    ax.plot([0], [0], "+", color="C3", ms=10, mew=1.5)
    ax.set(xlabel="x (µm)", ylabel="y (µm)", title=f"{title} ({mask.um_per_px:g} µm/px)")
    fig.colorbar(im, ax=ax, shrink=0.8, label="wettability (1 = pad)")
    save_figure(fig, path)


def plot_energy_curve(traj, path: str | os.PathLike) -> None:
    """Energy (nJ) and twist (deg) versus step (stepping methods) or time in ms (dynamics)."""
    plt = pyplot()
    fig, (ax, ax_t) = plt.subplots(2, 1, figsize=(6.4, 4.6), sharex=True, height_ratios=(2, 1), layout="constrained")
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
    ax.annotate("start", (x[0], e_nj[0]), xytext=(7, 3), textcoords="offset points", fontsize=8, va="bottom")
    ax.annotate(traj.outcome, (x[-1], e_nj[-1]), xytext=(-6, 4), textcoords="offset points", fontsize=8, ha="right")
    ax.set_ylabel("energy (nJ)")
    ax_t.set_ylabel("twist (°)")
    ax_t.set_xlabel(xlabel)
    s, f = traj.start, [round(v, 2) + 0.0 for v in traj.final]
    ax.set_title(f"{traj.method}: ({s[0]:g} µm, {s[1]:g} µm, {s[2]:g}°) → ({f[0]:g} µm, {f[1]:g} µm, {f[2]:g}°), "
                 f"{traj.outcome}", fontsize=9)
    save_figure(fig, path)


# ------------------------------------------------------------------ chip outline
def chip_outline(chip: Mask):
    """The chip's wettable footprint as a shapely geometry in its own frame (um, centred, y up).

    The exact geometry when the chip has one; for a chip PNG, the 0.5 iso-line of its
    mask (skimage ``find_contours`` through pixel centres), holes included: nested
    contours alternate between outline and hole (their symmetric difference).
    """
    if chip.geometry is not None:
        return chip.geometry
    import shapely
    from shapely.geometry import Polygon
    from skimage.measure import find_contours

    h, w = chip.shape
    s = chip.um_per_px
    geom = Polygon()
    for c in find_contours(np.pad(chip.data, 1), 0.5):  # padded: every contour closes
        if len(c) < 4:
            continue
        rows, cols = c[:, 0] - 1, c[:, 1] - 1
        ring = Polygon(np.column_stack([(cols + 0.5 - w / 2) * s, (h / 2 - rows - 0.5) * s]))
        geom = geom.symmetric_difference(shapely.make_valid(ring))
    return geom


def _outline_path(geom) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (K, 2), matplotlib path codes (K,)) of a polygonal geometry.

    Exteriors counter-clockwise, holes clockwise, so the non-zero fill rule leaves
    holes empty.
    """
    from matplotlib.path import Path
    from shapely.geometry.polygon import orient

    verts, codes = [], []
    polys = getattr(geom, "geoms", [geom])
    for poly in polys:
        if poly.geom_type != "Polygon" or poly.is_empty:
            continue
        poly = orient(poly, 1.0)
        for ring in [poly.exterior, *poly.interiors]:
            xy = np.asarray(ring.coords)
            verts.append(xy)
            codes.append([Path.MOVETO] + [Path.LINETO] * (len(xy) - 2) + [Path.CLOSEPOLY])
    if not verts:
        raise InputError("the chip has no outline to draw (no wettable area)")
    return np.concatenate(verts), np.concatenate(codes).astype(np.uint8)


def _place(xy: np.ndarray, pose) -> np.ndarray:
    """Chip-frame points (K, 2) um at pose (x_um, y_um, twist_deg): rotate CCW about (0, 0), then translate."""
    a = np.radians(pose[2])
    c, s = np.cos(a), np.sin(a)
    return np.column_stack([xy[:, 0] * c - xy[:, 1] * s + pose[0], xy[:, 0] * s + xy[:, 1] * c + pose[1]])


# ------------------------------------------------------------------ animation
def frame_indices(traj, max_frames: int = 120) -> np.ndarray:
    """Indices into ``traj.path`` of the frames to draw: at most ``max_frames``, first and last always.

    Stepping methods are sampled evenly in steps, dynamics evenly in time (so the
    animation runs at a constant multiple of physical time).
    """
    if isinstance(max_frames, bool) or not isinstance(max_frames, int | np.integer) or max_frames < 2:
        raise InputError(f"max_frames must be a whole number >= 2, got {max_frames!r}")
    n = len(traj.path)
    if n <= max_frames:
        return np.arange(n)
    if traj.t_s is not None:
        t = np.asarray(traj.t_s, float)
        idx = np.searchsorted(t, np.linspace(t[0], t[-1], max_frames)[1:-1])
    else:
        idx = np.round(np.linspace(0, n - 1, max_frames)[1:-1]).astype(int)
    return np.unique(np.concatenate([[0], np.clip(idx, 0, n - 1), [n - 1]]))


class TrajectoryAnimation:
    """Frames of a trajectory: the chip over the pattern, and its energy and twist so far.

    Left: the pattern (white = wettable, grey = substrate; anything outside the image
    is substrate), the chip outline at the current pose (red), its start pose
    (dashed), and the path of its centre so far (blue). Right: energy (nJ) and twist
    (deg) against step, or time (ms) for dynamics, with a marker at the current
    frame. The static parts are drawn once; each frame redraws only the moving
    artists (blitting), so a frame costs a few milliseconds.

    Args:
        scene: the scene the trajectory ran on (its pattern and chip are drawn).
        traj: a :class:`simulator.trajectory.Trajectory`.
        max_frames: at most this many frames (see :func:`frame_indices`).
        size_px: (width, height) of every frame in pixels.
    """

    def __init__(self, scene, traj, max_frames: int = 120, size_px: tuple[int, int] = (880, 440)):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.traj = traj
        self.indices = frame_indices(traj, max_frames)
        self.path = np.asarray(traj.path, float)
        self._verts, self._codes = _outline_path(chip_outline(scene.chip))
        dpi = 80
        self.fig = Figure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.fig)
        self._draw_static(scene)
        self.canvas.draw()
        self._background = self.canvas.copy_from_bbox(self.fig.bbox)

    # -- layout
    def _draw_static(self, scene) -> None:
        from matplotlib.patches import PathPatch
        from matplotlib.path import Path

        fig, traj, path = self.fig, self.traj, self.path
        gs = fig.add_gridspec(2, 2, width_ratios=(1.0, 1.05), height_ratios=(1.6, 1.0),
                              left=0.085, right=0.975, bottom=0.15, top=0.86, wspace=0.22, hspace=0.12)
        ax = self.ax = fig.add_subplot(gs[:, 0])
        ax_e = self.ax_e = fig.add_subplot(gs[0, 1])
        ax_t = self.ax_t = fig.add_subplot(gs[1, 1], sharex=ax_e)
        pat = scene.pattern
        ax.set_facecolor(_substrate_rgb())
        ax.imshow(pat.data, cmap=_pattern_cmap(), vmin=0, vmax=1, extent=pat.extent_um, origin="upper",
                  interpolation="antialiased")
        xlim, ylim = self._limits(pat)
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        ax.set_aspect("equal")
        ax.plot([0], [0], "+", color="k", ms=9, mew=1.2, zorder=3)
        ax.add_patch(PathPatch(Path(_place(self._verts, path[0]), self._codes), fill=False, ec=PATH_COLOUR,
                               lw=1.0, ls=(0, (4, 3)), alpha=0.8, zorder=3))
        ax.set_xlabel("x (µm)")
        ax.set_ylabel("y (µm)")
        ax.set_title("red: chip now · dashed: at start · blue: path of its centre", fontsize=9)
        self.chip = ax.add_patch(PathPatch(Path(_place(self._verts, path[0]), self._codes), fc=(0.91, 0.07, 0.18, 0.16),
                                           ec=CHIP_COLOUR, lw=2.0, zorder=5, animated=True))
        (self.trail,) = ax.plot([], [], "-", color=PATH_COLOUR, lw=1.6, zorder=4, animated=True)
        (self.centre,) = ax.plot([], [], "o", color=PATH_COLOUR, ms=5, zorder=6, animated=True)

        if traj.t_s is not None:
            self.xs, xlabel = np.asarray(traj.t_s, float) * S_TO_MS, "time (ms)"
        else:
            self.xs, xlabel = np.arange(len(path), dtype=float), "step"
        self.e_nj = np.asarray(traj.energy_J, float) * J_TO_NJ
        self.live = []
        for a, ys, label in ((ax_e, self.e_nj, "energy (nJ)"), (ax_t, path[:, 2], "twist (°)")):
            a.plot(self.xs, ys, color="0.78", lw=1.3)
            (done,) = a.plot([], [], color=PATH_COLOUR, lw=1.8, animated=True)
            (dot,) = a.plot([], [], "o", color=CHIP_COLOUR, ms=6, zorder=5, animated=True)
            self.live.append((done, dot, ys))
            a.set_ylabel(label)
            a.grid(alpha=0.3)
            lo, hi = float(np.min(ys)), float(np.max(ys))
            pad = 0.08 * (hi - lo) if hi > lo else max(1.0, abs(hi)) * 0.05
            a.set_ylim(lo - pad, hi + pad)
        ax_e.tick_params(labelbottom=False)
        ax_t.set_xlabel(xlabel)
        ax_e.set_title("energy E = Δγ · overlap area (lower = better aligned)", fontsize=9)
        self.title = fig.text(0.5, 0.955, "", ha="center", va="center", fontsize=12, animated=True)
        fig.text(0.5, 0.025, _scene_caption(scene, traj), ha="center", va="center", fontsize=9, color="0.3")

    def _limits(self, pat: Mask) -> tuple[tuple[float, float], tuple[float, float]]:
        """Square axis limits holding the pattern's pads, the chip at every frame and the path."""
        rows = np.flatnonzero(pat.data.max(axis=1) > 0)
        cols = np.flatnonzero(pat.data.max(axis=0) > 0)
        h, w = pat.shape
        s = pat.um_per_px
        pts = [np.array([[(cols[0] - w / 2) * s, (h / 2 - rows[-1] - 1) * s], [(cols[-1] + 1 - w / 2) * s, (h / 2 - rows[0]) * s]]),
               self.path[:, :2]]
        pts += [_place(self._verts, self.path[i]) for i in self.indices]
        pts = np.concatenate(pts)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        mid, half = (lo + hi) / 2, 0.53 * float((hi - lo).max())
        return (mid[0] - half, mid[0] + half), (mid[1] - half, mid[1] + half)

    # -- frames
    def title_of(self, i: int) -> str:
        """The frame title at path index ``i``: step (or time), pose, and the outcome at the end."""
        x, y, t = (round(float(v), 1) + 0.0 for v in self.path[i])
        n = len(self.path) - 1
        when = f"t = {self.xs[i]:.2f} ms" if self.traj.t_s is not None else f"step {i}/{n}"
        text = f"{self.traj.method}: {when}   chip at x {x:g} µm, y {y:g} µm, twist {t:g}°"
        return text + (f"   → {self.traj.outcome}" if i == n else "")

    def frame(self, i: int) -> np.ndarray:
        """The (H, W, 3) uint8 RGB picture at path index ``i``."""
        from matplotlib.path import Path

        self.canvas.restore_region(self._background)
        self.chip.set_path(Path(_place(self._verts, self.path[i]), self._codes))
        self.trail.set_data(self.path[: i + 1, 0], self.path[: i + 1, 1])
        self.centre.set_data(self.path[i : i + 1, 0], self.path[i : i + 1, 1])
        for done, dot, ys in self.live:
            done.set_data(self.xs[: i + 1], ys[: i + 1])
            dot.set_data(self.xs[i : i + 1], ys[i : i + 1])
        self.title.set_text(self.title_of(i))
        for artist in (self.trail, self.chip, self.centre, self.title, *(a for pair in self.live for a in pair[:2])):
            self.fig.draw_artist(artist)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def frames(self, quiet: bool = True) -> Iterator[np.ndarray]:
        """Every frame in order, with a progress bar on stderr unless ``quiet``."""
        from tqdm import tqdm

        for i in tqdm(self.indices, desc="gif", unit="frame", disable=quiet, leave=False):
            yield self.frame(int(i))

    def pixel_of(self, x_um, y_um) -> np.ndarray:
        """(column, row) in frame pixels (row 0 at the top, pixel edges at integers) of points in um."""
        xy = self.ax.transData.transform(np.column_stack([np.ravel(x_um), np.ravel(y_um)]))
        height = self.fig.bbox.height
        return np.column_stack([xy[:, 0], height - xy[:, 1]])

    def close(self) -> None:
        self.fig.clear()


def write_trajectory_gif(scene, traj, path: str | os.PathLike, max_frames: int = 120, fps: float = 20.0,
                         hold_s: float = 1.5, quiet: bool = True) -> int:
    """Write the trajectory as an animated GIF (loops forever); returns the number of frames.

    Long trajectories are subsampled to at most ``max_frames`` frames (first and last
    always kept, see :func:`frame_indices`); each frame shows ``1 / fps`` s, the first
    and last ``hold_s`` s. See :class:`TrajectoryAnimation` for what a frame shows.
    """
    import imageio.v3 as iio

    path = os.fspath(path)
    if not path.lower().endswith(".gif"):
        raise InputError(f"output {path}: the animation must end in .gif")
    if not (np.isfinite(fps) and 0 < fps <= 50):
        raise InputError(f"fps must be a number in (0, 50] frames per second, got {fps!r}")
    anim = TrajectoryAnimation(scene, traj, max_frames)
    try:
        frames = np.stack(list(anim.frames(quiet)))
    finally:
        anim.close()
    index, palette = _palette_frames(frames)
    ms = max(20, int(round(1000 / fps / 10)) * 10)  # GIF delays are whole centiseconds
    durations = [ms] * len(frames)
    durations[0] = durations[-1] = max(ms, int(round(hold_s * 100)) * 10)
    # Encoded in memory, then written: a full disk fails in our write, not inside the encoder.
    # optimize: pixels unchanged since the last frame are written as transparent
    data = iio.imwrite("<bytes>", index, extension=".gif", mode="P", palette=palette, optimize=True,
                       duration=durations, loop=0)
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)
    return len(frames)


def _palette_frames(frames: np.ndarray, colours: int = 128) -> tuple[np.ndarray, bytes]:
    """(N, H, W, 3) RGB frames -> (N, H, W) palette indices and one shared palette (RGB bytes).

    One palette for all frames (median cut of the first, middle and last frames, with
    the drawing colours added so they survive exactly) keeps colours steady between
    frames and lets unchanged pixels compress to nothing.
    """
    from matplotlib.colors import to_rgb
    from PIL import Image

    n, _, w, _ = frames.shape
    keys = [to_rgb(c) for c in (CHIP_COLOUR, PATH_COLOUR, "white", "black", _substrate_rgb())]
    strip = np.repeat((np.array(keys) * 255).round().astype(np.uint8), 8 * w // len(keys) + 1, axis=0)[: 8 * w]
    sample = np.concatenate([frames[0], frames[n // 2], frames[-1], strip.reshape(8, w, 3)], axis=0)
    pal = Image.fromarray(sample).quantize(colors=colours, method=Image.Quantize.MEDIANCUT)
    index = np.stack([np.asarray(Image.fromarray(f).quantize(palette=pal, dither=Image.Dither.NONE)) for f in frames])
    return index, bytes(pal.getpalette()[: 3 * colours])


def _pattern_cmap():
    """Substrate mid-grey, pads white: the red chip and blue path stand out on both."""
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list("pattern", [_substrate_rgb(), (1.0, 1.0, 1.0)])


def _substrate_rgb() -> tuple[float, float, float]:
    return (0.62, 0.63, 0.66)


def _scene_caption(scene, traj) -> str:
    p, c = scene.pattern, scene.chip
    h, w = p.shape
    chip = c.params.get("design", "PNG") if c.geometry is not None else "PNG"
    cw, ch = (c.params.get("width_um"), c.params.get("height_um")) if chip == "rectangle" else (None, None)
    chip_txt = f"{cw:g} x {ch:g} µm chip" if cw else f"chip footprint {c.area_um2:,.0f} µm²"
    s = traj.start
    grey = bool(np.any((p.data > 0.02) & (p.data < 0.98)))  # graded pads, or the anti-aliased edges
    shades = ", lighter = graded" if grey else ""  # partly wettable: graded pads, anti-aliased edges
    return (f"pattern {w * p.um_per_px:g} x {h * p.um_per_px:g} µm at {p.um_per_px:g} µm/px (white = pad, "
            f"grey = substrate{shades}, + = centre), {chip_txt}; start ({s[0]:g} µm, {s[1]:g} µm, {s[2]:g}°), twist CCW +")


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
        panels.append((e.min(axis=0), f"minimised over twist ({ls.twist_deg[0]:g}..{ls.twist_deg[-1]:g}°)"))
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
        panels[0] = (panels[0][0], f"{panels[0][1]} (the global minimum, at {gt:g}°, is on the right)")
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels) + 1.2, 5.0), squeeze=False, layout="constrained")
    for ax, (img, label), star in zip(axes[0], panels, stars, strict=True):
        im = ax.imshow(img, origin="lower", extent=extent, cmap="viridis", vmin=vmin, vmax=vmax, interpolation="antialiased")
        if vmax > vmin:
            levels = np.linspace(vmin, vmax, 9)[1:-1]
            ax.contour(ls.x_um, ls.y_um, img, levels=levels, colors="white", linewidths=0.5, alpha=0.6,
                       linestyles="solid")
        if pattern is not None:
            ax.contour(*_outline(pattern), levels=[0.5], colors="#ff9f1c", linewidths=1.0)
        if star:
            ax.plot(gx, gy, marker="*", ms=14, mfc=CHIP_COLOUR, mec="white", mew=1.0, ls="none",
                    label=f"global minimum ({gx:g} µm, {gy:g} µm, {gt:g}°), {ge * J_TO_NJ:.3g} nJ")
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


def _line_range(values: np.ndarray, centre: float, span: float | None) -> tuple[float, float]:
    step = axis_step(np.asarray(values))
    lo, hi = float(values[0]) + step, float(values[-1]) - step
    if span is not None:
        lo, hi = max(lo, centre - span), min(hi, centre + span)
    if not hi > lo:
        raise InputError(f"the landscape is too small to draw a curve through {centre:g} (grid {values[0]:g}..{values[-1]:g})")
    return lo, hi


def plot_forces(ls, path: str | os.PathLike, through: tuple[float, float, float] = (0.0, 0.0, 0.0),
                span_um: float | None = None, compare=None) -> None:
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
    curves = [ls.curve("x", through, *_line_range(ls.x_um, tx, span_um)),
              ls.curve("y", through, *_line_range(ls.y_um, ty, span_um))]
    if len(ls.twist_deg) > 1:
        if ls.wrap:
            lo, hi = tt - ls.period_deg / 2, tt + ls.period_deg / 2
        else:
            lo, hi = _line_range(ls.twist_deg, tt, None)
        curves.append(ls.curve("twist", through, lo, hi))
    fig, axes = plt.subplots(2, len(curves), figsize=(4.3 * len(curves), 5.6), sharex="col", squeeze=False,
                             layout="constrained")
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
                ax.axvspan(a, b, color="0.85" if no_contact else PLATEAU_COLOUR, alpha=0.6 if no_contact else 0.35, lw=0)
            ax.grid(alpha=0.3)
        h = getattr(ls, "meniscus_height_um", None)
        label = f"meniscus h = {h:.3g} µm" if h else None
        if compare is not None and (not twist or len(compare.twist_deg) > 1):
            lo, hi = float(v[0]), float(v[-1])
            ref = compare.curve(cur["axis"], through, lo, hi)
            ax_e.plot(ref["values"], ref["energy_J"] * J_TO_NJ, color="0.35", lw=1.1, ls="--", label="overlap model (h → 0)")
            ax_f.plot(ref["values"], ref["force"] * (NM_TO_NNM if twist else N_TO_UN), color="0.35", lw=1.1, ls="--")
        ax_e.plot(v, e_nj, color=PATH_COLOUR, lw=1.5, label=label)
        ax_f.plot(v, f, color=CHIP_COLOUR, lw=1.5)
        if compare is not None and col == min(1, len(curves) - 1):
            ax_e.legend(loc="upper right", fontsize=8, framealpha=0.85)
        ax_f.axhline(0, color="k", lw=0.6)
        name = {"x": "x (µm)", "y": "y (µm)", "twist": "twist (°)"}[cur["axis"]]
        fixed = {"x": f"y = {ly:g} µm, twist {lt:g}°", "y": f"x = {lx:g} µm, twist {lt:g}°",
                 "twist": f"x = {lx:g} µm, y = {ly:g} µm"}[cur["axis"]]
        ax_e.set_title(f"along {cur['axis']} ({fixed})", fontsize=10)
        ax_f.set_xlabel(f"chip {name}")
        ax_e.set_ylabel("energy (nJ)")
        ax_f.set_ylabel("torque τ (nN·m)" if twist else f"force F{cur['axis']} (µN)")
    from matplotlib.patches import Patch

    handles = [Patch(color=PLATEAU_COLOUR, alpha=0.35, label="plateau (zero force)")] if "plateau" in kinds else []
    handles += [Patch(color="0.85", alpha=0.6, label="no contact")] if "no contact" in kinds else []
    if handles:
        axes[0, 0].legend(handles=handles, loc="lower left", fontsize=8, framealpha=0.85)
    fig.suptitle(f"Energy and restoring force through ({lx:g} µm, {ly:g} µm, {lt:g}°); "
                 "force points towards lower energy", fontsize=11)
    save_figure(fig, path)


# --------------------------------------------------------------------- capture maps
#: Outcome colours of capture maps, in the order of :data:`simulator.stepping.OUTCOMES`.
OUTCOME_COLORS = ("#2ca02c", "#ff7f0e", "#d62728", "#7f7f7f", "#9467bd")
MAX_PANELS = 16


def plot_capture_map(cmap: np.ndarray, grid, scene, path, title: str = "") -> None:
    """The outcome of every grid start, one panel per twist (at most 16, evenly picked).

    Axes are the chip-centre start position in um (x right, y up, origin at the pattern
    centre); the pattern's outline (wettability 0.5) is drawn for orientation. Written
    atomically with :func:`simulator.render.save_figure`.
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    from simulator.stepping import OUTCOMES

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
            along, fixed, cells = ("x", f"y = {ys[0]:g} µm", cmap[k]) if ny == 1 else ("y", f"x = {xs[0]:g} µm", cmap[k].T)
            lo, hi = extent[:2] if ny == 1 else extent[2:]
            ax.imshow(cells, extent=(lo, hi, 0, 1), cmap=colors, norm=norm, interpolation="nearest", aspect="auto")
            ax.set_yticks([])
            ax.set_xlabel(f"start {along} (µm)")
            ax.set_title(f"{panel}, {fixed}", fontsize=10)
            continue
        ax.imshow(cmap[k], origin="lower", extent=extent, cmap=colors, norm=norm, interpolation="nearest", aspect="equal")
        ax.contour(px, py, outline, levels=[0.5], colors="black", linewidths=0.7, alpha=0.6)
        ax.plot([0], [0], marker="+", color="black", ms=8, mew=1.2)
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.set_title(panel, fontsize=10)
        ax.set_xlabel("start x (µm)")
        ax.set_ylabel("start y (µm)")
    counts = np.bincount(cmap.ravel().astype(np.int64), minlength=len(OUTCOMES))
    handles = [Patch(color=OUTCOME_COLORS[k], label=f"{name} ({counts[k]:,})") for k, name in enumerate(OUTCOMES) if counts[k]]
    if not line:
        handles.append(plt.Line2D([], [], color="black", lw=0.7, alpha=0.6, label="pattern edge"))
    legend_title = "outcome (starts)" if t == 1 else f"outcome (starts,\nall {t} twists)"
    fig.legend(handles=handles, loc="outside right center", fontsize=9, title=legend_title, title_fontsize=9)
    shown = f" ({len(show)} of {t} twists shown)" if len(show) < t else ""
    fig.suptitle(f"{title}{shown}\neach cell: the chip centre's start position; colour: how the run from there ended", fontsize=10)
    save_figure(fig, path)
