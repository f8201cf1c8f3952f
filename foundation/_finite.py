"""Every number an output holds is finite, or the run fails with one line.

JSON, CSV and the report carry no NaN or infinity: :func:`require_finite` walks a
result before it is written and names the first non-finite value by its key path.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from foundation._errors import InputError


def first_non_finite(obj: Any, path: str = "") -> tuple[str, float] | None:
    """(key path, value) of the first NaN or infinity in ``obj`` (dicts, lists, arrays, numbers)."""
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return None
    if isinstance(obj, int | np.integer):
        return None
    if isinstance(obj, float | np.floating):
        return None if math.isfinite(obj) else (path or "value", float(obj))
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in "fc" and not np.all(np.isfinite(obj)):
            i = int(np.flatnonzero(~np.isfinite(obj.ravel()))[0])
            return f"{path}[{i}]", float(obj.ravel()[i])
        return None
    if isinstance(obj, dict):
        for k, v in obj.items():
            hit = first_non_finite(v, f"{path}.{k}" if path else str(k))
            if hit:
                return hit
        return None
    if isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            hit = first_non_finite(v, f"{path}[{i}]")
            if hit:
                return hit
    return None


def require_finite(obj: Any, what: str) -> Any:
    """``obj`` unchanged if every number in it is finite, else InputError naming the value."""
    hit = first_non_finite(obj)
    if hit:
        key, value = hit
        raise InputError(
            f"{what}: {key} is {value} (not a finite number), so nothing was written; the scene's numbers are outside "
            "what the model can compute (check the volume, angles and scale)"
        )
    return obj
