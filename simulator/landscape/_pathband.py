"""The free contact lines' footprint in the path-cost engine: one twist of it, split into a part
the chip's side sums and a part the pattern's side sums, each sparse.

The footprint F (:meth:`simulator.landscape.ChipRotator.profile_at`) is 1 deep inside the
chip, 0 beyond the pad reach, and varies across a band along the outline (signed distances
``lo <= s <= hi``, about ``d_p + 6`` px wide). Its row differences are non-zero over the whole
band: on a 4000 px chip with a 60 px band that is a million values, a million reads per pose.
Split F along each row's runs of band pixels (its *segments*)::

    G = 1 inside, the segment's mean c on each segment, 0 outside;   B = F - G.

G is constant along a row between the ends of the segments, so its row differences are
non-zero there only (two per segment), and the chip's side sums it as it sums a chip's
outline (:class:`simulator.landscape.PathEnergy`). B is non-zero on the segments only and sums
to 0 on each; summation by parts on the pattern's side gives

    sum_{k,l} B[k, l] w[k + Y, l + X] = - sum_{r,i} Dw[r, i] Q[r - Y, i - X],

with Dw the pattern's row differences (a zero column before and after each row: non-zero
along the pattern's outline) and ``Q[k, m] = sum_{l < m} B[k, l]``, which is 0 outside the
segments (each sums to 0). So a pose costs two reads per segment on the chip's side and one
read per pattern outline step that falls on a segment; the footprint is made at the band's
pixels only (found by tiles: :data:`TILE_PX`), never on the whole canvas. The values are
the FFT engine's: the same rotation (the rotator's own :meth:`profile_at`), cast to the
scene's dtype as the FFT engine correlates them.
"""

from __future__ import annotations

import functools
import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np

#: Side (px) of the tiles that find the band's pixels: a tile whose centre lies further than
#: its half-diagonal and :data:`TILE_SLACK_PX` from the band holds none of them.
TILE_PX = 16
#: Slack (px) of the tile test over the tile's half-diagonal: the nearest-pixel look-up of the
#: signed distance moves each point by up to 0.71 px, and the distance transform on pixel
#: centres is within a pixel of a 1-Lipschitz function.
TILE_SLACK_PX = 4.0
#: Zeros kept around each segment's prefix sums: the longest run of columns one read takes.
SEGMENT_PAD = 64


def windows(a: np.ndarray, n: int) -> np.ndarray:
    """The read-only view ``w[i] = a[i : i + n]`` of a contiguous 1-D array (NumPy's
    ``sliding_window_view``, without its checks: this is made at every row of poses)."""
    return np.lib.stride_tricks.as_strided(
        a, (a.size - n + 1, n), (a.itemsize, a.itemsize), writeable=False
    )


@functools.cache
def _pool(n: int) -> ThreadPoolExecutor:
    """The process's threads that find and evaluate a band's pixels (made once per count)."""
    return ThreadPoolExecutor(n, thread_name_prefix="selfalign-band")


class Band:
    """B = F - G of one twist (module docstring): its segments and their prefix sums.

    Canvas coordinates (rows y up, as the rotator's raster after ``[::-1]``). seg_row,
    seg_a, seg_len: each segment's row, first column and length; seg_off: where its
    ``Q[k, a]`` lies in ``flat`` (``Q[k, a + j]`` at ``seg_off + j``, :data:`SEGMENT_PAD`
    zeros before and after); row_first, row_count: each canvas row's first segment and
    how many; row_lo, row_hi: the columns its segments span."""

    __slots__ = (
        "shape",
        "seg_row",
        "seg_a",
        "seg_len",
        "seg_off",
        "flat",
        "row_first",
        "row_count",
        "row_lo",
        "row_hi",
        "sum_B",
    )

    def correlate(self, pattern: tuple, Y: int, X0: int, n: int) -> np.ndarray:
        """``- sum Dw[r, i] Q[r - Y, i - X]`` for X = X0 .. X0 + n - 1 (n <= SEGMENT_PAD):
        the pattern's outline steps (``pattern``: rows sorted, columns, values) that fall on
        a segment, found row by row of the canvas."""
        pr, pc, pv = pattern
        out = np.zeros(n)
        hc = self.shape[0]
        a, b = np.searchsorted(pr, (Y, Y + hc))
        if a == b:
            return out
        k = pr[a:b] - Y
        m_hi = pc[a:b] - X0
        m_lo = m_hi - (n - 1)
        hit = np.flatnonzero((m_hi > self.row_lo[k]) & (m_lo < self.row_hi[k]))
        if len(hit) == 0:
            return out
        k, m_lo, m_hi, v = k[hit], m_lo[hit], m_hi[hit], pv[a:b][hit]
        first, count = self.row_first[k], self.row_count[k]
        win = windows(self.flat, n)
        acc = np.zeros(n)
        for j in range(int(count.max())):
            s = first + np.minimum(j, count - 1)
            sa, sl = self.seg_a[s], self.seg_len[s]
            on = np.flatnonzero((j < count) & (m_hi > sa) & (m_lo < sa + sl))
            if len(on) == 0:
                continue
            s = s[on]
            start = self.seg_off[s] + np.clip(m_lo[on] - sa[on], -SEGMENT_PAD, sl[on] + 1)
            acc += np.einsum("sn,s->n", win[start], v[on])
        # The window runs over m = i - X ascending, so X descending.
        out -= acc[::-1]
        return out

    def dense(self) -> np.ndarray:
        """B on the whole canvas (for checks and the cell bound)."""
        out = np.zeros(self.shape)
        for s in range(len(self.seg_a)):
            q = self.flat[self.seg_off[s] : self.seg_off[s] + self.seg_len[s] + 1]
            a = self.seg_a[s]
            out[self.seg_row[s], a : a + self.seg_len[s]] = np.diff(q)
        return out


#: Candidate pixels (about) one task of :func:`footprint_band` takes: enough for NumPy and
#: SciPy to release the GIL for most of it, few enough to stay in the cache.
TASK_PX = 1 << 17


def _band_pixels(
    rot, inverse, lo: float, hi: float, cand: np.ndarray, tile_rows, hc: int, wc: int, values=None
):
    """(rows, columns, footprint) of the band's pixels in the candidate tiles (``cand``) of
    the tile rows ``tile_rows``, row-major (``values``: :func:`footprint_band`'s)."""
    t = TILE_PX
    rows, cols = [], []
    for r in tile_rows:
        c = (np.flatnonzero(cand[r])[:, None] * t + np.arange(t)).ravel()
        c = c[c < wc]
        k = np.arange(r * t, min(r * t + t, hc))
        rows.append(np.repeat(k, len(c)))
        cols.append(np.tile(c, len(k)))
    kk = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    ll = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    xi, yi = inverse(kk.astype(float), ll.astype(float))
    s = rot.distance_at(xi, yi)
    if values is not None:
        band = np.flatnonzero((s >= lo) & (s <= hi))
        f, keep = values(xi[band], yi[band], s[band])
        band = band[keep]
        return kk[band], ll[band], f[keep]
    band = np.flatnonzero((s >= lo) & (s <= hi))
    return kk[band], ll[band], rot.profile_at(xi[band], yi[band], s[band])


def _inverse(rot, twist_deg: float):
    """Canvas pixel (row k y up, column) -> the unrotated chip's coordinates (px, y up) at
    ``twist_deg``: the same arithmetic as the rotator's whole-canvas rotation."""
    hc, wc = rot.shape
    a = math.radians(twist_deg)
    ca, sa = math.cos(a), math.sin(a)
    cx, cy = wc / 2 - 0.5, hc / 2 - 0.5

    def inverse(k, col):
        x, y = col - cx, k - cy
        return x * ca + y * sa, -x * sa + y * ca

    return inverse


def footprint_band(
    rot, twist_deg: float, dtype, values=None, span=None, inside_value: float = 1.0
) -> tuple:
    """One twist of the free contact lines' footprint on the rotator's canvas, split (module
    docstring): (rows, cols, values) of G's row differences (canvas coordinates, y up; columns
    0 .. W, one beyond the last) and the :class:`Band` of B. The band's pixels are found
    and evaluated by tiles, tasks of about :data:`TASK_PX` candidate pixels on
    :func:`simulator.core.threads` threads (the same values whatever the count).

    Another footprint of the chip's signed distance (the footprint state's counts and
    corrections, :mod:`simulator.landscape._pathfoot`): ``values(xi, yi, s)`` gives (its
    values, which pixels to keep) at band pixels (unrotated chip coordinates, px; their
    signed distance), ``span`` the signed distances (lo, hi) of its band (default the
    rotator's), and ``inside_value`` what it is below ``lo`` (0 beyond ``hi``).

    :func:`band_samples` then :func:`band_outline`: a caller that splits one band's pixels
    into several footprints evaluates them once."""
    bk, bl, f = band_samples(rot, twist_deg, values, span)
    return band_outline(rot, twist_deg, bk, bl, f, dtype, span, inside_value)


def band_samples(rot, twist_deg: float, values=None, span=None) -> tuple:
    """(rows, columns, values) of the band's pixels at ``twist_deg``, row by row (canvas
    coordinates, y up): :func:`footprint_band`'s first half."""
    hc, wc = rot.shape
    lo, hi = rot.band_px if span is None else span
    inverse = _inverse(rot, twist_deg)
    # Tiles that may hold band pixels.
    t = TILE_PX
    kt = np.arange(-(-hc // t)) * t + (t - 1) / 2
    lt = np.arange(-(-wc // t)) * t + (t - 1) / 2
    s = rot.distance_at(*inverse(kt[:, None], lt[None, :]), box=False)
    reach = (t - 1) / 2 * math.sqrt(2) + TILE_SLACK_PX
    cand = (s + reach >= lo) & (s - reach <= hi)
    # Tasks: runs of tile rows of about TASK_PX candidate pixels each.
    per_row = cand.sum(axis=1) * t * t
    tile_rows = np.flatnonzero(per_row)
    edges = np.searchsorted(
        np.cumsum(per_row[tile_rows]), np.arange(1, 1 + per_row.sum() // TASK_PX) * TASK_PX
    )
    tasks = [r for r in np.split(tile_rows, np.unique(edges)) if len(r)]
    from simulator.core import threads

    n = min(threads(), len(tasks))
    if n > 1:
        parts = list(
            _pool(n).map(
                lambda rs: _band_pixels(rot, inverse, lo, hi, cand, rs, hc, wc, values), tasks
            )
        )
    else:
        parts = [_band_pixels(rot, inverse, lo, hi, cand, rs, hc, wc, values) for rs in tasks]
    if parts:
        bk, bl, f = (np.concatenate(v) for v in zip(*parts, strict=True))
    else:
        bk = bl = np.zeros(0, np.int64)
        f = np.zeros(0)
    return bk, bl, f


def band_outline(
    rot, twist_deg: float, bk, bl, f, dtype, span=None, inside_value: float = 1.0
) -> tuple:
    """:func:`footprint_band`'s second half: the row differences and the :class:`Band` of
    the band pixels (``bk``, ``bl``, row by row) whose values are ``f``."""
    hc, wc = rot.shape
    lo = (rot.band_px if span is None else span)[0]
    inverse = _inverse(rot, twist_deg)
    f = np.asarray(f.astype(dtype), np.float64)  # the FFT engine correlates the scene's dtype
    # Segments: runs of consecutive band columns in a row.
    nb = len(bk)
    brk = np.ones(nb, bool)
    if nb > 1:
        brk[1:] = (bk[1:] != bk[:-1]) | (bl[1:] != bl[:-1] + 1)
    start = np.flatnonzero(brk)
    seg_len = np.diff(np.append(start, nb))
    seg_row, seg_a = bk[start], bl[start]
    mean = np.add.reduceat(f, start) / seg_len if nb else np.zeros(0)

    # The pixels just before and after each segment: inside (G = 1) or outside (G = 0).
    def inside(k, col):
        if inside_value == 0.0:
            return np.zeros(len(k))
        on = (col >= 0) & (col < wc)
        x, y = inverse(k.astype(float), col.astype(float))
        return (on & (rot.distance_at(x, y) < lo)).astype(float)

    left, right = inside(seg_row, seg_a - 1), inside(seg_row, seg_a + seg_len)
    same_row = seg_row[1:] == seg_row[:-1]
    assert np.array_equal(right[:-1][same_row], left[1:][same_row]), (
        "the pixels between two segments of a row are all inside or all outside"
    )
    d_rows = np.stack([seg_row, seg_row], axis=1).ravel()
    d_cols = np.stack([seg_a, seg_a + seg_len], axis=1).ravel()
    d_vals = np.stack([mean - left, right - mean], axis=1).ravel()
    keep = d_vals != 0
    # B's prefix sums in each segment, SEGMENT_PAD zeros around each.
    b = f - np.repeat(mean, seg_len)
    cs = np.cumsum(b)
    before = np.concatenate([[0.0], cs])[start]
    seg_off = SEGMENT_PAD + np.concatenate([[0], np.cumsum(seg_len + 1 + SEGMENT_PAD)[:-1]])
    total = int(seg_off[-1] + seg_len[-1] + 1 + SEGMENT_PAD) if nb else SEGMENT_PAD
    flat = np.zeros(total)
    seg_id = np.repeat(np.arange(len(start)), seg_len)
    j = np.arange(nb) - start[seg_id]
    flat[seg_off[seg_id] + j + 1] = cs - before[seg_id]
    out = Band()
    out.shape = (hc, wc)
    out.seg_row, out.seg_a, out.seg_len, out.seg_off = seg_row, seg_a, seg_len, seg_off
    out.flat = flat
    count = np.bincount(seg_row, minlength=hc)
    out.row_count = count
    out.row_first = np.concatenate([[0], np.cumsum(count)[:-1]])
    big = np.iinfo(np.int64).max // 4
    out.row_lo = np.full(hc, big, np.int64)
    out.row_hi = np.full(hc, -big, np.int64)
    has = count > 0
    out.row_lo[has] = seg_a[out.row_first[has]]
    last = out.row_first[has] + count[has] - 1
    out.row_hi[has] = seg_a[last] + seg_len[last]
    out.sum_B = float(b.sum())
    return d_rows[keep], d_cols[keep], d_vals[keep], out


def pattern_outline(pat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, columns, values) of the pattern's row differences (a zero column before and
    after each row; columns 0 .. W), sorted by row: what :meth:`Band.correlate` reads."""
    rows, cols, vals = [], [], []
    for a in range(0, pat.shape[0], 256):
        blk = np.asarray(pat[a : a + 256], np.float64)
        d = np.diff(blk, axis=1, prepend=0.0, append=0.0)
        r, c = np.nonzero(d)
        rows.append(r + a)
        cols.append(c)
        vals.append(d[r, c])
    return (
        np.concatenate(rows).astype(np.int64),
        np.concatenate(cols).astype(np.int64),
        np.concatenate(vals),
    )
