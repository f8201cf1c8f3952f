"""Exact anti-aliased rasterization: polygon -> float mask by area coverage.

Each pixel's value is the exact fraction of its area covered by the geometry
(signed-area accumulation over the polygon's edges, see :func:`_coverage`), so
``mask.sum() * um_per_px**2`` equals the polygon's area up to float round-off
whenever the geometry lies inside the canvas. Cost grows with the perimeter in
pixels plus one cumulative sum over the canvas (about 25 ms for a 912 x 912 px
canvas holding a rotated 730 px square).

Frame conventions are those of :class:`Mask` (``_mask``): the image centre is the
physical origin, row 0 is the top (largest y), x grows with the column.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely import affinity
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from foundation import InputError, positive, price_raster
from patterns.geometry._mask import Mask


def canvas_shape(
    geometry: BaseGeometry, um_per_px: float, margin_um: float = 0.0
) -> tuple[int, int]:
    """Smallest even (H, W) in pixels, symmetric about the origin, holding geometry + margin."""
    s = positive("um_per_px", um_per_px, "um per px")
    if geometry.is_empty:
        raise InputError("geometry is empty; nothing to rasterize")
    xmin, ymin, xmax, ymax = geometry.bounds
    half_w = max(abs(xmin), abs(xmax)) + margin_um
    half_h = max(abs(ymin), abs(ymax)) + margin_um
    fw, fh = half_w / s, half_h / s
    if not (math.isfinite(fw) and math.isfinite(fh)) or max(fw, fh) > 2**31:
        raise InputError(
            f"the raster would be {2 * fw:.3g} x {2 * fh:.3g} px at {s:g} um/px, more than any machine holds; "
            "use a coarser scale (--resolution or --um-per-px) or a smaller chip/pattern"
        )
    # Round to whole pixels with a tolerance so that 365.0000000001 um stays 365 px.
    w = 2 * max(1, math.ceil(half_w / s - 1e-9))
    h = 2 * max(1, math.ceil(half_h / s - 1e-9))
    return h, w


def to_pixel_frame(
    geometry: BaseGeometry, um_per_px: float, shape: tuple[int, int]
) -> BaseGeometry:
    """Map physical coordinates (um, y up, origin at centre) to (column, row) pixel units."""
    h, w = shape
    s = float(um_per_px)
    return affinity.affine_transform(geometry, [1 / s, 0.0, 0.0, -1 / s, w / 2, h / 2])


def _directed_edges(geom_px: BaseGeometry) -> np.ndarray:
    """(n, 4) array of edges (x0, y0, x1, y1) of every ring, consistently oriented."""
    geom_px = shapely.orient_polygons(geom_px)
    rings = []
    for poly in shapely.get_parts(geom_px):
        rings.append(shapely.get_exterior_ring(poly))
        rings.extend(shapely.get_interior_ring(poly, range(shapely.get_num_interior_rings(poly))))
    segs = [np.concatenate([c[:-1], c[1:]], axis=1) for c in map(shapely.get_coordinates, rings)]
    return np.concatenate(segs) if segs else np.zeros((0, 4))


def _integer_crossings(a0: np.ndarray, a1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(edge index, parameter t, integer value k) of every crossing of a line a = k."""
    lo = np.floor(np.minimum(a0, a1)) + 1
    hi = np.ceil(np.maximum(a0, a1)) - 1
    n = np.maximum(hi - lo + 1, 0).astype(np.int64)
    eid = np.repeat(np.arange(a0.size), n)
    k = lo[eid] + (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n))
    t = (k - a0[eid]) / (a1[eid] - a0[eid])  # n > 0 implies a1 != a0
    return eid, t, k


def _coverage(geom_px: BaseGeometry, shape: tuple[int, int]) -> np.ndarray:
    """Exact area coverage of pixels [c, c+1] x [r, r+1] by ``geom_px`` (pixel units).

    Signed-area accumulation (the scan-line method of exact font rasterizers): every
    edge is cut at each integer x and y, so each piece lies in one pixel. A piece
    with vertical extent dy adds dy * (fraction of its pixel to its right) to that
    pixel and dy to every pixel further right in its row; a cumulative sum along the
    row turns these increments into coverage. Exact for any polygon with holes.
    """
    h, w = shape
    r, c, here, dy = _pieces(geom_px, shape)
    # One canvas, summed in place: what a piece adds beyond the last column is never read.
    cov = np.zeros((h, w))
    np.add.at(cov, (r, c), here)
    right = c + 1 < w
    np.add.at(cov, (r[right], c[right] + 1), (dy - here)[right])
    np.cumsum(cov, axis=1, out=cov)
    # Orientation in the y-down pixel frame decides the overall sign.
    if cov.sum() < 0:
        np.abs(cov, out=cov)
    return np.clip(cov, 0.0, 1.0, out=cov)


def _pieces(
    geom_px: BaseGeometry, shape: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pieces of :func:`_coverage`: row, column, what the piece adds to its pixel, and
    its vertical extent (what it adds to every pixel further right)."""
    h, w = shape
    e = _directed_edges(geom_px)
    e = e[e[:, 1] != e[:, 3]]  # horizontal edges enclose no area in a row
    x0, y0, x1, y1 = e.T
    m = x0.size
    dx, dy_edge = x1 - x0, y1 - y0
    # Cut points: the ends, and every crossing of an integer x or y. A crossing's
    # integer coordinate is stored exactly, so pixel-aligned edges give exact pieces.
    ex, tx, kx = _integer_crossings(x0, x1)
    ey, ty, ky = _integer_crossings(y0, y1)
    eid = np.concatenate([np.arange(m), np.arange(m), ex, ey])
    t = np.concatenate([np.zeros(m), np.ones(m), tx, ty])
    px = np.concatenate([x0, x1, kx, x0[ey] + ty * dx[ey]])
    py = np.concatenate([y0, y1, y0[ex] + tx * dy_edge[ex], ky])
    order = np.lexsort((t, eid))
    eid, px, py = eid[order], px[order], py[order]
    same = eid[1:] == eid[:-1]
    xm = 0.5 * (px[:-1] + px[1:])[same]
    ym = 0.5 * (py[:-1] + py[1:])[same]
    dy = (py[1:] - py[:-1])[same]
    r, c = np.floor(ym).astype(np.int64), np.floor(xm).astype(np.int64)
    ok = (r >= 0) & (r < h) & (c < w) & (dy != 0)
    r, c, dy, xm = r[ok], c[ok], dy[ok], xm[ok]
    left = c < 0  # pieces left of the canvas cover their whole row
    here = np.where(left, dy, dy * (c + 1 - xm))
    c = np.maximum(c, 0)
    return r, c, here, dy


def coverage_steps(
    geometry: BaseGeometry,
    um_per_px: float,
    shape: tuple[int, int],
    dtype: np.typing.DTypeLike = np.float64,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The row differences of :func:`rasterize`'s raster (cast to ``dtype``), sparse, at the
    cost of the outline: ``(rows, cols, steps)`` with ``raster[r, c] - raster[r, c - 1]``
    (0 before column 0 and after the last, column ``W``), rows y-down. The raster's values
    between the steps are the running sums of the same pieces (equal to :func:`rasterize`'s
    to round-off); the whole canvas is never allocated."""
    h, w = int(shape[0]), int(shape[1])
    if geometry.is_empty:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    r, c, here, dy = _pieces(
        to_pixel_frame(geometry, positive("um_per_px", um_per_px, "um per px"), (h, w)), (h, w)
    )
    rows = np.concatenate([r, r])
    cols = np.concatenate([c, c + 1])
    inc = np.concatenate([here, dy - here])
    keep = cols < w
    rows, cols, inc = rows[keep], cols[keep], inc[keep]
    key = rows * (w + 1) + cols
    order = np.argsort(key, kind="stable")
    key, inc = key[order], inc[order]
    first = np.r_[True, key[1:] != key[:-1]]
    inc = np.add.reduceat(inc, np.flatnonzero(first)) if len(inc) else inc
    key = key[first]
    rows, cols = key // (w + 1), key % (w + 1)
    # Running sums within each row: the raster's value from each step to the next.
    start = np.r_[True, rows[1:] != rows[:-1]]
    total = np.cumsum(inc)
    seg = np.flatnonzero(start)
    first_of = np.repeat(seg, np.diff(np.r_[seg, len(inc)]))
    val = total - total[first_of] + inc[first_of]
    # Orientation: the sign of the raster's sum (each value holds up to the next step).
    nxt = np.r_[cols[1:], w]
    nxt = np.where(np.r_[~start[1:], False], nxt, w)
    if float(np.sum(val * (nxt - cols))) < 0:
        val = np.abs(val)
    val = np.clip(val, 0.0, 1.0).astype(dtype).astype(np.float64)
    prev = np.where(start, 0.0, np.r_[0.0, val[:-1]])
    last = np.r_[start[1:], True]
    rows = np.concatenate([rows, rows[last]])
    cols = np.concatenate([cols, np.full(int(last.sum()), w)])
    steps = np.concatenate([val - prev, -val[last]])
    nz = steps != 0
    return rows[nz], cols[nz], steps[nz]


def rasterize(
    geometry: BaseGeometry,
    um_per_px: float,
    shape: tuple[int, int] | None = None,
    margin_um: float = 0.0,
    budget_mb: float | None = None,
    what: str = "the raster",
) -> np.ndarray:
    """Area-coverage raster of ``geometry`` (um, centred) at ``um_per_px``.

    Args:
        geometry: shapely (Multi)Polygon in micrometres, origin at the nominal centre.
        um_per_px: pixel size in micrometres (> 0).
        shape: (H, W) of the canvas; default :func:`canvas_shape` (even, symmetric).
        margin_um: border added around the geometry when ``shape`` is None.
        budget_mb: memory budget (MiB) the raster must fit (default: the default budget);
            priced before anything is allocated (:func:`foundation.price_raster`).
        what: the raster's name in the refusal message.

    Returns:
        (H, W) float64 array in [0, 1]; row 0 at the top. Geometry outside the canvas
        is cut off.
    """
    s = positive("um_per_px", um_per_px, "um per px")
    if shape is None:
        shape = canvas_shape(geometry, s, margin_um)
    h, w = int(shape[0]), int(shape[1])
    if h < 1 or w < 1:
        raise InputError(f"canvas shape must be positive, got {shape}")
    price_raster((h, w), s, what, budget_mb)
    if geometry.is_empty:
        return np.zeros((h, w), dtype=np.float64)
    geom_px = to_pixel_frame(geometry, s, (h, w))
    rect = _rectangle(geom_px)
    if rect is not None:
        return _rectangle_coverage(rect, (h, w))
    return _coverage(geom_px, (h, w))


def _rectangle(geom: BaseGeometry) -> tuple[float, float, float, float] | None:
    """The bounds of ``geom`` when it is an axis-aligned rectangle (a polygon without holes
    whose vertices are all corners of its bounding box and whose area is the box's), else None."""
    if not isinstance(geom, Polygon) or len(geom.interiors):
        return None
    x0, y0, x1, y1 = geom.bounds
    xy = shapely.get_coordinates(geom.exterior)
    corners = np.isin(xy[:, 0], (x0, x1)).all() and np.isin(xy[:, 1], (y0, y1)).all()
    return (x0, y0, x1, y1) if corners and geom.area == (x1 - x0) * (y1 - y0) > 0 else None


def _rectangle_coverage(bounds: tuple[float, float, float, float], shape: tuple[int, int]):
    """Exact area coverage of pixels [c, c+1] x [r, r+1] by the rectangle ``bounds`` (pixel
    units): the product of the row's and the column's covered lengths, one pass over the
    canvas (:func:`_coverage` takes four for the same values, to round-off)."""
    x0, y0, x1, y1 = bounds
    h, w = shape
    cols, rows = np.arange(w + 1.0), np.arange(h + 1.0)
    cx = np.clip(np.minimum(x1, cols[1:]) - np.maximum(x0, cols[:-1]), 0.0, 1.0)
    cy = np.clip(np.minimum(y1, rows[1:]) - np.maximum(y0, rows[:-1]), 0.0, 1.0)
    return np.multiply.outer(cy, cx)


def mask_from_geometry(
    geometry: BaseGeometry,
    um_per_px: float,
    margin_um: float = 0.0,
    params: dict | None = None,
    shape: tuple[int, int] | None = None,
    budget_mb: float | None = None,
    what: str = "the raster",
) -> Mask:
    """Rasterize ``geometry`` into a :class:`Mask` that keeps the exact geometry."""
    data = rasterize(
        geometry, um_per_px, shape=shape, margin_um=margin_um, budget_mb=budget_mb, what=what
    )
    return Mask(data=data, um_per_px=um_per_px, geometry=geometry, params=dict(params or {}))
