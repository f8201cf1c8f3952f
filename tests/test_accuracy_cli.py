"""--accuracy presets on the command line: knobs set explicitly always win; feature warnings."""

import json

import pytest

from patterns.library import library_path
from simulator.cli import main
from simulator.scene import PRESETS, apply_preset

FOURPAD = str(library_path("four_pad_730_50"))
JAGGED = str(library_path("random_jagged_s2"))


def energy_json(tmp_path, *flags, pattern=FOURPAD, chip="730"):
    out = tmp_path / "e.json"
    assert (
        main(
            [
                "energy",
                "--pattern",
                pattern,
                "--chip-size",
                chip,
                "--at",
                "10,0,0",
                *flags,
                "--json",
                str(out),
            ]
        )
        == 0
    )
    return json.loads(out.read_text())


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_preset_sets_the_knobs_not_given(tmp_path, name):
    doc = energy_json(tmp_path, "--accuracy", name)
    want = apply_preset(
        name, {}, feature_um=50.0, native_um_per_px=1.0
    )  # the 50 um gap is the smallest feature
    assert doc["um_per_px"] == want["um_per_px"] and doc["dtype"] == want["dtype"]
    assert doc["twist_step_deg"] == want["twist_step_deg"]


def test_explicit_knobs_win_over_the_preset(tmp_path):
    doc = energy_json(
        tmp_path,
        "--accuracy",
        "fast",
        "--resolution",
        "1",
        "--twist-step",
        "0.5",
        "--dtype",
        "float64",
    )
    assert (doc["um_per_px"], doc["twist_step_deg"], doc["dtype"]) == (1.0, 0.5, "float64")


def test_feature_warning_on_coarse_scale(tmp_path, capsys):
    energy_json(tmp_path, "--resolution", "4", pattern=JAGGED, chip="200")
    err = capsys.readouterr().err
    assert (
        err.startswith("warning: ")
        and "smallest feature" in err
        and len(err.strip().splitlines()) == 1
    )


def test_no_feature_warning_at_fine_scale(tmp_path, capsys):
    energy_json(tmp_path, pattern=JAGGED, chip="200")
    assert "warning" not in capsys.readouterr().err
