"""``selfalign calibrate`` (simulator.design.calibrate): bad tables refused in one line before
any work, the known parameter found back within its reported range from trials the model
itself made, a resumed fit continues, the outputs are written and fitted.toml is a scene.

Small and coarse throughout: the 730/100 um four-pad at 20 um/px and 5 degree twists, the
overlap model with hysteresis and greedy steps (about a second per candidate); gradient steps
where the fit must place an angle between the grid's steps."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from simulator.cli import main
from simulator.design._calibrate._fit import PROFILE_BASE

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("calibrate")

ROOT = Path(__file__).resolve().parents[1]
SCENE = {
    "pattern": str(ROOT / "patterns" / "library" / "four_pad_730_100.png"),
    "chip_size_um": 730,
    "resolution_um": 20.0,
    "twist": {"step_deg": 5.0},
    "materials": {"pad_angle_deg": 30, "pad_receding_deg": 25, "pad_advancing_deg": 35},
    "effects": {"hysteresis": True},
}
#: The starts near the four-pad's capture edge, where the receding angle sets the yield.
EDGE = [(300, 0, 0), (325, 0, 0), (350, 0, 0), (375, 0, 0)]
#: Starts where the pinning weighs against a force that varies continuously with the pose.
THRESHOLD = [(650, 300, 0), (700, 350, 0), (0, 0, 40), (0, 0, 44)]
HEADER = "x_um,y_um,twist_deg,trials,aligned"


def _scene_file(tmp_path: Path) -> Path:
    from simulator.design import scene_toml

    p = tmp_path / "scene.toml"
    p.write_text(scene_toml(SCENE))
    return p


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ("x_um,y_um,twist_deg,trials\n1,2,0,10\n", "missing column aligned"),
        (HEADER + "\n0,0,0,5,7\n", "row 2, column aligned: 7 aligned of 5 trials"),
        (HEADER + "\n0,0,0,-5,0\n", "row 2, column trials: -5 is negative"),
        (
            HEADER + "\n0,0,0,10,5\n0,nan,0,10,5\n",
            "row 3, column y_um: 'nan' is not a finite number",
        ),
        (HEADER + "\n0,abc,0,10,5\n", "row 2, column y_um: 'abc' is not a number"),
        (HEADER + "\n", "has a header but no rows"),
        ("", "is empty"),
        (HEADER + ",time_ms\n0,0,0,10,5,1\n", "did you mean time_s?"),
        (HEADER + ",time_s\n0,0,0,10,0,0.3\n", "none of whose trials aligned"),
    ],
)
def test_a_bad_table_is_refused_in_one_line_before_any_work(tmp_path, capsys, body, says):
    csv = tmp_path / "bench.csv"
    csv.write_text(body)
    out = tmp_path / "fit"
    code = main(
        ["calibrate", str(csv), str(_scene_file(tmp_path)), "--fit", "receding_angle_deg"]
        + ["--spread", "20,20,2", "--out", str(out)]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1, err
    assert says in err and str(csv) in err, err
    assert not out.exists()


def test_unknown_names_and_bounds_get_a_did_you_mean(tmp_path, capsys):
    csv = tmp_path / "bench.csv"
    csv.write_text(HEADER + "\n300,0,0,10,5\n")
    out = tmp_path / "fit"
    scene = str(_scene_file(tmp_path))
    assert (
        main(
            [
                "calibrate",
                str(csv),
                scene,
                "--fit",
                "receding_angle",
                "--spread",
                "1,1,1",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "did you mean receding_angle_deg?" in capsys.readouterr().err
    assert (
        main(
            [
                "calibrate",
                str(csv),
                scene,
                "--fit",
                "volume_nl",
                "--bounds",
                "volume=1:2",
                "--spread",
                "1,1,1",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "did you mean volume_nl?" in capsys.readouterr().err
    assert main(["calibrate", str(csv), scene, "--fit", "volume_nl", "--out", str(out)]) == 2
    assert "--spread" in capsys.readouterr().err  # no placement noise for the row
    assert not out.exists()


def test_it_finds_the_receding_angle_the_trials_were_made_with():
    """Rows where the pinning decides against a force that varies continuously with the
    placement: a chip half off the pads' corner (its x force set by how far its edges
    overlap the pads in y) and a centred chip turned 40-44 deg (its torque against the
    lines' pinning torque), made and fitted with gradient steps. The chip stops where the
    force falls to the pinning at a continuous pose, so with the rows' placement noise the
    yields change smoothly and monotonically with the receding angle. (Greedy snaps every
    placement to the 20 um grid and 5 deg twists and weighs a few discrete energy steps
    against the pinning work: its yields at the capture edge step once, between 24 and 25
    deg, and are flat on either side, so no fit can place the angle within a step.)"""
    import tempfile

    import numpy as np

    from simulator.design import calibrate, read_trials, synthetic_trials, write_trials

    truth, n, draws = 22.0, 100, 64
    rows = synthetic_trials(
        SCENE, THRESHOLD, {"receding_angle_deg": truth}, trials=n, seed=1, method="gradient"
    )
    with tempfile.TemporaryDirectory() as d:
        csv = write_trials(Path(d) / "bench.csv", rows)
        fit = calibrate(
            read_trials(csv),
            SCENE,
            "receding_angle_deg",
            None,
            trials=10,
            draws=draws,
            seed=0,
            method="gradient",
        )
    r = fit["range"]["receding_angle_deg"]
    best = fit["best"]["receding_angle_deg"]
    assert r["lo"] <= truth <= r["hi"], fit["range"]
    assert r["lo"] <= best <= r["hi"]

    # What n trials per row can tell: the Fisher information of the rows' yields p(theta),
    # sum (dp/dtheta)^2 / (p (1 - p) (1/n + 1/draws)) (the bench's binomial and the model's
    # own draws), dp/dtheta from the model at truth -+ 3 deg on common draws. The best lies
    # within three of its standard errors of the truth.
    def yields(angle, trials, seed):
        made = synthetic_trials(
            SCENE,
            THRESHOLD,
            {"receding_angle_deg": angle},
            trials=trials,
            seed=seed,
            method="gradient",
        )
        return np.array([row["aligned"] for row in made]) / trials

    many, h = 400, 3.0
    p_lo, p_mid, p_hi = (yields(a, many, 2) for a in (truth - h, truth, truth + h))
    var = np.clip(p_mid * (1 - p_mid), 1 / many, None) * (1 / n + 1 / draws)
    sigma = float(np.sum(((p_hi - p_lo) / (2 * h)) ** 2 / var) ** -0.5)
    assert abs(best - truth) <= 3 * sigma, (best, sigma)
    # the range is informative: narrower than the bounds (0 to the advancing 35 deg)
    assert r["hi"] - r["lo"] < 0.6 * 35.0, r
    assert fit["log_likelihood"] > fit["baseline"]["log_likelihood"]


def test_two_names_that_trade_are_reported_as_such_with_the_truth_in_both_ranges():
    """On the overlap model with hysteresis, greedy yields depend on the pinning against the
    drive, gamma (cos th_r - cos th_a) / (gamma (cos th_s - cos th_p)), and not on the two
    angles apart: a valley of equal likelihood along which the receding and the pad angle
    trade. The search alone lands on one point of it (narrow ranges that missed the truth
    before the profile and the beta-binomial term); the profile follows the valley, so both
    ranges hold the angles the trials were made with, and at least one is flagged."""
    from simulator.design import calibrate, read_trials, synthetic_trials, write_trials

    truth = {"receding_angle_deg": 20.0, "pad_angle_deg": 30.0}
    rows = synthetic_trials(SCENE, EDGE, truth, trials=100, seed=1)
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        csv = write_trials(Path(d) / "bench.csv", rows)
        fit = calibrate(read_trials(csv), SCENE, list(truth), None, trials=8, draws=32, profile=4)
    for k, v in truth.items():
        r = fit["range"][k]
        assert r["lo"] <= v <= r["hi"], (k, fit["best"], fit["range"])
    assert not all(r["identified"] for r in fit["range"].values()), fit["range"]
    assert fit["profiled"] > 0


def test_a_fit_resumes_writes_its_outputs_and_fitted_toml_is_a_scene(tmp_path, capsys):
    from simulator.design import synthetic_trials, write_trials
    from simulator.scene import Scene

    csv = write_trials(
        tmp_path / "bench.csv",
        synthetic_trials(SCENE, EDGE[:2], {"receding_angle_deg": 20.0}, trials=50, seed=1),
    )
    scene = str(_scene_file(tmp_path))
    out = tmp_path / "fit"
    args = [
        "calibrate",
        str(csv),
        scene,
        "--fit",
        "receding_angle_deg",
        "--draws",
        "16",
        "--out",
        str(out),
    ]
    assert main([*args, "--trials", "2"]) == 0
    first = (out / "trials.jsonl").read_text().splitlines()
    trials = [json.loads(line)["trial"] for line in first]
    assert [t for t in trials if t < PROFILE_BASE] == [0, 1, 2]
    # one parameter's profile: its likelihood at the middles of six equal shares of 0..35 deg
    prof = [json.loads(line) for line in first if json.loads(line)["trial"] >= PROFILE_BASE]
    assert sorted(r["receding_angle_deg"] for r in prof) == pytest.approx(
        [35 * (j + 0.5) / 6 for j in range(6)]
    )
    assert {r["kind"] for r in prof} == {"profile"}
    assert main([*args, "--trials", "4", "--quiet"]) == 0
    lines = (out / "trials.jsonl").read_text().splitlines()
    trials = [json.loads(line)["trial"] for line in lines]
    assert [t for t in trials if t < PROFILE_BASE] == [0, 1, 2, 3, 4]
    assert lines[: len(first)] == first  # continued, not redone
    values = [json.loads(line)["receding_angle_deg"] for line in lines]
    assert len(set(values)) == len(values)  # the profile's points found again, not run twice
    capsys.readouterr()
    for name in ("fitted.toml", "fit.json", "bench.png", "report.html", "trials.csv"):
        assert (out / name).stat().st_size > 0, name
    fit = json.loads((out / "fit.json").read_text())
    assert fit["done"] == 4 and len(fit["rows"]) == 2
    assert fit["profiled"] == sum(t >= PROFILE_BASE for t in trials) >= 6
    assert {"bench_yield", "model_yield", "bench_time_s", "model_time_s"} <= set(fit["rows"][0])
    s = Scene.from_toml(out / "fitted.toml")
    assert s.materials.pad_receding_deg == pytest.approx(fit["best"]["receding_angle_deg"])
    assert s.effects.hysteresis
    # a different table into the same directory: refused in one line, nothing changed
    other = write_trials(
        tmp_path / "other.csv", [dict(x_um=300, y_um=0, twist_deg=0, trials=9, aligned=3)]
    )
    assert (
        main(
            [
                "calibrate",
                str(other),
                scene,
                "--fit",
                "receding_angle_deg",
                "--spread",
                "20,20,2",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "holds a different calibrate" in err and len(err.strip().splitlines()) == 1, err
    assert (out / "trials.jsonl").read_text().splitlines() == lines
