"""``selfalign energy`` end to end: values, JSON keys with units, bad input."""

import json
import re

import numpy as np
import pytest

from patterns import write_mask
from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.cli import main
from simulator.physics import Materials

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("energy_cli")


@pytest.fixture(scope="module")
def fourpad_png(tmp_path_factory):
    path = tmp_path_factory.mktemp("pat") / "fourpad.png"
    write_mask(path, mask_from_geometry(four_pad(200, 20), 1.0, margin_um=8))
    return path


@pytest.fixture(scope="module")
def chip_png(tmp_path_factory):
    path = tmp_path_factory.mktemp("chip") / "chip.png"
    write_mask(path, mask_from_geometry(square(200), 1.0))
    return path


@pytest.mark.fft
def test_poses_and_json_keys(fourpad_png, tmp_path, capsys):
    out = tmp_path / "e.json"
    rc = main(
        [
            "energy",
            "--pattern",
            str(fourpad_png),
            "--chip-size",
            "200",
            "--at",
            "40,25,0",
            "--at",
            "95,0,0",
            "--json",
            str(out),
        ]
    )
    assert rc == 0
    doc = json.loads(out.read_text())
    first, second = doc["poses"]
    assert set(first) == {
        "x_um",
        "y_um",
        "twist_deg",
        "overlap_um2",
        "energy_J",
        "force_N",
        "torque_Nm",
    }
    # float32: each energy within the noise floor (32 eps(float32) max|E|, the FFT round-off
    # bound) of the exact one, 0.12 um^2 at max|E| = 32,400 um^2 (abs=0.05 was one path's
    # luck); a force, a central difference over +-1 px, within floor / 1 px.
    dg = Materials().delta_gamma_N_m
    floor_J = doc["noise_floor_J"]
    floor_um2 = floor_J / (abs(dg) * 1e-12)
    assert floor_um2 == pytest.approx(32 * float(np.finfo(np.float32).eps) * 4 * 90**2)
    assert first["overlap_um2"] == pytest.approx(21700, abs=floor_um2)  # C2
    assert second["overlap_um2"] == pytest.approx(16200, abs=floor_um2)
    assert first["energy_J"] == pytest.approx(dg * 21700e-12, abs=floor_J)
    assert first["force_N"][0] == pytest.approx(
        dg * (180 - 25) * 1e-6, abs=floor_J / (doc["um_per_px"] * 1e-6)
    )  # C4 with y-bias
    printed = re.search(r"overlap ([\d,.]+) um\^2", capsys.readouterr().out)
    assert printed is not None
    assert float(printed[1].replace(",", "")) == pytest.approx(21700, abs=floor_um2 + 0.05)


def test_chip_png_equals_chip_size(fourpad_png, chip_png, tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert (
        main(
            [
                "energy",
                "--pattern",
                str(fourpad_png),
                "--chip",
                str(chip_png),
                "--at",
                "30,-70,4",
                "--json",
                str(a),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "energy",
                "--pattern",
                str(fourpad_png),
                "--chip-size",
                "200x200",
                "--at",
                "30,-70,4",
                "--json",
                str(b),
            ]
        )
        == 0
    )
    ea, eb = (json.loads(p.read_text())["poses"][0]["overlap_um2"] for p in (a, b))
    assert ea == pytest.approx(eb, rel=2e-3)  # bilinear resampling vs exact rotation


@pytest.mark.fft
def test_curve_reports_plateau(fourpad_png, tmp_path):
    out = tmp_path / "c.json"
    rc = main(
        [
            "energy",
            "--pattern",
            str(fourpad_png),
            "--chip-size",
            "200",
            "--no-twist",
            "--at",
            "0,0,0",
            "--curve",
            "x",
            "--from",
            "0",
            "--to",
            "150",
            "--json",
            str(out),
        ]
    )
    assert rc == 0
    cur = json.loads(out.read_text())["curve"]
    assert len(cur["values_um"]) == 151 and len(cur["energy_J"]) == 151
    ((start, end),) = cur["plateaus_um"]
    assert abs(start - 90) <= 1 and abs(end - 110) <= 1
    assert cur["flat_steps_um"] == []  # the plateau's own ties are not repeated as steps


@pytest.mark.fft
def test_twist_curve(fourpad_png, tmp_path):
    out = tmp_path / "t.json"
    assert (
        main(
            [
                "energy",
                "--pattern",
                str(fourpad_png),
                "--chip-size",
                "200",
                "--at",
                "0,0,0",
                "--curve",
                "twist",
                "--from",
                "-10",
                "--to",
                "10",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    cur = json.loads(out.read_text())["curve"]
    e = cur["energy_J"]
    assert cur["values_deg"][10] == 0 and e[10] == min(e)  # minimum at zero twist
    # Even in twist. Each float32 plane is within the landscape's noise floor of the exact
    # value, 32 eps(float32) max|E| (simulator.landscape: the FFT round-off bound), so
    # the two ends differ by at most twice that; rel=1e-6 (8 eps) held on one FFT path only.
    floor = 32 * float(np.finfo(np.float32).eps) * max(abs(v) for v in e)
    assert abs(e[0] - e[-1]) <= 2 * floor


@pytest.mark.parametrize(
    "args, message",
    [
        (["--pattern", "missing.png", "--chip-size", "200", "--at", "0,0,0"], "missing.png"),
        (["--pattern", "{pat}", "--at", "0,0,0"], "no chip given"),
        (["--pattern", "{pat}", "--chip-size", "200", "--at", "1,2"], "--at must be X,Y,TWIST"),
        (["--pattern", "{pat}", "--chip-size", "-5", "--at", "0,0,0"], "--chip-size"),
        (
            ["--pattern", "{pat}", "--chip-size", "200", "--at", "0,0,0", "--pad-angle", "70"],
            "Delta_gamma",
        ),
        (
            ["--pattern", "{pat}", "--chip-size", "200", "--at", "0,0,0", "--memory-budget", "1"],
            "memory budget",
        ),
        (["--pattern", "{pat}", "--chip-size", "200", "--curve", "x"], "--from"),
        (
            [
                "--pattern",
                "{pat}",
                "--chip-size",
                "200",
                "--at",
                "0,0,0",
                "--window",
                "20",
                "--curve",
                "x",
                "--from",
                "0",
                "--to",
                "100",
            ],
            "outside",
        ),
    ],
)
def test_bad_input_one_line_exit_2_no_output(fourpad_png, tmp_path, capsys, args, message):
    out = tmp_path / "bad.json"
    args = [a.replace("{pat}", str(fourpad_png)) for a in args]
    assert main(["energy", *args, "--json", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()
