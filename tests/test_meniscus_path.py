"""Meniscus runs without the full landscape: the free contact lines' footprint on the
path-cost engine (simulator.landscape.PathEnergy: its part G on the chip's side, its part B on
the pattern's side), the global minimum proved without the full cube, and the outcome on the
floor the chip floats on, measured around the global minimum. Every run is compared with the
same stepper on the full landscape (build_landscape over the whole grid)."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import box

from patterns.geometry import four_pad
from patterns.library import library_path
from patterns.raster import mask_from_geometry
from simulator.landscape import PathEnergy, build_landscape, global_minimum, minimum_box
from simulator.landscape._pathband import footprint_band
from simulator.landscape._rotation import ChipRotator
from simulator.motion import choose_engine, simulate
from simulator.physics import Liquid
from simulator.scene import Effects, Scene, TwistGrid

LIBRARY_200 = [
    "square_200",
    "defect_A_inward",
    "defect_A_outward",
    "defect_B_inward",
    "defect_B_outward",
    "defect_C_inward",
    "defect_C_outward",
    "constant_jagged_a1p7",
    "constant_jagged_a3p2",
    "constant_jagged_a5",
    "constant_jagged_a15",
    "random_jagged_s2",
    "random_jagged_s4",
    "random_jagged_s8",
]
FOUR_PADS = [("four_pad_730_50", 730), ("four_pad_730_100", 730)]
TWISTS = TwistGrid(2.0, -10.0, 10.0)


def library_scene(name: str, chip_um: float, um_per_px: float, volume_nl: float) -> Scene:
    # One translation window per chip size: every landscape of a test has the same shape, so
    # the steppers compile once.
    return Scene.from_inputs(
        library_path(name),
        chip_size_um=chip_um,
        resolution_um=um_per_px,
        effects=Effects(meniscus=True),
        liquid=Liquid(volume_nl=volume_nl),
        twist=TWISTS,
        window_um=20 * um_per_px if chip_um <= 200 else 50 * um_per_px,
    )


def same_run(scene: Scene, start, method: str, full) -> None:
    """The path engine's run ends where the same stepper on the full landscape does, with the
    same outcome, measured against the same global minimum."""
    ref = simulate(scene, start, method=method, landscape=full)
    t = simulate(scene, start, method=method, engine="path")
    assert t.cost["engine"] == "path"
    if method == "greedy":
        np.testing.assert_array_equal(t.path, ref.path)
    else:
        # Continuous float32 poses: the boxes and the full landscape round differently, and on
        # the floor the chip floats on a run stops where the energy's steps fall below float32's
        # resolution: within a fifth of a grid step (the FFT engine's boxes end up to 0.13 px
        # from the full landscape's runs on these cases too), at the same energy.
        tol = 0.2 * np.array([scene.um_per_px, scene.um_per_px, scene.twist_axis.step_deg])
        assert np.all(np.abs(np.subtract(t.final, ref.final)) <= tol), (t.final, ref.final)
        # Each run's last energy lies within a noise floor of the floor's (the float32
        # landscapes and the float64 path sums round differently), so the two within two.
        assert abs(t.energy_J[-1] - ref.energy_J[-1]) <= 2 * full.noise_floor_J
    assert t.outcome == ref.outcome
    np.testing.assert_allclose(t.optimum, ref.optimum, atol=1e-9)


@pytest.mark.parametrize("name", LIBRARY_200)
def test_defect_library_runs_equal_the_full_landscapes(name):
    s = library_scene(name, 200, 5.0, 0.9)  # h = 22.5 um: 4.5 px, d_s 2.6 px, d_p 7.8 px
    assert s.wall_profile is not None
    full = build_landscape(s)
    for method in ("greedy", "gradient"):
        same_run(s, (60.0, -40.0, 6.0), method, full)


@pytest.mark.parametrize("name, chip", FOUR_PADS)
def test_four_pad_runs_equal_the_full_landscapes(name, chip):
    s = library_scene(name, chip, 10.0, 20.0)  # h = 37.5 um: the floor is +-2 px
    full = build_landscape(s)
    for method, start in [
        ("greedy", (300.0, 200.0, 8.0)),
        ("greedy", (440.0, 0.0, 0.0)),  # beyond the flat part
        ("gradient", (300.0, -150.0, 6.0)),
    ]:
        same_run(s, start, method, full)


def test_a_generated_four_pad_on_the_floor():
    """A 1 um/px four-pad whose floor is several pixels wide: every run that stops on it is
    aligned, as on the full landscape (before, the run's last box decided)."""
    s = Scene.from_inputs(
        mask_from_geometry(four_pad(200, 20), 2.0, margin_um=4),
        chip_size_um=200,
        effects=Effects(meniscus=True),
        liquid=Liquid(height_um=16.0),
        twist=TwistGrid(1.0, -4.0, 4.0),
        window_um=100.0,
    )
    full = build_landscape(s)
    (t0, t1), (y0, y1), (x0, x1) = full.floor_extent()
    assert x1 - x0 >= 8  # a floor, not a single pose
    same_run(s, (70.0, 30.0, 3.0), "greedy", full)
    near = minimum_box(s, global_minimum(s, landscape=full), engine=PathEnergy(s))
    assert near.floor_range() == full.floor_range()


@pytest.mark.parametrize(
    "name, chip, res, vol",
    [("defect_B_inward", 200, 5.0, 0.9), ("four_pad_730_100", 730, 10.0, 20.0)],
)
def test_global_minimum_without_the_cube(name, chip, res, vol):
    """Proved from the run's boxes and the path engine's sparse footprint (its mass for the
    absolute bound): the full landscape's minimum, and no rotation of the whole canvas."""
    s = library_scene(name, chip, res, vol)
    full = build_landscape(s)
    want = global_minimum(s, landscape=full)
    pe = PathEnergy(s)
    got = global_minimum(s, evaluated=pe.nominal_boxes(), engine=pe)
    assert got.pose == pytest.approx(want.pose, abs=1e-9)
    assert got.energy_J == pytest.approx(want.energy_J, rel=1e-6)


def test_global_minimum_by_the_cell_bound_with_the_footprint():
    """A pad off the centre: the absolute bound cannot settle it, the cell bounds take the
    footprint's block maxima from the engine's sparse form."""
    pads = box(-90, -30, -30, 30).union(box(45, -15, 75, 15))  # the minimum lies off the centre
    pat = mask_from_geometry(pads, 2.0, margin_um=10)
    s = Scene.from_inputs(
        pat,
        chip_size_um=100,
        effects=Effects(meniscus=True),
        liquid=Liquid(height_um=8.0),
        twist=TwistGrid(5.0, -20.0, 20.0),
    )
    full = build_landscape(s)
    want = global_minimum(s, landscape=full)
    pe = PathEnergy(s)
    got = global_minimum(s, evaluated=pe.nominal_boxes(), engine=pe)
    assert got.how == "cell bound"
    assert got.pose == pytest.approx(want.pose, abs=1e-9)


@pytest.mark.parametrize("twist", [0.0, 7.0, 33.0, 45.0, -12.5])
def test_the_split_footprint_is_the_rotated_one(twist):
    """G + B (the band's pixels only) is the footprint the FFT engine rotates onto the whole
    canvas, to round-off, and the mass read off G is its sum."""
    s = Scene.from_inputs(
        mask_from_geometry(four_pad(200, 20), 1.0, margin_um=2),
        chip_size_um=200,
        effects=Effects(meniscus=True),
        liquid=Liquid(volume_nl=0.9),
    )
    rot = ChipRotator(
        s.chip,
        np.asarray([twist]),
        (0, 0),
        blur_px=s.meniscus_height_px,
        margin_px=s.meniscus_margin_px,
        profile=s.wall_profile,
    )
    ref = np.asarray(rot(twist), np.float32).astype(float)
    r, c, v, band = footprint_band(rot, twist, np.float32)
    d = np.zeros((ref.shape[0], ref.shape[1] + 1))
    np.add.at(d, (r, c), v)
    got = np.cumsum(d, axis=1)[:, :-1] + band.dense()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    assert len(v) <= 4 * ref.shape[0]  # two per segment, two segments a row at most here
    assert -float(np.dot(v, c)) + band.sum_B == pytest.approx(ref.sum(), rel=1e-12)


def test_auto_takes_the_path_engine_for_free_contact_lines():
    s = library_scene("four_pad_730_50", 730, 10.0, 20.0)
    assert choose_engine(s, (300, 200, 8), "greedy", "auto", 3, 48) == "path"
    assert choose_engine(s, (300, 200, 8), "gradient", "auto", 3, 48) == "path"
