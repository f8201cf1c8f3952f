"""Materials, liquid, chip body, damping and the analytic checks C12-C14 of docs/physics.md."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from foundation import InputError
from simulator.liquid import (
    critical_volume_nl,
    dimensionless_volume,
    overflow_angle_deg,
    overflow_bias_um,
    overflow_conditions,
)
from simulator.physics import (
    DAMPING_CALIBRATION,
    Chip,
    Liquid,
    Materials,
    couette_damping,
    couette_rotational_damping,
    couette_torsional_damping,
    delta_gamma,
    gamma_wet,
    meniscus_height_um,
    parallelepiped_force,
    parallelepiped_stiffness,
)

WATER = 0.0728


# ------------------------------------------------------------------- C14 Young weights


@pytest.mark.parametrize(
    ("theta_p", "theta_s", "mn_per_m", "places"),
    [(30, 60, -26.65, 2), (40, 60, -19.37, 2), (41, 89, -53.67, 2), (31, 159, -130.4, 1)],
)
def test_delta_gamma_worked_values(theta_p, theta_s, mn_per_m, places):
    """docs/physics.md §2 table and C14, to their printed precision."""
    dg = delta_gamma(WATER, theta_p, theta_s)
    assert round(dg * 1e3, places) == mn_per_m
    assert round(Materials(WATER, theta_p, theta_s).delta_gamma_N_m * 1e3, places) == mn_per_m


def test_delta_gamma_is_difference_of_wetting_energies():
    assert delta_gamma(WATER, 30, 60) == pytest.approx(gamma_wet(30, WATER) - gamma_wet(60, WATER))
    assert gamma_wet(90, WATER) == 0.0
    assert gamma_wet(0, WATER) == -WATER


def test_materials_defaults_are_the_four_pad_tests():
    mat = Materials()
    assert (mat.surface_tension_N_m, mat.pad_angle_deg, mat.substrate_angle_deg) == (
        0.0728,
        30.0,
        60.0,
    )
    assert round(mat.delta_gamma_N_m * 1e3, 2) == -26.65
    assert mat.joules_per_um2 == pytest.approx(mat.delta_gamma_N_m * 1e-12)
    assert hash(mat) == hash(Materials())
    with pytest.raises(dataclasses.FrozenInstanceError):
        mat.pad_angle_deg = 10  # type: ignore[misc]


@pytest.mark.parametrize(("pad", "sub"), [(60, 30), (45, 45), (150, 20)])
def test_repulsive_pair_raises(pad, sub):
    with pytest.raises(
        InputError, match=r"pad contact angle .* must be smaller than substrate .*allow_repulsive"
    ):
        Materials(pad_angle_deg=pad, substrate_angle_deg=sub)


def test_allow_repulsive_passes():
    mat = Materials(pad_angle_deg=60, substrate_angle_deg=30, allow_repulsive=True)
    assert round(mat.delta_gamma_N_m * 1e3, 2) == 26.65


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pad_angle_deg": -1}, "pad contact angle must be a contact angle in \\[0, 180\\]"),
        (
            {"substrate_angle_deg": 181},
            "substrate contact angle must be a contact angle in \\[0, 180\\]",
        ),
        ({"pad_angle_deg": float("nan")}, "pad contact angle"),
        ({"surface_tension_N_m": 0}, "surface tension must be a finite number > 0"),
        ({"surface_tension_N_m": math.inf}, "surface tension must be a finite number > 0"),
        ({"surface_tension_N_m": "water"}, "surface tension must be a number"),
    ],
)
def test_materials_validation(kwargs, match):
    with pytest.raises(InputError, match=match):
        Materials(**kwargs)


def test_graded_wettability_is_linear_in_cos_theta():
    mat = Materials()
    assert mat.weight(0.0) == 0.0
    assert mat.weight(1.0) == mat.delta_gamma_N_m
    np.testing.assert_allclose(
        mat.weight(np.array([0.25, 0.5])), [0.25, 0.5] * np.array(mat.delta_gamma_N_m)
    )
    assert mat.equivalent_angle_deg(0.0) == pytest.approx(60.0)
    assert mat.equivalent_angle_deg(1.0) == pytest.approx(30.0)
    # A uniform pad at the equivalent angle has exactly the graded weight.
    for v in (0.1, 0.5, 0.9):
        theta = mat.equivalent_angle_deg(v)
        assert delta_gamma(WATER, theta, 60) == pytest.approx(mat.weight(v), rel=1e-12)
    with pytest.raises(InputError, match="grey level must lie in \\[0, 1\\]"):
        mat.equivalent_angle_deg(1.5)


def test_rescaling_by_delta_gamma_keeps_the_sign():
    """C14: any attracting pair only rescales energies (same sign, different magnitude)."""
    a, b = (
        Materials(pad_angle_deg=30, substrate_angle_deg=60),
        Materials(pad_angle_deg=41, substrate_angle_deg=89),
    )
    assert a.delta_gamma_N_m < 0 and b.delta_gamma_N_m < 0
    overlaps = np.array([0.0, 100.0, 32400.0])
    ea, eb = a.joules_per_um2 * overlaps, b.joules_per_um2 * overlaps
    assert np.array_equal(np.argsort(ea), np.argsort(eb))


# ------------------------------------------------------------------ C12 meniscus, overflow


def test_meniscus_height_c12():
    assert round(meniscus_height_um(20, 730 * 730), 2) == 37.53
    assert meniscus_height_um(0.5, 200 * 200) == pytest.approx(12.5, abs=1e-12)
    assert meniscus_height_um(0.9, 200 * 200) == pytest.approx(22.5)
    assert meniscus_height_um(0.45, 200 * 200) == pytest.approx(11.25)
    assert Liquid(volume_nl=0.5).meniscus_height_um(40_000) == pytest.approx(12.5)


def test_overflow_bias_c12():
    assert round(overflow_bias_um(12.5, 90, 60), 2) == 21.65
    assert overflow_bias_um(12.5, 60, 60) == math.inf
    assert overflow_bias_um(12.5, 45, 60) == math.inf
    assert overflow_bias_um(12.5, 170, 60) == 0.0
    assert overflow_angle_deg(90, 60) == 150.0


def test_overflow_conditions():
    # Example of 9.4: vertical wall, pad advancing 60 deg, h = 12.5 um, chip advancing 20 deg.
    ok = overflow_conditions(90, 60, theta_chip_deg=20, bias_um=-10, h_um=12.5)
    assert ok.holding == (3,) and not ok.overflows
    assert round(ok.overflow_bias_um, 2) == 21.65
    bad = overflow_conditions(90, 60, theta_chip_deg=20, bias_um=30, h_um=12.5)
    assert bad.holding == () and bad.overflows
    dewets = overflow_conditions(90, 60, theta_chip_deg=40, bias_um=30, h_um=12.5)
    assert dewets.holding == (2,)
    flush = overflow_conditions(60, 60, theta_chip_deg=0, bias_um=1e6, h_um=12.5)
    # Condition 3 applies only when the edge is steeper than the pad's advancing angle (docs/physics.md §9, condition 3).
    assert flush.holding == (1,) and flush.overflow_bias_um == math.inf
    sloped = overflow_conditions(50, 60, theta_chip_deg=0, bias_um=1e6, h_um=12.5)
    assert sloped.holding == (1, 2)
    with pytest.raises(InputError, match="edge angle must be a contact angle"):
        overflow_conditions(200, 60, 20, 0, 12.5)


def test_critical_volume_round_trip():
    area = 710.0**2
    v = critical_volume_nl(0.5, area)
    assert v == pytest.approx((0.5 * area) ** 1.5 / 1e6)
    assert dimensionless_volume(v, area) == pytest.approx(0.5)
    with pytest.raises(InputError, match="V_ND must be a finite number > 0"):
        critical_volume_nl(-0.1, area)


# ---------------------------------------------------------------- C13 parallelepiped force


def test_parallelepiped_force_c13():
    g, L, h = WATER, 730.0, 37.5
    scale = 2 * g * L * 1e-6
    assert parallelepiped_force(1e9, h, L, g) == pytest.approx(-scale, rel=1e-12)
    assert parallelepiped_force(h, h, L, g) == pytest.approx(
        -math.sqrt(2) * g * L * 1e-6, rel=1e-14
    )
    assert parallelepiped_force(0.0, h, L, g) == 0.0
    dx = 1e-4
    slope = (parallelepiped_force(dx, h, L, g) - parallelepiped_force(-dx, h, L, g)) / (
        2 * dx * 1e-6
    )
    assert slope == pytest.approx(-scale / (h * 1e-6), rel=1e-9)
    assert parallelepiped_stiffness(h, L, g) == pytest.approx(-slope, rel=1e-9)
    assert round(scale * 1e6) == 106  # "water, L = 730 um gives 2 gamma L ~ 106 uN"
    xs = np.linspace(-100, 100, 11)
    f = np.asarray(parallelepiped_force(xs, h, L, g))  # an array for an array (typed float | array)
    assert f.shape == xs.shape and np.all(np.diff(f) < 0)
    np.testing.assert_array_equal(f, -f[::-1])


# ------------------------------------------------------------------- chip, liquid, damping


def test_chip_mass_and_inertia():
    chip = Chip(200, 200)
    assert chip.mass_kg == pytest.approx(2.4e-9, rel=1e-12)
    assert chip.moment_of_inertia_kg_m2 == pytest.approx(2.4e-9 * (2 * 200e-6**2) / 12, rel=1e-12)
    assert chip.polar_moment_um4 == pytest.approx(200**4 * 2 / 12)
    with pytest.raises(InputError, match="chip thickness must be a finite number > 0"):
        Chip(200, 200, thickness_um=0)


def test_liquid_defaults_and_validation():
    water = Liquid()
    assert (water.name, water.surface_tension_N_m, water.viscosity_Pa_s, water.density_kg_m3) == (
        "water",
        0.0728,
        1.0e-3,
        998.0,
    )
    with pytest.raises(InputError, match="viscosity must be a finite number > 0"):
        Liquid(viscosity_Pa_s=-1)
    with pytest.raises(InputError, match="droplet volume"):
        Liquid(volume_nl=0)


def test_couette_damping_units():
    # mu A / h: 1e-3 Pa s * 4e-8 m^2 / 12.5e-6 m = 3.2e-6 N s/m.
    assert couette_damping(1e-3, 200 * 200, 12.5) == pytest.approx(3.2e-6, rel=1e-12)
    # mu J / h with J = A (w^2 + h^2) / 12 in m^4.
    j_m4 = 4e-8 * (2 * 200e-6**2) / 12
    expected = 1e-3 * j_m4 / 12.5e-6
    assert couette_rotational_damping(1e-3, 200, 200, 12.5) == pytest.approx(expected, rel=1e-12)
    assert couette_torsional_damping(1e-3, Chip(200, 200).polar_moment_um4, 12.5) == pytest.approx(
        expected
    )
    assert DAMPING_CALIBRATION > 1


def test_damping_docstring_ratios():
    """The damping ratios quoted next to DAMPING_CALIBRATION (0.021 and 0.024 uncalibrated)."""
    for side, volume, zeta0 in [(200, 0.5, 0.021), (730, 20.0, 0.024)]:
        chip = Chip(side, side)
        h = meniscus_height_um(volume, chip.area_um2)
        c = couette_damping(1e-3, chip.area_um2, h)
        k = parallelepiped_stiffness(h, side)
        assert round(c / (2 * math.sqrt(k * chip.mass_kg)), 3) == zeta0
