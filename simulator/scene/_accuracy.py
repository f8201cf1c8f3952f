"""What accuracy costs: presets of the accuracy knobs, and feature-size guidance.

The landscape is a raster, so its accuracy is set by a few knobs: the pixel size
(``um_per_px``), the twist step (``twist_step_deg``) and the float type (``dtype``).
``benchmarks/accuracy.py`` measured each against exact polygon overlap
(:mod:`simulator.testing`) on a 2-core AMD EPYC: energy error in % of the chip area
(RMS / max over random poses), force error in % of the chip side x Delta_gamma
(90th percentile), landscape time relative to "balanced":

========  ==============================================  ===============  =========  ===========
preset    knobs                                           energy RMS/max   force p90  cost
========  ==============================================  ===============  =========  ===========
fast      pixel = feature / 2 in [1, 4] um, 2 deg          0.08 / 0.4 %     8 %        0.03-0.17 x
balanced  pixel = feature / 4 in [0.5, 1] um, 1 deg        0.015 / 0.1 %    3 %        1 x
precise   pixel = feature / 8 in [0.25, 0.5] um, 0.5 deg   0.004 / 0.05 %   1 %        9-13 x
========  ==============================================  ===============  =========  ===========

("feature" is the pattern's smallest feature, :func:`smallest_feature_um`; the pixel size
is rounded down to 1, 2, 2.5 or 5 x 10^k and kept in the range given. The bounds are
the worst measured over the sweep's patterns and the whole pattern library, with a
margin for pose sampling.) "balanced" is the default: 1 um/px, the scale of the source,
for every library pattern except the finest jagged ones. Greedy final poses matched the
exact greedy on the same grid in every measured case up to 4 um/px (at 8 um/px the final
twist was off by 2 degrees on the 200 um patterns). float64 doubled the cost and
changed no error (rasterization, not round-off, limits the accuracy), so every preset
uses float32. For the 730 um four-pad, "balanced" costs about 2-3 s and 0.55 GB per
landscape and "precise" about 30 s and 3.2 GB. For chips that large the twist step,
not the pixel, limits the accuracy (a 1 degree step moves the chip's corners by 9 um):
1 um/px with a 0.25 degree step measured 0.0007 % energy and 0.04 % force error at 5 x
the cost, so set the twist step explicitly there.

Presets never override a knob the user sets explicitly (:func:`apply_preset`).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import shapely
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from foundation import InputError, positive
from patterns.geometry import Mask
from simulator.core import REL_TOL

__all__ = [
    "DEFAULT_PRESET",
    "KNOBS",
    "PRESETS",
    "Preset",
    "apply_preset",
    "feature_sets_pixel",
    "feature_warning",
    "smallest_feature_um",
]


# --------------------------------------------------------------------- feature size
#: A vertex where the outline turns by more than this (degrees) is a corner.
CORNER_DEG = 15.0
#: The feature size is this quantile of the outline stretches (the shortest 10 % are
#: slivers where teeth are clipped at a pattern corner, or the ends of a jagged edge);
#: with 10 stretches or fewer it is the shortest.
QUANTILE = 0.10


def _geometry_of(pattern: Mask | BaseGeometry) -> tuple[BaseGeometry, float, float]:
    """(geometry, simplification tolerance, corner merge distance), um, of a geometry or mask."""
    if isinstance(pattern, BaseGeometry):
        if pattern.is_empty:
            raise InputError("pattern geometry is empty; nothing to measure")
        return pattern, 0.05, 0.1
    if not isinstance(pattern, Mask):
        raise InputError(
            f"expected a shapely geometry or a patterns.geometry.Mask, got {type(pattern).__name__}"
        )
    if pattern.geometry is not None:
        return pattern.geometry, 0.05, 0.1
    return _mask_outline(pattern), 0.5 * pattern.um_per_px, 1.5 * pattern.um_per_px


#: Peak bytes per outline vertex while a mask is outlined: the contour's float64 (row, col)
#: and (x, y) arrays, its shapely polygon (coordinates and GEOS's copy) and the parts and
#: simplified copy :func:`smallest_feature_um` makes of it.
OUTLINE_BYTES_PER_VERTEX = 160
#: Seconds per outline vertex (marching squares, one polygon each, their nesting and the
#: feature's measure), measured on a 2-core AMD EPYC (0.17 s for the 10,000 pads of a
#: 300 x 300 px image, 40,000 vertices), for the waiting line.
OUTLINE_S_PER_VERTEX = 5e-6


def _outline_vertices(data: np.ndarray) -> int:
    """The vertices the 0.5-level contours of ``data`` will have (one per pixel edge that
    crosses the level, the image's own border counted as dry), counted a row at a time."""
    n = 0
    step = max(1, 2**22 // max(1, data.shape[1]))
    prev = np.zeros(data.shape[1], bool)
    for r0 in range(0, data.shape[0], step):
        b = data[r0 : r0 + step] >= 0.5
        n += int(np.count_nonzero(b[:, 1:] != b[:, :-1]))
        n += int(np.count_nonzero(b[:, 0])) + int(np.count_nonzero(b[:, -1]))
        n += int(np.count_nonzero(b[0] != prev)) + int(np.count_nonzero(b[1:] != b[:-1]))
        prev = b[-1]
    return n + int(np.count_nonzero(prev))


def price_outline(mask: Mask, budget_mb: float | None = None) -> int:
    """The outline's vertices (:func:`_outline_vertices`); InputError when their polygons
    would not fit the memory budget (None: the default budget), and a waiting line on stderr
    when outlining them takes long (:func:`simulator.core.wait_line`)."""
    from foundation import require_fits, wait_line

    n = _outline_vertices(mask.data)
    h, w = mask.shape
    require_fits(
        f"the outline of the pattern ({w} x {h} px, {n:,} outline vertices) for its smallest feature",
        n * OUTLINE_BYTES_PER_VERTEX,
        "use a coarser --resolution or a pattern with fewer pads",
        budget_mb,
    )
    wait_line(
        f"outlining the pattern's {n:,} edge vertices for its smallest feature",
        n * OUTLINE_S_PER_VERTEX,
    )
    return n


def _mask_outline(mask: Mask, budget_mb: float | None = None) -> BaseGeometry:
    """Polygons along the 0.5 level of the mask (marching squares on pixel centres), in um.

    Nested outlines are holes and holes in holes are pads (the even-odd rule). The contours
    of the 0.5 level never cross nor touch (each crossing of a pixel edge belongs to one
    contour), so a contour's nesting depth is the number of contours around one of its
    vertices: one query of a tree of them, not a symmetric difference per contour (which
    grew with the square of the contours: 10,000 one-pixel pads took minutes). Each
    even-depth contour is a pad, with the contours one level deeper inside it as its holes.
    """
    from skimage import measure

    mask.require_nonempty("pattern")
    price_outline(mask, budget_mb)
    h, w = mask.shape
    s = mask.um_per_px
    d = mask.data
    # Every contour closes: pad with a dry border unless the image's own border is dry
    # (the usual case; a padded copy of a 16-megapixel pattern costs 128 MB).
    border_wet = max(d[0].max(), d[-1].max(), d[:, 0].max(), d[:, -1].max()) >= 0.5
    data, o = (np.pad(d, 1), 1) if border_wet else (d, 0)
    contours = [c for c in measure.find_contours(data, 0.5) if len(c) >= 4]
    if not contours:
        raise InputError("pattern: no outline at the 0.5 level; the mask has no pad a pixel wide")
    rc = np.concatenate(contours)
    xy = np.column_stack([(rc[:, 1] - o + 0.5 - w / 2) * s, (h / 2 - (rc[:, 0] - o) - 0.5) * s])
    ring_of = np.repeat(np.arange(len(contours)), [len(c) for c in contours])
    first = np.concatenate([[0], np.cumsum([len(c) for c in contours])[:-1]])
    # all contours at once (shapely's vectorised calls): one per contour took 0.2 ms each
    valid = shapely.make_valid(shapely.polygons(shapely.linearrings(xy, indices=ring_of)))
    parts, of = shapely.get_parts(valid, return_index=True)
    ok = (shapely.get_type_id(parts) == 3) & (shapely.area(parts) > 0)
    parts, of = parts[ok], of[ok]
    if not len(parts):
        raise InputError("pattern: no outline at the 0.5 level; the mask has no pad a pixel wide")
    if len(parts) == 1:
        return parts[0]
    # (point i, contour j): contour i's first vertex lies inside contour j (never its own)
    shells = cast("np.ndarray", shapely.polygons(shapely.get_exterior_ring(parts)))  # one per part
    tree = shapely.STRtree(shells)
    pi, pj = tree.query(shapely.points(xy[first[of]]), predicate="within")
    keep = pi != pj
    pi, pj = pi[keep], pj[keep]
    depth = np.bincount(pi, minlength=len(parts))
    direct = depth[pj] == depth[pi] - 1
    holes: dict[int, list] = {}
    for c, par in zip(pi[direct].tolist(), pj[direct].tolist(), strict=True):
        if depth[c] % 2 == 1:
            holes.setdefault(par, []).append(shapely.get_exterior_ring(parts[c]))
    pads = [
        Polygon(parts[i].exterior, [*parts[i].interiors, *holes[i]]) if i in holes else parts[i]
        for i in np.flatnonzero(depth % 2 == 0).tolist()
    ]
    return pads[0] if len(pads) == 1 else shapely.MultiPolygon(pads)


def _stretches(ring_xy: np.ndarray, corner_deg: float, merge: float) -> np.ndarray:
    """Outline lengths between consecutive corners of a closed ring (k + 1, 2).

    Corners closer than ``merge`` along the outline count as one (a tip cut flat).
    """
    p = ring_xy[:-1]
    seg = np.roll(p, -1, axis=0) - p  # segment i: vertex i -> i + 1
    length = np.hypot(seg[:, 0], seg[:, 1])
    keep = length > 0
    p, seg, length = p[keep], seg[keep], length[keep]
    prev = np.roll(seg, 1, axis=0)
    turn = np.degrees(
        np.abs(
            np.arctan2(prev[:, 0] * seg[:, 1] - prev[:, 1] * seg[:, 0], (prev * seg).sum(axis=1))
        )
    )
    corners = np.flatnonzero(turn > corner_deg)
    perimeter = length.sum()
    if len(corners) < 2:
        return np.array([perimeter / math.pi])  # no corners: a round shape, its diameter
    cum = np.concatenate([[0.0], np.cumsum(length)])
    at = cum[corners]  # outline position of each corner
    gaps = cast("np.ndarray", np.diff(np.concatenate([at, [at[0] + perimeter]])))  # floats
    long = gaps[gaps >= merge]
    return long if long.size else np.array([perimeter / math.pi])


#: Smallest features of the masks measured (by ``id``, dropped with the mask): a scene
#: asks for its pattern's up to three times (the preset, the warning, the pattern's check).
_FEATURE_OF_MASK: dict[int, float | str] = {}


def smallest_feature_um(pattern: Mask | BaseGeometry, corner_deg: float = CORNER_DEG) -> float:
    """The smallest feature of a pattern (um): its narrowest gap, pad, defect or tooth.

    What "feature" means here: the outline of every pad (and hole) is cut at its
    *corners*, the vertices where it turns by more than ``corner_deg`` (15 degrees);
    every straight or gently curved stretch between two corners is a feature of that
    length (a pad's side, a defect's flank, one flank of a jagged tooth), and so is every
    gap between two separate pads or between a hole and its pad's outline (their
    distance). A shape without corners (a circle) counts with its diameter
    (perimeter / pi). The result is the smallest of these, ignoring the shortest 2 % of
    the stretches (slivers where teeth are clipped at a pattern corner).

    Examples: a 200 um square gives 200; a 730/50 four-pad gives 50 (the gap);
    defect type A (h 10, w 20 um) gives 14.1 (its flank); random jaggedness with sigma
    2 um (pitch 8 um) gives about 4 (a tooth flank).

    Args:
        pattern: exact shapely geometry (um), or a :class:`~patterns.geometry.Mask`; a mask
            with ``geometry`` uses it, one without is outlined at its 0.5 level and
            simplified by half a pixel (features below about a pixel cannot be seen).
        corner_deg: turning angle above which an outline vertex is a corner.
    """
    if isinstance(pattern, Mask) and corner_deg == CORNER_DEG:
        key = id(pattern)
        if key not in _FEATURE_OF_MASK:
            try:
                _FEATURE_OF_MASK[key] = _smallest_feature_um(pattern, corner_deg)
            except InputError as err:
                _FEATURE_OF_MASK[key] = str(err)
            weakref.finalize(pattern, _FEATURE_OF_MASK.pop, key, None)
        got = _FEATURE_OF_MASK[key]
        if isinstance(got, str):
            raise InputError(got)
        return got
    return _smallest_feature_um(pattern, corner_deg)


def _simplified_parts(geom: BaseGeometry, tol: float) -> np.ndarray:
    """The polygons of ``geom``, each simplified by ``tol`` keeping its topology.

    One part at a time (vectorised): simplifying a geometry of 10,000 parts as one grew with
    the square of the parts (2 s for 10,000, 30 s for 40,000). Parts that simplified apart
    would touch or cross are simplified again together, as one geometry keeps them apart.
    """
    parts = shapely.get_parts(geom)
    simple = shapely.simplify(parts, tol, preserve_topology=True)
    if len(simple) < 2:
        return simple
    pi, pj = shapely.STRtree(simple).query(simple, predicate="intersects")
    clash = np.unique(np.concatenate([pi[pi != pj], pj[pi != pj]]))
    if clash.size:
        together = shapely.simplify(
            shapely.MultiPolygon(list(parts[clash])), tol, preserve_topology=True
        )
        keep = np.ones(len(simple), bool)
        keep[clash] = False
        simple = np.concatenate([simple[keep], shapely.get_parts(together)])
    return simple


#: Peak bytes per outline vertex of an exact geometry while its smallest feature is
#: measured: the simplified parts, their rings' coordinates and the per-vertex arrays of
#: :func:`_all_stretches` (float64 segments, lengths, turns, positions).
FEATURE_BYTES_PER_VERTEX = 200
#: Seconds per outline vertex of that measure (1 s per 100,000 polygons of four vertices, on
#: a 2-core AMD EPYC), for the waiting line.
FEATURE_S_PER_VERTEX = 2.5e-6


def _all_stretches(rings: np.ndarray, corner_deg: float, merge: float) -> np.ndarray:
    """:func:`_stretches` of every ring of ``rings`` (closed linear rings) at once, vectorised
    over their vertices (one Python call per ring took 0.3 ms: minutes for a million pads);
    the stretches of all rings, in no particular order."""
    xy = shapely.get_coordinates(rings)
    n = shapely.get_num_coordinates(rings) - 1  # closed: the last repeats the first
    ring_end = np.cumsum(n + 1)
    drop = ring_end - 1  # the repeated vertices
    keepv = np.ones(len(xy), bool)
    keepv[drop] = False
    p = xy[keepv]
    rid = np.repeat(np.arange(len(n)), n)
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    idx = np.arange(len(p))
    nxt = np.where(idx + 1 < (start + n)[rid], idx + 1, start[rid])
    seg = p[nxt] - p
    length = np.hypot(seg[:, 0], seg[:, 1])
    keep = length > 0
    seg, length, rid = seg[keep], length[keep], rid[keep]
    m = np.bincount(rid, minlength=len(n))
    start = np.concatenate([[0], np.cumsum(m)[:-1]])
    idx = np.arange(len(seg))
    prv = np.where(idx > start[rid], idx - 1, (start + m - 1)[rid])
    prev = seg[prv]
    cross = prev[:, 0] * seg[:, 1] - prev[:, 1] * seg[:, 0]
    turn = np.degrees(np.abs(np.arctan2(cross, (prev * seg).sum(axis=1))))
    perimeter = np.bincount(rid, weights=length, minlength=len(n))
    cum = np.cumsum(length) - length  # position of each vertex along all the rings before
    ring_at = np.zeros(len(n))
    ring_at[m > 0] = cum[start[m > 0]]
    at_all = cum - ring_at[rid]  # along its own ring
    corner = np.flatnonzero(turn > corner_deg)
    crid = rid[corner]
    at = at_all[corner]
    ncorner = np.bincount(crid, minlength=len(n))
    # the gap from each corner to the next of its ring (the last wraps to the first)
    first = np.concatenate([[0], np.cumsum(ncorner)[:-1]])
    nxt_c = np.arange(len(corner)) + 1
    last = nxt_c == (first + ncorner)[crid]
    nxt_c[last] = first[crid[last]]
    gaps = at[nxt_c] - at
    gaps[last] += perimeter[crid[last]]
    many = ncorner[crid] >= 2
    longg = many & (gaps >= merge)
    has_long = np.bincount(crid[longg], minlength=len(n)) > 0
    round_ = perimeter[(ncorner < 2) | ~has_long] / math.pi  # no corners, or none apart: round
    return np.concatenate([gaps[longg], round_])


#: The last exact geometries measured, with their features: a scene asks for its pattern's
#: feature more than once (the preset, the warning).
_FEATURE_OF_GEOMETRY: list[tuple[BaseGeometry, float, float | str]] = []


def _smallest_feature_um(pattern: Mask | BaseGeometry, corner_deg: float) -> float:
    if isinstance(pattern, Mask) and pattern.geometry is not None:
        pattern = pattern.geometry  # measured as its exact geometry (_geometry_of)
    if isinstance(pattern, BaseGeometry):
        for g, deg, got in _FEATURE_OF_GEOMETRY:
            # the same object, or an equal copy (a scene's pattern is rebuilt between the
            # preset and the warning): compared vertex by vertex, in C
            if deg == corner_deg and (
                g is pattern
                or (
                    g.bounds == pattern.bounds
                    and shapely.get_num_coordinates(g) == shapely.get_num_coordinates(pattern)
                    and shapely.equals_exact(g, pattern, 0.0)
                )
            ):
                if isinstance(got, str):
                    raise InputError(got)
                return got
        try:
            got = _measure(pattern, corner_deg)
        except InputError as err:
            got = str(err)
        _FEATURE_OF_GEOMETRY[:] = [*_FEATURE_OF_GEOMETRY[-3:], (pattern, corner_deg, got)]
        if isinstance(got, str):
            raise InputError(got)
        return got
    return _measure(pattern, corner_deg)


def _measure(pattern: Mask | BaseGeometry, corner_deg: float) -> float:
    from foundation import require_fits, wait_line

    geom, tol, merge = _geometry_of(pattern)
    vertices = int(shapely.get_num_coordinates(geom))
    require_fits(
        f"measuring the pattern's smallest feature ({vertices:,} outline vertices)",
        vertices * FEATURE_BYTES_PER_VERTEX,
        "use a coarser --resolution or a pattern with fewer pads",
    )
    wait_line(
        f"measuring the smallest feature of the pattern's {vertices:,} outline vertices",
        vertices * FEATURE_S_PER_VERTEX,
    )
    # Islands and holes smaller than merge^2 are noise (a mask's stray pixels).
    parts = _simplified_parts(geom, tol)
    parts = parts[shapely.area(parts) > merge**2]
    if not len(parts):
        raise InputError("pattern has no area to measure")
    rings = [shapely.get_exterior_ring(parts)]
    gaps: list[float] = []
    for i in np.flatnonzero(shapely.get_num_interior_rings(parts) > 0).tolist():
        part = parts[i]
        holes = [h for h in part.interiors if Polygon(h).area > merge**2]
        rings.append(np.array(holes, dtype=object))
        gaps += [part.exterior.distance(h) for h in holes]
    sizes = _all_stretches(np.concatenate(rings), corner_deg, merge)
    s = np.sort(sizes)
    feature = min([float(s[int(math.floor(QUANTILE * (len(s) - 1)))]), *gaps])
    if len(parts) > 1:
        # The gaps between parts: only those narrower than the feature so far can lower it, so
        # only the pairs within that distance are measured (a nearest-part query for every
        # part took 8 s for 90,000 pads on a grid, whose ties it could not prune).
        b = shapely.bounds(parts)
        near = shapely.box(
            b[:, 0] - feature, b[:, 1] - feature, b[:, 2] + feature, b[:, 3] + feature
        )
        i, j = shapely.STRtree(parts).query(near)  # boxes: candidates, measured below
        apart = i < j
        if apart.any():
            feature = min(feature, float(shapely.distance(parts[i[apart]], parts[j[apart]]).min()))
    return feature


def feature_warning(
    pattern: Mask | BaseGeometry, um_per_px: float, min_px: float = 3.0
) -> str | None:
    """A one-line warning when the pattern's smallest feature spans fewer than ``min_px`` pixels.

    Returns None when the scale resolves it. The warning names the feature size, its
    width in pixels and the pixel size that would resolve it (feature / min_px, rounded
    down to 1, 2, 2.5 or 5 x 10^k), as the CLI's ``--resolution`` flag. For an image read
    from a lossy format (``params["lossy_format"]``, :func:`patterns.read_mask`) it names the
    compression's speckle as the cause instead, with the fix (threshold, save as PNG).
    """
    s = positive("um_per_px", um_per_px, "um per px")
    need = positive("min_px", min_px, "px")
    f = smallest_feature_um(pattern)
    if f >= need * s * (1 - REL_TOL):
        return None
    lossy = pattern.params.get("lossy_format") if isinstance(pattern, Mask) else None
    if lossy:  # the compression's speckle, not a feature: a finer grid would only cost
        return (
            f"the pattern's smallest feature is {f:.3g} um, only {f / s:.2g} px at {s:g} um/px: "
            f"the speckle of its lossy {lossy} compression, not a feature of the drawing; threshold "
            "the image to black and white and save it as PNG (a finer --resolution would not help)"
        )
    return (
        f"the pattern's smallest feature is {f:.3g} um, only {f / s:.2g} px at {s:g} um/px; "
        f"use --resolution {_nice_down(f / need)} (um/px) or finer to resolve it with {need:g} px"
    )


def _nice_down(v: float) -> str:
    """The largest of 1, 2, 2.5, 5 x 10^k not above v, as text."""
    k = math.floor(math.log10(v))
    for m in (5, 2.5, 2, 1):
        if m * 10**k <= v * (1 + REL_TOL):
            return f"{m * 10**k:g}"
    return f"{10**k:g}"


# --------------------------------------------------------------------- presets
#: The knobs a preset sets, as keys of the dicts :func:`apply_preset` takes and returns.
KNOBS = ("um_per_px", "twist_step_deg", "dtype")
DEFAULT_PRESET = "balanced"


@dataclass(frozen=True)
class Preset:
    """Knob values of one accuracy preset, with what they were measured to give.

    Pixel size: ``feature / px_per_feature`` (the pattern's smallest feature,
    :func:`smallest_feature_um`, spans ``px_per_feature`` pixels), rounded down to
    1, 2, 2.5 or 5 x 10^k and clamped to [``min_um_per_px``, ``max_um_per_px``];
    ``max_um_per_px`` when the feature size is unknown.

    Measured (benchmarks/accuracy.py, worst case over its patterns): ``energy_rms_pct`` /
    ``energy_max_pct`` of the chip area (RMS / max), ``force_p90_pct`` of the chip side
    (x Delta_gamma; 90th percentile), at random poses against exact polygon overlap; ``cost`` is the landscape
    time relative to "balanced" (range over the patterns).
    """

    name: str
    px_per_feature: float
    max_um_per_px: float
    min_um_per_px: float
    twist_step_deg: float
    dtype: str
    energy_rms_pct: float
    energy_max_pct: float
    force_p90_pct: float
    cost: tuple[float, float]
    summary: str

    def knobs(
        self, feature_um: float | None = None, native_um_per_px: float | None = None
    ) -> dict[str, Any]:
        """The knob values for a pattern with this smallest feature (um), if known."""
        s = self.max_um_per_px
        if feature_um is not None:
            f = positive("feature_um", feature_um, "um")
            s = min(s, max(self.min_um_per_px, float(_nice_down(f / self.px_per_feature))))
        if native_um_per_px is not None:  # an image has no detail finer than its pixels
            s = max(s, positive("native_um_per_px", native_um_per_px, "um per px"))
        return {"um_per_px": s, "twist_step_deg": self.twist_step_deg, "dtype": self.dtype}

    def uses_feature(self, native_um_per_px: float | None = None) -> bool:
        """Whether the pixel size :meth:`knobs` gives depends on the smallest feature: not
        for an image whose own pixels are at least the preset's largest
        (``native_um_per_px >= max_um_per_px``), which :meth:`knobs` keeps whatever the
        feature."""
        return native_um_per_px is None or native_um_per_px < self.max_um_per_px

    def _cost_text(self) -> str:
        lo, hi = self.cost
        return f"{lo:.2g}" if lo == hi else f"{lo:.2g}-{hi:.2g}"

    def describe(self) -> str:
        return (
            f"{self.name}: {self.summary}; energy error <= {self.energy_rms_pct:.2g} % RMS ({self.energy_max_pct:.2g} % max) "
            f"of the chip area, force error <= {self.force_p90_pct:.2g} % of the chip side (90th percentile); "
            f"landscape cost {self._cost_text()} x balanced"
        )


PRESETS: dict[str, Preset] = {
    "fast": Preset(
        "fast",
        px_per_feature=2.0,
        max_um_per_px=4.0,
        min_um_per_px=1.0,
        twist_step_deg=2.0,
        dtype="float32",
        energy_rms_pct=0.08,
        energy_max_pct=0.4,
        force_p90_pct=8.0,
        cost=(0.03, 0.17),
        summary="pixel = smallest feature / 2 (1 to 4 um/px), 2 degree twist step, float32",
    ),
    "balanced": Preset(
        "balanced",
        px_per_feature=4.0,
        max_um_per_px=1.0,
        min_um_per_px=0.5,
        twist_step_deg=1.0,
        dtype="float32",
        energy_rms_pct=0.015,
        energy_max_pct=0.1,
        force_p90_pct=3.0,
        cost=(1.0, 1.0),
        summary="pixel = smallest feature / 4 (0.5 to 1 um/px), 1 degree twist step, float32",
    ),
    "precise": Preset(
        "precise",
        px_per_feature=8.0,
        max_um_per_px=0.5,
        min_um_per_px=0.25,
        twist_step_deg=0.5,
        dtype="float32",
        energy_rms_pct=0.004,
        energy_max_pct=0.05,
        force_p90_pct=1.0,
        cost=(9.0, 13.0),
        summary="pixel = smallest feature / 8 (0.25 to 0.5 um/px), 0.5 degree twist step, float32",
    ),
}


def feature_sets_pixel(name: str | None, native_um_per_px: float | None = None) -> bool:
    """Whether preset ``name`` (None: :data:`DEFAULT_PRESET`) needs the pattern's smallest
    feature to choose the pixel size (:meth:`Preset.uses_feature`): a scene measures it
    (outlining the whole pattern image, 0.3 s for 16 megapixels) only then.

    Raises:
        InputError: unknown preset name.
    """
    return _preset(name).uses_feature(native_um_per_px)


def _preset(name: str | None) -> Preset:
    name = DEFAULT_PRESET if name is None else name
    if name not in PRESETS:
        raise InputError(f"unknown accuracy preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[name]


def apply_preset(
    name: str | None,
    explicit: dict[str, Any] | None = None,
    *,
    feature_um: float | None = None,
    native_um_per_px: float | None = None,
) -> dict[str, Any]:
    """Knob values from a preset, with every explicitly set knob kept as given.

    Presets never override a knob the user sets explicitly: a key of ``explicit`` whose
    value is not None wins over the preset.

    Args:
        name: "fast", "balanced" or "precise"; None means :data:`DEFAULT_PRESET`.
        explicit: knob values the user set (keys from :data:`KNOBS`; None = not set).
        feature_um: the pattern's smallest feature (:func:`smallest_feature_um`); the
            preset's pixel size then scales with it. None: the preset's default pixel size.
        native_um_per_px: pixel size of a pattern image without exact geometry; the
            preset never asks for finer pixels (they would add cost, not detail).

    Returns:
        ``{"um_per_px": float, "twist_step_deg": float, "dtype": str}``.

    Raises:
        InputError: unknown preset name or knob.
    """
    preset = _preset(name)
    explicit = dict(explicit or {})
    unknown = sorted(set(explicit) - set(KNOBS))
    if unknown:
        raise InputError(
            f"unknown accuracy knob(s) {', '.join(unknown)}; presets set {', '.join(KNOBS)}"
        )
    knobs = preset.knobs(feature_um, native_um_per_px)
    knobs.update({k: v for k, v in explicit.items() if v is not None})
    return knobs
