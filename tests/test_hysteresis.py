"""Contact-angle hysteresis (simulator.physics): pinning forces from the contact lines that
slide over a pad (none in a pinned scene), the stopping rule of every stepper, zero width =
today's rule exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import box

from foundation import InputError
from patterns.geometry import Mask, mask_from_geometry
from simulator.motion import simulate
from simulator.physics import (
    Liquid,
    Materials,
    contact_line_integrals_um,
    line_reach_um,
    parse_window,
    pin_per_index,
    pinning,
    pinning_force_per_length,
    sliding_pinning,
    sliding_shares,
)
from simulator.scene import Effects, Scene

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("hysteresis")

GAMMA = 0.0728


def _scene(h=20.0, window=(31.0, 50.0), hysteresis=True, L=200.0, s=2.0, pinned=True, pad=None):
    """A square chip of side L over a square pad of side ``pad`` (default L), meniscus height h
    (the stateless footprint: the stopping rule by itself, without the pad's wet state)."""
    pad = L if pad is None else pad
    pat = mask_from_geometry(box(-pad / 2, -pad / 2, pad / 2, pad / 2), s, margin_um=4)
    mat = (
        Materials(pad_receding_deg=window[0], pad_advancing_deg=window[1])
        if window
        else Materials()
    )
    return Scene.from_inputs(
        pat,
        chip_size_um=L,
        materials=mat,
        effects=Effects(twist=False, meniscus=True, hysteresis=hysteresis),
        liquid=Liquid(height_um=h, pinned=pinned, dispense="none"),
        window_um=80,
        dtype="float64",
    )


def _dcos(w):
    return math.cos(math.radians(w[0])) - math.cos(math.radians(w[1]))


def test_pinning_forces_of_a_rectangle_and_a_square():
    f = pinning_force_per_length(GAMMA, 31, 50)
    assert f == pytest.approx(GAMMA * (math.cos(math.radians(31)) - math.cos(math.radians(50))))
    a, b = 200.0, 100.0
    geo = Scene.from_inputs(
        mask_from_geometry(box(-a / 2, -b / 2, a / 2, b / 2), 1.0),
        chip_size_um=(a, b),
        materials=Materials(pad_receding_deg=31, pad_advancing_deg=50),
        effects=Effects(hysteresis=True),
    )
    pt, py, px = pinning(geo)
    # Furmidge: P = f * (width across the motion). Torque: f/2 * oint |(z x r) . n| ds; the
    # a-edges give 2 int |x| dx = a^2 / 2, the b-edges b^2 / 2.
    assert px == pytest.approx(f * b * 1e-6) and py == pytest.approx(f * a * 1e-6)
    assert pt == pytest.approx(f / 2 * (a * a + b * b) / 2 * 1e-12, rel=1e-9)
    # Square of side L: P_t = f L^2 / 2 (each edge: 2 * int_0^{L/2} s ds = L^2 / 4; four edges, times f / 2).
    L = 200.0
    sq = Scene.from_inputs(
        mask_from_geometry(box(-L / 2, -L / 2, L / 2, L / 2), 1.0),
        chip_size_um=L,
        materials=Materials(pad_receding_deg=31, pad_advancing_deg=50),
        effects=Effects(hysteresis=True),
    )
    assert pinning(sq)[0] == pytest.approx(f * L**2 / 2 * 1e-12)
    # A chip image gives the same integrals as its exact geometry (pixel-aligned square).
    img = Mask(mask_from_geometry(box(-L / 2, -L / 2, L / 2, L / 2), 1.0).data, 1.0)
    assert np.allclose(
        contact_line_integrals_um(img), contact_line_integrals_um(sq.chip), rtol=1e-9
    )


def test_window_parsing_and_refusals():
    assert parse_window("31:50") == (31.0, 50.0)
    for bad in ("50", "50:31", "a:b", "-1:20", "10:190"):
        with pytest.raises(InputError):
            parse_window(bad)
    with pytest.raises(InputError, match="receding and advancing"):
        Materials(pad_receding_deg=30)
    with pytest.raises(InputError, match="hysteresis needs"):
        _scene(window=None)


def test_which_contact_lines_slide():
    mat = Materials(pad_receding_deg=31, pad_advancing_deg=50)
    # Pinned: every line is held by an edge (the chip's, the pad's), whatever the pad.
    for pad in (200.0, 300.0):
        sc = _scene(pinned=True, pad=pad)
        assert sliding_shares(sc) == (0.0, 0.0, 0.0) and sliding_pinning(sc) == (0.0, 0.0, 0.0)
        assert pin_per_index(sc, 2.0, 1.0) == (0.0, 0.0, 0.0) and any(pinning(sc))
    # Free lines, same-size pad: the lines stand on the substrate at d_s = h cot 60 deg beyond the
    # chip (d_p = h cot 30 deg = 34.6 um beyond it is substrate): nothing slides over the pad.
    free = _scene(pinned=False)
    assert line_reach_um(free) == pytest.approx(20.0 / math.tan(math.radians(30)))
    assert sliding_shares(free) == (0.0, 0.0, 0.0)
    # Free lines on a pad 50 um wider than the chip on each side (> d_p = 17.3 um at h = 10): all slide.
    inside = _scene(h=10.0, pinned=False, pad=300.0)
    assert sliding_shares(inside) == (1.0, 1.0, 1.0) and sliding_pinning(inside) == pinning(inside)
    # ... but at h = 40 um d_p = 69 um lies beyond that pad's edge: the edge holds every line.
    assert sliding_shares(_scene(h=40.0, pinned=False, pad=300.0)) == (0.0, 0.0, 0.0)
    # The overlap model (no meniscus): the line at the chip's edge, which lies on the pad's edge
    # at rest; half of it moves over the pad whichever way the chip goes.
    L = 200.0
    ov = Scene.from_inputs(
        mask_from_geometry(box(-L / 2, -L / 2, L / 2, L / 2), 1.0, margin_um=4),
        chip_size_um=L,
        materials=mat,
        effects=Effects(hysteresis=True),
    )
    assert np.allclose(sliding_shares(ov), 0.5, atol=0.01)
    # A chip image gives the shares of its exact geometry.
    img = ov.replace(
        chip=Mask(mask_from_geometry(box(-L / 2, -L / 2, L / 2, L / 2), 1.0).data, 1.0)
    )
    assert np.allclose(sliding_shares(img), sliding_shares(ov), atol=0.01)


@pytest.mark.parametrize("pinned", [True, False])
@pytest.mark.parametrize("method", ["greedy", "gradient", "overdamped", "inertial"])
def test_zero_width_is_todays_stopping_rule_exactly(method, pinned):
    # Free lines on the wider pad: every line slides, so a zero window is the only thing that
    # makes the pinning zero there.
    kw = {"pinned": True} if pinned else {"pinned": False, "h": 10.0, "pad": 300.0}
    start = (30.0, -12.0, 0.0) if pinned else (48.0, -3.0, 0.0)
    off = simulate(_scene(hysteresis=False, **kw), start, method=method)
    zero = simulate(_scene(window=(40.0, 40.0), **kw), start, method=method)
    assert (
        np.array_equal(off.path, zero.path)
        and off.outcome == zero.outcome
        and off.steps == zero.steps
    )


@pytest.mark.parametrize("method", ["greedy", "gradient", "overdamped", "inertial"])
def test_a_pinned_scene_is_not_held_by_the_pads_hysteresis(method):
    # Pinned lines are held at the chip's and the pad's edges: the walls tilt, no line slides over
    # the pad, so its hysteresis holds nothing. Before, this chip stopped h (cos r - cos a) / 2 =
    # 2.1 um short (h = 20 um, 31:50); now its path is the one without hysteresis.
    for h in (10.0, 20.0):
        for w in ((40.0, 50.0), (31.0, 50.0)):
            t = simulate(_scene(h=h, window=w), (30.0, 0.0, 0.0), method=method)
            ref = simulate(_scene(h=h, hysteresis=False), (30.0, 0.0, 0.0), method=method)
            assert t.outcome == "aligned"
            assert np.array_equal(t.path, ref.path)
            assert abs(t.final[0]) < 0.5 and abs(t.final[1]) < 0.05
            assert abs(t.final[0]) < h * _dcos(w) / 2 / 4


@pytest.mark.parametrize("method", ["gradient", "overdamped"])
def test_pinned_square_200_at_0p9_nl_stops_at_the_minimum(method):
    # The case: a 200 um chip on square_200.png, 0.9 nl (h = 22.5 um), pinned, pads 31:50,
    # from (40, 40) um and 2 deg. Before: (2.6, 2.5) um and 0.86 deg short (gradient).
    from simulator.scene import TwistGrid

    sc = Scene.from_inputs(
        "patterns/library/square_200.png",
        chip_size_um=200,
        resolution_um=2.0,
        materials=Materials(pad_receding_deg=31, pad_advancing_deg=50),
        twist=TwistGrid(0.5, -5, 5),
        effects=Effects(twist=True, meniscus=True, hysteresis=True),
        liquid=Liquid(volume_nl=0.9, pinned=True),
        window_um=60,
        dtype="float64",
    )
    assert sc.meniscus_height_um == pytest.approx(22.5)
    t = simulate(sc, (40.0, 40.0, 2.0), method=method)
    assert t.outcome == "aligned"
    assert abs(t.final[0]) < 0.5 and abs(t.final[1]) < 0.5 and abs(t.final[2]) < 0.3


@pytest.mark.parametrize("method", ["gradient", "overdamped"])
def test_free_lines_on_the_pad_stop_where_the_force_falls_to_the_pinning_force(method):
    # Free lines, a 200 um chip on a 300 um pad (pads 30 deg, substrate 60 deg): at rest every line
    # stands on the pad d_p = h cot 30 beyond the chip and slides. The chip floats for
    # |x| <= 50 - d_p; from x = 48 the pad edge comes within d_p of the chip's right edge and pulls
    # with |Delta_gamma| L f(u) (u = 50 - x, the wall profile), against the pinning of the lines
    # that slide at that pose: the right-hand line stands d_p beyond the chip, past the pad's edge,
    # held there, so only the left-hand one slides, f_pin L / 2 (per pose; the nominal pose's
    # shares had both, f_pin L). The chip stops where f(u) = f_pin / (2 |Delta_gamma|), i.e.
    # where u / sqrt(u^2 + h^2) = cos 30 - (cos r - cos a) / 2, short of the floor by d_p - u.
    finals = {}
    cp = math.cos(math.radians(30))
    for h in (10.0, 20.0):
        d_p = h / math.tan(math.radians(30))
        for w in ((40.0, 50.0), (31.0, 50.0)):
            sc = _scene(h=h, window=w, pinned=False, pad=300.0)
            assert sliding_shares(sc) == (1.0, 1.0, 1.0)
            t = simulate(sc, (48.0, 0.0, 0.0), method=method)
            c = cp - _dcos(w) / 2
            u = h * c / math.sqrt(1 - c * c)
            short = t.final[0] - (50.0 - d_p)
            finals[h, w] = short
            assert short == pytest.approx(d_p - u, rel=0.25)
            assert abs(t.final[1]) < 0.05
    # Grows with the hysteresis window and with the height (the ramp is h wide).
    assert (
        finals[10.0, (31.0, 50.0)] > finals[10.0, (40.0, 50.0)]
        and finals[20.0, (31.0, 50.0)] > finals[20.0, (40.0, 50.0)]
    )
    assert finals[10.0, (31.0, 50.0)] < finals[20.0, (31.0, 50.0)]


def test_free_lines_on_a_same_size_pad_are_not_held_by_its_hysteresis():
    # Same-size pad, free lines: near alignment one line stands on the substrate (d_s) and the
    # other is held by the pad's edge (between d_s and d_p); neither slides over the pad. Before,
    # the chip stopped on the ramp (u = 0.86 h from the edge); now it floats in to the floor.
    for method in ("greedy", "gradient"):
        t = simulate(_scene(pinned=False), (30.0, -12.0, 0.0), method=method)
        ref = simulate(_scene(pinned=False, hysteresis=False), (30.0, -12.0, 0.0), method=method)
        assert np.array_equal(t.path, ref.path) and t.outcome == ref.outcome == "aligned"
        assert max(abs(t.final[0]), abs(t.final[1])) <= 20.0 / math.tan(math.radians(60)) + 1.0


def test_montecarlo_applies_the_same_pinning():
    from simulator.batch import random_starts, run_batch, summarize

    starts = random_starts(200, (15.0, 15.0, 0.0), seed=3)
    starts[:, 2] = 0.0
    # Pinned: the pad's hysteresis changes nothing, start by start.
    res = {}
    for w in ((49.0, 50.0), (31.0, 50.0), None):
        r = run_batch(
            _scene(window=w or (31.0, 50.0), hysteresis=w is not None), starts, "gradient"
        )
        res[w] = r
        assert summarize(r)["yield"] > 0.95
    assert np.array_equal(res[31.0, 50.0].final, res[None].final) and np.array_equal(
        res[49.0, 50.0].final, res[None].final
    )
    assert np.abs(res[None].final[:, :2]).max() < 0.5
    # Free lines on the wider pad: every start from beyond the floor stops short of it, as a single run does.
    sc = _scene(h=10.0, pinned=False, pad=300.0)
    far = np.column_stack([np.linspace(44.0, 48.0, 5), np.zeros(5), np.zeros(5)])
    r = run_batch(sc, far, "gradient")
    for i in (0, 4):
        assert r.final[i] == pytest.approx(
            simulate(sc, tuple(far[i]), method="gradient").final, abs=1e-6
        )
    assert np.all(r.final[:, 0] > 50.0 - 10.0 / math.tan(math.radians(30)) + 5.0)
