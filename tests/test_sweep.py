"""``selfalign sweep``: points equal the evaluate assessment, error rows, resume (also after a kill), bad input."""

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

import simulator
from patterns.geometry import four_pad, mask_from_geometry
from simulator.batch import assess
from simulator.cli import main
from simulator.scene import Scene
from simulator.sweep import dask_client, flatten, load_sweep, run_sweep

# One xdist group for the module (make test: --dist loadgroup): its tests share the Dask
# worker and the tiny sweep of the module's fixtures, made once on one worker.
pytestmark = pytest.mark.xdist_group("sweep")

ROOT = Path(__file__).resolve().parents[1]

#: Two axes on a small four-pad at a coarse pixel, no twist; gap 250 > size 200 cannot be built.
TINY = """
[scene]
resolution_um = 5
[scene.effects]
twist = false

[design]
name = "four-pad"
size = 200
gap = 20

[axes]
gap = [20, 40, 250]
volume_nl = [0.5, 1]
placement_sigma_um = 20

[sweep]
seed = 1
yield_starts = 200
capture_grid = 9
"""
#: Timing columns: the only ones that differ between two runs of one point.
TIMING = {"seconds", "settings_landscape_s"}


@pytest.fixture(scope="module")
def cluster():
    """One local Dask worker shared by the tests (a worker's first point compiles the steppers)."""
    with dask_client(workers=1) as client:
        yield client.scheduler.address


@pytest.fixture(scope="module")
def tiny(tmp_path_factory, cluster):
    d = tmp_path_factory.mktemp("sw")
    (d / "tiny.toml").write_text(TINY)
    table = run_sweep(d / "tiny.toml", d / "out", scheduler=cluster)
    return d, table


def test_points_equal_the_evaluate_assessment(tiny):
    d, table = tiny
    assert len(table) == 6 and list(table["point"]) == list(range(6))
    assert (
        table["point_seed"].nunique() == 1
    )  # one realization: every design meets the same placement draws
    ok = table[table["status"] == "ok"]
    assert len(ok) == 4 and set(ok["gap_um"]) == {20, 40}
    for _, row in ok.iterrows():
        scene = Scene.from_dict(
            {
                "pattern": mask_from_geometry(four_pad(200, row["gap_um"]), 5.0, margin_um=10),
                "chip_size_um": [200, 200],
                "resolution_um": 5,
                "effects": {"twist": False},
                "liquid": {"volume_nl": row["volume_nl"]},
            }
        )
        direct = flatten(
            assess(
                scene,
                seed=int(row["point_seed"]),
                placement_sigma=(20, 20, 0),
                yield_starts=200,
                grid_cells=9,
            )
        )
        for key, value in direct.items():
            if key not in TIMING:
                assert row[key] == value, key
        assert row["settings_volume_nl"] == row["volume_nl"]
    # The four-pad's physics, in the columns' units: max bias one pad side, p = (L - g) / 2.
    assert list(ok["max_bias_x_um"]) == [90.0, 90.0, 80.0, 80.0]
    assert (
        ok["yield_placement_sigma_x_um"].eq(20).all() and ok["capture_fraction"].between(0, 1).all()
    )


def test_failed_point_is_one_error_row(tiny):
    _, table = tiny
    bad = table[table["status"] == "error"]
    assert list(bad["gap_um"]) == [250, 250]
    assert all(
        "gap=250 um must be smaller than size=200 um" in e and "\n" not in e for e in bad["error"]
    )
    assert bad["max_bias_x_um"].isna().all()


def test_files_tables_pictures_and_page(tiny):
    d, table = tiny
    out = d / "out"
    pq = pd.read_parquet(out / "results.parquet")
    csv = pd.read_csv(out / "results.csv")
    assert list(pq.columns) == list(table.columns) == list(csv.columns)
    assert pq["max_bias_x_um"].equals(table["max_bias_x_um"]) and np.allclose(
        csv["capture_fraction"], table["capture_fraction"], equal_nan=True
    )
    for col in (
        "gap_um",
        "volume_nl",
        "max_bias_x_um",
        "max_bias_plus_x_um",
        "capture_fraction",
        "yield_fraction",
        "restoring_force_plus_x_x_N",
        "global_minimum_x_um",
        "settings_um_per_px",
    ):
        assert col in table.columns
    lines = (out / "points.jsonl").read_text().splitlines()
    assert sorted(json.loads(x)["point"] for x in lines) == list(range(6))
    doc = json.loads((out / "points" / "00002.json").read_text())
    assert (
        doc["settings"] == {"gap": 40, "volume_nl": 0.5, "placement_sigma_um": 20}
        and doc["summary"]["max_bias_um"]["+x"] == 80.0
    )
    pics = {p.name for p in out.glob("*.png")}
    assert {
        "heatmap_max_bias_x_um.png",
        "heatmap_capture_fraction.png",
        "heatmap_yield_fraction.png",
    } <= pics
    page = (out / "report.html").read_text()
    refs = re.findall(r'(?:src|href)="([^"]+)"', page)
    assert "points/00005.json" in refs and all((out / r).exists() for r in refs)
    marker = json.loads((out / ".selfalign-output.json").read_text())
    assert marker["command"] == "sweep" and "results.parquet" in marker["files"]


def test_rerun_skips_the_points_done(tiny, cluster, tmp_path):
    import shutil

    d, table = tiny
    out = tmp_path / "out"  # a copy: the module's other tests read the fixture's own results
    shutil.copytree(d / "out", out)
    journal = (out / "points.jsonl").read_text()
    again = run_sweep(d / "tiny.toml", out, scheduler=cluster, pictures=False)
    assert again.attrs["sweep"]["run_now"] == 0 and (out / "points.jsonl").read_text() == journal
    pd.testing.assert_frame_equal(again, table)
    # Forget two points: exactly those two run again; the other rows stay as they were.
    lines = journal.splitlines(keepends=True)
    (out / "points.jsonl").write_text("".join(lines[:4]))
    kept = {json.loads(x)["point"] for x in lines[:4]}
    # pandas' selections are unions of frames, series and arrays: Any
    third: Any = run_sweep(d / "tiny.toml", out, scheduler=cluster, pictures=False)
    assert third.attrs["sweep"]["run_now"] == 2 and len(third) == 6 and third["point"].is_unique
    same = third[third["point"].isin(kept)].reset_index(drop=True)
    pd.testing.assert_frame_equal(same, table[table["point"].isin(kept)].reset_index(drop=True))


def test_killed_run_resumes_to_the_full_table(tmp_path, cluster):
    # The run to kill uses the shared (warm) worker through --scheduler: a cold worker would
    # spend its first 10 s compiling. Killing a run with its own LocalCluster ends its worker
    # processes too (Dask's nannies watch their parent).
    spec = TINY.replace("gap = [20, 40, 250]", "gap = { from = 20, to = 60, num = 5 }").replace(
        "volume_nl = [0.5, 1]", "volume_nl = [1, 2, 3, 4, 5, 6]"
    )
    (tmp_path / "s.toml").write_text(spec)
    out = tmp_path / "out"
    # The run holds once its second point is journalled (foundation/_hold.py); it is killed there.
    env = os.environ | {"PYTHONWARNINGS": "ignore", "SELFALIGN_HOLD_AT": "sweep-point:2"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "simulator",
            "sweep",
            str(tmp_path / "s.toml"),
            "--out",
            str(out),
            "--scheduler",
            cluster,
            "--quiet",
        ],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    journal = out / "points.jsonl"
    assert proc.stderr is not None
    for line in proc.stderr:  # blocks until the hold line, or the end of a run that never held
        if b"selfalign: holding at sweep-point" in line:
            proc.send_signal(signal.SIGKILL)  # a crash: no handler runs
            break
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, err.decode()[-2000:]
    done = [json.loads(x) for x in journal.read_text().splitlines() if x.endswith("}")]
    assert len(done) == 2
    # pandas' selections are unions of frames, series and arrays: Any
    table: Any = run_sweep(tmp_path / "s.toml", out, scheduler=cluster)
    assert table.attrs["sweep"]["run_now"] == 30 - len(done)
    assert (
        len(table) == 30
        and list(table["point"]) == list(range(30))
        and (table["status"] == "ok").all()
    )
    assert (
        len(pd.read_parquet(out / "results.parquet")) == 30
        and len(pd.read_csv(out / "results.csv")) == 30
    )
    before = {r["point"]: r["seconds"] for r in done}
    assert all(
        table.set_index("point").loc[p, "seconds"] == s for p, s in before.items()
    )  # not run again


def test_a_rerun_removes_a_killed_sweeps_leftovers_and_leaves_no_lock(tiny, tmp_path, cluster):
    import shutil

    d, table = tiny
    assert not (d / "out" / ".sweep.lock").exists()  # a finished sweep leaves no lock
    out = tmp_path / "out"
    shutil.copytree(d / "out", out)
    # What a sweep killed outright (SIGKILL: no handler runs) while it wrote leaves: its lock
    # and its atomic writes' temporaries, named as foundation names them.
    (out / ".sweep.lock").touch()
    dead = [
        out / ".results.parquet.k2j4_x9q.parquet",
        out / ".report.html.a1b2c3d4.html",
        out / ".heatmap_yield_fraction.png.zz00aa11.png",
        out / "points" / ".00003.json.q9w8e7r6.json",
    ]
    for p in dead:
        p.write_bytes(b"half a file")
    mine = [out / ".results.parquet.keep", out / "points" / "notes.txt"]  # not temporaries' names
    for p in mine:
        p.write_text("mine")
    again = run_sweep(d / "tiny.toml", out, scheduler=cluster, pictures=False)
    assert again.attrs["sweep"]["run_now"] == 0
    pd.testing.assert_frame_equal(again, table)
    assert not [p for p in dead if p.exists()]
    assert all(p.read_text() == "mine" for p in mine)
    assert not (out / ".sweep.lock").exists()


def test_python_api_latin_hypercube_realizations_one_axis_picture(tmp_path):
    spec = {
        "scene": {"resolution_um": 10, "effects": {"twist": False}, "chip_size_um": 200},
        "design": {"name": "random-jagged", "size": 200, "sigma": 2, "seed": 7},
        "axes": {"sigma": {"from": 1, "to": 5}},
        "sweep": {
            "samples": 4,
            "seed": 3,
            "realizations": 2,
            "yield_starts": 50,
            "capture_grid": 5,
        },
    }
    # pandas' selections are unions of frames, series and arrays: Any
    table: Any = simulator.run_sweep(spec, tmp_path / "lhs", workers=0)
    assert len(table) == 8 and (table["status"] == "ok").all()
    sig = table["sigma_um"].to_numpy()[::2]
    assert sorted(np.floor((sig - 1) / 1.0).astype(int)) == [
        0,
        1,
        2,
        3,
    ]  # one sample per quarter of [1, 5]
    assert (
        list(table["realization"]) == [0, 1] * 4 and list(table["seed"]) == [7, 8] * 4
    )  # the pattern's seed + realization
    assert (
        table.groupby("realization")["point_seed"].nunique().eq(1).all()
        and table["point_seed"].nunique() == 2
    )
    spec["sweep"]["independent_noise"] = True
    assert len({p.point_seed for p in load_sweep(spec).points()}) == 8
    assert (tmp_path / "lhs" / "sweep_sigma.png").exists()
    # The same spec again, as a SweepSpec: the same plan and hash.
    a, b = load_sweep(spec), load_sweep(spec)
    assert a.digest == b.digest and a.points() == b.points()


def test_flatten_puts_units_last_and_takes_new_metrics():
    flat = flatten(
        {
            "max_bias_um": {"+x": 90, "-x": 80, "+y": 70, "-y": 75},
            "restoring_force_N": {"+x": [-1e-5, 0.0]},
            "global_minimum": {"x_um": 3.0, "y_um": 4.0},
            "stiffness": {"x_N_per_m": 0.5},
            "note": "text",
            "torque": None,
        }
    )
    assert flat == {
        "max_bias_plus_x_um": 90,
        "max_bias_minus_x_um": 80,
        "max_bias_plus_y_um": 70,
        "max_bias_minus_y_um": 75,
        "restoring_force_plus_x_x_N": -1e-5,
        "restoring_force_plus_x_y_N": 0.0,
        "global_minimum_x_um": 3.0,
        "global_minimum_y_um": 4.0,
        "stiffness_x_N_per_m": 0.5,
        "max_bias_x_um": 80.0,
        "max_bias_y_um": 70.0,
        "global_minimum_offset_um": 5.0,
    }


GAP = "gap = [20, 40, 250]"
BAD = [
    ("sigma = [1, 2]", [], "design four-pad has size, gap"),
    ("gap = []", [], "the list is empty"),
    ("gap = { from = 60, to = 20, num = 3 }", [], "the range is inverted"),
    ("gap = { from = 20, to = 20, num = 3 }", [], "the range is empty"),
    ("gap = { from = 20, to = 60 }", [], "a grid needs num = N or step = D"),
    (
        "gap = { from = 1, to = 100, num = 100 }",
        ["--max-points", "50"],
        "more than the cap of 50; pass --max-points 200",
    ),
    (GAP, ["--scheduler", "tcp://127.0.0.1:9"], "cannot reach a Dask scheduler within 3 s"),
    (GAP, ["--scheduler", "nonsense"], "not a Dask scheduler address"),
    (GAP, ["--workers", "1", "--scheduler", "tcp://127.0.0.1:9"], "give --workers or --scheduler"),
]


@pytest.mark.parametrize("axis, flags, message", BAD)
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, axis, flags, message):
    (tmp_path / "s.toml").write_text(TINY.replace(GAP, axis))
    t0 = time.perf_counter()
    assert (
        main(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out"), "--quiet", *flags])
        == 2
    )
    assert time.perf_counter() - t0 < 20  # an unreachable scheduler: within a few seconds, no hang
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "out").exists()


def test_out_holding_another_sweep_or_other_files_is_refused(tiny, tmp_path, capsys):
    d, _ = tiny
    other = tmp_path / "other.toml"
    other.write_text(TINY.replace("volume_nl = [0.5, 1]", "volume_nl = [0.5, 2]"))
    before = sorted(p.name for p in (d / "out").iterdir())
    assert main(["sweep", str(other), "--out", str(d / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "holds a different sweep" in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in (d / "out").iterdir()) == before
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    assert main(["sweep", str(other), "--out", str(mine), "--quiet"]) == 2
    assert "not a selfalign sweep" in capsys.readouterr().err and [
        p.name for p in mine.iterdir()
    ] == ["notes.txt"]


def test_example_sweep_file_is_the_readme_sweep():
    spec = load_sweep(ROOT / "examples" / "sweep_fourpad.toml")
    assert spec.n_points == 24 and [a.name for a in spec.swept] == ["gap", "volume_nl"]
    assert spec.design is not None
    assert (
        spec.design["name"] == "four-pad"
        and spec.design["params"]["size"] == 730
        and spec.scene["effects"] == {"meniscus": True}
    )
    p = spec.points()[5]
    assert spec.columns(p) == {
        "point": 5,
        "realization": 0,
        "point_seed": p.point_seed,
        "gap_um": 50,
        "volume_nl": 10,
        "placement_sigma_um": 150,
        "placement_sigma_deg": 2,
        "design": "four-pad",
        "size_um": 730,
    }


def test_a_directory_another_sweep_is_writing_into_is_refused(tiny, capsys):
    import fcntl

    d, _ = tiny
    with open(d / "out" / ".sweep.lock", "a+") as f:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a running sweep holds it
        assert main(["sweep", str(d / "tiny.toml"), "--out", str(d / "out"), "--quiet"]) == 2
    assert "another selfalign sweep is writing into it" in capsys.readouterr().err
