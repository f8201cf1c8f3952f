"""Greedy and gradient trajectories: docs/physics.md C9 and C10 exactly, symmetry, monotone energy."""

import numpy as np
import pytest

from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.landscape import build_landscape
from simulator.motion import GREEDY_MOVES, simulate
from simulator.scene import Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("trajectory")


def make_scene(L, g, dtype="float32", um_per_px=1.0, **kw):
    pat = four_pad(L, g) if g else square(L)
    return Scene(
        pattern=mask_from_geometry(pat, um_per_px, margin_um=10),
        chip=mask_from_geometry(square(L), um_per_px),
        dtype=dtype,
        **kw,
    )


@pytest.fixture(scope="module")
def fp200():
    return make_scene(200, 20)


@pytest.fixture(scope="module")
def fp730():
    return make_scene(730, 50)


# ------------------------------------------------------------------ C9
@pytest.mark.parametrize(
    "start, final, steps",
    [
        ((89, 0, 0), (0, 0, 0), 89),
        ((100, 0, 0), (100, 0, 0), 0),
        ((120, 0, 0), (110, 0, 0), 10),
        ((120, 0, 5), (110, 0, 0), 10),
        ((120, 0, -5), (110, 0, 0), 10),
    ],
)
def test_c9_four_pad_200(fp200, start, final, steps):
    t = simulate(fp200, start)
    assert t.final == final and t.steps == steps
    assert t.outcome == ("aligned" if final == (0, 0, 0) else "plateau")


def test_c9_escape_at_plateau_end(fp200):
    t = simulate(fp200, (91, 0, 0))
    assert t.final == (0, 0, 0) and t.outcome == "aligned"


@pytest.mark.parametrize(
    "start, final, steps",
    [
        ((300, 0, 0), (0, 0, 0), 300),
        ((400, 0, 0), (390, 0, 0), 10),
        ((600, 0, 0), (390, 0, 0), 210),
    ],
)
def test_c9_four_pad_730(fp730, start, final, steps):
    t = simulate(fp730, start)
    assert t.final == final and t.steps == steps
    assert np.all(t.path[:, 2] == 0)  # no twisting on the way (C9)


def test_c9_730_ends_of_the_flat_region(fp730):
    t = simulate(fp730, (340, 0, 0))
    assert t.final == (0, 0, 0) and 20 <= np.abs(t.path[:, 2]).max() <= 23
    assert simulate(fp730, (342, 0, 0)).final == (0, 0, 0)
    far = simulate(fp730, (727, 0, 0))
    assert far.final == (390, 0, 0) and 30 <= np.abs(far.path[:, 2]).max() <= 33


def test_c9_730_100():
    s = make_scene(730, 100)
    assert simulate(s, (400, 0, 0)).final == (400, 0, 0)
    t = simulate(s, (500, 0, 0))
    assert t.final == (415, 0, 0) and t.steps == 85
    assert simulate(s, (317, 0, 0)).final == (0, 0, 0)


# ------------------------------------------------------------------ C10
def test_c10_square_every_x0():
    s = make_scene(200, 0)
    ls = build_landscape(s)
    for x0 in range(1, 200, 9):
        t = simulate(s, (x0, 0, 0), landscape=ls)
        assert t.final == (0, 0, 0) and t.steps == x0 and t.outcome == "aligned"


def test_c10_730_far_end_aligned_modulo_90():
    t = simulate(make_scene(730, 0), (727, 0, 0))
    assert t.final == (0, 0, -90) and t.steps == 727 and t.outcome == "aligned"


def test_step_lower_bound(fp200):
    t = simulate(fp200, (60, -35, 12))
    assert t.steps >= max(60, 35, 12)
    assert np.all(np.abs(np.diff(t.path, axis=0)) <= 1)  # each step moves each axis by <= 1 unit


# ------------------------------------------------------------------ symmetry, monotonicity, ties
def test_mirror_starts_give_mirror_paths(fp200):
    a = simulate(fp200, (70, 30, 4))
    b = simulate(fp200, (70, -30, -4))  # mirror in the x axis: (x, -y, -twist)
    c = simulate(fp200, (-70, 30, -4))  # mirror in the y axis: (-x, y, -twist)
    np.testing.assert_array_equal(b.path, a.path * [1, -1, -1])
    np.testing.assert_array_equal(c.path, a.path * [-1, 1, -1])


def test_greedy_energy_never_increases(fp200):
    for start in [(70, 30, 4), (150, 120, -20), (95, 95, 0)]:
        t = simulate(fp200, start)
        assert np.all(np.diff(t.energy_J) < 0)


def test_gradient_energy_never_increases_and_aligns(fp200):
    t = simulate(fp200, (60, 35, 8), method="gradient")
    assert np.all(np.diff(t.energy_J) <= 0)
    assert t.outcome == "aligned"
    assert np.abs(np.asarray(t.final) - [0, 0, 0]).max() <= 1.0


def test_gradient_plateau_stops_with_plateau(fp200):
    t = simulate(fp200, (100, 0, 0), method="gradient")
    assert t.outcome == "plateau" and t.final == (100, 0, 0)


def test_diagonal_tie_follows_documented_rule():
    # |x| = |y|: twisting either way ties exactly (C6: dA/dalpha = 0), in float32 and
    # float64 alike. The documented rule (smallest move, then (dt, dy, dx) from -1)
    # takes dt = -1 on both diagonals, so the two paths mirror in y but share the twist.
    s = make_scene(200, 0)
    for dtype in ("float32", "float64"):
        a, b = (
            simulate(s.replace(dtype=dtype), (50, 50, 0)),
            simulate(s.replace(dtype=dtype), (50, -50, 0)),
        )
        assert tuple(a.path[1]) == (49, 49, -1) and tuple(b.path[1]) == (49, -49, -1)
        np.testing.assert_array_equal(b.path, a.path * [1, -1, 1])
        assert a.outcome == b.outcome == "aligned"
    assert tuple(GREEDY_MOVES[0]) == (0, 0, 0) and tuple(GREEDY_MOVES[1]) == (-1, 0, 0)


@pytest.mark.parametrize("start", [(89, 0, 0), (120, 0, 5), (300, 0, 0), (60, -35, 12)])
def test_float32_and_float64_same_greedy_path(start):
    L = 730 if start[0] == 300 else 200
    g = 50 if L == 730 else 20
    a = simulate(make_scene(L, g, "float32"), start)
    b = simulate(make_scene(L, g, "float64"), start)
    np.testing.assert_array_equal(a.path, b.path)


def test_no_contact(fp200):
    t = simulate(fp200, (400, 0, 0))
    assert t.outcome == "no_contact" and t.steps == 0


def test_max_steps(fp200):
    t = simulate(fp200, (80, 0, 0), max_steps=10)
    assert t.outcome == "max_steps" and t.steps == 10 and t.final == (70, 0, 0)


def test_same_inputs_same_bits(fp200):
    a, b = simulate(fp200, (70, 30, 4)), simulate(fp200, (70, 30, 4))
    assert a.path.tobytes() == b.path.tobytes() and a.energy_J.tobytes() == b.energy_J.tobytes()


@pytest.mark.parametrize("method", ["greedy", "gradient"])
def test_lazy_boxes_equal_full_landscape(method):
    s = make_scene(730, 50, um_per_px=2.0, twist=TwistGrid(step_deg=2.0))
    full = build_landscape(s)
    starts = (
        [(680, 0, 0), (600, 400, 20), (-300, 250, -30)] if method == "greedy" else [(600, 400, 20)]
    )
    for start in starts:
        lazy = simulate(s, start, method=method)
        ref = simulate(s, start, method=method, landscape=full)
        if method == "greedy":
            np.testing.assert_array_equal(lazy.path, ref.path)
        else:  # continuous float32 poses: box and full FFTs round differently
            np.testing.assert_allclose(lazy.final, ref.final, atol=0.05)
        assert lazy.outcome == ref.outcome
        assert lazy.cost is not None  # a packaged run has its cost
        assert lazy.cost.fraction_of_full < 0.5
