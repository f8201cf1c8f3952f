"""Numerical robustness (GitHub issue 8): hard inputs end cleanly, with finite numbers.

Every case below runs the steppers it names and checks, besides its own expectation,
that every output is finite (:func:`assert_finite`: path, energies, times, the JSON
report) and that the run ended (a valid outcome, at most ``max_steps`` steps).

Case list (the tests are named after the cases):

Plateaus and ties
  * test_plateau_four_pad_flat_part: starts on the flat part of the four-pad energy
    curve hold still (greedy, gradient; dynamics where the plateau is flat in every
    direction), or escape through twist where a combined move gains (docs/physics.md §6.4);
    float32 and float64 give the same outcome for every method.
  * test_tie_exact_diagonal_on_square: |x| = |y| on a square, a true tie between
    twisting either way: the documented rule, quadrant-mirrored paths, both dtypes.
  * test_tie_mirror_symmetric_pattern: a pattern with only a mirror symmetry gives
    mirror-image results from mirror-image starts, both dtypes.
Degenerate geometry
  * test_degenerate_chip_of_1_to_3_px, test_degenerate_chip_larger_than_pattern,
    test_degenerate_chip_much_smaller_than_pad, test_degenerate_pattern_touching_border
    (no wrap-around), test_degenerate_start_without_overlap,
    test_degenerate_graded_levels_1_and_0999, test_degenerate_nearly_equal_wettability
    (59.99 vs 60 degrees).
Extreme numbers
  * test_extreme_surface_tension, test_extreme_scale (1e-3 and 1e3 um/px),
    test_extreme_volume (dynamics), test_extreme_twist_near_180 (periodic wrap, chips
    of period 90, 180 and 360 degrees), test_extreme_fine_twist_step (0.01 degrees),
    test_extreme_max_steps_reached.
Dynamics
  * test_dynamics_stiff_meniscus, test_dynamics_nearly_zero_damping,
    test_dynamics_heavy_damping: finite, mechanical energy never grows, the run stops.
Properties (hypothesis)
  * test_property_landscape_matches_exact_overlap: random star polygons for chip and
    pattern; |A_raster - A_exact| <= 0.25 * (chip + pattern perimeter) * um_per_px.
  * test_property_steppers_terminate_finite: every stepper, a finite pose, a valid outcome.
  * test_property_energy_never_increases: along greedy and gradient paths.
  * test_property_batch_equals_single: vmap of greedy (record=False) == single runs.
Resources
  * test_resources_over_budget_fails_before_allocating: the documented InputError, in
    well under a second, with no landscape-sized allocation.
  * test_resources_4096_px_pattern_single_trajectory: 4096 x 4096 px four-pad, 4000 px
    chip, 1 degree twist grid: one greedy run in a fresh process, peak RSS < 8 GiB.

Bugs found by these cases are fixed where they arose; each has a test_regression_* test
named after it, at the end of this file.

Cost: each new grid shape compiles every stepper again (about 9 s for all four), so
most cases share a few 100 px scenes and pass their landscape to simulate; the file runs
in about 2 minutes on a 2-core machine.
"""

import json
import math
import os
import subprocess
import sys
import textwrap
import tracemalloc

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely
from hypothesis import given, settings, strategies as st
from shapely import affinity
from shapely.geometry import Polygon

from foundation import InputError
from patterns.geometry import Mask, defect, four_pad, mask_from_geometry, rectangle, square
from simulator.core import DEFAULT_MAX_STEPS, OUTCOMES
from simulator.landscape import build_landscape
from simulator.motion import (
    CONVERGED,
    EDGE,
    MAX_STEPS,
    REST_TOL_STEPS,
    DynamicsParams,
    classify,
    dynamics_jitted,
    field_and_grid,
    gradient_descent,
    greedy,
    inertial,
    is_stiff,
    on_plateau,
    overdamped,
    radius_of_gyration_px,
    simulate,
)
from simulator.physics import Liquid, Materials
from simulator.scene import Effects, Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("robustness")

DTYPES = ("float32", "float64")
METHODS = ("greedy", "gradient", "overdamped", "inertial")
#: Each new grid shape compiles every stepper anew (about 9 s for all four): scenes of
#: their own shape run these three; inertial runs where it shares a compilation.
QUICK = ("greedy", "gradient", "overdamped")
STATIC = ("grid", "max_steps", "record")
GREEDY = jax.jit(greedy, static_argnames=STATIC)
GRADIENT = jax.jit(gradient_descent, static_argnames=STATIC)
OVERDAMPED = jax.jit(overdamped, static_argnames=STATIC)
INERTIAL = jax.jit(inertial, static_argnames=STATIC)


def scene(pattern_geom, chip_geom, um_per_px=1.0, margin=None, **kw):
    margin = 10 * um_per_px if margin is None else margin
    return Scene(
        pattern=mask_from_geometry(pattern_geom, um_per_px, margin_um=margin),
        chip=mask_from_geometry(chip_geom, um_per_px),
        **kw,
    )


def assert_finite(t, max_steps=5000):
    """No NaN or infinity anywhere in a trajectory's outputs, and the run ended."""
    assert t.outcome in OUTCOMES
    assert 0 <= t.steps <= max_steps and len(t.path) == len(t.energy_J) == t.steps + 1
    assert np.all(np.isfinite(t.path)) and np.all(np.isfinite(t.energy_J))
    if t.t_s is not None:
        assert np.all(np.isfinite(t.t_s)) and math.isfinite(t.time_s)

    def walk(v):
        if isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, list | tuple):
            for x in v:
                walk(x)
        elif isinstance(v, float):
            assert math.isfinite(v)

    walk(t.to_json())
    json.dumps(t.to_json(), allow_nan=False)


def run_all(s, start, methods=METHODS, **kw):
    out = {}
    for m in methods:
        out[m] = simulate(s, start, method=m, **kw)
        assert_finite(out[m], kw.get("max_steps", 5000))
    return out


def mechanical(state):
    """Mechanical energy Phi + kinetic (J) over the recorded steps of a dynamics state."""
    n = int(state.step) + 1
    return np.asarray(state.path_potential[:n], float) + np.asarray(state.path_kinetic[:n], float)


def mechanical_tolerance(state, floor):
    """The floor, plus a few ulp of |Phi + kinetic|: the guard compares in the state's
    dtype, and the recorded terms summed here are rounded to it."""
    h = mechanical(state)
    return floor + 4 * np.finfo(np.asarray(state.path_potential).dtype).eps * np.abs(h).max()


def assert_dynamics_sane(state, floor):
    """Finite state, a stop code, and mechanical energy that never grows (beyond the floor)."""
    for name, v in state._asdict().items():
        a = np.asarray(v)
        if name.startswith("path"):
            a = a[: int(state.step) + 1]
        assert np.all(np.isfinite(a)), name
    assert int(state.status) in (CONVERGED, MAX_STEPS, EDGE)
    h = mechanical(state)
    tol = mechanical_tolerance(state, floor)
    assert np.all(np.diff(h) <= tol), f"rise {np.diff(h).max():.3g} J > floor {floor:.3g} J"
    excess = h - np.minimum.accumulate(h)
    assert np.all(excess <= tol), (
        f"{excess.max():.3g} J above the lowest at step {int(np.argmax(excess))} of {len(h)}"
    )


TWIST3 = TwistGrid(step_deg=3.0)
START = (40, -30, 12)  # a generic start (um, um, deg): aligns on the four-pad 100/10


def base(pattern_geom, dtype="float32", **kw):
    """A 100 px chip with a 3 degree twist grid on a pattern in the same 100 px box: all such
    scenes share one grid shape, so each stepper compiles once for them (per dtype)."""
    return scene(pattern_geom, square(100), dtype=dtype, twist=TWIST3, **kw)


def with_landscape(s):
    return s, build_landscape(s)


@pytest.fixture(scope="module")
def fp100():
    """Four-pad 100/10 px, 100 px chip: pads of 45 px; on the axes flat for 45 <= |x| <= 55.
    Line friction in water's range (0.03 Pa s): at the default, fitted to the 730 um chip's
    video, this 100 um chip under a 2 mm column of the default 20 nl relaxes its inertia in
    0.5 us against a creep of 0.1 s, and the implicit solver's float64 runs use up their
    5000 steps where float32's align (what the dtypes are compared on here is the plateau)."""
    return {
        dt: with_landscape(base(four_pad(100, 10), dt, line_friction_Pa_s=0.03)) for dt in DTYPES
    }


@pytest.fixture(scope="module")
def sq100():
    return {dt: with_landscape(base(square(100), dt)) for dt in DTYPES}


# ====================================================================== plateaus and ties
PLATEAU_STARTS = [(50, 0, 0), (50, 50, 0), (-50, 52, 0), (52, -48, 0)]
_PLATEAU_RUNS: dict = {}


def plateau_runs(fp100, start, dt):
    """The four methods' runs from ``start`` on ``fp100[dt]``, once per worker (the two
    dtypes compile every stepper anew: a test per dtype, and the comparison reuses them)."""
    if (start, dt) not in _PLATEAU_RUNS:
        s, ls = fp100[dt]
        _PLATEAU_RUNS[start, dt] = run_all(s, start, landscape=ls)
    return _PLATEAU_RUNS[start, dt]


# the module's xdist group (pytestmark): the comparison below finds the runs on its own worker
@pytest.mark.parametrize("dt", DTYPES)
@pytest.mark.parametrize("start", PLATEAU_STARTS)
def test_plateau_four_pad_flat_part(fp100, start, dt):
    r = plateau_runs(fp100, start, dt)
    if start == (52, -48, 0):
        # On both axes' flat parts a combined twist move gains area (docs/physics.md §6.4):
        # greedy escapes and aligns; the gradient there is exactly zero.
        assert r["greedy"].final == (0, 0, 0) and r["greedy"].outcome == "aligned"
        assert r["gradient"].steps == 0 and r["gradient"].outcome == "plateau"
        return
    # Every move changes the energy by less than the floor: greedy keeps the pose (tie
    # rule), the gradient is exactly zero. No step at all, no drift.
    for m in ("greedy", "gradient"):
        assert r[m].steps == 0 and r[m].final == start and r[m].outcome == "plateau", m
    if start == (50, 50, 0):  # flat in twist as well: the dynamics hold still too
        for m in ("overdamped", "inertial"):
            assert r[m].steps == 0 and r[m].final == start and r[m].outcome == "plateau", m


@pytest.mark.parametrize("start", PLATEAU_STARTS)
def test_plateau_four_pad_outcomes_agree_across_dtypes(fp100, start):
    runs = {dt: plateau_runs(fp100, start, dt) for dt in DTYPES}
    for m in METHODS:  # float32 and float64 agree on the outcome of every method
        assert runs["float32"][m].outcome == runs["float64"][m].outcome, m


def test_tie_exact_diagonal_on_square(sq100):
    # |x| = |y|: twisting either way ties exactly (C6). The rule (smallest move, then
    # (dt, dy, dx) from -1) takes dt = -1 in every quadrant: the four greedy paths are one
    # path mirrored in x and y with the *same* twist, in float32 and float64 alike.
    paths = {}
    for dt, (s, ls) in sq100.items():
        for sx in (1, -1):
            for sy in (1, -1):
                t = simulate(s, (30 * sx, 30 * sy, 0), landscape=ls)
                assert_finite(t)
                assert t.outcome == "aligned" and tuple(t.path[1]) == (29 * sx, 29 * sy, -3)
                paths[dt, sx, sy] = t.path
    for (_, sx, sy), p in paths.items():
        np.testing.assert_array_equal(p, paths["float32", 1, 1] * [sx, sy, 1])
    # The continuous steppers see exactly zero torque: they stay on the diagonal, untwisted.
    for dt, (s, ls) in sq100.items():
        tol = 1e-3 if dt == "float32" else 1e-9
        for m in ("gradient", "overdamped"):
            for sx, sy in ((1, 1), (-1, 1), (1, -1), (-1, -1)):
                t = simulate(s, (30 * sx, 30 * sy, 0), method=m, landscape=ls)
                assert_finite(t)
                assert t.outcome == "aligned" and np.abs(t.path[:, 2]).max() <= tol, (dt, m)
                np.testing.assert_allclose(np.abs(t.path[:, 0]), np.abs(t.path[:, 1]), atol=tol)


def test_tie_mirror_symmetric_pattern():
    # An inward defect in the middle of the right edge: mirror symmetric in the x axis
    # only. Mirror-image starts (x, -y, -twist) give mirror-image results.
    pat = defect(100, kind="inward", position="middle", height=30, width=60)
    for dt in DTYPES:
        s, ls = with_landscape(base(pat, dt))
        for start in [(30, 20, 6), (-25, 35, -9), (40, 3, 0)]:
            mirror = (start[0], -start[1], -start[2])
            a, b = simulate(s, start, landscape=ls), simulate(s, mirror, landscape=ls)
            assert_finite(a)
            assert_finite(b)
            np.testing.assert_array_equal(b.path, a.path * [1, -1, -1])
            g, h = (simulate(s, p, method="gradient", landscape=ls) for p in (start, mirror))
            assert_finite(g)
            assert_finite(h)
            np.testing.assert_allclose(
                h.final, np.multiply(g.final, [1, -1, -1]), atol=1e-3 if dt == "float32" else 1e-9
            )
            assert a.outcome == b.outcome and g.outcome == h.outcome


# ====================================================================== degenerate geometry
def test_degenerate_chip_of_1_to_3_px():
    # Pads of 27 px (four-pad 60/6): a 1-3 px chip on a pad is on a plateau, in the gap it
    # has no contact, straddling the pad's inner edge (x = 3 um) it moves fully onto it.
    for n in (1, 2, 3):
        s, ls = with_landscape(scene(four_pad(60, 6), square(n), twist=TWIST3))
        methods = QUICK if n == 1 else ("greedy",)
        for start, outcome in [
            ((15, 15, 6), "plateau"),
            ((0, 0, 0), "no_contact"),
            ((-20, 0, 0), "no_contact"),
        ]:
            for m, t in run_all(s, start, methods, landscape=ls).items():
                assert t.steps == 0 and t.outcome == outcome, (n, start, m)
        t = simulate(s, (3, 15, 0), landscape=ls)
        assert t.steps >= 1 and t.energy_J[-1] <= ls.energy.min() + ls.noise_floor_J
        # The same chip as a PNG (no geometry: bilinear rotation, whose area is off by up to
        # 12.5 % at this size, see simulator.landscape): still finite, still ends.
        png = Scene(pattern=s.pattern, chip=Mask(np.ones((n, n)), 1.0), twist=TWIST3)
        t = simulate(png, (3, 15, 0), landscape=build_landscape(png))
        assert_finite(t)
        assert t.steps >= 1


def test_degenerate_chip_larger_than_pattern():
    # A 150 px chip over a 60 px square: wherever the chip covers the whole pattern the
    # energy is flat at its minimum, -|P| Delta_gamma.
    s, ls = with_landscape(scene(square(60), square(150), twist=TWIST3))
    assert ls.overlap_um2(ls.energy.min()) == pytest.approx(3600, rel=1e-5)
    for m, t in run_all(s, (20, -10, 9), QUICK, landscape=ls).items():
        assert t.steps == 0 and t.outcome == "plateau", m
    for m, t in run_all(s, (70, 60, 0), QUICK, landscape=ls).items():
        assert t.steps >= 1 and t.energy_J[-1] <= ls.energy.min() + 2 * ls.noise_floor_J, m


@pytest.fixture(scope="module")
def tiny_chip():
    """A 4 px chip on four-pad 200/20 px: pads of 90 px, a 20 px gap."""
    return with_landscape(scene(four_pad(200, 20), square(4), twist=TWIST3))


def test_degenerate_chip_much_smaller_than_pad(tiny_chip):
    s, ls = tiny_chip
    for m, t in run_all(s, (50, 50, 12), QUICK, landscape=ls).items():
        assert t.steps == 0 and t.outcome == "plateau", m
    for m, t in run_all(
        s, (10, 50, 0), QUICK, landscape=ls
    ).items():  # half on the pad edge at x = 10
        assert t.steps >= 1 and t.energy_J[-1] < t.energy_J[0], m
    assert simulate(s, (10, 50, 0), landscape=ls).final == (12, 50, 0)  # fully on, in two moves


def test_degenerate_pattern_touching_border():
    # The pattern fills its image: no margin; beyond it lies substrate, never the far side.
    s, ls = with_landscape(
        Scene(
            pattern=Mask(np.ones((80, 120)), 1.0),
            chip=mask_from_geometry(square(40), 1.0),
            twist=TWIST3,
        )
    )
    for x, y, want in [
        (70, 0, 400),
        (-70, 0, 400),
        (0, 50, 400),
        (0, -50, 400),
        (75, 55, 25),
        (-85, 0, 0),
    ]:
        assert ls.overlap_um2(ls.energy_at(x, y, 0)) == pytest.approx(want, abs=1e-2), (x, y)
    for m, t in run_all(s, (70, 45, 3), QUICK, landscape=ls).items():
        assert t.energy_J[-1] <= ls.energy.min() + 2 * ls.noise_floor_J, m  # fully on the pattern
        assert np.abs(t.path[:, 0]).max() <= 70 and np.abs(t.path[:, 1]).max() <= 45


def test_degenerate_start_without_overlap(fp100, tiny_chip):
    for dt, (s, ls) in fp100.items():
        for start in [(200, 0, 0), (-150, 150, 30), (120, -101, -40)]:
            for m, t in run_all(s, start, landscape=ls).items():
                assert (
                    t.steps == 0
                    and t.outcome == "no_contact"
                    and abs(t.energy_J[0]) <= ls.noise_floor_J
                ), (dt, m)
    s, ls = tiny_chip
    for m, t in run_all(
        s, (0, 40, 0), QUICK, landscape=ls
    ).items():  # inside the gap, 8 px from either pad
        assert t.steps == 0 and t.outcome == "no_contact", m


def test_degenerate_nearly_equal_wettability(fp100):
    # Pad 59.99 degrees, substrate 60: Delta_gamma = -1.1e-5 N/m, 2400 times weaker than
    # 30/60. Only the energy scale changes (C14): the same greedy paths bit for bit and
    # gradient paths within round-off; the weak force makes the dynamics slow (t_max).
    for dt, (s, ls) in fp100.items():
        weak, weak_ls = with_landscape(
            s.replace(materials=Materials(pad_angle_deg=59.99, substrate_angle_deg=60.0))
        )
        assert -2e-5 < weak.materials.delta_gamma_N_m < 0
        for start in [START, (52, -48, 0), (50, 50, 0)]:
            for m in ("greedy", "gradient"):
                a, b = (
                    simulate(s, start, method=m, landscape=ls),
                    simulate(weak, start, method=m, landscape=weak_ls),
                )
                assert_finite(b)
                assert a.outcome == b.outcome, (dt, start, m)
                if m == "greedy":
                    np.testing.assert_array_equal(b.path, a.path)
                else:
                    np.testing.assert_allclose(b.final, a.final, atol=1e-3)
        if dt == "float32":
            for m in ("overdamped", "inertial"):
                t = simulate(weak, START, method=m, landscape=weak_ls)
                assert_finite(t)
                assert t.energy_J[-1] < t.energy_J[0]


def test_degenerate_graded_levels_1_and_0999():
    # Left half 1.0, right half 0.999: a force of 0.1 % of a pad edge's. A 50 px chip at the
    # boundary drifts onto the better half. float32 resolves the levels (one px of motion
    # changes the energy by 2e-5 of its scale, above its floor); moves that differ by less
    # than the float32 floor are ties there but not in float64, so the paths may part.
    d = np.zeros((120, 120))
    d[10:110, 10:60], d[10:110, 60:110] = 1.0, 0.999
    for dt in DTYPES:
        s, ls = with_landscape(
            Scene(
                pattern=Mask(d, 1.0),
                chip=mask_from_geometry(square(50), 1.0),
                twist=TWIST3,
                dtype=dt,
            )
        )
        methods = (
            ("greedy", "gradient", "overdamped") if dt == "float32" else ("greedy", "gradient")
        )
        for m, t in run_all(s, (10, 0, 0), methods, landscape=ls).items():
            assert t.energy_J[-1] <= t.energy_J[0] and t.final[0] <= 10, (dt, m)
        t = simulate(s, (10, 0, 0), landscape=ls)
        assert t.steps >= 1 and t.final[0] < 0
        if dt == "float32":
            assert t.final == (-25, 0, 0)  # fully on the 1.0 half


# ====================================================================== extreme numbers
@pytest.mark.parametrize("gamma", [1e-12, 1e6])
def test_extreme_surface_tension(fp100, gamma):
    # Delta_gamma only scales the energy (C14): the same greedy path bit for bit and the
    # same gradient path up to round-off, in both dtypes; the overdamped path is the same
    # with its time scaled by 1/gamma (the damping does not depend on it).
    for dt, (s, ls) in fp100.items():
        t_scene, t_ls = with_landscape(s.replace(materials=Materials(surface_tension_N_m=gamma)))
        for m in ("greedy", "gradient"):
            a, b = (
                simulate(s, START, method=m, landscape=ls),
                simulate(t_scene, START, method=m, landscape=t_ls),
            )
            assert_finite(b)
            assert a.outcome == b.outcome
            if m == "greedy":
                np.testing.assert_array_equal(b.path, a.path)
            else:
                np.testing.assert_allclose(b.final, a.final, atol=1e-3)
        if dt == "float32":
            ratio = gamma / s.materials.surface_tension_N_m
            pa = DynamicsParams.from_scene(s)
            pb = DynamicsParams.from_scene(t_scene, t_max_s=pa.t_max_s / ratio)
            a = simulate(s, START, "overdamped", landscape=ls, dynamics=pa)
            b = simulate(t_scene, START, "overdamped", landscape=t_ls, dynamics=pb)
            assert_finite(b)
            assert a.outcome == b.outcome
            # The dynamics stop within REST_TOL_STEPS of a grid step of the rest point (the
            # tail of the exponential approach is cut there), so paths that differ by
            # round-off end that close: 1/20 px, 1/20 twist step.
            tol = REST_TOL_STEPS * np.array([s.um_per_px, s.um_per_px, s.twist_axis.step_deg])
            assert np.all(np.abs(np.subtract(b.final, a.final)) <= tol)
            assert b.time_s * ratio == pytest.approx(a.time_s, rel=0.05)


@pytest.mark.parametrize("k", [1e-3, 1e3])
def test_extreme_scale(fp100, k):
    # Geometry, droplet volume (x k^3) and chip thickness (x k) scaled with the pixel size:
    # the same poses in px; for the overdamped model with the Couette damping (a calibration
    # given), time scales with k. (The damping's terms do not scale: the wedges' ln(h / a)
    # has a molecular a, the film's unsteady factor the chip's natural frequency.)
    s, ls = with_landscape(
        scene(
            four_pad(100 * k, 10 * k),
            square(100 * k),
            um_per_px=k,
            twist=TWIST3,
            liquid=Liquid(volume_nl=20 * k**3),
            chip_thickness_um=50 * k,
            damping_calibration=600.0,
        )
    )
    ref_s, ref_ls = fp100["float32"]
    ref_s = ref_s.replace(damping_calibration=600.0)
    for m in QUICK:
        a = simulate(ref_s, START, method=m, landscape=ref_ls)
        b = simulate(s, (START[0] * k, START[1] * k, START[2]), method=m, landscape=ls)
        assert_finite(b)
        assert a.outcome == b.outcome, m
        px = b.path / [k, k, 1]
        if m == "greedy":
            np.testing.assert_allclose(px, a.path, rtol=0, atol=1e-9)
        elif m in ("overdamped", "inertial"):  # within REST_TOL_STEPS of a grid step (see above)
            assert np.all(
                np.abs(px[-1] - a.path[-1])
                <= REST_TOL_STEPS * np.array([1.0, 1.0, ref_s.twist_axis.step_deg])
            )
        else:
            np.testing.assert_allclose(px[-1], a.path[-1], atol=1e-2)
        if m == "overdamped":
            assert b.time_s / k == pytest.approx(a.time_s, rel=0.05)


@pytest.mark.parametrize("volume_nl", [1e-6, 1e6])
def test_extreme_volume(fp100, volume_nl):
    # Under the 100 px chip: 1e-6 nl is a film of h = V/A = 1e-4 um, damping 2e7 times the
    # default 20 nl's: the chip creeps until t_max (the inertial run is stiff and goes to
    # the implicit solver). 1e6 nl is h = 1e8 um, almost no damping: the inertial chip
    # rings until max_steps. Both finite, both end, the energy lower than at the start.
    s, ls = fp100["float32"]
    s = s.replace(liquid=Liquid(volume_nl=volume_nl))
    for m in ("overdamped", "inertial"):
        t = simulate(s, START, method=m, landscape=ls)
        assert_finite(t)
        assert t.time_s is not None
        assert 0 < t.time_s <= 1.0 + 1e-6 and t.energy_J[-1] <= t.energy_J[0]


@pytest.fixture(scope="module")
def periods():
    """Chips of rotational period 90 (square), 180 (rectangle) and 360 (triangle) on their own shape."""
    tri = Polygon([(-50, -40), (60, -40), (-50, 50)])
    return {
        90: with_landscape(base(square(100))),
        180: with_landscape(scene(rectangle(120, 60), rectangle(120, 60), twist=TWIST3)),
        360: with_landscape(scene(tri, tri, twist=TWIST3)),
    }


def test_extreme_twist_near_180(periods):
    # 179 and -181 degrees are one pose (so are 180 and -180): the twist axis is periodic,
    # the paths equal modulo 360 degrees, whatever the chip's period.
    for period, (s, ls) in periods.items():
        assert ls.period_deg == period and ls.wrap
        methods = ("greedy", "gradient", "overdamped") if period == 90 else ("greedy", "gradient")
        for up, down in [(179.0, -181.0), (180.0, -180.0), (181.5, -178.5)]:
            for m in methods:
                a = simulate(s, (10, 5, up), method=m, landscape=ls)
                b = simulate(s, (10, 5, down), method=m, landscape=ls)
                assert_finite(a)
                assert_finite(b)
                assert a.outcome == b.outcome, (period, up, m)
                if m == "greedy":
                    np.testing.assert_array_equal(b.path, a.path - [0, 0, 360])
                elif m == "overdamped":  # within REST_TOL_STEPS of a grid step (see above)
                    tol = REST_TOL_STEPS * np.array(
                        [s.um_per_px, s.um_per_px, s.twist_axis.step_deg]
                    )
                    assert np.all(
                        np.abs(np.subtract(b.final, np.subtract(a.final, [0, 0, 360]))) <= tol
                    )
                else:
                    np.testing.assert_allclose(
                        b.final, np.subtract(a.final, [0, 0, 360]), atol=2e-2
                    )
                assert a.steps > 0
                if period < 360:  # the start is one period away from aligned
                    assert a.outcome == "aligned" and abs(a.final[2] - 180) <= 0.5, (period, up, m)


@pytest.fixture(scope="module")
def fine_twist():
    """Twist steps of 0.01 degrees over [-0.5, 0.5] (101 twists, a bounded axis)."""
    return with_landscape(
        scene(square(100), square(100), twist=TwistGrid(step_deg=0.01, min_deg=-0.5, max_deg=0.5))
    )


def test_extreme_fine_twist_step(fine_twist):
    s, ls = fine_twist
    assert len(ls.twist_deg) == 101 and not ls.wrap
    for start in [(3, -2, 0.3), (0, 0, 0.37), (0, 0, -0.5)]:
        for m, t in run_all(s, start, QUICK, landscape=ls).items():
            assert t.outcome == "aligned", (start, m)
            assert np.all(np.abs(t.path[:, 2]) <= 0.5 + 1e-9)
    t = simulate(s, (0, 0, 0.37), landscape=ls)
    assert t.steps == 37 and t.final == (0, 0, 0)  # one 0.01 degree step per move


def test_extreme_max_steps_reached(fp100):
    s, ls = fp100["float32"]
    # (inertial: see test_dynamics_nearly_zero_damping, which runs out of solver steps)
    for m, t in run_all(s, START, QUICK, landscape=ls, max_steps=3).items():
        assert t.outcome == "max_steps" and t.steps == 3 and len(t.path) == 4, m


# ====================================================================== dynamics
@pytest.fixture(scope="module")
def fp100_field(fp100):
    s, ls = fp100["float32"]
    return (s, ls) + field_and_grid(ls, radius_of_gyration_px(s))


def run_dynamics(s, field, grid, method, pose=START):
    """One dynamics run as simulate does it (the same compiled function: simulate's
    solver choice, stiff runs implicit), returning the full state."""
    p = DynamicsParams.from_scene(s)
    fn = dynamics_jitted(method, is_stiff(method, field, grid, p))
    return fn(
        field, grid, p, jnp.asarray(grid.to_index(np.asarray(pose, float))), DEFAULT_MAX_STEPS
    ), p


def test_dynamics_stiff_meniscus(fp100_field):
    # 1e-4 nl (a 0.01 um film) under a 1 um thick, 100 kg/m^3 chip: inertia relaxes in
    # about 1e-12 s while the chip creeps for seconds. The implicit solver takes it.
    s, ls, field, grid = fp100_field
    s = s.replace(liquid=Liquid(volume_nl=1e-4), chip_thickness_um=1.0, chip_density_kg_m3=100.0)
    for m in ("overdamped", "inertial"):
        state, p = run_dynamics(s, field, grid, m)
        assert_dynamics_sane(state, float(field.floor))
        assert float(state.time_s) <= p.t_max_s * (1 + 1e-6) and int(state.step) >= 1
        assert float(state.energy) < float(state.path_energy[0])  # it moved downhill
    assert is_stiff("inertial", field, grid, DynamicsParams.from_scene(s))


def test_dynamics_nearly_zero_damping(fp100_field):
    # damping_calibration 1e-6: the chip rings for a very long time; it ends at
    # max_steps (or t_max) with a finite state, its mechanical energy never rising.
    s, ls, field, grid = fp100_field
    s = s.replace(damping_calibration=1e-6)
    state, p = run_dynamics(s, field, grid, "inertial")
    assert_dynamics_sane(state, float(field.floor))
    assert int(state.status) == MAX_STEPS and float(state.kinetic) > 0
    t = simulate(s, START, method="inertial", landscape=ls)
    assert_finite(t)
    assert t.outcome == "max_steps"


def test_dynamics_heavy_damping(fp100_field):
    # damping_calibration 1e9: a creep of under 1 um/s; both models stop at t_max, energy falling.
    s, ls, field, grid = fp100_field
    s = s.replace(damping_calibration=1e9)
    for m in ("overdamped", "inertial"):
        state, p = run_dynamics(s, field, grid, m)
        assert_dynamics_sane(state, float(field.floor))
        assert int(state.status) == MAX_STEPS and float(state.time_s) == pytest.approx(
            p.t_max_s, rel=1e-5
        )
        assert float(state.energy) < float(state.path_energy[0])


# ====================================================================== properties
R_PATTERN, R_CHIP = 16, 10  # px at 1 um/px
RG = 5.0  # one twist metric (px) for every example: one Grid, so each stepper compiles once
MAXP = 300
GRID_STEPS = (11, 52, 52)  # largest index of the (12, 53, 53) grid of every example


@st.composite
def star(draw, radius):
    """A random star-shaped polygon about the origin, simple by construction: vertices at
    0, 90, 180 and 270 degrees at ``radius`` (so every example has one bounding box, one
    reach and one grid shape), and 1-6 more at random angles and radii."""
    extra = draw(
        st.lists(st.integers(1, 359).filter(lambda a: a % 90), min_size=1, max_size=6, unique=True)
    )
    pts = {0: (radius, 0.0), 90: (0.0, radius), 180: (-radius, 0.0), 270: (0.0, -radius)}
    for a in extra:
        r = draw(st.floats(0.25 * radius, radius))
        pts[a] = (r * math.cos(math.radians(a)), r * math.sin(math.radians(a)))
    return Polygon([pts[a] for a in sorted(pts)])


def random_scene(pattern, chip, dtype="float32", um_per_px=1.0):
    pat, chp = (
        mask_from_geometry(pattern, um_per_px, margin_um=2 * um_per_px),
        mask_from_geometry(chip, um_per_px),
    )
    return with_landscape(Scene(pattern=pat, chip=chp, twist=TwistGrid(step_deg=30.0), dtype=dtype))


def starts_in_grid(integer):
    axis = st.integers if integer else (lambda lo, hi: st.floats(lo, hi))
    return st.tuples(*(axis(0, n) for n in GRID_STEPS))


@settings(max_examples=50, deadline=None)
@given(
    pattern=star(R_PATTERN),
    chip=star(R_CHIP),
    um_per_px=st.sampled_from([0.5, 1.0, 2.0]),
    poses=st.lists(starts_in_grid(True), min_size=10, max_size=10),
)
def test_property_landscape_matches_exact_overlap(pattern, chip, um_per_px, poses):
    # Stated bound: |A_raster - A_exact| <= 0.25 * (chip + pattern perimeter) * um_per_px (um^2).
    pattern, chip = (
        affinity.scale(g, um_per_px, um_per_px, origin=(0, 0)) for g in (pattern, chip)
    )
    s, ls = random_scene(pattern, chip, "float64", um_per_px)
    idx = np.array(poses)
    x, y = ls.x_um[idx[:, 2] % len(ls.x_um)], ls.y_um[idx[:, 1] % len(ls.y_um)]
    t = ls.twist_deg[idx[:, 0] % len(ls.twist_deg)]
    raster = ls.overlap_um2(ls.energy_at(x, y, t))
    moved = [
        affinity.translate(affinity.rotate(chip, ti, origin=(0, 0)), xi, yi)
        for xi, yi, ti in zip(x, y, t, strict=True)
    ]
    exact = shapely.area(shapely.intersection(pattern, moved))
    assert np.abs(raster - exact).max() <= 0.25 * (pattern.length + chip.length) * s.um_per_px
    assert (
        np.all(np.isfinite(ls.energy))
        and ls.overlap_um2(ls.energy.min()) <= min(pattern.area, chip.area) + 1e-6
    )


def random_field(pattern, chip):
    s, ls = random_scene(pattern, chip)
    field, grid = field_and_grid(ls, RG)
    return s, field, grid


# One test per stepper (the same 20 examples for each: derandomized in the ci profile), so
# that no one test runs all four and the parallel workers share them.
@pytest.mark.parametrize("method", ["greedy", "gradient", "overdamped", "inertial"])
@settings(max_examples=20, deadline=None)
@given(pattern=star(R_PATTERN), chip=star(R_CHIP), start=starts_in_grid(False))
def test_property_steppers_terminate_finite(method, pattern, chip, start):
    s, field, grid = random_field(pattern, chip)
    p, q = DynamicsParams.from_scene(s), jnp.asarray(start)
    run = {
        "greedy": lambda: GREEDY(field, grid, jnp.asarray(np.round(start), jnp.int32), MAXP),
        "gradient": lambda: GRADIENT(field, grid, q, MAXP),
        "overdamped": lambda: OVERDAMPED(field, grid, p, q, MAXP),
        "inertial": lambda: INERTIAL(field, grid, p, q, MAXP),
    }[method]
    for m, r in [(method, run())]:
        pose = r.idx if m == "greedy" else r.q
        n = int(r.step)
        assert 0 <= n <= MAXP and int(r.status) in (CONVERGED, MAX_STEPS), (
            m
        )  # full landscape: no EDGE
        for a in (pose, r.energy, r.path[: n + 1], r.path_energy[: n + 1]):
            assert np.all(np.isfinite(np.asarray(a))), m
        flat = getattr(r, "flat", False) | on_plateau(
            field, grid, jnp.round(pose).astype(jnp.int32)
        )
        assert 0 <= int(classify(field, grid, pose, r.energy, r.status, flat)) < len(OUTCOMES)


@settings(max_examples=30, deadline=None)
@given(pattern=star(R_PATTERN), chip=star(R_CHIP), start=starts_in_grid(False))
def test_property_energy_never_increases(pattern, chip, start):
    _, field, grid = random_field(pattern, chip)
    for r in (
        GREEDY(field, grid, jnp.asarray(np.round(start), jnp.int32), MAXP),
        GRADIENT(field, grid, jnp.asarray(start), MAXP),
    ):
        e = np.asarray(r.path_energy[: int(r.step) + 1], float)
        assert np.all(np.isfinite(e)) and np.all(np.diff(e) < 0)


BATCH_GREEDY = jax.jit(
    jax.vmap(greedy, in_axes=(None, None, 0, None, None)), static_argnums=(1, 3, 4)
)


@settings(max_examples=20, deadline=None)
@given(
    pattern=star(R_PATTERN),
    chip=star(R_CHIP),
    starts=st.lists(starts_in_grid(True), min_size=6, max_size=6),
)
def test_property_batch_equals_single(pattern, chip, starts):
    _, field, grid = random_field(pattern, chip)
    batch = BATCH_GREEDY(field, grid, jnp.asarray(starts, jnp.int32), MAXP, False)
    for i, start in enumerate(starts):
        one = GREEDY(field, grid, jnp.asarray(start, jnp.int32), MAXP)
        for name in ("idx", "energy", "step", "status"):
            np.testing.assert_array_equal(
                np.asarray(getattr(batch, name)[i]), np.asarray(getattr(one, name)), err_msg=name
            )


# ====================================================================== resources
def big_scene(budget_mb):
    """A 4096 x 4096 px pattern (filled) and a 4000 px chip at 1 um/px."""
    return Scene(
        pattern=Mask(np.ones((4096, 4096)), 1.0),
        chip=mask_from_geometry(square(4000), 1.0),
        memory_budget_mb=budget_mb,
    )


def test_resources_over_budget_fails_before_allocating():
    s = big_scene(64)
    tracemalloc.start()
    try:
        with pytest.raises(
            InputError,
            match=r"needs about [\d,]+ MB .* memory budget is 64 MB; use a coarser scale",
        ):
            build_landscape(s)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # How fast it is refused (target < 0.5 s): benchmarks/refusals.py.
    # Nothing landscape-sized: only masks of the inputs' size (the pattern is 128 MiB).
    assert peak < s.pattern.data.nbytes / 2, f"{peak / 2**20:.0f} MiB allocated before refusing"


BIG_RUN = """
import json, time
t0 = time.perf_counter()
import simulator
from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.scene import Scene
from simulator.motion import simulate
s = Scene(pattern=mask_from_geometry(four_pad(4096, 96), 1.0), chip=mask_from_geometry(square(4000), 1.0))
t = simulate(s, (90, -70, 1), method="greedy", max_steps=100)
print(json.dumps({"shape": s.pattern.shape, "final": t.final, "steps": t.steps, "outcome": t.outcome,
                  "finite": bool((abs(t.path) < 1e300).all() and (abs(t.energy_J) < 1e300).all()),
                  "planes": t.cost.planes, "seconds": time.perf_counter() - t0,
                  "peak_rss_mb": [int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")][0] / 1024}))
"""


def test_resources_4096_px_pattern_single_trajectory():
    # A 4096 um four-pad (gap 96 um) at 1 um/px with a 4000 um chip, 1 degree twist grid:
    # the full landscape would be 90 x 9755 x 9755 poses (32 GiB in float32); the run builds
    # a box of translations and a band of 7 twists. Fresh process: its own peak RSS.
    # The chip's edges lie on the pads for |x|, |y| <= 48 um: greedy stops at that corner.
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(BIG_RUN)],
        capture_output=True,
        text=True,
        timeout=300,
        env=os.environ | {"PYTHONWARNINGS": "ignore"},
    )
    assert out.returncode == 0, out.stderr[-2000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["shape"] == [4096, 4096] and r["finite"]
    assert r["final"] == [48.0, -48.0, 0.0] and r["steps"] == 42 and r["outcome"] == "plateau"
    assert r["planes"] <= 12
    assert r["peak_rss_mb"] < 8 * 1024, r  # this process's own peak (VmHWM)
    # How long it takes (target < 60 s): benchmarks/refusals.py.
    print(f"4096 px trajectory: {r['seconds']:.1f} s, peak RSS {r['peak_rss_mb']:.0f} MiB")


# ====================================================================== regressions
def test_regression_over_budget_request_transformed_the_pattern_first():
    # build_landscape built the Correlator (the pattern's whole spectrum, about 1.5 GB and
    # 5 s for the 4096 px scene) before comparing with the budget, and left the stored
    # spectrum out of the estimate. Sizes are now computed first.
    s = Scene(
        pattern=Mask(np.ones((2048, 2048)), 1.0),
        chip=mask_from_geometry(square(1900), 1.0),
        memory_budget_mb=16,
    )
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="memory budget is 16 MB"):
            build_landscape(s)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20


def test_regression_gradient_flat_test_underflowed_in_float32(fp100):
    # gradient_descent called a pose flat when sqrt(sum(g^2)) == 0: with g in J per px,
    # g^2 underflows float32 below 1e-19 J/px (1e-12 N/m here), so every start stopped at
    # once with outcome "plateau".
    s, ls = fp100["float32"]
    weak, weak_ls = with_landscape(s.replace(materials=Materials(surface_tension_N_m=1e-12)))
    a, b = (
        simulate(s, START, method="gradient", landscape=ls),
        simulate(weak, START, method="gradient", landscape=weak_ls),
    )
    assert b.steps > 0 and b.outcome == a.outcome == "aligned"


def test_regression_float32_energy_underflow_read_as_no_contact(fp100):
    # At 1e-30 N/m the float32 energies are subnormal, which XLA flushes to zero: every
    # pose looked like no contact. Such scenes (and ones that would overflow) are refused.
    s, _ = fp100["float32"]
    for gamma in (1e-30, 1e45):
        with pytest.raises(InputError, match="outside what float32 holds.*use dtype float64"):
            build_landscape(s.replace(materials=Materials(surface_tension_N_m=gamma)))
    s64, _ = fp100["float64"]
    tiny = s64.replace(materials=Materials(surface_tension_N_m=1e-30))
    t = simulate(tiny, START, landscape=build_landscape(tiny))
    assert_finite(t)
    assert t.outcome == "aligned"


def test_regression_dynamics_coefficients_underflowed_in_float32(fp100):
    # c s^2 (damping times the pixel size squared) was formed in float32 and underflowed to
    # 0 for a nearly undamped chip: tau = 0, an infinite end time, and the overdamped run
    # returned at once with max_steps. The coefficients are now formed in float64.
    s, ls = fp100["float32"]
    t = simulate(s.replace(damping_calibration=1e-30), START, method="overdamped", landscape=ls)
    assert_finite(t)
    assert t.time_s is not None
    assert t.steps > 0 and t.outcome == "aligned" and 0 < t.time_s < 1e-20


def test_regression_twist_free_scene_start_twist_gave_infinite_energy():
    # A scene without twist has one twist plane (0 degrees); a start twist of 7 degrees
    # sat beyond it, on a wall: every method reported an infinite energy.
    s = scene(four_pad(60, 6), square(60), effects=Effects(twist=False))
    with pytest.raises(InputError, match="start twist 7 deg: this scene has one twist"):
        simulate(s, (10, 5, 7))
    assert_finite(simulate(s, (10, 5, 0)))


def test_regression_start_past_bounded_twist_end_gave_infinite_energy(fine_twist):
    # A start within half a twist step past the end of a bounded twist axis is accepted
    # (greedy rounds it onto the axis); gradient and dynamics started beyond the end, on
    # the wall (+inf). Every stepper now starts at the end.
    s, ls = fine_twist
    for m, t in run_all(s, (3, -2, 0.504), QUICK, landscape=ls).items():
        assert t.path[0][2] == pytest.approx(0.5) and t.outcome == "aligned", m


def test_regression_gradient_saw_no_torque_at_twist_range_end(fine_twist):
    # The central difference at the end of a bounded twist axis reached the wall, and was
    # dropped as infinite: no torque at all, the run stopped as "plateau" at once.
    s, ls = fine_twist
    t = simulate(s, (0, 0, 0.5), method="gradient", landscape=ls)
    assert t.steps > 0 and t.outcome == "aligned"


def test_regression_dynamics_reported_infinite_energy_at_a_wall(fine_twist):
    # At (30, 20) the twist coupling (C6) turns the chip counter-clockwise, into the end of
    # the twist range: the run stops there (EDGE) and reported E = +inf past the wall.
    s, ls = fine_twist
    for m in ("overdamped",):
        t = simulate(s, (30, 20, 0.49), method=m, landscape=ls)
        assert_finite(t)
        assert t.final[2] >= 0.49


def test_regression_mechanical_energy_crept_up_in_long_runs(fp100_field):
    # Each accepted step could raise Phi + kinetic by up to the floor, measured from the
    # previous step: over 4700 steps of a nearly undamped chip it ended 3 floors above its
    # lowest value. The guard now measures rises from the lowest value accepted so far.
    s, ls, field, grid = fp100_field
    state, _ = run_dynamics(s.replace(damping_calibration=1e-6), field, grid, "inertial")
    h = mechanical(state)
    assert len(h) > 1000 and np.all(
        h - np.minimum.accumulate(h) <= mechanical_tolerance(state, float(field.floor))
    )


def test_regression_twist_step_from_axis_difference(fine_twist):
    # The twist step was twist_deg[1] - twist_deg[0] = 0.010000000000000009 for -0.5 + 0.01 k,
    # so 50 steps from -0.5 ended at 4.4e-16 degrees instead of 0.
    s, ls = fine_twist
    assert ls.twist_step_deg == 0.01
    assert simulate(s, (0, 0, 0.37), landscape=ls).final == (0, 0, 0)


def test_regression_box_parity_cut_the_reach(fp100):
    # A box reaching the end of the translation reach with an odd span was shrunk on that
    # side, which marked it cut: beyond it a wall (+inf) instead of no contact (0), so a
    # start beyond the reach (the lazy-box path of simulate) reported an infinite energy.
    s, _ = fp100["float32"]
    for m in ("greedy", "gradient"):
        t = simulate(s, (180, -170, 40), method=m)  # no landscape given: boxes as needed
        assert_finite(t)
        assert t.outcome == "no_contact" and t.steps == 0


def test_regression_huge_start_overflowed_grid_indices(fp100):
    # simulate took any finite start: x = 1e12 um wrapped around int32 (greedy reported
    # x = -2147483769 um), a twist of 1e20 degrees turned to NaN. Starts are now bounded
    # by 2**24 px (float32 holds every whole pixel up to there) and 3600 degrees.
    s, ls = fp100["float32"]
    for start in [(1e12, 0, 0), (60, 40, 1e20)]:
        with pytest.raises(
            InputError, match=r"out of range: \|x\| and \|y\| must be at most 1.67772e\+07 um"
        ):
            simulate(s, start)
    for start, outcome in [((1.6e7, -1e7, 0), "no_contact"), ((40, -30, -3600), "aligned")]:
        for m in ("greedy", "gradient"):
            t = simulate(s, start, method=m, landscape=ls)
            assert_finite(t)
            assert t.outcome == outcome and t.path[0][0] == start[0], m
