"""Energies pose by pose, at the cost of the chip's outline: the path-cost engine.

``E(x, y, a) = scale * sum_{k,l} chip_a[k, l] * w[k + y + oy, l + x + ox]`` (the FFT
engine's correlation, :class:`simulator.landscape.Correlator`). A chip raster is 1 inside
and 0 outside, fractional only along its outline, so its row differences
``D[k, l] = chip[k, l] - chip[k, l - 1]`` (a zero column before and after each row) are
non-zero only along the outline. With the pattern's row prefix sums
``P[r, j] = sum_{i < j} w[r, i]`` (made once), summation by parts gives

    E = -scale * sum_{k,l} D[k, l] * P[k + y + oy, l + x + ox]

exactly (each chip row sums its D to 0, so any constant per pattern row cancels: beyond
the pattern's left end P is 0, beyond its right end the row total, and rows off the
pattern are 0). One pose costs one gather per non-zero of D, about four per outline pixel,
whatever the chip's area. The same holds for a meniscus footprint that is exactly 1 deep
inside and 0 beyond a band (the free contact lines' wall profile, clipped): D is then
non-zero over the band only. The K_h-blurred chip (pinned lines) is smooth everywhere
and a meniscus below one pixel blurs the pattern: those stay with the FFT engine
(:func:`path_engine_supported`).

:class:`PathEnergy` computes poses on demand, row by row (one read per outline step and
row, whatever the row's length), and keeps one run of computed columns per row and twist,
and the outlines of the twists it has used (a meniscus footprint at ``-t`` is taken from
the one at ``+t`` when the chip is mirror-symmetric, and a run has the next twist's made
ahead on a background thread: :meth:`PathEnergy.prefetch`),
so boxes that overlap pay for their shared poses once; :meth:`PathEnergy.box`
returns a :class:`~simulator.landscape.Landscape` on the same grid as
:func:`~simulator.landscape.build_landscape` gives for the same twists, centre and
half-width, so the steppers run on it unchanged. The energies equal the FFT engine's to
its round-off (well below the noise floor): the FFT rounds in the scene's dtype, this
engine sums in float64 and rounds once.
"""

from __future__ import annotations

import functools
import time
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
from shapely import affinity

from patterns.geometry import coverage_steps
from simulator.core import UM2
from simulator.landscape._build import _box, _check_energy_range, _extent, _grid_of, energy_scale_J
from simulator.landscape._pathband import (
    SEGMENT_PAD,
    Band,
    footprint_band,
    pattern_outline,
    windows,
)
from simulator.landscape._posegrid import PoseGrid
from simulator.landscape._rotation import ChipRotator, canvas_shape
from simulator.physics import CHIP_BLUR_MIN_PX
from simulator.scene import Scene


def path_engine_supported(scene: Scene) -> tuple[bool, str]:
    """(True, "") when :class:`PathEnergy` computes this scene's energies, else (False, why).

    Supported: chips whose raster (or meniscus footprint) is exactly 1 inside and 0 outside
    away from its outline: exact geometry, chip PNGs, the free contact lines' footprint.
    Not: the K_h-blurred chip (smooth everywhere, so not sparse) and a meniscus below one
    pixel (its blur is on the pattern's side)."""
    h_px = scene.meniscus_height_px
    if h_px > 0 and scene.wall_profile is None:
        if h_px >= CHIP_BLUR_MIN_PX:
            return False, "the K_h-blurred chip is smooth everywhere (not sparse)"
        return False, "a meniscus below one pixel blurs the pattern"
    if h_px > 0 and h_px < CHIP_BLUR_MIN_PX:
        return False, "a meniscus below one pixel blurs the pattern"
    return True, ""


@functools.cache
def _background() -> ThreadPoolExecutor:
    """The thread that makes footprints ahead of a run (:meth:`PathEnergy.prefetch`)."""
    return ThreadPoolExecutor(1, thread_name_prefix="selfalign-prefetch")


#: Share of the memory budget the outlines a run keeps may take (:meth:`PathEnergy.drop_outlines`):
#: a 4000 px chip's meniscus footprint takes about 12 MB, so the default budget keeps about 40,
#: enough for a run that turns through 45 degrees to find most twists' mirror twins kept.
OUTLINE_BUDGET_SHARE = 1 / 16


def _outline_bytes(o) -> int:
    """Bytes one twist's outline holds (its steps and, for a meniscus footprint, its band)
    besides its band's prefix sums (``band.flat``, which a mirror twin shares)."""
    n = o.rows.nbytes + o.cols.nbytes + o.vals.nbytes
    b = o.band
    if b is not None:
        n += 4 * b.seg_a.nbytes + 4 * b.row_count.nbytes
    return int(n)


#: Columns a row computes beyond the box on each side when it starts (twice that when it
#: is extended), and the gap beyond which a row's computed run is dropped and started anew.
ROW_AHEAD, ROW_GAP = 8, 64


class _Outline:
    """The non-zeros of one twist's row differences, sorted by row: rows and columns
    (pattern coordinates at pose 0) and values; with the free contact lines' footprint, those
    of its part G and its part B with the canvas's place at pose 0 (:mod:`._pathband`)."""

    __slots__ = ("rows", "cols", "vals", "nnz", "band", "offset", "shape")

    def __init__(self, rows, cols, vals, offset, shape, band: Band | None = None):
        self.rows, self.cols, self.vals = rows, cols, vals
        self.nnz = len(vals)
        self.offset, self.shape, self.band = offset, shape, band


def rows_to_compute(rows: dict, y0: int, ny: int, x0: int, nx: int) -> dict:
    """The runs of columns still to compute for the poses of rows ``y0 ..`` and columns
    ``x0 .. x0 + nx - 1`` px, given ``rows`` (row -> (first column, values) kept so far; a
    row kept too far from the box is dropped from it): (first column, count) -> rows, with
    :data:`ROW_AHEAD` columns more on each side of a new row and twice that beyond an end
    a kept row extends (:meth:`PathEnergy.plane`)."""
    x1 = x0 + nx - 1
    todo: dict[tuple[int, int], list[int]] = {}
    for y in range(y0, y0 + ny):
        have = rows.get(y)
        if have is not None:
            a, e = have
            b = a + len(e) - 1
            if x0 > b + ROW_GAP or x1 < a - ROW_GAP:  # far from the run kept: start afresh
                del rows[y]
                have = None
        if have is None:
            todo.setdefault((x0 - ROW_AHEAD, nx + 2 * ROW_AHEAD), []).append(y)
            continue
        if x0 < a:
            lo = min(x0, a - 2 * ROW_AHEAD)
            todo.setdefault((lo, a - lo), []).append(y)
        if x1 > b:
            hi = max(x1, b + 2 * ROW_AHEAD)
            todo.setdefault((b + 1, hi - b), []).append(y)
    return todo


def keep_rows(rows: dict, ys, xa: int, values) -> None:
    """Add the computed runs ``values`` (one per row of ``ys``, from column ``xa``) to the
    runs ``rows`` keeps (:func:`rows_to_compute` planned them at a kept run's ends)."""
    for y, v in zip(ys, values, strict=True):
        have = rows.get(y)
        if have is None:
            rows[y] = [xa, v]
        elif xa < have[0]:
            rows[y] = [xa, np.concatenate([v, have[1]])]
        else:
            have[1] = np.concatenate([have[1], v])


def read_rows(rows: dict, y0: int, ny: int, x0: int, nx: int, dtype) -> np.ndarray:
    """(ny, nx) of ``dtype``: the box of rows ``y0 ..`` and columns ``x0 ..`` from ``rows``."""
    out = np.empty((ny, nx), dtype)
    for i, y in enumerate(range(y0, y0 + ny)):
        a, e = rows[y]
        out[i] = e[x0 - a : x0 - a + nx]
    return out


class PathEnergy:
    """A scene's energies at any grid pose, computed on demand at the cost of the chip's
    outline (module docstring), and kept.

    Poses are integer px from the pattern centre (x, y) and twist-axis indices ``k``
    (0 .. count - 1; wrapped on a periodic axis by the caller)."""

    def __init__(self, scene: Scene):
        ok, why = path_engine_supported(scene)
        if not ok:
            raise ValueError(f"the path-cost engine does not cover this scene: {why}")
        _check_energy_range(scene)
        self.scene = scene
        self.axis = scene.twist_axis
        self._extent = _extent(scene)  # one pass over pattern and chip, shared by every box
        b = _box(scene, None, extent=self._extent)
        self.grid: PoseGrid = _grid_of(scene, b)
        self.origin = b["origin"]
        r0, r1, c0, c1 = b["crop"]
        self.margin = b["margin"]
        pat = np.asarray(scene.pattern.data[r0:r1, c0:c1][::-1], np.float64)
        hp, wp = pat.shape
        # Prefix sums along rows, one column more (the row total), one zero row more (rows off the pattern).
        self.P = np.zeros((hp + 1, wp + 1), np.float64)
        np.cumsum(pat, axis=1, out=self.P[:hp, 1:])
        self.T = self.P[
            :, wp
        ].copy()  # row totals (what a step beyond the right end reads), contiguous
        self.hp, self.wp = hp, wp
        # The free contact lines' footprint: its part B is summed on the pattern's side.
        self._pattern_steps = pattern_outline(pat) if scene.wall_profile is not None else None
        self.parity = (int((2 * self.origin[1]) % 2), int((2 * self.origin[0]) % 2))
        self.scale = scene.delta_gamma_N_m * scene.um_per_px**2 * UM2
        self.dtype = np.dtype(scene.dtype)
        h_px = scene.meniscus_height_px
        self.chip_blur = h_px if h_px >= CHIP_BLUR_MIN_PX else 0.0
        self._outlines: dict[int, _Outline] = {}
        self._cache: dict[
            int, dict[int, list]
        ] = {}  # twist index -> row y -> [first column, energies]
        self.energy_scale = energy_scale_J(scene)
        self.rg_px = scene.chip_rg_px
        self.poses = 0  # poses computed
        self.rotations = 0
        self.mirrored = 0  # footprints taken from their mirror twin's (_mirrored)
        self._twin_index: dict[float, int] | None = None
        self._pending: dict[int, Future] = {}  # twist index -> its outline, being made (prefetch)
        self.seconds = 0.0
        self.nnz_max = 0

    # -- the chip's outline at one twist
    def outline(self, k: int) -> _Outline:
        """The outline of twist index k: kept, made in the background (:meth:`prefetch`),
        from its mirror twin's, or made now."""
        o = self._outlines.get(k)
        if o is not None:
            self._outlines[k] = self._outlines.pop(k)  # most recently used last
            return o
        pending = self._pending.pop(k, None)
        if pending is not None:
            o = pending.result()
            self.rotations += 1
        else:
            tw = float(self.axis.values_at(np.asarray([k]))[0])
            o = self._mirrored(tw) if self.scene.wall_profile is not None else None
            if o is not None:
                self.mirrored += 1
            else:
                o = self._make_outline(tw)
                self.rotations += 1
        self._outlines[k] = o
        self.nnz_max = max(self.nnz_max, o.nnz)
        return o

    def prefetch(self, k: int) -> None:
        """Start making the free contact lines' footprint at twist index k in the background
        (the costly outline: a run calls this for the twist it is likely to need next, and
        works on the boxes it has meanwhile); nothing when it is kept, on its way, or its
        mirror twin's is kept (then it is made now, cheaply). The same values as made now."""
        if self.scene.wall_profile is None or k in self._outlines or k in self._pending:
            return
        tw = float(self.axis.values_at(np.asarray([k]))[0])
        o = self._mirrored(tw)
        if o is not None:
            self.mirrored += 1
            self._outlines[k] = o
            self.nnz_max = max(self.nnz_max, o.nnz)
            return
        self._pending[k] = _background().submit(self._make_outline, tw)

    def close(self) -> None:
        """Cancel the footprints not yet started in the background and wait for the one
        under way (a run calls this when it ends)."""
        for f in self._pending.values():
            f.cancel()
        for f in self._pending.values():
            if not f.cancelled():
                f.exception()
        self._pending.clear()

    def _make_outline(self, tw: float) -> _Outline:
        """The outline at twist ``tw`` (degrees), made: reads the scene, changes nothing here
        (it may run on a background thread, :meth:`prefetch`)."""
        rot = ChipRotator(
            self.scene.chip,
            np.asarray([tw]),
            self.parity,
            blur_px=self.chip_blur,
            margin_px=self.margin if self.chip_blur else 0,
            profile=self.scene.wall_profile,
        )
        hc, wc = rot.shape
        oy, ox = self.origin[1] - hc / 2, self.origin[0] - wc / 2
        assert oy == int(oy) and ox == int(ox), "pixel grids of chip and pattern must coincide"
        chip = self.scene.chip
        if self.scene.wall_profile is not None:
            # The free contact lines' footprint at the band's pixels only, split in G and B.
            r, c, v, band = footprint_band(rot, tw, self.dtype)
            order = np.argsort(r, kind="stable")
            o = _Outline(
                r[order].astype(np.int64) + int(oy),
                c[order].astype(np.int64) + int(ox),
                v[order],
                (int(oy), int(ox)),
                rot.shape,
                band,
            )
            return o
        if chip.geometry is not None and not self.chip_blur and self.scene.wall_profile is None:
            # Exact geometry: the raster's steps straight from the outline's pieces (the
            # rotator's raster, y down; never the whole canvas).
            g = chip.geometry if tw == 0 else affinity.rotate(chip.geometry, tw, origin=(0, 0))
            r, c, v = coverage_steps(g, chip.um_per_px, rot.shape, self.dtype)
            rows, cols, vals = [hc - 1 - r], [c], [v]
        else:
            # The FFT engine correlates the raster in the scene's dtype.
            img = np.asarray(rot(tw), self.dtype)
            rows, cols, vals = [], [], []
            for a in range(
                0, hc, 256
            ):  # row blocks: the difference never holds the whole raster twice
                blk = np.asarray(img[a : a + 256], np.float64)
                d = np.diff(blk, axis=1, prepend=0.0, append=0.0)
                r, c = np.nonzero(d)
                rows.append(r + a)
                cols.append(c)
                vals.append(d[r, c])
            del img
        r, c, v = (np.concatenate(a) for a in (rows, cols, vals))
        order = np.argsort(r, kind="stable")  # by row (_rows slices the rows on the pattern)
        o = _Outline(
            r[order].astype(np.int64) + int(oy),
            c[order].astype(np.int64) + int(ox),
            v[order],
            (int(oy), int(ox)),
            rot.shape,
        )
        return o

    def _mirrored(self, tw: float) -> _Outline | None:
        """The free contact lines' footprint at ``tw`` from the one at ``-tw`` when that is
        kept: for a chip mirror-symmetric about the x axis (exactly, from its polygon, as
        the FFT engine takes it) the footprint at ``-tw`` is the one at ``+tw`` upside down
        on the same canvas (the canvas's row ``k`` maps to the chip's ``(x, y)`` at one twist
        and to ``(x, -y)``, bit for bit, from row ``H - 1 - k`` at the other), as the FFT
        engine's mirror twins (:func:`simulator.landscape.mirror_twins`). None otherwise."""
        if not (self.axis.mirror and self.scene.chip.geometry is not None) or tw == 0:
            return None
        if self._twin_index is None:
            self._twin_index = {round(float(v), 9): j for j, v in enumerate(self.axis.values())}
        j = self._twin_index.get(round(-tw, 9))
        src = self._outlines.get(j) if j is not None else None
        if src is None or src.band is None:
            return None
        hc, wc = src.shape
        margin = self.margin if self.chip_blur else 0  # as outline() makes the rotator
        if canvas_shape(self.scene.chip, np.asarray([tw]), self.parity, margin) != (hc, wc):
            return None
        oy, ox = src.offset
        rows = (hc - 1 + 2 * oy) - src.rows  # canvas row k -> H - 1 - k, in pattern rows
        order = np.argsort(rows, kind="stable")  # rows ascending, each row's order kept
        b = src.band
        m = Band()
        m.shape = b.shape
        seg_row = hc - 1 - b.seg_row
        so = np.argsort(seg_row, kind="stable")
        m.seg_row, m.seg_a, m.seg_len, m.seg_off = (
            seg_row[so],
            b.seg_a[so],
            b.seg_len[so],
            b.seg_off[so],
        )
        m.flat = b.flat  # the segments' prefix sums, shared
        m.row_count = b.row_count[::-1].copy()
        m.row_first = np.concatenate([[0], np.cumsum(m.row_count)[:-1]])
        m.row_lo, m.row_hi = b.row_lo[::-1].copy(), b.row_hi[::-1].copy()
        m.sum_B = b.sum_B
        o = _Outline(rows[order], src.cols[order], src.vals[order], src.offset, src.shape, m)
        self.nnz_max = max(self.nnz_max, o.nnz)
        return o

    def drop_outlines(self, keep: set[int]) -> None:
        """Forget the outlines of twists not in ``keep``, the least recently used first, while
        they take more than :data:`OUTLINE_BUDGET_SHARE` of the memory budget (a meniscus
        footprint's are megabytes each; a run that turns back reuses those it kept)."""
        cap = self.scene.memory_budget_mb * 2**20 * OUTLINE_BUDGET_SHARE
        users: dict[int, int] = {}  # id of a band's prefix sums -> outlines that hold them
        total = 0
        for o in self._outlines.values():
            total += _outline_bytes(o)
            if o.band is not None:
                i = id(o.band.flat)
                users[i] = users.get(i, 0) + 1
                total += o.band.flat.nbytes if users[i] == 1 else 0
        for k in list(self._outlines):  # least recently used first
            if total <= cap:
                break
            if k not in keep:
                o = self._outlines.pop(k)
                total -= _outline_bytes(o)
                if o.band is not None:
                    users[id(o.band.flat)] -= 1
                    total -= o.band.flat.nbytes if users[id(o.band.flat)] == 0 else 0

    # -- energies
    def _rows(self, o: _Outline, ys: np.ndarray, x0: int, n: int, part=None) -> np.ndarray:
        """Correlation (unscaled, float64), shape (len(ys), n), at twist outline ``o``, the
        rows ``ys`` and the consecutive columns ``x0 .. x0 + n - 1``: for each step of the
        outline and each row, ``n`` consecutive prefix sums of one pattern row (a contiguous
        read; the cost is one memory access per step and row, almost whatever ``n``). Steps
        whose columns lie all beyond the pattern's right end read the row total, all before
        its left end nothing. No BLAS (a threaded BLAS call on a busy machine costs
        milliseconds for a few thousand products): einsum sums in float64. Long runs of
        columns are cut so that one gather (steps x columns) stays near 2 M values.
        ``part``: another pattern than the scene's, with the same attributes ``P``, ``T``,
        ``hp``, ``wp`` and ``_pattern_steps`` (the footprint state's pads,
        :mod:`simulator.landscape._pathfoot`)."""
        src = self if part is None else part
        cols = max(16, 2_000_000 // max(o.nnz, 1))
        if o.band is not None:
            cols = min(cols, SEGMENT_PAD)
        if n > cols:
            return np.concatenate(
                [self._rows(o, ys, x0 + i, min(cols, n - i), part) for i in range(0, n, cols)],
                axis=1,
            )
        out = np.zeros((len(ys), n))
        if len(ys) == 0 or n == 0:
            return out
        wp, hp = src.wp, src.hp
        flat = src.P.reshape(-1)
        lo = o.cols + x0
        hi = lo + (n - 1)
        inside = (lo >= 0) & (hi <= wp)
        right = ~inside & (lo >= wp)
        mixed = ~inside & ~right & (hi > 0)
        # Steps are sorted by row: the steps on the pattern's rows at row shift y are one slice.
        parts = []
        for m in (inside, right, mixed):
            i = np.flatnonzero(m)
            parts.append((o.rows[i], o.cols[i] + x0, o.vals[i]) if len(i) else None)
        win = windows(flat, n)
        cn = np.arange(n)
        for j, y in enumerate(ys.tolist()):
            acc = 0.0
            for kind, part in enumerate(parts):
                if part is None:
                    continue
                r, c, v = part
                a, b = np.searchsorted(r, (-y, hp - y))
                if a == b:
                    continue
                rr = (r[a:b] + y) * (wp + 1)
                if kind == 0:
                    acc = acc + np.einsum("sn,s->n", win[rr + c[a:b]], v[a:b])
                elif kind == 1:  # beyond the right end: the row total
                    acc = acc + np.einsum("s,s->", src.T[r[a:b] + y], v[a:b])
                else:
                    cc = np.clip(c[a:b, None] + cn, 0, wp)
                    acc = acc + np.einsum("sn,s->n", flat[rr[:, None] + cc], v[a:b])
            out[j] -= acc
            if o.band is not None:  # the footprint's part B, on the pattern's side
                assert src._pattern_steps is not None  # a band comes with free lines only
                out[j] += o.band.correlate(src._pattern_steps, y + o.offset[0], x0 + o.offset[1], n)
        return out

    def mass(self, k: int) -> float:
        """The sum of the chip raster (or its footprint) at twist index k, px^2: from its row
        differences, ``-sum D[k, l] l`` per row (each row's differences sum to 0)."""
        o = self.outline(k)
        m = -float(np.dot(o.vals, o.cols.astype(np.float64)))
        return m + (o.band.sum_B if o.band is not None else 0.0)

    def raster(self, k: int) -> tuple[np.ndarray, tuple[int, int]]:
        """(the chip raster or its footprint at twist index k on its own canvas, y up; the
        canvas's place at pose 0 in pattern coordinates (row, column)), from its row
        differences (for the global minimum's cell bound)."""
        o = self.outline(k)
        (oy, ox), (hc, wc) = o.offset, o.shape
        d = np.zeros((hc, wc + 1))
        np.add.at(d, (o.rows - oy, o.cols - ox), o.vals)
        img = np.cumsum(d, axis=1)[:, :wc]
        if o.band is not None:
            img += o.band.dense()
        return img, (oy, ox)

    def plane(self, k: int, y0: int, ny: int, x0: int, nx: int) -> np.ndarray:
        """Energies (J, the scene's dtype), shape (ny, nx), at twist index k, rows
        ``y0 .. y0 + ny - 1`` and columns ``x0 .. x0 + nx - 1`` px. Each row keeps one run of
        columns computed (extended at its ends as boxes move: a pose is computed once), and
        computes :data:`ROW_AHEAD` columns more on each side of a new row and twice that
        beyond an end it extends (a row's cost is one memory access per outline step,
        almost whatever its length, so a few columns more cost less than one more call);
        rows that need the same columns are computed together."""
        rows = self._cache.setdefault(k, {})
        todo = rows_to_compute(rows, y0, ny, x0, nx)
        if todo:
            t0 = time.perf_counter()
            o = self.outline(k)
            for (xa, n), ys in todo.items():
                e = np.multiply(self._rows(o, np.asarray(ys, np.int64), xa, n), self.scale).astype(
                    self.dtype
                )
                self.poses += e.size
                keep_rows(rows, ys, xa, e)
            self.seconds += time.perf_counter() - t0
        return read_rows(rows, y0, ny, x0, nx, self.dtype)

    def energies(self, k: int, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
        """Energies (J, the scene's dtype) at twist index k and integer poses (ys[i], xs[i]) px
        (the rectangle that holds them is computed)."""
        ys, xs = np.asarray(ys, np.int64).ravel(), np.asarray(xs, np.int64).ravel()
        if len(ys) == 0:
            return np.empty(0, self.dtype)
        y0, x0 = int(ys.min()), int(xs.min())
        pl = self.plane(k, y0, int(ys.max()) - y0 + 1, x0, int(xs.max()) - x0 + 1)
        return pl[ys - y0, xs - x0]

    def box(self, twist_idx, center_px: tuple[int, int], half_px: int):
        """The landscape at the consecutive axis twists ``twist_idx`` (a periodic axis may
        run past its end: wrapped) and the translations within ``half_px`` of
        ``center_px``: the grid :func:`~simulator.landscape.build_landscape` gives, the
        energies computed here."""
        from simulator.landscape._landscape import Landscape

        t0 = time.perf_counter()
        twist_idx = [int(j) for j in twist_idx]
        n = self.axis.count
        twists = self.axis.values_at(np.asarray([j % n for j in twist_idx]))
        b = _box(self.scene, twists, center_px, half_px, extent=self._extent)
        g = _grid_of(self.scene, b)
        _, ny, nx = g.shape
        energy = np.empty(g.shape, self.dtype)
        poses0, s0 = self.poses, self.seconds
        for i, j in enumerate(twist_idx):
            energy[i] = self.plane(j % n, g.y_first_px, ny, g.x_first_px, nx)
        return Landscape(
            energy=energy,
            grid=g,
            delta_gamma=self.scene.delta_gamma_N_m,
            energy_scale_J=self.energy_scale,
            meniscus_height_um=self.scene.meniscus_height_um,
            stats={
                "rotations": 0,
                "mirrored_twists": 0,
                "copied_twists": 0,
                "seconds": time.perf_counter() - t0,
                "bytes": energy.nbytes,
                "backend": "path",
                "poses_computed": self.poses - poses0,
                "compute_s": self.seconds - s0,
            },
        )

    def nominal_boxes(self) -> list:
        """The nominal box of :func:`~simulator.landscape.global_minimum` (+-16 px, the
        twist steps around 0), pose by pose: landscapes of consecutive twists, for its
        ``evaluated``."""
        from simulator.landscape._landscape import NOMINAL_BALL_PX, NOMINAL_PX_PER_STEP
        from simulator.landscape._posegrid import consecutive_runs

        ax = self.axis
        n = ax.count
        k0 = int(np.argmin(np.abs(ax.values())))
        band = NOMINAL_BALL_PX // NOMINAL_PX_PER_STEP
        near = range(k0 - band, k0 + band + 1) if n > 1 else [0]
        idx = {j % n for j in near} if ax.periodic else {j for j in near if 0 <= j < n}
        return [self.box(run, (0, 0), NOMINAL_BALL_PX) for run in consecutive_runs(idx)]
