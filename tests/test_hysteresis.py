"""Contact-angle hysteresis (simulator.hysteresis): pinning forces from the chip outline,
the stopping rule of every stepper, zero width = today's rule exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import box

from patterns.errors import InputError
from patterns.mask import Mask
from patterns.raster import mask_from_geometry
from simulator import hysteresis as hy
from simulator.materials import Liquid, Materials
from simulator.scene import Effects, Scene
from simulator.trajectory import simulate

GAMMA = 0.0728


def _scene(h=20.0, window=(31.0, 50.0), hysteresis=True, L=200.0, s=2.0):
    pat = mask_from_geometry(box(-L / 2, -L / 2, L / 2, L / 2), s, margin_um=4)
    mat = Materials(pad_receding_deg=window[0], pad_advancing_deg=window[1]) if window else Materials()
    return Scene.from_inputs(pat, chip_size_um=L, materials=mat, effects=Effects(twist=False, meniscus=True, hysteresis=hysteresis),
                             liquid=Liquid(height_um=h, pinned=True), window_um=80, dtype="float64")


def test_pinning_forces_of_a_rectangle_and_a_square():
    f = hy.pinning_force_per_length(GAMMA, 31, 50)
    assert f == pytest.approx(GAMMA * (math.cos(math.radians(31)) - math.cos(math.radians(50))))
    a, b = 200.0, 100.0
    geo = Scene.from_inputs(mask_from_geometry(box(-a / 2, -b / 2, a / 2, b / 2), 1.0), chip_size_um=(a, b),
                            materials=Materials(pad_receding_deg=31, pad_advancing_deg=50), effects=Effects(hysteresis=True))
    pt, py, px = hy.pinning(geo)
    # Furmidge: P = f * (width across the motion). Torque: f/2 * oint |(z x r) . n| ds; the
    # a-edges give 2 int |x| dx = a^2 / 2, the b-edges b^2 / 2.
    assert px == pytest.approx(f * b * 1e-6) and py == pytest.approx(f * a * 1e-6)
    assert pt == pytest.approx(f / 2 * (a * a + b * b) / 2 * 1e-12, rel=1e-9)
    # Square of side L: P_t = f L^2 / 2 (each edge: 2 * int_0^{L/2} s ds = L^2 / 4; four edges, times f / 2).
    L = 200.0
    sq = Scene.from_inputs(mask_from_geometry(box(-L / 2, -L / 2, L / 2, L / 2), 1.0), chip_size_um=L,
                           materials=Materials(pad_receding_deg=31, pad_advancing_deg=50), effects=Effects(hysteresis=True))
    assert hy.pinning(sq)[0] == pytest.approx(f * L**2 / 2 * 1e-12)
    # A chip image gives the same integrals as its exact geometry (pixel-aligned square).
    img = Mask(mask_from_geometry(box(-L / 2, -L / 2, L / 2, L / 2), 1.0).data, 1.0)
    assert np.allclose(hy.contact_line_integrals_um(img), hy.contact_line_integrals_um(sq.chip), rtol=1e-9)


def test_window_parsing_and_refusals():
    assert hy.parse_window("31:50") == (31.0, 50.0)
    for bad in ("50", "50:31", "a:b", "-1:20", "10:190"):
        with pytest.raises(InputError):
            hy.parse_window(bad)
    with pytest.raises(InputError, match="receding and advancing"):
        Materials(pad_receding_deg=30)
    with pytest.raises(InputError, match="hysteresis needs"):
        _scene(window=None)


@pytest.mark.parametrize("method", ["greedy", "gradient", "overdamped", "inertial"])
def test_zero_width_is_todays_stopping_rule_exactly(method):
    off = simulate(_scene(hysteresis=False), (30.0, -12.0, 0.0), method=method)
    zero = simulate(_scene(window=(40.0, 40.0)), (30.0, -12.0, 0.0), method=method)
    assert np.array_equal(off.path, zero.path) and off.outcome == zero.outcome and off.steps == zero.steps


@pytest.mark.parametrize("method", ["gradient", "overdamped"])
def test_chip_stops_where_the_force_falls_to_the_pinning_force(method):
    # Square, pinned meniscus: spring 2 gamma L / h; pinning f L: stops at x = h (cos r - cos a) / 2
    # in the linear regime (x << h); the meniscus model's corner factor softens the spring by 2h/(pi L).
    finals = {}
    for h in (10.0, 20.0):
        for w in ((40.0, 50.0), (31.0, 50.0)):
            t = simulate(_scene(h=h, window=w), (30.0, 0.0, 0.0), method=method)
            dcos = math.cos(math.radians(w[0])) - math.cos(math.radians(w[1]))
            x_lin = h * dcos / 2 / (1 - 2 * h / (math.pi * 200.0))
            finals[h, w] = t.final[0]
            assert t.outcome == "aligned"
            assert t.final[0] == pytest.approx(x_lin, rel=0.25)
            assert abs(t.final[1]) < 0.05
    # Grows with the hysteresis window, falls with the stiffness (smaller h = stiffer).
    assert finals[10.0, (31.0, 50.0)] > finals[10.0, (40.0, 50.0)] and finals[20.0, (31.0, 50.0)] > finals[20.0, (40.0, 50.0)]
    assert finals[10.0, (31.0, 50.0)] < finals[20.0, (31.0, 50.0)]


def test_montecarlo_reports_a_spread_of_errors():
    from simulator.montecarlo import random_starts, run_batch, summarize

    starts = random_starts(200, (15.0, 15.0, 0.0), seed=3)
    starts[:, 2] = 0.0
    res = {}
    for w in ((49.0, 50.0), (31.0, 50.0)):
        out = summarize(run_batch(_scene(window=w), starts, "gradient"))
        res[w] = out
        assert out["yield"] > 0.95
    wide, narrow = res[(31.0, 50.0)]["aligned_error_um"], res[(49.0, 50.0)]["aligned_error_um"]
    assert wide["x"]["std"] > 3 * narrow["x"]["std"] > 0
