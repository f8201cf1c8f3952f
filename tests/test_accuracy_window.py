"""One answer to "how accurate?" and the droplet window from the pattern (issue 39, items 3-4).

* every final pose says what limits its error, ``error_limit = {"by", "um"}``: the grid step
  of a run that ends on the grid, the floor a chip floats on (free contact lines), the
  refinement below the grid (a smooth well) -- in the JSON of simulate, montecarlo and
  evaluate; the evaluate report probes the restoring force beyond the floor;
* ``selfalign liquid window`` against the calculators (critical volume, thin-film and
  overflow limits) on a four-pad and a single pad, drawn as a PNG and as a GDSII;
* the droplet volume a scene without one takes: a film of 5 % of the chip's smallest side.

Small chips (200 um) at coarse pixels (4 um), no twist: each run a few seconds.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from PIL import Image

from simulator.core import UM3_PER_NL
from simulator.liquid import (
    DEFAULT_FILM_FRACTION,
    THIN_FILM_FRACTION,
    critical_volume,
    overflow_bias_um,
)

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("accuracy_window")

SQUARE = "patterns/library/square_200.png"  # a 200 um pad at 1 um/px
COARSE = ["--resolution", "4", "--no-twist", "--quiet"]
L, G = 200.0, 20.0  # the four-pad: outer side and gap (um)


def _fourpad_png(path) -> str:
    """L = 200 um, gap 20 um, 1 um/px (no stored scale: --um-per-px 1), 20 um of substrate around."""
    a = np.zeros((240, 240), np.uint8)
    p = int((L - G) / 2)
    for r in (20, 20 + p + int(G)):
        for c in (20, 20 + p + int(G)):
            a[r : r + p, c : c + p] = 255
    Image.fromarray(a).save(path)
    return str(path)


def _gds(path, pads) -> str:
    """A GDSII (um units, 1 nm precision) of rectangles ((x0, y0), (x1, y1)) on layer 1/0."""
    import gdstk

    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    cell = lib.new_cell("PADS")
    for a, b in pads:
        cell.add(gdstk.rectangle(a, b))
    lib.write_gds(str(path))
    return str(path)


def _fourpad_gds(path) -> str:
    p = (L - G) / 2
    h = L / 2
    return _gds(path, [((x, y), (x + p, y + p)) for x in (-h, G / 2) for y in (-h, G / 2)])


def _window(run_cli, *args) -> dict:
    rc, out, err = run_cli(["liquid", "window", *args, "--json"])
    assert rc == 0, err
    return json.loads(out)


# ----------------------------------------------------------------------- error_limit
def _simulate(run_cli, tmp_path, name, *args) -> dict:
    out = tmp_path / f"{name}.json"
    rc, text, err = run_cli(
        ["simulate", "--pattern", SQUARE, "--chip-size", "200", *COARSE, *args, "--json", out]
    )
    assert rc == 0, err
    return json.loads(out.read_text()) | {"stdout": text, "stderr": err}


def _reach(optimum: dict, fl: dict) -> float:
    """The floor's largest reach from the global minimum along x or y (um)."""
    x, y = optimum["x_um"], optimum["y_um"]
    return max(x - fl["x_um"][0], fl["x_um"][1] - x, y - fl["y_um"][0], fl["y_um"][1] - y)


def test_simulate_on_the_overlap_model_is_grid_limited(run_cli, tmp_path):
    # The overlap model, greedy: the run ends on the 4 um grid.
    d = _simulate(run_cli, tmp_path, "grid", "--start", "20,0,0")
    assert d["outcome"] == "aligned" and d["error_limit"] == {"by": "grid", "um": 4.0}
    assert d["floating_range"] is None and "limited by the 4 um grid step" in d["stdout"]


def test_simulate_with_free_lines_is_floor_limited_and_prints_the_floor(run_cli, tmp_path):
    # Free contact lines: the chip floats on the well's floor, printed with its extent.
    d = _simulate(run_cli, tmp_path, "floor", "--start", "20,0,0", "--meniscus", "--volume", "0.4")
    fl = d["floating_range"]
    assert d["error_limit"]["by"] == "floor" and d["final_refined"] is None
    assert d["error_limit"]["um"] == _reach(d["optimum"], fl) >= 4.0  # at least one grid step
    assert f"floats on the well's floor: x {fl['x_um'][0]:g} to {fl['x_um'][1]:g} um" in d["stdout"]


def test_simulate_on_a_smooth_well_is_refinement_limited(run_cli, tmp_path):
    # Pinned lines, gradient steps: a smooth well, refined below the grid; its limit lies
    # below the grid step (the landscape's round-off over the stiffness).
    d = _simulate(
        run_cli, tmp_path, "refined", "--start", "20,0,0", "--meniscus", "--pinned",
        "--volume", "0.4", "--method", "gradient",
    )  # fmt: skip
    lim = d["error_limit"]
    assert d["final_refined"] is not None and lim["by"] == "refined" and 0 < lim["um"] < 4.0
    assert "limited by the refinement below the grid" in d["stdout"]


def test_montecarlo_json_says_the_grid_or_the_floor(run_cli, tmp_path):
    base = ["montecarlo", "--pattern", SQUARE, "--chip-size", "200", *COARSE]
    base += ["--grid", "-20:20:20,-20:20:20"]
    rc, text, err = run_cli([*base, "--json", tmp_path / "g.json"])
    assert rc == 0, err
    d = json.loads((tmp_path / "g.json").read_text())
    assert d["error_limit"] == {"by": "grid", "um": 4.0}
    assert "limited by the 4 um grid step" in text
    rc, text, err = run_cli([*base, "--meniscus", "--volume", "0.4", "--json", tmp_path / "f.json"])
    assert rc == 0, err
    d = json.loads((tmp_path / "f.json").read_text())
    assert d["error_limit"]["by"] == "floor" and d["error_limit"]["um"] >= 4.0
    assert "limited by the floor" in text


def test_evaluate_probes_the_force_beyond_the_floor_and_says_the_limit(run_cli, tmp_path):
    out = tmp_path / "ev"
    rc, text, err = run_cli(
        ["evaluate", SQUARE, "--chip-size", "200", *COARSE, "--meniscus", "--volume", "0.4",
         "--out", out]
    )  # fmt: skip
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    fl, g = s["floating_range"], s["global_minimum"]
    reach = max(
        g["x_um"] - fl["x_from_um"], fl["x_to_um"] - g["x_um"],
        g["y_um"] - fl["y_from_um"], fl["y_to_um"] - g["y_um"],
    )  # fmt: skip
    assert s["error_limit"] == {"by": "floor", "um": reach}
    f = s["restoring_force_N"]
    # One grid step beyond the floor: the force points back (on the floor it is 0).
    assert f["bias_um"] == reach + 4.0
    assert f["+x"][0] < 0 < f["-x"][0] and f["+y"][1] < 0 < f["-y"][1]
    page = (out / "report.html").read_text()
    assert "one grid step beyond the floor" in page and "limited by the floor" in page
    assert "restoring force probed at" in text and "limited by the floor" in text
    # The report's droplet window is the command's.
    w = _window(run_cli, "--pattern", SQUARE, "--chip-size", "200", "--volume", "0.4")
    assert s["volume_window"]["upper_nl"] == w["upper_nl"] and "volume window" in page


def test_evaluate_of_the_overlap_model_is_grid_limited(run_cli, tmp_path):
    out = tmp_path / "ev"
    rc, text, err = run_cli(["evaluate", SQUARE, "--chip-size", "200", *COARSE, "--out", out])
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["error_limit"] == {"by": "grid", "um": 4.0}
    assert s["restoring_force_N"]["bias_um"] == 8.0  # two grid steps (2 % of 200 um is 4 um)


def test_evaluate_reads_the_window_at_the_pattern_s_own_pixels(run_cli, tmp_path, monkeypatch):
    # evaluate coarsens a pattern to keep its landscape small; the four-pad's L and gap are
    # read before that, so its window is liquid window's (at 4 um/px the gap reads 16 um).
    import simulator.batch._evaluate as ev

    monkeypatch.setattr(ev, "auto_resolution", lambda scene: scene.at_resolution(4.0))
    fp, out = _fourpad_png(tmp_path / "fp.png"), tmp_path / "ev"
    rc, text, err = run_cli(
        ["evaluate", fp, "--um-per-px", "1", "--chip-size", "200", "--no-twist", "--quiet"]
        + ["--out", out]
    )
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["settings"]["um_per_px"] == 4.0 and s["settings"]["resolution_auto"] is True
    w = _window(run_cli, "--pattern", fp, "--um-per-px", "1", "--chip-size", "200")
    cv = critical_volume(L, G, 30.0, 60.0).critical_volume_nl
    assert s["volume_window"]["critical_volume_nl"] == w["critical_volume_nl"] == pytest.approx(cv)
    assert "L 200 um, gap 20 um" in s["volume_window"]["critical_volume_note"]
    assert f"usable droplet volume: {cv:.3g} to" in text


# ----------------------------------------------------------------------- the window
def _thin_nl(side: float, area: float) -> float:
    return THIN_FILM_FRACTION * side * area / UM3_PER_NL


@pytest.mark.parametrize("kind", ["png", "gds"])
def test_window_of_a_four_pad_is_the_critical_volume_to_the_thin_film_limit(
    run_cli, tmp_path, kind
):
    pattern = (
        ["--pattern", _fourpad_png(tmp_path / "fp.png"), "--um-per-px", "1"]
        if kind == "png"
        else ["--pattern", _fourpad_gds(tmp_path / "fp.gds")]
    )
    w = _window(run_cli, *pattern, "--chip-size", "200")
    cv = critical_volume(L, G, 30.0, 60.0).critical_volume_nl
    # Recognised from the pixels: L and g exact at 1 um/px, so the calculator's number.
    assert w["critical_volume_nl"] == pytest.approx(cv, rel=1e-9)
    assert w["lower_nl"] == w["critical_volume_nl"]
    assert w["upper_nl"] == w["thin_film_limit_nl"] == pytest.approx(_thin_nl(200, 200**2))
    assert w["usable"] is True and w["overflow_limit_nl"] is None
    rc, text, err = run_cli(["liquid", "window", *pattern, "--chip-size", "200"])
    assert rc == 0, err
    assert f"usable droplet volume: {cv:.3g} to {_thin_nl(200, 200**2):.3g} nl" in text
    assert (
        "critical volume" in text and "thin-film limit" in text and "derived from the chip" in text
    )


@pytest.mark.parametrize("kind", ["png", "gds"])
def test_window_of_a_single_pad_has_no_critical_volume(run_cli, tmp_path, kind):
    pattern = (
        ["--pattern", SQUARE]
        if kind == "png"
        else ["--pattern", _gds(tmp_path / "pad.gds", [((-100, -100), (100, 100))])]
    )
    w = _window(run_cli, *pattern, "--chip-size", "150x100")
    assert w["critical_volume_nl"] is None and "single pad" in w["critical_volume_note"]
    assert w["lower_nl"] is None and w["upper_nl"] == pytest.approx(_thin_nl(100, 150 * 100))
    # With a protruding pad and a bias: the film whose overflow bias is the bias.
    w = _window(
        run_cli, *pattern, "--chip-size", "150x100", "--edge-angle", "90",
        "--pad-advancing", "60", "--bias", "10",
    )  # fmt: skip
    h = 10.0 / overflow_bias_um(1.0, 90.0, 60.0)  # h / tan(30 deg) = 10 um
    assert w["overflow_limit_film_um"] == pytest.approx(h, rel=1e-12)
    assert w["overflow_limit_nl"] == pytest.approx(h * 150 * 100 / UM3_PER_NL, rel=1e-12)
    assert w["lower_nl"] == w["overflow_limit_nl"]


def test_window_refuses_a_bad_bias_before_reading_the_pattern(run_cli, tmp_path):
    from tests.cli_helpers import one_line_error

    rc, _, err = run_cli(
        ["liquid", "window", "--pattern", tmp_path / "missing.png", "--chip-size", "200",
         "--bias", "nan"]
    )  # fmt: skip
    one_line_error(rc, err, "--bias")


# ----------------------------------------------------------------------- the default volume
def test_without_a_volume_the_film_is_a_fixed_share_of_the_chip_side(run_cli, tmp_path):
    from simulator.physics import Liquid
    from simulator.scene import Scene

    scene = Scene.from_dict({"pattern": SQUARE, "chip_size_um": [150, 100]})
    assert scene.liquid.volume_derived is True
    assert scene.liquid.volume_nl == pytest.approx(
        DEFAULT_FILM_FRACTION * 100 * 150 * 100 / UM3_PER_NL
    )
    assert scene.liquid_height_um == pytest.approx(DEFAULT_FILM_FRACTION * 100)
    typed = Scene.from_dict(
        {"pattern": SQUARE, "chip_size_um": [150, 100], "liquid": {"volume_nl": 0.5}}
    )
    assert typed.liquid.volume_nl == 0.5 and typed.liquid.volume_derived is False
    assert Liquid().volume_nl == 20.0  # the Python default stays the source's 20 nl
    # The command says the volume it chose.
    d = _simulate(run_cli, tmp_path, "derived", "--start", "20,0,0", "--meniscus")
    assert d["meniscus_height_um"] == pytest.approx(DEFAULT_FILM_FRACTION * 200)
    assert "droplet volume 0.4 nl derived from the chip" in d["stderr"]
    w = _window(run_cli, "--pattern", SQUARE, "--chip-size", "200")
    assert w["volume_nl"] == w["default_volume_nl"] == pytest.approx(0.4)
    assert w["volume_given"] is False and w["in_window"] is True
    assert math.isclose(w["film_um"], 10.0)
