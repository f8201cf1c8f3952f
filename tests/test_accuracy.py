"""Accuracy: the exact reference (docs/physics.md C1, C5, C6, C9, C11), raster errors shrinking
with the pixel size, presets meeting their stated bounds, feature-size guidance."""

import math

import numpy as np
import pytest

from foundation import InputError
from patterns.geometry import (
    Mask,
    build,
    defect_type,
    four_pad,
    mask_from_geometry,
    random_jagged,
    square,
)
from patterns.library import LIBRARY
from simulator.core import UM2
from simulator.landscape import build_landscape
from simulator.scene import (
    KNOBS,
    PRESETS,
    Scene,
    TwistGrid,
    apply_preset,
    feature_sets_pixel,
    feature_warning,
    smallest_feature_um,
)
from simulator.testing import (
    exact_gradient_descent,
    exact_greedy,
    force_N,
    gradient_um2,
    overlap_um2,
)

#: Rerun by make test under each FFT backend (SELFALIGN_FFT_BACKEND; tests/conftest.py).
# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = [pytest.mark.fft, pytest.mark.xdist_group("accuracy")]

SQ = square(200)


# ------------------------------------------------------------------ reference: known answers
def test_c1_square_on_square():
    assert overlap_um2(SQ, SQ, (40, 25, 0))[0] == pytest.approx(28_000, abs=1e-9)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-220, 220, (50, 2))
    a = overlap_um2(SQ, SQ, np.column_stack([xy, np.zeros(50)]))
    u = np.clip(200 - np.abs(xy), 0, None)
    np.testing.assert_allclose(a, u[:, 0] * u[:, 1], atol=1e-8)


@pytest.mark.parametrize(
    "alpha, area",
    [
        (0.5, 39_826.98),
        (1, 39_656.97),
        (5, 38_399.68),
        (10, 37_063.53),
        (30, 33_811.98),
        (45, 33_137.08),
    ],
)
def test_c5_pure_twist(alpha, area):
    a = overlap_um2(SQ, SQ, (0, 0, alpha))[0]
    t = math.radians(alpha)
    exact = 200**2 * (1 - (math.cos(t) + math.sin(t) - 1) ** 2 / math.sin(2 * t))
    assert a == pytest.approx(exact, rel=1e-12)
    assert round(a, 2) == area
    assert overlap_um2(SQ, SQ, (0, 0, -alpha))[0] == pytest.approx(a, rel=1e-12)


C11 = {
    ("C", "outward"): (40_000, 39_919, 39_800, 39_688.75, 39_688.75),
    ("C", "inward"): (36_400, 36_200, 36_319, 36_086.95, 36_086.95),
    ("B", "outward"): (40_000, 39_859, 39_800, 39_656.97, 39_727.88),
    ("B", "inward"): (39_100, 38_900, 38_959, 38_827.65, 38_758.44),
}


@pytest.mark.parametrize("key", list(C11))
def test_c11_defect_table(key):
    a = overlap_um2(
        defect_type(*key), SQ, [(0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1)]
    )
    np.testing.assert_array_equal(np.round(a, 2), C11[key])


def test_c6_twist_coupling_and_force_units():
    g = gradient_um2(SQ, SQ, [(40, 25, 0), (25, 40, 0), (50, 10, 0), (10, 80, 0)])
    np.testing.assert_allclose(g[:, 2], [1012.5, -1012.5, 2800, -3850], rtol=1e-6)
    np.testing.assert_allclose(g[0, :2], [-175, -160], rtol=1e-9)  # dA/dx = -(L - |y|) for x > 0
    f = force_N(SQ, SQ, [(40, 25, 0)])[0]
    dg = -0.0728 * (math.cos(math.radians(30)) - math.cos(math.radians(60)))
    assert f[0] == pytest.approx(dg * 175 * 1e-6, rel=1e-6)  # restoring: points to -x


def test_c9_greedy_on_exact_overlap():
    fp = four_pad(200, 20)
    for start, final, steps in [
        ((89, 0, 0), (0, 0, 0), 89),
        ((100, 0, 0), (100, 0, 0), 0),
        ((120, 0, 5), (110, 0, 0), 10),
    ]:
        run = exact_greedy(fp, SQ, start)
        assert run.final == final and run.steps == steps and run.status == "converged"
    assert exact_greedy(fp, SQ, (91, 0, 0)).final == (0, 0, 0)  # the escape at the plateau end


def test_greedy_step_sizes_follow_the_grid():
    run = exact_greedy(SQ, SQ, (41, -19, 3.2), step_um=2.0, step_deg=0.5)
    assert run.final == (0, 0, 0)
    assert np.all(np.abs(np.diff(run.path, axis=0)) <= [2, 2, 0.5])
    assert np.allclose(run.path[:, :2] % 2, 0) and np.allclose(run.path[:, 2] % 0.5, 0)


def test_gradient_descent_reaches_the_minimum():
    run = exact_gradient_descent(SQ, SQ, (30.3, -12.7, 4.0))
    assert np.all(np.abs(run.final) < [0.05, 0.05, 0.05])
    assert np.all(np.diff(run.overlap_um2) > 0)


# ------------------------------------------------------------------ raster vs exact
def _scene(geom, chip, s, dtype="float32", step=1.0):
    return Scene(
        pattern=mask_from_geometry(geom, s, margin_um=10),
        chip=mask_from_geometry(chip, s),
        twist=TwistGrid(step, -12.0, 12.0),
        window_um=70,
        dtype=dtype,
    )


def _energy_error(geom, chip, s, poses, **kw) -> float:
    """RMS |A_raster - A_exact| / A_chip at the poses."""
    ls = build_landscape(_scene(geom, chip, s, **kw))
    a = ls.energy_at(*poses.T) / (ls.delta_gamma * UM2)
    return float(np.sqrt(np.mean((a - overlap_um2(geom, chip, poses)) ** 2)) / chip.area)


POSES = np.random.default_rng(7).uniform(-1, 1, (60, 3)) * [60, 60, 10]


@pytest.mark.parametrize(
    "geom", [square(200), four_pad(200, 20)], ids=["square200", "fourpad200_20"]
)
def test_energy_error_shrinks_with_the_pixel_size(geom):
    err = [_energy_error(geom, SQ, s, POSES) for s in (4.0, 2.0, 1.0)]
    assert err[0] > err[1] > err[2]
    assert err[2] < 2e-4  # 0.02 % of the chip area at 1 um/px


@pytest.mark.parametrize(
    "stem", ["random_jagged_s2", "defect_B_outward", "square_200", "constant_jagged_a3p2"]
)
@pytest.mark.parametrize("name", list(PRESETS))
def test_presets_meet_their_stated_energy_error(stem, name):
    design, params = next((d, p) for s, d, p in LIBRARY if s == stem)
    geom = build(design, **params)
    k = apply_preset(name, {}, feature_um=smallest_feature_um(geom))
    err = _energy_error(geom, SQ, k["um_per_px"], POSES, dtype=k["dtype"], step=k["twist_step_deg"])
    assert 100 * err <= PRESETS[name].energy_rms_pct


# ------------------------------------------------------------------ presets
@pytest.mark.parametrize("name", [*PRESETS, None])
def test_apply_preset_never_overrides_explicit_knobs(name):
    explicit = {"um_per_px": 3.7, "twist_step_deg": 0.7, "dtype": "float64"}
    for knob in KNOBS:
        out = apply_preset(name, {knob: explicit[knob]}, feature_um=1.0, native_um_per_px=0.1)
        assert out[knob] == explicit[knob]
        assert set(out) == set(KNOBS)
    assert apply_preset(name, explicit, feature_um=0.01) == explicit
    assert apply_preset(name, dict.fromkeys(KNOBS)) == apply_preset(name, {})  # None = not set


def test_presets_order_and_default():
    f = smallest_feature_um(random_jagged(200, sigma=2, seed=1))
    px = [apply_preset(n, {}, feature_um=f)["um_per_px"] for n in ("fast", "balanced", "precise")]
    assert px[0] > px[1] > px[2]
    assert apply_preset(None, {}) == apply_preset("balanced", {})
    assert apply_preset("precise", {}, feature_um=1000.0, native_um_per_px=2.0)["um_per_px"] == 2.0


@pytest.mark.parametrize("name", [*PRESETS, None])
def test_the_feature_sets_the_pixel_only_of_an_image_finer_than_the_presets_largest(name):
    """An image whose pixels are at least the preset's largest keeps them whatever its
    smallest feature; a finer image, or exact geometry, takes the pixel from the feature."""
    largest = PRESETS[name or "balanced"].max_um_per_px
    for native in (largest, 2 * largest):
        assert not feature_sets_pixel(name, native)
        pixels = {
            apply_preset(name, {}, feature_um=f, native_um_per_px=native)["um_per_px"]
            for f in (0.1, 5.0, 1e4)
        }
        assert pixels == {native} == {apply_preset(name, {}, native_um_per_px=native)["um_per_px"]}
    assert feature_sets_pixel(name, largest / 2) and feature_sets_pixel(name, None)
    with pytest.raises(InputError, match="unknown accuracy preset 'exact'"):
        feature_sets_pixel("exact")


def test_a_scene_measures_the_feature_only_when_it_sets_the_pixel(monkeypatch, tmp_path):
    """Outlining a pattern image is measured work: the scene of a 1 um/px image under the
    balanced or precise preset never outlines it (its pixel is 1 um/px whatever the
    feature); under the fast preset it does, and takes the pixel from its 50 um gap."""
    from patterns import write_mask
    from simulator.scene import Scene, _accuracy

    calls = []
    measure = _accuracy._smallest_feature_um
    monkeypatch.setattr(
        _accuracy, "_smallest_feature_um", lambda *a: calls.append(1) or measure(*a)
    )
    png = write_mask(tmp_path / "fp.png", mask_from_geometry(four_pad(400, 50), 1.0))
    doc = {"pattern": str(png), "chip_size_um": [400, 400]}
    assert Scene.from_dict(doc).um_per_px == 1.0 and calls == []
    assert Scene.from_dict(doc | {"accuracy": "precise"}).um_per_px == 1.0 and calls == []
    # 50 um / 2 px per feature = 25 um, kept to the fast preset's largest pixel, 4 um
    assert Scene.from_dict(doc | {"accuracy": "fast"}).um_per_px == 4.0 and len(calls) == 1
    calls.clear()
    fine = write_mask(tmp_path / "fine.png", mask_from_geometry(four_pad(400, 50), 0.25))
    assert Scene.from_dict({"pattern": str(fine), "chip_size_um": [400, 400]}).um_per_px == 1.0
    assert len(calls) == 1  # 50 um / 4 px per feature, rounded down: 10 um, kept to 1 um/px


def test_apply_preset_rejects_unknowns():
    with pytest.raises(InputError, match="unknown accuracy preset 'exact'"):
        apply_preset("exact", {})
    with pytest.raises(InputError, match="unknown accuracy knob"):
        apply_preset("fast", {"um_per_pixel": 1.0})


# ------------------------------------------------------------------ feature size
def test_feature_warning_random_jagged_sigma_2():
    g = random_jagged(200, sigma=2, seed=1)
    msg = feature_warning(g, 4.0)
    assert msg is not None and "\n" not in msg and "--resolution 1 " in msg
    assert feature_warning(g, 0.5) is None


def test_feature_warning_four_pad_730_50():
    g = four_pad(730, 50)
    assert smallest_feature_um(g) == pytest.approx(50.0)
    assert feature_warning(g, 1.0) is None
    assert feature_warning(mask_from_geometry(g, 1.0), 1.0) is None
    assert feature_warning(g, 20.0) is not None  # the 50 um gap is 2.5 px


def test_smallest_feature_of_geometry_and_png():
    assert smallest_feature_um(square(200)) == pytest.approx(200.0)
    assert smallest_feature_um(defect_type("A", "outward")) == pytest.approx(10 * math.sqrt(2))
    g = four_pad(730, 100)
    png = mask_from_geometry(g, 1.0)
    assert smallest_feature_um(Mask(png.data, 1.0)) == pytest.approx(
        100.0, abs=1.0
    )  # no geometry: outline
    with pytest.raises(InputError, match="geometry or a patterns.geometry.Mask"):
        smallest_feature_um(np.ones((4, 4)))  # pyright: ignore[reportArgumentType] - the test's point
