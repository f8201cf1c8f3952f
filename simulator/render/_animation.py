"""The trajectory animation: the chip's outline, the frames and the animated GIF.

Owns :func:`chip_outline` (a chip's wettable footprint as shapely geometry),
:func:`frame_indices` (which steps become frames), :class:`TrajectoryAnimation` (the
frames: the chip over the pattern beside its energy and twist, blitted) and
:func:`write_trajectory_gif` (one shared palette, encoded in memory, written
atomically). Drawn in the physical frame of :mod:`simulator.render`; matplotlib,
shapely, skimage, PIL and imageio are imported only when a frame is drawn.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np

from foundation import InputError, atomic_output
from patterns.geometry import Mask
from simulator.render._style import CHIP_COLOUR, J_TO_NJ, PATH_COLOUR, S_TO_MS

__all__ = ["TrajectoryAnimation", "chip_outline", "frame_indices", "write_trajectory_gif"]


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
    return np.column_stack(
        [xy[:, 0] * c - xy[:, 1] * s + pose[0], xy[:, 0] * s + xy[:, 1] * c + pose[1]]
    )


# ------------------------------------------------------------------ animation
def frame_indices(traj, max_frames: int = 120) -> np.ndarray:
    """Indices into ``traj.path`` of the frames to draw: at most ``max_frames``, first and last always.

    Stepping methods are sampled evenly in steps, dynamics evenly in time (so the
    animation runs at a constant multiple of physical time).
    """
    if (
        isinstance(max_frames, bool)
        or not isinstance(max_frames, int | np.integer)
        or max_frames < 2
    ):
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


#: The tint of a wet pad in a trajectory's frames (the footprint as the run's state).
WET_RGBA = (0.30, 0.62, 1.0, 0.42)


class TrajectoryAnimation:
    """Frames of a trajectory: the chip over the pattern, and its energy and twist so far.

    Left: the pattern (white = wettable, grey = substrate; anything outside the image
    is substrate), the chip outline at the current pose (red), its start pose
    (dashed), and the path of its centre so far (blue); with the footprint as the run's
    state (``--dispense``), the pads wet at that frame tinted blue. Right: energy (nJ) and twist
    (deg) against step, or time (ms) for dynamics, with a marker at the current
    frame. The static parts are drawn once; each frame redraws only the moving
    artists (blitting), so a frame costs a few milliseconds.

    Args:
        scene: the scene the trajectory ran on (its pattern and chip are drawn).
        traj: a :class:`simulator.motion.Trajectory`.
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
        self._wet_now = None
        self.wet = None
        if traj.footprint is not None:
            from patterns.geometry import pad_labels

            self._labels = pad_labels(scene.pattern)[0]
            pat = scene.pattern
            self.wet = self.ax.imshow(
                np.zeros(pat.shape + (4,)),
                extent=pat.extent_um,
                origin="upper",
                interpolation="nearest",
                zorder=2,
                animated=True,
            )
            self.ax.set_title(
                "red: chip now · dashed: at start · blue: path · tinted: wet pads", fontsize=9
            )
        self.canvas.draw()
        self._background = self.canvas.copy_from_bbox(self.fig.bbox)

    # -- layout
    def _draw_static(self, scene) -> None:
        from matplotlib.patches import PathPatch
        from matplotlib.path import Path

        fig, traj, path = self.fig, self.traj, self.path
        gs = fig.add_gridspec(
            2,
            2,
            width_ratios=(1.0, 1.05),
            height_ratios=(1.6, 1.0),
            left=0.085,
            right=0.975,
            bottom=0.15,
            top=0.86,
            wspace=0.22,
            hspace=0.12,
        )
        ax = self.ax = fig.add_subplot(gs[:, 0])
        ax_e = self.ax_e = fig.add_subplot(gs[0, 1])
        ax_t = self.ax_t = fig.add_subplot(gs[1, 1], sharex=ax_e)
        pat = scene.pattern
        ax.set_facecolor(_substrate_rgb())
        ax.imshow(
            pat.data,
            cmap=_pattern_cmap(),
            vmin=0,
            vmax=1,
            extent=pat.extent_um,
            origin="upper",
            interpolation="antialiased",
        )
        xlim, ylim = self._limits(pat)
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        ax.set_aspect("equal")
        ax.plot([0], [0], "+", color="k", ms=9, mew=1.2, zorder=3)
        ax.add_patch(
            PathPatch(
                Path(_place(self._verts, path[0]), self._codes),
                fill=False,
                ec=PATH_COLOUR,
                lw=1.0,
                ls=(0, (4, 3)),
                alpha=0.8,
                zorder=3,
            )
        )
        ax.set_xlabel("x (µm)")
        ax.set_ylabel("y (µm)")
        ax.set_title("red: chip now · dashed: at start · blue: path of its centre", fontsize=9)
        self.chip = PathPatch(
            Path(_place(self._verts, path[0]), self._codes),
            fc=(0.91, 0.07, 0.18, 0.16),
            ec=CHIP_COLOUR,
            lw=2.0,
            zorder=5,
            animated=True,
        )
        ax.add_patch(self.chip)
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
        self.energy_title = _energy_title(scene, traj)
        ax_e.set_title(self.energy_title, fontsize=9)
        self.title = fig.text(0.5, 0.955, "", ha="center", va="center", fontsize=12, animated=True)
        fig.text(
            0.5,
            0.025,
            _scene_caption(scene, traj),
            ha="center",
            va="center",
            fontsize=9,
            color="0.3",
        )

    def _limits(self, pat: Mask) -> tuple[tuple[float, float], tuple[float, float]]:
        """Square axis limits holding the pattern's pads, the chip at every frame and the path."""
        rows = np.flatnonzero(pat.data.max(axis=1) > 0)
        cols = np.flatnonzero(pat.data.max(axis=0) > 0)
        h, w = pat.shape
        s = pat.um_per_px
        pts = [
            np.array(
                [
                    [(cols[0] - w / 2) * s, (h / 2 - rows[-1] - 1) * s],
                    [(cols[-1] + 1 - w / 2) * s, (h / 2 - rows[0]) * s],
                ]
            ),
            self.path[:, :2],
        ]
        pts += [_place(self._verts, self.path[i]) for i in self.indices]
        pts = np.concatenate(pts)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        mid, half = (lo + hi) / 2, 0.53 * float((hi - lo).max())
        return (mid[0] - half, mid[0] + half), (mid[1] - half, mid[1] + half)

    # -- frames
    def title_of(self, i: int) -> str:
        """The frame title at path index ``i``: step (or time), pose, the wet pads with the
        footprint state, and the outcome at the end."""
        x, y, t = (round(float(v), 1) + 0.0 for v in self.path[i])
        n = len(self.path) - 1
        when = f"t = {self.xs[i]:.2f} ms" if self.traj.t_s is not None else f"step {i}/{n}"
        text = f"{self.traj.method}: {when}   chip at x {x:g} µm, y {y:g} µm, twist {t:g}°"
        if self.traj.footprint is not None:
            wet = self.wet_pads(i)
            text += "   wet: " + (", ".join(str(k) for k in wet) if wet else "none")
        return text + (f"   → {self.traj.outcome}" if i == n else "")

    def wet_pads(self, i: int) -> tuple[int, ...]:
        """The pads wet at path index ``i`` (the footprint's initial pads and its events up to
        ``i``), or () without the footprint state."""
        fp = self.traj.footprint
        if fp is None:
            return ()
        wet = set(fp["initial"])
        for e in fp["events"]:
            if e["step"] <= i:
                (wet.add if e["state"] == "wet" else wet.discard)(e["pad"])
        return tuple(sorted(wet))

    def frame(self, i: int) -> np.ndarray:
        """The (H, W, 3) uint8 RGB picture at path index ``i``."""
        from matplotlib.path import Path

        self.canvas.restore_region(self._background)
        if self.wet is not None:
            now = self.wet_pads(i)
            if now != self._wet_now:
                rgba = np.zeros(self._labels.shape + (4,))
                rgba[np.isin(self._labels, now)] = WET_RGBA
                self.wet.set_data(rgba)
                self._wet_now = now
            self.fig.draw_artist(self.wet)
        self.chip.set_path(Path(_place(self._verts, self.path[i]), self._codes))
        self.trail.set_data(self.path[: i + 1, 0], self.path[: i + 1, 1])
        self.centre.set_data(self.path[i : i + 1, 0], self.path[i : i + 1, 1])
        for done, dot, ys in self.live:
            done.set_data(self.xs[: i + 1], ys[: i + 1])
            dot.set_data(self.xs[i : i + 1], ys[i : i + 1])
        self.title.set_text(self.title_of(i))
        for artist in (
            self.trail,
            self.chip,
            self.centre,
            self.title,
            *(a for pair in self.live for a in pair[:2]),
        ):
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


def write_trajectory_gif(
    scene,
    traj,
    path: str | os.PathLike,
    max_frames: int = 120,
    fps: float = 20.0,
    hold_s: float = 1.5,
    quiet: bool = True,
) -> int:
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
    data = iio.imwrite(
        "<bytes>",
        index,
        extension=".gif",
        mode="P",
        palette=palette,
        optimize=True,
        # one frame (a run that stopped where it was released): one delay, as Pillow's
        # single-frame writer takes no list
        duration=durations if len(frames) > 1 else durations[0],
        loop=0,
    )
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
    strip = np.repeat(
        (np.array(keys) * 255).round().astype(np.uint8), 8 * w // len(keys) + 1, axis=0
    )[: 8 * w]
    sample = np.concatenate([frames[0], frames[n // 2], frames[-1], strip.reshape(8, w, 3)], axis=0)
    pal = Image.fromarray(sample).quantize(colors=colours, method=Image.Quantize.MEDIANCUT)
    index = np.stack(
        [
            np.asarray(Image.fromarray(f).quantize(palette=pal, dither=Image.Dither.NONE))
            for f in frames
        ]
    )
    palette = pal.getpalette()
    assert palette is not None  # a quantized image has its palette
    return index, bytes(palette[: 3 * colours])


def _pattern_cmap():
    """Substrate mid-grey, pads white: the red chip and blue path stand out on both."""
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list("pattern", [_substrate_rgb(), (1.0, 1.0, 1.0)])


def _substrate_rgb() -> tuple[float, float, float]:
    return (0.62, 0.63, 0.66)


def _energy_title(scene, traj) -> str:
    """The energy panel's title: the model the energy is of (docs/physics.md §2, §3, §3.5)."""
    h = scene.meniscus_height_um
    if h is None:
        return "energy E = Δγ · overlap area (lower = better aligned)"
    model = "the wet pads' footprint" if traj.footprint is not None else "the footprint"
    return f"energy of {model}, meniscus h = {h:.3g} µm (lower = better aligned)"


def _scene_caption(scene, traj) -> str:
    p, c = scene.pattern, scene.chip
    h, w = p.shape
    chip = c.params.get("design", "PNG") if c.geometry is not None else "PNG"
    cw, ch = (
        (c.params.get("width_um"), c.params.get("height_um"))
        if chip == "rectangle"
        else (None, None)
    )
    chip_txt = f"{cw:g} x {ch:g} µm chip" if cw else f"chip footprint {c.area_um2:,.0f} µm²"
    s = traj.start
    grey = bool(np.any((p.data > 0.02) & (p.data < 0.98)))  # graded pads, or the anti-aliased edges
    shades = (
        ", lighter = graded" if grey else ""
    )  # partly wettable: graded pads, anti-aliased edges
    return (
        f"pattern {w * p.um_per_px:g} x {h * p.um_per_px:g} µm at {p.um_per_px:g} µm/px (white = pad, "
        f"grey = substrate{shades}, + = centre), {chip_txt}; start ({s[0]:g} µm, {s[1]:g} µm, {s[2]:g}°), twist CCW +"
    )
