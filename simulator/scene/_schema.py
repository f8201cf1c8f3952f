"""A strict, declarative schema of TOML scene files, with one-line errors.

:data:`SCHEMA` lists, per section (``None`` is the top level), every key a scene file
may hold and what its value must be: a TOML type (numbers unquoted, booleans
``true``/``false``), a range with its unit, or a set of choices. :func:`validate_scene`
checks a parsed document against it and raises :class:`~foundation.InputError`
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

The scene's own keys (every section but ``[simulate]`` and ``[montecarlo]``) are its
parameters' (:data:`simulator.scene._params.SCENE_PARAMS`): adding one is one record there,
which gives it its flag too. Adding a key of ``[simulate]`` or ``[montecarlo]`` is one line
in :data:`SCHEMA`; adding a section is one more entry. The ranges are meant to be no
stricter than what the code downstream accepts (the dataclass validators and the
command parsers), but finite: they stop nonsense early, with the key's name, and the
downstream checks still apply. Checks across keys (``min_deg`` <= ``max_deg``, one of
``chip`` / ``chip_size_um``, repulsive pads, ...) stay downstream.

The methods and the limits of steps and chunks are :mod:`simulator.core`'s and the dispense
protocols :mod:`simulator.physics`', imported, not copied; the Monte Carlo distributions and
the most starts stay copies of :mod:`simulator.batch`'s (a package above this one), which
``tests/test_schema.py`` checks agree.
"""

from __future__ import annotations

import difflib
import os
import re
import stat
import tomllib
from typing import Any

from foundation import InputError
from patterns import check_nesting, show_key, show_value

__all__ = ["SCHEMA", "read_scene_file", "validate_scene"]

from simulator.core import (
    BATCH_METHODS as MONTECARLO_METHODS,
    DISTRIBUTIONS as DISTRIBUTIONS,
    MAX_CHUNK as MAX_CHUNK,
    MAX_STARTS as MAX_STARTS,
    MAX_STEPS_LIMIT as MAX_STEPS,
    MAX_TWIST_DEG as MAX_TWIST_DEG,
    METHODS as SIMULATE_METHODS,
)
from simulator.physics import DISPENSE_CHOICES as DISPENSE  # noqa: F401 (as the tests read it)
from simulator.scene._params import scene_tables
from simulator.scene._schema_kinds import (
    ACCURACY_PRESETS as ACCURACY_PRESETS,  # the choices the tests compare with the code's
    DTYPES as DTYPES,
    DXF_UNITS as DXF_UNITS,
    MAX_ARRAY_ITEMS,
    MAX_DEPTH,
    MAX_SCENE_BYTES,
    MAX_SEED,
    MAX_UM,
    POSITION_UM,
    TWIST_DEG,
    Bool as Bool,  # the kinds, on this module as the tests read them
    Bounds as Bounds,
    Choice,
    FilePath as FilePath,
    Integer as Integer,
    Kind,
    Number as Number,
    Pose,
    Size as Size,
    StartRanges,
    Text as Text,
    integer,
    number,
)

MAX_STEPS_KIND = integer(f"[1, {MAX_STEPS}]")
START_POSE = Pose((("x", POSITION_UM), ("y", POSITION_UM), ("twist", TWIST_DEG)))

#: Every key of a scene file, per section (None = top level): what its value must be.
SCHEMA: dict[str | None, dict[str, Kind]] = {
    **scene_tables(),  # the scene's keys, one declaration each (simulator.scene._params)
    "simulate": {
        "start": START_POSE,
        "method": Choice(SIMULATE_METHODS),
        "max_steps": MAX_STEPS_KIND,
    },
    "montecarlo": {
        "grid": StartRanges((("x", POSITION_UM), ("y", POSITION_UM), ("twist", TWIST_DEG))),
        "random": integer(f"[1, {MAX_STARTS:g}]", whole_floats=True),  # 1e6 as --random 1e6
        "spread": Pose(
            (
                ("sx", number(f"[0, {MAX_UM:g}]", "um")),
                ("sy", number(f"[0, {MAX_UM:g}]", "um")),
                ("stwist", number(f"[0, {MAX_TWIST_DEG}]", "deg")),
            ),
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
                raise InputError(
                    f"{src}: {key} = {show_value(value)}: must be a table ([{key}] with keys {', '.join(keys)})"
                )
            for sub, v in value.items():
                if sub not in keys:
                    raise InputError(
                        f"{src}: [{key}] {show_key(sub)} = {show_value(v)}: unknown key{_suggest(sub, list(keys))}; "
                        f"[{key}] takes {', '.join(keys)}"
                    )
                _check(src, key, sub, v, keys[sub])
        elif isinstance(value, dict):
            sections = [s for s in SCHEMA if s is not None]
            raise InputError(
                f"{src}: [{show_key(key)}]: unknown section{_suggest(key, sections)}; sections are {_sections_text()}"
            )
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
        text = "".join(
            c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text
        )
    return text if len(text) <= 300 else text[:297] + "..."


def _one_line(text: object) -> str:
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
        raise InputError(
            f"scene file {shown} cannot be read ({err.strerror or _one_line(err)})"
        ) from None
    with os.fdopen(fd, "rb") as f:
        why = _kind_of(os.fstat(f.fileno()).st_mode)
        if why:
            raise InputError(f"scene file {shown} {why}")
        try:
            data = f.read(MAX_SCENE_BYTES + 1)
        except OSError as err:
            raise InputError(
                f"scene file {shown} cannot be read ({err.strerror or _one_line(err)})"
            ) from None
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
        raise InputError(
            f"scene file {shown} is not a usable scene: a dotted key or table header has more than {MAX_DEPTH} parts"
        )
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
            raise InputError(
                f"scene file {shown} is not a usable scene: an integer has more than 4300 digits"
            ) from None
        raise InputError(f"scene file {shown} is not valid TOML: {_one_line(err)[:200]}") from None
    hit = check_nesting(doc, MAX_DEPTH, MAX_ARRAY_ITEMS)
    if hit:
        where, problem = hit
        raise InputError(f"scene file {shown} is not a usable scene: {where} {problem}")
    validate_scene(doc, source=shown)
    return doc
