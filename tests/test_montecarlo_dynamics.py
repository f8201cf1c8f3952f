"""Batch dynamics (montecarlo, evaluate, sweep with --method overdamped|inertial): the
vmapped solver equals the single-run path start by start, the time to align and its
distribution, the memory price, the flag on every command and a bad method refused.

Coarse pixels and few starts: each case compiles the solver once per method."""

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from foundation import InputError
from patterns import write_mask
from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.batch import assess, random_starts, run_batch, summarize, time_histogram, time_stats
from simulator.cli import main
from simulator.core import OUTCOMES
from simulator.landscape import build_landscape
from simulator.motion import simulate
from simulator.physics import Liquid
from simulator.scene import Effects, Scene, TwistGrid
from simulator.sweep import flatten

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("montecarlo_dynamics")

ROOT = Path(__file__).resolve().parents[1]
SQUARE = ROOT / "patterns" / "library" / "square_200.png"
DYNAMIC = ("overdamped", "inertial")


@pytest.fixture(scope="module")
def overlap():
    """200 um four-pad (gap 20 um) at 4 um/px, 10 degree twist steps; starts aligned, on
    the pads, at a corner, twisted, and two beyond the pattern (no contact). The damping's
    terms with line friction in water's range (0.03 Pa s): every start that aligns does so
    well within the run's second (at the default, fitted to the 730 um chip's video, the
    corner start creeps)."""
    scene = Scene(
        pattern=mask_from_geometry(four_pad(200, 20), 4.0, margin_um=10),
        chip=mask_from_geometry(square(200), 4.0),
        twist=TwistGrid(step_deg=10.0),
        line_friction_Pa_s=0.03,
    )
    starts = np.array(
        [
            [0, 0, 0],
            [8, -4, 0],
            [60, 40, 10],
            [-100, 20, 0],
            [96, 0, 0],
            [0, -110, -10],
            [200, 200, 0],
            [240, 0, 0],
            [-236, 100, 0],
        ],
        float,
    )
    return scene, build_landscape(scene), starts


@pytest.fixture(scope="module")
def floating():
    """The 200 um square at 0.9 nl, free contact lines (the chip floats on a flat floor near
    alignment), 5 um/px, no twist: some starts align (the one on the floor at time 0), some
    run out of the 1 s the single run allows."""
    scene = Scene.from_inputs(
        SQUARE,
        chip_size_um=200,
        resolution_um=5,
        effects=Effects(twist=False, meniscus=True),
        liquid=Liquid(volume_nl=0.9, dispense="none"),  # the stateless landscape, built once
        damping_calibration=600.0,  # the former fit: heavily damped, the stiff (IMEX) path
    )
    starts = np.array(
        [[0, 0, 0], [8, -4, 0], [30, 0, 0], [60, 40, 0], [150, 0, 0], [95, 0, 0], [0, -110, 0]],
        float,
    )
    return scene, build_landscape(scene), starts


# ------------------------------------------------------------------ batch == single runs
@pytest.mark.parametrize("method", DYNAMIC)
@pytest.mark.parametrize("case", ["overlap", "floating"])
def test_batch_dynamics_equal_single_runs_start_by_start(request, case, method):
    scene, ls, starts = request.getfixturevalue(case)
    # chunk 4 on two threads: a padded last chunk, lanes of different lengths side by side
    r = run_batch(scene, starts, method, landscape=ls, chunk=4, workers=2, progress=False)
    assert r.time_s is not None and r.time_s.shape == (len(starts),)
    # the floating chip's inertial runs are stiff (implicit solver, mapped start by start); the others vmapped
    assert r.stats["stiff"] == (case == "floating" and method == "inertial")
    for i, start in enumerate(starts):
        traj = simulate(
            scene, tuple(start), method=method, landscape=ls
        )  # the single-run path, one start at a time
        assert r.outcome_names()[i] == traj.outcome, (i, start)
        assert np.max(np.abs(r.final[i, :2] - np.asarray(traj.final[:2]))) <= 1e-6, (
            i,
            r.final[i],
            traj.final,
        )
        assert abs(r.final[i, 2] - traj.final[2]) <= 1e-6
        assert r.steps[i] == traj.steps
        assert r.time_s[i] == pytest.approx(traj.time_s, rel=1e-6, abs=1e-12)
    names = set(r.outcome_names())
    # On the floating floor every run ends aligned: those that creep on the floor until their
    # simulated second is up end inside it (simulator.motion.classify), not out of time.
    assert names == ({"aligned", "no_contact"} if case == "overlap" else {"aligned"})
    # the start at the aligned pose: aligned at once; the time to align is the aligned runs' time, NaN elsewhere
    assert r.outcome_names()[0] == "aligned" and r.time_s[0] == 0.0
    ok = r.outcome == OUTCOMES.index("aligned")
    assert r.time_to_align_s is not None
    assert (
        np.array_equal(r.time_to_align_s[ok], r.time_s[ok])
        and np.isnan(r.time_to_align_s[~ok]).all()
    )
    # a run that creeps on the floor until its second is up reports that second (an upper bound)
    assert (r.time_s[ok] <= 1.0).all() and np.count_nonzero(
        (r.time_s[ok] > 0) & (r.time_s[ok] < 1.0)
    ) >= 2


def test_time_to_align_distribution_in_the_summary(overlap):
    scene, ls, starts = overlap
    r = run_batch(scene, starts, "overdamped", landscape=ls, chunk=4, progress=False)
    t = summarize(r)["time_to_align_s"]
    assert r.time_s is not None
    aligned = r.time_s[r.outcome == OUTCOMES.index("aligned")]
    assert t["n"] == len(aligned) == 7
    assert t["median"] == pytest.approx(np.median(aligned)) and t["p90"] == pytest.approx(
        np.percentile(aligned, 90)
    )
    assert (
        t["min"] == 0.0
        and t["max"] == aligned.max()
        and t["min"] <= t["median"] <= t["p90"] <= t["max"]
    )
    h = time_histogram(r.time_to_align_s, bins=5)
    assert h is not None
    assert (
        sum(h["counts"]) == 7
        and h["edges_s"][0] == 0.0
        and h["edges_s"][-1] == aligned.max()
        and len(h["edges_s"]) == 6
    )
    # the steppers have no time: no key, no per-start times
    g = run_batch(scene, starts, "greedy", landscape=ls, progress=False)
    assert g.time_s is None and g.time_to_align_s is None and "time_to_align_s" not in summarize(g)
    assert time_stats([np.nan, np.nan]) is None and time_histogram([np.nan]) is None


def test_dynamics_parameters_are_the_scenes_unless_given(overlap):
    """Default parameters: DynamicsParams.from_scene, as simulate takes them; others change the times."""
    from simulator.motion import DynamicsParams

    scene, ls, starts = overlap
    a = run_batch(scene, starts[:4], "overdamped", landscape=ls, progress=False)
    p = DynamicsParams.from_scene(scene)
    b = run_batch(scene, starts[:4], "overdamped", landscape=ls, progress=False, dynamics=p)
    assert a.time_s is not None and b.time_s is not None
    assert a.time_s.tobytes() == b.time_s.tobytes() and a.final.tobytes() == b.final.tobytes()
    slow = DynamicsParams(
        p.mass_kg, p.inertia_kg_m2, 2 * p.damping_N_s_m, 2 * p.rot_damping_N_m_s, p.t_max_s
    )
    c = run_batch(scene, starts[:4], "overdamped", landscape=ls, progress=False, dynamics=slow)
    assert c.time_s is not None
    moved = a.time_s > 0
    assert np.allclose(
        c.time_s[moved], 2 * a.time_s[moved], rtol=0.05
    )  # overdamped: time scales with the damping


def test_bad_method_and_memory_price_are_refused_before_any_work(overlap):
    scene, ls, starts = overlap
    with pytest.raises(
        InputError, match="method must be one of greedy, gradient, overdamped, inertial"
    ):
        run_batch(scene, starts, "newton", landscape=ls, progress=False)
    tight = scene.replace(memory_budget_mb=1.0)
    with pytest.raises(InputError, match="solver states of 1,000 dynamics runs"):
        run_batch(
            tight,
            random_starts(1000, (1, 1, 0), seed=0),
            "inertial",
            chunk=1000,
            workers=1,
            progress=False,
        )


# ------------------------------------------------------------------ CLI
@pytest.fixture(scope="module")
def fp_png(tmp_path_factory):
    path = tmp_path_factory.mktemp("pat") / "fourpad.png"
    write_mask(path, mask_from_geometry(four_pad(200, 20), 4.0, margin_um=8))
    return path


BASE = ["montecarlo", "--chip-size", "200", "--twist-step", "10", "--quiet"]


def test_cli_montecarlo_method_inertial(fp_png, tmp_path, capsys):
    j, c, p = tmp_path / "mc.json", tmp_path / "mc.csv", tmp_path / "t.png"
    rc = main(
        BASE
        + [
            "--pattern",
            str(fp_png),
            "--random",
            "40",
            "--spread",
            "60,60,5",
            "--around",
            "120,0,0",
            "--seed",
            "2",
            "--method",
            "inertial",
            "--chunk",
            "16",
            "--json",
            str(j),
            "--csv",
            str(c),
            "--time-plot",
            str(p),
        ]
    )
    assert rc == 0
    doc = json.loads(j.read_text())
    assert doc["method"] == "inertial" and doc["n"] == 40
    t, h = doc["time_to_align_s"], doc["time_to_align_histogram"]
    n_ok = doc["outcomes"]["aligned"]
    assert 0 < n_ok < 40 and t["n"] == n_ok and sum(h["counts"]) == n_ok
    assert 0 < t["median"] <= t["p90"] <= t["max"] < 1.0
    lines = c.read_text().splitlines()
    assert lines[0].endswith(",outcome,steps,time_to_align_s") and len(lines) == 41
    rows = [line.split(",") for line in lines[1:]]
    times = [float(row[8]) for row in rows if row[6] == "aligned"]
    assert len(times) == n_ok and all(row[8] == "" for row in rows if row[6] != "aligned")
    assert np.median(times) == pytest.approx(t["median"], rel=1e-9)
    from PIL import Image

    with Image.open(p) as im:
        assert im.size[0] > 400 and im.size[1] > 200
    out = capsys.readouterr().out
    assert "time to align" in out and "median" in out and "90th percentile" in out


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--method", "newton"], "invalid choice: 'newton'"),
        (
            ["--method", "greedy", "--time-plot", "OUT/t.png"],
            "--time-plot needs --method overdamped or inertial",
        ),
        (["--method", "overdamped", "--time-plot", "OUT/t.jpg"], "must end in"),
        (
            ["--method", "inertial", "--random", "2000", "--chunk", "2000", "--memory-budget", "8"],
            "solver states of",
        ),
    ],
)
def test_cli_bad_method_or_output_one_line_exit_2_no_files(fp_png, tmp_path, run_cli, extra, match):
    out = tmp_path / "out"
    out.mkdir()
    extra = [e.replace("OUT", str(out)) for e in extra]
    starts = [] if "--random" in extra else ["--grid", "0:40:20,0"]
    spread = ["--spread", "1,1,0"] if "--random" in extra else []
    rc, _, err = run_cli(
        BASE + ["--pattern", str(fp_png), "--json", str(out / "s.json"), *starts, *spread] + extra
    )
    assert rc == 2 and match in err and len(err.strip().splitlines()) == 1, err
    assert list(out.iterdir()) == []


def test_cli_evaluate_method_overdamped(tmp_path, capsys, run_cli):
    out = tmp_path / "ev"
    rc = main(
        [
            "evaluate",
            str(SQUARE),
            "--chip-size",
            "200",
            "--resolution",
            "10",
            "--no-twist",
            "--method",
            "overdamped",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["settings"]["method"] == "overdamped"
    for part in ("capture", "yield"):
        t = s[part]["time_to_align_s"]
        assert (
            t["n"] == s[part]["outcomes"]["aligned"] > 0
            and 0 <= t["median"] <= t["p90"] <= t["max"] < 1.0
        )
    assert (out / "time_to_align.png").stat().st_size > 0
    page = (out / "report.html").read_text()
    assert (
        "Time to align" in page
        and 'src="time_to_align.png"' in page
        and "overdamped starts" in page
    )
    assert "time to align" in capsys.readouterr().out
    # the flag is refused in one line when the method is not one of the four
    rc, _, err = run_cli(
        [
            "evaluate",
            str(SQUARE),
            "--chip-size",
            "200",
            "--method",
            "newton",
            "--out",
            str(tmp_path / "bad"),
        ]
    )
    assert (
        rc == 2
        and len(err.strip().splitlines()) == 1
        and "invalid choice: 'newton'" in err
        and not (tmp_path / "bad").exists()
    )


SWEEP = """
[scene]
resolution_um = 10
chip_size_um = 200
[scene.effects]
twist = false

[design]
name = "four-pad"
size = 200
gap = 20

[axes]
method = METHODS
placement_sigma_um = 20

[sweep]
seed = 1
yield_starts = 40
capture_grid = 5
"""


def test_sweep_file_method_axis_runs_the_dynamics(tmp_path, capsys):
    f = tmp_path / "s.toml"
    f.write_text(SWEEP.replace("METHODS", '["greedy", "inertial"]'))
    assert main(["sweep", str(f), "--out", str(tmp_path / "out"), "--workers", "0", "--quiet"]) == 0
    import pandas as pd

    # pandas' selections are unions of frames, series and arrays: Any
    table: Any = pd.read_csv(tmp_path / "out" / "results.csv")
    assert list(table["method"]) == ["greedy", "inertial"] and (table["status"] == "ok").all()
    greedy, inertial = table.iloc[0], table.iloc[1]
    assert (
        np.isnan(greedy["yield_time_to_align_median_s"])
        and inertial["yield_time_to_align_median_s"] > 0
    )
    assert inertial["yield_time_to_align_median_s"] <= inertial["yield_time_to_align_p90_s"]
    # the point equals evaluate's assessment with the same method and draws
    scene = Scene.from_dict(
        {
            "pattern": mask_from_geometry(four_pad(200, 20), 10.0, margin_um=10),
            "chip_size_um": [200, 200],
            "resolution_um": 10,
            "effects": {"twist": False},
        }
    )
    direct = flatten(
        assess(
            scene,
            method="inertial",
            seed=int(inertial["point_seed"]),
            placement_sigma=(20, 20, 2.0),
            yield_starts=40,
            grid_cells=5,
        )
    )
    for key in (
        "yield_fraction",
        "yield_time_to_align_median_s",
        "yield_time_to_align_p90_s",
        "capture_time_to_align_median_s",
    ):
        assert inertial[key] == pytest.approx(direct[key], rel=1e-12), key
    # a method that is not one of the four: one line, nothing written
    f.write_text(SWEEP.replace("METHODS", '"newton"'))
    assert main(["sweep", str(f), "--out", str(tmp_path / "bad"), "--workers", "0", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert (
        len(err.strip().splitlines()) == 1
        and '"greedy", "gradient", "overdamped", "inertial"' in err
    ), err
    assert not (tmp_path / "bad").exists()
