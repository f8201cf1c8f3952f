"""What a newcomer meets in the first hour (issue 39, items 1, 2 and 5).

Implausible scales are refused before any work (a chip off by about 1000 from the pattern, a
chip under 3 px) or warned of (a chip much larger than the pattern's image); a drawing of the
wrong polarity is warned of, a colour drawing refused unless its channels agree or
``--channel`` picks one, a JPEG's speckle named as such; and the small things: the README's
Python snippet from any directory, "did you mean" for a misspelled flag, the usage line of a
design's required parameters, ``energy --quiet``, the free-form report's minimum to the grid,
the evaluate report's header, evaluate's placement noise, ``make demo``'s install.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_line_error
from PIL import Image

from foundation import InputError
from patterns import read_mask
from patterns.geometry import Mask
from patterns.library import library_path

ROOT = Path(__file__).resolve().parents[1]
FOURPAD = library_path("four_pad_730_50")  # 750 x 750 px at 1 um/px, pads 340 um, gap 50 um


def _no_work(monkeypatch) -> None:
    """Any landscape or chip raster made from here on fails the test: a refusal comes first."""

    def boom(*a, **k):
        raise AssertionError("work was done before the refusal")

    import simulator.landscape
    import simulator.scene._build

    monkeypatch.setattr(simulator.landscape, "build_landscape", boom)
    monkeypatch.setattr(simulator.scene._build, "mask_from_geometry", boom)


def _fourpad_wet() -> np.ndarray:
    return read_mask(FOURPAD).data >= 0.5


# ------------------------------------------------------------------ item 1: implausible scales


def test_chip_size_in_mm_is_refused_before_any_work(run_cli, tmp_path, monkeypatch):
    _no_work(monkeypatch)
    out = tmp_path / "r0"
    rc, stdout, err = run_cli(["evaluate", FOURPAD, "--chip-size", "0.73", "--out", out])
    one_line_error(rc, err, "1000 times smaller", "in mm?", "--chip-size 730")
    assert stdout == "" and not out.exists()


def test_chip_size_in_nm_is_refused(run_cli, tmp_path, monkeypatch):
    _no_work(monkeypatch)
    rc, _, err = run_cli(["energy", "--pattern", FOURPAD, "--chip-size", "730000", "--at", "0,0,0"])
    one_line_error(rc, err, "1000 times larger", "in nm?", "--chip-size 730")


def test_pattern_scale_in_mm_per_px_is_refused(run_cli, tmp_path, monkeypatch):
    _no_work(monkeypatch)
    json_out = tmp_path / "e.json"
    rc, _, err = run_cli(
        ["energy", "--pattern", FOURPAD, "--um-per-px", "0.001", "--override-scale"]
        + ["--chip-size", "730", "--at", "0,0,0", "--json", json_out]
    )
    # the pattern is 0.73 um across at 0.001 um/px: its scale was typed in mm per px
    one_line_error(rc, err, "1000 times larger", "scale in mm per px?", "--um-per-px 1 ")
    assert not json_out.exists()


def test_chip_under_three_pixels_is_refused(run_cli, monkeypatch):
    _no_work(monkeypatch)
    # 20 um at 10 um/px: 2 px (the chip is 1/36 of the pattern: no unit slip)
    rc, _, err = run_cli(
        ["simulate", "--pattern", FOURPAD, "--chip-size", "20", "--resolution", "10"]
        + ["--start", "0,0,0"]
    )
    one_line_error(rc, err, "spans 2 px at 10 um/px", "--resolution")


def test_python_api_refuses_the_slip_too():
    with pytest.raises(InputError, match=r"about 1000 times smaller.*--chip-size 730"):
        from simulator import Scene

        Scene.from_inputs(FOURPAD, chip_size_um=0.73)


def test_chip_much_larger_than_the_image_is_one_warning(run_cli):
    rc, stdout, err = run_cli(
        ["energy", "--pattern", FOURPAD, "--chip-size", "2000", "--at", "100,0,0", "--no-twist"]
        + ["--resolution", "10"]
    )
    assert rc == 0, err
    assert err.count("\n") == 1 and err.startswith("warning: the 2000 x 2000 um chip is 2.67 times")
    # (2000 - 730) / 2 um: where every pad is under the chip, and the energy flat
    assert "within about 635 um of the centre" in err and "plateau" in err
    assert "force (0.0000e+00, 0.0000e+00) N" in stdout  # on the plateau indeed


# ------------------------------------------------------------------ item 2: polarity and colour


def test_pattern_drawn_black_on_white_is_warned_of(run_cli, tmp_path):
    wet = _fourpad_wet()
    path = tmp_path / "inverted.png"
    Image.fromarray(((~wet) * 255).astype(np.uint8)).save(path)
    args = ["energy", "--pattern", path, "--um-per-px", "1", "--chip-size", "730", "--at", "0,0,0"]
    rc, _, err = run_cli(args)
    assert rc == 0, err
    assert err.count("\n") == 1 and err.startswith("warning: ")
    assert "touches all four image borders" in err and "give --invert" in err
    rc, stdout, err = run_cli([*args, "--invert"])
    assert rc == 0 and err == "", err
    assert "overlap 462,400.0 um^2" in stdout  # the four 340 um pads under the chip


def test_all_white_image_is_warned_of(run_cli, tmp_path):
    path = tmp_path / "white.png"
    Image.fromarray(np.full((300, 300), 255, np.uint8)).save(path)
    rc, _, err = run_cli(
        ["energy", "--pattern", path, "--um-per-px", "1", "--chip-size", "100", "--at", "0,0,0"]
    )
    assert rc == 0, err
    assert err.count("\n") == 1 and "covers the whole image" in err and "--invert" in err


def test_library_patterns_are_not_warned_of():
    from patterns import polarity_warning

    for name in ("four_pad_730_50", "four_pad_710_100", "defect_C_outward", "constant_jagged_a1p7"):
        assert polarity_warning(read_mask(library_path(name))) is None, name


def _red_on_white(tmp_path) -> Path:
    wet = _fourpad_wet()
    rgb = np.full(wet.shape + (3,), 255, np.uint8)
    rgb[wet] = (255, 0, 0)
    path = tmp_path / "red.png"
    Image.fromarray(rgb).save(path)
    return path


def test_colour_drawing_is_refused_before_any_work(run_cli, tmp_path, monkeypatch):
    _no_work(monkeypatch)
    json_out = tmp_path / "e.json"
    rc, stdout, err = run_cli(
        ["energy", "--pattern", _red_on_white(tmp_path), "--um-per-px", "1"]
        + ["--chip-size", "730", "--at", "0,0,0", "--json", json_out]
    )
    one_line_error(rc, err, "channels differ (by up to 255 of 255 levels)", "--channel")
    assert stdout == "" and not json_out.exists()


def test_channel_picks_one_and_reads_as_the_grey_drawing(run_cli, tmp_path):
    common = ["--um-per-px", "1", "--chip-size", "730", "--at", "40,25,0", "--no-twist"]
    grey = tmp_path / "grey.png"
    Image.fromarray((_fourpad_wet() * 255).astype(np.uint8)).save(grey)
    rc, want, err = run_cli(["energy", "--pattern", grey, *common])
    assert rc == 0 and err == "", err
    # the green channel of red pads on white: the pads dark, so inverted, is the grey drawing
    red = _red_on_white(tmp_path)
    rc, got, err = run_cli(["energy", "--pattern", red, *common, "--channel", "green", "--invert"])
    assert rc == 0 and err == "", err
    assert got == want


def test_jpeg_speckle_is_named_with_its_fix(tmp_path):
    from simulator.scene import feature_warning

    data = np.zeros((200, 200))
    data[50:150, 50:150] = 1.0
    data[20:22, 20:22] = 1.0  # a stray 2 x 2 px speck: a "feature" under 3 px at 1 um/px
    plain = feature_warning(Mask(data, 1.0), 1.0)
    assert plain is not None and "--resolution 0.5" in plain
    lossy = feature_warning(Mask(data, 1.0, params={"lossy_format": "JPEG"}), 1.0)
    assert lossy is not None and "lossy JPEG compression" in lossy
    assert "save it as PNG" in lossy and "--resolution 0." not in lossy
    # the reader names the format of a JPEG, and of no PNG
    Image.fromarray((data * 255).astype(np.uint8)).save(tmp_path / "p.jpg", quality=90)
    Image.fromarray((data * 255).astype(np.uint8)).save(tmp_path / "p.png")
    assert read_mask(tmp_path / "p.jpg", um_per_px=1).params["lossy_format"] == "JPEG"
    assert "lossy_format" not in read_mask(tmp_path / "p.png", um_per_px=1).params


# ------------------------------------------------------------------ item 5: the small things


def test_readme_python_snippet_runs_from_any_directory(tmp_path):
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks, "the README has a Python snippet"
    code = blocks[0] + "\nprint(t.outcome)\n"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().splitlines()[-1] == "aligned"
    assert list(tmp_path.iterdir()) == []  # nothing written where it ran


def test_misspelled_flag_gets_did_you_mean_and_the_subcommand_help(run_cli):
    rc, _, err = run_cli(["simulate", "--pattern", FOURPAD, "--chipsize", "730"])
    one_line_error(rc, err, "did you mean --chip-size?", "(see selfalign simulate --help)")
    rc, _, err = run_cli(["pattern", "four-pad", "--size", "730", "--gapp", "50", "-o", "x.png"])
    one_line_error(rc, err, "did you mean --gap?", "(see selfalign pattern four-pad --help)")
    rc, _, err = run_cli(["liquid", "window", "--patern", FOURPAD, "--chip-size", "730"])
    one_line_error(rc, err, "did you mean --pattern?", "(see selfalign liquid window --help)")


def test_required_design_parameters_show_without_brackets(run_cli):
    rc, out, _ = run_cli(["pattern", "four-pad", "--help"])
    assert rc == 0
    usage = " ".join(out.split("\n\n")[0].split())
    assert "--size UM --gap UM" in usage and "[--size" not in usage and "-o OUT.png" in usage
    assert "[--um-per-px UM]" in usage


def test_energy_takes_quiet(run_cli, monkeypatch):
    monkeypatch.setenv("SELFALIGN_WAIT_S", "0")  # every waiting line would show
    rc, out, err = run_cli(
        ["energy", "--pattern", FOURPAD, "--chip-size", "730", "--at", "0,0,0", "--quiet"]
    )
    assert rc == 0 and err == "", err
    assert out.startswith("pose (0 um, 0 um, 0 deg)")


def test_freeform_report_shows_the_minimum_to_the_grid():
    from simulator.design._freeform._report import _pose_text

    noise = {"x_um": 4.934e-08, "y_um": 6.506e-08, "twist_deg": -3.183e-07, "refined": False}
    assert _pose_text({"global_minimum": noise, "grid": {"um": 2.0, "twist_deg": 1.0}}) == (
        "(0, 0, 0)"
    )
    off = {"x_um": 6.0, "y_um": -4.0, "twist_deg": 2.0, "refined": False}
    assert _pose_text({"global_minimum": off, "grid": {"um": 2.0, "twist_deg": 1.0}}) == (
        "(6, -4, 2)"
    )
    below = {"x_um": 1.2345, "y_um": -0.0449, "twist_deg": 0.26, "refined": True}
    assert _pose_text({"global_minimum": below, "grid": {"um": 2.0}}) == "(1.2, 0, 0.3)"


def test_evaluate_report_header_names_no_key():
    from simulator.batch._evaluate import _model_note

    for summary in ({"meniscus_height_um": 24.0, "pinned": True}, {"meniscus_height_um": 24.0}):
        note = _model_note(summary)
        assert "height 24 um" in note and "meniscus_height_um" not in note


def test_evaluate_names_its_placement_noise(run_cli, tmp_path, monkeypatch):
    import simulator.batch
    from simulator.batch import assess

    def few_starts(scene, out, quiet=False, method="greedy", **kw):  # the numbers, fewer starts
        return assess(scene, method=method, yield_starts=20, grid_cells=3)

    monkeypatch.setattr(simulator.batch, "evaluate", few_starts)
    rc, out, err = run_cli(
        ["evaluate", FOURPAD, "--chip-size", "730", "--resolution", "10", "--no-twist"]
        + ["--quiet", "--out", tmp_path / "r"]
    )
    assert rc == 0, err
    # evaluate's noise: 10 % of the chip's side, no twist for an untwisted chip
    assert "of 20 starts under placement noise sigma 73 um, 73 um, 0 deg (greedy)" in out


def test_demo_installs_only_what_it_runs():
    make = (ROOT / "Makefile").read_text(encoding="utf-8")
    base = re.search(r"^\$\(BIN\)/selfalign:.*?\n((?:\t.*\n)+)", make, re.M)
    assert base is not None
    assert "-e .\n" in base.group(1) and "[" not in base.group(1)  # no extra
    assert re.search(r"^demo: \$\(BIN\)/selfalign$", make, re.M)
    assert re.search(r"^test: \$\(VENV\)/\.extra-test$", make, re.M)
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    extras = project["project"]["optional-dependencies"]
    assert "selfalign[docs]" in extras["test"]
    assert not any(d.startswith(("pytest", "mkdocs")) for d in project["project"]["dependencies"])


def test_a_dynamic_run_says_each_stage_after_its_landscape(run_cli, monkeypatch):
    # The 730 um four-pad at 2 um/px (345 M poses): after its landscape, the floor, the
    # stepper's field, the compile and the end's classification each took 3-16 s on a loaded
    # machine, all under one line. Each says what it does now, in the order it runs.
    import foundation._progress as progress

    monkeypatch.setenv("SELFALIGN_WAIT_S", "0")  # every waiting line shows
    monkeypatch.setattr(progress, "_shown", set())
    scene = ["simulate", "--pattern", library_path("square_200"), "--chip-size", "200"]
    scene += ["--resolution", "4", "--no-twist", "--meniscus", "--volume", "0.4"]
    scene += ["--method", "overdamped", "--start", "20,0,0"]
    # stateless, then with the default footprint state (the pads' planes before the floor)
    runs = ((["--dispense", "none"], "landscape: 1 twist x "), ([], "footprint planes: 1 pads"))
    for protocol, first in runs:
        progress._shown.clear()  # the compile line not yet shown
        rc, out, err = run_cli(scene + protocol)
        assert rc == 0, err
        stages = [
            first,
            "the well's floor around the global minimum (",
            "the overdamped stepper's field on the landscape (",
            "compiling the overdamped stepper with JAX",
            "where the run ended: plateau, global minimum and error limit (",
        ]
        lines = err.splitlines()
        at = [next(i for i, line in enumerate(lines) if line.startswith(s)) for s in stages]
        assert at == sorted(at), lines
        assert out.startswith("overdamped: aligned at")
    rc, out, err = run_cli(
        ["simulate", "--pattern", library_path("square_200"), "--chip-size", "200"]
        + ["--resolution", "4", "--no-twist", "--meniscus", "--volume", "0.4"]
        + ["--method", "overdamped", "--start", "20,0,0", "--quiet"]
    )
    assert rc == 0 and err == "", err
