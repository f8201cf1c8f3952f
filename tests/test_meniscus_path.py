"""Meniscus runs without the full landscape: the free contact lines' footprint on the
path-cost engine (simulator.landscape.PathEnergy: its part G on the chip's side, its part B on
the pattern's side), the global minimum proved without the full cube, and the outcome on the
floor the chip floats on, measured around the global minimum. Every run is compared with the
same stepper on the full landscape (build_landscape over the whole grid)."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import box

from patterns.geometry import four_pad, mask_from_geometry
from patterns.library import library_path
from simulator.landscape import PathEnergy, build_landscape, global_minimum, minimum_box
from simulator.landscape._pathband import footprint_band
from simulator.landscape._rotation import ChipRotator
from simulator.motion import choose_engine, simulate
from simulator.physics import Liquid
from simulator.scene import Effects, Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("meniscus_path")

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
        liquid=Liquid(dispense="none", volume_nl=volume_nl),
        twist=TWISTS,
        window_um=20 * um_per_px if chip_um <= 200 else 50 * um_per_px,
    )


def same_run(scene: Scene, start, method: str, full) -> None:
    """The path engine's run ends where the same stepper on the full landscape does, with the
    same outcome, measured against the same global minimum."""
    ref = simulate(scene, start, method=method, landscape=full)
    t = simulate(scene, start, method=method, engine="path")
    assert t.cost is not None  # a packaged run has its cost
    assert t.cost.engine == "path"
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
    assert t.optimum is not None and ref.optimum is not None
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
        liquid=Liquid(dispense="none", height_um=16.0),
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
@pytest.mark.fft
def test_global_minimum_without_the_cube(name, chip, res, vol):
    """Proved from the run's boxes and the path engine's sparse footprint (its mass for the
    absolute bound): the full landscape's minimum, and no rotation of the whole canvas."""
    s = library_scene(name, chip, res, vol)
    full = build_landscape(s)
    want = global_minimum(s, landscape=full)
    pe = PathEnergy(s)
    got = global_minimum(s, evaluated=pe.nominal_boxes(), engine=pe)
    assert got.pose == pytest.approx(want.pose, abs=1e-9)
    # The FFT's energy within the noise floor (32 eps(float32) max|E|) of the exact one, the
    # path engine's rounded once from float64: rel=1e-6 (8 eps of |E| = max|E|) was one path's luck
    assert got.energy_J == pytest.approx(want.energy_J, rel=0, abs=full.noise_floor_J)


def test_global_minimum_by_the_cell_bound_with_the_footprint():
    """A pad off the centre: the absolute bound cannot settle it, the cell bounds take the
    footprint's block maxima from the engine's sparse form."""
    pads = box(-90, -30, -30, 30).union(box(45, -15, 75, 15))  # the minimum lies off the centre
    pat = mask_from_geometry(pads, 2.0, margin_um=10)
    s = Scene.from_inputs(
        pat,
        chip_size_um=100,
        effects=Effects(meniscus=True),
        liquid=Liquid(dispense="none", height_um=8.0),
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
        liquid=Liquid(dispense="none", volume_nl=0.9),
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


def _footprint_scene(chip) -> Scene:
    return Scene.from_inputs(
        mask_from_geometry(four_pad(200, 20), 1.0, margin_um=2),
        chip=mask_from_geometry(chip, 1.0),
        effects=Effects(meniscus=True),
        liquid=Liquid(dispense="none", volume_nl=0.9),
    )


@pytest.mark.parametrize(
    "chip", [box(-100, -100, 100, 100), box(-100, -60, 100, 60)], ids=["square", "rectangle"]
)
def test_a_mirror_twins_footprint_is_the_one_made(chip):
    """A chip mirror-symmetric about x: the footprint at -t is the one at +t upside down
    (taken, not made), and gives the energies and the mass of the one made, bit for bit."""
    s = _footprint_scene(chip)
    assert s.twist_axis.mirror and s.chip.geometry is not None
    ax = s.twist_axis
    index = {round(float(v), 9): j for j, v in enumerate(ax.values())}
    mirrored, made = PathEnergy(s), PathEnergy(s)
    made._mirrored = lambda tw: None
    for t in (3.0, 17.0, 44.0):
        plus, minus = index[t], index[-t]
        mirrored.plane(plus, -3, 2, 4, 3)  # the twin, kept
        got = mirrored.plane(minus, -25, 50, -30, 61)
        want = made.plane(minus, -25, 50, -30, 61)
        np.testing.assert_array_equal(got, want)
        assert mirrored.mass(minus) == made.mass(minus)
    assert mirrored.mirrored == 3 and made.mirrored == 0
    assert mirrored.rotations == 3 and made.rotations == 3  # the +t made, the -t taken


def test_a_footprint_made_ahead_is_the_one_made_now():
    s = _footprint_scene(box(-100, -70, 100, 70))  # its twins at -t: made ahead, not taken
    ahead, now = PathEnergy(s), PathEnergy(s)
    k = s.twist_axis.count // 3
    ahead.prefetch(k)
    ahead.prefetch(k)  # once
    assert list(ahead._pending) == [k]
    np.testing.assert_array_equal(ahead.plane(k, -5, 9, 7, 12), now.plane(k, -5, 9, 7, 12))
    assert not ahead._pending and ahead.rotations == 1
    ahead.prefetch(k)  # kept: nothing to make
    ahead.prefetch(k + 1)
    ahead.close()
    assert not ahead._pending


def test_the_bands_threads_do_not_change_it(monkeypatch):
    """The band's pixels found and evaluated in tasks on several threads: the same footprint
    as on one."""
    from simulator.landscape import _pathband

    s = _footprint_scene(box(-100, -100, 100, 100))
    rot = ChipRotator(
        s.chip,
        np.asarray([21.0]),
        (0, 0),
        blur_px=s.meniscus_height_px,
        margin_px=s.meniscus_margin_px,
        profile=s.wall_profile,
    )
    monkeypatch.setattr(_pathband, "TASK_PX", 2048)  # many tasks on this small chip
    got = {}
    for n in ("1", "2"):
        monkeypatch.setenv("SELFALIGN_THREADS", n)
        got[n] = footprint_band(rot, 21.0, np.float32)
    one, two = got["1"], got["2"]
    for a, b in zip(one[:3], two[:3], strict=True):
        np.testing.assert_array_equal(a, b)
    for f in ("seg_row", "seg_a", "seg_len", "seg_off", "flat", "row_first", "row_count"):
        np.testing.assert_array_equal(getattr(one[3], f), getattr(two[3], f))


def test_a_long_path_run_shows_its_boxes(monkeypatch, capsys):
    """A counter of the boxes with the chip's pose, on stderr, once the run has taken the
    waiting threshold (0 here); nothing with the waits silenced (``--quiet``)."""
    from foundation import WAIT_ENV, quiet_waits

    s = library_scene("square_200", 200, 5.0, 0.9)
    monkeypatch.setenv(WAIT_ENV, "0")
    simulate(s, (60.0, -40.0, 6.0), method="greedy", engine="path")
    err = capsys.readouterr().err
    assert "greedy run (path engine): " in err and " box" in err and "chip at (" in err, err
    with quiet_waits():
        simulate(s, (60.0, -40.0, 6.0), method="greedy", engine="path")
    assert "path engine" not in capsys.readouterr().err
