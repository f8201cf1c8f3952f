"""The footprint state against Surface Evolver's bench protocol (validation/FOURPAD_BENCH.md:
the liquid on all four pads, the chip placed at x = 400-600 um and at (300, -300) um, a free
and a held far-pad contact line) and the curved wall's reaches (simulator.physics._reach,
validation/FOURPAD.md "The reach of a curved wall"). The stored CSVs are read; no Evolver.

The two variants bound what hysteresis can do: the free line (no hysteresis) drains the far
pads, so the free bound is the state of a freely receding line at that x (the outward
continuation, validation/evolver_fourpad_levels.csv); the held line (a receding angle near 0)
keeps them wet. A bound is used only where Surface Evolver settles it: the free one where the
two finest levels agree to 5 %, the held one (level 1 at these poses) where its envelope and
finite-difference forces agree to 10 % (FOURPAD_BENCH.md's "usable" rows).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from simulator.landscape import build_footprint_planes
from simulator.physics import Liquid, Materials, arc_wall, curved_reaches, free_bridge
from simulator.scene import Effects, Scene

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / "patterns" / "library"
VALIDATION = ROOT / "validation"
GAMMA_SE = 0.072  # N/m, the Evolver runs' surface tension
L, V = 730.0, 2.0e7  # um, um^3 (20 nl)


def _rows(name: str) -> list[dict[str, str]]:
    with (VALIDATION / name).open(newline="") as f:
        return list(csv.DictReader(f))


BENCH = _rows("evolver_fourpad_bench.csv")
LEVELS = _rows("evolver_fourpad_levels.csv")


def _outward(gap: int, x: float) -> list[dict[str, str]]:
    """The outward continuation's rows at (x, 0), by level."""
    rows = [
        r
        for r in LEVELS
        if r["path"] == f"x_730_{gap}" and float(r["x_um"]) == x and float(r["y_um"]) == 0
    ]
    return sorted(rows, key=lambda r: int(r["level"]))


def free_bound_N(gap: int, x: float) -> float | None:
    """The free line's force magnitude (N) at (x, 0) where the two finest levels agree to 5 %
    (the smaller of their envelope and finite-difference forces), else None."""
    rows = _outward(gap, x)
    if len(rows) < 2:
        return None
    f1, f0 = abs(float(rows[-1]["force_x_N"])), abs(float(rows[-2]["force_x_N"]))
    if abs(f1 - f0) > 0.05 * f1:
        return None
    return min(abs(float(r[k])) for r in rows[-2:] for k in ("force_x_N", "force_x_fd_N"))


def held_bound_N(gap: int, x: float, y: float) -> float | None:
    """The held far line's force magnitude (N) along x at (x, y), at the finest stored level
    where its envelope and finite-difference forces agree to 10 % (the larger of the two),
    else None."""
    rows = [
        r
        for r in BENCH
        if r["variant"] == "held"
        and float(r["gap_um"]) == gap
        and float(r["x_um"]) == x
        and float(r["y_um"]) == y
    ]
    for r in sorted(rows, key=lambda r: -int(r["level"])):
        f, fd = abs(float(r["force_x_N"])), abs(float(r["force_x_fd_N"]))
        if abs(f - fd) <= 0.10 * fd:
            return max(f, fd)
    return None


def fourpad(gap: int, receding: float | None) -> Scene:
    return Scene.from_inputs(
        LIB / f"four_pad_730_{gap}.png",
        chip_size_um=730,
        resolution_um=2.0,
        effects=Effects(twist=False, meniscus=True, hysteresis=receding is not None),
        materials=Materials()
        if receding is None
        else Materials(pad_receding_deg=receding, pad_advancing_deg=35.0),
        liquid=Liquid(volume_nl=20.0, dispense="pattern"),
    )


_PLANES: dict = {}


def planes(gap: int, receding: float | None):
    """The pads' planes of the bench case (one twist, 2 um/px), built once per module."""
    key = (gap, receding)
    if key not in _PLANES:
        s = fourpad(gap, receding)
        _PLANES[key] = (s, build_footprint_planes(s, twists=[0.0]))
    return _PLANES[key]


def released(gap: int, receding: float | None, x: float, y: float):
    """The state and the force (N, at Surface Evolver's surface tension) of a chip released
    at (x, y) onto the pattern-dispensed footprint (all four pads wet)."""
    s, fp = planes(gap, receding)
    wet = fp.next_state(np.ones(fp.n_pads, bool), (x, y, 0.0))
    fx, fy = fp.landscape(wet).force_at(x, y, 0.0)
    scale = GAMMA_SE / s.materials.surface_tension_N_m
    far = [k for k in range(fp.n_pads) if fp.pad_centre_um[k][0] < 0]
    return wet, far, float(np.asarray(fx)) * scale, float(np.asarray(fy)) * scale


# ------------------------------------------------------------------ the stored runs
def test_bench_free_runs_are_draining_and_the_held_runs_keep_the_far_pads():
    free = [r for r in BENCH if r["variant"] == "free"]
    held = [r for r in BENCH if r["variant"] == "held"]
    # level 1 at every pose of both gaps (x = 400-600 um and (300, -300) um), free and held
    poses = {(r["gap_um"], r["x_um"], r["y_um"]) for r in free if r["level"] == "1"}
    assert len(free) == len(poses) == 12 and len(held) == 14
    assert poses == {(r["gap_um"], r["x_um"], r["y_um"]) for r in held if r["level"] == "1"}
    for r in free:  # the line left the far pads' outer edge, and the energy still fell
        assert float(r["far_wet_frac"]) < 0.6 and float(r["xmin_y0_um"]) > -365 + 100, r
    falling = [float(r["pre_last_dE"]) for r in free if r["pre_last_dE"]]  # where recorded
    assert len(falling) == 11 and max(falling) < -100  # gamma um^2 per round, still draining
    for r in held:  # held at the outer edge: every far pad stays wet
        assert float(r["far_wet_frac"]) == pytest.approx(1.0) and r["far_pads_wet"] == "True"


# ------------------------------------------------------------------ the far pads drain
@pytest.mark.parametrize("gap", [50, 100])
def test_without_hysteresis_the_far_pads_dry_where_evolver_lets_them_go(gap):
    # Released onto all four wet pads without hysteresis, the model's far pads stay wet or dry
    # as the state of Surface Evolver's freely receding line at the same x (every stored
    # level): on 730/50 the inner corners stay wet at 400 um and the pads are dry from 450 um;
    # on 730/100 dry from 400 um. Beyond 500 um (no stored outward rows, the free bench runs
    # still draining) the model's far pads are dry.
    xs = sorted({float(r["x_um"]) for r in BENCH if float(r["y_um"]) == 0})
    assert xs == [400.0, 450.0, 500.0, 550.0, 600.0]
    for x in xs:
        wet, far, _, _ = released(gap, None, x, 0.0)
        rows = _outward(gap, x)
        if rows:
            se = {r["left_pads_wetted"] for r in rows}
            assert len(se) == 1, (x, se)  # the levels agree
            assert bool(wet[far].any()) == (se == {"True"}), x
        else:
            assert not wet[far].any(), x


# ------------------------------------------------------------------ relaxed without hysteresis
LONG = [r for r in BENCH if r["variant"] == "free-long" and r["level"] == "1"]
#: um: a free vertex further below the substrate is a touch-down the Evolver run cannot make
#: (validation/evolver_fourpad_bench.py, TOUCH_TOL_UM): that row is not a valid state
TOUCH_TOL_UM = 1.0


def _pose(r: dict[str, str]) -> tuple[int, float, float]:
    return int(float(r["gap_um"])), float(r["x_um"]), float(r["y_um"])


def _valid(r: dict[str, str]) -> bool:
    return float(r["z_min_free_um"]) >= -TOUCH_TOL_UM


def test_relaxed_free_runs_keep_the_far_pads_wet_where_the_model_does():
    # Surface Evolver's bench protocol without hysteresis, relaxed to equilibrium (free-long:
    # the pre-relaxation ran until a round lowered E by less than 1 gamma um^2, 132-297
    # rounds, at all twelve poses of both gaps). Six of them are valid states: in the other
    # six the free surface passed 1.4-52 um through the substrate, where a real liquid would
    # have touched down. In the six, the far pads keep more than 1 % of their region wet
    # exactly where the model's released state keeps them wet: 730/50 at 400 um (3.1 %, the
    # inner corners) and on the diagonal (17.7 %); dry at 730/50 450 and 500 um and 730/100
    # 550 and 600 um (a residue of 0.04 % on 730/100).
    assert sorted(_pose(r) for r in LONG) == sorted(
        (g, x, y)
        for g in (50, 100)
        for x, y in [(400, 0), (450, 0), (500, 0), (550, 0), (600, 0), (300, -300)]
    )
    valid = [r for r in LONG if _valid(r)]
    assert {_pose(r) for r in valid} == {
        (50, 400.0, 0.0),
        (50, 450.0, 0.0),
        (50, 500.0, 0.0),
        (50, 300.0, -300.0),
        (100, 550.0, 0.0),
        (100, 600.0, 0.0),
    }
    wet_se = set()
    for r in LONG:
        assert abs(float(r["pre_last_dE"])) < 1.0 and r["level"] == "1", r  # relaxed
    for r in valid:
        g, x, y = _pose(r)
        wet, far, _, _ = released(g, None, x, y)
        assert bool(wet[far].any()) == (float(r["far_wet_frac"]) > 0.01), (g, x, y)
        if float(r["far_wet_frac"]) > 0.01:
            wet_se.add((g, x, y))
    assert wet_se == {(50, 400.0, 0.0), (50, 300.0, -300.0)}


def test_relaxed_free_runs_force_within_10_percent_but_at_three_poses():
    # The valid runs' force on the chip along x (their envelope and finite-difference forces
    # agree to 3 %) against the model's released without hysteresis: within 10 % at 730/50
    # 450 um (+8.4 %), 500 um (-3.4 %) and on the diagonal (+0.1 %, and F_y -6 %); the
    # misses, stated here: 730/50 at 400 um, +25 % (the model's far pads pull the whole
    # interior force, Surface Evolver's 3 % left wet do not: the dip of
    # validation/FOURPAD.md), and 730/100 at 550 and 600 um, -16 % (Surface Evolver pulls
    # 19.8 uN, above the interior force |dgamma| (L - g) = 16.6 uN that the model and the
    # outward continuation give).
    misses, checked = set(), 0
    for r in LONG:
        if not _valid(r):
            continue
        g, x, y = _pose(r)
        f, fd = abs(float(r["force_x_N"])), abs(float(r["force_x_fd_N"]))
        assert abs(f - fd) <= 0.03 * fd, (g, x, y)
        _, _, fx, _ = released(g, None, x, y)
        checked += 1
        if abs(abs(fx) - f) > 0.10 * f:
            misses.add((g, x, y))
    assert checked == 6
    assert misses == {(50, 400.0, 0.0), (100, 550.0, 0.0), (100, 600.0, 0.0)}
    # two of them refined once more (level 2): the force moves by at most 1 %, the 19.8 uN of
    # 730/100 at 550 um included, so the misses are not the mesh's
    fine = [r for r in BENCH if r["variant"] == "free-long" and r["level"] == "2"]
    assert {_pose(r) for r in fine} == {(50, 450.0, 0.0), (100, 550.0, 0.0)}
    coarse = {_pose(r): r for r in LONG}
    for r in fine:
        f1, f2 = (abs(float(q["force_x_N"])) for q in (coarse[_pose(r)], r))
        assert f2 == pytest.approx(f1, rel=0.01) and _valid(r), _pose(r)


# ------------------------------------------------------------------ between the bounds
BENCH_POSES = [
    pytest.param(50, 400.0, 0.0, None),
    pytest.param(50, 400.0, 0.0, 10.0),
    pytest.param(50, 450.0, 0.0, None),
    pytest.param(50, 450.0, 0.0, 10.0),
    pytest.param(50, 500.0, 0.0, None),
    pytest.param(50, 500.0, 0.0, 10.0),
    pytest.param(50, 300.0, -300.0, None),
    pytest.param(100, 400.0, 0.0, None),
    pytest.param(
        100,
        400.0,
        0.0,
        10.0,
        marks=pytest.mark.xfail(
            strict=True,
            reason="the bridged far pads pull the full interior force, 16.6 uN at gamma = 0.072 "
            "N/m, above the held bound 15.1 uN (the held liquid's dome lowers the chip to 18 um)",
        ),
    ),
    pytest.param(100, 450.0, 0.0, 10.0),
    pytest.param(100, 450.0, 0.0, None),
    pytest.param(100, 500.0, 0.0, None),
    pytest.param(100, 300.0, -300.0, 10.0),
]


@pytest.mark.parametrize("gap,x,y,receding", BENCH_POSES)
def test_released_force_lies_between_the_free_and_the_held_bounds(gap, x, y, receding):
    # |F_x| of the chip released at (x, y): at least the free line's (where converged) and at
    # most the held line's (where usable); at least one of the two is there at every pose.
    lo = free_bound_N(gap, x) if y == 0 else None
    hi = held_bound_N(gap, x, y)
    assert lo is not None or hi is not None
    wet, far, fx, fy = released(gap, receding, x, y)
    assert fx <= 0  # never away from the centre (0 on the flat part: 730/100 at 400 um)
    if lo is not None:
        assert -fx >= lo, (-fx, lo)
    if hi is not None:
        assert -fx <= hi, (-fx, hi)
    if y != 0:  # the diagonal pose: the mirror about y = -x
        assert fy == pytest.approx(-fx, rel=1e-3)


# ------------------------------------------------------------------ the curved wall's reaches
def _arc(h: float, kappa: float, deg: float):
    """arc_wall's wall where the test's angle and curvature have one (asserted)."""
    w = arc_wall(h, kappa, deg)
    assert w is not None
    return w


def test_an_arc_of_vanishing_curvature_is_the_flat_wall_and_an_arc_is_a_circle():
    h = 20.0
    w = _arc(h, 0.0, 30.0)
    assert w.reach_um == pytest.approx(h / math.tan(math.radians(30)), rel=1e-12)
    assert w.area_um2 == pytest.approx(0.5 * h * w.reach_um, rel=1e-12)
    # a small curvature: the series' next term, c = h cot(t) + kappa h^2 / (2 sin^3 t)
    k = 1e-5
    t = math.radians(30)
    c1 = h / math.tan(t) + k * h**2 / (2 * math.sin(t) ** 3)
    assert _arc(h, k, 30.0).reach_um == pytest.approx(c1, rel=1e-6)
    # a finite curvature: both ends on the circle of radius 1/kappa whose centre lies on the
    # normal at the foot; the area is the quadrature of x(z) along the arc
    from scipy.integrate import quad

    k = 0.004
    w = _arc(h, k, 60.0)
    t, p, R = math.radians(60), math.radians(w.top_deg), 1 / k
    centre = (-w.reach_um + R * math.sin(t), -R * math.cos(t))  # inside the liquid
    assert math.dist(centre, (-w.reach_um, 0.0)) == pytest.approx(R, rel=1e-12)
    assert math.dist(centre, (0.0, h)) == pytest.approx(R, rel=1e-12)
    x_of = lambda psi: (math.sin(psi) - math.sin(p)) / k  # noqa: E731 - distance beyond the edge
    area, _ = quad(lambda psi: x_of(psi) * math.sin(psi) / k, p, t)
    assert w.area_um2 == pytest.approx(area, rel=1e-10)
    assert arc_wall(h, 0.01, 30.0) is None  # cos 30 + kappa h > 1: no wall reaches the edge
    # a bridged pad's walls pull gamma (cos(phi_p) - cos(phi_s)) per unit length of edge: the
    # overlap model's cos(theta_p) - cos(theta_s) at any pressure (the arc makes no dip)
    for k in (0.0, 0.002, 0.0035):
        top = {t: math.radians(_arc(h, k, t).top_deg) for t in (30.0, 60.0)}
        pull = math.cos(top[30.0]) - math.cos(top[60.0])
        assert pull == pytest.approx(math.cos(math.radians(30)) - 0.5, rel=1e-12)


def test_free_bridge_conserves_the_volume_and_balances_the_chip():
    b = free_bridge(V, L * L, [(4 * L, 60.0)])
    w = _arc(b.h_um, b.curvature_per_um, 60.0)
    assert L * L * b.h_um + 4 * L * w.area_um2 == pytest.approx(V, rel=1e-10)
    assert b.curvature_per_um * L * L == pytest.approx(4 * L * math.sin(math.radians(w.top_deg)))
    assert b.h_um < V / (L * L)  # the bulging walls hold some of the liquid


def _se_row(gap: int, x: float) -> dict[str, str]:
    return _outward(gap, x)[-1]


@pytest.mark.parametrize("gap", [50, 100])
def test_the_curved_wall_gives_evolvers_height_pressure_and_substrate_reach(gap):
    # Aligned (x = 0), every wall stands on the 60 deg substrate beyond the pattern's outer
    # edge: the bridge from the volume alone against Surface Evolver's finest level. The
    # corners, left out, are of order c / L = 3 % of the perimeter.
    r = _se_row(gap, 0.0)
    b = free_bridge(V, L * L, [(4 * L, 60.0)])
    assert b.h_um == pytest.approx(float(r["chip_height_um"]), rel=0.035)
    assert b.curvature_per_um == pytest.approx(float(r["pressure_per_um"]), rel=0.035)
    reach_se = float(r["cl_xmax_y0_um"]) - L / 2
    d_s, _ = curved_reaches(V, L, L - gap, 30.0, 60.0)
    assert d_s == pytest.approx(reach_se, abs=1.0)  # the flat wall: h cot 60 = 20.2 um
    assert abs(b.h_um / math.tan(math.radians(60)) - reach_se) > 4.0


def _drying_bracket(path: str) -> tuple[float, float]:
    """The last pose with the far (left) pads wet and the first with them dry along an
    outward path, each pose at its finest stored level."""
    finest: dict[float, dict[str, str]] = {}
    for r in LEVELS:
        if r["path"] == path and float(r["y_um"]) == 0:
            x = float(r["x_um"])
            if x not in finest or int(r["level"]) > int(finest[x]["level"]):
                finest[x] = r
    rows = list(finest.values())
    last_wet = max(float(r["x_um"]) for r in rows if r["left_pads_wetted"] == "True")
    first_dry = min(float(r["x_um"]) for r in rows if r["left_pads_wetted"] == "False")
    return last_wet, first_dry


@pytest.mark.parametrize("side,gap,volume", [(730, 50, V), (730, 100, V), (200, 20, 5.0e5)])
def test_the_curved_wall_dries_the_far_pads_within_10_um_of_evolver(side, gap, volume):
    # Outward from alignment with the far pads wet (Surface Evolver's outward path): they dry
    # between the last wet and the first dry pose. The curved wall's reach at the pads' 30 deg,
    # with one side of the chip on the pad, puts the drying bias (L - g) / 2 + d_r within
    # 10 um of that bracket: 431.8, 408.3 and 125.6 um against 420-430, 390-400 and 115-120 um
    # (the flat wall's h cot(30 deg) with h = V / A: 406, 382 and 111.7 um).
    last_wet, first_dry = _drying_bracket(f"x_{side}_{gap}")
    assert 0 < first_dry - last_wet <= 10.0
    _, d_r = curved_reaches(volume, side, side - gap, 30.0, 60.0)
    x_dry = (side - gap) / 2 + d_r
    assert last_wet - 10 <= x_dry <= first_dry + 10, (x_dry, last_wet, first_dry)


@pytest.mark.parametrize("gap", [50, 100])
def test_the_curved_substrate_reach_snaps_onto_the_far_pads_where_evolver_does(gap):
    # Coming inward with the far pads dry (validation/evolver_fourpad_inward.csv, level 1):
    # they are first wet between two poses 10 um apart; the curved d_s (24.6 um, every edge
    # on the substrate) puts the snap, (L - g) / 2 + d_s, within 10 um of them.
    inward = [
        r
        for r in _rows("evolver_fourpad_inward.csv")
        if r["path"] == f"x_730_{gap}_inward" and r["level"] == "1"
    ]
    wet_in = max(float(r["x_um"]) for r in inward if r["left_pads_wetted"] == "True")
    dry_in = min(float(r["x_um"]) for r in inward if r["left_pads_wetted"] == "False")
    assert 0 < dry_in - wet_in <= 10.0
    d_s, _ = curved_reaches(V, L, L - gap, 30.0, 60.0)
    assert wet_in - 10 <= (L - gap) / 2 + d_s <= dry_in + 10


def test_below_the_bridges_flattest_wall_no_receding_wall_exists():
    # Below 27 deg (3 deg under the pads' 30) the receding wall's arc would turn horizontal
    # below the chip (cos(theta_r) + kappa h > 1): no reach (the held runs' dome instead).
    # Above it the reach grows fast as the angle falls.
    _, r30 = curved_reaches(V, L, L - 50, 30.0, 60.0)
    _, r29 = curved_reaches(V, L, L - 50, 30.0, 60.0, receding_deg=29.0)
    _, r10 = curved_reaches(V, L, L - 50, 30.0, 60.0, receding_deg=10.0)
    assert r29 is not None and r30 is not None
    assert r29 > r30 > 0 and r10 is None
