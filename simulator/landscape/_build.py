"""The landscape engine: plan a build (twists, translation box, pattern crop, budget)
and build E[twist, y, x] for a scene, sizes first and allocation after.

Twists are processed in chunks so that peak memory stays under the scene's budget;
an over-budget request fails before any chip rotation or transform.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from patterns.errors import InputError
from patterns.mask import nonzero_box
from simulator.core import UM2, progress_bar
from simulator.landscape._correlator import (
    NOISE_FACTOR,
    SAME_CHIP_TOL,
    Correlator,
    Window,
    correlate_planes,
    fft_shape,
    work_bytes,
)
from simulator.landscape._posegrid import (
    PoseGrid,
    _axis_box,
    _twist_cut,
    evenly_spaced_axis,
)
from simulator.landscape._rotation import ChipRotator, _chip_reach_px, mirror_twins
from simulator.physics import CHIP_BLUR_MIN_PX
from simulator.scene import Scene, TwistAxis

if TYPE_CHECKING:
    from simulator.landscape._landscape import Landscape



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


def estimate_bytes(scene: Scene, twists: np.ndarray | None = None) -> int:
    """Bytes the landscape array of ``scene`` would take (before building it; nothing is rotated)."""
    return _box(scene, twists)["landscape_bytes"]


def _refuse_over_budget(scene: Scene, need: float, n_twists: int, ny: int, nx: int) -> None:
    """InputError unless ``need`` bytes fit ``scene.memory_budget_mb``."""
    if need > scene.memory_budget_mb * 2**20:
        raise InputError(
            f"the landscape needs about {need / 2**20:,.0f} MB ({n_twists} twists x "
            f"{ny} x {nx} poses, {scene.dtype}) but the memory budget is "
            f"{scene.memory_budget_mb:,.0f} MB; use a coarser scale (--um-per-px), a larger twist step "
            "or narrower twist range, a smaller translation window (window_um), or raise memory_budget_mb"
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


def _scene_extent(scene: Scene) -> dict:
    """What every box of a scene shares (one pass over the pattern and the chip): the
    pattern's crop and origin, the reach of pattern and chip, the meniscus margin, the window."""
    pat = scene.pattern.data
    r0, r1, c0, c1 = nonzero_box(pat > 0)
    h, w = pat.shape
    # Cropped pattern, y-up; origin (physical 0, 0) in pixel-corner coordinates.
    origin = (w / 2 - c0, r1 - h / 2)
    reach = (max(w / 2 - c0, c1 - w / 2), max(h / 2 - r0, r1 - h / 2))
    chip_rx, chip_ry = _chip_reach_px(scene.chip, scene.effects.twist)
    # A finite meniscus widens the liquid footprint: poses that far beyond contact still feel it.
    margin = scene.meniscus_margin_px
    limit = None if scene.window_um is None else math.ceil(scene.window_um / scene.um_per_px - 1e-9)
    return {"crop": (r0, r1, c0, c1), "origin": origin, "reach": reach, "chip_reach": (chip_rx + margin, chip_ry + margin),
            "margin": margin, "limit": limit}


def _box(scene: Scene, twists, center_px: tuple[int, int] = (0, 0), half_px: int | None = None, extent: dict | None = None) -> dict:
    """Twists and translation box of a build, and its landscape bytes: sizes only, no rotation
    (``extent``: the scene's :func:`_scene_extent`, when a caller keeps it)."""
    axis, t_first, n_twists, t_cut = _twist_run(scene, twists)
    ext = _scene_extent(scene) if extent is None else extent
    origin, reach, (chip_rx, chip_ry), margin, limit = ext["origin"], ext["reach"], ext["chip_reach"], ext["margin"], ext["limit"]
    cx, rx, x_lo, x_hi = _axis_box(math.ceil(reach[0] + chip_rx - 1e-9), limit, int(center_px[0]), half_px)
    cy, ry, y_lo, y_hi = _axis_box(math.ceil(reach[1] + chip_ry - 1e-9), limit, int(center_px[1]), half_px)
    nbytes = n_twists * (2 * ry + 1) * (2 * rx + 1) * np.dtype(scene.dtype).itemsize
    grid = PoseGrid(
        shape=(n_twists, 2 * ry + 1, 2 * rx + 1),
        um_per_px=scene.um_per_px,
        twist=axis,
        wrap=axis.periodic and n_twists == axis.count,
        cut=(t_cut, (y_lo, y_hi), (x_lo, x_hi)),
        rg_px=0.0,  # set by build_landscape once the budget is checked (it costs a pass over the chip)
        x_first_px=cx - rx,
        y_first_px=cy - ry,
        t_first=t_first,
    )
    return {"grid": grid, "origin": origin, "crop": ext["crop"], "landscape_bytes": int(nbytes), "margin": margin}


def require_landscape_fits(scene: Scene, twists: np.ndarray | None = None) -> None:
    """Refuse (InputError) a landscape over the memory budget or with too many twists, cheaply
    (no rotation, no allocation): for commands to call before announcing a long run."""
    b = _box(scene, twists)
    t, ny, nx = b["grid"].shape
    _refuse_over_budget(scene, b["landscape_bytes"], t, ny, nx)


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


def plan(scene: Scene, twists: np.ndarray | None = None, center_px: tuple[int, int] = (0, 0), half_px: int | None = None,
         check_budget: bool = True) -> Plan:
    """Everything the build will do, computed without allocating the landscape.

    Refuses (InputError) a landscape over the scene's memory budget before any chip
    rotation is computed (``check_budget=False``: the layout only, for a caller that
    never allocates the landscape, e.g. :mod:`simulator.landscape`'s bound).
    """
    b = _box(scene, twists, center_px, half_px)
    grid, origin, (r0, r1, c0, c1) = b["grid"], b["origin"], b["crop"]
    n_twists, ny, nx = grid.shape
    rx, ry = nx // 2, ny // 2
    cx, cy = grid.x_first_px + rx, grid.y_first_px + ry
    if check_budget:
        _refuse_over_budget(scene, b["landscape_bytes"], n_twists, ny, nx)
    pat = scene.pattern.data
    parity = (int((2 * origin[1]) % 2), int((2 * origin[0]) % 2))
    # The meniscus blur: on the chip (rotated smoothly) from one pixel up; below a pixel on
    # the pattern, whose exact rasters then return the overlap model to round-off as h -> 0.
    h_px = scene.meniscus_height_px
    chip_blur = h_px if h_px >= CHIP_BLUR_MIN_PX else 0.0
    rot = ChipRotator(scene.chip, grid.twist_deg(), parity, blur_px=chip_blur, margin_px=b["margin"] if chip_blur else 0,
                      profile=scene.wall_profile)
    hc, wc = rot.shape
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
    if m:  # room for the blurred footprint, so that the meniscus blur does not wrap around
        pat_up = np.pad(pat_up, m)
        win = Window(rx=win.rx, ry=win.ry, dx=win.dx + m, dy=win.dy + m)
    return Plan(grid, pat_up, rot, win, int(b["landscape_bytes"]), h_px if not chip_blur else 0.0, bool(chip_blur))


def build_landscape(
    scene: Scene,
    twists: np.ndarray | None = None,
    center_px: tuple[int, int] = (0, 0),
    half_px: int | None = None,
    backend: str = "auto",
    chunk: int = 8,
    progress: bool = False,
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

    Raises:
        InputError: the landscape would exceed ``scene.memory_budget_mb``.
    """
    t_start = time.perf_counter()
    p = plan(scene, twists, center_px, half_px)
    win, rot = p.window, p.rotator
    _check_energy_range(scene)
    # Sizes first, allocation after: an over-budget request fails before any transform.
    twists_deg = p.twists
    chunk = max(1, min(chunk, len(twists_deg)))
    fft = fft_shape(p.pattern_up.shape, rot.shape, win)
    # A chunk of mirror twins works on twice the twists (the twins' spectra and windows).
    twins = mirror_twins(scene.twist_axis.mirror, twists_deg)
    per_chunk = chunk * (2 if twins else 1)
    need = p.landscape_bytes + work_bytes(fft, 2 * win.ry + 1, scene.dtype, per_chunk, -(-len(twists_deg) // chunk))
    _refuse_over_budget(scene, need, len(twists_deg), 2 * win.ry + 1, 2 * win.rx + 1)
    cor = Correlator(p.pattern_up, rot.shape, win, scene.dtype, backend, meniscus_px=p.meniscus_px)
    scale = scene.delta_gamma_N_m * scene.um_per_px**2 * UM2
    energy = np.empty((len(twists_deg), 2 * win.ry + 1, 2 * win.rx + 1), dtype=scene.dtype)
    # Exact geometry, and a blurred one (a mirror-symmetric image rotated by splines on a
    # mirror-symmetric grid): the raster at -alpha is the one at +alpha upside down.
    exact = scene.chip.geometry is not None
    # Pattern mirror-symmetric too (about y = 0) and the window centred on y = 0:
    # E(x, y, -alpha) = E(x, -y, +alpha), the twin's plane upside down, no transform.
    pat = scene.pattern.data
    copy = exact and p.grid.y_first_px + win.ry == 0 and bool(np.abs(pat - pat[::-1]).max() <= SAME_CHIP_TOL)
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
        n_mirror, n_copied = correlate_planes(cor, rasters, len(twists_deg), energy, scale, work, chunk, twins=twins,
                                              flip_rows=energy.shape[1] if copy else None,
                                              verify=None if exact else verify, progress=bar.update)
    from simulator.landscape._landscape import Landscape

    return Landscape(
        energy=energy,
        grid=replace(p.grid, rg_px=scene.chip_rg_px),
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
