"""The columns of a sweep's table: a point's summary flattened, units at the end of the names.

Owns :func:`flatten` (every number and boolean of a nested assessment summary as one
column, ``max_bias_plus_x_um``, ``global_minimum_offset_um``, ...), the unit suffixes it
recognises (:data:`UNITS`, ``_split_unit``, also what the sweep's pictures label axes
with), the names of list components and the status columns of every row. A point's
identity columns are :data:`simulator.sweep.ID_COLUMNS`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["STATUS_COLUMNS", "UNITS", "flatten"]

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


def _split_unit(key: str) -> tuple[str, str | None]:
    for u in UNITS:
        if key.endswith("_" + u) and len(key) > len(u) + 1:
            return key[: -len(u) - 1], u
    return key, None


def _name(key: str) -> str:
    key = str(key)
    if key[:1] in "+-" and len(key) > 1:
        key = ("plus_" if key[0] == "+" else "minus_") + key[1:]
    return key.replace(" ", "_")


def flatten(summary: dict) -> dict[str, Any]:
    """Every number (and boolean) of a nested summary as one column, the unit at the end.

    ``{"max_bias_um": {"+x": 90}}`` gives ``max_bias_plus_x_um``; ``{"global_minimum":
    {"x_um": 0}}`` gives ``global_minimum_x_um``; ``{"restoring_force_N": {"+x": [fx, fy]}}``
    gives ``restoring_force_plus_x_x_N`` and ``..._y_N``; a new key such as
    ``{"stiffness": {"x_N_per_m": k}}`` gives ``stiffness_x_N_per_m``. Strings, None and
    lists of lists (plateaus) are left out.
    """
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
    b = summary.get("max_bias_um") or {}
    for axis in ("x", "y"):
        ends = [b.get(f"+{axis}"), b.get(f"-{axis}")]
        if all(isinstance(e, int | float) for e in ends):
            out[f"max_bias_{axis}_um"] = float(min(ends))
    g = summary.get("global_minimum") or {}
    if isinstance(g.get("x_um"), int | float) and isinstance(g.get("y_um"), int | float):
        out["global_minimum_offset_um"] = float(math.hypot(g["x_um"], g["y_um"]))
    fl = summary.get("floating_range")
    if isinstance(fl, dict):  # free contact lines: the chip floats on the well's floor
        out["floating_half_width_um"] = float(
            max(fl["x_to_um"] - fl["x_from_um"], fl["y_to_um"] - fl["y_from_um"]) / 2
        )
    return out
