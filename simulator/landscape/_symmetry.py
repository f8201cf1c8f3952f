"""The chip's symmetry, which saves transforms: chips that repeat or are each other's mirror
image (:func:`chip_relations`), the planes of a stack made with as few transforms as those
relations allow (:func:`correlate_planes`, the one symmetry-saving path of the build), and
the full correlation of a pattern with a stack of chips (:func:`correlate_stack`)."""

from __future__ import annotations

import numpy as np

from simulator.landscape._correlator import Correlator, Workspace
from simulator.landscape._fftsize import Window

#: Rasters equal to within this (per pixel) count as the same chip: rasters of a
#: symmetric chip one period apart, or mirror twins, differ by float round-off only.
SAME_CHIP_TOL = 1e-9


def chip_relations(chips: np.ndarray, tol: float = SAME_CHIP_TOL) -> list[tuple[int, bool]]:
    """For each chip i, ``(j, mirrored)``: chip i equals chip j <= i (``mirrored`` False;
    j == i for a chip seen first) or chip j upside down (``chips[j, ::-1]``, True).

    Candidates are found by hashing cheap row and column profiles (a row profile
    reverses under the mirror, a column profile over a mirror-symmetric set of rows does
    not change), then confirmed pixel by pixel within ``tol``; a near miss is just a new
    chip.
    """
    chips = np.asarray(chips)
    if not np.issubdtype(chips.dtype, np.floating):
        chips = chips.astype(np.float64)
    t, h, w = chips.shape
    if t == 0:
        return []
    # Both profiles over one mirror-symmetric set of rows, a quarter of the stack (a row
    # profile over every row read all of it: 0.12 s for 181 chips of 512 x 512 px).
    rows = np.unique(np.r_[np.arange(0, h, 8), h - 1 - np.arange(0, h, 8)])
    sub = chips[:, rows, :]
    row_prof = np.round(sub.sum(axis=2, dtype=np.float64), 6)
    col_prof = np.round(sub.sum(axis=1, dtype=np.float64), 6)
    tmp = np.empty((h, w), chips.dtype)

    def close(i: int, j: int, mirrored: bool) -> bool:
        """chips[i] == chips[j] (upside down if mirrored) within tol: the sampled rows first."""
        if np.abs(sub[i] - (sub[j, ::-1] if mirrored else sub[j])).max() > tol:
            return False
        np.subtract(chips[i], chips[j, ::-1] if mirrored else chips[j], out=tmp)
        return max(-float(tmp.min()), float(tmp.max())) <= tol

    # Every first chip under its profiles' key; a key can hold more than one (profiles
    # that agree on the sampled rows only), each then checked in turn.
    seen: dict[tuple[bytes, bytes], list[int]] = {}
    out: list[tuple[int, bool]] = []
    for i in range(t):
        cp = col_prof[i].tobytes()
        key = (row_prof[i].tobytes(), cp)
        twin_key = (row_prof[i, ::-1].tobytes(), cp)
        rel = next(((j, False) for j in seen.get(key, ()) if close(i, j, False)), None)
        if rel is None:
            rel = next(((j, True) for j in seen.get(twin_key, ()) if close(i, j, True)), None)
        if rel is None:
            seen.setdefault(key, []).append(i)
            rel = (i, False)
        out.append(rel)
    return out


def _run(idx: list[int], step: int) -> bool:
    """True if idx is a run of consecutive indices with this step (+1 or -1)."""
    return idx == list(range(idx[0], idx[0] + step * len(idx), step))


def _correlate_into(
    cor: Correlator,
    stack: np.ndarray,
    energy: np.ndarray,
    idx: list[int],
    scale: float,
    mirror_idx: list[int] | None = None,
    work: Workspace | None = None,
) -> None:
    """``cor(stack)`` into ``energy[idx]`` (and the chips' mirror images into
    ``energy[mirror_idx]``), straight into views of ``energy`` where the indices run
    consecutively (mirror indices descending), through a copy otherwise."""
    out = energy[idx[0] : idx[-1] + 1] if _run(idx, 1) else None
    mirror = None
    if mirror_idx is not None:
        mirror = (
            energy[mirror_idx[-1] : mirror_idx[0] + 1][::-1]
            if _run(mirror_idx, -1)
            else np.empty((len(idx),) + energy.shape[1:], energy.dtype)
        )
    res = cor(stack, out=out, scale=scale, mirror_out=mirror, work=work)
    if out is None:
        energy[idx] = res
    if mirror_idx is not None and not _run(mirror_idx, -1):
        energy[mirror_idx] = mirror


def correlate_planes(
    cor: Correlator,
    rasters,
    count: int,
    out: np.ndarray,
    scale: float,
    work: Workspace | None,
    chunk: int,
    twins: dict[int, int] | None = None,
    repeats: dict[int, int] | None = None,
    flip_rows: int | None = None,
    verify=None,
    progress=None,
    self_twins: tuple[int, ...] = (),
) -> tuple[int, int]:
    """Planes ``out[0:count]`` of a stack of chips, saving every transform their symmetry
    allows: the one symmetry-saving path of :func:`simulator.landscape.build_landscape` and
    :func:`correlate_stack`.

    Args:
        rasters: ``rasters(sel)`` -> the (len(sel), h, w) chips of planes ``sel``.
        twins: {i: j}: the chip of plane j is that of plane i upside down. Plane j comes
            from plane i's spectrum (``mirror_out``), or, with ``flip_rows``, is plane i
            upside down over its first ``flip_rows`` rows (the pattern is mirror-symmetric
            too and the window centred on y = 0): no transform at all.
        repeats: {j: i}: plane j equals plane i (a chip seen before), copied.
        self_twins: planes whose chip is its own mirror image (a mirror-symmetric chip at
            twist 0): with ``flip_rows`` they are mirror-symmetric too, and are made so
            exactly (the mean of the plane and its flip), so that a start on the mirror
            line stays on it (the transforms' round-off alone breaks the symmetry).
        verify: for chips whose twin relation is not exact by construction,
            ``verify(j, chip_i)`` -> the chip of plane j when it is *not* chip i upside
            down (that plane is then transformed directly), else None.
        progress: called with the number of planes done.

    Returns (planes from a twin's spectrum, planes copied upside down).
    """
    twins, repeats = twins or {}, repeats or {}
    paired = set(twins) | set(twins.values())
    singles = [i for i in range(count) if i not in paired and i not in repeats]
    pairs = sorted(twins.items())
    n_mirror = n_copied = 0
    for k in range(0, len(singles), chunk):
        sel = singles[k : k + chunk]
        _correlate_into(cor, rasters(sel), out, sel, scale, work=work)
        if progress:
            progress(len(sel))
    for k in range(0, len(pairs), chunk):
        sel = pairs[k : k + chunk]
        pos, neg = [a for a, _ in sel], [b for _, b in sel]
        stack = rasters(pos)
        if flip_rows is not None:
            _correlate_into(cor, stack, out, pos, scale, work=work)
            for a, b in sel:
                out[b, :flip_rows] = out[a, :flip_rows][::-1]
            n_copied += len(sel)
        else:
            _correlate_into(cor, stack, out, pos, scale, mirror_idx=neg, work=work)
            n_mirror += len(sel)
        if verify is not None:
            for b, img in zip(neg, stack, strict=True):
                direct = verify(b, img)
                if direct is not None:
                    cor(direct[None], out=out[b : b + 1], scale=scale, work=work)
                    if flip_rows is None:
                        n_mirror -= 1
                    else:
                        n_copied -= 1
        if progress:
            progress(2 * len(sel))
    if flip_rows is not None:
        for i in self_twins:
            plane = out[i, :flip_rows]
            plane += plane[::-1].copy()
            plane *= 0.5
    for j, i in repeats.items():
        out[j] = out[i]
    return n_mirror, n_copied


def correlate_stack(
    pattern: np.ndarray,
    chips: np.ndarray,
    dtype: str = "float32",
    backend: str = "auto",
    chunk: int = 8,
) -> np.ndarray:
    """Full linear cross-correlation of ``pattern`` (H, W) with each of ``chips`` (T, h, w).

    ``out[t, m + h - 1, n + w - 1] = sum_{k,l} chips[t, k, l] * pattern[k + m, l + n]``,
    i.e. what ``cv2.matchTemplate(TM_CCORR)`` gives on a pattern zero-padded by the chip
    size, for every shift.

    Symmetries save transforms (:func:`chip_relations`, equal within
    :data:`SAME_CHIP_TOL`): a chip that repeats (a symmetric chip one period apart) is
    not transformed again; a chip that is another upside down (a mirror-symmetric chip
    at -alpha and +alpha) gets its spectrum from its twin's; and when the pattern too is
    mirror-symmetric (rows), the twin's correlation is the other's upside down (no
    transform at all).
    """
    pattern, chips = np.asarray(pattern), np.asarray(chips)
    (hp, wp), (t, hc, wc) = pattern.shape, chips.shape
    # Window m in [-(hc - 1), hp - 1]: centre dy = (hp - hc)/2, half-width ry = (hp + hc)/2 - 1;
    # a zero row/column appended to the pattern makes both whole.
    py, px = (hp - hc) % 2, (wp - wc) % 2
    hq, wq = hp + py, wp + px
    win = Window(rx=(wq + wc) // 2 - 1, ry=(hq + hc) // 2 - 1, dx=(wq - wc) // 2, dy=(hq - hc) // 2)
    cor = Correlator(np.pad(pattern, ((0, py), (0, px))), (hc, wc), win, dtype, backend)
    rel = chip_relations(chips)
    twin = {}  # first chip -> a chip that is its mirror image
    for i, (j, mirrored) in enumerate(rel):
        if mirrored:
            twin.setdefault(j, i)
    pf = np.asarray(pattern, np.float64)
    pattern_mirror = bool(np.abs(pf - pf[::-1]).max() <= SAME_CHIP_TOL)
    # Every other chip repeats a first one, or its twin (the first upside down).
    repeats = {
        i: (twin[j] if mirrored else j)
        for i, (j, mirrored) in enumerate(rel)
        if i != j and twin.get(j) != i
    }
    out = np.empty((t, 2 * win.ry + 1, 2 * win.rx + 1), cor.dtype)
    work = cor.workspace(min(chunk, max(t, 1)), mirror=not pattern_mirror and bool(twin))
    H, W = hp + hc - 1, wp + wc - 1  # the full layout (a window of out)

    def rasters(sel: list[int]) -> np.ndarray:
        return chips[sel[0] : sel[-1] + 1] if _run(sel, 1) else chips[sel]

    correlate_planes(
        cor,
        rasters,
        t,
        out,
        1.0,
        work,
        chunk,
        twins=twin,
        repeats=repeats,
        flip_rows=H if pattern_mirror else None,
    )
    return out[:, :H, :W]
