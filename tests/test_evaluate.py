"""``selfalign evaluate``: the files, their keys and units, and bad input."""

import json
import re

import imageio.v3 as iio
import numpy as np
import pytest

from patterns import write_mask
from patterns.geometry import four_pad, mask_from_geometry
from patterns.library import library_path
from simulator.cli import main

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("evaluate")


@pytest.fixture(scope="module")
def fourpad_png(tmp_path_factory):
    path = tmp_path_factory.mktemp("ev") / "fp.png"
    write_mask(path, mask_from_geometry(four_pad(200, 20), 2.0, margin_um=10))
    return path


@pytest.fixture(scope="module")
def report(fourpad_png, tmp_path_factory):
    out = tmp_path_factory.mktemp("rep") / "report"
    assert (
        main(["evaluate", str(fourpad_png), "--out", str(out), "--quiet", "--twist-step", "3"]) == 0
    )
    return out


def test_writes_every_file_with_units(report):
    names = {
        "summary.json",
        "landscape.png",
        "force.png",
        "capture.png",
        "pattern.png",
        "report.html",
    }
    assert names <= {p.name for p in report.iterdir()}
    s = json.loads((report / "summary.json").read_text())
    g = s["global_minimum"]
    assert (g["x_um"], g["y_um"], g["twist_deg"]) == (0.0, 0.0, 0.0)
    # float32 landscape: within its noise floor, 32 eps(float32) of max|E| (the FFT round-off
    # bound), and max|E| is this overlap's energy (rel=1e-6, 8 eps, was one FFT path's luck)
    assert g["overlap_um2"] == pytest.approx(4 * 90**2, rel=32 * float(np.finfo(np.float32).eps))
    # Four-pad: the force near alignment is |dgamma| (L - g) (C4) and points back.
    f = s["restoring_force_N"]["+x"][0]
    assert f == pytest.approx(s["settings"]["delta_gamma_N_m"] * 180e-6, rel=1e-3)
    # Max bias is one pad, p = 90 um, within one pixel (C3).
    for k in ("+x", "-x", "+y", "-y"):
        assert abs(s["max_bias_um"][k] - 90) <= 2
    assert any(abs(a - 90) <= 2 and abs(b - 110) <= 2 for a, b in s["plateaus_um"]["x"])
    assert 0 < s["capture"]["fraction"] <= 1 and s["yield"]["n"] == 2000
    assert s["yield"]["placement_sigma"] == {"x_um": 20.0, "y_um": 20.0, "twist_deg": 2.0}
    for png in ("landscape.png", "force.png", "capture.png", "pattern.png"):
        assert iio.imread(report / png).ndim == 3


def test_html_references_files_that_exist(report):
    page = (report / "report.html").read_text()
    refs = re.findall(r'src="([^"]+)"', page)
    assert set(refs) == {"pattern.png", "force.png", "landscape.png", "capture.png"}
    assert all((report / r).exists() for r in refs)
    assert "um" in page and "uN" in page and "deg" in page


def test_library_pattern_needs_no_other_flag(tmp_path):
    out = tmp_path / "sq"
    assert (
        main(
            [
                "evaluate",
                str(library_path("square_200")),
                "--out",
                str(out),
                "--quiet",
                "--twist-step",
                "5",
            ]
        )
        == 0
    )
    s = json.loads((out / "summary.json").read_text())
    assert s["settings"]["chip_um"] == [200.0, 200.0]  # default chip: the pattern's bounding box
    assert s["capture"]["fraction"] == 1.0


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.png"], "missing.png"),
        (["{pat}", "--chip", "nochip.png"], "nochip.png"),
        (["{pat}", "--pad-angle", "80"], "Delta_gamma"),
    ],
)
def test_bad_input_leaves_no_directory(fourpad_png, tmp_path, capsys, args, message):
    out = tmp_path / "out"
    args = [a.replace("{pat}", str(fourpad_png)) for a in args]
    assert main(["evaluate", *args, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_unwritable_output_directory(fourpad_png, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["evaluate", str(fourpad_png), "--out", str(blocker / "rep"), "--quiet"]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_report_page_shows_a_refined_minimum_to_a_thousandth():
    from simulator.batch._evaluate import _at

    assert [_at(v) for v in (-0.000102256, 1.23456, -2.5e-07, 12.0)] == ["0", "1.235", "0", "12"]


def test_a_flat_stretch_one_sample_long_ends_the_max_bias():
    # The 730/50 four-pad at 5 um/px with free contact lines (20 nl, no footprint state):
    # its flat part (406-410 um at 2 um/px) is one 5 um step here, 405-410 um, equal to the
    # noise floor, which the central-difference force straddles (it points back at every
    # sample). The greedy steps see it: released at 410 um the chip stops, at 405 um it
    # aligns. The max bias is where they stop, 405 um, not 795 um.
    from simulator.batch._evaluate import max_bias_along
    from simulator.landscape import build_landscape
    from simulator.motion import simulate
    from simulator.physics import Liquid
    from simulator.scene import Effects, Scene

    scene = Scene.from_inputs(
        library_path("four_pad_730_50"),
        chip_size_um=730,
        resolution_um=5.0,
        effects=Effects(twist=False, meniscus=True),
        liquid=Liquid(volume_nl=20.0),
    )
    scene = scene.replace(liquid=Liquid(volume_nl=20.0, dispense="none"))
    assert scene.dispense is None  # the stateless landscape
    ls = build_landscape(scene)
    c = ls.curve("x", (0.0, 0.0, 0.0), -800, 800)
    floor = [-20.0, 20.0]
    plus, minus = max_bias_along(
        c["values"], c["force"], 0.0, floor, c["energy_J"], ls.noise_floor_J
    )
    assert plus == minus == 405.0
    assert max_bias_along(c["values"], c["force"], 0.0, floor) == (795.0, 795.0)  # force alone
    ends = [simulate(scene, (b, 0.0, 0.0), "greedy", landscape=ls).outcome for b in (405, 410)]
    assert ends == ["aligned", "plateau"]
    # the curve lists that step as flat on both sides (no plateau: the force is not zero),
    # beside the floor's plateau, which its own ties do not repeat
    assert c["flat_steps"] == [[-410.0, -405.0], [405.0, 410.0]]
    assert c["plateaus"] == [[-15.0, 15.0]]


def test_flat_steps_are_neighbours_within_the_noise_floor_away_from_plateaus():
    # Samples 0..9 (um): a tie between 3, 4 and 5 (two flat steps in a row: one range), a
    # plateau at 7-9 whose own ties are not repeated, one comparison not allowed (another
    # state on a released curve), and no contact at 0 (no step reaches it).
    from simulator.landscape._landscape import curve_of

    floor = 1e-12
    v = np.arange(10.0)
    e = -np.array([0.0, 10, 9, 8, 8, 8, 7, 6, 6, 6]) * 1e-9
    e[4] += 0.5 * floor  # within the floor of its neighbours
    force = np.array([1, 1, 1, 0.5, 0.5, 0.5, 1, 0, 0, 0]) * 1e-6
    c = curve_of("x", v, e, force, floor)
    assert c["plateaus"] == [[7.0, 9.0]]
    assert c["flat_steps"] == [[3.0, 5.0]]
    assert c["no_contact"] == []
    linked = np.ones(9, bool)
    linked[3] = False  # samples 3 and 4 on different states
    assert curve_of("x", v, e, force, floor, linked)["flat_steps"] == [[4.0, 5.0]]
    assert curve_of("x", v, e * 0 - 1e-9 * v, force, floor)["flat_steps"] == []  # a slope
