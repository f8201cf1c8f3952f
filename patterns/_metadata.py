"""The ``selfalign`` PNG text chunk (JSON provenance), parsed and checked with one-line errors.

:func:`write_mask <patterns.write_mask>` stores the parameters that generated a pattern
as JSON in a PNG text chunk; :func:`parse_png_params` reads it back. The note is
provenance, so a note that is not JSON at all, or not a JSON object, is ignored (``{}``)
and never makes the image unusable. A note that *is* an object must be sane, because
the tool reads some of its keys (:data:`PNG_KEYS`): a wrong type, a NaN or an infinity
there, a note over :data:`MAX_PARAMS_CHARS` characters, or one nested deeper than
:data:`MAX_PARAMS_DEPTH` (deep JSON makes ``json.loads`` raise RecursionError) raises
:class:`~foundation.InputError` naming the PNG file and the key. Unknown keys are
kept as they are.

Also here, because both the scene schema (:mod:`simulator.scene`) and this module
need them and ``patterns`` is the lower layer: :func:`show_value` (a short one-line
rendering of a value for messages) and :func:`check_nesting` (an iterative depth and
size check of parsed JSON/TOML data).
"""

from __future__ import annotations

import datetime
import json
import math
import os
import re
from collections.abc import Callable
from typing import Any

from foundation import InputError

__all__ = [
    "MAX_PARAMS_CHARS",
    "MAX_PARAMS_DEPTH",
    "MAX_PARAMS_ITEMS",
    "PNG_KEYS",
    "check_nesting",
    "parse_png_params",
    "show_key",
    "show_value",
    "validate_png_params",
]

#: Longest ``selfalign`` note read (characters). The tool writes a few hundred, a
#: polygon design with many vertices tens of thousands; Pillow itself refuses a text
#: chunk over 1 MiB (``PngImagePlugin.MAX_TEXT_CHUNK``), so this is that limit.
MAX_PARAMS_CHARS = 1 << 20
#: Deepest nesting of objects/arrays in the note (the note itself is level 1;
#: ``parameters -> gap -> value`` reaches level 3, a list of points level 5).
MAX_PARAMS_DEPTH = 8
#: Most elements of one array or keys of one object in the note (a polygon's vertices).
MAX_PARAMS_ITEMS = 100_000

#: Longest rendering of a value in a message (characters).
SHOW_CHARS = 60


# ----------------------------------------------------------------- shared helpers
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _escape(text: str) -> str:
    """``text`` quoted, with every non-printable character escaped (so it stays on one line)."""
    body = "".join(
        c
        if c.isprintable() and c not in '"\\'
        else ("\\" + c if c in '"\\' else c.encode("unicode_escape").decode("ascii"))
        for c in text
    )
    return f'"{body}"'


def _shorten(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def show_key(key: Any, limit: int = SHOW_CHARS) -> str:
    """A key as TOML writes it: bare when it can be, else quoted; shortened, one line."""
    limit = max(limit, 8)
    if isinstance(key, str) and _BARE_KEY.fullmatch(key[: limit + 1]) and len(key) <= limit:
        return key
    if isinstance(key, str):
        return _shorten(_escape(key[: limit + 1]), limit)
    return _shorten(show_value(key), limit)


def _render(value: Any, budget: int, depth: int) -> str:
    """TOML-like text of ``value``, stopping early once ``budget`` characters are reached."""
    budget = max(budget, 8)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        if value.bit_length() > 200:  # str() of a huge int is slow, and raises past 4300 digits
            return f"<a {'negative ' if value < 0 else ''}whole number of about {int(value.bit_length() * 0.30103):,} digits>"
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _escape(value[: budget + 1])
    if isinstance(value, datetime.date | datetime.time):
        return value.isoformat()
    if value is None:
        return "null"
    if isinstance(value, list | tuple | dict):
        if depth >= 4:
            return "[...]" if not isinstance(value, dict) else "{...}"
        items = value.items() if isinstance(value, dict) else value
        opening, closing = ("{", "}") if isinstance(value, dict) else ("[", "]")
        parts, used = [], 1
        for item in items:
            if used > budget:
                parts.append("...")
                break
            if isinstance(value, dict):
                k, v = item
                text = f"{show_key(k, budget)} = {_render(v, budget - used, depth + 1)}"
            else:
                text = _render(item, budget - used, depth + 1)
            parts.append(text)
            used += len(text) + 2
        return opening + ", ".join(parts) + closing
    return f"<{type(value).__name__}>"


def show_value(value: Any, limit: int = SHOW_CHARS) -> str:
    """``value`` as one short line (TOML-like: ``true``, ``"text"``, ``[1, 2]``), at most ``limit`` chars."""
    return _shorten(_render(value, limit, 0), limit)


def check_nesting(obj: Any, max_depth: int, max_items: int) -> tuple[str, str] | None:
    """The first container nested deeper than ``max_depth`` or holding more than ``max_items``.

    ``obj`` itself is level 1 when it is a list, tuple or dict. Iterative (no
    recursion), so any depth is safe. Returns ``(key path, problem)`` or None.
    """
    stack: list[tuple[Any, str, int]] = [(obj, "", 1)]
    while stack:
        node, where, depth = stack.pop()
        if not isinstance(node, dict | list | tuple):
            continue
        label = where or "the document"
        if depth > max_depth:
            return (
                label,
                f"is nested {depth} levels deep (arrays and tables inside each other); at most {max_depth}",
            )
        if len(node) > max_items:
            what = "keys" if isinstance(node, dict) else "elements"
            return label, f"has {len(node):,} {what}; at most {max_items:,}"
        if isinstance(node, dict):
            children = [
                (v, f"{where}.{show_key(k, 40)}" if where else show_key(k, 40), depth + 1)
                for k, v in node.items()
            ]
        else:
            children = [(v, f"{where}[{i}]", depth + 1) for i, v in enumerate(node)]
        stack.extend(reversed(children))
    return None


# ----------------------------------------------------------------- PNG keys
def _number(lo: float, hi: float, unit: str, lo_open: bool = True) -> Callable[[Any], str | None]:
    low = f"> {lo:g}" if lo_open else f">= {lo:g}"
    rule = f"must be a finite number {low} and <= {hi:g} {unit}".rstrip()

    def check(v: Any) -> str | None:
        ok = (
            isinstance(v, int | float)
            and not isinstance(v, bool)
            and (isinstance(v, int) or math.isfinite(v))
        )
        ok = ok and (v > lo if lo_open else v >= lo) and v <= hi
        return None if ok else rule

    return check


def _text(max_chars: int) -> Callable[[Any], str | None]:
    def check(v: Any) -> str | None:
        return (
            None
            if isinstance(v, str) and len(v) <= max_chars
            else f"must be a string of at most {max_chars} characters"
        )

    return check


def _object(keys: dict[str, Any]) -> dict[str, Any]:
    return keys


#: Keys of the note that the tool reads, and what each must be (unknown keys are kept
#: as provenance). A dict value is a nested JSON object checked the same way; a
#: callable returns None when the value is fine, else the rule it breaks.
#: ``io._scale_from_file`` reads ``um_per_px``; ``render`` reads ``design``,
#: ``width_um`` and ``height_um`` (a chip); ``commands.demo`` reads
#: ``parameters.gap.value``.
PNG_KEYS: dict[str, Any] = {
    "um_per_px": _number(0, 1e6, "um per px"),
    "design": _text(200),
    "width_um": _number(0, 1e6, "um"),
    "height_um": _number(0, 1e6, "um"),
    "parameters": _object({"gap": _object({"value": _number(0, 1e6, "um", lo_open=False)})}),
}


def _fail(path: os.PathLike | str, key: str, value: Any, rule: str) -> InputError:
    return InputError(
        f"{path}: selfalign metadata {key} = {show_value(value)}: {rule}; rewrite the PNG with `selfalign pattern` or remove its selfalign text chunk"
    )


def _check_object(obj: dict, spec: dict[str, Any], prefix: str, path: os.PathLike | str) -> None:
    for key, rule in spec.items():
        if key not in obj:
            continue
        value, name = obj[key], f"{prefix}{key}"
        if isinstance(rule, dict):
            if not isinstance(value, dict):
                raise _fail(path, name, value, "must be a JSON object")
            _check_object(value, rule, name + ".", path)
        else:
            problem = rule(value)
            if problem:
                raise _fail(path, name, value, problem)


def validate_png_params(params: object, path: os.PathLike | str) -> dict:
    """``params`` (the decoded ``selfalign`` note of PNG ``path``) as a dict, checked.

    Raises InputError naming ``path`` and the key when ``params`` is not an object,
    is nested too deep or too large, or a key of :data:`PNG_KEYS` has a wrong type or
    a value out of range (NaN and infinity included). Unknown keys are kept.
    """
    if not isinstance(params, dict):
        raise InputError(
            f"{path}: selfalign metadata must be a JSON object, got {show_value(params)}"
        )
    hit = check_nesting(params, MAX_PARAMS_DEPTH, MAX_PARAMS_ITEMS)
    if hit:
        where, problem = hit
        raise InputError(f"{path}: selfalign metadata {where} {problem}")
    _check_object(params, PNG_KEYS, "", path)
    return dict(params)


def parse_png_params(text: object, path: os.PathLike | str) -> dict:
    """The ``selfalign`` note of PNG ``path`` (JSON text) as a checked dict.

    Returns ``{}`` when ``text`` is not a string, not JSON, or JSON but not an object
    (a damaged note is ignored). Raises InputError for a note over
    :data:`MAX_PARAMS_CHARS` characters, nested deeper than :data:`MAX_PARAMS_DEPTH`,
    holding a number with too many digits, or failing :func:`validate_png_params`.
    """
    if not isinstance(text, str):
        return {}
    if len(text) > MAX_PARAMS_CHARS:
        raise InputError(
            f"{path}: its selfalign metadata note is {len(text):,} characters; at most {MAX_PARAMS_CHARS:,} are read"
        )
    try:
        params = json.loads(text)
    except json.JSONDecodeError:
        return {}  # provenance only: a damaged note does not make the image unusable
    except RecursionError:
        raise InputError(
            f"{path}: its selfalign metadata note is nested too deeply (more than {MAX_PARAMS_DEPTH} levels)"
        ) from None
    except ValueError as err:  # an integer past Python's int-string limit
        raise InputError(
            f"{path}: its selfalign metadata note holds a number with too many digits ({_shorten(str(err), 80)})"
        ) from None
    if not isinstance(params, dict):
        return {}
    return validate_png_params(params, path)
