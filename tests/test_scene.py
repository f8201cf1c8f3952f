"""Scene: construction, validation, TOML files, chip resampling."""

import numpy as np
import pytest

from foundation import InputError
from patterns import write_mask
from patterns.geometry import Mask, four_pad, mask_from_geometry, square
from simulator.scene import Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("scene")


@pytest.fixture()
def pattern_png(tmp_path):
    path = tmp_path / "fp.png"
    write_mask(path, mask_from_geometry(four_pad(200, 20), 1.0, margin_um=5))
    return path


def test_from_toml_with_every_table(pattern_png, tmp_path):
    scene_file = tmp_path / "s.toml"
    scene_file.write_text(
        f'pattern = "{pattern_png.name}"\nchip_size_um = [200, 100]\ndtype = "float64"\nwindow_um = 150\n'
        "[materials]\nsurface_tension_mN_m = 50\npad_angle_deg = 20\nsubstrate_angle_deg = 100\n"
        "[twist]\nstep_deg = 2\nmin_deg = -10\nmax_deg = 10\n[effects]\ntwist = true\n"
        "[liquid]\nvolume_nl = 0.5\nviscosity_mPa_s = 2\n"
    )
    s = Scene.from_toml(scene_file)  # the pattern path is relative to the TOML file
    assert s.dtype == "float64" and s.window_um == 150
    assert s.materials.surface_tension_N_m == pytest.approx(0.05)
    assert s.twist == TwistGrid(step_deg=2, min_deg=-10, max_deg=10)
    assert s.liquid.volume_nl == 0.5 and s.liquid.viscosity_Pa_s == pytest.approx(2e-3)
    assert s.chip.area_um2 == pytest.approx(200 * 100)
    assert s.chip.geometry is not None  # a size gives exact geometry


@pytest.mark.parametrize(
    "text, message",
    [
        ("chip_size_um = 200\n", "needs a 'pattern'"),
        (
            'pattern = "{p}"\nchip_size_um = 200\ncolour = 3\n',
            r"colour = 3: unknown key; top-level keys are",
        ),
        (
            'pattern = "{p}"\nchip_size_um = 200\n[twist]\nsteps = 3\n',
            r"\[twist\] steps = 3: unknown key",
        ),
        (
            'pattern = "{p}"\nchip_size_um = 200\n[twist]\nstep_deg = 0\n',
            r"\[twist\] step_deg = 0: must be a number > 0",
        ),
        (
            'pattern = "{p}"\nchip_size_um = 200\ndtype = "float16"\n',
            r'dtype = "float16": must be one of',
        ),
        ('pattern = "{p}"\n', "give exactly one of"),
        ('pattern = "{p}"\nchip_size_um = 200\nwindow_um = -3\n', "window_um"),
        ("this is [not toml", "not valid TOML"),
    ],
)
def test_bad_scene_files(pattern_png, tmp_path, text, message):
    f = tmp_path / "bad.toml"
    f.write_text(text.replace("{p}", str(pattern_png)))
    with pytest.raises(InputError, match=message):
        Scene.from_toml(f)


def test_missing_scene_file(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        Scene.from_toml(tmp_path / "nope.toml")


def test_chip_png_at_other_scale_is_resampled(pattern_png, tmp_path):
    chip_png = tmp_path / "chip.png"
    write_mask(
        chip_png, Mask(mask_from_geometry(square(100), 0.5).data, 0.5)
    )  # no geometry in a PNG
    s = Scene.from_inputs(pattern_png, chip=chip_png)
    assert s.chip.um_per_px == 1.0 and s.chip.area_um2 == pytest.approx(100 * 100, rel=1e-3)


def test_nan_and_empty_masks_are_refused():
    with pytest.raises(InputError, match="NaN or infinite"):
        Mask(np.full((4, 4), np.nan), 1.0)
    empty = Mask(np.zeros((8, 8)), 1.0)
    with pytest.raises(InputError, match="all black"):
        Scene(pattern=empty, chip=mask_from_geometry(square(4), 1.0))


def test_scale_mismatch_is_refused():
    with pytest.raises(InputError, match="differs from pattern scale"):
        Scene(pattern=mask_from_geometry(square(20), 1.0), chip=mask_from_geometry(square(10), 0.5))


@pytest.mark.parametrize("resolution", [2.0, 3.0, 0.5])
def test_resolution_resamples_raster_keeping_centre_and_area(tmp_path, resolution):
    path = tmp_path / "p.png"
    g = four_pad(200, 20)
    write_mask(
        path, Mask(mask_from_geometry(g, 1.0, margin_um=7).data, 1.0)
    )  # a raster: no geometry
    s = Scene.from_inputs(path, chip_size_um=200, resolution_um=resolution)
    assert s.um_per_px == resolution and s.pattern.area_um2 == pytest.approx(g.area, rel=1e-9)
    # Centre kept: the mask's centroid stays at the image centre (the four-pad is symmetric).
    d = s.pattern.data
    h, w = d.shape
    ys, xs = np.mgrid[0:h, 0:w]
    assert (d * (xs + 0.5)).sum() / d.sum() == pytest.approx(w / 2) and (
        d * (ys + 0.5)
    ).sum() / d.sum() == pytest.approx(h / 2)


def test_resolution_that_would_move_the_centre_is_refused(tmp_path):
    path = tmp_path / "p.png"
    write_mask(path, Mask(mask_from_geometry(square(20), 1.0, margin_um=1).data, 1.0))
    with pytest.raises(InputError, match="without moving its centre"):
        Scene.from_inputs(path, chip_size_um=10, resolution_um=1 / 0.3731)


@pytest.mark.parametrize("accuracy", ['accuracy = "fast"\n', 'accuracy = "precise"\n', ""])
def test_scene_file_means_the_same_in_python_and_on_the_command_line(tmp_path, capsys, accuracy):
    import json

    from simulator.cli import main

    png = tmp_path / "pad.png"
    assert main(["pattern", "square", "--size", "100", "--um-per-px", "0.5", "-o", str(png)]) == 0
    f = tmp_path / "s.toml"
    f.write_text(f'pattern = "pad.png"\nchip_size_um = 100\n{accuracy}')
    s = Scene.from_toml(f)
    out = tmp_path / "e.json"
    assert main(["energy", str(f), "--at", "0,0,0", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert (s.um_per_px, s.twist.step_deg, s.dtype) == (
        doc["um_per_px"],
        doc["twist_step_deg"],
        doc["dtype"],
    )
    expected = {
        'accuracy = "fast"\n': (4.0, 2.0),
        'accuracy = "precise"\n': (0.5, 0.5),
        "": (1.0, 1.0),
    }[accuracy]
    assert (
        s.um_per_px,
        s.twist.step_deg,
    ) == expected  # the preset's knobs, in Python as on the command line
