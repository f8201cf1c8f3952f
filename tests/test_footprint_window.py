"""A ``--dispense`` run on the pads' FFT planes makes them over a window of twists around its
start and the aligned pose, not over the whole axis, and makes the run again on a wider one
while its path comes near the window's side (docs/physics.md §3.5): the same run as on the
whole axis's planes, which agree with the window's to round-off (the transforms' sizes
follow the twists' extent)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import simulator.motion._footprint_run as footprint_run
from simulator.landscape import build_footprint_planes
from simulator.motion import simulate
from simulator.motion._footprint_run import WINDOW_MARGIN_STEPS, twist_window
from tests.test_footprint_planes import fourpad

pytestmark = pytest.mark.xdist_group("footprint_window")


@pytest.fixture(scope="module")
def chip_dispensed():
    """The 730/100 four-pad at 10 um/px, 1 deg twists over [-45, 45), pads 10:35 deg, the
    liquid coming in under the chip (far pads wet on the way in), and its planes on every
    twist."""
    s = fourpad(10.0, twist=True)
    s = s.replace(liquid=dataclasses.replace(s.liquid, dispense="chip"))
    return s, build_footprint_planes(s)


def test_the_window_is_symmetric_about_zero_and_holds_each_twist_with_its_margin():
    s = fourpad(10.0, twist=True)
    axis = s.twist_axis
    assert (axis.count, axis.step_deg, axis.periodic) == (90, 1.0, True)
    w = twist_window(s, [7.0, -2.0], 10.0)
    assert w is not None
    np.testing.assert_array_equal(w, np.arange(-17.0, 18.0))  # |7| + 10 either way
    # at least the margin and the steppers' 4 cells either side of each twist, whatever
    # the half-width asked: a run starts clear of the side on any axis
    one = twist_window(s, [0.0], 0.0)
    assert one is not None and list(one) == list(np.arange(-10.0, 11.0))
    assert WINDOW_MARGIN_STEPS + 4 == 10
    coarse = s.replace(twist=dataclasses.replace(s.twist, step_deg=2.0))
    assert (coarse.twist_axis.count, coarse.twist_axis.step_deg) == (45, 2.0)
    w2 = twist_window(coarse, [4.0], 10.0)
    assert w2 is not None and list(w2) == list(np.arange(-24.0, 25.0, 2.0))  # 4 + 10 steps
    # a window within 2 margins of the whole axis is the whole axis
    assert twist_window(s, [45.0 - WINDOW_MARGIN_STEPS], 0.0) is None
    assert (
        twist_window(s.replace(effects=dataclasses.replace(s.effects, twist=False)), [0.0], 10.0)
        is None
    )


def _same_run(s, a, b, method: str) -> None:
    """``b`` (on its window) is ``a`` (on every twist's planes): the same events, outcome and
    path (greedy, node to node: the planes' round-off decides no move), or the same end."""
    assert a.footprint and b.footprint and a.footprint["events"], "the case has events"
    ea, eb = a.footprint["events"], b.footprint["events"]
    assert [(e["pad"], e["state"]) for e in ea] == [(e["pad"], e["state"]) for e in eb]
    assert a.outcome == b.outcome == "aligned"
    if method == "greedy":
        assert [e["step"] for e in ea] == [e["step"] for e in eb]
        np.testing.assert_array_equal(a.path, b.path)
    else:
        # the planes agree to 1e-6 of their scale (10 float32 eps, within the noise floor of
        # 32 eps); the solver's step control carries that along, and a pose near a relay's
        # threshold may cross it a step apart: measured 0 or 1 step, and at the end of the
        # 1 s run 0.004 um (4e-4 px) and 8e-4 deg
        assert all(abs(x["step"] - y["step"]) <= 1 for x, y in zip(ea, eb, strict=True))
        step = np.array([s.um_per_px, s.um_per_px, s.twist_axis.step_deg])
        assert (np.abs(np.subtract(a.final, b.final)) / step < 0.05).all(), (a.final, b.final)


@pytest.mark.parametrize("method", ["greedy", "inertial"])
def test_a_run_on_its_twist_window_is_the_run_on_every_twist(chip_dispensed, method, monkeypatch):
    """From (400, 150 um, 8 deg), the far pads wetting on the way in: with a 20 deg window
    the planes are made over [-28, 28] deg (57 of the 90 twists), the path turns up to 19.4
    deg (inertial) and stays inside."""
    s, full = chip_dispensed
    monkeypatch.setattr(footprint_run, "WINDOW_DEG", 20.0)
    start = (400.0, 150.0, 8.0)
    a = simulate(s, start, method, planes=full, engine="fft")
    b = simulate(s, start, method, engine="fft")
    assert a.cost is not None and b.cost is not None
    assert a.cost.footprint_twists is None  # planes given: the caller's
    assert b.cost.footprint_twists == len(np.arange(-28.0, 29.0))
    _same_run(s, a, b, method)


def test_a_path_near_the_window_side_runs_again_on_a_wider_window(chip_dispensed, monkeypatch):
    """The same start with the default 10 deg window: [-18, 18] deg first, which the path
    leaves (it turns to 18 deg, within the margin of the side); the run is made again on
    [-28, 28] (10 deg beyond where it went) and is the whole axis's run."""
    s, full = chip_dispensed
    assert footprint_run.WINDOW_DEG == 10.0
    made = []
    real = footprint_run.twist_window
    monkeypatch.setattr(footprint_run, "twist_window", lambda *a: made.append(real(*a)) or made[-1])
    start = (400.0, 150.0, 8.0)
    a = simulate(s, start, "greedy", planes=full, engine="fft")
    b = simulate(s, start, "greedy", engine="fft")
    assert [(w[0], w[-1]) for w in made] == [(-18.0, 18.0), (-28.0, 28.0)]
    assert b.cost is not None and b.cost.footprint_twists == 57
    assert np.asarray(b.path)[:, 2].max() <= 28.0 - WINDOW_MARGIN_STEPS
    _same_run(s, a, b, "greedy")


@pytest.mark.parametrize("method", ["greedy", "gradient"])
def test_a_batch_on_its_twist_window_is_the_batch_on_every_twist(
    chip_dispensed, method, monkeypatch
):
    """A batch that makes its own planes makes them over a window around its starts' twists
    and the aligned pose's: from (400, 150 um, 8 deg) the path turns to 18 deg, inside the
    margin of [-18, 18] deg (the first window, 8 + 10 deg with the batch's reach set to a
    single run's), so that lane stops there and runs
    again from its start on [-28, 28] (10 deg beyond the side); the lanes that stayed clear
    keep their ends. Every lane ends as on the whole axis's planes, greedy node for node (the
    planes' round-off decides no move). (A gradient lane stops on the pinned aligned floor
    where the planes' round-off leaves it, 0.05-0.17 px apart, as a single gradient run on a
    window does; the batch equals the single run on the same planes.)"""
    import simulator.batch._footprint_batch as footprint_batch
    from simulator.batch import run_batch

    s, full = chip_dispensed
    made = []
    real = footprint_run.twist_window
    monkeypatch.setattr(
        "simulator.motion.twist_window", lambda *a: made.append(real(*a)) or made[-1]
    )
    # a batch's first window reaches 20 deg (its lanes share it); a single run's 10, which
    # this lane leaves
    assert footprint_batch.BATCH_WINDOW_DEG == 2 * footprint_run.WINDOW_DEG == 20.0
    monkeypatch.setattr(footprint_batch, "BATCH_WINDOW_DEG", 10.0)
    starts = np.array([(400.0, 150.0, 8.0), (250.0, -40.0, 3.0), (-300.0, 60.0, -5.0)])
    a = run_batch(s, starts, "greedy", progress=False, planes=full)
    b = run_batch(s, starts, "greedy", progress=False)
    assert a.stats["footprint_twists"] == 90
    assert [(w[0], w[-1]) for w in made] == [(-18.0, 18.0), (-28.0, 28.0)]
    assert b.stats["footprint_twists"] == 57
    np.testing.assert_array_equal(a.outcome, b.outcome)
    assert a.stats["footprint_events"] == b.stats["footprint_events"] > 0
    np.testing.assert_array_equal(a.steps, b.steps)
    np.testing.assert_array_equal(a.final, b.final)
