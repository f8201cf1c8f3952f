"""The axes of a design sweep: what each may vary, and an axis parsed from its sweep-file entry.

Owns :class:`AxisKind` (an axis's column with its units, its kind and its check),
:data:`AXES` (the axes every sweep has) and the design's parameters as axes
(:func:`axis_kinds`), the parsed :class:`Axis` (discrete values, or a continuous range
for samples), and ``_parse_axis``: a list, a range ``{from, to, num | step}`` or one
fixed value, checked into one :class:`InputError` line. :mod:`simulator.sweep`
builds the sweep from them. Nothing heavy is imported here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from foundation import InputError, require
from patterns import show_value
from simulator.core import MAX_TWIST_DEG

__all__ = ["AXES", "HARD_MAX_POINTS", "Axis", "AxisKind", "axis_kinds"]

#: Points no sweep may have (the plan is held in memory).
HARD_MAX_POINTS = 10_000_000


# ----------------------------------------------------------------------- axes
@dataclass(frozen=True)
class AxisKind:
    """What an axis varies: its column (units in the name), its values and where they go."""

    column: str
    kind: str  # "number", "int", "choice", "path"
    help: str
    check: Callable[[Any], str | None] = lambda v: None
    choices: tuple[str, ...] = ()


def _interval(text: str, unit: str) -> Callable[[Any], str | None]:
    from simulator.scene import number

    return number(text, unit).check


def _choice_check(choices: tuple[str, ...]) -> Callable[[Any], str | None]:
    def check(v: Any) -> str | None:
        return (
            None
            if isinstance(v, str) and v in choices
            else "must be one of " + ", ".join(f'"{c}"' for c in choices)
        )

    return check


def _path_check(v: Any) -> str | None:
    return (
        None
        if isinstance(v, str) and v.strip() and "\x00" not in v
        else "must be the path of a pattern file as a quoted string"
    )


def _scene_axes() -> dict[str, AxisKind]:
    """The axes every sweep has, by name in :data:`AXES`' order: the scene's sweepable
    parameters (:data:`simulator.scene.SCENE_PARAMS`: their ranges and helps) and the
    assessment's placement noise and stepper."""
    from simulator.core import BATCH_METHODS as METHODS
    from simulator.scene import SCENE_PARAMS, Number, Size

    kinds = {
        "placement_sigma_um": AxisKind(
            "placement_sigma_um",
            "number",
            "placement noise, standard deviation in x and y (um); default 10 % of the chip",
            _interval("[0, 1e6]", "um"),
        ),
        "placement_sigma_deg": AxisKind(
            "placement_sigma_deg",
            "number",
            "placement noise in twist, standard deviation (deg); default 2",
            _interval(f"[0, {MAX_TWIST_DEG}]", "deg"),
        ),
        "method": AxisKind(
            "method",
            "choice",
            "stepper of the capture and yield runs: greedy, gradient, or the dynamics overdamped, inertial",
            _choice_check(METHODS),
            METHODS,
        ),
    }
    for p in SCENE_PARAMS:
        if not p.sweepable:
            continue
        kind = p.kind.side if isinstance(p.kind, Size) else p.kind  # a chip size: a square's side
        if isinstance(kind, Number):
            kinds[p.axis] = AxisKind(p.axis, "number", p.sweep, kind.check)
        else:  # the pattern: a file, relative to the sweep file
            kinds[p.axis] = AxisKind(p.axis, "path", p.sweep, _path_check)
    return {name: kinds[name] for name in AXES}


#: Axes that every sweep has (design parameters come on top, see :func:`axis_kinds`).
AXES: tuple[str, ...] = (
    "pattern",
    "chip_size_um",
    "volume_nl",
    "pad_angle_deg",
    "substrate_angle_deg",
    "surface_tension_mN_m",
    "placement_sigma_um",
    "placement_sigma_deg",
    "method",
    "resolution_um",
    "twist_step_deg",
)


def _design_axes(design: str) -> dict[str, AxisKind]:
    from patterns.geometry import DESIGNS

    out = {}
    for p in DESIGNS[design].params:
        if p.kind == "points":
            continue
        column = f"{p.name}_um" if p.unit == "um" else p.name

        def check(v: Any, p=p) -> str | None:
            if p.kind == "int" and (isinstance(v, bool) or not isinstance(v, int)):
                return "must be a whole number >= 0"
            try:
                p.coerce(v)
            except InputError as err:
                return str(err)
            return None

        out[p.name] = AxisKind(
            column, {"length": "number"}.get(p.kind, p.kind), p.help, check, p.choices
        )
    return out


def axis_kinds(design: str | None) -> dict[str, AxisKind]:
    """Every axis a sweep of ``design`` (None: pattern files) may have, by its key."""
    kinds = _scene_axes()
    if design is not None:
        kinds = _design_axes(design) | kinds
    return kinds


@dataclass(frozen=True)
class Axis:
    """One axis: discrete ``values``, or (for samples) a continuous range ``lo``..``hi``."""

    name: str
    column: str
    kind: str
    values: tuple | None = None
    lo: float | None = None
    hi: float | None = None

    @property
    def size(self) -> int:
        return len(self.values) if self.values is not None else 0

    def record(self) -> dict:
        return {
            "name": self.name,
            "values": list(self.values) if self.values is not None else None,
            "lo": self.lo,
            "hi": self.hi,
        }


def _parse_axis(name: str, raw: Any, kind: AxisKind, sampling: bool, src: str) -> Axis:
    where = f"{src}: [axes] {name} = {show_value(raw, 60)}"

    def checked(v: Any) -> Any:
        if isinstance(v, float) and kind.kind == "int" and v.is_integer():
            v = int(v)
        problem = kind.check(v)
        if problem:
            raise InputError(f"{where}: {show_value(v, 30)}: {problem}")
        return v

    if isinstance(raw, list):
        require(len(raw) > 0, f"{where}: the list is empty; give at least one value")
        vals = tuple(checked(v) for v in raw)
        dup = next((v for i, v in enumerate(vals) if v in vals[:i]), None)
        require(
            dup is None,
            f"{where}: lists {show_value(dup)} twice; give each value once (realizations = N repeats points)",
        )
        return Axis(name, kind.column, kind.kind, vals)
    if isinstance(raw, dict):
        require(
            kind.kind in ("number", "int"), f"{where}: {name} takes a list of values, not a range"
        )
        extra = sorted(set(raw) - {"from", "to", "num", "step"})
        if extra:
            raise InputError(
                f"{where}: unknown key {extra[0]}; a range is {{from = A, to = B}} with num = N or step = D"
            )
        require("from" in raw and "to" in raw, f"{where}: a range needs from and to")
        a, b = checked(raw["from"]), checked(raw["to"])
        require(
            a != b, f"{where}: the range is empty (from = to); give a list of one value instead"
        )
        require(
            a < b,
            f"{where}: the range is inverted (from > to); write from = {show_value(b)}, to = {show_value(a)}",
        )
        require(not ("num" in raw and "step" in raw), f"{where}: give num or step, not both")
        if "num" in raw:
            n = raw["num"]
            require(
                isinstance(n, int) and not isinstance(n, bool) and 2 <= n <= HARD_MAX_POINTS,
                f"{where}: num must be a whole number >= 2 (the values from..to, ends included)",
            )
            vals = tuple(float(v) for v in np.linspace(a, b, n))
        elif "step" in raw:
            d = raw["step"]
            require(
                isinstance(d, int | float)
                and not isinstance(d, bool)
                and math.isfinite(d)
                and d > 0,
                f"{where}: step must be a number > 0",
            )
            n = math.floor((b - a) / d + 1e-9) + 1
            require(
                n <= HARD_MAX_POINTS,
                f"{where}: the step gives more than {HARD_MAX_POINTS:,} values",
            )
            vals = tuple(float(a + k * d) for k in range(n))
        elif kind.kind == "int":
            require(
                b - a < HARD_MAX_POINTS,
                f"{where}: the range holds more than {HARD_MAX_POINTS:,} values",
            )
            vals = tuple(range(int(a), int(b) + 1)) if not sampling else None
        else:
            require(
                sampling,
                f"{where}: a grid needs num = N or step = D in the range (or set [sweep] samples = N for random points)",
            )
            return Axis(name, kind.column, kind.kind, None, float(a), float(b))
        if vals is None:
            return Axis(name, kind.column, kind.kind, None, float(a), float(b))
        if kind.kind == "int":
            require(
                all(float(v).is_integer() for v in vals),
                f"{where}: {name} takes whole numbers; choose a whole step",
            )
            vals = tuple(int(round(v)) for v in vals)
        else:
            vals = tuple(round(v, 12) for v in vals)
        return Axis(name, kind.column, kind.kind, tuple(checked(v) for v in vals))
    return Axis(name, kind.column, kind.kind, (checked(raw),))
