"""The columns of a sweep's table: a point's summary flattened, units at the end of the names.

Owns :func:`flatten` (every number and boolean of a nested assessment summary as one
column, ``max_bias_plus_x_um``, ``global_minimum_offset_um``, ...), the unit suffixes it
recognises (:data:`UNITS`, ``_split_unit``, also what the sweep's pictures label axes
with), the names of list components, the status columns of every row, and the columns a
sweep expects (:func:`expected_columns`): not a list kept by hand, but :func:`flatten` of
the summary the assessment's types give a scene of the sweep's effects
(:func:`simulator.batch.summary_shape`). A point's identity columns are
:data:`simulator.sweep.ID_COLUMNS`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = [
    "METRIC_LABELS",
    "STATUS_COLUMNS",
    "UNITS",
    "UNIT_TEXT",
    "column_label",
    "expected_columns",
    "flatten",
    "metric",
]

STATUS_COLUMNS = ("status", "error", "seconds")


# ----------------------------------------------------------------------- flattening
#: Unit suffixes of summary keys, longest first; a key ``name_UNIT`` puts UNIT at the end of its column.
UNITS = (
    "um_per_px",
    "Nm_per_rad",
    "N_per_m",
    "mN_m",
    "N_m",
    "kg_m3",
    "mPa_s",
    "Pa_s",
    "um2",
    "um",
    "deg",
    "Nm",
    "nl",
    "MB",
    "J",
    "N",
    "s",
    "px",
)
#: Names of list components, by key (default x, y, twist).
COMPONENTS = {"pattern_px": ("rows", "cols"), "chip_um": ("width", "height")}


#: How units in column names are written on the pictures and pages.
UNIT_TEXT = {
    "um": "um",
    "nl": "nl",
    "deg": "deg",
    "mN_m": "mN/m",
    "N_m": "N/m",
    "N_per_m": "N/m",
    "Nm_per_rad": "N m/rad",
    "N": "N",
    "Nm": "N m",
    "J": "J",
    "um2": "um^2",
    "s": "s",
}

#: The assessment's numbers as the pictures and pages show them, one label each: column ->
#: (label, factor to the unit shown). The sweep's pictures (:data:`simulator.sweep`'s
#: metrics) and a design search's comparison of the best design with the baseline take
#: theirs from here (:func:`metric`); other columns are labelled from their names
#: (:func:`column_label`). Each labelled column is one the assessment's types make
#: (tests/test_assessment.py): a renamed field fails there, not silently on a page.
METRIC_LABELS = {
    "max_bias_x_um": ("max bias along x (um)", 1.0),
    "max_bias_y_um": ("max bias along y (um)", 1.0),
    "capture_fraction": ("capture fraction (%)", 100.0),
    "yield_fraction": ("yield under placement noise (%)", 100.0),
    "stiffness_x_N_per_m": ("stiffness k_x (N/m)", 1.0),
    "stiffness_y_N_per_m": ("stiffness k_y (N/m)", 1.0),
    "restoring_force_plus_x_x_N": ("restoring force -F_x at the +x bias (uN)", -1e6),
    "restoring_force_bias_um": (
        "the bias the force is probed at (um; beyond the floor when the chip floats)",
        1.0,
    ),
    "error_limit_um": ("what limits the final-pose error (um: grid step or floor)", 1.0),
    "global_minimum_offset_um": ("offset of the global minimum (um)", 1.0),
    "floating_half_width_um": ("the chip floats within +- (um)", 1.0),
    "yield_error_x_mean_abs_um": ("aligned placements: mean |error| in x (um)", 1.0),
    "yield_time_to_align_median_s": ("time to align, median (ms)", 1e3),
    "yield_time_to_align_p90_s": ("time to align, 90th percentile (ms)", 1e3),
    "volume_nl": ("droplet volume (nl)", 1.0),
    "critical_volume_nl": ("critical volume of the four-pad (nl)", 1.0),
}


def column_label(column: str) -> str:
    """``stiffness_twist_Nm_per_rad`` -> ``stiffness twist (N m/rad)``."""
    name, unit = _split_unit(column)
    text = name.replace("_", " ")
    return f"{text} ({UNIT_TEXT.get(unit, unit.replace('_', ' '))})" if unit else text


def metric(column: str) -> tuple[str, str, float]:
    """``(column, label, factor to the unit shown)`` of a column: its :data:`METRIC_LABELS`
    entry, else the label of its name (:func:`column_label`) unscaled."""
    label, factor = METRIC_LABELS.get(column) or (column_label(column), 1.0)
    return column, label, factor


def _split_unit(key: str) -> tuple[str, str | None]:
    for u in UNITS:
        if key.endswith("_" + u) and len(key) > len(u) + 1:
            return key[: -len(u) - 1], u
    return key, None


def _name(key: str) -> str:
    key = str(key)
    if key[:1] in ("+", "-"):  # "+x" -> plus_x; a sign alone ("+" of a torque) -> plus
        key = ("plus" if key[0] == "+" else "minus") + (f"_{key[1:]}" if len(key) > 1 else "")
    return key.replace(" ", "_")


def flatten(summary: Any) -> dict[str, Any]:
    """Every number (and boolean) of a nested summary as one column, the unit at the end.

    ``{"max_bias_um": {"+x": 90}}`` gives ``max_bias_plus_x_um``; ``{"global_minimum":
    {"x_um": 0}}`` gives ``global_minimum_x_um``; ``{"restoring_force_N": {"+x": [fx, fy]}}``
    gives ``restoring_force_plus_x_x_N`` and ``..._y_N``; a new key such as
    ``{"stiffness": {"x_N_per_m": k}}`` gives ``stiffness_x_N_per_m``. Strings, None and
    lists of lists (plateaus) are left out. ``summary`` may be the
    :class:`simulator.batch.Assessment` itself (its dict is flattened).
    """
    if not isinstance(summary, dict):
        summary = summary.to_dict()
    out: dict[str, Any] = {}

    def emit(parts: tuple[str, ...], unit: str | None, v: Any) -> None:
        col = "_".join(p for p in parts if p) + (f"_{unit}" if unit else "")
        if isinstance(v, bool | np.bool_):
            out[col] = bool(v)
        elif isinstance(v, int | np.integer):
            out[col] = int(v)
        else:
            out[col] = float(v)

    def walk(d: dict, parts: tuple[str, ...], unit: str | None) -> None:
        for k, v in d.items():
            name, u = _split_unit(str(k))
            name, u = _name(name), u or unit
            if isinstance(v, dict):
                walk(v, (*parts, name), u)
            elif isinstance(v, list | tuple):
                if v and all(
                    isinstance(x, int | float | np.number) and not isinstance(x, bool) for x in v
                ):
                    comps = COMPONENTS.get(str(k)) or (
                        ("x", "y", "twist") if len(v) <= 3 else tuple(str(i) for i in range(len(v)))
                    )
                    for c, x in zip(comps, v, strict=False):
                        emit((*parts, name, c), u, x)
            elif isinstance(v, bool | int | float | np.number):
                emit((*parts, name), u, v)

    walk(summary, (), None)
    protocols = summary.get("protocols") or {}
    for prefix, b in (
        ("max_bias", summary.get("max_bias_um") or {}),
        *(
            (f"protocols_{k}_max_bias", v.get("max_bias_um") or {})
            for k, v in protocols.items()
            if isinstance(v, dict)
        ),
    ):  # the smaller end along each axis: the bias from which both sides still align
        for axis in ("x", "y"):
            plus, minus = b.get(f"+{axis}"), b.get(f"-{axis}")
            if isinstance(plus, int | float) and isinstance(minus, int | float):
                out[f"{prefix}_{axis}_um"] = float(min(plus, minus))
    g = summary.get("global_minimum") or {}
    if isinstance(g.get("x_um"), int | float) and isinstance(g.get("y_um"), int | float):
        out["global_minimum_offset_um"] = float(math.hypot(g["x_um"], g["y_um"]))
    fl = summary.get("floating_range")
    if isinstance(fl, dict):  # free contact lines: the chip floats on the well's floor
        out["floating_half_width_um"] = float(
            max(fl["x_to_um"] - fl["x_from_um"], fl["y_to_um"] - fl["y_from_um"]) / 2
        )
    return out


# ----------------------------------------------------------------------- the columns to expect
def _metric_columns(
    twist: bool,
    meniscus: bool,
    free: bool,
    dynamics: bool,
    dispense: bool = False,
    four_pad: bool = False,
) -> list[str]:
    """The columns :func:`flatten` makes of a sweep point's summary (:func:`simulator.batch.assess`'s,
    with the point's settings) for a scene of these effects: derived from the assessment's
    types (:func:`simulator.batch.summary_shape`), in the summary's order. ``free`` counts
    only with a ``meniscus``; ``four_pad`` adds the pattern's critical volume."""
    from simulator.batch import summary_shape

    flags = {
        "twist": twist,
        "meniscus": meniscus,
        "free": meniscus and free,
        "dynamics": dynamics,
        "dispense": dispense,
        "four_pad": four_pad,
    }
    return list(flatten(summary_shape(k for k, on in flags.items() if on)))


def expected_columns(spec) -> list[str]:
    """The columns a row of the sweep ``spec`` (:class:`simulator.sweep.SweepSpec`) may have:
    the point's identity and settings, the status, and the assessment's numbers for the
    scene's effects (twist, a finite meniscus with free or pinned lines, dynamics among the
    methods; ``critical_volume_nl`` when the pattern may be a four-pad). A column here may
    still be missing from a row whose assessment did not reach it (no start aligned, a
    well without a flat floor)."""
    from simulator.core import DYNAMIC_METHODS

    values = {a.name: a.values[0] if a.values is not None else a.lo for a in spec.axes}
    ident = list(spec.columns(spec.point(values, 0, 0)))
    scene = spec.scene
    effects = scene.get("effects") or {}
    liquid = scene.get("liquid") or {}
    methods = next((a.values or () for a in spec.axes if a.name == "method"), ())
    cols = _metric_columns(
        four_pad=spec.design is None or spec.design["name"] == "four-pad",
        twist=bool(effects.get("twist", True)),
        meniscus=bool(effects.get("meniscus", False)),
        free=not liquid.get("pinned", False),
        dynamics=any(m in DYNAMIC_METHODS for m in methods),
        dispense=liquid.get("dispense") in ("pattern", "chip")
        or (  # the default protocol (simulator.scene.Scene.dispense)
            liquid.get("dispense") is None
            and bool(effects.get("meniscus", False))
            and not liquid.get("pinned", False)
        ),
    )
    return list(dict.fromkeys([*ident, *STATUS_COLUMNS, *cols]))
