"""The typed results: the assessment's parts and a run's cost, their dicts, and the sweep's
columns and the reports' metric rows derived from them (simulator.batch.Assessment,
simulator.motion.RunCost)."""

from __future__ import annotations

import dataclasses
import itertools

import pytest

from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.batch import (
    ABSENT,
    EFFECTS,
    Assessment,
    TimeStats,
    assess,
    summary_shape,
)
from simulator.motion import RunCost
from simulator.scene import Scene
from simulator.sweep import flatten
from simulator.sweep._columns import _metric_columns

pytestmark = pytest.mark.xdist_group("assessment")

#: The summary keys a sweep point adds to its settings (simulator.sweep assess_point).
POINT_SETTINGS = {"source_um_per_px": 10.0, "resolution_auto": False, "volume_nl": 20.0}


def _scene(**doc) -> Scene:
    """The 200 um four-pad (gap 20 um) at 10 um/px, 200 um chip: a second's assessment."""
    base = {
        "pattern": mask_from_geometry(four_pad(200, 20), 10.0, margin_um=10),
        "chip_size_um": [200, 200],
        "resolution_um": 10,
    }
    return Scene.from_dict(base | doc)


def _keys(d) -> object:
    """The key tree of a summary: its dicts' keys, in order, down to the values."""
    if isinstance(d, dict):
        return [(k, _keys(v)) for k, v in d.items()]
    return None


def _as_point(a: Assessment) -> Assessment:
    return dataclasses.replace(a, settings=dataclasses.replace(a.settings, **POINT_SETTINGS))


# ---------------------------------------------------------------- the assessment's dict
@pytest.fixture(scope="module")
def plain():
    """No twist, the overlap model, greedy steps."""
    return assess(_scene(effects={"twist": False}), yield_starts=20, grid_cells=5)


@pytest.fixture(scope="module")
def floating():
    """Twist and a finite meniscus with free contact lines: the chip floats on a floor."""
    s = _scene(effects={"meniscus": True}, liquid={"volume_nl": 0.4, "dispense": "none"})
    assert s.wall_profile is not None  # free contact lines
    return assess(s, yield_starts=20, grid_cells=5)


@pytest.fixture(scope="module")
def dispensed():
    """No twist, a floating meniscus, both dispense protocols, overdamped starts."""
    s = _scene(
        effects={"twist": False, "meniscus": True}, liquid={"volume_nl": 0.4, "dispense": "chip"}
    )
    return assess(s, method="overdamped", yield_starts=20, grid_cells=5)


#: The fixtures' effects (simulator.batch.EFFECTS).
CASES = {
    "plain": set(),
    "floating": {"twist", "meniscus", "free"},
    "dispensed": {"meniscus", "free", "dynamics", "dispense"},
}


@pytest.mark.parametrize("case, effects", CASES.items())
def test_the_columns_derived_from_the_types_are_a_real_point_s(case, effects, request):
    # The sweep's expected columns (from the types, simulator.sweep.expected_columns) are
    # those a real point's summary flattens to, in its order
    a = request.getfixturevalue(case)
    flags = {k: k in effects for k in ("twist", "meniscus", "free", "dynamics", "dispense")}
    real = [c for c in flatten(_as_point(a)) if "wet_at_dispense" not in c]  # pads by number
    assert real == _metric_columns(**flags)


@pytest.mark.parametrize("case, effects", CASES.items())
def test_the_shape_of_the_types_is_the_summary_s_keys(case, effects, request):
    # summary_shape: the keys and their order of a real summary, the types' `when` included
    a = request.getfixturevalue(case)
    shape = summary_shape(effects)
    shape["settings"] = {k: v for k, v in shape["settings"].items() if k not in POINT_SETTINGS}
    del shape["layout"]  # a layout pattern's record (these are generated patterns)
    assert _keys(a.to_dict()) == _keys(shape)


def test_a_part_s_dict_follows_its_fields_and_their_keys(plain):
    d = plain.to_dict()
    # a key that cannot be a name: its metadata's; tuples written as lists
    assert list(d["restoring_force_N"]) == ["bias_um", "+x", "-x", "+y", "-y"]
    assert d["restoring_force_N"]["+x"] == list(plain.restoring_force_N.plus_x)
    assert list(d["capture"]["grid_um"]) == ["from", "to", "step"]
    assert d["yield"]["fraction"] == plain.yield_.fraction
    # None written null where the key belongs, a key left out where it does not
    assert d["restoring_torque_Nm"] is None and d["settings"]["twist_step_deg"] is None
    assert "protocols" not in d and "meniscus_height_um" not in d
    assert plain.capture.time_to_align_s is ABSENT and "time_to_align_s" not in d["capture"]
    timed = dataclasses.replace(plain.yield_, time_to_align_s=None)
    assert timed.to_dict()["time_to_align_s"] is None
    stats = TimeStats(n=2, median=1e-3, p90=2e-3, mean=1.5e-3, min=1e-3, max=2e-3)
    assert dataclasses.replace(plain.yield_, time_to_align_s=stats).to_dict()[
        "time_to_align_s"
    ] == {"n": 2, "median": 1e-3, "p90": 2e-3, "mean": 1.5e-3, "min": 1e-3, "max": 2e-3}


def test_every_effect_combination_has_its_columns():
    # each effect adds columns and removes none (the flags as the sweep passes them)
    every = set()
    for combo in itertools.product([False, True], repeat=6):
        names = ("twist", "meniscus", "free", "dynamics", "dispense", "four_pad")
        flags = dict(zip(names, combo, strict=True))
        cols = _metric_columns(**flags)
        assert len(cols) == len(set(cols)), flags
        for k, on in flags.items():
            if not on:
                more = _metric_columns(**(flags | {k: True}))
                assert set(cols) <= set(more), k
        every |= set(cols)
    assert every == set(_metric_columns(True, True, True, True, True, True))
    with pytest.raises(ValueError, match="effects must be among"):
        summary_shape({"wind"})
    assert summary_shape(EFFECTS)["liquid_warnings"] == []  # evaluate's own keys


# ---------------------------------------------------------------- the metric rows
def test_every_labelled_column_is_one_the_types_produce():
    # A renamed field renames its column: a label (or a report's row) of a column the types
    # no longer make fails here, not silently on a page.
    from simulator.design._search._report import COMPARED, PROTOCOL_COMPARED
    from simulator.sweep import METRIC_LABELS
    from simulator.sweep._report import METRICS

    produced = set(_metric_columns(True, True, True, True, True, True))
    own = {"volume_nl"}  # a design search's column of its trials, beside the point's
    rows = [*METRIC_LABELS, *(c for c, _, _ in (*METRICS, *COMPARED, *PROTOCOL_COMPARED))]
    assert {c for c in rows if c not in own} <= produced
    assert "critical_volume_nl" in produced and "volume_nl" not in produced


# ---------------------------------------------------------------- a run's cost
def test_a_run_s_cost_is_its_json_key_for_key():
    from simulator.motion import simulate

    s = Scene(
        pattern=mask_from_geometry(four_pad(200, 20), 10.0, margin_um=10),
        chip=mask_from_geometry(square(200), 10.0),
    )
    t = simulate(s, (40.0, 20.0, 0.0))
    assert isinstance(t.cost, RunCost)
    doc = t.to_json()["cost"]
    assert doc == {k: v for k, v in dataclasses.asdict(t.cost).items() if v is not None}
    own = [f.name for f in dataclasses.fields(RunCost) if not f.name.startswith("footprint_")]
    assert list(doc) == own  # a footprint run's own keys are left out of any other run's
    assert doc["engine"] == t.cost.engine and doc["total_s"] >= doc["landscape_s"] >= 0
    foot = dataclasses.replace(t.cost, footprint_planes_s=0.5, footprint_pieces=2).to_dict()
    assert list(foot) == [*own, "footprint_planes_s", "footprint_pieces"]
    foot = dataclasses.replace(t.cost, footprint_planes_s=0.5, footprint_twists=23).to_dict()
    assert list(foot) == [*own, "footprint_planes_s", "footprint_twists"]
