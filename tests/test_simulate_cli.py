"""``selfalign simulate`` end to end on the pattern library: every method, outputs, bad input."""

import json

import imageio.v3 as iio
import pytest

from patterns.library import library_path
from simulator.cli import main

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("simulate_cli")

SQUARE = str(library_path("square_200"))
KEYS = {"method", "outcome", "start", "final", "steps", "time_s", "path"}


@pytest.mark.parametrize("method", ["greedy", "gradient", "overdamped", "inertial"])
def test_every_method_aligns_and_writes_json_and_plot(method, tmp_path, capsys):
    out, plot = tmp_path / "t.json", tmp_path / "t.png"
    rc = main(
        [
            "simulate",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--start",
            "40,-30,6",
            "--method",
            method,
            "--volume",
            "0.5",
            "--json",
            str(out),
            "--plot",
            str(plot),
        ]
    )
    assert rc == 0
    doc = json.loads(out.read_text())
    assert KEYS <= set(doc) and doc["method"] == method and doc["outcome"] == "aligned"
    assert doc["start"] == {"x_um": 40.0, "y_um": -30.0, "twist_deg": 6.0}
    assert set(doc["final"]) == {"x_um", "y_um", "twist_deg"}
    assert abs(doc["final"]["x_um"]) <= 1 and abs(doc["final"]["y_um"]) <= 1
    assert len(doc["path"]) == doc["steps"] + 1 and "energy_J" in doc["path"][0]
    if method in ("overdamped", "inertial"):
        # under a millisecond for water with the damping's terms (docs/physics.md §4; it was tens
        # of ms with the former calibration)
        assert 1e-5 < doc["time_s"] < 1.0 and "t_s" in doc["path"][-1]
        assert doc["path"][-1]["t_s"] == pytest.approx(doc["time_s"])
    else:
        assert doc["time_s"] is None and "t_s" not in doc["path"][0]
    assert iio.imread(plot).ndim == 3
    assert "aligned at" in capsys.readouterr().out


def test_scene_file_and_flag_override(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(
        f'pattern = "{SQUARE}"\nchip_size_um = [200, 200]\n[simulate]\nstart = [30, 0, 0]\nmethod = "greedy"\n'
    )
    assert main(["simulate", str(scene)]) == 0
    assert "after 30 steps" in capsys.readouterr().out
    assert main(["simulate", str(scene), "--start", "12,0,0"]) == 0
    assert "after 12 steps" in capsys.readouterr().out


@pytest.mark.parametrize(
    "args, message",
    [
        (["--pattern", SQUARE, "--chip-size", "200"], "--start"),
        (
            ["--pattern", SQUARE, "--chip-size", "200", "--start", "1,2,x"],
            "--start must be X,Y,TWIST",
        ),
        (
            ["--pattern", SQUARE, "--chip-size", "200", "--start", "1,2,3", "--max-steps", "0"],
            "max steps",
        ),
        (
            ["--pattern", SQUARE, "--chip-size", "200", "--start", "1,2,3", "--volume", "-1"],
            "droplet volume",
        ),
        (["--pattern", SQUARE, "--chip", "nothere.png", "--start", "1,2,3"], "nothere.png"),
        (
            [
                "--pattern",
                SQUARE,
                "--chip-size",
                "200",
                "--start",
                "1,2,3",
                "--json",
                "/nonexistent/dir/t.json",
            ],
            "does not exist",
        ),
    ],
)
def test_bad_input(args, message, tmp_path, capsys):
    plot = tmp_path / "p.png"
    assert main(["simulate", *args, "--plot", str(plot)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not plot.exists()
