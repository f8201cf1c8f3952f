"""The landscape engine: plan a build (twists, translation box, pattern crop, budget)
and build E[twist, y, x] for a scene, sizes first and allocation after.

Twists are processed in chunks so that peak memory stays under the scene's budget;
an over-budget request fails before any chip rotation or transform.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np

from patterns.errors import InputError
from patterns.mask import nonzero_box
from simulator.correlator import (
    NOISE_FACTOR,
    SAME_CHIP_TOL,
    Correlator,
    Window,
    _correlate_into,
    fft_shape,
    work_bytes,
)
from simulator.feedback import progress_bar
from simulator.materials import UM2
from simulator.meniscus import CHIP_BLUR_MIN_PX, margin_px
from simulator.posegrid import _axis_box, _twist_cut, twist_axis
from simulator.rotation import ChipRotator, _chip_reach_px, mirror_twins
from simulator.scene import Scene

if TYPE_CHECKING:
    from simulator.landscape import Landscape



def energy_scale_J(scene: Scene) -> float:
    """The largest |E| the scene can reach, ``|Delta_gamma| min(|P|, |C|)`` in J (PHYSICS.md C8)."""
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


def _box(scene: Scene, twists: np.ndarray | None, center_px: tuple[int, int] = (0, 0), half_px: int | None = None) -> dict:
    """Twists and translation box of a build, and its landscape bytes: sizes only, no rotation."""
    all_twists, wrap, period = twist_axis(scene)
    twists = all_twists if twists is None else np.asarray(twists, float)
    pat = scene.pattern.data
    r0, r1, c0, c1 = nonzero_box(pat > 0)
    h, w = pat.shape
    # Cropped pattern, y-up; origin (physical 0, 0) in pixel-corner coordinates.
    origin = (w / 2 - c0, r1 - h / 2)
    reach = (max(w / 2 - c0, c1 - w / 2), max(h / 2 - r0, r1 - h / 2))
    chip_rx, chip_ry = _chip_reach_px(scene.chip, scene.effects.twist)
    # A finite meniscus widens the liquid footprint: poses that far beyond contact still feel it.
    margin = margin_px(scene.meniscus_height_px)
    chip_rx, chip_ry = chip_rx + margin, chip_ry + margin
    limit = None if scene.window_um is None else math.ceil(scene.window_um / scene.um_per_px - 1e-9)
    cx, rx, x_lo, x_hi = _axis_box(math.ceil(reach[0] + chip_rx - 1e-9), limit, int(center_px[0]), half_px)
    cy, ry, y_lo, y_hi = _axis_box(math.ceil(reach[1] + chip_ry - 1e-9), limit, int(center_px[1]), half_px)
    nbytes = len(twists) * (2 * ry + 1) * (2 * rx + 1) * np.dtype(scene.dtype).itemsize
    return {
        "twists": twists, "all_twists": all_twists, "wrap": wrap, "period": period, "origin": origin,
        "crop": (r0, r1, c0, c1), "x": (cx, rx, x_lo, x_hi), "y": (cy, ry, y_lo, y_hi), "landscape_bytes": int(nbytes),
        "margin": margin,
    }


def require_landscape_fits(scene: Scene, twists: np.ndarray | None = None) -> None:
    """Refuse (InputError) a landscape over the memory budget or with too many twists, cheaply
    (no rotation, no allocation): for commands to call before announcing a long run."""
    b = _box(scene, twists)
    _, rx, _, _ = b["x"]
    _, ry, _, _ = b["y"]
    _refuse_over_budget(scene, b["landscape_bytes"], len(b["twists"]), 2 * ry + 1, 2 * rx + 1)


def plan(scene: Scene, twists: np.ndarray | None = None, center_px: tuple[int, int] = (0, 0), half_px: int | None = None,
         check_budget: bool = True) -> dict:
    """Everything the build will do, computed without allocating the landscape.

    Refuses (InputError) a landscape over the scene's memory budget before any chip
    rotation is computed (``check_budget=False``: the layout only, for a caller that
    never allocates the landscape, e.g. :mod:`simulator.optimum`'s bound).
    """
    b = _box(scene, twists, center_px, half_px)
    twists, all_twists, wrap, period, origin = b["twists"], b["all_twists"], b["wrap"], b["period"], b["origin"]
    (r0, r1, c0, c1), (cx, rx, x_lo, x_hi), (cy, ry, y_lo, y_hi) = b["crop"], b["x"], b["y"]
    if check_budget:
        _refuse_over_budget(scene, b["landscape_bytes"], len(twists), 2 * ry + 1, 2 * rx + 1)
    pat = scene.pattern.data
    parity = (int((2 * origin[1]) % 2), int((2 * origin[0]) % 2))
    # The meniscus blur: on the chip (rotated smoothly) from one pixel up; below a pixel on
    # the pattern, whose exact rasters then return the overlap model to round-off as h -> 0.
    h_px = scene.meniscus_height_px
    chip_blur = h_px if h_px >= CHIP_BLUR_MIN_PX else 0.0
    rot = ChipRotator(scene.chip, twists, parity, blur_px=chip_blur, margin_px=b["margin"] if chip_blur else 0)
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
    nbytes = b["landscape_bytes"]
    return {
        "twists": twists,
        "wrap": wrap and len(twists) == len(all_twists),
        "period": period,
        "pattern_up": pat_up,
        "rotator": rot,
        "window": win,
        "center_px": (cx, cy),
        "cut": (_twist_cut(all_twists, wrap, twists), (y_lo, y_hi), (x_lo, x_hi)),
        "landscape_bytes": int(nbytes),
        "meniscus_px": h_px if not chip_blur else 0.0,  # blur left to the correlator (pattern side)
        "chip_blurred": bool(chip_blur),
    }


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
    win, rot = p["window"], p["rotator"]
    _check_energy_range(scene)
    # Sizes first, allocation after: an over-budget request fails before any transform.
    chunk = max(1, min(chunk, len(p["twists"])))
    fft = fft_shape(p["pattern_up"].shape, rot.shape, win)
    # A chunk of mirror twins works on twice the twists (the twins' spectra and windows).
    twins = mirror_twins(scene.twist_axis.mirror, p["twists"])
    per_chunk = chunk * (2 if twins else 1)
    need = p["landscape_bytes"] + work_bytes(fft, 2 * win.ry + 1, scene.dtype, per_chunk, -(-len(p["twists"]) // chunk))
    _refuse_over_budget(scene, need, len(p["twists"]), 2 * win.ry + 1, 2 * win.rx + 1)
    cor = Correlator(p["pattern_up"], rot.shape, win, scene.dtype, backend, meniscus_px=p["meniscus_px"])
    twists_deg = p["twists"]
    scale = scene.delta_gamma_N_m * scene.um_per_px**2 * UM2
    energy = np.empty((len(twists_deg), 2 * win.ry + 1, 2 * win.rx + 1), dtype=scene.dtype)
    singles = [i for i in range(len(twists_deg)) if i not in twins and i not in twins.values()]
    pairs = sorted(twins.items())
    # Exact geometry, and a blurred one (a mirror-symmetric image rotated by splines on a
    # mirror-symmetric grid): the raster at -alpha is the one at +alpha upside down.
    exact = scene.chip.geometry is not None
    # Pattern mirror-symmetric too (about y = 0) and the window centred on y = 0:
    # E(x, y, -alpha) = E(x, -y, +alpha), the twin's plane upside down, no transform.
    pat = scene.pattern.data
    copy = exact and p["center_px"][1] == 0 and bool(np.abs(pat - pat[::-1]).max() <= SAME_CHIP_TOL)
    n_mirror = n_copied = rotations = 0
    work = cor.workspace(chunk, mirror=bool(pairs) and not copy)

    def rotate(t: float) -> np.ndarray:
        nonlocal rotations
        rotations += 1
        return rot(t)

    with progress_bar(progress, len(twists_deg), "landscape", "twist") as bar:
        for i in range(0, len(singles), chunk):
            sel = singles[i : i + chunk]
            _correlate_into(cor, np.stack([rotate(twists_deg[k]) for k in sel]), energy, sel, scale, work=work)
            bar.update(len(sel))
        for i in range(0, len(pairs), chunk):
            sel = pairs[i : i + chunk]
            pos, neg = [a for a, _ in sel], [b for _, b in sel]
            stack = np.stack([rotate(twists_deg[a]) for a in pos])
            if copy:
                _correlate_into(cor, stack, energy, pos, scale, work=work)
                for a, b in sel:
                    energy[b] = energy[a, ::-1]
                n_copied += len(sel)
            else:
                _correlate_into(cor, stack, energy, pos, scale, mirror_idx=neg, work=work)
                n_mirror += len(sel)
            if not exact:
                # The raster at -alpha is the one at +alpha upside down for exact,
                # mirror-symmetric geometry; a resampled PNG chip is checked pixel by pixel.
                for b, img in zip(neg, stack, strict=True):
                    direct = rotate(twists_deg[b])
                    if np.abs(direct - img[::-1]).max() > SAME_CHIP_TOL:
                        cor(direct[None], out=energy[b : b + 1], scale=scale, work=work)
                        n_mirror -= 1
            bar.update(2 * len(sel))
    from simulator.landscape import Landscape

    s = scene.um_per_px
    cx, cy = p["center_px"]
    return Landscape(
        energy=energy,
        x_um=(np.arange(2 * win.rx + 1) - win.rx + cx) * s,
        y_um=(np.arange(2 * win.ry + 1) - win.ry + cy) * s,
        twist_deg=twists_deg,
        wrap=p["wrap"],
        period_deg=p["period"],
        um_per_px=s,
        delta_gamma=scene.delta_gamma_N_m,
        cut=p["cut"],
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
