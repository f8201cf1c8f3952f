"""The landscape engine: plan a build (twists, translation box, pattern crop, budget)
and build E[twist, y, x] for a scene, sizes first and allocation after.

Twists are processed in chunks so that peak memory stays under the scene's budget;
an over-budget request fails before any chip rotation or transform.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from foundation import RASTER_BYTES_PER_PX, InputError, progress_bar, wait_line
from patterns.geometry import nonzero_box
from simulator.core import UM2
from simulator.landscape._correlator import NOISE_FACTOR, Correlator
from simulator.landscape._fftsize import Window, fft_shape, work_bytes
from simulator.landscape._posegrid import (
    PoseGrid,
    _axis_box,
    _twist_cut,
    evenly_spaced_axis,
)
from simulator.landscape._rotation import (
    SMOOTH_ROTATE_BYTES_PER_PX,
    ChipRotator,
    _chip_reach_px,
    canvas_shape,
    mirror_twins,
    smooth_bytes,
    smooth_canvas,
)
from simulator.landscape._symmetry import SAME_CHIP_TOL, correlate_planes
from simulator.physics import CHIP_BLUR_MIN_PX
from simulator.scene import Scene, TwistAxis, resampled_extent

if TYPE_CHECKING:
    from simulator.landscape._landscape import Landscape

#: Transform pixels per second and twist of a build (2 cores: 3 to 6e6 measured, SciPy): for
#: the waiting line of a long build (:func:`simulator.core.wait_line`), not for any result.
FFT_PX_PER_S = 5e6


def energy_scale_J(scene: Scene) -> float:
    """The largest |E| the scene can reach, ``|Delta_gamma| min(|P|, |C|)`` in J (docs/physics.md C8)."""
    return abs(scene.delta_gamma_N_m) * min(scene.pattern.area_um2, scene.chip.area_um2) * UM2


def _check_energy_range(scene: Scene) -> None:
    """Refuse a scene whose energies in joules the dtype cannot hold as normal numbers.

    Three values must be normal (not subnormal, not infinite): the energy of one fully
    overlapping pixel (the factor every correlation is multiplied by), the noise floor
    (the smallest energy difference that counts) and the largest energy, with a margin
    of 2**10 for sums and differences. Otherwise float32 silently loses the landscape:
    XLA flushes subnormals to zero, so a weak scene would look like "no contact"
    everywhere. In float32 one pixel of overlap must be worth 1.2e-38 J or more
    (|Delta_gamma| >= 1.2e-26 N/m at 1 um/px, 1.2e-20 N/m at 1e-3 um/px) and no energy more
    than 3.3e35 J (water at 30/60 degrees: 2.7e-14 J per um^2). In float64, anything physical.
    A scene with Delta_gamma = 0 (``allow_repulsive``) has no energy at all and passes.
    """
    fi = np.finfo(scene.dtype)
    dg = abs(scene.delta_gamma_N_m)
    if dg == 0:
        return
    pixel = dg * scene.um_per_px**2 * UM2
    largest = energy_scale_J(scene)
    floor = NOISE_FACTOR * float(fi.eps) * largest
    if min(pixel, floor) < fi.tiny or largest > fi.max / 2**10:
        m = scene.materials
        raise InputError(
            f"the energies of this scene are outside what {scene.dtype} holds: one pixel of overlap is "
            f"{pixel:.3g} J, the noise floor {floor:.3g} J and the largest energy {largest:.3g} J, but they "
            f"must lie between {float(fi.tiny):.3g} and {float(fi.max) / 2**10:.3g} J (surface tension "
            f"{m.surface_tension_N_m:g} N/m, contact angles {m.pad_angle_deg:g}/{m.substrate_angle_deg:g} deg, "
            f"{scene.um_per_px:g} um/px); use dtype float64, or check the surface tension and the scale"
        )


def estimate_bytes(
    scene: Scene, twists: ArrayLike | None = None, um_per_px: float | None = None
) -> int:
    """Bytes the landscape array of ``scene`` would take (before building it; nothing is rotated).

    ``um_per_px``: the landscape of ``scene.at_resolution(um_per_px)``, computed from the
    scene's rasters without resampling them (:func:`simulator.scene.resampled_extent`: the
    reach of pattern and chip at that pixel size; the scene's twist axis and meniscus height).
    """
    if um_per_px is None or math.isclose(um_per_px, scene.um_per_px, rel_tol=1e-9):
        return _box(scene, twists)["landscape_bytes"]
    n_twists = _twist_run(scene, twists)[2]
    e = _extent(scene, um_per_px)
    _, rx, _, _ = _axis_box(e["full"][0], e["limit"], 0, None)
    _, ry, _, _ = _axis_box(e["full"][1], e["limit"], 0, None)
    return int(n_twists * (2 * ry + 1) * (2 * rx + 1) * np.dtype(scene.dtype).itemsize)


def _refuse_over_budget(
    scene: Scene, need: float, n_twists: int, ny: int, nx: int, what: str = ""
) -> None:
    """InputError unless ``need`` bytes fit ``scene.memory_budget_mb``; ``what`` says what
    the estimate holds beyond the energy array (the transforms' work space, the footprint)."""
    if need > scene.memory_budget_mb * 2**20:
        raise InputError(
            f"the landscape needs about {need / 2**20:,.0f} MB ({n_twists} twist{'s' if n_twists != 1 else ''} x "
            f"{ny} x {nx} poses, {scene.dtype}{what}) but the memory budget is "
            f"{scene.memory_budget_mb:,.0f} MB; use a coarser scale (--um-per-px), a larger twist step "
            "or narrower twist range, a smaller translation window (window_um), or raise memory_budget_mb (--memory-budget)"
        )


def _refuse_footprint(scene: Scene, need: float, canvas: tuple[int, int]) -> None:
    """InputError unless the meniscus footprint of the chip (``need`` bytes while it is
    made on its ``canvas``) fits the memory budget: before the chip is rasterized for it."""
    if need > scene.memory_budget_mb * 2**20:
        h, w = canvas
        cw, ch = (v * scene.chip.um_per_px for v in scene.chip.shape[::-1])
        how = "the distance transform" if scene.wall_profile is not None else "the K_h blur"
        raise InputError(
            f"the meniscus footprint of the {cw:,.4g} x {ch:,.4g} um chip ({how} of {w:,} x {h:,} px at "
            f"{scene.um_per_px:g} um/px, meniscus {scene.meniscus_height_um:.3g} um) needs about {need / 2**20:,.0f} MB "
            f"but the memory budget is {scene.memory_budget_mb:,.0f} MB; use a coarser scale (--resolution), a lower "
            "meniscus (--volume or --meniscus-height), or raise --memory-budget"
        )


def _twist_run(scene: Scene, twists) -> tuple[TwistAxis, int, int, tuple[bool, bool]]:
    """(axis, first index, count, cut ends) of the twists a build computes: the scene's
    whole axis, a run of consecutive twists of it, or any other evenly spaced twists on an
    axis of their own (InputError otherwise: a landscape's twists are one pose grid); the
    cut ends say where the run stops short of the scene's twist range."""
    axis = scene.twist_axis
    if twists is None:
        return axis, 0, axis.count, axis.cut_of(0, axis.count)
    tw = np.atleast_1d(np.asarray(twists, float))
    k0 = axis.locate(tw)
    if k0 is not None:
        return axis, k0, len(tw), axis.cut_of(k0, len(tw))
    return evenly_spaced_axis(tw, axis), 0, len(tw), _twist_cut(axis.values(), axis.periodic, tw)


def _box(
    scene: Scene,
    twists,
    center_px: tuple[int, int] = (0, 0),
    half_px: int | None = None,
    extent: dict | None = None,
) -> dict:
    """Twists and translation box of a build, and its landscape bytes: sizes only, no rotation
    (the pose grid is made by :func:`_grid_of`, complete, once the budget is checked;
    ``extent``: the scene's :func:`_extent`, when a caller keeps it for many boxes)."""
    axis, t_first, n_twists, t_cut = _twist_run(scene, twists)
    e = _extent(scene) if extent is None else extent
    limit = e["limit"]
    cx, rx, x_lo, x_hi = _axis_box(e["full"][0], limit, int(center_px[0]), half_px)
    cy, ry, y_lo, y_hi = _axis_box(e["full"][1], limit, int(center_px[1]), half_px)
    shape = (n_twists, 2 * ry + 1, 2 * rx + 1)
    return {
        "axis": axis,
        "t_first": t_first,
        "shape": shape,
        "cut": (t_cut, (y_lo, y_hi), (x_lo, x_hi)),
        "first_px": (cx - rx, cy - ry),
        "origin": e["origin"],
        "crop": e["crop"],
        "landscape_bytes": int(math.prod(shape) * np.dtype(scene.dtype).itemsize),
        "margin": e["margin"],
    }


def _grid_of(scene: Scene, b: dict) -> PoseGrid:
    """The pose grid of a box (:func:`_box`), complete: its twist run, translations, cut sides
    and the chip's radius of gyration (the scene's, derived once per scene)."""
    axis, (x_first, y_first), n_twists = b["axis"], b["first_px"], b["shape"][0]
    return PoseGrid(
        shape=b["shape"],
        um_per_px=scene.um_per_px,
        twist=axis,
        wrap=axis.periodic and n_twists == axis.count,
        cut=b["cut"],
        rg_px=scene.chip_rg_px,
        x_first_px=x_first,
        y_first_px=y_first,
        t_first=b["t_first"],
    )


def _extent(scene: Scene, um_per_px: float | None = None) -> dict:
    """The translation reach of a scene's pose grid, in px: ``full`` (x, y), the half-widths
    at which the chip no longer touches the pattern (its meniscus footprint included), and
    ``limit``, the scene's window; with the pattern's crop, origin and the meniscus margin.

    ``um_per_px``: at that pixel size, as :meth:`Scene.at_resolution` would resample the
    scene, computed from the extents of the resampled rasters
    (:func:`simulator.scene.resampled_extent`) without making them (default: the scene's own).
    """
    native = um_per_px is None
    s = scene.um_per_px if native else um_per_px
    pat = scene.pattern
    (h, w), (r0, r1, c0, c1) = (
        (pat.shape, nonzero_box(pat.data > 0)) if native else resampled_extent(pat, s)
    )
    # Cropped pattern, y-up; origin (physical 0, 0) in pixel-corner coordinates.
    origin = (w / 2 - c0, r1 - h / 2)
    reach = (max(w / 2 - c0, c1 - w / 2), max(h / 2 - r0, r1 - h / 2))
    chip_rx, chip_ry = _chip_reach_px(scene.chip, scene.effects.twist, None if native else s)
    # A finite meniscus widens the liquid footprint: poses that far beyond contact still feel it.
    margin = scene.meniscus_margin_px_at(s)
    chip_rx, chip_ry = chip_rx + margin, chip_ry + margin
    limit = None if scene.window_um is None else math.ceil(scene.window_um / s - 1e-9)
    full = (math.ceil(reach[0] + chip_rx - 1e-9), math.ceil(reach[1] + chip_ry - 1e-9))
    return {
        "full": full,
        "limit": limit,
        "origin": origin,
        "crop": (r0, r1, c0, c1),
        "margin": margin,
    }


def scene_extent(scene: Scene) -> dict:
    """The translation reach of ``scene``'s pose grid (:func:`_extent`), for
    :func:`build_landscape`'s ``extent``."""
    return _extent(scene)


def require_landscape_fits(
    scene: Scene,
    twists: ArrayLike | None = None,
    center_px: tuple[int, int] = (0, 0),
    half_px: int | None = None,
) -> int:
    """Refuse (InputError) a landscape over the memory budget or with too many twists, cheaply
    (no rotation, no allocation): for commands to call before announcing a long run.

    Prices what :func:`build_landscape` of the same arguments would hold at its peak, in
    its smallest chunk of twists: the energy array, the transforms' work space, and with a
    meniscus the chip's footprint (made once per chip) and its rotations. Returns the bytes
    of the landscape's energy array (the plan's ``landscape_bytes``).
    """
    return int(_layout(scene, twists, center_px, half_px, check_budget=True)["landscape_bytes"])


@dataclass(frozen=True, eq=False)
class Plan:
    """What a build will do, computed before the landscape is allocated (:func:`plan`).

    grid: the landscape's pose grid. pattern_up: the cropped pattern, y up, that the chip
    poses of the grid can reach. rotator: the chip raster at each twist. window: where
    the grid lies in the correlation. landscape_bytes: the energy array's size.
    meniscus_px: the meniscus blur left to the pattern side (px; 0 when the chip is
    blurred, ``chip_blurred``).
    """

    grid: PoseGrid
    pattern_up: np.ndarray
    rotator: ChipRotator
    window: Window
    landscape_bytes: int
    meniscus_px: float
    chip_blurred: bool

    @property
    def twists(self) -> np.ndarray:
        """The twists (degrees) the build rotates the chip to: the grid's."""
        return self.grid.twist_deg()


def plan(
    scene: Scene,
    twists: ArrayLike | None = None,
    center_px: tuple[int, int] = (0, 0),
    half_px: int | None = None,
    check_budget: bool = True,
) -> Plan:
    """Everything the build will do, computed without allocating the landscape.

    Refuses (InputError) a build over the scene's memory budget before any chip rotation
    is computed: the landscape with its smallest chunk of twists (the energy array, the
    transforms' work space, the chip's rasters) and, with a meniscus, the chip's footprint
    (a distance transform or a blur of the whole chip, made once per chip). With
    ``check_budget=False`` (the layout only, for a caller that never allocates the
    landscape, e.g. :mod:`simulator.landscape`'s bound) the footprint alone is priced.
    """
    return _plan_of(scene, _layout(scene, twists, center_px, half_px, check_budget))


def _plan_of(scene: Scene, lay: dict) -> Plan:
    """The plan of a priced layout (:func:`_layout`): the chip's rotator made (with a
    meniscus, its footprint: the expensive part, after the pricing)."""
    grid, win, pat_up = lay["grid"], lay["window"], lay["pattern_up"]
    rot = ChipRotator(
        scene.chip,
        grid.twist_deg(),
        lay["parity"],
        blur_px=lay["chip_blur"],
        margin_px=lay["rot_margin"],
        profile=scene.wall_profile,
    )
    assert rot.shape == lay["canvas"], "the rotator's canvas is the one priced"
    m = lay["pad"]
    if m:  # room for the blurred footprint, so that the meniscus blur does not wrap around
        pat_up = np.pad(pat_up, m)
        win = Window(rx=win.rx, ry=win.ry, dx=win.dx + m, dy=win.dy + m)
    h_px = scene.meniscus_height_px
    return Plan(
        grid,
        pat_up,
        rot,
        win,
        int(lay["landscape_bytes"]),
        h_px if not lay["chip_blur"] else 0.0,
        bool(lay["chip_blur"]),
    )


def _layout(
    scene: Scene,
    twists,
    center_px: tuple[int, int],
    half_px: int | None,
    check_budget: bool,
    extent: dict | None = None,
) -> dict:
    """The plan's sizes (grid, window, cropped pattern, the rotator's canvas), priced against
    the budget (see :func:`plan`): nothing rotated, rasterized or transformed (``extent``: a
    scene's :func:`_extent` to lay the grid out by instead of this scene's own)."""
    b = _box(scene, twists, center_px, half_px, extent)
    origin, (r0, r1, c0, c1) = b["origin"], b["crop"]
    n_twists, ny, nx = b["shape"]
    if check_budget:  # the energy array alone, before anything else is sized
        _refuse_over_budget(scene, b["landscape_bytes"], n_twists, ny, nx)
    # The pose grid, complete, after the budget check.
    grid = _grid_of(scene, b)
    rx, ry = nx // 2, ny // 2
    cx, cy = grid.x_first_px + rx, grid.y_first_px + ry
    pat = scene.pattern.data
    parity = (int((2 * origin[1]) % 2), int((2 * origin[0]) % 2))
    # The meniscus blur: on the chip (rotated smoothly) from one pixel up; below a pixel on
    # the pattern, whose exact rasters then return the overlap model to round-off as h -> 0.
    h_px = scene.meniscus_height_px
    chip_blur = h_px if h_px >= CHIP_BLUR_MIN_PX else 0.0
    rot_margin = b["margin"] if chip_blur else 0
    hc, wc = canvas_shape(scene.chip, grid.twist_deg(), parity, rot_margin)
    dx, dy = origin[0] - wc / 2 + cx, origin[1] - hc / 2 + cy
    assert dx == int(dx) and dy == int(dy), "pixel grids of chip and pattern must coincide"
    win = Window(rx=rx, ry=ry, dx=int(dx), dy=int(dy))
    # Keep only the pattern rows/columns some chip pose in the window can reach.
    pat_up = pat[r0:r1, c0:c1][::-1]
    ya, yb = max(0, win.dy - win.ry), min(pat_up.shape[0], win.dy + win.ry + hc)
    xa, xb = max(0, win.dx - win.rx), min(pat_up.shape[1], win.dx + win.rx + wc)
    if yb <= ya or xb <= xa:  # no pose of the box touches the pattern
        ya, yb, xa, xb = 0, 1, 0, 1
    pat_up = pat_up[ya:yb, xa:xb]
    win = Window(rx=win.rx, ry=win.ry, dx=win.dx - xa, dy=win.dy - ya)
    m = b["margin"] if 0 < h_px < CHIP_BLUR_MIN_PX else 0
    out = {
        "grid": grid,
        "window": win,
        "pattern_up": pat_up,
        "parity": parity,
        "chip_blur": chip_blur,
        "rot_margin": rot_margin,
        "canvas": (hc, wc),
        "pad": m,
        "landscape_bytes": b["landscape_bytes"],
        # where pattern_up lies in the pattern (rows r0:r1, cols c0:c1, then flipped up and
        # cut to ya:yb, xa:xb): another pattern of the same size on the same box is cut so
        "crop": (r0, r1, c0, c1, ya, yb, xa, xb),
    }
    # The footprint (made once per chip, kept) and the rotations onto the canvas.
    make, kept = smooth_bytes(scene.chip, chip_blur, rot_margin, scene.wall_profile, parity)
    rotating = hc * wc * (SMOOTH_ROTATE_BYTES_PER_PX if kept else RASTER_BYTES_PER_PX)
    out["rotator_bytes"] = kept + rotating
    if make:
        _refuse_footprint(
            scene,
            make,
            smooth_canvas(scene.chip, rot_margin, parity, scene.wall_profile is not None),
        )
    if check_budget:
        need = _build_bytes(scene, out, 1)
        if need > scene.memory_budget_mb * 2**20:
            _refuse_over_budget(
                scene,
                need,
                n_twists,
                ny,
                nx,
                ", with the transforms' work space"
                + (" and the chip's meniscus footprint" if kept else ""),
            )
    return out


def _fft_of(lay: dict) -> tuple[int, int]:
    """(ny, nx) of the correlation's transforms for the layout ``lay`` (:func:`_layout`)."""
    win, m = lay["window"], lay["pad"]
    win = Window(rx=win.rx, ry=win.ry, dx=win.dx + m, dy=win.dy + m)  # as the plan pads the pattern
    return fft_shape(tuple(v + 2 * m for v in lay["pattern_up"].shape), lay["canvas"], win)


def _build_bytes(scene: Scene, lay: dict, chunk: int) -> int:
    """Peak bytes of a build of the layout ``lay`` (:func:`_layout`) in chunks of ``chunk``
    twists: the energy array, the correlation's work space, the chunk's chip rasters (each
    made, then stacked) and the footprint with its rotations."""
    win = lay["window"]
    n_twists = lay["grid"].shape[0]
    fft = _fft_of(lay)
    twists_deg = lay["grid"].twist_deg()
    per_chunk = chunk * (2 if mirror_twins(scene.twist_axis.mirror, twists_deg) else 1)
    hc, wc = lay["canvas"]
    rasters = 2 * chunk * hc * wc * 8
    return int(
        lay["landscape_bytes"]
        + work_bytes(fft, 2 * win.ry + 1, scene.dtype, per_chunk, -(-n_twists // chunk))
        + rasters
        + lay["rotator_bytes"]
    )


def _whole(v) -> bool:
    """``v`` is a whole number (an int, or an integral finite float), not a bool."""
    if isinstance(v, bool | np.bool_):
        return False
    if isinstance(v, int | np.integer):
        return True
    return isinstance(v, float | np.floating) and math.isfinite(v) and float(v).is_integer()


def _check_build_arguments(twists, center_px, half_px) -> None:
    """InputError (one line naming the argument) for twists that are not a list of finite
    degrees, a centre that is not two finite pixel numbers, or a negative or fractional half-width."""
    if twists is not None:
        try:
            tw = np.asarray(twists, dtype=float)
        except (TypeError, ValueError):
            tw = None
        if tw is None or tw.ndim != 1 or tw.size == 0 or not np.all(np.isfinite(tw)):
            raise InputError(
                f"twists must be a non-empty list of finite twists in degrees, got {twists!r}"
            )
    try:
        ok = len(center_px) == 2 and all(
            not isinstance(c, bool | np.bool_) and math.isfinite(c) for c in center_px
        )
    except TypeError:
        ok = False
    if not ok:
        raise InputError(
            f"center_px must be two finite numbers of pixels (x, y) from the pattern centre, got {center_px!r}"
        )
    if half_px is not None and not (_whole(half_px) and half_px >= 0):
        raise InputError(
            f"half_px must be a whole number of pixels >= 0 (or None for the scene's whole window), got {half_px!r}"
        )


def build_landscape(
    scene: Scene,
    twists: ArrayLike | None = None,
    center_px: tuple[int, int] = (0, 0),
    half_px: int | None = None,
    backend: str = "auto",
    chunk: int = 8,
    progress: bool = False,
    label: str = "landscape",
    extent: dict | None = None,
) -> Landscape:
    """Compute E[twist, y, x] (J) for the scene, or for a subset of its twists.

    Args:
        scene: what to simulate.
        twists: twist values (degrees) to compute; default the scene's whole twist axis.
            A twist-free scene computes exactly one rotation.
        center_px, half_px: compute only the box of translations within ``half_px`` px of
            ``center_px`` (x, y px from the pattern centre), clamped to the reach; default
            the scene's whole window.
        backend: "auto" (SciPy on CPU, JAX on GPU), "scipy" or "jax".
        chunk: twists transformed together (memory per chunk is reported in stats).
        progress: show a progress bar over twist chunks.
        label: what the waiting line calls this build when no progress bar is shown and it
            takes long enough (:func:`simulator.core.wait_line`), e.g. "landscape box 3".
        extent: lay the pose grid out by another scene's reach (:func:`scene_extent`) instead
            of this scene's: one pattern's pads, built one by one, on one grid
            (:mod:`simulator.landscape` footprint planes).

    Raises:
        InputError: the landscape would exceed ``scene.memory_budget_mb``.
    """
    t_start = time.perf_counter()
    _check_build_arguments(twists, center_px, half_px)
    _check_energy_range(scene)
    # Sizes first, allocation after: an over-budget request fails before any rotation or
    # transform, and the chunk of twists shrinks until the build fits the budget.
    lay = _layout(scene, twists, center_px, half_px, check_budget=True, extent=extent)
    chunk = max(1, min(chunk, lay["grid"].shape[0]))
    while chunk > 1 and _build_bytes(scene, lay, chunk) > scene.memory_budget_mb * 2**20:
        chunk = max(1, chunk // 2)
    if not progress:
        n, ny, nx = lay["grid"].shape
        fy, fx = _fft_of(lay)
        wait_line(
            f"{label}: {n} twist{'s' if n != 1 else ''} x {ny:,} x {nx:,} poses (transforms of {fy:,} x {fx:,} px)",
            n * fy * fx / FFT_PX_PER_S,
        )
    p = _plan_of(scene, lay)
    win, rot = p.window, p.rotator
    twists_deg = p.twists
    # A chunk of mirror twins works on twice the twists (the twins' spectra and windows).
    twins = mirror_twins(scene.twist_axis.mirror, twists_deg)
    cor = Correlator(p.pattern_up, rot.shape, win, scene.dtype, backend, meniscus_px=p.meniscus_px)
    scale = scene.delta_gamma_N_m * scene.um_per_px**2 * UM2
    energy = np.empty((len(twists_deg), 2 * win.ry + 1, 2 * win.rx + 1), dtype=scene.dtype)
    # Exact geometry, and a blurred one (a mirror-symmetric image rotated by splines on a
    # mirror-symmetric grid): the raster at -alpha is the one at +alpha upside down.
    exact = scene.chip.geometry is not None
    # Pattern mirror-symmetric too (about y = 0) and the window centred on y = 0:
    # E(x, y, -alpha) = E(x, -y, +alpha), the twin's plane upside down, no transform.
    pat = scene.pattern.data
    copy = (
        exact
        and p.grid.y_first_px + win.ry == 0
        and bool(np.abs(pat - pat[::-1]).max() <= SAME_CHIP_TOL)
    )
    work = cor.workspace(chunk, mirror=bool(twins) and not copy)
    rotations = 0

    def rasters(sel: list[int]) -> np.ndarray:
        nonlocal rotations
        rotations += len(sel)
        return np.stack([rot(twists_deg[k]) for k in sel])

    def verify(b: int, img: np.ndarray) -> np.ndarray | None:
        # A resampled PNG chip is checked pixel by pixel against its twin upside down.
        direct = rasters([b])[0]
        return direct if np.abs(direct - img[::-1]).max() > SAME_CHIP_TOL else None

    with progress_bar(progress, len(twists_deg), "landscape", "twist") as bar:
        n_mirror, n_copied = correlate_planes(
            cor,
            rasters,
            len(twists_deg),
            energy,
            scale,
            work,
            chunk,
            twins=twins,
            flip_rows=energy.shape[1] if copy else None,
            verify=None if exact else verify,
            progress=bar.update,
            self_twins=tuple(int(i) for i in np.flatnonzero(np.round(twists_deg, 9) == 0))
            if copy
            else (),
        )
    from simulator.landscape._landscape import Landscape

    return Landscape(
        energy=energy,
        grid=p.grid,
        delta_gamma=scene.delta_gamma_N_m,
        energy_scale_J=energy_scale_J(scene),
        meniscus_height_um=scene.meniscus_height_um,
        stats={
            "rotations": rotations,
            "mirrored_twists": n_mirror,  # spectrum from the twin's transform
            "copied_twists": n_copied,  # the twin's plane upside down
            "seconds": time.perf_counter() - t_start,
            "bytes": energy.nbytes,
            "backend": cor.backend,
            "fft_shape": (cor.ny, cor.nx),
            "chip_canvas": rot.shape,
        },
    )
