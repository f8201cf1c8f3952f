"""Exact pattern geometry: shapely polygons in micrometres, centred on the nominal pattern.

Conventions (see :mod:`patterns.mask` for the image side):

* Units are micrometres. The origin is the centre of the *nominal* (ideal) pattern, x right,
  y up. For defect and jagged designs the origin is the centre of the nominal square, not the
  centroid of the defective shape (PHYSICS.md 1.2).
* Every builder returns a valid shapely geometry (``Polygon``, or ``MultiPolygon`` for the
  four-pad design) with counter-clockwise exterior rings, and raises
  :class:`patterns.errors.InputError` with a one-line message for impossible input.
* Quarter turns are applied with exact integer matrices, so rotated copies of an edge carry
  bit-identical coordinates (4-fold symmetry holds to machine precision).

Jagged designs (PHYSICS.md 10.2-10.3) are built edge by edge. Each edge has a *profile*
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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from shapely import affinity
from shapely.geometry import MultiPolygon, Polygon, box
from shapely.geometry.polygon import orient

from patterns.errors import InputError, positive, require

__all__ = [
    "DEFECT_TYPES",
    "DESIGNS",
    "Design",
    "Param",
    "build",
    "circle",
    "constant_jagged",
    "defect",
    "defect_type",
    "design_record",
    "four_pad",
    "polygon",
    "random_jagged",
    "rectangle",
    "resolve",
    "rotate_quarter",
    "square",
]

EDGES = ("right", "top", "left", "bottom")  # counter-clockwise order; index = quarter turns


# ---------------------------------------------------------------------------- helpers


def _length(name: str, value: Any) -> float:
    return positive(name, value, "um")


def _choice(name: str, value: Any, allowed: Sequence[str]) -> str:
    if value not in allowed:
        raise InputError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")
    return str(value)


def rotate_quarter(geom: Any, quarter_turns: int) -> Any:
    """Rotate ``geom`` about the origin by ``90 * quarter_turns`` degrees counter-clockwise, exactly."""
    c, s = ((1, 0), (0, 1), (-1, 0), (0, -1))[quarter_turns % 4]
    return affinity.affine_transform(geom, [c, -s, s, c, 0, 0])


def _finish(geom: Any, what: str) -> Any:
    """Orient rings counter-clockwise and check validity (a bug guard for the builders)."""
    if isinstance(geom, Polygon):
        geom = orient(geom, 1.0)
    elif isinstance(geom, MultiPolygon):
        geom = MultiPolygon([orient(g, 1.0) for g in geom.geoms])
    if not geom.is_valid or geom.is_empty:
        raise InputError(f"{what}: the parameters give an invalid shape ({shapely.is_valid_reason(geom)})")
    return geom


# ---------------------------------------------------------------------------- simple shapes


def rectangle(width: float, height: float) -> Polygon:
    """Axis-aligned rectangle ``width`` x ``height`` (um) centred on the origin."""
    w, h = _length("width", width), _length("height", height)
    return orient(box(-w / 2, -h / 2, w / 2, h / 2), 1.0)


def square(size: float) -> Polygon:
    """Square of side ``size`` (um) centred on the origin."""
    s = _length("size", size)
    return rectangle(s, s)


def circle(diameter: float, segments: int = 1024) -> Polygon:
    """Regular ``segments``-gon with the same area as the circle of ``diameter`` (um).

    Vertices sit at angles ``2 pi k / segments`` on radius
    ``r' = r sqrt(2 pi / (n sin(2 pi / n)))``, so the polygon's area equals ``pi r^2`` to
    rounding (no systematic area error). The boundary deviates from the true circle by less
    than ``r (pi/n)^2 / 3`` in radius: 3.2e-6 r for the default ``n = 1024``. ``segments``
    must be a multiple of 4 (>= 8) so the polygon keeps the square's symmetries.
    """
    r = _length("diameter", diameter) / 2
    n = segments
    require(isinstance(n, int | np.integer) and n >= 8 and n % 4 == 0,
            f"segments must be a multiple of 4 and >= 8, got {segments!r}")
    r_eff = r * math.sqrt(2 * math.pi / (n * math.sin(2 * math.pi / n)))
    k = np.arange(n)
    # Quarter-turn-exact vertices: compute one quadrant and rotate it by swapping coordinates.
    ang = 2 * np.pi * k[: n // 4] / n
    q = np.column_stack([r_eff * np.cos(ang), r_eff * np.sin(ang)])
    quads = [q, np.column_stack([-q[:, 1], q[:, 0]]), -q, np.column_stack([q[:, 1], -q[:, 0]])]
    return orient(Polygon(np.vstack(quads)), 1.0)


def four_pad(size: float, gap: float) -> MultiPolygon:
    """Four square pads of side ``p = (size - gap)/2`` (PHYSICS.md 6.1).

    The outer square has side ``size`` and includes the cross-shaped gap of width ``gap``;
    pads occupy ``[-L/2, -g/2] U [g/2, L/2]`` in x and in y; there is no border gap.
    """
    L, g = _length("size", size), _length("gap", gap)
    require(g < L, f"gap={g:g} um must be smaller than size={L:g} um (pads of side (size - gap)/2)")
    lo, hi = g / 2, L / 2
    pads = [box(x0, y0, x1, y1) for (x0, x1) in ((-hi, -lo), (lo, hi)) for (y0, y1) in ((-hi, -lo), (lo, hi))]
    return _finish(MultiPolygon(pads), "four-pad")


def polygon(points: Sequence[Sequence[float]]) -> Polygon:
    """Simple polygon through ``points`` [(x, y), ...] in um, in the pattern frame (not re-centred).

    Needs at least 3 finite points, no self-intersection and a positive area. The ring is
    closed automatically and oriented counter-clockwise.
    """
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"points must be a list of (x, y) pairs in um, got {points!r}") from None
    require(pts.ndim == 2 and pts.shape[1] == 2, f"points must be (x, y) pairs, got array of shape {pts.shape}")
    require(np.all(np.isfinite(pts)), "points must be finite numbers (um)")
    if len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
        pts = pts[:-1]
    require(len(pts) >= 3, f"points: a polygon needs at least 3 distinct points, got {len(pts)}")
    poly = Polygon(pts)
    require(poly.is_valid, f"points: the polygon is not simple ({shapely.is_valid_reason(poly)}); "
            "give the vertices in order along the boundary, without crossings")
    require(poly.area > 0, "points: the polygon has zero area")
    return orient(poly, 1.0)


# ---------------------------------------------------------------------------- defect


def defect(size: float = 200.0, *, kind: str, position: str = "middle", edge: str = "right",
           height: float, width: float) -> Polygon:
    """Square of side ``size`` with one isosceles triangular defect (PHYSICS.md 10.1).

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
    require(w <= L, f"width={w:g} um: the defect's base must fit on its edge, width <= size={L:g} um")
    if kind == "inward":
        require(h <= L / 2, f"height={h:g} um: an inward defect may reach at most the centre, height <= size/2 = {L / 2:g} um")
    y0, y1 = (-w / 2, w / 2) if position == "middle" else (L / 2 - w, L / 2)
    apex_x = L / 2 + h if kind == "outward" else L / 2 - h
    tri = Polygon([(L / 2, y0), (apex_x, (y0 + y1) / 2), (L / 2, y1)])
    base = square(L)
    shape = base.union(tri) if kind == "outward" else base.difference(tri)
    return _finish(rotate_quarter(shape, EDGES.index(edge)), "defect")


#: Named defect types of PHYSICS.md 10.1 on a 200 um square: position, height h_d, width w_d (um).
DEFECT_TYPES: dict[str, tuple[str, float, float]] = {
    "A": ("middle", 10.0, 20.0),
    "B": ("corner", 30.0, 60.0),
    "C": ("middle", 60.0, 120.0),
}


def defect_type(name: str, kind: str, size: float = 200.0, edge: str = "right") -> Polygon:
    """The library defect type ``'A'``, ``'B'`` or ``'C'`` (PHYSICS.md 10.1), inward or outward."""
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
        raise InputError(f"{what}: the teeth cut the pattern apart into {len(parts)} pieces; use smaller teeth")
    return _finish(parts[0], what)


def _triangle_wave(t: np.ndarray, pitch: float, phase: str) -> np.ndarray:
    """Unit triangle wave in [-1, 1] with period ``pitch``.

    ``phase='zero'``: rising zero crossing at t = 0 (odd in t); ``'peak'``: maximum at t = 0 (even).
    """
    u = t / pitch - (0.25 if phase == "zero" else 0.0)
    return 1.0 - 4.0 * np.abs(u - np.round(u))


def constant_jagged(size: float = 200.0, *, amplitude: float, pitch: float | None = None,
                    teeth: str = "centred", phase: str = "zero") -> Polygon:
    """Square with every edge a regular zigzag (PHYSICS.md 10.2).

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
    require(a < L / 4, f"amplitude={a:g} um is too large for size={L:g} um; use amplitude < size/4 = {L / 4:g} um")
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


def random_jagged(size: float = 200.0, *, sigma: float, seed: int, pitch: float | None = None,
                  profile: str = "teeth") -> Polygon:
    """Square whose edges carry peaks of random signed height (PHYSICS.md 10.3).

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
    require(p <= L, f"pitch={p:g} um must not exceed the edge, pitch <= size={L:g} um (sigma <= size/4 for the default pitch)")
    require(isinstance(seed, int | np.integer) and not isinstance(seed, bool) and seed >= 0,
            f"seed must be an integer >= 0, got {seed!r}")
    profile = _choice("profile", profile, ("teeth", "polyline"))
    n = math.floor(L / p + 1e-9)
    peaks_t = (np.arange(n) - (n - 1) / 2) * p
    heights = np.random.default_rng(int(seed)).normal(0.0, s, size=(4, n))
    profiles = []
    for h in heights:
        if profile == "teeth":
            t = np.concatenate([[-L / 2], np.ravel(np.column_stack([peaks_t - p / 2, peaks_t])), [peaks_t[-1] + p / 2, L / 2]])
            d = np.concatenate([[0.0], np.ravel(np.column_stack([np.zeros(n), h])), [0.0, 0.0]])
        else:
            t = np.concatenate([[-L / 2], peaks_t, [L / 2]])
            d = np.concatenate([[0.0], h, [0.0]])
        t, idx = np.unique(t, return_index=True)
        profiles.append((t, d[idx]))
    try:
        return _from_edges(L, profiles, "random-jagged")
    except InputError:
        raise InputError(f"sigma={s:g} um with seed={seed} cuts the {L:g} um pattern apart; "
                         "use a smaller sigma or another seed") from None


# ---------------------------------------------------------------------------- registry

REQUIRED = object()  # sentinel: the parameter has no default


@dataclass(frozen=True)
class Param:
    """One design parameter as the CLI and the provenance record see it.

    ``kind`` is ``'length'`` (finite > 0, um), ``'int'`` (>= 0), ``'choice'`` or ``'points'``
    (``"X1,Y1;X2,Y2;..."`` in um). ``default`` may be :data:`REQUIRED`, a value, ``None``
    (the builder's own default, described in ``help``) or a callable of the other resolved
    values (e.g. pitch = 2 * amplitude).
    """

    name: str
    kind: str
    help: str
    default: Any = REQUIRED
    unit: str = ""
    choices: tuple[str, ...] = ()

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def coerce(self, value: Any, label: str | None = None) -> Any:
        """Convert ``value`` (a Python value or command-line text) or raise InputError naming ``label``."""
        label = label or self.name
        if self.kind == "length":
            return positive(label, value, "um")
        if self.kind == "int":
            try:
                v = int(value) if not isinstance(value, float) else None
            except (TypeError, ValueError):
                v = None
            if v is None or isinstance(value, bool) or v < 0:
                raise InputError(f"{label} must be an integer >= 0, got {value!r}")
            return v
        if self.kind == "choice":
            return _choice(label, value, self.choices)
        if self.kind == "points":
            return _parse_points(value, label)
        raise AssertionError(self.kind)

    def describe(self) -> str:
        if self.required:
            d = "required"
        elif callable(self.default) or self.default is None:
            d = "optional"
        else:
            d = f"default {self.default}"
        unit = f" [{self.unit}]" if self.unit else ""
        opts = f" ({'|'.join(self.choices)})" if self.choices else ""
        return f"{self.flag}{unit}{opts}: {self.help} ({d})"


def _parse_points(value: Any, label: str) -> list[tuple[float, float]]:
    if not isinstance(value, str):
        return value  # a sequence of (x, y) pairs; polygon() validates it
    pts = []
    for item in value.replace(" ", "").strip(";").split(";"):
        try:
            x, y = item.split(",")
            pts.append((float(x), float(y)))
        except ValueError:
            raise InputError(f"{label}: cannot read point {item!r}; write \"X1,Y1;X2,Y2;X3,Y3\" in um") from None
    return pts


@dataclass(frozen=True)
class Design:
    """A named design: its builder, a one-line description and its parameters."""

    name: str
    builder: Callable[..., Any]
    description: str
    params: tuple[Param, ...] = field(default_factory=tuple)


def _size_param(default: Any = REQUIRED, help: str = "side of the (nominal) square") -> Param:
    return Param("size", "length", help, default, "um")


DESIGNS: dict[str, Design] = {d.name: d for d in (
    Design("square", square, "Square pad of side size.", (_size_param(),)),
    Design("rectangle", rectangle, "Rectangular pad width x height.", (
        Param("width", "length", "extent along x", unit="um"),
        Param("height", "length", "extent along y", unit="um"))),
    Design("circle", circle, "Circular pad (equal-area regular 1024-gon, radius error < 3.2e-6 r).", (
        Param("diameter", "length", "circle diameter", unit="um"),
        Param("segments", "int", "polygon vertices, a multiple of 4", 1024))),
    Design("four-pad", four_pad, "2x2 square pads split by a cross-shaped gap (PHYSICS 6.1).", (
        _size_param(help="outer side, gaps included"),
        Param("gap", "length", "width of the hydrophobic cross; pad side = (size - gap)/2", unit="um"))),
    Design("defect", defect, "Square with one triangular defect on an edge (PHYSICS 10.1).", (
        _size_param(200.0),
        Param("kind", "choice", "add the triangle (outward) or cut it out (inward)", choices=("inward", "outward")),
        Param("position", "choice", "base centred on the edge, or flush with its counter-clockwise end",
              "middle", choices=("middle", "corner")),
        Param("edge", "choice", "edge carrying the defect", "right", choices=EDGES),
        Param("height", "length", "triangle height, perpendicular to the edge", unit="um"),
        Param("width", "length", "triangle base along the edge", unit="um"))),
    Design("constant-jagged", constant_jagged, "Square with regular zigzag edges (PHYSICS 10.2).", (
        _size_param(200.0),
        Param("amplitude", "length", "tooth height, peak to valley", unit="um"),
        Param("pitch", "length", "tooth base along the edge (default 2 x amplitude: 45-degree flanks)",
              lambda v: 2 * v["amplitude"], "um"),
        Param("teeth", "choice", "teeth centred on the nominal edge, or all outside / inside it",
              "centred", choices=("centred", "outward", "inward")),
        Param("phase", "choice", "edge midpoint at a zero crossing (4-fold symmetric, exact area) "
              "or at a tooth tip (also mirror symmetric)", "zero", choices=("zero", "peak")))),
    Design("random-jagged", random_jagged, "Square with random-height teeth on every edge (PHYSICS 10.3).", (
        _size_param(200.0),
        Param("sigma", "length", "standard deviation of the peak heights", unit="um"),
        Param("pitch", "length", "peak spacing (default 4 x sigma)", lambda v: 4 * v["sigma"], "um"),
        Param("seed", "int", "seed of numpy.random.default_rng for the peak heights"),
        Param("profile", "choice", "triangular teeth on the nominal edge, or a polyline through the peaks",
              "teeth", choices=("teeth", "polyline")))),
    Design("polygon", polygon, "Any simple polygon, vertices in um about the pattern centre.", (
        Param("points", "points", 'vertices "X1,Y1;X2,Y2;..." in order along the boundary', unit="um"),)),
)}


def _design(name: str) -> Design:
    if name not in DESIGNS:
        raise InputError(f"unknown design {name!r}; choose one of {', '.join(DESIGNS)}")
    return DESIGNS[name]


def resolve(design_name: str, **params: Any) -> dict[str, Any]:
    """Validate and complete ``params`` for a design: coerce types, fill defaults, reject unknowns."""
    design = _design(design_name)
    unknown = set(params) - {p.name for p in design.params}
    require(not unknown, f"design {design_name} has no parameter {', '.join(sorted(unknown))}; "
            f"it takes {', '.join(p.name for p in design.params)}")
    values: dict[str, Any] = {}
    for p in design.params:
        v = params.get(p.name)
        if v is None:
            require(not p.required, f"design {design_name} needs {p.name} ({p.help}, {p.unit or p.kind})")
            continue
        values[p.name] = p.coerce(v)
    for p in design.params:  # derived defaults, after every given value is known
        if p.name not in values and callable(p.default):
            values[p.name] = p.default(values)
        elif p.name not in values and p.default is not None:
            values[p.name] = p.default
    return values


def build(design_name: str, **params: Any) -> Any:
    """Build the geometry of a registered design from its parameters (um)."""
    return _design(design_name).builder(**resolve(design_name, **params))


def design_record(design_name: str, **params: Any) -> dict[str, Any]:
    """Provenance record ``{"design": name, "parameters": {name: {"value", "unit"}}}`` (JSON-ready)."""
    values = resolve(design_name, **params)
    design = _design(design_name)
    out = {}
    for p in design.params:
        if p.name in values:
            v = values[p.name]
            out[p.name] = {"value": [list(q) for q in v] if p.kind == "points" else v, "unit": p.unit}
    return {"design": design_name, "parameters": out}
