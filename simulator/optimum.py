"""The global minimum of a scene's energy: the pose every command calls "aligned".

One rule in every command (``simulate``, ``montecarlo``, ``evaluate``, ``demo``): the
global minimum is the grid pose of lowest energy over the scene's whole pose grid, and
ties (energies within the noise floor of the lowest) are decided by position: the tie
nearest the nominal pose (0, 0, 0) wins (:meth:`simulator.landscape.Landscape.minimum_index`,
:func:`simulator.landscape.nominal_order`). Where the whole landscape is at hand
(``montecarlo``, ``evaluate``, the dynamics) it is read off it
(:func:`landscape_minimum`). A single greedy or gradient run builds only boxes of the
landscape; :func:`global_minimum` then finds the same pose without building the rest,
and proves it:

1. The boxes already built (the run's) and the nominal box (+-16 px, +-2 twist steps
   around (0, 0, 0)) are searched.
2. *Absolute bound.* If their lowest energy reaches the lowest any pose can have,
   ``-|Delta_gamma| min(|P|, |C|)`` (within the noise floor), and the tie nearest the
   nominal pose lies in the nominal box, no pose elsewhere can be lower or win a tie:
   done. This is the chip on its own pattern (pads inside the chip, or the chip inside
   a pad).
3. *Cell bounds.* Otherwise the pose grid is cut into cells of k x k translations at each
   twist, and the overlap of every pose in a cell is bounded from above by one small
   correlation (:meth:`_Bounds.cells`). A cell whose bound cannot come within the noise
   floor of the lowest energy found holds no better pose and no tie, and is dropped.
   The most promising cell left is computed exactly (lowering the energy to beat), the
   bound is refined (k / 4) over the cells left, and what is left at the end is
   computed exactly. So every pose that could be lower, or tie, has been computed.

Scenes the bound does not cover (a finite meniscus, whose energy is a blurred overlap;
a repulsive pad, Delta_gamma > 0) are searched over the whole landscape, built in chunks
of twists that fit the memory budget.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from simulator.landscape import (
    NOMINAL_BALL_PX,
    NOMINAL_PX_PER_STEP,
    Landscape,
    nominal_distance,
    nominal_order,
)
from simulator.materials import UM2
from simulator.scene import Scene

#: Target number of cells per axis of the first (coarsest) cell bound.
CELLS_PER_AXIS = 128
#: Cells left whose box (times its twists) holds at most this many poses are computed
#: exactly at once; larger sets are refined first (k / 4: 1/16 of the work per level).
EXACT_POSES = 20_000


@dataclass(frozen=True)
class GlobalMinimum:
    """The global minimum pose (x_um, y_um, twist_deg) and its energy (J).

    how: "landscape" (read off a landscape), "absolute bound", "cell bound" or "full
    landscape" (how :func:`global_minimum` proved it). poses: landscape poses computed to
    find it (beyond those it was given); seconds: the time it took.
    """

    x_um: float
    y_um: float
    twist_deg: float
    energy_J: float
    how: str = "landscape"
    poses: int = 0
    seconds: float = 0.0

    @property
    def pose(self) -> tuple[float, float, float]:
        return (self.x_um, self.y_um, self.twist_deg)


def landscape_minimum(ls: Landscape) -> GlobalMinimum:
    """The global minimum of ``ls`` (its own grid: the scene's when ``ls`` is the full landscape)."""
    return GlobalMinimum(*ls.global_minimum(), how="landscape")


def global_minimum(scene: Scene, landscape: Landscape | None = None, evaluated: tuple | list = (), backend: str = "auto") -> GlobalMinimum:
    """The global minimum of ``scene``'s energy over its whole pose grid.

    Args:
        scene: what to simulate.
        landscape: a landscape to read it off (its grid decides; pass the full landscape).
        evaluated: boxes of the scene's landscape already built (e.g. a trajectory's), reused.
        backend: as :func:`simulator.engine.build_landscape`.
    """
    if landscape is not None:
        return landscape_minimum(landscape)
    t0 = time.perf_counter()
    search = _Search(scene, backend)
    for ls in evaluated:
        search.add(ls, counted=False)
    how = search.run()
    x, y, t, e = search.best()
    return GlobalMinimum(x, y, t, e, how=how, poses=search.poses, seconds=time.perf_counter() - t0)


# ----------------------------------------------------------------------------- search
class _Piece:
    """A built box, reduced to its extent and its tie candidates (energies within the
    noise floor of its own lowest: a superset of its poses that tie the global minimum)."""

    def __init__(self, ls: Landscape, floor: float):
        e = ls.energy
        self.low = float(e.min())
        idx = np.flatnonzero(e <= self.low + floor)
        it, iy, ix = np.unravel_index(idx, e.shape)
        self.x, self.y, self.t, self.e = ls.x_um[ix], ls.y_um[iy], ls.twist_deg[it], e.reshape(-1)[idx].astype(float)
        s = ls.um_per_px
        self.rect = (ls.x_um[0] / s, ls.x_um[-1] / s, ls.y_um[0] / s, ls.y_um[-1] / s)
        self.twists = np.asarray(ls.twist_deg, float)


class _Search:
    def __init__(self, scene: Scene, backend: str):
        from simulator.engine import energy_scale_J
        from simulator.posegrid import axis_step, twist_axis

        self.scene, self.backend = scene, backend
        self.axis, self.wrap, self.period = twist_axis(scene)
        self.step = axis_step(self.axis)
        self.s = scene.um_per_px
        eps = np.finfo(scene.dtype).eps
        from simulator.correlator import NOISE_FACTOR

        self.floor = float(NOISE_FACTOR * eps * max(energy_scale_J(scene), np.finfo(float).tiny))
        self.pieces: list[_Piece] = []
        self.poses = 0

    # -- pieces
    def add(self, ls: Landscape, counted: bool = True) -> None:
        self.pieces.append(_Piece(ls, self.floor))
        _debug(f"piece {ls.energy.shape} at x {ls.x_um[0]:g}..{ls.x_um[-1]:g}, twists {ls.twist_deg[0]:g}..{ls.twist_deg[-1]:g}: low {self.pieces[-1].low:.6g}{'' if counted else ' (given)'}")
        if counted:
            self.poses += int(ls.energy.size)

    def build(self, twist_idx, center_px: tuple[int, int], half_px: int | None) -> None:
        """Build the box at the axis twists ``twist_idx`` in chunks that fit a quarter of the budget."""
        from simulator.engine import _box, build_landscape

        twist_idx = sorted({int(j) % len(self.axis) if self.wrap else int(j) for j in twist_idx if self.wrap or 0 <= j < len(self.axis)})
        if not twist_idx:
            return
        one = _box(self.scene, self.axis[twist_idx[:1]], center_px, half_px)["landscape_bytes"]
        chunk = max(1, int(self.scene.memory_budget_mb * 2**20 / 4 // max(one, 1)))
        for i in range(0, len(twist_idx), chunk):
            tw = self.axis[twist_idx[i : i + chunk]]
            self.add(build_landscape(self.scene, twists=tw, center_px=center_px, half_px=half_px, backend=self.backend))

    def low(self) -> float:
        return min(p.low for p in self.pieces)

    def best(self) -> tuple[float, float, float, float]:
        """The tie nearest the nominal pose among the poses within the floor of the lowest energy."""
        lo = self.low()
        parts = [(p.x, p.y, p.t, p.e) for p in self.pieces if p.low <= lo + self.floor]
        x, y, t, e = (np.concatenate(v) for v in zip(*parts, strict=True))
        keep = e <= lo + self.floor
        x, y, t, e = x[keep], y[keep], t[keep], e[keep]
        k = nominal_order(x, y, t, self.s, self.step, self.period)[0]
        return float(x[k]), float(y[k]), float(t[k]), float(e[k])

    def covered(self, j: int, x0, x1, y0, y1) -> np.ndarray:
        """Which px rectangles [x0, x1] x [y0, y1] (arrays) at axis twist j some piece holds."""
        tw = self.axis[j]
        out = np.zeros(np.shape(x0), bool)
        for p in self.pieces:
            d = p.twists - tw
            if self.wrap:
                d = np.mod(d + self.period / 2, self.period) - self.period / 2
            if not np.any(np.abs(d) <= 1e-6 * self.step):
                continue
            px0, px1, py0, py1 = p.rect
            out |= (px0 <= x0 + 1e-6) & (x1 <= px1 + 1e-6) & (py0 <= y0 + 1e-6) & (y1 <= py1 + 1e-6)
        return out

    # -- the search
    def run(self) -> str:
        scene = self.scene
        if getattr(scene.effects, "meniscus", False) or _delta_gamma(scene) >= 0:
            return self._full()
        n = len(self.axis)
        k0 = int(np.argmin(np.abs(self.axis)))
        band = NOMINAL_BALL_PX // NOMINAL_PX_PER_STEP
        near = list(range(k0 - band, k0 + band + 1)) if n > 1 else [0]
        h = NOMINAL_BALL_PX
        if not all(self.covered(j % n if self.wrap else j, -h, h, -h, h) for j in near if self.wrap or 0 <= j < n):
            self.build(near, (0, 0), h)  # the nominal box
        bounds = _Bounds(scene)
        x, y, t, e = self.best()
        r, _ = nominal_distance(x, y, t, self.s, self.step, self.period)
        # An axis longer than one symmetry period holds poses equivalent to those near 0
        # outside the nominal box, which could win a tie: the bound alone does not settle it.
        one_period = self.wrap or n == 1 or self.axis[-1] - self.axis[0] < self.period - 1e-9
        if one_period and r <= NOMINAL_BALL_PX and e <= bounds.scale * bounds.absolute_px() + self.floor:
            return "absolute bound"
        return self._cells(bounds)

    def _cells(self, b: _Bounds) -> str:
        n = len(self.axis)
        k = max(2, math.ceil(max(b.ny, b.nx) / CELLS_PER_AXIS))
        regions = {j: None for j in range(n)}  # twist index -> translations (x0, x1, y0, y1) px left (None: all)
        first = True
        while regions:
            cand = {j: b.cells(j, k, reg) for j, reg in regions.items()}
            # keep the cells that could hold a lower pose or a tie, and are not computed yet
            left = self._prune(cand, k, b)
            if not left:
                break
            j = min(left, key=lambda j: left[j][2].min())
            i = int(np.argmin(left[j][2]))
            # The most promising cell, computed exactly when it likely beats the best found so
            # far (its bound, less the bound's slack of about k px along the chip's outline,
            # still holds more overlap): the energy to beat drops, and most cells go.
            likely = left[j][2][i] / b.scale - k * b.perimeter_px() > self.low() / b.scale
            if first and likely:
                x0, x1, y0, y1 = (int(v) for v in b.cell_px(left[j][0][i], left[j][1][i], k))
                self.build(range(j - 2, j + 3) if n > 1 else [0], ((x0 + x1) // 2, (y0 + y1) // 2), (max(x1 - x0, y1 - y0) + 1) // 2 + 8)
                left = self._prune(left, k, b)
                if not left:
                    break
            first = False
            regions = {}
            for j, (mm, nn, _) in left.items():
                x0, x1, y0, y1 = b.cell_px(mm, nn, k)
                regions[j] = (int(x0.min()), int(x1.max()), int(y0.min()), int(y1.max()))
            union = _union(regions.values())
            poses = len(regions) * (union[1] - union[0] + 1) * (union[3] - union[2] + 1)
            _debug(f"level k={k}: {sum(len(v[0]) for v in left.values())} cells left at {len(left)} twists, {poses:,} poses to compute")
            if k <= 4 or poses <= EXACT_POSES:
                self._exact(regions)
                break
            k = max(2, k // 4)
        return "cell bound"

    def _prune(self, cand: dict, k: int, b: _Bounds) -> dict:
        beat = self.low() + self.floor
        left = {}
        for j, (mm, nn, lo_e) in cand.items():
            keep = lo_e <= beat
            if not keep.any():
                continue
            mm, nn, lo_e = mm[keep], nn[keep], lo_e[keep]
            x0, x1, y0, y1 = b.cell_px(mm, nn, k)
            keep = ~self.covered(j, x0, x1, y0, y1)
            if keep.any():
                left[j] = (mm[keep], nn[keep], lo_e[keep])
        return left

    def _exact(self, regions: dict) -> None:
        """Compute the cells left: one box over their union at the twists that have any, or,
        when that box would be more than twice their own, one box per twist."""
        def square(r):
            return (int(math.ceil(max(r[1] - r[0], r[3] - r[2]) / 2)) + 1) * 2 + 1

        union = _union(regions.values())
        if len(regions) * square(union) ** 2 <= 2 * sum(square(r) ** 2 for r in regions.values()):
            groups = [(sorted(regions), union)]
        else:
            groups = [([j], r) for j, r in sorted(regions.items())]
        for twists, (x0, x1, y0, y1) in groups:
            self.build(twists, ((x0 + x1) // 2, (y0 + y1) // 2), int(math.ceil(max(x1 - x0, y1 - y0) / 2)) + 1)

    def _full(self) -> str:
        self.build(range(len(self.axis)), (0, 0), None)
        return "full landscape"


# ----------------------------------------------------------------------------- the bound
class _Bounds:
    """Upper bounds on the overlap of every cell of k x k translations at one twist.

    The engine computes, for the chip raster c (y up) and the cropped pattern p
    (:func:`simulator.engine.plan`), ``A(oy, ox) = sum_{i,j} c[i, j] p[i + oy, j + ox]``
    with ``(oy, ox)`` = translation + window offset. Pool the pattern into k x k block sums
    ``W[a, b]`` and the chip into block maxima ``Cm``. For every offset with
    ``floor(oy / k) = m`` (and likewise n), the chip rows that meet pattern block a lie in
    chip blocks a - m - 1 and a - m, so with ``Cd[a] = max(Cm[a], Cm[a - 1])`` (both axes)

        A(oy, ox) <= sum_{a,b} W[a, b] max_{(u,v) in block (a,b)} c[u - oy, v - ox]
                  <= sum_{a,b} W[a, b] Cd[a - m, b - n] =: U[m, n],

    one correlation of arrays k^2 times smaller than the landscape's. Values are in
    [0, 1] (the overlap model), so every term is >= 0. A chip with exact geometry is
    rasterized at the block size (a block counts as 1 where the rotated outline, grown by
    1e-3 block, covers more than 1e-6 of it: the pixels the engine covers, but for slivers
    far below the noise floor); a chip image is
    rotated as the engine rotates it and max-pooled.
    """

    def __init__(self, scene: Scene):
        from simulator.engine import plan

        p = plan(scene, check_budget=False)
        self.scene = scene
        self.pat = np.asarray(p["pattern_up"], float)
        self.rot = p["rotator"]
        self.twists = p["twists"]
        w = p["window"]
        self.rx, self.ry, self.dx, self.dy = w.rx, w.ry, w.dx, w.dy
        self.ny, self.nx = 2 * w.ry + 1, 2 * w.rx + 1
        self.s = scene.um_per_px
        self.scale = _delta_gamma(scene) * self.s**2 * UM2  # J per px^2 of overlap (< 0)
        self._pat_blocks: dict[int, np.ndarray] = {}
        self._fine: dict[int, np.ndarray] = {}
        self._spectra: dict = {}

    def absolute_px(self) -> float:
        """The largest overlap any pose can have, min(|P|, |C|) in px^2 (with a margin)."""
        c = self.scene.chip
        if c.geometry is not None:
            chip = max(float(c.data.sum()), c.geometry.area / self.s**2)
        else:
            chip = max(float(self.fine(j).sum()) for j in range(len(self.twists)))
        return min(float(self.pat.sum()), chip) * (1 + 1e-9)

    def perimeter_px(self) -> float:
        """The chip outline's length in px (exact geometry), or its raster's total variation."""
        c = self.scene.chip
        if c.geometry is not None:
            return float(c.geometry.length) / self.s
        d = c.data
        return float(np.abs(np.diff(d, axis=0)).sum() + np.abs(np.diff(d, axis=1)).sum())

    def fine(self, j: int) -> np.ndarray:
        if j not in self._fine:
            self._fine[j] = self.rot(float(self.twists[j]))
        return self._fine[j]

    def pattern_blocks(self, k: int) -> np.ndarray:
        if k not in self._pat_blocks:
            self._pat_blocks[k] = _pool(self.pat, k, np.sum)
        return self._pat_blocks[k]

    def chip_blocks(self, j: int, k: int) -> np.ndarray:
        """Cd: the chip's block maxima at twist j, dilated by one block (+1 row and column)."""
        c = self.scene.chip
        hc, wc = self.rot.shape
        if c.geometry is not None:
            from shapely import affinity

            from patterns.raster import rasterize

            t = float(self.twists[j])
            g = c.geometry if t == 0 else affinity.rotate(c.geometry, t, origin=(0, 0))
            hb, wb = -(-hc // k), -(-wc // k)
            # um -> block units (x right, y up, origin at the canvas corner) -> rasterize's frame
            a = 1.0 / (self.s * k)
            g = affinity.affine_transform(g, [a, 0.0, 0.0, a, wc / 2 / k - wb / 2, hc / 2 / k - hb / 2]).buffer(1e-3, quad_segs=1)
            # Coverage > 1e-6 block: the raster's row sums leave round-off (1e-17) right of
            # every edge, which "> 0" would count. A block the outline meets has at least the
            # grown rim, so only blocks it touches with less than 1e-6 of a block are missed:
            # together under 1e-6 k^2 px^2 per block of outline, far below the noise floor.
            cm = (rasterize(g, 1.0, shape=(hb, wb))[::-1] > 1e-6).astype(float)
        else:
            cm = _pool(self.fine(j), k, np.max)
        cd = np.zeros((cm.shape[0] + 1, cm.shape[1] + 1))
        for da in (0, 1):
            for db in (0, 1):
                sl = cd[da : da + cm.shape[0], db : db + cm.shape[1]]
                np.maximum(sl, cm, out=sl)
        return cd

    def cell_range(self, k: int) -> tuple[int, int, int, int]:
        """Cells (m0, m1, n0, n1) that hold the window's offsets."""
        return ((self.dy - self.ry) // k, (self.dy + self.ry) // k, (self.dx - self.rx) // k, (self.dx + self.rx) // k)

    def cell_px(self, m, n, k: int):
        """Translations (x0, x1, y0, y1) in px that cells (m, n) hold, within the window."""
        m, n = np.asarray(m), np.asarray(n)
        y0 = np.maximum(k * m - self.dy, -self.ry)
        y1 = np.minimum(k * m + k - 1 - self.dy, self.ry)
        x0 = np.maximum(k * n - self.dx, -self.rx)
        x1 = np.minimum(k * n + k - 1 - self.dx, self.rx)
        return x0, x1, y0, y1

    def cells(self, j: int, k: int, region=None):
        """(m, n, lower energy bound) of every cell at twist j, or of those holding the
        translations of ``region`` = (x0, x1, y0, y1) px."""
        import scipy.fft as sfft

        m0, m1, n0, n1 = self.cell_range(k)
        if region is not None:
            x0, x1, y0, y1 = region
            m0, m1 = max(m0, (y0 + self.dy) // k), min(m1, (y1 + self.dy) // k)
            n0, n1 = max(n0, (x0 + self.dx) // k), min(n1, (x1 + self.dx) // k)
        cd = self.chip_blocks(j, k)
        hd, wd = cd.shape
        key = (k, m0, m1, n0, n1)
        if key not in self._spectra:  # the pattern side, shared by every twist of a level
            w = self.pattern_blocks(k)
            # W rows m0 .. m1 + hd - 1, columns n0 .. n1 + wd - 1 (zero outside the pattern)
            wc = np.zeros((m1 - m0 + hd, n1 - n0 + wd))
            ra, rb = max(m0, 0), min(m1 + hd, w.shape[0])
            ca, cb = max(n0, 0), min(n1 + wd, w.shape[1])
            if ra < rb and ca < cb:
                wc[ra - m0 : rb - m0, ca - n0 : cb - n0] = w[ra:rb, ca:cb]
            shape = (sfft.next_fast_len(wc.shape[0]), sfft.next_fast_len(wc.shape[1], real=True))
            self._spectra = {key: (sfft.rfft2(wc, s=shape), shape, float(wc.sum()))}
        spec, shape, total = self._spectra[key]
        # Valid correlation by a circular one of length >= len(W): no alias reaches it.
        full = sfft.irfft2(spec * sfft.rfft2(cd[::-1, ::-1], s=shape), s=shape)
        u = full[hd - 1 : hd + m1 - m0, wd - 1 : wd + n1 - n0]
        u = np.maximum(u, 0) + 1e-9 * total + 1e-9  # FFT round-off, bounded above
        mm, nn = np.meshgrid(np.arange(m0, m1 + 1), np.arange(n0, n1 + 1), indexing="ij")
        return mm.ravel(), nn.ravel(), (self.scale * u).ravel()


def _delta_gamma(scene: Scene) -> float:
    """The scene's energy per unit overlap (N/m), as the engine scales it."""
    return float(getattr(scene, "delta_gamma_N_m", scene.materials.delta_gamma_N_m))


def _union(rects) -> tuple[int, int, int, int]:
    """The bounding box (x0, x1, y0, y1) of rectangles (x0, x1, y0, y1)."""
    r = np.array(list(rects))
    return int(r[:, 0].min()), int(r[:, 1].max()), int(r[:, 2].min()), int(r[:, 3].max())


def _debug(text: str) -> None:
    import os
    import sys

    if os.environ.get("SELFALIGN_OPTIMUM_DEBUG"):
        print(f"optimum: {text}", file=sys.stderr)


def _pool(a: np.ndarray, k: int, fn) -> np.ndarray:
    """k x k block reduction (sum or max) of ``a``, padded with zeros to whole blocks."""
    h, w = a.shape
    hb, wb = -(-h // k), -(-w // k)
    p = np.zeros((hb * k, wb * k))
    p[:h, :w] = a
    return fn(p.reshape(hb, k, wb, k), axis=(1, 3))
