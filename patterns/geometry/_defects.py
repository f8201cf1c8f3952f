"""Imperfect squares: one triangular defect (docs/physics.md §10) and jagged edges (§10.2, §10.3).

Jagged designs (docs/physics.md §10-10.3) are built edge by edge. Each edge has a *profile*
``d(t)``: the outward offset of the edge line at position ``t`` along the edge, for
``t`` in ``[-L/2, L/2]``, measured in the frame of the right edge (``t = y``; the edge runs
from the bottom-right to the top-right corner, the direction of a counter-clockwise walk).
The top, left and bottom edges are that construction turned by 90, 180 and 270 degrees
counter-clockwise. The pattern is the set of points that lie inside all four jagged edge
lines, each edge line being straight (the nominal line) beyond the ends of its edge. So teeth
never cross at a corner: a tooth that would reach past a corner is clipped by the
neighbouring edge's nominal line, and two inward teeth that meet at a corner simply both cut
it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry import Polygon

from foundation import InputError, require
from patterns.geometry._shapes import EDGES, _choice, _finish, _length, rotate_quarter, square

# ---------------------------------------------------------------------------- defect


def defect(
    size: float = 200.0,
    *,
    kind: str,
    position: str = "middle",
    edge: str = "right",
    height: float,
    width: float,
) -> Polygon:
    """Square of side ``size`` with one isosceles triangular defect (docs/physics.md §10).

    The triangle has its base (``width``) on the chosen ``edge`` and its apex ``height`` away
    from the edge, above the middle of the base; ``kind='outward'`` adds it outside the square,
    ``'inward'`` cuts it out. ``position='middle'`` centres the base on the edge;
    ``'corner'`` puts the base flush with one end of the edge. On the right edge that end is
    the upper one (+y). The other edges are the right-edge design turned by 90 (top),
    180 (left) and 270 (bottom) degrees counter-clockwise, so the corner end is always the end
    reached last when walking the square counter-clockwise: top -> left end (-x),
    left -> lower end (-y), bottom -> right end (+x).
    """
    L = _length("size", size)
    h, w = _length("height", height), _length("width", width)
    kind = _choice("kind", kind, ("inward", "outward"))
    position = _choice("position", position, ("middle", "corner"))
    edge = _choice("edge", edge, EDGES)
    require(
        w <= L, f"width={w:g} um: the defect's base must fit on its edge, width <= size={L:g} um"
    )
    if kind == "inward":
        require(
            h <= L / 2,
            f"height={h:g} um: an inward defect may reach at most the centre, height <= size/2 = {L / 2:g} um",
        )
    y0, y1 = (-w / 2, w / 2) if position == "middle" else (L / 2 - w, L / 2)
    apex_x = L / 2 + h if kind == "outward" else L / 2 - h
    tri = Polygon([(L / 2, y0), (apex_x, (y0 + y1) / 2), (L / 2, y1)])
    base = square(L)
    shape = base.union(tri) if kind == "outward" else base.difference(tri)
    return _finish(rotate_quarter(shape, EDGES.index(edge)), "defect")


#: Named defect types of docs/physics.md §10 on a 200 um square: position, height h_d, width w_d (um).
DEFECT_TYPES: dict[str, tuple[str, float, float]] = {
    "A": ("middle", 10.0, 20.0),
    "B": ("corner", 30.0, 60.0),
    "C": ("middle", 60.0, 120.0),
}


def defect_type(name: str, kind: str, size: float = 200.0, edge: str = "right") -> Polygon:
    """The library defect type ``'A'``, ``'B'`` or ``'C'`` (docs/physics.md §10), inward or outward."""
    name = _choice("defect type", name, tuple(DEFECT_TYPES))
    position, h, w = DEFECT_TYPES[name]
    return defect(size=size, kind=kind, position=position, edge=edge, height=h, width=w)


# ---------------------------------------------------------------------------- jagged edges


def _edge_region(L: float, t: np.ndarray, d: np.ndarray) -> Polygon:
    """Points left of the right edge's jagged line ``x = L/2 + d(t)`` at ``y = t``.

    ``t`` must increase from -L/2 to L/2; beyond the edge ends the line is the nominal
    ``x = L/2``.
    """
    far = 2 * L + 4 * float(np.max(np.abs(d), initial=0.0))
    pts = [(-far, -far), (L / 2, -far), (L / 2, -L / 2)]
    pts += list(zip((L / 2 + d).tolist(), t.tolist(), strict=True))
    pts += [(L / 2, L / 2), (L / 2, far), (-far, far)]
    dedup = [pts[0]] + [p for p, q in zip(pts[1:], pts[:-1], strict=True) if p != q]
    return Polygon(dedup)


def _from_edges(L: float, profiles: Sequence[tuple[np.ndarray, np.ndarray]], what: str) -> Polygon:
    """Intersect the four jagged edge regions (profiles in right, top, left, bottom order)."""
    shape = None
    for k, (t, d) in enumerate(profiles):
        region = rotate_quarter(_edge_region(L, t, d), k)
        shape = region if shape is None else shape.intersection(region)
    # Teeth touching at a corner can leave stray points or lines next to the polygon: drop them.
    parts = [g for g in shapely.get_parts(shape) if isinstance(g, Polygon) and g.area > 0]
    if len(parts) != 1 or len(parts[0].interiors) > 0:
        raise InputError(
            f"{what}: the teeth cut the pattern apart into {len(parts)} pieces; use smaller teeth"
        )
    return _finish(parts[0], what)


def _triangle_wave(t: np.ndarray, pitch: float, phase: str) -> np.ndarray:
    """Unit triangle wave in [-1, 1] with period ``pitch``.

    ``phase='zero'``: rising zero crossing at t = 0 (odd in t); ``'peak'``: maximum at t = 0 (even).
    """
    u = t / pitch - (0.25 if phase == "zero" else 0.0)
    return 1.0 - 4.0 * np.abs(u - np.round(u))


def constant_jagged(
    size: float = 200.0,
    *,
    amplitude: float,
    pitch: float | None = None,
    teeth: str = "centred",
    phase: str = "zero",
) -> Polygon:
    """Square with every edge a regular zigzag (docs/physics.md §10).

    Teeth are triangles of height ``amplitude`` (peak to valley, perpendicular to the edge)
    and base ``pitch`` along it (default ``2 * amplitude``: right-angled teeth, 45-degree
    flanks). ``teeth`` places them: ``'centred'`` (offsets in [-a/2, a/2], the mean edge line
    is the nominal square), ``'outward'`` ([0, a]) or ``'inward'`` ([-a, 0]).

    ``phase`` fixes where the zigzag sits along each edge, measured from the edge midpoint:

    * ``'zero'`` (default): the zigzag crosses its mean line at the edge midpoint, going
      outward when walking counter-clockwise. The profile is odd about the midpoint, so each
      edge adds exactly zero area for any pitch; with centred teeth and flanks no steeper than
      45 degrees (pitch >= 2 * amplitude) inward teeth of neighbouring edges never overlap
      at a corner, and the area is exactly ``size**2``. Symmetric under quarter turns (and so
      under the point reflection), but not under mirrors: the teeth have a handedness.
    * ``'peak'``: a tooth tip at every edge midpoint. Symmetric under quarter turns *and*
      mirrors; the area equals ``size**2`` only when the edge holds a whole, even number of
      pitches (the corner then sits on a tooth tip, clipped by the neighbouring edge line).

    Corners follow the module rule: each edge's zigzag ends at the corner lines.
    """
    L, a = _length("size", size), _length("amplitude", amplitude)
    require(
        a < L / 4,
        f"amplitude={a:g} um is too large for size={L:g} um; use amplitude < size/4 = {L / 4:g} um",
    )
    p = 2 * a if pitch is None else _length("pitch", pitch)
    require(p <= L, f"pitch={p:g} um must not exceed the edge, pitch <= size={L:g} um")
    teeth = _choice("teeth", teeth, ("centred", "outward", "inward"))
    phase = _choice("phase", phase, ("zero", "peak"))
    shift = (-0.25 if phase == "zero" else 0.0) * p  # breakpoints of the wave at shift + k p / 2
    k = np.arange(math.floor((-L / 2 - shift) / (p / 2)) + 1, math.ceil((L / 2 - shift) / (p / 2)))
    t = np.unique(np.concatenate([[-L / 2], shift + k * p / 2, [L / 2]]))
    t = t[(t >= -L / 2) & (t <= L / 2)]
    offset = {"centred": 0.0, "outward": 1.0, "inward": -1.0}[teeth]
    d = (a / 2) * (_triangle_wave(t, p, phase) + offset)
    return _from_edges(L, [(t, d)] * 4, "constant-jagged")


def random_jagged(
    size: float = 200.0,
    *,
    sigma: float,
    seed: int,
    pitch: float | None = None,
    profile: str = "teeth",
) -> Polygon:
    """Square whose edges carry peaks of random signed height (docs/physics.md §10).

    Each edge holds ``n = floor(size / pitch)`` peaks at a fixed ``pitch`` (default
    ``4 * sigma``), centred on the edge (the leftover ``size - n * pitch`` is split between the
    two ends, where the edge stays on the nominal line). Peak heights are independent
    ``N(0, sigma^2)`` draws, positive outward, from ``numpy.random.default_rng(seed)``: one
    array of shape (4, n) for the edges right, top, left, bottom, each row in
    counter-clockwise walking order.

    ``profile='teeth'`` (default): each peak is the apex of a triangular tooth of base
    ``pitch`` standing on the nominal edge (the edge returns to the nominal line halfway
    between peaks). ``'polyline'``: straight segments from peak to peak, and from the outer
    peaks to the nominal corners. Corners follow the module rule (teeth are clipped by the
    neighbouring edge's nominal line), so the result is always a valid polygon unless inward
    peaks cut the pattern apart, which raises InputError.
    """
    L, s = _length("size", size), _length("sigma", sigma)
    p = 4 * s if pitch is None else _length("pitch", pitch)
    require(
        p <= L,
        f"pitch={p:g} um must not exceed the edge, pitch <= size={L:g} um (sigma <= size/4 for the default pitch)",
    )
    require(
        isinstance(seed, int | np.integer) and not isinstance(seed, bool) and seed >= 0,
        f"seed must be an integer >= 0, got {seed!r}",
    )
    profile = _choice("profile", profile, ("teeth", "polyline"))
    n = math.floor(L / p + 1e-9)
    peaks_t = (np.arange(n) - (n - 1) / 2) * p
    heights = np.random.default_rng(int(seed)).normal(0.0, s, size=(4, n))
    profiles = []
    for h in heights:
        if profile == "teeth":
            t = np.concatenate(
                [
                    [-L / 2],
                    np.ravel(np.column_stack([peaks_t - p / 2, peaks_t])),
                    [peaks_t[-1] + p / 2, L / 2],
                ]
            )
            d = np.concatenate([[0.0], np.ravel(np.column_stack([np.zeros(n), h])), [0.0, 0.0]])
        else:
            t = np.concatenate([[-L / 2], peaks_t, [L / 2]])
            d = np.concatenate([[0.0], h, [0.0]])
        t, idx = np.unique(t, return_index=True)
        profiles.append((t, d[idx]))
    try:
        return _from_edges(L, profiles, "random-jagged")
    except InputError:
        raise InputError(
            f"sigma={s:g} um with seed={seed} cuts the {L:g} um pattern apart; "
            "use a smaller sigma or another seed"
        ) from None
