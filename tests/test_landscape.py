"""The landscape engine against docs/physics.md section 12 (C1-C8, C11) and exact polygon overlap.

Rasters are exact area coverage (patterns.geometry), so shapes whose edges lie on pixel
boundaries give integer overlaps up to FFT round-off; rotated chips differ from the
exact polygon overlap by an amount bounded by their perimeter (stated per test).
"""

import math

import numpy as np
import pytest
import shapely
from shapely import affinity

from foundation import InputError
from patterns.geometry import Mask, defect_type, four_pad, mask_from_geometry, square
from simulator.landscape import (
    Correlator,
    Window,
    build_landscape,
    chip_relations,
    correlate_stack,
    twist_axis,
)
from simulator.physics import Materials
from simulator.scene import Effects, Scene, TwistGrid, chip_symmetry

#: Rerun by make test under each FFT backend (SELFALIGN_FFT_BACKEND; tests/conftest.py).
# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = [pytest.mark.fft, pytest.mark.xdist_group("landscape")]


def scene(pattern_geom, chip_geom, um_per_px=1.0, margin=10.0, **kw):
    pat = mask_from_geometry(pattern_geom, um_per_px, margin_um=margin)
    chip = mask_from_geometry(chip_geom, um_per_px)
    return Scene(pattern=pat, chip=chip, **kw)


def overlap(ls, x, y, t=0.0):
    return float(ls.overlap_um2(ls.energy_at(x, y, t)))


def exact_overlap(pattern_geom, chip_geom, x, y, t):
    moved = affinity.translate(affinity.rotate(chip_geom, t, origin=(0, 0)), x, y)
    return shapely.intersection(pattern_geom, moved).area


@pytest.fixture(scope="module")
def square_flat():
    return build_landscape(
        scene(square(200), square(200), effects=Effects(twist=False), dtype="float64")
    )


@pytest.fixture(scope="module")
def square_twist():
    return build_landscape(scene(square(200), square(200), dtype="float64"))


@pytest.fixture(scope="module")
def fourpad_flat():
    return build_landscape(
        scene(four_pad(200, 20), square(200), effects=Effects(twist=False), dtype="float64")
    )


# ------------------------------------------------------------------ C1, C2, C8
@pytest.mark.parametrize("x, y", [(40, 25), (-40, 25), (0, 0), (199, 3), (-150, -150), (100, -100)])
def test_c1_square_on_square(square_flat, x, y):
    assert overlap(square_flat, x, y) == pytest.approx((200 - abs(x)) * (200 - abs(y)), abs=1e-7)


def test_c1_check_value_and_no_contact(square_flat):
    assert overlap(square_flat, 40, 25) == pytest.approx(28000, abs=1e-7)
    assert overlap(square_flat, 200, 0) == pytest.approx(0, abs=1e-7)
    assert overlap(square_flat, 500, 0) == 0.0  # outside the window: no contact


def test_c1_chip_smaller_than_pattern():
    ls = build_landscape(
        scene(
            square(200),
            affinity.scale(square(200), 0.6, 0.3),
            effects=Effects(twist=False),
            dtype="float64",
        )
    )

    def u(s, lc, lp):
        return max(0.0, min(s + lc / 2, lp / 2) - max(s - lc / 2, -lp / 2))

    for x, y in [(0, 0), (50, 20), (-130, 70), (159, -129), (170, 0)]:
        assert overlap(ls, x, y) == pytest.approx(u(x, 120, 200) * u(y, 60, 200), abs=1e-7)


C2 = [
    ((0, 0), 32400),
    ((40, 25), 21700),
    ((95, 0), 16200),
    ((105, 3), 15930),
    ((140, 50), 7800),
    ((-150, -40), 7000),
    ((10, -100), 15300),
]


@pytest.mark.parametrize("pose, area", C2)
def test_c2_four_pad_table(fourpad_flat, pose, area):
    assert overlap(fourpad_flat, *pose) == pytest.approx(area, abs=1e-7)


def test_c2_factorises(fourpad_flat):
    def w(s, L=200, g=20):
        p, s = (L - g) / 2, abs(s)
        return 2 * p - s if s <= p else p if s <= p + g else max(L - s, 0)

    xs = np.arange(-210, 211, 7)
    got = np.array([[overlap(fourpad_flat, x, y) for x in xs] for y in xs[::3]])
    want = np.array([[w(x) * w(y) for x in xs] for y in xs[::3]])
    np.testing.assert_allclose(got, want, atol=1e-7)


def test_c8_sum_rule_and_bounds(square_twist):
    ls = square_twist
    chip_area, pat_area = 200.0**2, 200.0**2
    a = ls.overlap_um2(ls.energy)
    sums = a.sum(axis=(1, 2))
    # Every twist: sum over translations = |P| |C_rot| (rotated chip area is exact).
    np.testing.assert_allclose(sums, pat_area * chip_area, rtol=1e-10)
    assert a.min() >= -1e-6 and a.max() <= min(pat_area, chip_area) + 1e-6
    assert a.max() == pytest.approx(chip_area, abs=1e-6)


# ------------------------------------------------------------------ C3, C4
@pytest.mark.parametrize("L, g", [(730, 50), (730, 100)])
def test_c3_plateau_starts_at_max_bias(L, g):
    ls = build_landscape(scene(four_pad(L, g), square(L), effects=Effects(twist=False)))
    cur = ls.curve("x", (0, 0, 0), 0, L + 20)
    p = (L - g) / 2
    plateau = [pl for pl in cur["plateaus"] if pl[0] > 1]
    assert plateau, "the four-pad must show the gap plateau"
    start, end = plateau[0]
    assert abs(start - p) <= 1 and abs(end - (p + g)) <= 1
    # Strictly monotonic before the plateau.
    e = cur["energy_J"][cur["values"] <= p]
    assert np.all(np.diff(e) > ls.noise_floor_J)


def test_c4_restoring_force(fourpad_flat):
    ls = fourpad_flat
    dg = abs(Materials().delta_gamma_N_m)
    fx, fy = ls.force_at(40, 0, 0)
    assert float(fx) == pytest.approx(-dg * (200 - 20) * 1e-6, rel=1e-9)  # points to the origin
    assert float(fy) == pytest.approx(0, abs=1e-12)
    assert float(ls.force_at(-40, 0, 0)[0]) == pytest.approx(dg * 180e-6, rel=1e-9)
    assert float(ls.force_at(100, 0, 0)[0]) == pytest.approx(0, abs=1e-12)  # plateau
    for y in (10, 50, 89):
        assert float(ls.force_at(40, y, 0)[0]) == pytest.approx(-dg * (2 * 90 - y) * 1e-6, rel=1e-9)


def test_c4_surface_tension_scales_force_only():
    base = scene(four_pad(200, 20), square(200), effects=Effects(twist=False))
    other = base.replace(
        materials=Materials(surface_tension_N_m=0.03, pad_angle_deg=41, substrate_angle_deg=89)
    )
    a, b = build_landscape(base), build_landscape(other)
    ratio = other.materials.delta_gamma_N_m / base.materials.delta_gamma_N_m
    np.testing.assert_allclose(b.energy, a.energy * ratio, rtol=1e-5, atol=4 * b.noise_floor_J)


# ------------------------------------------------------------------ C5, C6
C5 = [(1, 39656.97), (5, 38399.68), (10, 37063.53), (30, 33811.98), (45, 33137.08)]


@pytest.mark.parametrize("alpha, area", C5)
def test_c5_pure_twist(square_twist, alpha, area):
    # Exact-coverage rasters of a pixel-aligned pattern: the error is round-off only.
    assert overlap(square_twist, 0, 0, alpha) == pytest.approx(area, abs=0.01)
    assert overlap(square_twist, 0, 0, -alpha) == pytest.approx(area, abs=0.01)
    assert overlap(square_twist, 0, 0, alpha + 90) == pytest.approx(area, abs=0.01)


def test_c5_half_degree_by_interpolation_is_within_cusp_bound(square_twist):
    # Linear interpolation across the V-shaped cusp at 0: within L^2 * (1 deg in rad) / 4.
    assert overlap(square_twist, 0, 0, 0.5) == pytest.approx(
        39826.98, abs=200**2 * math.radians(1) / 4
    )


@pytest.mark.parametrize(
    "x, y, want", [(40, 25, 1012.5), (25, 40, -1012.5), (50, 10, 2800), (10, 80, -3850)]
)
def test_c6_twist_coupling(x, y, want):
    ls = build_landscape(
        scene(
            square(200),
            square(200),
            dtype="float64",
            twist=TwistGrid(step_deg=0.1, min_deg=-0.2, max_deg=0.2),
        )
    )
    # dA/dalpha per radian from the torque; the exact polygon clipping gives the same.
    got = float(ls.torque_at(x, y, 0)) / (abs(ls.delta_gamma) * 1e-12)
    h = 1e-4
    exact = (
        exact_overlap(square(200), square(200), x, y, math.degrees(h))
        - exact_overlap(square(200), square(200), x, y, -math.degrees(h))
    ) / (2 * h)
    assert exact == pytest.approx(want, rel=1e-4)
    # Central difference over +-0.1 deg: error of order L^3 * (0.1 deg)^2 ~ 1 um^2/rad.
    assert got == pytest.approx(want, abs=2.0)


# ------------------------------------------------------------------ C7
@pytest.fixture(scope="module")
def fourpad_twist():
    return build_landscape(
        scene(four_pad(200, 20), square(200), dtype="float64", twist=TwistGrid(step_deg=3.0))
    )


def test_c7_symmetries(fourpad_twist):
    ls = fourpad_twist
    e = ls.energy  # [t, y, x]; twists -45..42 in steps of 3, periodic
    tol = 4 * ls.noise_floor_J
    np.testing.assert_allclose(e, e[:, ::-1, ::-1], atol=tol)  # point symmetry
    # Mirror in x axis: A(x, -y, -a) = A(x, y, a). Twist index of -a: (-a + 45)/3.
    idx = [int(round((-t + 45) / 3)) % len(ls.twist_deg) for t in ls.twist_deg]
    np.testing.assert_allclose(e, e[idx][:, ::-1, :], atol=tol)
    np.testing.assert_allclose(e, e[idx][:, :, ::-1], atol=tol)  # mirror in y axis
    # 4-fold: A(x, y, a) = A(-y, x, a): E[t, y, x] = E[t, x, -y].
    np.testing.assert_allclose(e, np.transpose(e, (0, 2, 1))[:, :, ::-1], atol=tol)


def test_c7_square_chip_period(square_twist):
    assert square_twist.wrap and square_twist.period_deg == 90.0
    assert len(square_twist.twist_deg) == 90
    assert overlap(square_twist, 30, -20, 17) == pytest.approx(
        overlap(square_twist, 30, -20, 17 - 90), abs=1e-6
    )


# ------------------------------------------------------------------ C11
C11 = {
    ("C", "outward"): (40000, 39919, 39800, 39688.75, 39688.75),
    ("C", "inward"): (36400, 36200, 36319, 36086.95, 36086.95),
    ("B", "outward"): (40000, 39859, 39800, 39656.97, 39727.88),
    ("B", "inward"): (39100, 38900, 38959, 38827.65, 38758.44),
}


@pytest.mark.parametrize("kind", sorted(C11))
def test_c11_single_defect(kind):
    geom = defect_type(*kind)
    ls = build_landscape(
        scene(
            geom,
            square(200),
            dtype="float64",
            twist=TwistGrid(step_deg=1.0, min_deg=-3, max_deg=3),
            window_um=30,
        )
    )
    a0, ax, amx, at, amt = C11[kind]
    # Sloped defect edges are anti-aliased: error at most ~ defect perimeter * 1 px / 4.
    tol = 0.25 * 2 * math.hypot(*{"C": (60, 60), "B": (30, 30)}[kind[0]])
    for (x, y, t), want in zip(
        [(0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1)], C11[kind], strict=True
    ):
        assert overlap(ls, x, y, t) == pytest.approx(
            exact_overlap(geom, square(200), x, y, t), abs=tol
        )
        assert exact_overlap(geom, square(200), x, y, t) == pytest.approx(want, abs=0.01)
    xm, ym, tm, _ = ls.global_minimum()
    assert (xm, ym, tm) == (0.0, 0.0, 0.0)


# ------------------------------------------------------------------ exactness vs resolution
@pytest.mark.parametrize("um_per_px", [1.0, 2.0, 4.0])
def test_against_exact_polygon_overlap(um_per_px):
    """|A_raster - A_exact| <= 0.25 * (chip + pattern perimeter) * um_per_px (um^2)."""
    pat_g, chip_g = four_pad(200, 20), square(200)
    ls = build_landscape(
        scene(pat_g, chip_g, um_per_px=um_per_px, dtype="float64", twist=TwistGrid(step_deg=1.0))
    )
    bound = 0.25 * (chip_g.length + pat_g.length) * um_per_px
    rng = np.random.default_rng(1)
    for _ in range(25):
        x, y = (rng.integers(-60, 61, 2) * um_per_px).tolist()
        t = float(rng.integers(-44, 45))
        assert abs(overlap(ls, x, y, t) - exact_overlap(pat_g, chip_g, x, y, t)) <= bound


# ------------------------------------------------------------------ engine properties
def test_float32_agrees_with_float64():
    sc = scene(four_pad(200, 20), square(200), twist=TwistGrid(step_deg=5.0))
    a, b = build_landscape(sc), build_landscape(sc.replace(dtype="float64"))
    assert a.energy.dtype == np.float32 and b.energy.dtype == np.float64
    # Stated tolerance: the float32 noise floor, 32 eps32 max|E|.
    assert np.abs(a.energy - b.energy).max() <= a.noise_floor_J


def test_twist_free_scene_computes_one_rotation():
    ls = build_landscape(scene(four_pad(200, 20), square(200), effects=Effects(twist=False)))
    assert ls.stats["rotations"] == 1 and ls.energy.shape[0] == 1


def test_pattern_touching_border_has_no_wraparound():
    pat = Mask(np.ones((200, 200)), 1.0)  # fills the whole image: no margin at all
    sc = Scene(
        pattern=pat,
        chip=mask_from_geometry(square(200), 1.0),
        effects=Effects(twist=False),
        dtype="float64",
    )
    ls = build_landscape(sc)
    for x, y in [(150, 0), (199, 199), (-199, 120), (0, -180)]:
        assert overlap(ls, x, y) == pytest.approx((200 - abs(x)) * (200 - abs(y)), abs=1e-7)


def test_png_chip_rotation_keeps_area():
    chip_geom = affinity.scale(square(120), 1.0, 0.5)
    chip = Mask(mask_from_geometry(chip_geom, 1.0).data, 1.0)  # a raster without geometry
    sc = Scene(
        pattern=mask_from_geometry(square(200), 1.0),
        chip=chip,
        twist=TwistGrid(step_deg=7.0),
        dtype="float64",
    )
    ls = build_landscape(sc)
    a = np.asarray(ls.overlap_um2(ls.energy))  # an array for an array (typed array | float)
    rot_area = a.sum(axis=(1, 2)) / 200**2  # sum rule: sum = |P| |C_rot|
    np.testing.assert_allclose(rot_area, chip_geom.area, rtol=0.005)
    assert ls.period_deg == 180.0


def test_symmetry_detection():
    assert chip_symmetry(mask_from_geometry(square(100), 1.0)) == (90.0, True)
    assert chip_symmetry(mask_from_geometry(affinity.scale(square(100), 1, 0.5), 1.0)) == (
        180.0,
        True,
    )
    tri = shapely.Polygon([(0, 0), (40, 0), (0, 30)])
    assert chip_symmetry(mask_from_geometry(tri, 1.0))[0] == 360.0


def test_twist_axis_defaults_to_one_period():
    sc = scene(square(200), square(100), twist=TwistGrid(step_deg=2.0))
    t, wrap, period = twist_axis(sc)
    assert wrap and period == 90 and t[0] == -44 and t[-1] == 44 and len(t) == 45 and 0.0 in t


@pytest.mark.parametrize("backend", ["scipy", "opencv"])
def test_correlate_stack_is_linear_correlation(backend):
    from scipy.signal import correlate

    rng = np.random.default_rng(3)
    pat = rng.random((31, 40))
    chips = rng.random((4, 12, 9))
    chips[2] = chips[0]  # a repeated chip is transformed once, still answered
    out = correlate_stack(pat, chips, dtype="float64", backend=backend)
    ref = np.stack([correlate(pat, c, mode="full", method="direct") for c in chips])
    np.testing.assert_allclose(out, ref, atol=1e-10)
    # float32 within the FFT round-off bound, NOISE_FACTOR eps(float32) of the largest value
    # (the landscape's noise floor; 3.1 eps measured here, so 8 eps held on this machine only)
    from simulator.landscape._correlator import NOISE_FACTOR

    out32 = correlate_stack(pat, chips, dtype="float32", backend=backend)
    assert out32.dtype == np.float32
    np.testing.assert_allclose(out32, ref, atol=NOISE_FACTOR * np.finfo(np.float32).eps * ref.max())
    # binary masks as bool arrays: the same as their 0/1 floats
    np.testing.assert_allclose(
        correlate_stack(pat > 0.5, chips > 0.5, dtype="float64"),
        correlate_stack((pat > 0.5) * 1.0, (chips > 0.5) * 1.0, dtype="float64"),
        atol=1e-10,
    )


@pytest.mark.parametrize("backend", ["scipy", "opencv", "jax"])
@pytest.mark.parametrize("symmetric_pattern", [True, False])
def test_correlate_stack_mirror_twins_and_repeats_match_direct_correlation(
    symmetric_pattern, backend
):
    from scipy.signal import correlate

    rng = np.random.default_rng(4)
    pat = rng.random((31, 40))
    if symmetric_pattern:
        pat = pat + pat[::-1]  # mirror-symmetric rows: twins become flipped copies
    chips = rng.random((6, 12, 9))
    chips[1] = chips[0][::-1]  # mirror twin of chip 0
    chips[3] = chips[0]  # repeat
    chips[4] = chips[2][::-1] + 1e-6  # a near miss: computed on its own
    chips[5] = chips[2][::-1] + 1e-12  # a twin to within round-off
    rel = chip_relations(chips)
    assert rel == [(0, False), (0, True), (2, False), (0, False), (4, False), (2, True)]
    out = correlate_stack(pat, chips, dtype="float64", backend=backend)
    ref = np.stack([correlate(pat, c, mode="full", method="direct") for c in chips])
    np.testing.assert_allclose(out, ref, atol=1e-9)


@pytest.mark.parametrize("backend", ["scipy", "opencv"])
def test_correlator_mirror_output_is_the_mirror_images_correlation(backend):
    rng = np.random.default_rng(5)
    pat = rng.random((50, 44))
    chips = rng.random((3, 20, 16))
    chips[:, :3] = 0  # zero rows: the cut row pass and the mirror relation together
    win = Window(rx=20, ry=25, dx=14, dy=15)
    cor = Correlator(pat, chips.shape[1:], win, "float64", backend)
    mirror = np.empty((3, 51, 41))
    direct = cor(chips, scale=2.0, mirror_out=mirror)
    np.testing.assert_allclose(mirror, cor(chips[:, ::-1], scale=2.0), atol=1e-10)
    np.testing.assert_allclose(direct, cor(chips, scale=2.0), atol=0)


@pytest.mark.parametrize("ny, nx", [(8, 10), (12, 6), (30, 40)])
def test_packed_spectrum_is_opencvs(ny, nx):
    # The kernel of the OpenCV backend: SciPy's half spectrum packed as cv2.dft packs it.
    import cv2
    import scipy.fft as sfft

    from simulator.landscape._spectra import _ccs

    x = np.random.default_rng(ny).random((ny, nx))
    half = sfft.fft(sfft.rfft(x, axis=1), axis=0)
    # two float64 transforms, each within the FFT round-off bound, NOISE_FACTOR eps(float64)
    # of max|X| = x.sum() (the DC term of x >= 0); atol=1e-12 was 7.5 eps of it at 30 x 40
    from simulator.landscape._correlator import NOISE_FACTOR

    tol = 2 * NOISE_FACTOR * np.finfo(np.float64).eps * x.sum()
    np.testing.assert_allclose(_ccs(half, nx), cv2.dft(x), atol=tol)


@pytest.mark.parametrize(
    "pattern_geom, chip_geom, kind",
    [
        (four_pad(120, 20), square(100), "copied_twists"),  # both mirror-symmetric: planes flipped
        (
            defect_type("B", "inward", 120),
            square(100),
            "mirrored_twists",
        ),  # pattern not: spectra shared
        (
            square(120),
            shapely.Polygon([(-50, -50), (50, -50), (30, 50), (-50, 30)]),
            None,
        ),  # chip not
    ],
)
def test_landscape_symmetry_savings_change_nothing(pattern_geom, chip_geom, kind):
    sc = scene(
        pattern_geom,
        chip_geom,
        um_per_px=2.0,
        twist=TwistGrid(step_deg=10.0, min_deg=-40, max_deg=40),
    )
    ls = build_landscape(sc)
    t = ls.twist_deg
    pairs = int(np.sum(t > 0))
    for name in ("copied_twists", "mirrored_twists"):
        assert ls.stats[name] == (pairs if name == kind else 0)
    assert ls.stats["rotations"] == len(t) - (pairs if kind else 0)
    # each twist on its own (no twin to share with) gives the same planes
    for k in (0, 1, len(t) - 1):
        alone = build_landscape(sc, twists=t[k : k + 1])
        np.testing.assert_allclose(ls.energy[k], alone.energy[0], rtol=0, atol=ls.noise_floor_J)


def test_a_mirror_symmetric_scene_has_an_exactly_symmetric_plane_at_twist_zero():
    # Pattern and chip mirror-symmetric: E(x, y, 0) = E(x, -y, 0) exactly (the transforms'
    # round-off alone breaks it, which drifted a start on the mirror line off it), and
    # the twins' planes are each other's flips.
    sc = scene(
        four_pad(120, 20),
        square(100),
        um_per_px=2.0,
        twist=TwistGrid(step_deg=10.0, min_deg=-40, max_deg=40),
    )
    e = build_landscape(sc).energy
    np.testing.assert_array_equal(e, e[::-1, ::-1])  # (twist, y) -> (-twist, -y)
    assert np.abs(e).max() > 0


def test_memory_budget_error_names_the_knobs():
    sc = scene(four_pad(730, 50), square(730), memory_budget_mb=10)
    with pytest.raises(InputError, match=r"needs about .* MB .* coarser scale .* twist .* window"):
        build_landscape(sc)


def test_window_restricts_translations():
    ls = build_landscape(
        scene(four_pad(200, 20), square(200), effects=Effects(twist=False), window_um=50)
    )
    assert ls.x_um[0] == -50 and ls.x_um[-1] == 50 and not ls.full_reach
    with pytest.raises(InputError, match="outside the landscape"):
        ls.energy_at(80, 0, 0)


def test_fft_backend_env_forces_the_default_and_refuses_an_unknown_name(monkeypatch):
    from simulator.landscape import Correlator, Window

    pat = np.zeros((8, 8))
    pat[2:6, 2:6] = 1.0
    win = Window(2, 2, 3, 3)
    for name in ("scipy", "opencv", "jax"):
        monkeypatch.setenv("SELFALIGN_FFT_BACKEND", name)
        assert Correlator(pat, (3, 3), win, "float32").backend == name
        # an explicit backend= is not overridden
        assert Correlator(pat, (3, 3), win, "float32", "scipy").backend == "scipy"
    monkeypatch.setenv("SELFALIGN_FFT_BACKEND", "cufft")
    with pytest.raises(InputError, match="SELFALIGN_FFT_BACKEND='cufft'.*scipy, opencv, jax"):
        Correlator(pat, (3, 3), win, "float32")


def test_the_floor_is_the_minimums_connected_ties_labelled_on_their_box():
    # floor_extent labels the low poses on their bounding box only: on 200 random small
    # landscapes with many ties (energies rounded to whole units, several separate low
    # patches) it finds the same floor as labelling the whole grid.
    from scipy import ndimage

    from simulator.landscape import Landscape, PoseGrid

    rng = np.random.default_rng(3)
    for _ in range(200):
        shape = tuple(int(v) for v in rng.integers(2, 9, size=3))
        e = -np.round(rng.uniform(0, 3, shape)).astype(np.float32) * 1e-9
        grid = PoseGrid.uniform(
            shape,
            wrap=False,
            cut=((False, False), (False, False), (False, False)),
            um_per_px=1.0,
            twist_step_deg=1.0,
            period_deg=90.0,
            rg_px=1.0,
        )
        ls = Landscape(energy=e, grid=grid, delta_gamma=-0.01, energy_scale_J=3e-9)
        it, iy, ix = ls.minimum_index()
        lab, _ = ndimage.label(e <= float(e[it, iy, ix]) + ls.noise_floor_J)
        sel = np.nonzero(lab == lab[it, iy, ix])
        assert ls.floor_extent() == tuple((int(a.min()), int(a.max())) for a in sel)
