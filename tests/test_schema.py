"""The scene-file schema (simulator.scene) and the PNG metadata note (patterns).

Regression tests named after the bugs they pin: string booleans read as True, unknown
[simulate] keys ignored, wrong types, and files that crashed or hung the TOML reader
(a 10000-digit integer, 5000-deep arrays, a 25-million-element array, a FIFO).
"""

import contextlib
import dataclasses
import json
import math
import os
import tempfile
import threading
import tomllib
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st
from PIL import Image

from foundation import InputError
from patterns import (
    MAX_PARAMS_CHARS,
    MAX_PARAMS_DEPTH,
    MAX_PARAMS_ITEMS,
    check_nesting,
    parse_png_params,
    show_value,
    validate_png_params,
)
from simulator.scene import (
    MAX_ARRAY_ITEMS,
    MAX_DEPTH,
    MAX_SCENE_BYTES,
    SCHEMA,
    _schema as schema,
    read_scene_file,
    validate_scene,
)

ROOT = Path(__file__).resolve().parent.parent
# Scene files; the sweep file (a scene inside a [scene] table) is checked by tests/test_sweep.py.
#: The scene files of examples/ (sweep and design files are not scenes: their tests load them).
EXAMPLES = sorted(
    p for p in (ROOT / "examples").glob("*.toml") if not p.name.startswith(("sweep_", "design_"))
)
LIBRARY_PNGS = sorted((ROOT / "patterns" / "library").glob("*.png"))


def refused(doc, *needles, source="scene.toml"):
    """The one-line InputError message validate_scene gives for ``doc``; it holds every needle."""
    with pytest.raises(InputError) as info:
        validate_scene(doc, source)
    msg = str(info.value)
    assert len(msg.splitlines()) == 1 and "\n" not in msg and "\r" not in msg, msg
    assert msg.startswith(f"{source}: "), msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    return msg


def file_refused(path, *needles, before="validation"):
    """The file is refused with one line; ``before`` names the stage it must not reach:
    ``"parse"`` (tomllib never sees it) or ``"read"`` (its bytes are never read).

    These stages, not times, are what the tests assert: how fast each refusal is belongs
    to ``benchmarks/refusals.py`` (timed assertions flake on a shared machine)."""
    import tracemalloc
    from unittest import mock

    def parsed(_text):
        raise AssertionError("the file was parsed before it was refused")

    with (
        mock.patch.object(schema.tomllib, "loads", parsed)
        if before in ("parse", "read")
        else contextlib.nullcontext()
    ):
        tracemalloc.start()
        try:
            with pytest.raises(InputError) as info:
                read_scene_file(path)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
    msg = str(info.value)
    assert len(msg.splitlines()) == 1, msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    if before == "read":
        assert peak < os.path.getsize(path) / 10, f"{peak:,} bytes allocated: the file was read"
    return msg


def write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# ------------------------------------------------------------- valid files stay valid
@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_validates(path):
    assert len(EXAMPLES) >= 5
    doc = read_scene_file(path)
    assert doc == tomllib.loads(path.read_text())
    assert validate_scene(doc, path.name) is None


def _readme_scene_block() -> str:
    text = (
        ROOT / "docs" / "guide" / "scenes.md"
    ).read_text()  # the README's "Scenes as files", moved to the manual
    start = text.index("Keys (all optional except")
    block = text[
        text.index("```toml", start) + len("```toml") : text.index(
            "```", text.index("```toml", start) + 7
        )
    ]
    assert "[montecarlo]" in block
    return block


@pytest.mark.parametrize(
    "text",
    [
        # tests/test_scene.py: test_from_toml_with_every_table
        'pattern = "fp.png"\nchip_size_um = [200, 100]\ndtype = "float64"\nwindow_um = 150\n'
        "[materials]\nsurface_tension_mN_m = 50\npad_angle_deg = 20\nsubstrate_angle_deg = 100\n"
        "[twist]\nstep_deg = 2\nmin_deg = -10\nmax_deg = 10\n[effects]\ntwist = true\n"
        "[liquid]\nvolume_nl = 0.5\nviscosity_mPa_s = 2\n",
        # tests/test_simulate_cli.py: test_scene_file_and_flag_override
        'pattern = "/x/square_200.png"\nchip_size_um = [200, 200]\n[simulate]\nstart = [30, 0, 0]\nmethod = "greedy"\n',
        # README: the CLI's --random/--spread/--grid forms as TOML
        '[montecarlo]\nrandom = 1e6\nspread = "40,40,5"\naround = [-60, 0, 0]\ndistribution = "uniform"\nseed = 3\nchunk = 512\n',
        '[montecarlo]\ngrid = "-220:220:4,-220:220:4"\nmethod = "gradient"\nmax_steps = 100\n',
        '[montecarlo]\ngrid = ["-400:400:20", "-400:400:20", "-10:10:5"]\n',
        '[montecarlo]\ngrid = [0, "-5:5:1", 3]\n',
        'pattern = "a.png"\nchip = "chip.png"\num_per_px = 0.5\nresolution_um = 2\naccuracy = "precise"\nmax_image_mpx = 100\n'
        '[liquid]\nname = "glycerol 50 %"\nsurface_tension_mN_m = 68\ndensity_kg_m3 = 1130\n[effects]\ntwist = false\n'
        "[materials]\nallow_repulsive = true\npad_angle_deg = 90\nsubstrate_angle_deg = 30\n",
        _readme_scene_block(),
    ],
)
def test_scenes_written_by_tests_and_docs_validate(tmp_path, text):
    assert isinstance(read_scene_file(write(tmp_path, text)), dict)


def test_choices_and_limits_match_the_code_downstream():
    from simulator.core import (
        BATCH_METHODS,
        DISTRIBUTIONS,
        MAX_CHUNK,
        MAX_STARTS,
        MAX_STEPS_LIMIT,
        MAX_TWIST_DEG,
        METHODS,
    )
    from simulator.scene import DTYPES, PRESETS

    assert schema.DTYPES == DTYPES
    assert schema.ACCURACY_PRESETS == tuple(PRESETS)
    assert schema.SIMULATE_METHODS == METHODS
    assert schema.MONTECARLO_METHODS == BATCH_METHODS
    assert schema.DISTRIBUTIONS == DISTRIBUTIONS
    from simulator.physics import DISPENSE_CHOICES

    assert schema.DISPENSE == DISPENSE_CHOICES
    assert schema.MAX_STARTS == MAX_STARTS
    assert schema.MAX_STEPS == MAX_STEPS_LIMIT
    assert schema.MAX_CHUNK == MAX_CHUNK
    assert schema.MAX_TWIST_DEG == MAX_TWIST_DEG


def test_sections_cover_the_dataclass_fields():
    from simulator.physics import Liquid, Materials
    from simulator.scene import Effects, TwistGrid

    def toml_names(cls):
        rename = {
            "surface_tension_N_m": "surface_tension_mN_m",
            "viscosity_Pa_s": "viscosity_mPa_s",
            "height_um": "meniscus_height_um",
        }
        # volume_derived records that the scene derived the volume from the chip: set by the
        # scene, never a key of the file
        derived = {"volume_derived"}
        return {rename.get(f.name, f.name) for f in dataclasses.fields(cls)} - derived

    assert set(SCHEMA["materials"]) == toml_names(Materials)
    assert set(SCHEMA["liquid"]) == toml_names(Liquid)
    assert set(SCHEMA["twist"]) == toml_names(TwistGrid)
    assert set(SCHEMA["effects"]) == toml_names(Effects)
    assert {"pattern", "chip", "chip_size_um", "accuracy", "dtype"} <= set(SCHEMA[None])


# ------------------------------------------------------------- the reported bugs
def test_allow_repulsive_string_false_is_refused():
    msg = refused(
        {"materials": {"allow_repulsive": "false"}},
        '[materials] allow_repulsive = "false"',
        "true or false",
    )
    assert (
        msg
        == 'scene.toml: [materials] allow_repulsive = "false": must be true or false (a TOML boolean, unquoted)'
    )
    validate_scene({"materials": {"allow_repulsive": False}})


def test_effects_twist_string_no_is_refused():
    refused({"effects": {"twist": "no"}}, '[effects] twist = "no"', "a TOML boolean")
    refused({"effects": {"twist": 0}}, "[effects] twist = 0", "true or false")


def test_allow_repulsive_string_in_a_file_is_refused(tmp_path):
    p = write(tmp_path, '[materials]\nallow_repulsive = "false"\n')
    msg = file_refused(p, "[materials] allow_repulsive", '"false"')
    assert msg.startswith(f"{p}: ")


def test_unknown_simulate_key_metod_is_refused():
    refused(
        {"simulate": {"metod": "gradient"}},
        '[simulate] metod = "gradient"',
        "unknown key",
        "did you mean method?",
        "start, method, max_steps",
    )


@pytest.mark.parametrize(
    "doc, needles",
    [
        (
            {"materials": {"surface_tension_mN_m": "water"}},
            ['[materials] surface_tension_mN_m = "water"', "number", "mN/m", "got a string"],
        ),
        ({"materials": {"surface_tension_mN_m": "72.8"}}, ["without quotes"]),
        ({"chip_size_um": [1, 2, 3]}, ["chip_size_um = [1, 2, 3]", "W or [W, H]", "um"]),
        ({"pattern": 42}, ["pattern = 42", "path", "quoted string", "got an integer"]),
        ({"materials": {"pad_angle_deg": 200}}, ["pad_angle_deg = 200", "from 0 to 180 deg"]),
        ({"materials": {"surface_tension_mN_m": 0}}, ["> 0 and <= 10000 mN/m"]),
        ({"twist": {"step_deg": 91}}, ["[twist] step_deg = 91", "> 0 and <= 90 deg"]),
        ({"window_um": float("inf")}, ["window_um = inf", "non-finite"]),
        ({"window_um": True}, ["window_um = true", "got a boolean"]),
        ({"liquid": {"volume_nl": -1}}, ["[liquid] volume_nl = -1", "nl"]),
        (
            {"simulate": {"max_steps": 0}},
            ["[simulate] max_steps = 0", "whole number from 1 to 2147483646"],
        ),
        ({"simulate": {"max_steps": 10.0}}, ["no decimal point"]),
        (
            {"simulate": {"start": [1, 2]}},
            ["[simulate] start = [1, 2]", "[x, y, twist]", "got 2 elements"],
        ),
        ({"simulate": {"start": [0, 0, 4000]}}, ["twist must be a number from -3600 to 3600 deg"]),
        ({"simulate": {"method": "newton"}}, ['"greedy", "gradient", "overdamped", "inertial"']),
        (
            {"montecarlo": {"method": "newton"}},
            ['must be one of "greedy", "gradient", "overdamped", "inertial"'],
        ),
        ({"montecarlo": {"random": 2.5}}, ["[montecarlo] random = 2.5", "whole number"]),
        ({"montecarlo": {"random": 0}}, ["from 1 to 1e8"]),
        ({"montecarlo": {"seed": -1}}, ["[montecarlo] seed = -1", "from 0 to"]),
        ({"montecarlo": {"spread": [1, -2, 3]}}, ["sy must be a number from 0 to"]),
        ({"montecarlo": {"grid": "-200:200:-10,0"}}, ["STEP > 0"]),
        ({"montecarlo": {"grid": "1,2,3,4"}}, ["got 4 axes"]),
        ({"montecarlo": {"grid": "a:b:c,0"}}, ["START:STOP:STEP"]),
        ({"montecarlo": {"chunk": 2**40}}, ["[montecarlo] chunk"]),
        ({"dtype": "float16"}, ['dtype = "float16"', '"float32", "float64"']),
        ({"accuracy": "best"}, ['"fast", "balanced", "precise"']),
        ({"liquid": {"name": "a\nb"}}, ['[liquid] name = "a\\nb"', "one-line"]),
        ({"materials": 3}, ["materials = 3", "must be a table", "pad_angle_deg"]),
        ({"simulate": [1, 2, 3]}, ["simulate = [1, 2, 3]", "must be a table"]),
        ({"colour": 3}, ["colour = 3", "unknown key", "top-level keys are pattern"]),
        ({"patern": "a.png"}, ["did you mean pattern?"]),
        (
            {"simulat": {"start": [0, 0, 0]}},
            ["[simulat]", "unknown section", "did you mean simulate?"],
        ),
        (
            {"twist": {"steps": 3}},
            ["[twist] steps = 3", "unknown key", "step_deg, min_deg, max_deg"],
        ),
        ({"window_um": 10**5000}, ["window_um = <a whole number of about", "digits>"]),
    ],
)
def test_wrong_values_give_one_line_naming_the_key(doc, needles):
    refused(doc, *needles)


def test_long_values_are_shortened():
    msg = refused({"pattern": ["x" * 10_000] * 1000}, "pattern = [")
    assert len(msg) < 400
    assert len(refused({"k" * 10_000: 1}, "unknown key")) < 800


def test_first_problem_in_document_order():
    refused({"dtype": "f", "pattern": 1}, "dtype =")
    refused({"pattern": 1, "dtype": "f"}, "pattern =")


def test_10000_digit_integer(tmp_path):
    p = write(tmp_path, "window_um = " + "9" * 10_000 + "\n")
    file_refused(p, str(p), "integer", "4300 digits")


def test_5000_deep_toml_array(tmp_path):
    p = write(tmp_path, "x = " + "[" * 5000 + "]" * 5000 + "\n")
    file_refused(p, str(p), "nested too deeply")
    p = write(tmp_path, "x = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n", "inline.toml")
    file_refused(p, "nested too deeply")


def test_nesting_over_max_depth_is_refused_after_parsing(tmp_path):
    p = write(tmp_path, "x = " + "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1) + "\n")
    file_refused(p, "x[0]", "levels deep", f"at most {MAX_DEPTH}")
    ok = "[montecarlo]\ngrid = " + "[" * (MAX_DEPTH - 2) + "]" * (MAX_DEPTH - 2) + "\n"
    file_refused(write(tmp_path, ok, "ok.toml"), "[montecarlo] grid")  # depth fine, value wrong


def test_dotted_key_with_thousands_of_parts_refused_fast(tmp_path):
    # tomllib is quadratic in the parts of a dotted key: 500k parts would take hours.
    for name, text in [
        ("dotted", "x" + ".a" * 200_000 + " = 1\n"),
        ("header", "[" + ".".join(["a"] * 200_000) + "]\n"),
        ("quoted", "x" + '."a b"' * 100_000 + " = 1\n"),
    ]:
        file_refused(
            write(tmp_path, text, f"{name}.toml"),
            "dotted key or table header",
            f"more than {MAX_DEPTH} parts",
            before="parse",
        )
    # dots inside strings, comments and floats are not keys
    text = 'pattern = "a.b.c.d.e.f.g.h.i.j.k.png"  # a.b.c.d.e.f.g.h.i.j.k\nwindow_um = 1.5\n[twist]\nstep_deg = 0.5\n'
    assert read_scene_file(write(tmp_path, text))["window_um"] == 1.5


def test_25_million_element_array_refused_fast(tmp_path):
    p = tmp_path / "big.toml"
    with open(p, "wb") as f:  # x = [0,0,...] with 25e6 elements: 50 MB
        f.write(b"x = [")
        chunk = b"0," * 1_000_000
        for _ in range(25):
            f.write(chunk)
        f.write(b"]\n")
    size = p.stat().st_size
    msg = file_refused(p, f"{size:,} bytes", f"at most {MAX_SCENE_BYTES:,} bytes", before="read")
    assert "1 MiB" in msg


def test_array_over_item_limit_within_size_limit(tmp_path):
    n = MAX_ARRAY_ITEMS * 2
    p = write(tmp_path, "[montecarlo]\nspread = [" + "0," * n + "]\n")
    assert p.stat().st_size < MAX_SCENE_BYTES
    file_refused(p, "montecarlo.spread", f"{n:,} elements", f"at most {MAX_ARRAY_ITEMS:,}")


def test_fifo_scene_file_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    result = {}

    def read():
        try:
            read_scene_file(fifo)
        except InputError as err:
            result["msg"] = str(err)

    t = threading.Thread(target=read, daemon=True)
    t.start()
    t.join(timeout=60)  # a bound for a hang, not a speed target: the refusal is immediate
    if t.is_alive():  # blocked in open(): release it with a writer, then fail
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
        t.join(timeout=5)
        pytest.fail("read_scene_file blocked on a FIFO")
    assert "FIFO" in result["msg"] and str(fifo) in result["msg"]
    assert len(result["msg"].splitlines()) == 1


def test_missing_directory_device_and_bad_bytes(tmp_path):
    file_refused(tmp_path / "nope.toml", "does not exist")
    file_refused(tmp_path / "nope" / "deeper.toml", "does not exist")
    file_refused(tmp_path, "is a directory")
    if os.path.exists("/dev/null"):
        file_refused("/dev/null", "is a device")
    p = tmp_path / "latin1.toml"
    p.write_bytes('pattern = "caf\xe9.png"\n'.encode("latin-1"))
    file_refused(p, "not valid TOML", "UTF-8", "0xe9")
    file_refused(write(tmp_path, "this is [not toml"), "not valid TOML")
    file_refused(str(tmp_path / "a\x00b.toml"), "cannot be read")


def test_utf8_bom_and_non_ascii_are_accepted(tmp_path):
    p = tmp_path / "bom.toml"
    p.write_bytes('\ufeffpattern = "café.png"\n[liquid]\nname = "éthanol"\n'.encode())
    assert read_scene_file(p)["liquid"]["name"] == "éthanol"


def test_unreadable_file(tmp_path, monkeypatch):
    p = write(tmp_path, 'pattern = "a.png"\n')
    real_open = os.open

    def denied(path, *a, **k):  # as for a chmod 0 file (root reads those, so refuse here)
        if os.fspath(path) == os.fspath(p):
            raise PermissionError(13, "Permission denied", os.fspath(path))
        return real_open(path, *a, **k)

    monkeypatch.setattr(os, "open", denied)
    file_refused(p, "permission denied")


# ------------------------------------------------------------- properties
SCALARS = (
    st.booleans()
    | st.integers()
    | st.integers(min_value=-(10**400), max_value=10**400)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=30)
    | st.datetimes()
    | st.dates()
    | st.none()
)


def nested(leaves, keys, depth: int = 3, size: int = 4):
    """Values nested up to ``depth`` levels of lists and tables over ``leaves``: written out
    level by level (Hypothesis 6.170's ``st.recursive`` warns, now and then, that a lambda
    extend "doesn't use its argument", and this suite turns warnings into errors)."""
    level = leaves
    for _ in range(depth):
        level = (
            leaves | st.lists(level, max_size=size) | st.dictionaries(keys, level, max_size=size)
        )
    return level


VALUES = nested(SCALARS, st.text(max_size=10), depth=3, size=4)
PLACES = [(section, key) for section, keys in SCHEMA.items() for key in keys]


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(st.sampled_from(PLACES), VALUES), min_size=1, max_size=4),
    st.dictionaries(st.text(max_size=12), VALUES, max_size=2),
)
def test_property_any_value_under_a_known_key_is_ok_or_one_line_error(placed, extra):
    doc = dict(extra)
    for (section, key), value in placed:
        if section is None:
            doc[key] = value
        else:
            table = doc.get(section)
            if not isinstance(table, dict):
                table = doc[section] = {}
            table[key] = value
    try:
        assert validate_scene(doc, "s.toml") is None
    except InputError as err:
        msg = str(err)
        assert len(msg.splitlines()) == 1 and "\n" not in msg, msg
        assert msg.startswith("s.toml: ") and len(msg) < 1200


def _valid_value(kind):
    """A strategy of values ``kind`` accepts."""
    if isinstance(kind, schema.Number):
        b = kind.bounds
        return st.floats(b.lo, b.hi, exclude_min=b.lo_open, exclude_max=b.hi_open, allow_nan=False)
    if isinstance(kind, schema.Integer):
        b = kind.bounds
        return st.integers(int(b.lo), int(b.hi))
    if isinstance(kind, schema.Bool):
        return st.booleans()
    if isinstance(kind, schema.Choice):
        return st.sampled_from(kind.choices)
    if isinstance(kind, schema.FilePath):
        return st.text(min_size=1, max_size=20).filter(lambda s: s.strip() and "\x00" not in s)
    if isinstance(kind, schema.Text):
        return st.text(max_size=20).filter(str.isprintable)
    if isinstance(kind, schema.Pose):
        return st.tuples(*(_valid_value(k) for _, k in kind.parts)).map(list)
    if isinstance(kind, schema.Size):
        return _valid_value(kind.side) | st.lists(_valid_value(kind.side), min_size=2, max_size=2)
    if isinstance(kind, schema.StartRanges):
        return st.just("-10:10:2,0,-5:5:1") | st.just([0, "-3:3:1"])
    raise AssertionError(f"no strategy for {kind!r}")


@settings(max_examples=100, deadline=None)
@given(st.data())
def test_property_values_inside_the_table_validate(data):
    doc = {}
    for section, keys in SCHEMA.items():
        for key, kind in keys.items():
            if data.draw(st.booleans()):
                value = data.draw(_valid_value(kind))
                (doc if section is None else doc.setdefault(section, {}))[key] = value
    assert validate_scene(doc) is None


@settings(max_examples=200, deadline=None)
@given(
    st.text(max_size=200)
    | st.sampled_from(["[a]\nb = [[[[[[[[[[1]]]]]]]]]]", "x = {a = {b = {c = 1}}}", 'a."b".c = 1'])
)
def test_property_any_file_text_gives_a_dict_or_one_line_error(text):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.toml"
        p.write_bytes(text.encode("utf-8", "replace"))  # lone surrogates become "?"
        try:
            assert isinstance(read_scene_file(p), dict)
        except InputError as err:
            assert len(str(err).splitlines()) == 1, str(err)


# ------------------------------------------------------------- helpers
def test_show_value_and_check_nesting_are_bounded():
    assert (
        show_value("false") == '"false"'
        and show_value(True) == "true"
        and show_value(float("nan")) == "nan"
    )
    assert show_value("a\u2028b\x85c").count("\\") == 2  # Unicode line breaks escaped
    deep: list = []
    node = deep
    for _ in range(100_000):  # far past the recursion limit
        node.append([])
        node = node[0]
    assert len(show_value(deep)) <= 60
    found = check_nesting({"a": deep}, 8, 10)
    assert found is not None
    where, problem = found
    assert where.startswith("a[0]") and "levels deep" in problem
    assert check_nesting({"a": [1, 2]}, 8, 10) is None
    found = check_nesting([0] * 11, 8, 10)
    assert found is not None
    assert found[1] == "has 11 elements; at most 10"


def test_bounds_parse():
    b = schema.Bounds.parse("(0, 1e4]")
    assert 0 not in b and 1e-300 in b and 1e4 in b and 1e4 + 1 not in b
    assert b.text("mN/m") == "> 0 and <= 10000 mN/m"
    assert schema.Bounds.parse("[0, 180]").text("deg") == "from 0 to 180 deg"
    with pytest.raises(ValueError):
        schema.Bounds.parse("0..1")
    with pytest.raises(ValueError):
        schema.Bounds.parse("[0, inf]")


# ------------------------------------------------------------- PNG metadata
PNG = "pattern.png"


def png_refused(func, arg, *needles):
    with pytest.raises(InputError) as info:
        func(arg, PNG)
    msg = str(info.value)
    assert len(msg.splitlines()) == 1 and msg.startswith(f"{PNG}: "), msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    return msg


def test_deeply_nested_png_json():
    png_refused(parse_png_params, "[" * 60_000, "nested too deeply")  # json.loads: RecursionError
    png_refused(parse_png_params, '{"a": ' + "[" * 20_000 + "]" * 20_000 + "}", "nested too deeply")
    depth = MAX_PARAMS_DEPTH + 1
    png_refused(
        parse_png_params,
        '{"a": ' + "[" * depth + "]" * depth + "}",
        "selfalign metadata a[0]",
        "levels deep",
    )
    assert parse_png_params(
        '{"a": ' + "[" * (MAX_PARAMS_DEPTH - 1) + "]" * (MAX_PARAMS_DEPTH - 1) + "}", PNG
    )


def test_png_note_that_is_not_a_json_object_is_ignored():
    for text in ["", "not json", "{broken", "[1, 2]", '"text"', "3", "null", None, b"{}"]:
        assert parse_png_params(text, PNG) == {}


def test_png_note_limits():
    png_refused(
        parse_png_params, '{"a": "' + "x" * MAX_PARAMS_CHARS + '"}', f"at most {MAX_PARAMS_CHARS:,}"
    )
    png_refused(parse_png_params, '{"seed": ' + "1" * 5000 + "}", "too many digits")
    n = MAX_PARAMS_ITEMS + 1
    png_refused(
        parse_png_params,
        json.dumps({"a": [0] * n}, separators=(",", ":")),
        "selfalign metadata a",
        f"{n:,} elements",
    )


@pytest.mark.parametrize(
    "note, needles",
    [
        ({"um_per_px": "1"}, ['um_per_px = "1"', "finite number > 0"]),
        ({"um_per_px": float("nan")}, ["um_per_px = nan"]),
        ({"um_per_px": True}, ["um_per_px = true"]),
        ({"width_um": float("inf")}, ["width_um = inf"]),
        ({"height_um": -1}, ["height_um = -1"]),
        ({"design": 3}, ["design = 3", "string"]),
        ({"parameters": []}, ["parameters = []", "JSON object"]),
        ({"parameters": {"gap": 50}}, ["parameters.gap = 50", "JSON object"]),
        (
            {"parameters": {"gap": {"value": "wide"}}},
            ['parameters.gap.value = "wide"', "finite number >= 0"],
        ),
        ({"parameters": {"gap": {"value": float("-inf")}}}, ["parameters.gap.value = -inf"]),
    ],
)
def test_png_note_wrong_types_name_file_and_key(note, needles):
    png_refused(validate_png_params, note, *needles)
    png_refused(
        parse_png_params, json.dumps(note), *needles
    )  # NaN/Infinity survive json.dumps/loads


def test_png_note_unknown_keys_are_kept():
    note = {
        "design": "x",
        "gap": 5,
        "custom": {"nested": [1, "two", None]},
        "area_um2": float("nan"),
        "parameters": {
            "gap": {"value": 50.0, "unit": "um"},
            "points": {"value": [[0, 0], [1, 2]], "unit": "um"},
        },
    }
    assert validate_png_params(note, PNG) is not note
    out = parse_png_params(json.dumps(note), PNG)
    assert out["custom"] == note["custom"] and math.isnan(out["area_um2"]) and out["gap"] == 5
    png_refused(validate_png_params, [note], "must be a JSON object")


def test_png_note_of_a_polygon_with_many_vertices_is_read():
    points = [
        [round(100 * math.cos(i / 800), 6), round(100 * math.sin(i / 800), 6)] for i in range(5000)
    ]
    note = {
        "design": "polygon",
        "parameters": {"points": {"value": points, "unit": "um"}},
        "um_per_px": 1.0,
    }
    text = json.dumps(note)
    assert len(text) > 64 * 1024
    assert parse_png_params(text, PNG)["parameters"]["points"]["value"][4999] == points[4999]


@pytest.mark.parametrize("path", LIBRARY_PNGS, ids=[p.name for p in LIBRARY_PNGS])
def test_library_png_notes_validate(path):
    with Image.open(path) as im:
        text = im.info.get("selfalign")
    params = parse_png_params(text, path)
    assert (params == {}) == (text is None)
    if params:
        assert params["um_per_px"] > 0 and isinstance(params["design"], str)


def test_note_written_by_write_mask_reads_back(tmp_path):
    from patterns import write_mask
    from patterns.geometry import design_record, four_pad, mask_from_geometry

    record = design_record("four-pad", size=200, gap=20)
    path = write_mask(
        tmp_path / "fp.png", mask_from_geometry(four_pad(200, 20), 2.0, params=record)
    )
    with Image.open(path) as im:
        params = parse_png_params(im.info["selfalign"], path)
    assert params["um_per_px"] == 2.0 and params["parameters"]["gap"]["value"] == 20


@settings(max_examples=200, deadline=None)
@given(
    nested(
        st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=10),
        st.sampled_from(
            ["um_per_px", "design", "width_um", "height_um", "parameters", "gap", "value", "x"]
        ),
        depth=3,
        size=3,
    )
)
def test_property_png_note_gives_a_dict_or_one_line_error(obj):
    try:
        out = parse_png_params(json.dumps(obj), PNG)
    except InputError as err:
        assert len(str(err).splitlines()) == 1 and str(err).startswith(f"{PNG}: ")
    else:
        assert out == {} or isinstance(obj, dict)
