"""The value kinds of the scene schema (:mod:`simulator.scene`): numbers with intervals and
units, integers, booleans, text, choices, file paths, poses, sizes and start ranges, and the
limits they enforce. Each kind checks one value and says what is allowed in one line."""

from __future__ import annotations

import datetime
import math
import re
from dataclasses import dataclass
from typing import Any

from patterns import show_value
from patterns.layout import DXF_UNITS as LAYOUT_DXF_UNITS
from simulator.core import MAX_TWIST_DEG

# ----------------------------------------------------------------------- limits
#: Largest scene file read (bytes); real scenes are under 2 KB.
MAX_SCENE_BYTES = 1 << 20
#: Deepest nesting of tables and arrays (the document is level 1, ``[materials]``
#: level 2, the ``[montecarlo] grid`` list level 3).
MAX_DEPTH = 8
#: Most elements of one array (and keys of one table).
MAX_ARRAY_ITEMS = 10_000
#: Longest path string (characters).
MAX_PATH_CHARS = 4096

#: Largest length and |position| (um): one metre.
MAX_UM = 1e6
#: Largest seed (numpy's default_rng takes any int >= 0; 64 bits is plenty).
MAX_SEED = 2**63 - 1

# ----------------------------------------------------------------------- choices
#: The landscape's precisions (:attr:`simulator.scene.Scene.dtype`).
DTYPES = ("float32", "float64")
#: The accuracy presets, by name (the keys of :data:`simulator.scene.PRESETS`, which needs
#: numpy and shapely; tests/test_schema.py checks they agree).
ACCURACY_PRESETS = ("fast", "balanced", "precise")
#: A DXF file's units, as ``--dxf-units`` takes them (the keys of :data:`patterns.layout.DXF_UNITS`).
DXF_UNITS = tuple(LAYOUT_DXF_UNITS)
# The trajectory and batch methods, the placements' distributions, the step, chunk, start
# and twist limits are simulator.core's (METHODS, BATCH_METHODS, DISTRIBUTIONS,
# MAX_STEPS_LIMIT, MAX_CHUNK, MAX_STARTS, MAX_TWIST_DEG) and the dispense protocols
# simulator.physics' (DISPENSE_CHOICES): the schema and the scene's parameters import them
# from there, no copy is kept here.


# ----------------------------------------------------------------------- helpers
def _fmt(x: float) -> str:
    """A bound as people write it: 180, 0.5, 1e6, 2147483646."""
    if isinstance(x, int):
        return str(x)
    if x.is_integer() and abs(x) < 1e5:
        return str(int(x))
    return re.sub(r"e([+-])0*(\d)", lambda m: "e" + ("-" if m[1] == "-" else "") + m[2], f"{x:g}")


def _is_number(v: Any) -> bool:
    """int or float, not bool, finite (a huge int is finite: no float() on it)."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return False
    return isinstance(v, int) or math.isfinite(v)


def _type_name(v: Any) -> str:
    """What ``v`` is, in TOML words."""
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, int):
        return "an integer"
    if isinstance(v, float):
        return "a float" if math.isfinite(v) else "a non-finite float"
    if isinstance(v, str):
        return "a string"
    if isinstance(v, list | tuple):
        return "an array"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, datetime.date | datetime.time):
        return "a date-time"
    return f"a {type(v).__name__}"


def _got(v: Any) -> str:
    """', got a string' etc.; a numeric-looking string gets a hint to drop the quotes."""
    if isinstance(v, str):
        try:
            float(v)
        except ValueError:
            return ", got a string"
        return ", got a string (write numbers without quotes)"
    return f", got {_type_name(v)}"


@dataclass(frozen=True)
class Bounds:
    """An interval of allowed numbers, e.g. ``Bounds.parse("(0, 1e4]")`` (finite ends)."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False

    @classmethod
    def parse(cls, text: str) -> Bounds:
        m = re.fullmatch(r"\s*([\[(])\s*([^,\s]+)\s*,\s*([^,\s]+)\s*([\])])\s*", text)
        if not m:
            raise ValueError(
                f"interval {text!r}: write it as [lo, hi], (lo, hi], [lo, hi) or (lo, hi)"
            )

        def num(t: str) -> float:
            try:
                return int(t)
            except ValueError:
                return float(t)

        b = cls(num(m[2]), num(m[3]), m[1] == "(", m[4] == ")")
        if not (math.isfinite(b.lo) and math.isfinite(b.hi) and b.lo <= b.hi):
            raise ValueError(f"interval {text!r} must have finite ends, lo <= hi")
        return b

    def __contains__(self, v: float) -> bool:
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return above and below

    def text(self, unit: str = "") -> str:
        u = f" {unit}" if unit else ""
        if not (self.lo_open or self.hi_open):
            return f"from {_fmt(self.lo)} to {_fmt(self.hi)}{u}"
        return f"{'>' if self.lo_open else '>='} {_fmt(self.lo)} and {'<' if self.hi_open else '<='} {_fmt(self.hi)}{u}"


# ----------------------------------------------------------------------- kinds
class Kind:
    """What one key's value must be. ``check`` returns None when fine, else the rule broken."""

    def check(self, value: Any) -> str | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError


@dataclass(frozen=True)
class Number(Kind):
    """An int or float (not a boolean), finite, in ``bounds``, in ``unit``."""

    bounds: Bounds
    unit: str = ""

    def describe(self) -> str:
        return f"must be a number {self.bounds.text(self.unit)}"

    def check(self, value: Any) -> str | None:
        if not _is_number(value):
            return self.describe() + _got(value)
        return None if value in self.bounds else self.describe()


@dataclass(frozen=True)
class Integer(Kind):
    """A whole number (TOML integer, not a boolean) in ``bounds``.

    ``whole_floats``: also take a float with no fraction (``random = 1e6``, as the CLI's
    ``--random 1e6``).
    """

    bounds: Bounds
    unit: str = ""
    whole_floats: bool = False

    def describe(self) -> str:
        return f"must be a whole number {self.bounds.text(self.unit)}"

    def check(self, value: Any) -> str | None:
        if (
            isinstance(value, float)
            and _is_number(value)
            and value.is_integer()
            and self.whole_floats
        ):
            return None if value in self.bounds else self.describe()
        if isinstance(value, float) and _is_number(value):
            return self.describe() + " (an integer, no decimal point)"
        if isinstance(value, bool) or not isinstance(value, int):
            return self.describe() + _got(value)
        return None if value in self.bounds else self.describe()


@dataclass(frozen=True)
class Bool(Kind):
    """``true`` or ``false``: never a string ("false" is truthy) or a number."""

    def describe(self) -> str:
        return "must be true or false (a TOML boolean, unquoted)"

    def check(self, value: Any) -> str | None:
        return None if isinstance(value, bool) else self.describe()


@dataclass(frozen=True)
class Text(Kind):
    """A one-line string of at most ``max_chars`` characters."""

    max_chars: int = 200

    def describe(self) -> str:
        return f"must be a one-line quoted string of at most {self.max_chars} characters"

    def check(self, value: Any) -> str | None:
        if not isinstance(value, str):
            return self.describe() + _got(value)
        ok = len(value) <= self.max_chars and value.isprintable()
        return None if ok else self.describe()


@dataclass(frozen=True)
class Choice(Kind):
    """One of ``choices`` (strings)."""

    choices: tuple[str, ...]

    def describe(self) -> str:
        return "must be one of " + ", ".join(f'"{c}"' for c in self.choices)

    def check(self, value: Any) -> str | None:
        if isinstance(value, str) and value in self.choices:
            return None
        return self.describe() + ("" if isinstance(value, str) else _got(value))


@dataclass(frozen=True)
class FilePath(Kind):
    """A file path as a non-empty string (relative to the scene file)."""

    what: str = "a file"

    def describe(self) -> str:
        return f"must be the path of {self.what} as a quoted string (relative to the scene file)"

    def check(self, value: Any) -> str | None:
        if not isinstance(value, str):
            return self.describe() + _got(value)
        if not value.strip():
            return self.describe() + ", got an empty string"
        if len(value) > MAX_PATH_CHARS or "\x00" in value:
            return (
                self.describe() + f" of at most {MAX_PATH_CHARS} characters, without NUL characters"
            )
        return None


def _split_numbers(text: str, sep: str) -> list[float] | None:
    """'1, 2,3' -> [1.0, 2.0, 3.0] (finite), else None."""
    try:
        vals = [float(p) for p in text.split(sep)]
    except ValueError:
        return None
    return vals if all(math.isfinite(v) for v in vals) else None


@dataclass(frozen=True)
class Pose(Kind):
    """Three numbers ``[x, y, twist]``, each in its own range and unit.

    ``text_ok``: also take the command-line form ``"X,Y,TWIST"`` (``[montecarlo]``
    passes its values to the flag parsers as text).
    """

    parts: tuple[tuple[str, Number], ...]
    text_ok: bool = False

    def describe(self) -> str:
        names = ", ".join(n for n, _ in self.parts)
        units = ", ".join(k.unit for _, k in self.parts)
        text = f' or the text "{names.upper().replace(" ", "")}"' if self.text_ok else ""
        return f"must be [{names}]: {len(self.parts)} numbers ({units}){text}"

    def check(self, value: Any) -> str | None:
        if self.text_ok and isinstance(value, str):
            parsed = _split_numbers(value, ",")
            if parsed is None or len(parsed) != len(self.parts):
                return self.describe()
            value = parsed
        if not isinstance(value, list | tuple):
            return self.describe() + _got(value)
        if len(value) != len(self.parts):
            return self.describe() + f"; got {len(value)} elements"
        for (name, kind), v in zip(self.parts, value, strict=True):
            if kind.check(v):
                return f"{self.describe()}; {name} {kind.describe()}, got {show_value(v, 30)}"
        return None


@dataclass(frozen=True)
class Size(Kind):
    """A chip size: one number W (a square) or ``[W, H]``, each in ``side``."""

    side: Number

    def describe(self) -> str:
        return f"must be W or [W, H]: {self.side.describe().removeprefix('must be ')} each"

    def check(self, value: Any) -> str | None:
        if isinstance(value, list | tuple):
            if len(value) != 2 or any(self.side.check(v) for v in value):
                return self.describe()
            return None
        if self.side.check(value):
            return self.describe() + ("" if _is_number(value) else _got(value))
        return None


@dataclass(frozen=True)
class StartRanges(Kind):
    """A start grid: ``"X0:X1:DX,Y0:Y1:DY[,TWISTS]"`` or a list of 2 or 3 axes.

    Each axis is one value or ``START:STOP:STEP`` (stop included, step > 0); in a list,
    an axis is a number or such a text. ``axes`` gives each axis's name and range.
    """

    axes: tuple[tuple[str, Number], ...]

    def describe(self) -> str:
        units = ", ".join(k.unit for _, k in self.axes)
        return (
            f'must be "X0:X1:DX,Y0:Y1:DY[,TWISTS]" ({units}; ends included) or a list of 2 or 3 axes, '
            'each a number or "START:STOP:STEP" text'
        )

    def _axis(self, name: str, kind: Number, spec: Any) -> str | None:
        if _is_number(spec):
            vals: list[float] | None = [spec]
        elif isinstance(spec, str):
            vals = _split_numbers(spec.strip(), ":")
        else:
            return f"{self.describe()}; the {name} axis is {_type_name(spec)}"
        rule = f"{self.describe()}; {name} values {kind.bounds.text(kind.unit)}"
        if vals is None or len(vals) not in (1, 3):
            return f"{self.describe()}; the {name} axis {show_value(spec, 30)} is not one number or START:STOP:STEP"
        if any(v not in kind.bounds for v in vals[:2]):
            return rule
        if len(vals) == 3:
            a, b, d = vals
            if not (d > 0 and b >= a):
                return f"{self.describe()}; the {name} axis needs STEP > 0 and STOP >= START, got {show_value(spec, 30)}"
        return None

    def check(self, value: Any) -> str | None:
        if isinstance(value, str):
            value = value.split(",")
        if not isinstance(value, list | tuple):
            return self.describe() + _got(value)
        if len(value) not in (2, 3):
            return self.describe() + f"; got {len(value)} axes"
        for (name, kind), spec in zip(self.axes, value, strict=False):
            problem = self._axis(name, kind, spec)
            if problem:
                return problem
        return None


# ----------------------------------------------------------------------- shared kinds
def number(interval: str, unit: str = "") -> Number:
    """``number("(0, 1e4]", "mN/m")``: a finite number in that interval."""
    return Number(Bounds.parse(interval), unit)


def integer(interval: str, unit: str = "", whole_floats: bool = False) -> Integer:
    """``integer("[1, 1e9]")``: a whole number in that interval."""
    return Integer(Bounds.parse(interval), unit, whole_floats)


BOOL = Bool()
LENGTH_UM = number(f"(0, {MAX_UM:g}]", "um")
POSITION_UM = number(f"[-{MAX_UM:g}, {MAX_UM:g}]", "um")
TWIST_DEG = number(f"[-{MAX_TWIST_DEG}, {MAX_TWIST_DEG}]", "deg")
CONTACT_ANGLE_DEG = number("[0, 180]", "deg")
SURFACE_TENSION_MN_M = number("(0, 1e4]", "mN/m")  # water 72.8, mercury 485
