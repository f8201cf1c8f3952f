"""A strict, declarative schema of TOML scene files, with one-line errors.

:data:`SCHEMA` lists, per section (``None`` is the top level), every key a scene file
may hold and what its value must be: a TOML type (numbers unquoted, booleans
``true``/``false``), a range with its unit, or a set of choices. :func:`validate_scene`
checks a parsed document against it and raises :class:`~patterns.errors.InputError`
for the first problem, in one line that names the key with its section, shows the
value and says what is allowed, e.g.::

    scene.toml: [materials] allow_repulsive = "false": must be true or false (a TOML boolean, unquoted)

:func:`read_scene_file` reads and parses a file safely first: a missing file, a
directory, a FIFO or a device is refused before anything opens it (a FIFO would block
the read forever); so is a file over :data:`MAX_SCENE_BYTES`; TOML that Python's
parser cannot handle (an integer past Python's int-string limit, arrays nested
thousands deep, a dotted key with thousands of parts, which parses in quadratic time)
and data nested deeper than :data:`MAX_DEPTH` or with more than
:data:`MAX_ARRAY_ITEMS` elements in one array become one-line errors too.

Adding a key is one line in :data:`SCHEMA` (e.g. ``"meniscus": BOOL`` under
``"effects"``); adding a section is one more entry. The ranges are meant to be no
stricter than what the code downstream accepts (the dataclass validators and the
command parsers), but finite: they stop nonsense early, with the key's name, and the
downstream checks still apply. Checks across keys (``min_deg`` <= ``max_deg``, one of
``chip`` / ``chip_size_um``, repulsive pads, ...) stay downstream.

The choices are copies of :data:`simulator.trajectory.METHODS` and friends, kept here
so this module imports nothing heavy (and no import cycle with :mod:`simulator.scene`);
``tests/test_schema.py`` checks that they agree.
"""

from __future__ import annotations

import datetime
import difflib
import math
import os
import re
import stat
import tomllib
from dataclasses import dataclass
from typing import Any

from patterns.errors import InputError
from patterns.metadata import (
    check_nesting,
    parse_png_params,
    show_key,
    show_value,
    validate_png_params,
)

__all__ = [
    "MAX_ARRAY_ITEMS",
    "MAX_DEPTH",
    "MAX_SCENE_BYTES",
    "SCHEMA",
    "Kind",
    "parse_png_params",
    "read_scene_file",
    "validate_png_params",
    "validate_scene",
]

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
#: Largest |twist| (degrees), as :class:`simulator.scene.TwistGrid` and the start checks.
MAX_TWIST_DEG = 3600
#: Largest max_steps (:data:`simulator.trajectory.MAX_STEPS_LIMIT`: int32 step counters).
MAX_STEPS = 2**31 - 2
#: Most Monte Carlo starts (:data:`simulator.montecarlo.MAX_STARTS`).
MAX_STARTS = 10**8
#: Largest Monte Carlo chunk (:data:`simulator.montecarlo.MAX_CHUNK`).
MAX_CHUNK = 2**20
#: Largest seed (numpy's default_rng takes any int >= 0; 64 bits is plenty).
MAX_SEED = 2**63 - 1

# Copies of the choices downstream (tests/test_schema.py checks they agree).
DTYPES = ("float32", "float64")  # simulator.scene.DTYPES
ACCURACY_PRESETS = ("fast", "balanced", "precise")  # simulator.accuracy.PRESETS
SIMULATE_METHODS = ("greedy", "gradient", "overdamped", "inertial")  # simulator.trajectory.METHODS
MONTECARLO_METHODS = ("greedy", "gradient")  # simulator.montecarlo.METHODS
DISTRIBUTIONS = ("normal", "uniform")  # simulator.montecarlo.DISTRIBUTIONS
DXF_UNITS = ("um", "mm", "nm")  # patterns.layout.DXF_UNITS


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
            raise ValueError(f"interval {text!r}: write it as [lo, hi], (lo, hi], [lo, hi) or (lo, hi)")

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
        if isinstance(value, float) and _is_number(value) and value.is_integer() and self.whole_floats:
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
            return self.describe() + f" of at most {MAX_PATH_CHARS} characters, without NUL characters"
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
        return (f'must be "X0:X1:DX,Y0:Y1:DY[,TWISTS]" ({units}; ends included) or a list of 2 or 3 axes, '
                'each a number or "START:STOP:STEP" text')

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


# ----------------------------------------------------------------------- the table
def number(interval: str, unit: str = "") -> Number:
    """``number("(0, 1e4]", "mN/m")``: a finite number in that interval."""
    return Number(Bounds.parse(interval), unit)


def integer(interval: str, unit: str = "", whole_floats: bool = False) -> Integer:
    return Integer(Bounds.parse(interval), unit, whole_floats)


BOOL = Bool()
LENGTH_UM = number(f"(0, {MAX_UM:g}]", "um")
POSITION_UM = number(f"[-{MAX_UM:g}, {MAX_UM:g}]", "um")
TWIST_DEG = number(f"[-{MAX_TWIST_DEG}, {MAX_TWIST_DEG}]", "deg")
CONTACT_ANGLE_DEG = number("[0, 180]", "deg")
SURFACE_TENSION_MN_M = number("(0, 1e4]", "mN/m")  # water 72.8, mercury 485
MAX_STEPS_KIND = integer(f"[1, {MAX_STEPS}]")
START_POSE = Pose((("x", POSITION_UM), ("y", POSITION_UM), ("twist", TWIST_DEG)))

#: Every key of a scene file, per section (None = top level): what its value must be.
SCHEMA: dict[str | None, dict[str, Kind]] = {
    None: {
        "pattern": FilePath("the pattern image (PNG) or layout (.gds, .oas, .dxf)"),
        "chip": FilePath("the chip footprint image (PNG) or layout"),
        "layer": Text(200),  # layout pattern layer "L/D" (DXF: the layer name); checked by patterns.layout
        "cell": Text(200),
        "chip_layer": Text(200),
        "dxf_units": Choice(DXF_UNITS),
        "chip_size_um": Size(LENGTH_UM),
        "um_per_px": number(f"(0, {MAX_UM:g}]", "um per px"),  # as write_mask's pHYs range
        "resolution_um": number(f"(0, {MAX_UM:g}]", "um per px"),
        "dtype": Choice(DTYPES),
        "window_um": LENGTH_UM,
        "memory_budget_mb": number("(0, 1e9]", "MB"),  # downstream also caps it at the machine's memory
        "max_image_mpx": number("(0, 1e6]", "megapixels"),
        "accuracy": Choice(ACCURACY_PRESETS),
        "chip_thickness_um": LENGTH_UM,
        "chip_density_kg_m3": number("(0, 1e6]", "kg/m^3"),  # osmium 22590
        "damping_calibration": number("(0, 1e9]"),  # default 1000
    },
    "materials": {
        "surface_tension_mN_m": SURFACE_TENSION_MN_M,
        "pad_angle_deg": CONTACT_ANGLE_DEG,
        "substrate_angle_deg": CONTACT_ANGLE_DEG,
        "allow_repulsive": BOOL,
    },
    "twist": {
        "step_deg": number("(0, 90]", "deg"),
        "min_deg": TWIST_DEG,
        "max_deg": TWIST_DEG,
    },
    "effects": {
        "twist": BOOL,
    },
    "liquid": {
        "name": Text(200),
        "surface_tension_mN_m": SURFACE_TENSION_MN_M,
        "viscosity_mPa_s": number("(0, 1e9]", "mPa s"),  # water 1, glycerol 1400
        "density_kg_m3": number("(0, 1e6]", "kg/m^3"),
        "volume_nl": number("(0, 1e9]", "nl"),  # 1e9 nl = 1 litre
    },
    "simulate": {
        "start": START_POSE,
        "method": Choice(SIMULATE_METHODS),
        "max_steps": MAX_STEPS_KIND,
    },
    "montecarlo": {
        "grid": StartRanges((("x", POSITION_UM), ("y", POSITION_UM), ("twist", TWIST_DEG))),
        "random": integer(f"[1, {MAX_STARTS:g}]", whole_floats=True),  # 1e6 as --random 1e6
        "spread": Pose(
            (("sx", number(f"[0, {MAX_UM:g}]", "um")), ("sy", number(f"[0, {MAX_UM:g}]", "um")),
             ("stwist", number(f"[0, {MAX_TWIST_DEG}]", "deg"))),
            text_ok=True,
        ),
        "around": Pose(START_POSE.parts, text_ok=True),
        "distribution": Choice(DISTRIBUTIONS),
        "seed": integer(f"[0, {MAX_SEED}]"),
        "method": Choice(MONTECARLO_METHODS),
        "max_steps": MAX_STEPS_KIND,
        "chunk": integer(f"[1, {MAX_CHUNK}]"),
    },
}


# ----------------------------------------------------------------------- validation
def _suggest(key: Any, candidates: list[str]) -> str:
    if not isinstance(key, str):
        return ""
    close = difflib.get_close_matches(key[:60], candidates, n=1, cutoff=0.6)
    return f" (did you mean {close[0]}?)" if close else ""


def _sections_text() -> str:
    return ", ".join(f"[{s}]" for s in SCHEMA if s is not None)


def validate_scene(doc: dict, source: str = "scene") -> None:
    """Raise InputError for the first key of ``doc`` (a parsed scene file) that breaks :data:`SCHEMA`.

    The message is one line: ``{source}: [section] key = value: what is allowed``.
    Keys are checked in the document's order; nothing is returned or changed.
    """
    src = _display(source)
    if not isinstance(doc, dict):
        raise InputError(f"{src}: a scene must be a table of keys, got {show_value(doc)}")
    top = SCHEMA[None]
    for key, value in doc.items():
        if key in top:
            _check(src, None, key, value, top[key])
        elif key in SCHEMA and key is not None:
            keys = SCHEMA[key]
            if not isinstance(value, dict):
                raise InputError(f"{src}: {key} = {show_value(value)}: must be a table ([{key}] with keys {', '.join(keys)})")
            for sub, v in value.items():
                if sub not in keys:
                    raise InputError(
                        f"{src}: [{key}] {show_key(sub)} = {show_value(v)}: unknown key{_suggest(sub, list(keys))}; "
                        f"[{key}] takes {', '.join(keys)}"
                    )
                _check(src, key, sub, v, keys[sub])
        elif isinstance(value, dict):
            sections = [s for s in SCHEMA if s is not None]
            raise InputError(f"{src}: [{show_key(key)}]: unknown section{_suggest(key, sections)}; sections are {_sections_text()}")
        else:
            raise InputError(
                f"{src}: {show_key(key)} = {show_value(value)}: unknown key{_suggest(key, list(top))}; "
                f"top-level keys are {', '.join(top)} (and the sections {_sections_text()})"
            )


def _check(src: str, section: str | None, key: str, value: Any, kind: Kind) -> None:
    problem = kind.check(value)
    if problem:
        where = key if section is None else f"[{section}] {key}"
        raise InputError(f"{src}: {where} = {show_value(value)}: {problem}")


# ----------------------------------------------------------------------- reading
def _display(path: Any) -> str:
    """A path (or source name) as one printable line."""
    text = os.fsdecode(path) if isinstance(path, str | bytes | os.PathLike) else str(path)
    if not text.isprintable():
        text = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
    return text if len(text) <= 300 else text[:297] + "..."


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


#: A string (every form; an unterminated one to its end of line or of text) or a comment.
#: Each alternative matches whenever its first character does, so the scan is linear.
_STRING_OR_COMMENT = re.compile(
    r'"""[^"\\]*+(?:(?:\\[\s\S]|"(?!""))[^"\\]*+)*+(?:"""|\\?\Z)'
    r"|'''[\s\S]*?(?:'''|\Z)"
    r'|"[^"\\\n]*+(?:\\.[^"\\\n]*+)*+(?:"|\\?$)'
    r"|'[^'\n]*+(?:'|$)"
    r"|#[^\n]*+",
    re.MULTILINE,
)
#: A bare-key chain with MAX_DEPTH or more dots (only dotted keys and headers have more than one).
_LONG_CHAIN = re.compile(r"(?<![\w-])[\w-]++(?:[ \t]*+\.[ \t]*+[\w-]++){" + str(MAX_DEPTH) + ",}")


def _without_strings(text: str) -> str:
    """``text`` with every string replaced by ``s`` and every comment dropped (linear time)."""
    return _STRING_OR_COMMENT.sub(lambda m: "" if m[0][0] == "#" else "s", text)


def _too_many_key_parts(text: str) -> bool:
    """Whether a dotted key or table header has more than MAX_DEPTH parts.

    tomllib takes time quadratic in the parts of a dotted key (1 MB of ``a.a.a...``
    would take hours), so this is checked before parsing.
    """
    return _LONG_CHAIN.search(_without_strings(text)) is not None


def _kind_of(mode: int) -> str | None:
    """Why a file of this mode is not a scene file, or None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a directory, not a TOML file"
    if stat.S_ISFIFO(mode):
        return "is a named pipe (FIFO), not a regular file; save the scene to a .toml file and give that"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "is a device, not a regular file; give a .toml file"
    if stat.S_ISSOCK(mode):
        return "is a socket, not a regular file; give a .toml file"
    return "is not a regular file; give a .toml file"


def _size_error(shown: str, size: int) -> InputError:
    return InputError(
        f"scene file {shown} is {size:,} bytes; a scene file may be at most {MAX_SCENE_BYTES:,} bytes "
        f"({MAX_SCENE_BYTES / 2**20:g} MiB)"
    )


def read_scene_file(path: str | os.PathLike) -> dict[str, Any]:
    """Read, parse and validate a TOML scene file; every failure is a one-line InputError.

    Refuses, before opening it, anything that is not a regular file (missing, a
    directory, a FIFO, a device) and files over :data:`MAX_SCENE_BYTES`; then decodes
    UTF-8, parses with :mod:`tomllib`, enforces :data:`MAX_DEPTH` and
    :data:`MAX_ARRAY_ITEMS`, and calls :func:`validate_scene`. Returns the document.
    """
    shown = _display(path)
    try:
        st = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise InputError(f"scene file {shown} does not exist") from None
    except PermissionError:
        raise InputError(f"scene file {shown} cannot be read: permission denied") from None
    except (OSError, ValueError) as err:  # ValueError: a NUL in the path
        reason = err.strerror if isinstance(err, OSError) and err.strerror else _one_line(err)
        raise InputError(f"scene file {shown} cannot be read ({reason})") from None
    why = _kind_of(st.st_mode)
    if why:
        raise InputError(f"scene file {shown} {why}")
    if st.st_size > MAX_SCENE_BYTES:
        raise _size_error(shown, st.st_size)
    try:  # O_NONBLOCK: should the path become a FIFO after the stat, open does not block
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
    except PermissionError:
        raise InputError(f"scene file {shown} cannot be read: permission denied") from None
    except OSError as err:
        raise InputError(f"scene file {shown} cannot be read ({err.strerror or _one_line(err)})") from None
    with os.fdopen(fd, "rb") as f:
        why = _kind_of(os.fstat(f.fileno()).st_mode)
        if why:
            raise InputError(f"scene file {shown} {why}")
        try:
            data = f.read(MAX_SCENE_BYTES + 1)
        except OSError as err:
            raise InputError(f"scene file {shown} cannot be read ({err.strerror or _one_line(err)})") from None
    if len(data) > MAX_SCENE_BYTES:
        raise _size_error(shown, len(data))
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise InputError(
            f"scene file {shown} is not valid TOML: not UTF-8 text (byte 0x{data[err.start]:02x} at offset {err.start}); save it as UTF-8"
        ) from None
    text = text.removeprefix("\ufeff")  # a byte-order mark from some editors
    if _too_many_key_parts(text):
        raise InputError(f"scene file {shown} is not a usable scene: a dotted key or table header has more than {MAX_DEPTH} parts")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise InputError(f"scene file {shown} is not valid TOML: {_one_line(err)}") from None
    except RecursionError:
        raise InputError(
            f"scene file {shown} is not a usable scene: arrays or inline tables nested too deeply (more than {MAX_DEPTH} levels)"
        ) from None
    except ValueError as err:
        if "integer string conversion" in str(err):
            raise InputError(f"scene file {shown} is not a usable scene: an integer has more than 4300 digits") from None
        raise InputError(f"scene file {shown} is not valid TOML: {_one_line(err)[:200]}") from None
    hit = check_nesting(doc, MAX_DEPTH, MAX_ARRAY_ITEMS)
    if hit:
        where, problem = hit
        raise InputError(f"scene file {shown} is not a usable scene: {where} {problem}")
    validate_scene(doc, source=shown)
    return doc
