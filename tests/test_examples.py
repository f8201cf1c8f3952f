"""Every example scene in examples/ runs with the command its header names."""

import json
from pathlib import Path

import pytest

from simulator.cli import main

EX = Path(__file__).resolve().parents[1] / "examples"


def test_every_example_is_covered():
    assert {p.name for p in EX.glob("*.toml")} == {
        "simulate_fourpad.toml",
        "dynamics_square.toml",
        "montecarlo_fourpad.toml",
        "evaluate_defect.toml",
        "energy_fourpad.toml",
        "sweep_fourpad.toml",
        "design_fourpad_gap.toml",
        "design_freeform_rfid.toml",
        "calibrate_fourpad.toml",
    }


def test_simulate_example(tmp_path):
    out = tmp_path / "t.json"
    assert main(["simulate", str(EX / "simulate_fourpad.toml"), "--json", str(out), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    assert doc["outcome"] == "aligned" and doc["start"] == {
        "x_um": 380.0,
        "y_um": 120.0,
        "twist_deg": 8.0,
    }


def test_dynamics_example(tmp_path):
    out = tmp_path / "d.json"
    assert main(["simulate", str(EX / "dynamics_square.toml"), "--json", str(out), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    assert doc["outcome"] == "aligned" and 0.005 < doc["time_s"] < 0.5  # tens of ms


def test_montecarlo_example(tmp_path):
    out = tmp_path / "mc.json"
    assert (
        main(["montecarlo", str(EX / "montecarlo_fourpad.toml"), "--json", str(out), "--quiet"])
        == 0
    )
    doc = json.loads(out.read_text())
    assert doc["n"] == 2000 and doc["seed"] == 1 and 0.5 < doc["yield"] <= 1


def test_evaluate_example(tmp_path):
    out = tmp_path / "rep"
    assert main(["evaluate", str(EX / "evaluate_defect.toml"), "--out", str(out), "--quiet"]) == 0
    s = json.loads((out / "summary.json").read_text())
    g = s["global_minimum"]
    assert (g["x_um"], g["y_um"], g["twist_deg"]) == (
        0.0,
        0.0,
        0.0,
    )  # C11: the defect does not move it


@pytest.mark.fft
@pytest.mark.parametrize("flags", [["--at", "40,25,0"]])
def test_energy_example(tmp_path, flags):
    out = tmp_path / "e.json"
    assert main(["energy", str(EX / "energy_fourpad.toml"), *flags, "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    # float32: within the noise floor, 32 eps(float32) max|E| (the FFT round-off bound),
    # 1.8 um^2 at max|E| = 4 x 340^2 um^2 (abs=1 um^2 was below it: one machine's luck)
    floor_um2 = doc["noise_floor_J"] / (abs(doc["delta_gamma_N_m"]) * 1e-12)
    assert doc["poses"][0]["overlap_um2"] == pytest.approx(419200, abs=floor_um2)


def test_design_example_is_the_guides_search():
    # Its run (about a minute on 2 cores) is in docs/guide/design.md; here its plan.
    from simulator.design import load_search

    spec = load_search(EX / "design_fourpad_gap.toml")
    (gap,) = spec.searched
    assert (gap.name, gap.values, gap.lo, gap.hi) == ("gap", None, 20.0, 300.0)
    assert spec.trials == 24 and spec.sampler == "tpe"
    assert [o.text for o in spec.objectives] == ["maximize gap_um"]
    assert [c.text for c in spec.constraints] == [
        "protocols_pattern_yield_fraction >= 0.99",
        "volume_nl >= critical_volume_nl",
    ]
    assert spec.sweep.scene["liquid"]["dispense"] == "pattern"
    assert spec.sweep.design["params"] == {"size": 730, "gap": 50}
    assert spec.baseline_values() == {"placement_sigma_um": 150, "placement_sigma_deg": 2}


def test_freeform_design_example_loads():
    """The free-form example is checked whole (running it takes minutes: docs/guide/design.md):
    its chip has an index mark, so no turn repeats it and the orientation term is allowed; the
    baseline is the four contact pads it keeps."""
    import numpy as np

    from simulator.design import load_freeform
    from simulator.scene import chip_symmetry

    spec = load_freeform(EX / "design_freeform_rfid.toml")
    assert chip_symmetry(spec.scene.chip)[0] == 360.0
    assert spec.twists_deg() == (0.0, 90.0, 180.0, 270.0) and spec.shape == (180, 180)
    assert spec.keep_in.sum() * 16 == 4 * 120 * 120  # the four 120 um pads at 4 um/px
    assert np.array_equal(spec.baseline.data >= 0.5, spec.keep_in)


def test_calibrate_example_runs_its_header_command(tmp_path):
    """The calibrate example's own command (its first line), cut to one trial after the
    scene's own start and 16 draws a row (the full fit is in docs/guide/calibrate.md): the
    ten bench rows are read and each gets the model's yield beside the bench's."""
    import shlex

    header = (EX / "calibrate_fourpad.toml").read_text().splitlines()[0]
    argv = shlex.split(header.lstrip("# "))
    assert argv[:2] == ["selfalign", "calibrate"] and argv[-2:] == ["--out", "fit"]
    argv = [str(EX.parent / a) if a.startswith("examples/") else a for a in argv[1:-2]]
    out = tmp_path / "fit"
    assert main([*argv, "--out", str(out), "--trials", "1", "--draws", "16", "--quiet"]) == 0
    fit = json.loads((out / "fit.json").read_text())
    bench = (EX / "calibrate_trials.csv").read_text().splitlines()[1:]
    assert len(fit["rows"]) == len(bench) == 10
    assert set(fit["best"]) == {"receding_angle_deg"}
    assert [r["bench_yield"] for r in fit["rows"]] == pytest.approx(
        [int(line.split(",")[4]) / int(line.split(",")[3]) for line in bench]
    )
