"""Time-resolved dynamics (simulator.motion) against closed forms and invariants.

Known answers: on a synthetic quadratic landscape ``E = k x^2 / 2`` (a linear spring with
the parallelepiped stiffness k0 = 2 gamma L / h of docs/physics.md C13) the overdamped run
follows ``x0 exp(-k t / c)`` and the inertial run the damped-oscillator closed form, both
under- and overdamped. The smoothed potential of the steppers equals E plus a constant
on a quadratic, so the only error is the integrator's: stated per test, relative to x0.
Invariants: mechanical energy never rises by more than the noise floor along the
recorded path, runs stop (CONVERGED) before t_max, same inputs give the same bits,
vmap equals single runs. A synthetic four-pad-like well: overdamped chips stop on its
plateau, a lightly damped inertial one crosses it. Real landscape: a 200 um square chip
on a 200 um square pad.
All in float32, the project's default dtype.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from foundation import InputError
from patterns.geometry import mask_from_geometry, square
from simulator.core import OUTCOMES
from simulator.landscape import PoseGrid, build_landscape
from simulator.motion import (
    CONVERGED,
    EDGE,
    MAX_STEPS,
    DynamicsParams,
    classify,
    field_and_grid,
    gradient,
    inertial,
    interpolate,
    make_field,
    overdamped,
    potential,
    potential_and_gradient,
)
from simulator.physics import DAMPING_CALIBRATION, Chip, Liquid, parallelepiped_stiffness
from simulator.scene import Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("dynamics")

STATIC = ("grid", "max_steps", "record")
OVERDAMPED = jax.jit(overdamped, static_argnames=STATIC)
INERTIAL = jax.jit(inertial, static_argnames=STATIC)
PHI_GRAD = jax.jit(jax.vmap(potential_and_gradient, (None, None, 0)), static_argnums=1)
MAX_STEPS_N = 1000  # one buffer size everywhere: one compilation per model and field shape

# The 200 x 200 x 50 um SU-8 chip on 0.5 nl of water (docs/physics.md §2): h = 12.5 um.
K0 = parallelepiped_stiffness(12.5, 200.0)  # N/m, 2.33
MASS = Chip(200.0, 200.0).mass_kg  # 2.4e-9 kg
UM_PER_PX = 0.5
NX, NY, XC = 201, 5, 100  # spring minimum at ix = XC, iy = NY // 2
X0_PX = 80.0  # start 40 um off


def spring_field(k=K0, sign=1.0):
    """E = sign * k x^2 / 2 (J) on one twist, NY rows, NX columns; x and y sides cut."""
    x = (np.arange(NX) - XC) * UM_PER_PX * 1e-6
    e = np.broadcast_to(sign * 0.5 * k * x * x, (1, NY, NX)).astype(np.float32)
    floor = 32 * np.finfo(np.float32).eps * np.abs(e).max()
    grid = PoseGrid.uniform(
        (1, NY, NX),
        wrap=False,
        cut=((False, False), (True, True), (True, True)),
        um_per_px=UM_PER_PX,
        twist_step_deg=1.0,
        x_first_px=-XC,
        y_first_px=-(NY // 2),
        period_deg=90.0,
        rg_px=100.0,
    )
    field = make_field(e, grid, floor, [0, NY // 2, XC])
    return field, grid


def params(c, t_max_s=1e-2):
    return DynamicsParams(
        mass_kg=MASS, inertia_kg_m2=1e-17, damping_N_s_m=c, rot_damping_N_m_s=1e-12, t_max_s=t_max_s
    )


def spring_start(dx=X0_PX):
    return jnp.asarray([0.0, NY // 2, XC + dx], jnp.float32)


def trajectory(s):
    """(t, x in m, mechanical energy in J) over the recorded steps of a run."""
    n = int(s.step) + 1
    t = np.asarray(s.path_t[:n], float)
    x = (np.asarray(s.path[:n, 2], float) - XC) * UM_PER_PX * 1e-6
    h = np.asarray(s.path_potential[:n], float) + np.asarray(s.path_kinetic[:n], float)
    return t, x, h


def oscillator(t, x0, k, m, c):
    """x(t) of m x'' + c x' + k x = 0 from rest at x0."""
    w = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    if zeta < 1:
        wd = w * math.sqrt(1 - zeta**2)
        return x0 * np.exp(-zeta * w * t) * (np.cos(wd * t) + zeta * w / wd * np.sin(wd * t))
    r1, r2 = -zeta * w + w * math.sqrt(zeta**2 - 1), -zeta * w - w * math.sqrt(zeta**2 - 1)
    return x0 * (r2 * np.exp(r1 * t) - r1 * np.exp(r2 * t)) / (r2 - r1)


def assert_energy_never_rises(s, floor):
    _, _, h = trajectory(s)
    assert np.all(np.diff(h) <= floor), f"rise {np.diff(h).max():.3g} J > floor {floor:.3g} J"
    # no slow drift either: never above the lowest value so far by more than the floor
    assert np.all(h - np.minimum.accumulate(h) <= floor)


# ------------------------------------------------------------------ linear spring
def test_potential_is_the_spring_plus_a_constant_and_its_gradient_the_central_difference():
    field, grid = spring_field()
    k_idx = K0 * (UM_PER_PX * 1e-6) ** 2  # J per index step^2
    dx = np.array([-37.3, -1.0, -0.25, 0.0, 0.6, 12.5, 79.9])
    q = jnp.asarray(
        np.stack([np.zeros_like(dx), np.full_like(dx, 2.3), XC + dx], axis=1), jnp.float32
    )
    phi, grad = PHI_GRAD(field, grid, q)
    # box mean of x^2 over +-1 is x^2 + 1/3, the chords of the interpolant add 1/6: Phi = k x^2/2 + k/4
    np.testing.assert_allclose(
        np.asarray(phi), 0.5 * k_idx * dx * dx + k_idx / 4, rtol=1e-5, atol=1e-6 * k_idx
    )
    np.testing.assert_allclose(np.asarray(grad[:, 2]), k_idx * dx, rtol=1e-5, atol=1e-5 * k_idx)
    central = jax.jit(jax.vmap(gradient, (None, None, 0)), static_argnums=1)(field, grid, q)
    np.testing.assert_allclose(
        np.asarray(grad[:, 2]), np.asarray(central[:, 2]), rtol=1e-5, atol=float(field.floor)
    )
    assert np.all(np.asarray(grad[:, 0]) == 0.0) and np.all(
        np.abs(np.asarray(grad[:, 1])) <= float(field.floor)
    )


def test_overdamped_spring_follows_the_exponential():
    field, grid = spring_field()
    c = 9.6e-5  # the calibrated Couette damping of the 200 um set-up, N s/m
    s = OVERDAMPED(field, grid, params(c), spring_start(), MAX_STEPS_N)
    t, x, _ = trajectory(s)
    x0 = X0_PX * UM_PER_PX * 1e-6
    # Tolerance: integrator error only; measured 3e-6 x0 at the default tolerances.
    np.testing.assert_allclose(x, x0 * np.exp(-K0 * t / c), rtol=0, atol=1e-4 * x0)
    assert int(s.status) == CONVERGED and float(s.time_s) < 1e-2
    assert int(s.step) > 5 and float(s.kinetic) == 0.0
    assert abs(float(s.q[2]) - XC) < 0.05 and float(s.q[0]) == 0.0 and float(s.q[1]) == NY // 2
    assert_energy_never_rises(s, float(field.floor))


@pytest.mark.parametrize("zeta", [0.2, 2.0], ids=["underdamped", "overdamped"])
def test_inertial_spring_follows_the_damped_oscillator(zeta):
    field, grid = spring_field()
    c = 2 * zeta * math.sqrt(K0 * MASS)
    p = params(c)
    assert p.damping_ratio(K0) == pytest.approx(zeta)
    s = INERTIAL(field, grid, p, spring_start(), MAX_STEPS_N)
    t, x, _ = trajectory(s)
    x0 = X0_PX * UM_PER_PX * 1e-6
    # Tolerance: integrator error only; measured <= 1e-5 x0 at the default tolerances.
    np.testing.assert_allclose(x, oscillator(t, x0, K0, MASS, c), rtol=0, atol=1e-4 * x0)
    if zeta < 1:
        assert (
            x.min() < -0.5 * x0
        )  # it overshoots (first swing: x0 exp(-pi zeta / sqrt(1 - zeta^2)))
    else:
        assert x.min() > -1e-4 * x0
    assert int(s.status) == CONVERGED and float(s.time_s) < 1e-2
    assert float(s.kinetic) <= float(field.floor)
    assert_energy_never_rises(s, float(field.floor))


def plateau_field(a=1e-12):
    """A 1-D four-pad-like well on the spring's grid (so no new compilation): E = -a w(|x|)
    with w = 90 - s for s <= 45 px, 45 on the plateau 45..55 px, 100 - s beyond (J)."""
    s = np.abs(np.arange(NX) - XC).astype(float)
    w = np.where(s <= 45, 90 - s, np.where(s <= 55, 45, np.maximum(100 - s, 0)))
    e = np.broadcast_to(-a * w, (1, NY, NX)).astype(np.float32)
    field, grid = spring_field()
    floor = 32 * np.finfo(np.float32).eps * np.abs(e).max()
    return make_field(e, grid, floor, field.best), grid


@pytest.mark.parametrize(
    "model, c, x0, stop_px, outcome",
    [
        ("overdamped", 1e-5, 50.0, 50.0, "plateau"),  # on the plateau: no force, no step
        ("overdamped", 1e-5, 80.0, 54.0, "plateau"),  # stops where the plateau starts
        ("inertial", 1e-4, 80.0, 54.0, "plateau"),  # heavily damped: the same
        ("inertial", 1e-5, 80.0, 0.0, "aligned"),  # light damping: momentum crosses it
    ],
)
def test_plateau_stops_overdamped_chips_and_inertia_can_cross_it(model, c, x0, stop_px, outcome):
    # The quasi-static model cannot say what happens on a plateau (docs/physics.md §3.2, limit 2);
    # the dynamics can. Phi rounds the plateau edge at 55 px over +-1 px.
    field, grid = plateau_field()
    s = (OVERDAMPED if model == "overdamped" else INERTIAL)(
        field, grid, params(c), spring_start(x0), MAX_STEPS_N
    )
    assert int(s.status) == CONVERGED
    assert abs(float(s.q[2]) - XC - stop_px) <= 1.0
    assert OUTCOMES[int(classify(field, grid, s.q, s.energy, s.status, s.flat))] == outcome
    if outcome == "plateau":
        assert bool(s.flat)  # (at the well bottom, too: E does not depend on y here)
    if x0 == 50.0:
        assert int(s.step) == 0
    assert_energy_never_rises(s, float(field.floor))


def test_runs_out_of_time_or_steps():
    field, grid = spring_field()
    s = INERTIAL(field, grid, params(2e-5, t_max_s=1e-4), spring_start(), MAX_STEPS_N)
    assert int(s.status) == MAX_STEPS and float(s.time_s) == pytest.approx(1e-4, rel=1e-5)
    # A lightly damped chip ringing in the four-pad-like well needs more than MAX_STEPS_N
    # solver steps (accepted or rejected): the buffers end full, the last row is the end.
    field_p, _ = plateau_field()
    s = INERTIAL(field_p, grid, params(1e-6), spring_start(), MAX_STEPS_N)
    assert int(s.status) == MAX_STEPS and 0 < int(s.step) <= MAX_STEPS_N
    assert float(s.time_s) < 1e-2 and float(s.time_s) == float(s.path_t[int(s.step)])
    np.testing.assert_array_equal(np.asarray(s.q), np.asarray(s.path[int(s.step)]))
    with pytest.raises(InputError, match="max_steps"):
        overdamped(field, grid, params(9.6e-5), spring_start(), 0)


def test_reaching_a_cut_side_stops_with_edge():
    field, grid = spring_field(sign=-1.0)  # a hill: pushed out to the cut side of the window
    s = INERTIAL(field, grid, params(2e-5), spring_start(20.0), MAX_STEPS_N)
    assert int(s.status) == EDGE and float(s.q[2]) >= NX - 1


def test_same_inputs_same_bits():
    field, grid = spring_field()
    a = INERTIAL(field, grid, params(3e-5), spring_start(), MAX_STEPS_N)
    b = INERTIAL(field, grid, params(3e-5), spring_start(), MAX_STEPS_N)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_vmap_over_starts_equals_single_runs_and_record_off_keeps_the_end():
    field, grid = spring_field()
    p = params(3e-5)
    starts = jnp.stack([spring_start(d) for d in (80.0, -55.5, 7.25, 0.0)])
    batch = jax.jit(
        jax.vmap(inertial, in_axes=(None, None, None, 0, None, None)),
        static_argnums=(1, 4, 5),
    )
    out = batch(field, grid, p, starts, MAX_STEPS_N, False)
    assert out.path.shape == (4, 1, 3)
    for i in range(len(starts)):
        one = INERTIAL(field, grid, p, starts[i], MAX_STEPS_N)
        assert int(out.step[i]) == int(one.step) and int(out.status[i]) == int(one.status)
        np.testing.assert_allclose(np.asarray(out.q[i]), np.asarray(one.q), rtol=0, atol=1e-5)
        np.testing.assert_allclose(float(out.time_s[i]), float(one.time_s), rtol=1e-6)
        np.testing.assert_array_equal(np.asarray(out.path[i, 0]), np.asarray(starts[i]))
    assert int(out.step[3]) == 0 and int(out.status[3]) == CONVERGED  # starts at the minimum


# ------------------------------------------------------------------ parameters
def test_params_from_physics_is_the_calibrated_couette_estimate():
    chip, liquid = Chip(200.0, 200.0), Liquid(volume_nl=0.5)
    p = DynamicsParams.from_physics(chip, liquid, 200.0 * 200.0, calibration=30.0)
    # c = 30 mu A / h with h = V / A = 12.5 um
    assert p.damping_N_s_m == pytest.approx(30 * 1e-3 * 4e-8 / 12.5e-6)
    assert p.rot_damping_N_m_s == pytest.approx(30 * 1e-3 * (4e-8 * 8e-8 / 12) / 12.5e-6)
    former = DynamicsParams.from_physics(
        chip, liquid, 200.0 * 200.0, calibration=DAMPING_CALIBRATION
    )
    assert former.damping_N_s_m == pytest.approx(p.damping_N_s_m * DAMPING_CALIBRATION / 30)
    assert p.mass_kg == pytest.approx(2.4e-9) and p.inertia_kg_m2 == pytest.approx(
        2.4e-9 * 8e-8 / 12
    )
    assert p.damping_ratio(K0) == pytest.approx(30 * 0.0214, rel=0.01)  # DAMPING_CALIBRATION table
    bare = DynamicsParams.from_physics(chip, liquid, calibration=1.0)
    assert bare.damping_N_s_m == pytest.approx(p.damping_N_s_m / 30)


def test_params_from_scene_match_the_cuboid(square_200):
    _, _, p = square_200  # from_scene of a 200 um square chip mask at 2 um/px
    q = DynamicsParams.from_physics(Chip(200.0, 200.0), Liquid(volume_nl=0.5), calibration=30.0)
    for name in ("mass_kg", "inertia_kg_m2", "damping_N_s_m", "rot_damping_N_m_s", "t_max_s"):
        assert getattr(p, name) == pytest.approx(getattr(q, name), rel=1e-9), name


def test_params_reject_bad_values():
    with pytest.raises(InputError, match="damping_N_s_m"):
        DynamicsParams(
            mass_kg=1e-9, inertia_kg_m2=1e-17, damping_N_s_m=-1.0, rot_damping_N_m_s=1e-12
        )
    with pytest.raises(InputError, match="damping calibration"):
        DynamicsParams.from_physics(Chip(200.0, 200.0), Liquid(), calibration=0.0)


# ------------------------------------------------------------------ real landscape
@pytest.fixture(scope="module")
def square_200():
    """200 um square chip on a 200 um square pad, 2 um/px, 5 degree twist steps (float32)."""
    scene = Scene(
        pattern=mask_from_geometry(square(200), 2.0, margin_um=10.0),
        chip=mask_from_geometry(square(200), 2.0),
        twist=TwistGrid(step_deg=5.0),
        liquid=Liquid(volume_nl=0.5),
        damping_calibration=30.0,  # underdamped (zeta ~ 0.65): the explicit solver's regime
    )
    rg_px = 200.0 / math.sqrt(6.0) / 2.0  # radius of gyration of the square, px
    field, grid = field_and_grid(build_landscape(scene), rg_px)
    return field, grid, DynamicsParams.from_scene(scene)


def test_phi_gradient_is_its_autodiff_gradient(square_200):
    field, grid, _ = square_200
    q = jnp.asarray(
        np.random.default_rng(0).uniform([0, 100, 100], [17, 140, 140], size=(8, 3)), jnp.float32
    )
    _, grad = PHI_GRAD(field, grid, q)
    auto = jax.jit(jax.vmap(jax.grad(potential, argnums=2), (None, None, 0)), static_argnums=1)(
        field, grid, q
    )
    np.testing.assert_allclose(
        np.asarray(grad), np.asarray(auto), rtol=1e-4, atol=float(field.floor)
    )


def test_square_aligns_from_30_20_5(square_200):
    # Inertial only (the overdamped model aligns too): one compilation per model and field
    # shape keeps this file fast.
    field, grid, p = square_200
    start = jnp.asarray(grid.to_index([30.0, 20.0, 5.0]), jnp.float32)
    s = INERTIAL(field, grid, p, start, MAX_STEPS_N)
    assert int(s.status) == CONVERGED and float(s.time_s) < float(p.t_max_s)
    outcome = OUTCOMES[int(classify(field, grid, s.q, s.energy, s.status, s.flat))]
    assert outcome == "aligned"
    x, y, twist = grid.to_pose(np.asarray(s.q))
    assert (
        abs(x) <= grid.um_per_px and abs(y) <= grid.um_per_px and abs(twist) <= grid.twist_step_deg
    )
    assert_energy_never_rises(s, float(field.floor))
    # the energy the other steppers report, at the end of the path: two float32 trilinear
    # interpolations of the same corners (the stepper's block, interpolate's lookups), each
    # within about ten eps(float32) of max|E|, so within the field's noise floor (32 eps
    # max|E|) of each other; rel=1e-6 (8 eps of |E| at the minimum) held on one machine
    assert float(s.energy) == pytest.approx(
        float(interpolate(field, grid, s.q)), rel=0, abs=float(field.floor)
    )


def test_no_contact_start_returns_immediately(square_200):
    field, grid, p = square_200
    start = jnp.asarray(grid.to_index([-238.0, 236.0, 0.0]), jnp.float32)  # chip far off the pad
    s = INERTIAL(field, grid, p, start, MAX_STEPS_N)
    assert int(s.step) == 0 and int(s.status) == CONVERGED and float(s.time_s) == 0.0
    np.testing.assert_array_equal(np.asarray(s.q), np.asarray(start))
    assert OUTCOMES[int(classify(field, grid, s.q, s.energy, s.status, s.flat))] == "no_contact"
