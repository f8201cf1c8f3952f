"""The scene's parameters, each declared once (:data:`simulator.scene.SCENE_PARAMS`).

Every flag reaches its document key and the scene's attribute; the schema's scene sections,
the keys :meth:`Scene.from_dict` knows, the sweep's scene axes and the design search's
baseline are the registry's; no choice or limit of the schema differs from its home's.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
from pathlib import Path
from typing import TypeVar

import numpy as np
import pytest
from PIL import Image

from foundation import InputError
from simulator.cli import build_parser
from simulator.commands._request import SceneRequest
from simulator.commands._scene import scene_document_from_args
from simulator.scene import FLAG_GROUPS, SCENE_PARAMS, SCHEMA, Scene, Size, sweep_places
from simulator.scene._schema_kinds import Choice, Integer, Kind

#: Sections of a scene file that are not the scene's parameters (a command's own).
COMMAND_SECTIONS = ("simulate", "montecarlo")


def _place(p):
    return (p.table, p.key)


def test_each_parameter_is_declared_once():
    places = [_place(p) for p in SCENE_PARAMS]
    flags = [p.flag for p in SCENE_PARAMS if p.flag]
    names = [p.axis for p in SCENE_PARAMS]
    assert len(set(places)) == len(places)
    assert len(set(flags)) == len(flags)
    assert len(set(names)) == len(names)
    for p in SCENE_PARAMS:
        assert (p.flag is None) == (p.group == ""), p
        assert p.flag is None or (p.group in FLAG_GROUPS) == bool(p.help_text()), p


def test_the_schemas_scene_sections_are_the_registry():
    scene = {s: keys for s, keys in SCHEMA.items() if s not in COMMAND_SECTIONS}
    assert {(s, k): kind for s, keys in scene.items() for k, kind in keys.items()} == {
        _place(p): p.kind for p in SCENE_PARAMS
    }


# ----------------------------------------------------------------------- the round trip
@pytest.fixture(scope="module")
def pattern_png(tmp_path_factory):
    """A 60 x 60 px pattern (a 30 px pad), no stored scale."""
    data = np.zeros((60, 60), np.uint8)
    data[15:45, 15:45] = 255
    path = tmp_path_factory.mktemp("params") / "p.png"
    Image.fromarray(data).save(path)
    return path


def _mN(v):
    return v * 1000


#: flag -> (its text, extra flags it needs, the scene's attribute, the value expected there).
#: The layout keys and the image keys are checked where the scene hands them on.
ROUND_TRIP = {
    "--surface-tension": ("70", (), lambda s: _mN(s.materials.surface_tension_N_m), 70),
    "--pad-angle": ("20", (), lambda s: s.materials.pad_angle_deg, 20),
    "--substrate-angle": ("80", (), lambda s: s.materials.substrate_angle_deg, 80),
    "--allow-repulsive": (None, (), lambda s: s.materials.allow_repulsive, True),
    "--twist-step": ("0.5", (), lambda s: s.twist.step_deg, 0.5),
    "--no-twist": (None, (), lambda s: s.effects.twist, False),
    "--window": ("30", (), lambda s: s.window_um, 30),
    "--dtype": ("float64", (), lambda s: s.dtype, "float64"),
    "--memory-budget": ("100", (), lambda s: s.memory_budget_mb, 100),
    "--volume": ("0.001", (), lambda s: s.liquid.volume_nl, 0.001),
    "--meniscus": (None, (), lambda s: s.effects.meniscus, True),
    "--meniscus-height": ("5", (), lambda s: (s.liquid.height_um, s.effects.meniscus), (5, True)),
    "--hysteresis": (
        "31:50",
        (),
        lambda s: (s.effects.hysteresis, s.materials.pad_receding_deg, s.materials.pad_advancing_deg),
        (True, 31, 50),
    ),
    "--dispense": ("none", (), lambda s: s.liquid.dispense, "none"),
    "--dispense-at": ("1,2", ("--meniscus",), lambda s: tuple(s.liquid.dispense_at_um), (1, 2)),
    "--pinned": (None, (), lambda s: s.liquid.pinned, True),
    "--edge-angle": ("90", (), lambda s: s.topography.edge_angle_deg, 90),
    "--pad-advancing": (
        "40",
        ("--edge-angle", "90"),
        lambda s: s.topography.pad_advancing_deg,
        40,
    ),
    "--chip-angle": ("70", ("--edge-angle", "90"), lambda s: s.topography.chip_angle_deg, 70),
    "--viscosity": ("2", (), lambda s: _mN(s.liquid.viscosity_Pa_s), 2),
    "--chip-thickness": ("30", (), lambda s: s.chip_thickness_um, 30),
    "--chip-density": ("1000", (), lambda s: s.chip_density_kg_m3, 1000),
    "--damping-calibration": ("3", (), lambda s: s.damping_calibration, 3),
    "--line-friction": ("4", (), lambda s: s.line_friction_Pa_s, 4),
    "--resolution": ("3", (), lambda s: s.um_per_px, 3),
    "--um-per-px": ("2", (), lambda s: s.pattern.shape, (120, 120)),  # 60 px of 2 um at 1 um/px
    "--chip-size": ("40x20", (), lambda s: (s.chip.params["width_um"], s.chip.params["height_um"]), (40, 20)),
    "--accuracy": ("precise", (), lambda s: s.twist.step_deg, 0.5),  # precise's twist step
}  # fmt: skip


def _document(argv):
    args = build_parser("simulate").parse_args(["simulate", *argv])
    return scene_document_from_args(SceneRequest.from_args(args, doc={}))[0]


def _expected_document_value(p, text):
    if p.flag_type == "switch":
        return p.switch_value
    if p.merge == "hysteresis":
        return True
    if p.merge == "path":
        return str(Path(text).resolve())
    if p.merge == "chip_size":
        return [float(v) for v in text.split("x")] * (2 if "x" not in text else 1)
    if p.choices is not None or p.flag_type == "text":
        return text
    return float(text) if p.flag_type != "count" else int(text)


def test_every_flag_reaches_its_document_key(pattern_png):
    base = ["--pattern", str(pattern_png), "--chip-size", "20"]
    texts = {
        "--pattern": str(pattern_png),
        "--chip": str(pattern_png),
        "--chip-size": "40x20",
        "--channel": "red",
        "--layer": "1/0",
        "--cell": "TOP",
        "--chip-layer": "2/0",
        "--dxf-units": "mm",
        "--max-polygons": "7",
        "--max-image-mpx": "5",
        "--pattern-um-per-px": "2",
        "--chip-um-per-px": "2",
    }
    flagged = [p for p in SCENE_PARAMS if p.flag]
    for p in flagged:
        assert p.flag is not None
        text = texts[p.flag] if p.flag in texts else ROUND_TRIP.get(p.flag, (None,))[0]
        doc = _document([*base, p.flag] + ([text] if text is not None else []))
        where = doc.get(p.table, {}) if p.table else doc
        assert where[p.key] == _expected_document_value(p, text), p.flag


def test_every_flag_reaches_the_scene(pattern_png):
    """Each flag's value is the scene's: built from the flags' document (layout and image keys
    go to the layout selection and the image reader: their names are those arguments')."""
    from patterns.layout import LayoutSelection

    handed_on = {
        "layout": {f.name for f in dataclasses.fields(LayoutSelection)},
        "image": set(inspect.signature(Scene.from_inputs).parameters),
        "input": set(inspect.signature(Scene.from_inputs).parameters),
    }
    checked = set()
    for p in SCENE_PARAMS:
        if p.flag is None:
            continue
        if p.flag not in ROUND_TRIP:
            assert p.key in handed_on[p.role], p.flag
            continue
        text, extra, attribute, expected = ROUND_TRIP[p.flag]
        argv = ["--pattern", str(pattern_png), "--um-per-px", "1", "--chip-size", "20"]
        argv += [*extra, p.flag] + ([text] if text is not None else [])
        argv += ["--resolution", "1"] if p.flag not in ("--resolution", "--accuracy") else []
        doc = _document(argv)
        scene = Scene.from_dict(doc)
        assert attribute(scene) == expected, p.flag
        checked.add(p.flag)
    assert checked == set(ROUND_TRIP)


def test_the_known_keys_are_the_registrys():
    with pytest.raises(InputError) as err:
        Scene.from_dict({"pattern": "p.png", "bogus": 1})
    allowed = ast.literal_eval(str(err.value).split("allowed: ", 1)[1])
    expected = {p.key if p.table is None else p.table for p in SCENE_PARAMS}
    assert set(allowed) == expected - {"accuracy"}  # the preset: allowed, not listed


# ----------------------------------------------------------------------- sweep and search
#: axis -> (a value, the scene's attribute of it)
SWEPT = {
    "chip_size_um": (300, lambda s: s.chip.params["width_um"]),
    "volume_nl": (2.0, lambda s: s.liquid.volume_nl),
    "pad_angle_deg": (25, lambda s: s.materials.pad_angle_deg),
    "substrate_angle_deg": (70, lambda s: s.materials.substrate_angle_deg),
    "surface_tension_mN_m": (60, lambda s: _mN(s.materials.surface_tension_N_m)),
    "twist_step_deg": (2, lambda s: s.twist.step_deg),
    "resolution_um": (10, lambda s: s.um_per_px),
}


def test_the_sweeps_scene_axes_are_the_registrys():
    from simulator.sweep import AXES, axis_kinds

    sweepable = [p for p in SCENE_PARAMS if p.sweepable]
    assert sweep_places() == {p.axis: _place(p) for p in sweepable}
    assert set(sweep_places()) == set(SWEPT) | {"pattern"}
    kinds = axis_kinds(None)
    assert {p.axis for p in sweepable} <= set(AXES)
    for p in sweepable:
        k = kinds[p.axis]
        assert (k.column, k.help) == (p.axis, p.sweep)
        kind = p.kind.side if isinstance(p.kind, Size) else p.kind
        for v in (-1, 0, 1, 45, 90, 180, 1e6, 2e9, "x"):
            if k.kind == "number":
                assert k.check(v) == kind.check(v), (p.axis, v)


def test_a_sweep_point_puts_each_axis_where_the_registry_says():
    from simulator.sweep import load_sweep, point_scene

    spec = load_sweep(
        {
            "design": {"name": "four-pad", "size": 200, "gap": 20},
            "axes": {axis: value for axis, (value, _) in SWEPT.items()},
        }
    )
    scene, _ = point_scene(spec.task(spec.points()[0]))
    for axis, (value, attribute) in SWEPT.items():
        assert attribute(scene) == pytest.approx(value), axis


def test_the_search_baseline_reads_the_scene_where_the_registry_says():
    from simulator.design import load_search

    scene = {"effects": {"twist": False}}
    for axis, (value, _) in SWEPT.items():
        table, key = sweep_places()[axis]
        (scene.setdefault(table, {}) if table else scene)[key] = value
    spec = load_search(
        {
            "scene": scene,
            "design": {"name": "four-pad", "size": 200, "gap": 20},
            "axes": {axis: {"from": 1, "to": 10} for axis in SWEPT},
            "search": {"trials": 2, "maximize": "yield_fraction"},
        }
    )
    assert spec.baseline_settings() == {axis: value for axis, (value, _) in SWEPT.items()}


# ----------------------------------------------------------------------- choices and limits
K = TypeVar("K", bound=Kind)


def _kind(table: str | None, key: str, cls: type[K]) -> K:
    """``SCHEMA[table][key]``, asserted to be a ``cls``."""
    kind = SCHEMA[table][key]
    assert isinstance(kind, cls), kind
    return kind


def test_no_choice_or_limit_of_the_schema_is_a_copy():
    """The schema quotes the choices and limits of their homes (simulator.core, the physics,
    the layout reader, the scene's own): the same objects, not copies that may drift."""
    from patterns import CHANNELS
    from patterns.layout import DXF_UNITS
    from simulator.core import BATCH_METHODS, DISTRIBUTIONS, MAX_CHUNK, MAX_STEPS_LIMIT, METHODS
    from simulator.physics import DISPENSE_CHOICES
    from simulator.scene import DTYPES, PRESETS

    assert _kind("simulate", "method", Choice).choices is METHODS
    assert _kind("montecarlo", "method", Choice).choices is BATCH_METHODS
    assert _kind("simulate", "max_steps", Integer).bounds.hi == MAX_STEPS_LIMIT
    assert _kind("montecarlo", "max_steps", Integer).bounds.hi == MAX_STEPS_LIMIT
    assert _kind("montecarlo", "chunk", Integer).bounds.hi == MAX_CHUNK
    assert _kind("liquid", "dispense", Choice).choices is DISPENSE_CHOICES
    assert _kind(None, "channel", Choice).choices is CHANNELS
    assert _kind(None, "dtype", Choice).choices is DTYPES
    homes = {
        METHODS,
        BATCH_METHODS,
        DISPENSE_CHOICES,
        CHANNELS,
        DTYPES,
        tuple(DXF_UNITS),
        tuple(PRESETS),
        DISTRIBUTIONS,
    }
    for section, keys in SCHEMA.items():
        for key, kind in keys.items():
            if isinstance(kind, Choice):
                assert kind.choices in homes, (section, key)
