"""The path-cost engine (simulator.landscape.PathEnergy, simulate(engine="path")): the
same energies as the FFT engine to its round-off, and the same trajectories: greedy paths
bit for bit, gradient final poses within the box-vs-full tolerance, the same outcomes."""

from __future__ import annotations

import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import Point, box

from patterns.geometry import Mask, coverage_steps, four_pad, mask_from_geometry, rasterize, square
from simulator.landscape import PathEnergy, build_landscape, path_engine_supported
from simulator.motion import choose_engine, simulate
from simulator.physics import Liquid
from simulator.scene import Effects, Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("pathcost")


def make_scene(L, g, um_per_px=1.0, png_chip=False, **kw):
    pat = four_pad(L, g) if g else square(L)
    chip = mask_from_geometry(square(L), um_per_px)
    if png_chip:  # a chip image: no geometry, resampled (fractional edges)
        chip = Mask(chip.data, um_per_px)
    return Scene(pattern=mask_from_geometry(pat, um_per_px, margin_um=10), chip=chip, **kw)


@pytest.fixture(scope="module")
def fp200():
    return make_scene(200, 20)


@pytest.fixture(scope="module")
def fp730():
    return make_scene(730, 50, um_per_px=2.0, twist=TwistGrid(step_deg=2.0))


@pytest.mark.parametrize(
    "geom, shape",
    [
        (affinity.rotate(box(-50, -30, 50, 30), 17, origin=(0, 0)), (140, 141)),
        (box(-50, -30, 50, 30).difference(Point(3, 4).buffer(10)), (70, 111)),
    ],
)
def test_coverage_steps_are_the_rasters_row_differences(geom, shape):
    img = rasterize(geom, 1.0, shape=shape)
    r, c, d = coverage_steps(geom, 1.0, shape)
    sparse = np.zeros((shape[0], shape[1] + 1))
    np.add.at(sparse, (r, c), d)
    np.testing.assert_allclose(sparse, np.diff(img, axis=1, prepend=0, append=0), atol=1e-12)


@pytest.mark.parametrize("png", [False, True])
def test_boxes_equal_the_fft_engines(png):
    s = make_scene(730, 50, um_per_px=2.0, png_chip=png, twist=TwistGrid(step_deg=2.0))
    pe = PathEnergy(s)
    n = s.twist_axis.count
    for run, c, h in [
        ([3, 4, 5], (100, 50), 6),
        ([0, 1], (-30, 7), 5),
        ([n - 2, n - 1], (180, 120), 4),
        ([0], (400, -400), 3),
    ]:
        ref = build_landscape(
            s, twists=s.twist_axis.values_at(np.asarray(run)), center_px=c, half_px=h
        )
        ls = pe.box(run, c, h)
        assert ls.grid == ref.grid and ls.energy.shape == ref.energy.shape
        np.testing.assert_allclose(ls.energy, ref.energy, rtol=0, atol=ref.noise_floor_J / 4)


C9 = [
    (89, 0, 0),
    (100, 0, 0),
    (120, 0, 0),
    (120, 0, 5),
    (120, 0, -5),
    (91, 0, 0),
    (70, 30, 4),
    (400, 0, 0),
    (60, 35, 8),
]


@pytest.mark.parametrize("start", C9)
def test_greedy_same_path_on_the_trajectory_cases(fp200, start):
    a, b = simulate(fp200, start, engine="fft"), simulate(fp200, start, engine="path")
    np.testing.assert_array_equal(a.path, b.path)
    # the FFT's energies within its noise floor, NOISE_FACTOR eps(float32) max|E|, max|E| at
    # most |dg| min(pattern, chip area); the path engine's rounded once from float64
    # (1e-6 of the path's largest |E|, 8 eps, was below the floor)
    from simulator.landscape._correlator import NOISE_FACTOR

    top = abs(fp200.delta_gamma_N_m) * min(fp200.pattern.area_um2, fp200.chip.area_um2) * 1e-12
    floor = NOISE_FACTOR * float(np.finfo(fp200.dtype).eps) * top
    np.testing.assert_allclose(a.energy_J, b.energy_J, rtol=0, atol=floor)
    assert (a.outcome, a.steps, a.optimum) == (b.outcome, b.steps, b.optimum)
    assert a.cost is not None and b.cost is not None  # packaged runs have their costs
    assert b.cost.engine == "path" and a.cost.engine == "fft"


@pytest.mark.parametrize(
    "method, start",
    [
        ("greedy", (680, 0, 0)),
        ("greedy", (600, 400, 20)),
        ("greedy", (-300, 250, -30)),
        ("gradient", (600, 400, 20)),
        ("gradient", (60, 35, 8)),
    ],
)
def test_same_run_as_the_full_landscape(fp730, method, start):
    full = build_landscape(fp730)
    ref = simulate(fp730, start, method=method, landscape=full)
    t = simulate(fp730, start, method=method, engine="path")
    if method == "greedy":
        np.testing.assert_array_equal(t.path, ref.path)
    else:  # continuous float32 poses: the engines round differently (as boxes and the full FFT do)
        np.testing.assert_allclose(t.final, ref.final, atol=0.05)
    assert t.outcome == ref.outcome
    assert t.cost is not None  # a packaged run has its cost
    assert t.cost.poses_computed < 0.05 * full.energy.size


def test_png_chip_with_twist_same_greedy_path():
    s = make_scene(200, 20, png_chip=True)
    for start in [(60, 35, 8), (120, 0, -5)]:
        a, b = simulate(s, start, engine="fft"), simulate(s, start, engine="path")
        np.testing.assert_array_equal(a.path, b.path)
        assert a.outcome == b.outcome


def test_free_contact_lines_are_covered_and_equal():
    s = Scene.from_inputs(
        mask_from_geometry(four_pad(200, 20), 1.0, margin_um=2),
        chip_size_um=200,
        effects=Effects(twist=True, meniscus=True),
        liquid=Liquid(height_um=5.0, pinned=False, dispense="none"),
        twist=TwistGrid(0.5, -2, 2),
        window_um=40.0,
        dtype="float64",
    )
    assert path_engine_supported(s)[0]
    pe = PathEnergy(s)
    ref = build_landscape(
        s, twists=s.twist_axis.values_at(np.asarray([3, 4])), center_px=(10, -6), half_px=5
    )
    ls = pe.box([3, 4], (10, -6), 5)
    # float64 sums of the footprint's steps against the FFT's round-off
    np.testing.assert_allclose(
        ls.energy, ref.energy, rtol=0, atol=max(ref.noise_floor_J, 1e-9 * np.abs(ref.energy).max())
    )
    # runs take the path engine (their outcome on the floor is measured around the global
    # minimum, tests/test_meniscus_path.py)
    cost = simulate(s, (20, 10, 1.0)).cost
    assert cost is not None and cost.engine == "path"


def test_the_pinned_meniscus_stays_with_the_fft_engine():
    s = Scene.from_inputs(
        mask_from_geometry(square(200), 1.0, margin_um=2),
        chip_size_um=200,
        effects=Effects(twist=False, meniscus=True),
        liquid=Liquid(height_um=5.0, pinned=True),
        window_um=40.0,
    )
    ok, why = path_engine_supported(s)
    assert not ok and "K_h" in why
    t = simulate(s, (20, 0, 0))
    assert t.cost is not None  # a packaged run has its cost
    assert t.cost.engine == "fft"


@pytest.mark.parametrize(
    "L, method, want",
    [
        (730, "greedy", "fft"),
        (999, "greedy", "fft"),
        (1000, "greedy", "path"),
        (1000, "gradient", "fft"),
        (1999, "gradient", "fft"),
        (2000, "gradient", "path"),
    ],
)
def test_auto_keeps_small_chips_on_the_fft_engine(L, method, want):
    s = Scene(pattern=mask_from_geometry(square(L), 1.0), chip=mask_from_geometry(square(L), 1.0))
    assert choose_engine(s, (30, -20, 1), method, "auto", 3, 48) == want
    assert choose_engine(s, (30, -20, 1), method, "fft", 3, 48) == "fft"
    assert choose_engine(s, (30, -20, 1), method, "path", 3, 48) == "path"


def test_auto_takes_the_path_engine_for_a_large_chip_and_a_short_path():
    s = Scene(
        pattern=mask_from_geometry(four_pad(2000, 100), 1.0),
        chip=mask_from_geometry(square(2000), 1.0),
    )
    t = simulate(s, (30, -20, 1), engine="auto")
    assert t.cost is not None  # a packaged run has its cost
    assert t.cost.engine == "path"
