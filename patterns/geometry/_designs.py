"""Exact pattern geometry: shapely polygons in micrometres, centred on the nominal pattern.

Conventions (``_mask`` has the image side, :class:`Mask`):

* Units are micrometres. The origin is the centre of the *nominal* (ideal) pattern, x right,
  y up. For defect and jagged designs the origin is the centre of the nominal square, not the
  centroid of the defective shape (docs/physics.md §1).
* Every builder returns a valid shapely geometry (``Polygon``, or ``MultiPolygon`` for the
  four-pad design) with counter-clockwise exterior rings, and raises
  :class:`foundation.InputError` with a one-line message for impossible input.
* Quarter turns are applied with exact integer matrices, so rotated copies of an edge carry
  bit-identical coordinates (4-fold symmetry holds to machine precision).

Jagged designs are built edge by edge: how, in ``_defects`` (docs/physics.md §10-10.3).

The family's modules (their names are :mod:`patterns.geometry`'s): ``_shapes`` (the ideal
shapes and the builders' shared helpers), ``_defects`` (defect and jagged designs); this
module holds the registry of named designs (:data:`DESIGNS`, :func:`build`,
:func:`design_record`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from foundation import InputError, positive, require
from patterns.geometry._defects import (
    constant_jagged,
    defect,
    random_jagged,
)
from patterns.geometry._shapes import (
    EDGES,
    _choice,
    circle,
    four_pad,
    polygon,
    rectangle,
    square,
)

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
            raise InputError(
                f'{label}: cannot read point {item!r}; write "X1,Y1;X2,Y2;X3,Y3" in um'
            ) from None
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


DESIGNS: dict[str, Design] = {
    d.name: d
    for d in (
        Design("square", square, "Square pad of side size.", (_size_param(),)),
        Design(
            "rectangle",
            rectangle,
            "Rectangular pad width x height.",
            (
                Param("width", "length", "extent along x", unit="um"),
                Param("height", "length", "extent along y", unit="um"),
            ),
        ),
        Design(
            "circle",
            circle,
            "Circular pad (equal-area regular 1024-gon, radius error < 3.2e-6 r).",
            (
                Param("diameter", "length", "circle diameter", unit="um"),
                Param("segments", "int", "polygon vertices, a multiple of 4", 1024),
            ),
        ),
        Design(
            "four-pad",
            four_pad,
            "2x2 square pads split by a cross-shaped gap (docs/physics.md §6.1).",
            (
                _size_param(help="outer side, gaps included"),
                Param(
                    "gap",
                    "length",
                    "width of the hydrophobic cross; pad side = (size - gap)/2",
                    unit="um",
                ),
            ),
        ),
        Design(
            "defect",
            defect,
            "Square with one triangular defect on an edge (docs/physics.md §10.1).",
            (
                _size_param(200.0),
                Param(
                    "kind",
                    "choice",
                    "add the triangle (outward) or cut it out (inward)",
                    choices=("inward", "outward"),
                ),
                Param(
                    "position",
                    "choice",
                    "base centred on the edge, or flush with its counter-clockwise end",
                    "middle",
                    choices=("middle", "corner"),
                ),
                Param("edge", "choice", "edge carrying the defect", "right", choices=EDGES),
                Param("height", "length", "triangle height, perpendicular to the edge", unit="um"),
                Param("width", "length", "triangle base along the edge", unit="um"),
            ),
        ),
        Design(
            "constant-jagged",
            constant_jagged,
            "Square with regular zigzag edges (docs/physics.md §10.2).",
            (
                _size_param(200.0),
                Param("amplitude", "length", "tooth height, peak to valley", unit="um"),
                Param(
                    "pitch",
                    "length",
                    "tooth base along the edge (default 2 x amplitude: 45-degree flanks)",
                    lambda v: 2 * v["amplitude"],
                    "um",
                ),
                Param(
                    "teeth",
                    "choice",
                    "teeth centred on the nominal edge, or all outside / inside it",
                    "centred",
                    choices=("centred", "outward", "inward"),
                ),
                Param(
                    "phase",
                    "choice",
                    "edge midpoint at a zero crossing (4-fold symmetric, exact area) "
                    "or at a tooth tip (also mirror symmetric)",
                    "zero",
                    choices=("zero", "peak"),
                ),
            ),
        ),
        Design(
            "random-jagged",
            random_jagged,
            "Square with random-height teeth on every edge (docs/physics.md §10.3).",
            (
                _size_param(200.0),
                Param("sigma", "length", "standard deviation of the peak heights", unit="um"),
                Param(
                    "pitch",
                    "length",
                    "peak spacing (default 4 x sigma)",
                    lambda v: 4 * v["sigma"],
                    "um",
                ),
                Param("seed", "int", "seed of numpy.random.default_rng for the peak heights"),
                Param(
                    "profile",
                    "choice",
                    "triangular teeth on the nominal edge, or a polyline through the peaks",
                    "teeth",
                    choices=("teeth", "polyline"),
                ),
            ),
        ),
        Design(
            "polygon",
            polygon,
            "Any simple polygon, vertices in um about the pattern centre.",
            (
                Param(
                    "points",
                    "points",
                    'vertices "X1,Y1;X2,Y2;..." in order along the boundary',
                    unit="um",
                ),
            ),
        ),
    )
}


def _design(name: str) -> Design:
    if name not in DESIGNS:
        raise InputError(f"unknown design {name!r}; choose one of {', '.join(DESIGNS)}")
    return DESIGNS[name]


def resolve(design_name: str, **params: Any) -> dict[str, Any]:
    """Validate and complete ``params`` for a design: coerce types, fill defaults, reject unknowns."""
    design = _design(design_name)
    unknown = set(params) - {p.name for p in design.params}
    require(
        not unknown,
        f"design {design_name} has no parameter {', '.join(sorted(unknown))}; "
        f"it takes {', '.join(p.name for p in design.params)}",
    )
    values: dict[str, Any] = {}
    for p in design.params:
        v = params.get(p.name)
        if v is None:
            require(
                not p.required,
                f"design {design_name} needs {p.name} ({p.help}, {p.unit or p.kind})",
            )
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
            out[p.name] = {
                "value": [list(q) for q in v] if p.kind == "points" else v,
                "unit": p.unit,
            }
    return {"design": design_name, "parameters": out}
