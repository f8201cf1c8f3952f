"""Contact-angle hysteresis as friction, per pose (docs/physics.md §4, §5.3), and the damping
from its terms.

Known answers: a block on a linear spring ``E = k x^2 / 2`` with Coulomb friction P: started
within the stick band ``|x| <= P / k`` it does not move (every method); beyond it the
overdamped block follows ``x* + (x0 - x*) exp(-k t / c)`` (x* = P / k) and the underdamped
one the damped oscillator about x* for half a period, then sticks where its speed first
vanishes, inside the band. The friction is not regularized (the overdamped velocity is the
force beyond the pinning; the inertial step is Moreau-Jean's): halving the step's tolerance
moves the end by less than the tolerance allows. The pinning per pose against its NumPy
reference, with the footprint state's wet bits. The damping's terms against their closed
forms. Tolerances: from the solvers' tolerances and step counts, and float32's round-off
on the index (eps times the largest index).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from shapely.geometry import box

from patterns.geometry import Mask, mask_from_geometry
from simulator.core import OUTCOMES
from simulator.landscape import PoseGrid
from simulator.motion import (
    MOREAU_TOL,
    DynamicsParams,
    Relay,
    dissipation,
    field_and_grid,
    inertial,
    make_field,
    overdamped,
    pin_at,
    pin_lines,
    simulate,
    stepper,
)
from simulator.physics import (
    Chip,
    Liquid,
    Materials,
    couette_damping,
    couette_torsional_damping,
    dissipation_terms,
    line_dissipation_integrals_um,
    parallelepiped_stiffness,
    sliding_pinning_at,
    stokes_layer_factor,
    wedge_friction_Pa_s,
)
from simulator.scene import Effects, Scene, TwistGrid

pytestmark = pytest.mark.xdist_group("friction")

STATIC = ("grid", "max_steps", "record")
OVERDAMPED = jax.jit(overdamped, static_argnames=STATIC)
INERTIAL = jax.jit(inertial, static_argnames=STATIC)
N_STEPS = 2000

# The spring of tests/test_dynamics.py: a 200 um SU-8 chip on 0.5 nl (h = 12.5 um).
K0 = parallelepiped_stiffness(12.5, 200.0)  # N/m
MASS = Chip(200.0, 200.0).mass_kg  # kg
S_UM = 0.5  # um per px
NX, NY, XC = 201, 9, 100
X_STAR_UM = 10.0  # P / k: the stick band's half-width
P_N = K0 * X_STAR_UM * 1e-6  # N
EPS32 = float(np.finfo(np.float32).eps)


def spring_field(pin_N=P_N):
    x = (np.arange(NX) - XC) * S_UM * 1e-6
    e = np.broadcast_to(0.5 * K0 * x * x, (1, NY, NX)).astype(np.float32)
    floor = 32 * EPS32 * np.abs(e).max()
    grid = PoseGrid.uniform(
        (1, NY, NX),
        wrap=False,
        cut=((False, False), (True, True), (True, True)),
        um_per_px=S_UM,
        twist_step_deg=1.0,
        x_first_px=-XC,
        y_first_px=-(NY // 2),
        period_deg=90.0,
        rg_px=100.0,
    )
    # pinning work over one grid step (J): P times the step, on x and y
    w = pin_N * S_UM * 1e-6
    return make_field(e, grid, floor, [0, NY // 2, XC], pin=(0.0, w, w)), grid


def params(c, t_max_s=2e-2):
    return DynamicsParams(
        mass_kg=MASS, inertia_kg_m2=1e-17, damping_N_s_m=c, rot_damping_N_m_s=1e-12, t_max_s=t_max_s
    )


def start(x_um):
    return jnp.asarray([0.0, NY // 2, XC + x_um / S_UM], jnp.float32)


def path_um(s):
    n = int(s.step) + 1
    return np.asarray(s.path_t[:n], float), (np.asarray(s.path[:n, 2], float) - XC) * S_UM


def test_within_the_static_pinning_no_method_moves():
    field, grid = spring_field()
    for method in ("greedy", "gradient", "overdamped", "inertial"):
        run = jax.jit(stepper(method), static_argnames=STATIC)
        p = params(1e-3) if method in ("overdamped", "inertial") else None
        for x0 in (8.0, -9.5):  # |k x0| < P: the force stays within the pinning
            s = run(field, grid, p, start(x0), N_STEPS)
            assert np.array_equal(np.asarray(s.q), np.asarray(start(x0))), (method, x0)
        # just beyond the band, every method moves
        s = run(field, grid, p, start(12.0), N_STEPS)
        assert float(s.q[2]) < float(start(12.0)[2]) - 0.5, method


def test_overdamped_block_with_coulomb_friction_on_a_spring():
    field, grid = spring_field()
    c = 1e-3  # N s/m
    x0 = 40.0
    s = OVERDAMPED(field, grid, params(c, 0.05), start(x0), N_STEPS)
    t, x = path_um(s)
    exact = X_STAR_UM + (x0 - X_STAR_UM) * np.exp(-K0 * t / c)
    # local error per step at most atol + rtol |d| grid steps (default tolerances, float32),
    # summed over the steps (the flow contracts, so this bounds the global error), plus round-off
    rtol = math.sqrt(EPS32) / 30
    bound_px = len(t) * rtol * (1 + x0 / S_UM) + 4 * EPS32 * (XC + x0 / S_UM)
    assert np.abs(x - exact).max() <= bound_px * S_UM
    # it stops on the band's edge, where the force beyond the pinning is what the run resolves
    assert int(s.status) == 1 and x[-1] > X_STAR_UM
    assert x[-1] - X_STAR_UM < 0.05 * (x0 - X_STAR_UM)


@pytest.mark.parametrize("tol", [MOREAU_TOL, MOREAU_TOL / 2])
def test_inertial_block_sticks_where_its_speed_first_vanishes(tol):
    field, grid = spring_field()
    zeta = 0.2
    c = 2 * zeta * math.sqrt(K0 * MASS)
    x0 = 40.0
    s = INERTIAL(field, grid, params(c), start(x0), N_STEPS, rtol=tol, atol=tol)
    t, x = path_um(s)
    w = math.sqrt(K0 / MASS)
    wd = w * math.sqrt(1 - zeta**2)
    t_stop = math.pi / wd
    x_stop = X_STAR_UM - (x0 - X_STAR_UM) * math.exp(-zeta * w * t_stop)
    assert abs(x_stop) < X_STAR_UM  # inside the band: it sticks there
    moving = t < t_stop
    exact = X_STAR_UM + (x0 - X_STAR_UM) * np.exp(-zeta * w * t[moving]) * (
        np.cos(wd * t[moving]) + zeta * w / wd * np.sin(wd * t[moving])
    )
    # first order: the local error is held to tol (grid steps, relative to the displacement);
    # summed over the steps
    bound_um = len(t) * tol * (1 + x0 / S_UM) * S_UM
    assert np.abs(x[moving] - exact).max() <= bound_um
    assert int(s.status) == 1  # stuck: CONVERGED
    assert abs(x[-1] - x_stop) <= bound_um
    # the time it sticks: the step that ended with zero speed, within one step of t_stop
    dt_max = float(np.diff(t).max())
    assert abs(float(s.time_s) - t_stop) <= dt_max + bound_um / (w * (x0 - X_STAR_UM))


def test_halving_the_moreau_tolerance_keeps_the_end():
    field, grid = spring_field()
    c = 2 * 0.2 * math.sqrt(K0 * MASS)
    ends = []
    for tol in (MOREAU_TOL, MOREAU_TOL / 2):
        s = INERTIAL(field, grid, params(c), start(40.0), N_STEPS, rtol=tol, atol=tol)
        ends.append((float(s.q[2]), float(s.time_s), int(s.step)))
    (q1, t1, n1), (q2, t2, n2) = ends
    # the end pose moves by less than the looser run's accumulated tolerance
    assert abs(q1 - q2) <= n1 * MOREAU_TOL * (1 + 40.0 / S_UM)
    # the stick time by less than the looser run's longest step
    assert abs(t1 - t2) <= t1 / n1 * 4


def test_overdamped_limit_equals_inertial_at_high_viscosity():
    field, grid = spring_field()
    zeta = 50.0
    c = 2 * zeta * math.sqrt(K0 * MASS)
    od = OVERDAMPED(field, grid, params(c, 0.5), start(40.0), N_STEPS)
    tw = INERTIAL(field, grid, params(c, 0.5), start(40.0), N_STEPS)
    t_od, x_od = path_um(od)
    t_in, x_in = path_um(tw)
    # the inertial block lags the overdamped one by about m / c; the paths differ by at most
    # the overdamped speed times that lag, (x0 - x*) k m / c^2 = (x0 - x*) / (4 zeta^2)
    x_od_at = np.interp(t_in, t_od, x_od)
    lag = (40.0 - X_STAR_UM) / (4 * zeta**2)
    bound = lag + len(t_in) * MOREAU_TOL * (1 + 40.0 / S_UM) * S_UM
    assert np.abs(x_in - x_od_at).max() <= bound
    assert abs(x_in[-1] - x_od[-1]) <= bound


# ----------------------------------------------------------------- per pose and footprint
def _two_pad_scene(hysteresis=True, window=(31.0, 50.0)):
    """A 200 um chip over two 150 x 300 um pads 20 um apart, free lines, h = 10 um."""
    from shapely.ops import unary_union

    pads = unary_union([box(-160, -150, -10, 150), box(10, -150, 160, 150)])
    pat = mask_from_geometry(pads, 2.0, margin_um=40)
    return Scene.from_inputs(
        pat,
        chip_size_um=200.0,
        materials=Materials(pad_receding_deg=window[0], pad_advancing_deg=window[1]),
        twist=TwistGrid(1.0, -6.0, 6.0),
        effects=Effects(twist=True, meniscus=True, hysteresis=hysteresis),
        liquid=Liquid(height_um=10.0, pinned=False),
        window_um=64,
        dtype="float64",
    )


def test_pinning_changes_with_the_pose_and_the_footprint():
    from simulator.landscape import build_landscape

    sc = _two_pad_scene()
    ls = build_landscape(sc)
    field, grid = field_and_grid(ls, lines=pin_lines(sc, ls.energy.dtype))
    scale = np.array([math.radians(grid.twist_step_deg), 2e-6, 2e-6])
    poses = [(0.0, 0.0, 0.0), (30.0, 0.0, 0.0), (-20.0, 25.0, 0.0), (10.0, -5.0, 3.0)]
    z = np.zeros((1, 1, 1, 1), np.uint8)
    seen = set()
    for wet in (None, (True, False), (False, True), (False, False)):
        fields = [field]
        if wet is not None:
            bits = np.packbits(np.asarray(wet, bool), bitorder="little")
            relay = Relay(jnp.asarray(z), jnp.asarray(z), jnp.asarray(bits))
            # the state's pattern made once as the relay is set, and (a relay set without
            # it) the pads' labels read at each pose: the same pinning
            f = field._replace(relay=relay)
            assert f.relay is not None and f.relay.lines_pattern is not None
            fields = [f, dataclasses.replace(field, relay=relay)]
        for f in fields:
            for pose in poses:
                ref = np.asarray(sliding_pinning_at(sc, pose, wet)) * scale
                got = np.asarray(pin_at(f, grid, jnp.asarray(grid.to_index(np.asarray(pose)))))
                # float64 sums of about 1,600 elements: round-off far below 1e-9 of the value
                assert np.allclose(got, ref, rtol=1e-9, atol=1e-30), (wet, pose)
                seen.add(tuple(np.round(ref / scale, 15)))
    # the pinning changes with the pose and with which pads are wet; none wet, none pins
    assert len(seen) >= 8
    assert sliding_pinning_at(sc, (0, 0, 0), (False, False)) == (0.0, 0.0, 0.0)
    full = sliding_pinning_at(sc, (0, 0, 0))
    half = sliding_pinning_at(sc, (0, 0, 0), (True, False))
    # one pad of two: half the lines along x (the chip is centred between the pads)
    assert half[2] == pytest.approx(full[2] / 2, rel=0.02)


@pytest.fixture(scope="module")
def two_pads():
    from simulator.landscape import build_landscape

    sc = _two_pad_scene()
    return sc, build_landscape(sc)


def test_batch_equals_single_runs_with_per_pose_pinning(two_pads):
    from simulator.batch import run_batch

    sc, ls = two_pads
    # beyond the floor (|x| > 160 - 100 - d_p = 42.7 um, |y| > 32.7 um): the pads' edges pull
    starts = np.array([[52.0, 5.0, 2.0], [-50.0, -40.0, -3.0], [10.0, 45.0, 0.0]])
    for method in ("greedy", "gradient", "overdamped", "inertial"):
        r = run_batch(sc, starts, method, landscape=ls)
        for i, st in enumerate(starts):
            one = simulate(sc, tuple(st), method=method, landscape=ls)
            # the same code, vmapped or not: XLA may order the sums (the pinning's over the
            # outline among them) differently, which the dynamics' step control carries
            # along, within the position error it allows per step (float64: 5e-10 grid steps,
            # relative to the displacement) times its steps; the steppers to round-off
            moved = float(np.abs(np.subtract(one.final, st)).max()) / 2.0  # px
            tol_px = (
                one.steps * 5e-10 * (1 + moved) if method in ("overdamped", "inertial") else 1e-9
            )
            if method == "inertial":
                tol_px = one.steps * MOREAU_TOL * (1 + moved)
            assert np.allclose(r.final[i], one.final, rtol=0, atol=tol_px * 2.0), (method, i)
            assert OUTCOMES[r.outcome[i]] == one.outcome, (method, i)


# ----------------------------------------------------------------- dissipation
def test_stokes_layer_factor_against_its_closed_form():
    nu = 1e-6
    h = 37.5
    for omega in (1.0, 1e2, 1e3, 9.35e3, 1e5, 1e7):
        x = h * 1e-6 * math.sqrt(omega / (2 * nu))
        real_form = x * (math.sinh(2 * x) + math.sin(2 * x)) / (math.cosh(2 * x) - math.cos(2 * x))
        assert stokes_layer_factor(omega, h, nu) == pytest.approx(real_form, rel=1e-12)
    # the limits: quasi-steady 1 + (omega h^2 / nu)^2 / 45; thick film h / delta
    w = 10.0
    assert stokes_layer_factor(w, h, nu) - 1 == pytest.approx(
        (w * (h * 1e-6) ** 2 / nu) ** 2 / 45, rel=1e-3
    )
    w = 1e9
    assert stokes_layer_factor(w, h, nu) == pytest.approx(h * 1e-6 / math.sqrt(2 * nu / w))
    assert stokes_layer_factor(0.0, h, nu) == 1.0


def test_line_integrals_of_a_rectangle_and_its_image():
    w, h = 200.0, 100.0
    geo = mask_from_geometry(box(-w / 2, -h / 2, w / 2, h / 2), 1.0)
    lx, ly, lt = line_dissipation_integrals_um(geo)
    assert lx == pytest.approx(2 * h, rel=1e-9) and ly == pytest.approx(2 * w, rel=1e-9)
    assert lt == pytest.approx((w**3 + h**3) / 6, rel=1e-9)
    img = Mask(geo.data, 1.0)
    assert np.allclose(line_dissipation_integrals_um(img), (lx, ly, lt), rtol=1e-9)


def test_each_damping_term_against_its_closed_form():
    L, hf, mu, rho, gamma = 730.0, 37.5, 1e-3, 1000.0, 0.0728
    A, J = L * L, L**4 / 6
    m = Chip(L, L).mass_kg
    zeta = 0.05
    d = dissipation_terms(
        viscosity_Pa_s=mu,
        density_kg_m3=rho,
        surface_tension_N_m=gamma,
        area_um2=A,
        polar_moment_um4=J,
        h_um=hf,
        mass_kg=m,
        line_um=(2 * L, 2 * L, L**3 / 3),
        across_um=2 * L,
        line_angle_deg=60.0,
        line_friction_Pa_s=zeta,
    )
    t = d["terms"]
    assert t["couette"][0] == pytest.approx(mu * A * 1e-12 / (hf * 1e-6))
    assert t["couette"][1] == pytest.approx(mu * J * 1e-24 / (hf * 1e-6))
    omega = math.sqrt(gamma * 2 * L / hf / m)  # the sheared block's 2 gamma L / h
    f = stokes_layer_factor(omega, hf, mu / rho)
    assert d["omega_rad_s"] == pytest.approx(omega)
    assert t["stokes"][0] == pytest.approx(t["couette"][0] * (f - 1))
    assert 1.5 < f < 4  # of order one at the chip's natural frequency (about 1.5 kHz)
    zw = 3 * mu * math.log(hf * 1e-6 / 1e-9) / math.radians(60.0)
    assert wedge_friction_Pa_s(mu, 60.0, hf) == pytest.approx(zw)
    assert t["wedge"][0] == pytest.approx(zw * 2 * L * 1e-6)
    assert t["wedge"][1] == pytest.approx(zw * L**3 / 3 * 1e-18)
    assert t["line"][0] == pytest.approx(zeta * 2 * L * 1e-6)
    assert t["line"][1] == pytest.approx(zeta * L**3 / 3 * 1e-18)
    assert d["damping_N_s_m"] == pytest.approx(sum(v[0] for v in t.values()))
    # DynamicsParams: the terms by default, the Couette override as before
    liq = Liquid(volume_nl=20.0)
    p = DynamicsParams.from_physics(Chip(L, L), liq, line_friction_Pa_s=zeta)
    assert p.damping_N_s_m == pytest.approx(d["damping_N_s_m"], rel=1e-3)
    k = DynamicsParams.from_physics(Chip(L, L), liq, calibration=600.0)
    h = liq.meniscus_height_um(A)
    assert k.damping_N_s_m == pytest.approx(600 * couette_damping(1e-3, A, h))
    assert k.rot_damping_N_m_s == pytest.approx(
        600 * couette_torsional_damping(1e-3, A * 2 * L * L / 12, h)
    )
    # a pinned film: no moving line, film terms only
    pinned = DynamicsParams.from_physics(Chip(L, L), liq, moving_lines=False)
    film = dissipation_terms(
        viscosity_Pa_s=liq.viscosity_Pa_s,
        density_kg_m3=liq.density_kg_m3,
        surface_tension_N_m=liq.surface_tension_N_m,
        area_um2=A,
        polar_moment_um4=A * 2 * L * L / 12,
        h_um=h,
        mass_kg=m,
        line_um=None,
        across_um=2 * L,
        line_angle_deg=60.0,
    )
    assert pinned.damping_N_s_m == pytest.approx(film["damping_N_s_m"], rel=1e-12)
    assert film["terms"]["wedge"] == film["terms"]["line"] == (0.0, 0.0)


def test_a_scenes_terms_are_the_damping_its_dynamics_take():
    # free lines: the film's terms and the outline's moving lines; pinned: the film's alone
    for scene in (
        _two_pad_scene(),
        _two_pad_scene(hysteresis=False).replace(liquid=Liquid(height_um=10.0, pinned=True)),
    ):
        d = dissipation(scene)
        p = DynamicsParams.from_scene(scene)
        assert p.damping_N_s_m == d["damping_N_s_m"]
        assert p.rot_damping_N_m_s == d["rot_damping_N_m_s"]
        assert d["damping_N_s_m"] == pytest.approx(sum(v[0] for v in d["terms"].values()))
        moving = d["terms"]["line"][0] > 0
        assert moving == (not scene.liquid.pinned)
