"""The cell bound of the global-minimum search: upper bounds on the overlap of cells of poses.

Owns :class:`_Bounds`: for every cell of k x k translations at one twist, an upper bound
on the overlap of every pose in it (so a lower bound on its energy), from one
correlation of the pattern's k x k block sums with the chip's dilated block maxima,
and the absolute bound ``min(|P|, |C|)`` on the overlap of any pose; with its helpers
(:func:`_delta_gamma`, the scene's energy per unit overlap, and :func:`_pool`, block
reduction). :mod:`simulator.landscape` runs the search that prunes cells with it (step 3
of its docstring).
"""

from __future__ import annotations

import numpy as np

from simulator.core import UM2
from simulator.landscape._rotation import SMOOTH_ROTATE_BYTES_PER_PX
from simulator.scene import Scene

#: Canvas pixels per second of a footprint's rotation by splines (2 cores: 1.6e7 measured),
#: for the waiting lines only.
ROTATE_PX_PER_S = 1.5e7


# ----------------------------------------------------------------------------- the bound
class _Bounds:
    """Upper bounds on the overlap of every cell of k x k translations at one twist.

    The engine computes, for the chip raster c (y up) and the cropped pattern p
    (:func:`simulator.landscape.plan`), ``A(oy, ox) = sum_{i,j} c[i, j] p[i + oy, j + ox]``
    with ``(oy, ox)`` = translation + window offset. Pool the pattern into k x k block sums
    ``W[a, b]`` and the chip into block maxima ``Cm``. For every offset with
    ``floor(oy / k) = m`` (and likewise n), the chip rows that meet pattern block a lie in
    chip blocks a - m - 1 and a - m, so with ``Cd[a] = max(Cm[a], Cm[a - 1])`` (both axes)

        A(oy, ox) <= sum_{a,b} W[a, b] max_{(u,v) in block (a,b)} c[u - oy, v - ox]
                  <= sum_{a,b} W[a, b] Cd[a - m, b - n] =: U[m, n],

    one correlation of arrays k^2 times smaller than the landscape's. Values are in
    [0, 1] (the overlap model, and a meniscus's footprint), so every term is >= 0. A chip with exact geometry is
    rasterized at the block size (a block counts as 1 where the rotated outline, grown by
    1e-3 block, covers more than 1e-6 of it: the pixels the engine covers, but for slivers
    far below the noise floor); a chip image, and a meniscus's footprint, is
    rotated as the engine rotates it and max-pooled.
    """

    def __init__(self, scene: Scene, engine=None):
        from simulator.landscape._build import plan

        p = plan(scene, check_budget=False)  # prices the footprint before it is made
        self.scene = scene
        # A run's path-cost engine (simulator.landscape.PathEnergy): a footprint's mass and
        # rasters from its sparse form (the free contact lines': the band's pixels only).
        self.engine = engine if scene.wall_profile is not None else None
        self.pat = np.asarray(p.pattern_up, float)
        self.rot = p.rotator
        self.twists = p.twists
        # The chip at one twist on the whole canvas, its rotation's work space and its block
        # maxima; rotations are kept while they fit a quarter of the budget (_fine).
        hc, wc = self.rot.shape
        self._fine_bytes = hc * wc * 8
        budget = scene.memory_budget_mb * 2**20
        self.require_fits(scene, (hc, wc), self.footprint and self.engine is None)
        self._fine_keep = max(1, int(budget / 4 // self._fine_bytes))
        self._mass: dict[int, float] = {}
        w = p.window
        self.rx, self.ry, self.dx, self.dy = w.rx, w.ry, w.dx, w.dy
        self.ny, self.nx = 2 * w.ry + 1, 2 * w.rx + 1
        self.s = scene.um_per_px
        self.scale = _delta_gamma(scene) * self.s**2 * UM2  # J per px^2 of overlap (< 0)
        self._pat_blocks: dict[int, np.ndarray] = {}
        self._fine: dict[int, np.ndarray] = {}
        self._spectra: dict = {}

    @staticmethod
    def require_fits(scene: Scene, canvas: tuple[int, int], footprint: bool) -> None:
        """InputError unless the bound's least memory fits the budget: the chip at one twist
        on its ``canvas`` (with a ``footprint``, its rotation's work space), its block maxima
        and the pooling's copy."""
        from foundation import require_fits

        hc, wc = canvas
        require_fits(
            f"the global minimum's bound ({hc:,} x {wc:,} px chip canvas at {scene.um_per_px:g} um/px)",
            hc * wc * 8 * 3 + (hc * wc * SMOOTH_ROTATE_BYTES_PER_PX if footprint else 0),
            "use a coarser scale (--resolution)",
            scene.memory_budget_mb,
        )

    @staticmethod
    def covers_meniscus(scene: Scene) -> bool:
        """Whether the bounds hold for the scene's meniscus: from one pixel of height up the
        meniscus is all on the chip's side (its footprint, in [0, 1]); below, the pattern is
        blurred in the correlation and the pattern's block sums do not bound it."""
        from simulator.physics import CHIP_BLUR_MIN_PX

        return scene.meniscus_height_px >= CHIP_BLUR_MIN_PX

    @property
    def footprint(self) -> bool:
        """The chip side is a smooth footprint (a finite meniscus), not the chip's raster."""
        return self.rot.profile is not None or self.rot.blur_px > 0

    def absolute_px(self) -> float:
        """The largest overlap any pose can have, min(|P|, |C|) in px^2 (with a margin); with
        a meniscus |C| is the footprint's mass (the chip's area and the liquid beyond it)."""
        c = self.scene.chip
        pat = float(self.pat.sum())
        if c.geometry is not None and not self.footprint:
            chip = max(float(c.data.sum()), c.geometry.area / self.s**2)
        else:
            # min(|P|, max over twists of the footprint's mass): |P| as soon as one twist's
            # mass reaches it (the twist nearest 0 first), without rotating the chip to the others.
            chip = 0.0
            for j in np.argsort(np.abs(self.twists), kind="stable"):
                chip = max(chip, self.mass(int(j)))
                if chip >= pat:
                    break
        return min(pat, chip) * (1 + 1e-9)

    def seconds_per_twist(self, k: int) -> float:
        """A rough time of :meth:`cells` at one twist with k x k px cells (for the waiting
        lines): the chip rotated onto its canvas (a footprint by splines; exact geometry
        rasterized at the block size), and a correlation k^2 times smaller than the landscape's."""
        hc, wc = self.rot.shape
        rotate = hc * wc / (ROTATE_PX_PER_S if self.footprint else ROTATE_PX_PER_S * k * k)
        return rotate + (self.ny + hc) * (self.nx + wc) / (k * k) / 5e6

    def mass(self, j: int) -> float:
        """The footprint's (or the chip raster's) sum at twist j, px^2."""
        if j not in self._mass:
            if self.engine is not None:
                self._mass[j] = self.engine.mass(j)
            else:
                self._mass[j] = float(self.fine(j).sum())
        return self._mass[j]

    def perimeter_px(self) -> float:
        """The chip outline's length in px (exact geometry), or its raster's total variation."""
        c = self.scene.chip
        if c.geometry is not None:
            return float(c.geometry.length) / self.s
        d = c.data
        return float(np.abs(np.diff(d, axis=0)).sum() + np.abs(np.diff(d, axis=1)).sum())

    def fine(self, j: int) -> np.ndarray:
        """The chip (or its footprint) at twist j on the canvas; the latest rotations are kept
        while they fit a quarter of the memory budget (a 4000 px chip's canvas is 270 MB)."""
        if j in self._fine:
            self._fine[j] = self._fine.pop(j)  # most recently used last
            return self._fine[j]
        if self.engine is not None:  # the engine's canvas of this twist, centred on this one
            small, _ = self.engine.raster(j)
            img = np.zeros(self.rot.shape)
            (hc, wc), (h, w) = self.rot.shape, small.shape
            r0, c0 = (hc - h) // 2, (wc - w) // 2
            img[r0 : r0 + h, c0 : c0 + w] = small
        else:
            img = self.rot(float(self.twists[j]))
        while len(self._fine) >= self._fine_keep:
            self._fine.pop(next(iter(self._fine)))
        self._fine[j] = img
        return img

    def pattern_blocks(self, k: int) -> np.ndarray:
        if k not in self._pat_blocks:
            self._pat_blocks[k] = _pool(self.pat, k, np.sum)
        return self._pat_blocks[k]

    def chip_blocks(self, j: int, k: int) -> np.ndarray:
        """Cd: the chip's block maxima at twist j, dilated by one block (+1 row and column)."""
        c = self.scene.chip
        hc, wc = self.rot.shape
        if c.geometry is not None and not self.footprint:
            from shapely import affinity

            from patterns.geometry import rasterize

            t = float(self.twists[j])
            g = c.geometry if t == 0 else affinity.rotate(c.geometry, t, origin=(0, 0))
            hb, wb = -(-hc // k), -(-wc // k)
            # um -> block units (x right, y up, origin at the canvas corner) -> rasterize's frame
            a = 1.0 / (self.s * k)
            g = affinity.affine_transform(
                g, [a, 0.0, 0.0, a, wc / 2 / k - wb / 2, hc / 2 / k - hb / 2]
            ).buffer(1e-3, quad_segs=1)
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
        return (
            (self.dy - self.ry) // k,
            (self.dy + self.ry) // k,
            (self.dx - self.rx) // k,
            (self.dx + self.rx) // k,
        )

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


def _pool(a: np.ndarray, k: int, fn) -> np.ndarray:
    """k x k block reduction (sum or max) of ``a``, padded with zeros to whole blocks."""
    h, w = a.shape
    hb, wb = -(-h // k), -(-w // k)
    p = np.zeros((hb * k, wb * k))
    p[:h, :w] = a
    return fn(p.reshape(hb, k, wb, k), axis=(1, 3))
