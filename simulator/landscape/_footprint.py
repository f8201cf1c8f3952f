"""The landscape of every footprint state: one energy plane set per pad, summed by state.

The energy is linear in the pattern, so the pattern's pads (its connected regions) are
correlated one at a time, each on the same pose grid, with the chip footprints the
footprint state needs (:mod:`simulator.physics`, ``FootprintRules``): the wall profile (a
wet pad the chip covers), four counts of the pad's area within a distance of the chip
(covered, reached at ``d_s``, within the reach ``d_r``) and the bridged pad's term (a
weighted sum of the counts either side of a band just beyond ``d_r``, one footprint). Pads
behind one another add a pairwise correction where both are wet (the shadow rule of
:mod:`simulator.physics._footprint`: a near pad's strip under the bridge to a far pad has no
line of its own). The energy of a state is then the sum of the wet pads' planes and of the
wet pairs' corrections (:meth:`FootprintPlanes.landscape`), and the state at a pose the
relay of each pad (:meth:`FootprintPlanes.next_state`): no transform per event.

How it is made (docs/physics.md §3.5, cost): the chip's footprints are rotated once per
twist and shared by every pad (the rotations are the same for every pad); each pad is
correlated with each footprint only over the poses where that footprint can touch it (its
bounding box grown by the chip's reach and the footprint's margin; elsewhere the count or
energy is zero), and each pair over the poses where the side of the chip facing it can;
the planes are reduced to what the state needs a chunk of twists at a time (no full-grid
temporary), and the parts whose transforms have the same sizes share their work arrays.
A pattern that a quarter or half turn takes onto itself, under a chip the turn leaves as
it is, has some pads' and pairs' planes made as others' turned (:mod:`._turns`,
checked chunk by chunk on everything they read: a quarter of the transforms for a four-pad
under a square chip).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from foundation import InputError, wait_line
from patterns.geometry import Mask, pad_labels
from simulator.core import UM2
from simulator.scene import Scene

from ._build import (
    FFT_PX_PER_S,
    _check_energy_range,
    _fft_of,
    _layout,
    _plan_of,
    scene_extent,
)
from ._landscape import Landscape
from ._symmetry import SAME_CHIP_TOL
from ._turns import (
    _grid_box_turned,
    _pattern_mirror,
    _pattern_turns,
    _same_turned,
    _turn,
    _turn_image,
)

if TYPE_CHECKING:
    from simulator.physics import FootprintRules

    from ._correlator import Correlator


def _variant(scene: Scene, pattern: Mask, profile) -> Scene:
    """``scene`` with another pattern and another chip footprint (the wall profile the builder
    correlates): a scene's ``wall_profile`` is derived once and cached on it, and here it is
    set before the builder first reads it."""
    s = scene.replace(pattern=pattern)
    s.__dict__["wall_profile"] = profile
    return s


def footprint_poses(scene: Scene) -> int:
    """Poses of the grid the pads' planes share (:func:`build_footprint_planes`): the scene's
    reach widened to the furthest count footprint (a band just beyond ``d_r``), so larger
    than the stateless landscape's when the receding angle is small. No rotation, no build."""
    from simulator.physics import FootprintRules

    from ._build import estimate_bytes

    prof = scene.wall_profile
    if prof is None:
        return estimate_bytes(scene) // np.dtype(scene.dtype).itemsize
    m = scene.materials
    rules = FootprintRules.of(prof, m.pad_receding_deg if scene.effects.hysteresis else None)
    wide = _variant(scene, scene.pattern, rules.count_profiles()["band_out"])
    return estimate_bytes(wide) // np.dtype(scene.dtype).itemsize


def _pads_of(scene: Scene, rules) -> tuple[np.ndarray, int, list, list]:
    """(labels, n, each pad's mask, whether each is deep enough for the bridged term: its
    smaller side beyond the band and its steps)."""
    from scipy import ndimage

    from simulator.physics import STEP_PX

    labels, n = pad_labels(scene.pattern)
    masks, deep = [], []
    for k, box in enumerate(ndimage.find_objects(labels), start=1):
        masks.append(labels == k)
        deep.append(
            min(box[0].stop - box[0].start, box[1].stop - box[1].start)
            >= rules.band_px + 2 * STEP_PX
        )
    return labels, n, masks, deep


def _area_centre(values, rows, cols, shape, um_per_px: float) -> tuple[float, tuple[float, float]]:
    """A pad's area (um^2) and centroid (x, y um from the image's centre, y up), weighted by
    the pattern's ``values`` at its pixels (``rows``, ``cols`` of an image of ``shape``)."""
    h, w = shape
    s, total = um_per_px, values.sum()
    return float(total) * s * s, (
        float(((cols + 0.5 - w / 2) * values).sum() / total) * s,
        float(((h / 2 - rows - 0.5) * values).sum() / total) * s,
    )


def _shadowed(masks: list, deep: list, residuals) -> list[tuple[int, int, int, dict]]:
    """The shadow rule's pairs (near, far, axis, {residual deg: pixel box of the near pad's
    part upstream of the far one}), for every far pad on its bridged term (a narrow one keeps
    its wall term: no bridge over the near pad). The shadow of the side of the chip facing
    the pattern's axis ``axis`` is cast along that side's own normal, ``axis * 90`` deg plus
    the twist's residual (:func:`simulator.physics.shadow_residual_deg`), for each residual
    in ``residuals``; a pair is listed where some residual gives it a part."""
    from simulator.physics import ray_coordinates

    if not any(deep):
        return []
    lab = np.zeros(masks[0].shape, np.int32)
    for k, m in enumerate(masks):
        lab[m] = k + 1
    rows, cols = np.nonzero(lab)
    pad = lab[rows, cols] - 1
    h, w = (int(v) for v in lab.shape)
    found: dict = {}
    for ax in range(4):
        for r in sorted({float(v) for v in np.asarray(residuals, float)}):
            ray, along = ray_coordinates(rows, cols, (h, w), ax * 90.0 + r)
            lo = ray.min()
            for b in range(len(masks)):
                if not deep[b]:
                    continue
                far = np.full(ray.max() - lo + 1, -np.inf)
                on_b = pad == b
                np.maximum.at(far, ray[on_b] - lo, along[on_b])
                up = (along < far[ray - lo]) & ~on_b
                for a in np.unique(pad[up]):
                    rr, cc = rows[up & (pad == a)], cols[up & (pad == a)]
                    box = (
                        cc.min() - w / 2,
                        cc.max() + 1 - w / 2,
                        h / 2 - rr.max() - 1,
                        h / 2 - rr.min(),
                    )
                    found.setdefault((int(a), b, ax), {})[r] = box
    return sorted(
        ((a, b, ax, d) for (a, b, ax), d in found.items()), key=lambda t: (t[1], t[2], t[0])
    )


def _shadow_part(masks: list, a: int, b: int, ax: int, r: float) -> np.ndarray:
    """The near pad ``a``'s part upstream of the far pad ``b`` along ``axis * 90 + r`` deg
    (:func:`_shadowed`), booleans on the pattern."""
    from simulator.physics import upstream_along

    return masks[a] & upstream_along(masks[b], ax * 90.0 + r)


def _covering(mask: np.ndarray, reach: tuple[float, float], margin: float) -> tuple:
    """(x0, x1, y0, y1) px: the poses at which a chip of half-extent ``reach`` (px, over its
    twists) with a footprint ``margin`` px wide can cover some of ``mask``."""
    x0, x1, y0, y1 = _pixel_box(mask)
    rx, ry = reach[0] + margin, reach[1] + margin
    return x0 - rx - 1, x1 + rx + 1, y0 - ry - 1, y1 + ry + 1


def _faces(twists_deg, ax: int) -> tuple[np.ndarray, np.ndarray]:
    """(the chip's side whose normal is nearest the pattern's axis ``ax``, the twist's
    residual deg) at each twist (the chip frame's sides as ``_Sides``)."""
    from simulator.physics import shadow_residual_deg

    t = np.asarray(twists_deg, float)
    nearest = np.rint(t / 90.0).astype(int)
    return (ax - nearest) % 4, shadow_residual_deg(t)


def _pair_ranges(boxes: dict, corners, tw_rad, res, within=None) -> tuple[list, list]:
    """([x0, x1], [y0, y1]) px from the pattern's centre of the poses at which a chip side's
    strip (``corners``: per twist, the chip-frame corners of the box holding it) reaches the
    near pad's part (``boxes``, by residual), over the twists ``tw_rad`` (residuals ``res``),
    within the box ``within`` (x0, x1, y0, y1) px where one is given."""
    xr, yr = [np.inf, -np.inf], [np.inf, -np.inf]
    for c, t, r in zip(corners, tw_rad, res, strict=True):
        c = np.asarray(c, float).reshape(-1, 2)
        if not len(c):
            continue
        x0, x1, y0, y1 = boxes[r]
        ca, sa = math.cos(t), math.sin(t)
        qx = c[:, 0] * ca - c[:, 1] * sa
        qy = c[:, 0] * sa + c[:, 1] * ca
        xr = [min(xr[0], x0 - qx.max()), max(xr[1], x1 - qx.min())]
        yr = [min(yr[0], y0 - qy.max()), max(yr[1], y1 - qy.min())]
    if within is not None:  # the poses where the chip covers some of the near pad
        xr = [max(xr[0], within[0]), min(xr[1], within[1])]
        yr = [max(yr[0], within[2]), min(yr[1], within[3])]
    return xr, yr


def footprint_pairs(scene: Scene) -> tuple[int, int, int]:
    """(pairs, at most how many poses their planes hold together, poses of one twist of the
    grid) of the shadow rule (:class:`PairPlane`): each pair's part against the box of the
    chip's side facing its axis (the chip's half-widths, out to the band), rotated over the
    grid's twists, within the grid, as the build lays them out (there from the chip's signed
    distance, inside this box). No rotation, no build."""
    from simulator.physics import STEP_PX, FootprintRules

    from ._build import _box, _grid_of
    from ._rotation import _chip_reach_px

    prof = scene.wall_profile
    if prof is None:
        return 0, 0, 0
    m = scene.materials
    rules = FootprintRules.of(prof, m.pad_receding_deg if scene.effects.hysteresis else None)
    wide = _variant(scene, scene.pattern, rules.count_profiles()["band_out"])
    b = _box(wide, None)
    n_t, ny, nx = b["shape"]
    x_first, y_first = b["first_px"]
    twists_deg = _grid_of(wide, b).twist_deg()
    tw = np.radians(twists_deg)
    hx, hy = _chip_reach_px(scene.chip, False)
    lo, hi = rules.d_s - 5.0, rules.band_px + STEP_PX
    side_box = {  # chip frame, (x0, x1, y0, y1) px: +x, +y, -x, -y
        0: (hx + lo - 1, hx + hi + 1, -hy - hi - 1, hy + hi + 1),
        1: (-hx - hi - 1, hx + hi + 1, hy + lo - 1, hy + hi + 1),
        2: (-hx - hi - 1, -hx - lo + 1, -hy - hi - 1, hy + hi + 1),
        3: (-hx - hi - 1, hx + hi + 1, -hy - hi - 1, -hy - lo + 1),
    }
    corners = {
        k: [(a0, b0), (a0, b1), (a1, b0), (a1, b1)] for k, (a0, a1, b0, b1) in side_box.items()
    }
    _, _, masks, deep = _pads_of(scene, rules)
    total = 0
    pairs = _shadowed(masks, deep, _faces(twists_deg, 0)[1])
    reach = _chip_reach_px(scene.chip, scene.effects.twist)
    cm = rules.count_profiles()["covered"].margin_px
    for a, _, ax, boxes in pairs:
        face, res = _faces(twists_deg, ax)
        on = [i for i in range(len(tw)) if res[i] in boxes]
        xr, yr = _pair_ranges(
            boxes,
            [corners[int(face[i])] for i in on],
            tw[on],
            res[on],
            _covering(masks[a], reach, cm),
        )
        wx = min(xr[1], x_first + nx - 1) - max(xr[0], x_first) + 2
        wy = min(yr[1], y_first + ny - 1) - max(yr[0], y_first) + 2
        total += len(on) * max(0, int(wx)) * max(0, int(wy))
    return len(pairs), total, ny * nx


@dataclass(frozen=True, eq=False)
class PairPlane:
    """The shadow rule's correction for one pair of pads (:mod:`simulator.physics._footprint`):
    ``near`` and ``far`` (0-based pad indices), the pattern's axis ``axis`` whose facing chip
    side casts the shadow, and ``energy`` (len(twists), ny, nx) J at the grid's twists
    ``twists`` (those whose shadow reaches from the near pad to the far one) on the box of
    the grid whose first node is (``y0``, ``x0``): added to a state's landscape where both
    pads are wet (it is already 0 where the near pad is not covered or the far pad not on its
    bridged term)."""

    near: int
    far: int
    axis: int
    y0: int
    x0: int
    energy: np.ndarray
    twists: np.ndarray

    def box(self) -> tuple[np.ndarray | slice, slice, slice]:
        """The indices of the grid (twists, y slice, x slice) that :attr:`energy` covers (the
        twists as a slice where they run in a row: a state's sum adds in place)."""
        _, ny, nx = self.energy.shape
        t = np.asarray(self.twists)
        run = len(t) > 0 and bool(np.all(np.diff(t) == 1))
        twists = slice(int(t[0]), int(t[-1]) + 1) if run else t
        return twists, slice(self.y0, self.y0 + ny), slice(self.x0, self.x0 + nx)


@dataclass(frozen=True, eq=False)
class FootprintPlanes:
    """Per-pad planes of one scene on one pose grid (module docstring).

    rules: the relay's reaches (:class:`simulator.physics.FootprintRules`). wet_energy:
    (pads, T, Ny, Nx) J, each pad's energy while it is wet (the wall profile's term where the
    chip covers some of it, the bridged term elsewhere; a pad whose smaller side is below the
    bridged term's band, ``FootprintRules.band_px`` and two steps, keeps the wall term
    everywhere: its far edge would lie inside the band). reached_bits, within_bits: (T, Ny,
    Nx, ceil(pads / 8)) uint8, the relay's inputs packed a bit per pad (pad k in bit k % 8 of
    byte k // 8: :attr:`reached` and :attr:`within_reach` unpack them). pairs: the shadow rule's corrections
    (:class:`PairPlane`), each added where both its pads are wet. template: a landscape of the
    grid (its metadata). pad_area_um2, pad_centre_um: each pad's area and centroid (x, y um,
    y up).
    """

    rules: FootprintRules
    wet_energy: np.ndarray
    reached_bits: np.ndarray
    within_bits: np.ndarray
    template: Landscape
    pad_area_um2: np.ndarray
    pad_centre_um: np.ndarray
    labels: np.ndarray
    seconds: float
    pairs: tuple = field(default=())

    @property
    def n_pads(self) -> int:
        return int(self.wet_energy.shape[0])

    def _unpacked(self, bits: np.ndarray) -> np.ndarray:
        """(..., W) packed flags as (..., pads) booleans."""
        return np.unpackbits(bits, axis=-1, count=self.n_pads, bitorder="little").astype(bool)

    @property
    def reached(self) -> np.ndarray:
        """(pads, T, Ny, Nx) booleans: some of the pad within ``d_s`` of the chip (a dry pad
        wets). Unpacked from :attr:`reached_bits` on each call: a byte per pad and pose."""
        return np.moveaxis(self._unpacked(self.reached_bits), -1, 0)

    @property
    def within_reach(self) -> np.ndarray:
        """(pads, T, Ny, Nx) booleans: some of the pad within ``d_r`` of the chip (a wet pad
        stays wet). Unpacked from :attr:`within_bits` on each call."""
        return np.moveaxis(self._unpacked(self.within_bits), -1, 0)

    def flags_at(self, it, iy, ix) -> tuple[np.ndarray, np.ndarray]:
        """(reached, within_reach) at grid nodes (index arrays of one shape S): (*S, pads)
        booleans each, unpacked there only."""
        return (
            self._unpacked(self.reached_bits[it, iy, ix]),
            self._unpacked(self.within_bits[it, iy, ix]),
        )

    def energy(self, wet, out: np.ndarray | None = None) -> np.ndarray:
        """(T, Ny, Nx) J: the energy of the footprint state ``wet`` ((pads,) booleans), the wet
        pads' planes and the corrections of the pairs of them (:attr:`pairs`); ``out``: an
        array of that shape and dtype to write it in (a batch's states, one after another)."""
        from simulator.core import threads

        from ._backends import _pool

        w = np.asarray(wet, bool)
        e = np.empty(self.template.energy.shape, self.template.energy.dtype) if out is None else out
        pads = np.flatnonzero(w)
        pairs = [(p.energy, p.box()) for p in self.pairs if w[p.near] and w[p.far]]

        def add(t0: int, t1: int) -> None:
            """The sum at twists t0..t1 - 1: each pose's terms in the same order whatever
            the blocks (the result does not depend on the threads)."""
            part = e[t0:t1]
            part[...] = 0
            for k in pads:
                part += self.wet_energy[k][t0:t1]
            for pe, (tw, ys, xs) in pairs:
                if isinstance(tw, slice):
                    a, b = max(tw.start, t0), min(tw.stop, t1)
                    if a < b:
                        part[a - t0 : b - t0, ys, xs] += pe[a - tw.start : b - tw.start]
                    continue
                rows = np.flatnonzero((tw >= t0) & (tw < t1))
                if rows.size:
                    part[tw[rows] - t0, ys, xs] += pe[rows]

        # twists in blocks, one per thread: a pass over memory that one core does not
        # saturate (the benchmark's 63 x 505 x 505 grid: 0.038 s a state on one thread,
        # 0.017 s on two, on the 2-core machine of docs/benchmarks.md)
        n_t = len(e)
        n = max(1, min(threads(), n_t))
        edges = np.linspace(0, n_t, n + 1).round().astype(int)
        if n == 1:
            add(0, n_t)
        else:
            blocks = zip(edges[:-1], edges[1:], strict=True)
            for f in [_pool(n).submit(add, int(a), int(b)) for a, b in blocks]:
                f.result()
        return e

    def landscape(self, wet) -> Landscape:
        """The landscape of the footprint state ``wet`` ((pads,) booleans)."""
        t = self.template
        return Landscape(
            energy=self.energy(wet),
            grid=t.grid,
            delta_gamma=t.delta_gamma,
            energy_scale_J=t.energy_scale_J,
            meniscus_height_um=t.meniscus_height_um,
            stats=dict(t.stats),
        )

    def node(self, pose) -> tuple[int, int, int]:
        """The grid node nearest ``pose`` (x_um, y_um, twist_deg), clipped to the grid."""
        g = self.template.grid
        it, iy, ix = (int(round(float(v))) for v in g.to_index(np.asarray(pose, float)))
        n_t, ny, nx = g.shape
        it = it % n_t if g.wrap else min(max(it, 0), n_t - 1)
        return it, min(max(iy, 0), ny - 1), min(max(ix, 0), nx - 1)

    def released_curve(self, dispensed, axis: str, through, start: float, stop: float) -> dict:
        """:meth:`Landscape.curve` where each sample is a chip released at that pose onto the
        footprint ``dispensed`` (its state: :meth:`next_state` there), not a continuation
        along the curve; ``wet`` holds each sample's wet pads (1..n)."""
        from ._landscape import curve_of

        ref = self.template.curve(axis, through, start, stop)  # the samples, checked
        v = ref["values"]
        poses = np.tile(np.asarray(through, float), (len(v), 1))
        poses[:, {"x": 0, "y": 1, "twist": 2}[axis]] = v
        states = [tuple(np.flatnonzero(self.next_state(dispensed, p)) + 1) for p in poses]
        e, force = np.empty(len(v)), np.empty(len(v))
        floor = 0.0
        for st in set(states):
            wet = np.zeros(self.n_pads, bool)
            wet[np.asarray(st, int) - 1] = True
            ls = self.landscape(wet)
            c = ls.curve(axis, through, start, stop)
            sel = np.array([s == st for s in states])
            e[sel], force[sel] = c["energy_J"][sel], c["force"][sel]
            floor = ls.noise_floor_J
        same = np.array([a == b for a, b in zip(states[:-1], states[1:], strict=True)], bool)
        return curve_of(axis, v, e, force, floor, linked=same) | {
            "wet": [list(map(int, s)) for s in states]
        }

    def next_state(self, wet, pose) -> np.ndarray:
        """The pads' state once the chip, with the footprint ``wet``, is at ``pose``."""
        from simulator.physics import relay

        reached, within = self.flags_at(*self.node(pose))
        return relay(wet, reached, within)


def side_weights(sides: np.ndarray, ties: np.ndarray, side: int) -> np.ndarray:
    """How much of each pixel lies on the chip's side ``side`` (float64): 1 on its own side,
    half on each of a tie's two sides (``_Sides``: its bin and the side clockwise of it)."""
    w = (sides == side).astype(np.float64)
    w[ties] *= 0.5
    w[ties & ((sides.astype(np.int16) - 1) % 4 == side)] = 0.5
    return w


class _Sides:
    """Which side of the chip each pixel of a rotator's canvas lies on: the direction of the
    signed distance's gradient (outward normal) rounded to one of the chip's four axes
    (``simulator.physics._footprint.AXES``, in the chip's frame), looked up at every twist
    as the rotator looks up the distance (nearest pixel of the unrotated footprint)."""

    def __init__(self, rot):
        sdf = rot._sdf
        gr, gc = np.gradient(sdf)
        phi = np.arctan2(-gr, gc)  # rows run down: y = -row
        # A pixel on a corner's diagonal (its normal exactly halfway between two axes) is a
        # tie: it counts half on each of the two sides (:func:`side_weights`), its bin the
        # one counter-clockwise. Every corner is then split alike, so a quarter turn or a
        # mirror of a square chip takes its sides onto one another exactly (rounding half to
        # even gave the diagonals to the x sides: a chip moving along x and one moving along
        # y saw different corners).
        quarter = phi / (np.pi / 2)
        self.ties = quarter - np.floor(quarter) == 0.5
        self.bins = (np.floor(quarter + 0.5).astype(np.int64) % 4).astype(np.int8)
        self.shape = rot.shape
        self.half = rot._half
        self._xy: tuple[np.ndarray, np.ndarray] | None = None  # the canvas's pixel centres

    def __call__(self, twist_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """(H, W) int8 sides on the canvas at ``twist_deg`` and (H, W) booleans, its ties, y
        up (as the rotator's rasters)."""
        if self._xy is None:  # made on first use: the path engine reads ``bins`` and ``ties``
            ho, wo = self.shape
            self._xy = (
                np.arange(wo, dtype=float)[None, :] - (wo / 2 - 0.5),
                -(np.arange(ho, dtype=float)[:, None] - (ho / 2 - 0.5)),
            )
        x, y = self._xy
        a = math.radians(twist_deg)
        ca, sa = math.cos(a), math.sin(a)
        xi = x * ca + y * sa
        yi = -x * sa + y * ca
        h, w = self.bins.shape
        r = np.clip(np.rint(-yi + (h / 2 - 0.5)), 0, h - 1).astype(np.intp)
        c = np.clip(np.rint(xi + (w / 2 - 0.5)), 0, w - 1).astype(np.intp)
        return self.bins[r, c][::-1], self.ties[r, c][::-1]

    def reach(self, side: int, from_px: float, upto_px: float, sdf: np.ndarray) -> np.ndarray:
        """(x, y) px (chip frame, about its centre) of the corners of the box holding the
        canvas pixels on ``side`` between ``from_px`` and ``upto_px`` from the outline."""
        h, w = sdf.shape
        on = side_weights(self.bins, self.ties, side) > 0
        rr, cc = np.nonzero(on & (sdf > from_px) & (sdf <= upto_px))
        if rr.size == 0:
            return np.zeros((0, 2))
        xs = cc + 0.5 - w / 2
        ys = h / 2 - rr - 0.5
        x0, x1, y0, y1 = xs.min() - 1, xs.max() + 1, ys.min() - 1, ys.max() + 1
        return np.array([(x0, y0), (x0, y1), (x1, y0), (x1, y1)])


def _pixel_box(mask: np.ndarray) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) px from the pattern's centre (y up) of the pixels of ``mask``."""
    h, w = mask.shape
    rr, cc = np.nonzero(mask)
    return cc.min() - w / 2, cc.max() + 1 - w / 2, h / 2 - rr.max() - 1, h / 2 - rr.min()


def _box_args(xr: tuple[float, float], yr: tuple[float, float]) -> tuple[tuple[int, int], int]:
    """(centre px, half-width px) of a square box of poses holding the ranges ``xr``, ``yr``."""
    cx, cy = 0.5 * (xr[0] + xr[1]), 0.5 * (yr[0] + yr[1])
    half = max(xr[1] - xr[0], yr[1] - yr[0]) / 2
    return (int(round(cx)), int(round(cy))), int(math.ceil(half)) + 2


class _Part:
    """One pattern part (a pad, or a pad's part upstream of another) correlated on its box of
    the shared grid: its correlator, work space and where its box lies in the grid."""

    def __init__(
        self,
        scene,
        data,
        profile,
        twists,
        extent,
        center,
        half,
        backend,
        chunk,
        twins,
        spaces,
        like: dict | None = None,
    ):
        if like is None:
            s = _variant(scene, Mask(data, scene.um_per_px), profile)
            lay = _layout(s, twists, center, half, check_budget=True, extent=extent)
        else:  # the layout of another part of the same pattern's size on the same box
            r0, r1, c0, c1, ya, yb, xa, xb = like["crop"]
            lay = like | {"pattern_up": data[r0:r1, c0:c1][::-1][ya:yb, xa:xb]}
        self.lay = lay
        self.grid = lay["grid"]
        win = lay["window"]
        assert lay["pad"] == 0, "the chip carries the footprint"
        self._cor_args = (lay["pattern_up"], lay["canvas"], win, scene.dtype, backend)
        self._cor: Correlator | None = None  # made when first used (a turned part never is)
        self.shape = (2 * win.ry + 1, 2 * win.rx + 1)
        self.fft = _fft_of(lay)
        # A part mirror-symmetric about y = 0 on a box centred there (a pad on the axis of a
        # two-pad pattern): a twin's plane is its partner's upside down and a plane at twist 0
        # is made symmetric exactly, as build_landscape does (a start on the mirror line stays on it).
        self.flip = (
            scene.chip.geometry is not None
            and self.grid.y_first_px + win.ry == 0
            and bool(np.abs(data - data[::-1]).max() <= SAME_CHIP_TOL)
        )
        self._mirror = bool(twins) and not self.flip
        self._chunk, self._spaces = chunk, spaces

    @property
    def cor(self) -> Correlator:
        """The part's correlator, made on first use with its work arrays (:attr:`work`)."""
        if self._cor is None:
            from ._correlator import Correlator

            cor = Correlator(*self._cor_args)
            # The threads' work arrays, shared by the parts whose transforms have the same
            # sizes (``spaces``; the calls run one after another): a part's own are never
            # touched.
            self.work = cor.workspace(self._chunk, mirror=self._mirror)
            key = (cor.backend, cor.ny, cor.nx, self.shape[0], self._mirror)
            if key in self._spaces:
                self.work = self.work._replace(slots=self._spaces[key])
            else:
                self._spaces[key] = self.work.slots
            self._cor = cor
        return self._cor

    def offset(self, full) -> tuple[int, int]:
        """(y, x) of this box's first node in the grid ``full``."""
        return (
            self.grid.y_first_px - full.y_first_px,
            self.grid.x_first_px - full.x_first_px,
        )

    def correlate(self, stack, pos, neg, scale: float, at_zero=()) -> np.ndarray:
        """(len(pos) + len(neg), ny, nx): the planes of the chips ``stack`` at twists ``pos``,
        then, with ``neg``, their mirror twins (the chips upside down), from the same spectra
        (or, for a symmetric part, :attr:`flip`, the planes upside down); ``at_zero``: the
        positions in ``pos`` of twist 0 (their planes made symmetric when the part is)."""
        n = len(pos)
        cor = self.cor
        out = np.empty((n + len(neg), *self.shape), cor.dtype)
        mirror = out[n:] if neg and not self.flip else None
        cor(stack, out=out[:n], scale=scale, mirror_out=mirror, work=self.work)
        if self.flip:
            if neg:
                out[n:] = out[:n, ::-1]
            for i in at_zero:
                plane = out[i]
                plane += plane[::-1].copy()
                plane *= 0.5
        return out


class _PairBox:
    """A shadow pair's parts (:func:`_shadow_part`, one per residual of the twists) on one box
    of the shared grid: each made when first asked for and dropped when the build moves on
    (:meth:`keep`), all on the same box and work space."""

    def __init__(
        self, scene, masks, data, key, profile, twists, extent, center, half, *rest, shadow
    ):
        self._args = (scene, masks, data, key, profile, twists, extent, center, half, *rest)
        self.shadow = shadow  # (a, b, axis, r) -> the part's pixels (:func:`_shadow_part`)
        self._parts: dict = {}
        self._like: dict | None = None
        first = self.part(None)
        # every part of the pair lies on this one's box: its layout, made and priced once,
        # serves them all (only the pattern's cut differs)
        self._like = first.lay
        self.shape, self.fft, self.grid = first.shape, first.fft, first.grid
        self.offset = first.offset

    def part(self, r) -> _Part:
        """The part at the residual ``r`` deg (``None``: an empty part, for the box's sizes)."""
        if r not in self._parts:
            scene, masks, data, (a, b, ax), profile, twists, extent, center, half, *rest = (
                self._args
            )
            part = self.shadow(a, b, ax, r) if r is not None else np.zeros(data.shape, bool)
            if r is None:
                part[masks[a]] = True  # the near pad itself: the same box and sizes
            self._parts[r] = _Part(
                scene,
                np.where(part, data, 0.0),
                profile,
                twists,
                extent,
                center,
                half,
                rest[0],
                rest[1],
                {},
                rest[2],
                like=self._like,
            )
        return self._parts[r]

    def keep(self, residuals) -> None:
        """Drop every part but those at ``residuals``."""
        for r in [r for r in self._parts if r not in {float(v) for v in residuals}]:
            del self._parts[r]


def _pair_sides(at, ax: int, face, pos) -> list[int]:
    """The chip's side (``_Sides``) whose strip a pair on the pattern's axis ``ax`` reads at
    each twist of ``at`` ((position in the chunk, twist, raster, upside down) tuples): the
    side facing the axis; for a mirror twin, the side of its partner's raster that the
    flip puts there."""
    sides = []
    for _, i, k, flipped in at:
        if flipped:  # the side facing the axis at -alpha, before the flip
            fneg = (ax + (ax - int(face[pos[k]]))) % 4
            sides.append((fneg + 2) % 4 if fneg % 2 == 1 else fneg)
        else:
            sides.append(int(face[i]))
    return sides


def _pair_chips(at, sides: list[int], side_of, tie_of, strip) -> np.ndarray:
    """(len(at), H, W): the strip of the chip's side ``sides`` (:func:`_pair_sides`) at each
    twist of ``at`` (:func:`side_weights`), zero on the other sides; a mirror twin's from its
    partner's raster, upside down."""
    chips = []
    for (_, _, k, flipped), side in zip(at, sides, strict=True):
        chip = strip[k] * side_weights(side_of[k], tie_of[k], side)
        chips.append(chip[::-1] if flipped else chip)
    return np.ascontiguousarray(np.stack(chips))


def _side_shift(side_of: np.ndarray, tie_of: np.ndarray, strip: np.ndarray, m: int) -> int | None:
    """The c for which the chip's sides turned by ``m`` (:func:`_turn`) are its sides plus c
    (mod 4), and its ties its ties, at every pixel of its strips, at every twist of the
    chunk; None if there is none (a pixel's side is decided another way after the turn)."""
    on = strip != 0
    if not np.array_equal(_turn(tie_of, m)[on], tie_of[on]):
        return None
    shift = (_turn(side_of, m).astype(np.int16) - side_of) % 4
    values = np.unique(shift[on])
    return int(values[0]) if len(values) == 1 else None


def build_footprint_planes(
    scene: Scene, backend: str = "auto", progress: bool = False, twists=None
) -> FootprintPlanes:
    """The per-pad planes of ``scene`` over its whole pose grid (module docstring).

    Needs the finite meniscus with free contact lines of a pixel or more
    (``scene.wall_profile``); the pads' receding angle is the hysteresis window's when the
    scene declares one, else their Young angle. ``twists``: only these (as
    :func:`build_landscape`'s), default the scene's whole twist axis.
    """
    from simulator.physics import STEP_PX, TOUCH_PX2, FootprintRules

    from ._build import _check_build_arguments, energy_scale_J
    from ._rotation import _chip_reach_px, mirror_twins, rotate_footprints

    t0 = time.perf_counter()
    prof = scene.wall_profile
    if prof is None:
        raise InputError(
            "--dispense needs the finite meniscus with free contact lines (--meniscus, not --pinned) "
            f"of at least a pixel of height; give --meniscus, or a finer --resolution than {scene.um_per_px:g} um"
        )
    _check_build_arguments(twists, (0, 0), None)
    _check_energy_range(scene)
    m = scene.materials
    rules = FootprintRules.of(prof, m.pad_receding_deg if scene.effects.hysteresis else None)
    labels, n, masks, deep = _pads_of(scene, rules)
    counts = rules.count_profiles()
    wide = _variant(scene, scene.pattern, counts["band_out"])
    extent = scene_extent(wide)
    data = scene.pattern.data
    s = scene.um_per_px
    h, w = data.shape
    # The whole grid (every pad's planes lie on it) and the chip's footprints, each rotated
    # once per twist for every pad: one rotator per footprint, on the widest one's canvas.
    full = _layout(wide, twists, (0, 0), None, check_budget=True, extent=extent)
    grid = full["grid"]
    names = ("wall", "reached", "within", "covered", "band_in", "band_out")
    profiles = {"wall": prof} | {k: counts[k] for k in names[1:]}
    rotators = {}
    for name in names:
        lay = _layout(
            _variant(scene, scene.pattern, profiles[name]), twists, (0, 0), None, False, extent
        )
        assert lay["canvas"] == full["canvas"], "one canvas for every footprint"
        rotators[name] = _plan_of(_variant(scene, scene.pattern, profiles[name]), lay).rotator
    twists_deg = grid.twist_deg()
    n_t_all = len(twists_deg)
    exact = scene.chip.geometry is not None
    # Mirror twins (a mirror-symmetric chip at -alpha is the one at +alpha upside down): one
    # forward transform serves both; a resampled PNG chip's twins are not exact, so none.
    twins = mirror_twins(scene.twist_axis.mirror, twists_deg) if exact else {}
    chunk = max(1, min(8, grid.shape[0]))
    # Each pad on its boxes: for each footprint the poses where it can touch the pad (the
    # chip's reach and that footprint's margin; beyond, its count or energy is zero).
    reach_x, reach_y = _chip_reach_px(scene.chip, scene.effects.twist)
    margins = {
        "wall": prof.margin_px,
        "reached": counts["reached"].margin_px,
        "within": counts["within"].margin_px,
        "covered": counts["covered"].margin_px,
        "band": counts["band_out"].margin_px,
    }
    pads, areas, centres = [], [], []
    spaces: dict = {}
    for mask in masks:
        x0, x1, y0, y1 = _pixel_box(mask)
        parts: dict = {}
        by_box: dict = {}
        for nm, mg in margins.items():
            rx, ry = reach_x + mg, reach_y + mg
            key = _box_args((x0 - rx, x1 + rx), (y0 - ry, y1 + ry))
            if key not in by_box:
                by_box[key] = _Part(
                    scene,
                    np.where(mask, data, 0.0),
                    prof,
                    twists,
                    extent,
                    *key,
                    backend,
                    chunk,
                    twins,
                    spaces,
                )
            parts[nm] = by_box[key]
        pads.append(parts)
        rr, cc = np.nonzero(mask)
        area, centre = _area_centre(data[rr, cc], rr, cc, (h, w), s)
        areas.append(area)
        centres.append(centre)
    # The shadow rule's pairs: the part of pad A upstream of pad B along the normal of the
    # chip's side facing an axis, on the poses where that side can reach it (its box, grown by
    # the reach of the side's strip out to the band), at the twists where the part is not empty.
    sides = _Sides(rotators["wall"])
    upto = rules.band_px + STEP_PX
    tw_rad = np.radians(twists_deg)
    strips = [sides.reach(side, rules.d_s - 5.0, upto, rotators["wall"]._sdf) for side in range(4)]
    pair_parts = []
    shadows: dict = {}

    def shadow(a: int, b: int, ax: int, r: float) -> np.ndarray:
        """:func:`_shadow_part`, each made once (a turned pair's check reads its partner's)."""
        if (a, b, ax, r) not in shadows:
            shadows[(a, b, ax, r)] = _shadow_part(masks, a, b, ax, r)
        return shadows[(a, b, ax, r)]

    for a, b, ax, boxes in _shadowed(masks, deep, _faces(twists_deg, 0)[1]):
        face, res = _faces(twists_deg, ax)
        on = np.array([i for i in range(n_t_all) if res[i] in boxes], np.intp)
        cover = _covering(masks[a], (reach_x, reach_y), margins["covered"])
        xr, yr = _pair_ranges(boxes, [strips[int(face[i])] for i in on], tw_rad[on], res[on], cover)
        if not np.isfinite(xr[0]):
            continue
        center, half = _box_args(tuple(xr), tuple(yr))
        p = _PairBox(
            scene,
            masks,
            data,
            (a, b, ax),
            prof,
            twists,
            extent,
            center,
            half,
            backend,
            chunk,
            spaces,
            shadow=shadow,
        )
        # the stored box: the ranges asked for, within the part's correlation box
        oy, ox = p.offset(grid)
        gx = grid.x_first_px + ox
        gy = grid.y_first_px + oy
        cx0 = max(0, int(math.floor(xr[0])) - gx)
        cx1 = min(p.shape[1], int(math.ceil(xr[1])) - gx + 1)
        cy0 = max(0, int(math.floor(yr[0])) - gy)
        cy1 = min(p.shape[0], int(math.ceil(yr[1])) - gy + 1)
        if cx1 <= cx0 or cy1 <= cy0:
            continue
        pair_parts.append((a, b, ax, p, (cy0, cy1, cx0, cx1), on))
    near = {a for a, *_ in pair_parts}
    # A pattern that a quarter or half turn takes onto itself (a four-pad's pads, a square
    # pad's pairs) under a chip it leaves unchanged: a pad's planes are another's turned,
    # where the chip's rasters are the same turned at every twist of a chunk (checked there,
    # to their round-off; the sides, parts and cover exactly) - a quarter of the transforms
    # for a four-pad under a square chip.
    turns = _pattern_turns(masks, data, grid)
    # pad k: the (pad j < k, m) it is the turn of (a chunk takes the first its rasters fit:
    # a rectangular chip fits a half turn only)
    pad_from: dict[int, list[tuple[int, int]]] = {}
    for m, image in turns.items():
        for j, k in enumerate(image):
            if j < k and (deep[k] or k in near) == (deep[j] or j in near):
                pad_from.setdefault(k, []).append((j, m))
    # each pad's box of the grid: every part's box and every source's turned (its planes,
    # flags and cover lie within, made or turned)
    pad_box = []
    for k, parts in enumerate(pads):
        boxes = [
            (oy, oy + h, ox, ox + w)
            for (oy, ox), (h, w) in ((p.offset(grid), p.shape) for p in parts.values())
        ]
        boxes += [_grid_box_turned(pad_box[j], m, grid.shape[1:]) for j, m in pad_from.get(k, [])]
        pad_box.append(
            (
                min(b[0] for b in boxes),
                max(b[1] for b in boxes),
                min(b[2] for b in boxes),
                max(b[3] for b in boxes),
            )
        )
    # pair j2: the (pair j1 < j2, m, mirror) it is made from (:func:`made_from`), the turns'
    # first
    pair_from: dict[int, list[tuple[int, int, bool]]] = {}
    stored = [
        (
            p.offset(grid)[0] + c[0],
            p.offset(grid)[0] + c[1],
            p.offset(grid)[1] + c[2],
            p.offset(grid)[1] + c[3],
        )
        for *_, p, c, _on in pair_parts
    ]
    index = {(a, b, ax): j for j, (a, b, ax, *_) in enumerate(pair_parts)}
    for j1, (a1, b1, ax1, _p, _c, on1) in enumerate(pair_parts):
        for m, image in turns.items():  # the pair this one turns onto, if it is a later one
            j2 = index.get((image[a1], image[b1], (ax1 - m) % 4))
            if (
                j2 is not None
                and j2 > j1
                and np.array_equal(on1, pair_parts[j2][5])
                and _grid_box_turned(stored[j1], m, grid.shape[1:]) == stored[j2]
            ):
                pair_from.setdefault(j2, []).append((j1, m, False))
    # Under the mirror y -> -y (a pattern symmetric about its x axis, a chip whose mirror
    # twins are exact), then a quarter turn or none: pair j2's planes at a twist are pair
    # j1's at the opposite twist upside down, turned, the twin in the same chunk.
    mirrored = _pattern_mirror(masks, data, grid) if twins else None
    if mirrored is not None:
        tw_key = np.round(twists_deg, 9)
        for j1, (a1, b1, ax1, _p, _c, on1) in enumerate(pair_parts):
            y0, y1, x0, x1 = stored[j1]
            flipped_box = (grid.shape[1] - y1, grid.shape[1] - y0, x0, x1)
            for m in (0, *turns):
                image = turns[m] if m else list(range(n))
                j2 = index.get((image[mirrored[a1]], image[mirrored[b1]], (-ax1 - m) % 4))
                if (
                    j2 is not None
                    and j2 > j1
                    and sorted(-tw_key[on1]) == sorted(tw_key[pair_parts[j2][5]])
                    and _grid_box_turned(flipped_box, m, grid.shape[1:]) == stored[j2]
                ):
                    pair_from.setdefault(j2, []).append((j1, m, True))

    def made_from(j, j1, m, mirror, r, at, sides_j, keep, pos, neg, covered, c1) -> bool:
        """Pair j's planes at the twists ``at`` (residual ``r``) made as pair j1's turned by
        ``m`` (0: not turned), at the same twists, or with ``mirror`` at the opposite ones
        (each entry's mirror twin, in this chunk) upside down first, where every input of
        pair j is pair j1's moved so: its chips (the strips turned, their sides shifted by
        ``c1`` as the turn shifts every side, a twin's the other way; a twin's raster is its
        partner's upside down), the near pad's cover ``keep`` and its part of the pattern.
        False (nothing made) where one is not."""
        a, b, ax = pair_parts[j][:3]
        a1, b1, ax1, p1, (dy0, dy1, dx0, dx1), _ = pair_parts[j1]
        face1, res1 = _faces(twists_deg, ax1)
        mates = at  # pair j1's entries read: the same, or each one's mirror twin
        if mirror:
            mates = []
            for _, _i, k, flipped in at:
                i2 = pos[k] if flipped else neg[k] if k < len(neg) else None
                if i2 is None or i2 not in pair_at[j1]:
                    return False
                mates.append((k if flipped else len(pos) + k, i2, k, not flipped))
            if len({float(res1[t[1]]) for t in mates}) != 1:
                return False
        r1 = float(res1[mates[0][1]])

        def moved(x: np.ndarray, image: bool = False) -> np.ndarray:
            """``x`` (pair j1's, y up; ``image``: rows down) as pair j's."""
            x = x[..., ::-1, :] if mirror else x
            return _turn_image(x, m) if image else _turn(x, m)

        oy1, ox1 = p1.offset(grid)
        gsl1 = (slice(oy1 + dy0, oy1 + dy1), slice(ox1 + dx0, ox1 + dx1))
        sides_1 = _pair_sides(mates, ax1, face1, pos)
        if not (
            all(
                s2 == (s1 + c1 if t[3] else s1 - c1) % 4
                for s1, s2, t in zip(sides_1, sides_j, at, strict=True)
            )
            and np.array_equal(moved(covered[a1][([t[0] for t in mates], *gsl1)]), keep)
            and np.array_equal(moved(shadow(a1, b1, ax1, r1), image=True), shadow(a, b, ax, r))
        ):
            return False
        for t, u in zip(at, mates, strict=True):
            pair_energy[j][pair_at[j][t[1]]] = moved(pair_energy[j1][pair_at[j1][u[1]]])
        return True

    n_t, ny_full, nx_full = grid.shape
    if not progress:
        fft_px = sum(math.prod(pp[nm].fft) for pp in pads for nm in margins) + sum(
            math.prod(p[3].fft) * len(p[5]) / n_t for p in pair_parts
        )
        wait_line(
            f"footprint planes: {n} pads, {len(pair_parts)} pairs, {n_t} twist{'s' if n_t != 1 else ''} x "
            f"{ny_full:,} x {nx_full:,} poses",
            n_t * fft_px / FFT_PX_PER_S,
        )
    shape = (n, *grid.shape)
    wet_energy = np.zeros(shape, scene.dtype)
    # the relay's flags packed a bit per pad (pad k in bit k % 8 of byte k // 8), as the
    # steppers read them: n / 4 bytes a pose for both instead of 2 n
    bits = (*grid.shape, -(-n // 8))
    reached, within = np.zeros(bits, np.uint8), np.zeros(bits, np.uint8)
    pair_energy = [
        np.zeros((len(on), c[1] - c[0], c[3] - c[2]), scene.dtype) for *_, c, on in pair_parts
    ]
    pair_at = [{int(i): k for k, i in enumerate(on)} for *_, on in pair_parts]
    scale = scene.delta_gamma_N_m * s**2 * UM2
    c_band = (rules.band_px - rules.f_inf) / STEP_PX
    w_in, w_out = 0.5 + c_band, 0.5 - c_band
    paired = set(twins) | set(twins.values())
    singles = [i for i in range(n_t) if i not in paired]
    groups = [(singles[k : k + chunk], []) for k in range(0, len(singles), chunk)]
    pairs = sorted(twins.items())
    groups += [
        ([a for a, _ in pairs[k : k + chunk]], [b for _, b in pairs[k : k + chunk]])
        for k in range(0, len(pairs), chunk)
    ]
    for pos, neg in groups:
        idx = pos + neg
        # the six footprints at each twist, the canvas's points on the chip found once
        turned = [rotate_footprints([rotators[nm] for nm in names], twists_deg[i]) for i in pos]
        raster = {nm: np.stack([t[j] for t in turned]) for j, nm in enumerate(names)}
        del turned
        zero = [i for i, t in enumerate(pos) if round(float(twists_deg[t]), 9) == 0]
        band = raster["band_in"] * w_in
        band += raster["band_out"] * w_out
        # which pads the chip covers at these twists, on the whole grid (the pairs read them)
        covered = np.zeros((n, len(idx), ny_full, nx_full), bool)
        # the turns that leave every footprint's raster at these twists as it is (to its
        # round-off; their mirror twins' then too)
        fits: dict[int, bool] = {}
        for m in sorted(turns):
            if m == 3 and 1 in fits:  # three quarter turns undo one
                fits[m] = fits[1]
            elif m == 2 and fits.get(1, False):  # two quarter turns
                fits[m] = True
            else:
                fits[m] = all(_same_turned(raster[nm], raster[nm], m) for nm in names)
        for k, parts in enumerate(pads):
            turned_from = next(((j, m) for j, m in pad_from.get(k, []) if fits[m]), None)
            if turned_from is not None:  # pad j's planes turned
                j, m = turned_from
                # on pad j's box (nothing of it is written beyond) and its turned image
                y0, y1, x0, x1 = pad_box[j]
                src = np.s_[y0:y1, x0:x1]
                ty0, ty1, tx0, tx1 = _grid_box_turned(pad_box[j], m, grid.shape[1:])
                dst = np.s_[ty0:ty1, tx0:tx1]
                shift_j, shift_k = np.uint8(j % 8), np.uint8(k % 8)
                for t in idx:
                    wet_energy[k][t][dst] = _turn(wet_energy[j][t][src], m)
                    for flags in (reached, within):
                        bits_j = (flags[t][src][..., j // 8] >> shift_j) & np.uint8(1)
                        flags[t][dst][..., k // 8] |= _turn(bits_j, m) << shift_k
                if deep[k] or k in near:
                    covered[k][(slice(None), *dst)] = _turn(covered[j][(slice(None), *src)], m)
                continue

            def put(nm: str, chips, sc: float, parts=parts, pos=pos, neg=neg, zero=zero):
                """The footprint ``nm``'s planes of pad k at these twists, and their slices."""
                p = parts[nm]
                oy, ox = p.offset(grid)
                sl = (slice(oy, oy + p.shape[0]), slice(ox, ox + p.shape[1]))
                return p.correlate(chips, pos, neg, sc, zero), sl

            we = wet_energy[k]
            e, sl = put("wall", raster["wall"], scale)
            we[(idx, *sl)] = e
            bit, byte = np.uint8(1 << (k % 8)), k // 8
            for nm, flags in (("reached", reached), ("within", within)):
                c, sl = put(nm, raster[nm], 1.0)
                at = (idx, *sl, byte)
                flags[at] = flags[at] | np.where(c >= TOUCH_PX2, bit, np.uint8(0))
            if not (deep[k] or k in near):
                continue
            c, sl = put("covered", raster["covered"], 1.0)
            covered[k][(slice(None), *sl)] = c >= TOUCH_PX2
            # a pad narrower than the band: its far edge would take from the bridged term
            if not deep[k]:
                continue
            # bridged = jp [N(b) - (b - F_inf) l(b)]: the band's two counts weighted, one
            # footprint; the wall term where the chip covers some of the pad (the wall's and
            # the covered count's boxes lie inside the band's, zero beyond them)
            bridged, sl = put("band", band, scale)
            np.copyto(bridged, we[(idx, *sl)], where=covered[k][(slice(None), *sl)])
            we[(idx, *sl)] = bridged
        if not pair_parts:
            continue
        # The shadow rule: N_b - f on the side of the chip facing the pair's axis, its part
        # of the near pad the one of each twist's residual.
        strip = 0.5 * (raster["band_in"] + raster["band_out"])
        strip -= raster["wall"]
        looked = [sides(twists_deg[i]) for i in pos]
        side_of, tie_of = np.stack([v[0] for v in looked]), np.stack([v[1] for v in looked])
        del looked
        # each turn's shift of the sides, where the rasters fit it (the strips then too)
        shifts = {m: _side_shift(side_of, tie_of, strip, m) if fits[m] else None for m in turns}
        for j, (a, _b, ax, p, (cy0, cy1, cx0, cx1), _) in enumerate(pair_parts):
            face, res = _faces(twists_deg, ax)
            # (position in idx, twist, the chip raster at that twist, upside down or not)
            todo = [(k, i, k, False) for k, i in enumerate(pos) if i in pair_at[j]]
            # the twins: the chip upside down, its sides upside down too (+y and -y swap)
            todo += [(len(pos) + k, i, k, True) for k, i in enumerate(neg) if i in pair_at[j]]
            oy, ox = p.offset(grid)
            gsl = (slice(oy + cy0, oy + cy1), slice(ox + cx0, ox + cx1))
            for r in sorted({float(res[i]) for _, i, _, _ in todo}):
                at = [t for t in todo if res[t[1]] == r]
                sides_j = _pair_sides(at, ax, face, pos)
                rows = [t[0] for t in at]
                # only where the near pad is covered and the far one on its bridged term
                keep = covered[a][(rows, *gsl)]
                # another pair's planes turned, where all it reads is that pair's turned,
                # or mirrored from the opposite twists (and turned)
                if any(
                    made_from(j, j1, m, mirror, r, at, sides_j, keep, pos, neg, covered, c1)
                    for j1, m, mirror in pair_from.get(j, [])
                    if (c1 := 0 if m == 0 else shifts[m]) is not None
                ):
                    continue
                chips = _pair_chips(at, sides_j, side_of, tie_of, strip)
                planes = p.part(r).correlate(chips, range(len(at)), [], scale)
                c = planes[:, cy0:cy1, cx0:cx1]
                c[~keep] = 0
                pair_energy[j][[pair_at[j][t[1]] for t in at]] = c
                p.keep(())  # one pair's part at a time: each is made again where needed
    template = Landscape(
        energy=wet_energy[0],
        grid=grid,
        delta_gamma=scene.delta_gamma_N_m,
        energy_scale_J=energy_scale_J(scene),
        meniscus_height_um=scene.meniscus_height_um,
        stats={"backend": pads[0]["wall"].cor.backend, "footprint_pairs": len(pair_parts)},
    )
    return FootprintPlanes(
        rules=rules,
        wet_energy=wet_energy,
        reached_bits=reached,
        within_bits=within,
        template=template,
        pad_area_um2=np.asarray(areas),
        pad_centre_um=np.asarray(centres),
        labels=labels,
        seconds=time.perf_counter() - t0,
        pairs=tuple(
            PairPlane(a, b, ax, p.offset(grid)[0] + c[0], p.offset(grid)[1] + c[2], e, on)
            for (a, b, ax, p, c, on), e in zip(pair_parts, pair_energy, strict=True)
        ),
    )
