"""The footprint as the run's state in the steppers and in batches (docs/physics.md §3.5).

A run on a field with the footprint's relay stops where the state first changes; a batch
carries one state per lane, in rounds, and ends each lane where the single run ends; the
commands that run batches (montecarlo, evaluate, sweep) take ``--dispense``.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from patterns.geometry import Mask
from simulator.batch import assess, run_batch
from simulator.core import OUTCOMES
from simulator.landscape import build_footprint_planes
from simulator.liquid import dispensed_footprint
from simulator.motion import DynamicsParams, Relay, footprint_relay, simulate, wet_bits
from simulator.physics import Liquid
from simulator.scene import Effects, Scene

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("footprint_batch")

#: float32 poses (the landscapes' dtype) carry about 7 digits: two runs of the same
#: computation agree to a few ulps of the largest coordinate (the grid spans 600 um)
POSE_TOL_UM = 8 * float(np.finfo(np.float32).eps) * 600.0


def two_pads(dispense: str = "pattern") -> Scene:
    """A 200 um pad A (x, y in [-100, 100] um) and a 70 x 60 um pad B at x in [160, 230],
    under a 200 um chip with 0.9 nl (h = 22.5 um: d_s = 13 um, d_r = d_p = 39 um): a chip
    that starts over both wets both; moving onto A it leaves B, which dries beyond d_r."""
    a = np.zeros((240, 300))  # 480 x 600 um at 2 um/px
    a[70:170, 100:200] = 1.0
    a[105:135, 230:265] = 1.0
    return Scene.from_inputs(
        Mask(a, 2.0),
        chip_size_um=200,
        effects=Effects(twist=False, meniscus=True),
        liquid=Liquid(volume_nl=0.9, dispense=dispense),
        damping_calibration=600.0,  # the former fit: the times below are its
    )


STARTS = np.array(
    [(80, 0, 0), (60, 10, 0), (-40, 0, 0), (120, -20, 0), (200, 30, 0), (0, 0, 0)], float
)


@pytest.fixture(scope="module")
def scene_planes():
    s = two_pads()
    return s, build_footprint_planes(s)


def test_a_relayed_run_stops_where_the_state_first_changes(scene_planes):
    # The same greedy run without the relay, recorded: the first pose of its path where the
    # relay changes the state is where the relayed run stops, with the same path up to there
    s, fp = scene_planes
    dispensed, _ = dispensed_footprint(s, fp.labels, fp.n_pads)
    start = (80.0, 0.0, 0.0)
    wet = fp.next_state(dispensed, start)
    assert wet.all()  # the chip covers some of both pads at release
    inner = s.replace(liquid=dataclasses.replace(s.liquid, dispense="none"))
    free = simulate(inner, start, landscape=fp.landscape(wet))
    first = next(i for i, p in enumerate(free.path) if (fp.next_state(wet, p) != wet).any())
    reached, within = footprint_relay(fp)
    stopped = simulate(
        inner,
        start,
        landscape=fp.landscape(wet),
        # a numpy array where the relay is typed jax's: jax takes one as its own
        relay=Relay(reached, within, np.asarray(wet_bits(wet))),
    )
    assert stopped.outcome == "event" and stopped.steps == first
    np.testing.assert_array_equal(stopped.path, free.path[: first + 1])
    # the state there: pad B dry (the chip left it beyond d_r), pad A still wet
    assert fp.next_state(wet, stopped.final).tolist() == [True, False]


@pytest.mark.parametrize("method", ["greedy", "gradient", "overdamped", "inertial"])
def test_batch_lanes_carry_their_own_footprint_and_equal_single_runs(method, scene_planes):
    s, fp = scene_planes
    starts = STARTS if method in ("greedy", "gradient") else STARTS[[0, 2, 5]]
    r = run_batch(s, starts, method, progress=False, planes=fp)
    events = 0
    for i, start in enumerate(starts):
        t = simulate(s, tuple(start), method=method, planes=fp)
        assert t.footprint is not None
        events += len(t.footprint["events"])
        assert OUTCOMES[r.outcome[i]] == t.outcome, (start, t.outcome)
        assert r.steps[i] == t.steps, start
        np.testing.assert_allclose(r.final[i], t.final, atol=POSE_TOL_UM, rtol=0)
        if r.time_s is not None:
            assert r.time_s[i] == pytest.approx(t.time_s, rel=4 * float(np.finfo(np.float32).eps))
    # the lanes took different histories: some changed state on the way, some never did
    assert r.stats["footprint_events"] == events > 0
    assert r.stats["footprint_rounds"] >= 2


def test_a_footprint_run_never_passes_its_time_limit(scene_planes):
    # From 80 um the overdamped chip's pad B dries at t_ev (about 0.02 s, x = 20 um) and the
    # chip then slides onto the floor of pad A (|x| <= d_s = 13 um). With t_max = t_ev + 1 ms
    # for the whole run, the stretch after the event has only that millisecond: the run
    # stops at t_max, short of the floor (not aligned: how the run reads its creeping end is
    # classify's rule), single run and batch alike
    s, fp = scene_planes
    free = simulate(s, (80.0, 0.0, 0.0), method="overdamped", planes=fp)
    assert free.footprint is not None
    (ev,) = free.footprint["events"]
    assert free.outcome == "aligned" and ev["x_um"] > 15
    d = dataclasses.replace(DynamicsParams.from_scene(s), t_max_s=ev["t_s"] + 1e-3)
    t = simulate(s, (80.0, 0.0, 0.0), method="overdamped", dynamics=d, planes=fp)
    assert t.footprint is not None and t.time_s is not None and t.t_s is not None
    assert [e["step"] for e in t.footprint["events"]] == [ev["step"]]
    assert t.outcome != "aligned" and t.time_s <= d.t_max_s and t.final[0] > 13
    assert np.all(np.diff(t.t_s) >= 0) and t.t_s[-1] <= d.t_max_s
    r = run_batch(s, STARTS[:1], "overdamped", progress=False, dynamics=d, planes=fp)
    assert r.time_s is not None
    assert OUTCOMES[r.outcome[0]] == t.outcome and r.time_s[0] <= d.t_max_s
    assert r.time_s[0] == pytest.approx(t.time_s, rel=4 * float(np.finfo(np.float32).eps))


def test_montecarlo_cli_carries_the_footprint(run_cli, tmp_path):
    # 730/100 at 10 um/px, starts at x = 300, 360, 420 um: the far pads' inner edges lie 15,
    # 45 and 105 um beyond the chip's. With the liquid coming in under the chip (chip) they
    # wet only within d_s = 21.7 um: the start from 300 um aligns, the others stop on the
    # flat part. Without the state they pull from d_p = 65 um: 360 um aligns as well.
    from tests.test_footprint_state import LIB

    args = ["montecarlo", "--pattern", LIB / "four_pad_730_100.png", "--chip-size", "730"]
    args += ["--meniscus", "--volume", "20", "--resolution", "10", "--no-twist"]
    args += ["--grid", "300:420:60,0,0", "--quiet"]
    out = tmp_path / "mc.json"
    rc, stdout, err = run_cli([*args, "--dispense", "chip", "--json", out])
    assert rc == 0, err
    assert "footprint (--dispense chip)" in stdout
    d = json.loads(out.read_text())
    assert d["scene"]["dispense"] == "chip" and d["footprint"]["dispense"] == "chip"
    assert d["outcomes"]["aligned"] == 1 and d["outcomes"]["plateau"] == 2, d["outcomes"]
    assert d["footprint"]["events"] == 0  # each start's pads wet at release, or never reached
    assert d["footprint"]["twists"] == 1  # --no-twist: the planes' one twist
    rc, _, err = run_cli([*args, "--dispense", "none", "--json", tmp_path / "stateless.json"])
    assert rc == 0, err
    d = json.loads((tmp_path / "stateless.json").read_text())
    assert d["scene"]["dispense"] is None and "footprint" not in d
    assert d["outcomes"]["aligned"] == 2 and d["outcomes"]["plateau"] == 1, d["outcomes"]


@pytest.mark.parametrize("receding", [None, 10.0])
def test_the_max_bias_is_the_farthest_release_that_comes_back(receding):
    # 730/50 at 10 um/px along +x, each protocol: a greedy run released at the reported
    # bias aligns, one released a grid step further does not. Without hysteresis the far
    # pads of a pattern-dispensed chip dry from 406 um, and the dry pads' state is flat
    # short of that (the inward branch's flat part): released beyond, the chip stops there.
    # Read as each sample's fresh release (the curve's force points back at every sample),
    # this case gave 795 um (the design baseline), where every release from 410 um
    # stops.
    from simulator.batch._evaluate import released_max_bias
    from tests.test_footprint_state import fourpad

    liquid = {} if receding is None else {"receding": receding}
    s = fourpad(50, res=10.0, dispense="pattern", **liquid)
    planes = build_footprint_planes(s)
    for proto in ("pattern", "chip"):
        sc = s.replace(liquid=dataclasses.replace(s.liquid, dispense=proto))
        dispensed, _ = dispensed_footprint(sc, planes.labels, planes.n_pads)
        bias, _ = released_max_bias(planes, dispensed, "x", (0.0, 0.0, 0.0), -800, 800, [-20, 20])
        assert 300 < bias < 795, (proto, bias)
        ends = [simulate(sc, (b, 0.0, 0.0), "greedy", planes=planes) for b in (bias, bias + 10)]
        assert [t.outcome for t in ends] == ["aligned", "plateau"], (proto, bias)


def test_evaluate_reports_each_protocol(tmp_path):
    # The four-pad 730/100 at 10 um/px without hysteresis: released with the far pads wet
    # (pattern), the chip is pulled back from further than with them dry (chip), whose
    # liquid reaches them only at d_s < d_r = d_p
    from tests.test_footprint_state import fourpad

    s = fourpad(100, res=10.0, dispense="chip")
    summary = assess(s, yield_starts=20, grid_cells=7).to_dict()
    p = summary["protocols"]
    assert p["dispense"] == "chip" and p["pattern"]["wet_at_dispense"] == [1, 2, 3, 4]
    assert p["chip"]["wet_at_dispense"] == []
    for axis in ("+x", "-x", "+y", "-y"):
        assert p["pattern"]["max_bias_um"][axis] > p["chip"]["max_bias_um"][axis] > 0
    assert p["pattern"]["capture_fraction"] >= p["chip"]["capture_fraction"]
    # the sweep's columns of a dispense scene are those this summary flattens to
    from simulator.sweep._columns import _metric_columns, flatten

    cols = {c for c in flatten(summary) if c.startswith("protocols_")}
    expected = {
        c
        for c in _metric_columns(
            twist=False, meniscus=True, free=True, dynamics=False, dispense=True
        )
        if c.startswith("protocols_")
    }
    assert expected <= cols
    assert {c for c in cols if "wet_at_dispense" not in c} == expected
