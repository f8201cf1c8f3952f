"""The footprint state in the path engine (docs/physics.md §3.5): each pad's energies, relay
flags and the shadow pairs' corrections at the poses of a box equal the FFT planes' at the
same grid nodes (a two-pad pattern, the 730/100 four-pad at large twists), and a greedy
``--dispense`` run on the path engine takes the FFT planes' run's path, events and end, a
gradient run with dry pads its steps."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from simulator.landscape import FootprintPath, build_footprint_planes
from simulator.landscape._correlator import NOISE_FACTOR
from simulator.physics import TOUCH_PX2
from simulator.scene import TwistGrid
from tests.test_footprint_planes import fourpad, two_pads

pytestmark = pytest.mark.xdist_group("footprint_path")


def _floor(planes) -> np.floating:
    """The noise floor: 32 eps (float32) times the planes' largest |E|."""
    return NOISE_FACTOR * np.finfo(np.float32).eps * float(np.abs(planes.wet_energy).max())


def _flags_agree(fp: FootprintPath, box, planes, sel, name: str, k_axis) -> None:
    """The relay flags equal, except where the count lies within round-off of TOUCH_PX2."""
    a = getattr(box, name)  # (pads, T, ny, nx)
    b = getattr(planes, name)[(slice(None), *sel)]
    bad = np.argwhere(a != b)
    if not len(bad):
        return
    count = {"reached": "reached", "within_reach": "within"}[name]
    g = box.template.grid
    tol = (
        NOISE_FACTOR
        * np.finfo(np.float32).eps
        * float(fp.pad_area_um2.max())
        / fp.scene.um_per_px**2
    )
    for p, it, iy, ix in bad:
        c = fp.sums(count, int(p), int(k_axis[it]), g.y_first_px + iy, 1, g.x_first_px + ix, 1)
        assert abs(float(c[0, 0]) - TOUCH_PX2) <= tol, (name, p, it, iy, ix, float(c[0, 0]))


def _compare(scene, planes, fp: FootprintPath, twist_idx, center_px, half_px, states) -> int:
    """Compare a box of the path engine with the FFT planes there; return how many pair
    corrections the box holds (non-zero)."""
    box = fp.box(twist_idx, center_px, half_px)
    g, G = box.template.grid, planes.template.grid
    assert g.um_per_px == G.um_per_px
    # the box's nodes in the FFT grid (twists by value: the planes may hold some twists only)
    tw_fft = np.round(G.twist_deg(), 9)
    it = np.array([int(np.flatnonzero(tw_fft == round(float(t), 9))[0]) for t in g.twist_deg()])
    iy = slice(g.y_first_px - G.y_first_px, g.y_first_px - G.y_first_px + g.shape[1])
    ix = slice(g.x_first_px - G.x_first_px, g.x_first_px - G.x_first_px + g.shape[2])
    sel = (it, iy, ix)
    floor = _floor(planes)
    d = np.abs(box.wet_energy.astype(float) - planes.wet_energy[(slice(None), *sel)]).max()
    assert d <= floor, f"pads' energies differ by {d / floor:.2f} noise floors"
    for name in ("reached", "within_reach"):
        _flags_agree(fp, box, planes, sel, name, [j % fp.axis.count for j in twist_idx])
    for wet in states:
        e1 = planes.energy(wet)[sel]
        e2 = box.energy(wet)
        d = np.abs(e1.astype(float) - e2).max()
        assert d <= floor, f"state {wet.astype(int)}: energies differ by {d / floor:.2f} floors"
    return sum(int(np.count_nonzero(p.energy)) for p in box.pairs)


def test_two_pads_every_pose_equals_the_planes():
    s = two_pads()
    planes = build_footprint_planes(s)
    fp = FootprintPath(s)
    G = planes.template.grid
    assert (fp.grid.shape, fp.grid.x_first_px, fp.grid.y_first_px) == (
        G.shape,
        G.x_first_px,
        G.y_first_px,
    )
    _, ny, nx = G.shape
    states = [np.array(w, bool) for w in ((1, 1), (1, 0), (0, 1))]
    centre = (G.x_first_px + nx // 2, G.y_first_px + ny // 2)
    paired = _compare(s, planes, fp, [0], centre, max(nx, ny) // 2, states)
    assert paired > 0  # the shadow rule acts somewhere on the grid
    # a small box moved along the row (the run's boxes): the rows it keeps are reused
    for cx in (-30, -29, -20, 25, 40):
        _compare(s, planes, fp, [0], (cx, 3), 4, states)


@pytest.fixture(scope="module")
def four():
    """The 730/100 four-pad at 10 um/px with twist (3 deg steps), its planes at every third
    twist from -42 to 39 deg (one evenly spaced run: the large twists where the pairs' parts
    change with the twist, 21 to 44 deg either way, and small ones)."""
    s = fourpad(10.0, twist=True)
    s = s.replace(twist=TwistGrid(3.0, s.twist.min_deg, s.twist.max_deg))
    ta = s.twist_axis
    want = np.arange(-42.0, 40.0, 9.0)
    idx = [int(np.argmin(np.abs(ta.values() - t))) for t in want]
    np.testing.assert_allclose(ta.values_at(np.asarray(idx)), want)
    planes = build_footprint_planes(s, twists=want)
    return s, planes, FootprintPath(s), idx


def test_four_pad_large_twists_equal_the_planes(four):
    s, planes, fp, idx = four
    all_wet = np.ones(4, bool)
    states = [all_wet] + [np.roll(np.array([1, 1, 0, 0], bool), k) for k in range(4)]
    paired = 0
    # bias toward one side (the far pads bridged, the near pads' strips shadowed), at every
    # twist of the fixture, one twist per box as a run's band holds several
    for k in idx:
        for centre in ((40, 3), (-38, -5), (4, 41), (30, -30)):
            paired += _compare(s, planes, fp, [k], centre, 3, states)
    assert paired > 0


def test_a_pad_covered_throughout_a_box_skips_its_count_and_nothing_changes(four, monkeypatch):
    # where the chip covers a pad's anchor pixel at every pose of a box the covered count
    # is not summed (FootprintPath._covered_throughout); the box is the same, bit for bit,
    # as the one that sums it, and the summed count is above TOUCH_PX2 wherever it is skipped
    s, _, _, idx = four
    fired = []
    real = FootprintPath._covered_throughout

    def checked(self, p, k, tw, y0, ny, x0, nx):
        skip = real(self, p, k, tw, y0, ny, x0, nx)
        if skip:
            counts = self.sums("covered", p, k, y0, ny, x0, nx)
            assert counts.min() >= TOUCH_PX2, (p, k, counts.min())
            fired.append(p)
        return skip

    # two engines made alike, asked for the same boxes in the same order (their rows
    # computed alike), one skipping the counts it can
    fp, fresh = FootprintPath(s), FootprintPath(s)
    boxes = [([k], centre, 3) for k in idx[::3] for centre in ((40, 3), (4, 41), (0, 0))]
    monkeypatch.setattr(FootprintPath, "_covered_throughout", checked)
    skipped = [fp.box(*b) for b in boxes]
    monkeypatch.setattr(FootprintPath, "_covered_throughout", lambda *a: False)
    summed = [fresh.box(*b) for b in boxes]
    assert len(set(fired)) == 4  # each pad's count skipped somewhere
    for a, b in zip(skipped, summed, strict=True):
        for name in ("wet_energy", "reached_bits", "within_bits"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        for wet in (np.ones(4, bool), np.array([1, 1, 0, 0], bool)):
            assert np.array_equal(a.energy(wet), b.energy(wet))


def _ragged_pads() -> np.ndarray:
    """Three pads of uneven outline, one with a hole and one graded (0.6), 1 um/px: the
    shapes where a ray's furthest pad pixel is not a corner."""
    n = 160
    y, x = np.mgrid[0:n, 0:n] + 0.5
    d = np.zeros((n, n))
    t = np.arctan2(y - 45, x - 45)
    d[np.hypot(y - 45, x - 45) < 28 * (1 + 0.25 * np.sin(5 * t))] = 1.0
    ring = np.hypot(y - 45, x - 115)
    d[(ring < 30) & (ring >= 9)] = 1.0  # a pad with a hole
    d[np.hypot(y - 118, x - 80) < 26 * (1 + 0.2 * np.cos(3 * np.arctan2(y - 118, x - 80)))] = 0.6
    d[::7, ::5] *= np.hypot(y[::7, ::5] - 45, x[::7, ::5] - 45) > 24  # a ragged first pad
    return d


def test_pair_parts_are_the_fft_builds_on_ragged_pads():
    # the near pad's part upstream of the far one, made on the two pads' boxes (the far
    # pad's edge pixels only), is the FFT build's masks[a] & upstream_along(masks[b]) on the
    # whole image, pixel for pixel, at any angle (exact: the same rays, the same values)
    from patterns.geometry import Mask
    from simulator.physics import Liquid, Materials
    from simulator.physics._footprint import upstream_along
    from simulator.scene import Effects, Scene

    d = _ragged_pads()
    s = Scene.from_inputs(
        Mask(d, 1.0),
        chip_size_um=120,
        effects=Effects(twist=True, meniscus=True),
        materials=Materials(),
        liquid=Liquid(volume_nl=0.4, dispense="pattern"),
    )
    fp = FootprintPath(s)
    assert fp.n_pads == 3
    angles = [0.0, 90.0, -90.0, 180.0, 45.0, -45.0, 135.0, 7.3, -33.1, 61.7, 101.9, -158.4]
    for a in range(3):
        for b in range(3):
            if a == b:
                continue
            cut = 0  # angles where the shadow's side runs through pad a
            for ang in angles:
                up = fp.masks[a] & upstream_along(fp.masks[b], ang)
                ref, got = fp._part_box(np.where(up, d, 0.0), 0, 0), fp._upstream(a, b, ang)
                assert ref.empty == got.empty, (a, b, ang)
                if ref.empty:
                    continue
                cut += bool(up.sum() < fp.masks[a].sum())
                assert (ref.i0, ref.j0) == (got.i0, got.j0), (a, b, ang)
                assert np.array_equal(ref.P, got.P), (a, b, ang)
            assert cut > 0, (a, b)  # each pair's part is cut somewhere among these angles


@pytest.fixture(scope="module")
def chip_dispensed():
    """The 730/100 four-pad at 10 um/px, 3 deg twists, ``--dispense chip``, and its planes."""
    s = fourpad(10.0, twist=True)
    s = s.replace(
        liquid=dataclasses.replace(s.liquid, dispense="chip"),
        twist=TwistGrid(3.0, s.twist.min_deg, s.twist.max_deg),
    )
    return s, build_footprint_planes(s)


def test_greedy_run_on_the_path_engine_takes_the_planes_run(chip_dispensed):
    """A chip-dispensed greedy run with an event (a far pad wets), from a large twist: the
    same path, events, outcome and final pose on the path engine as on the FFT planes."""
    s, planes = chip_dispensed
    from simulator.motion import simulate

    start = (450.0, 100.0, 30.0)
    a = simulate(s, start, "greedy", planes=planes)
    b = simulate(s, start, "greedy", engine="path")
    assert a.cost is not None and b.cost is not None  # packaged runs have their costs
    assert a.cost.engine == "footprint planes" and b.cost.engine == "footprint path"
    assert a.footprint is not None and b.footprint is not None
    assert [(e["pad"], e["state"], e["step"]) for e in a.footprint["events"]] == [
        (e["pad"], e["state"], e["step"]) for e in b.footprint["events"]
    ]
    assert a.footprint["events"], "the case has an event"
    assert a.outcome == b.outcome
    np.testing.assert_array_equal(a.path, b.path)
    assert a.footprint["final"] == b.footprint["final"]


@pytest.mark.parametrize("start", [(450.0, 100.0, 30.0), (-430.0, 60.0, -10.0)])
def test_gradient_run_with_dry_pads_steps_as_on_the_planes(chip_dispensed, start):
    """A chip-dispensed gradient run, its far pads dry (one wets on the way from the first
    start): the force scale of a gradient step is the scene's, every pad wet, on either
    engine (not the current state's own largest |E|, about half of it with two pads dry), so
    the two engines take the same steps and differ by their energies' round-off only.
    (Before, the planes' run stepped on its state's scale: 38 um off the path engine's.)"""
    s, planes = chip_dispensed
    from simulator.motion import simulate

    a = simulate(s, start, "gradient", planes=planes)
    b = simulate(s, start, "gradient", engine="path")
    assert a.footprint is not None and b.footprint is not None
    assert len(a.footprint["initial"]) < 4  # pads dry at the start
    assert [(e["pad"], e["state"], e["step"]) for e in a.footprint["events"]] == [
        (e["pad"], e["state"], e["step"]) for e in b.footprint["events"]
    ]
    assert a.outcome == b.outcome and a.floor == b.floor
    # the energies agree to the noise floor (above), which moves a gradient step by a
    # fraction of a pixel's round-off (measured: 2e-4 px and 0.002 twist steps on these
    # paths), up to the well's flat floor, where the energy is flat to round-off and where
    # the creeping chip stops is round-off's choice: there both runs end on the floor
    step = np.array([s.um_per_px, s.um_per_px, s.twist.step_deg])
    n = min(_until_floor(a), _until_floor(b))
    off = np.abs(np.asarray(a.path[:n]) - np.asarray(b.path[:n])).max(axis=0) / step
    assert n > 10 and (off < 0.01).all(), (n, off)
    on_floor = [_until_floor(t) < len(t.path) for t in (a, b)]
    assert on_floor[0] == on_floor[1]
    if not on_floor[0]:  # stopped before the floor (a plateau): the same steps to the end,
        # but where the chip creeps (steps of a thousandth of a pixel), which creeping step no
        # halving can lower is round-off's choice: 179 against 180 steps on a CPU where OpenCV's
        # IPP takes its AVX-512 code path; so the ends are held together, not the step counts
        assert (np.abs(np.subtract(a.final, b.final)) / step < 0.01).all(), (a.final, b.final)


def _until_floor(tr) -> int:
    """The index of the first pose of ``tr`` on its well's flat floor (len(path): none)."""
    if tr.floor is None:
        return len(tr.path)
    (x0, x1), (y0, y1) = tr.floor["x_um"], tr.floor["y_um"]
    p = np.asarray(tr.path)
    on = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
    return int(np.argmax(on)) if on.any() else len(p)


def test_auto_takes_the_path_engine_for_a_greedy_dispense_run():
    from simulator.motion import footprint_engine

    s = two_pads()
    assert footprint_engine(s, (100.0, 0.0, 0.0), "greedy", "auto") == "path"
    assert footprint_engine(s, (100.0, 0.0, 0.0), "greedy", "fft") == "fft"
    assert footprint_engine(s, (100.0, 0.0, 0.0), "inertial", "auto") == "fft"
    from foundation import InputError

    with pytest.raises(InputError, match="--engine path runs greedy and gradient"):
        footprint_engine(s, (100.0, 0.0, 0.0), "inertial", "path")


def test_cli_dispense_run_on_the_path_engine(run_cli, tmp_path):
    """`simulate --dispense pattern --engine path`: the footprint record and the engine in the
    JSON, no plane priced or built."""
    import json

    from tests.test_footprint_planes import LIB

    out = tmp_path / "run.json"
    rc, stdout, err = run_cli(
        ["simulate", "--pattern", LIB / "four_pad_730_100.png", "--chip-size", "730"]
        + ["--meniscus", "--volume", "20", "--resolution", "10", "--no-twist"]
        + ["--hysteresis", "10:35", "--dispense", "pattern", "--method", "greedy"]
        + ["--start=400,10,0", "--engine", "path", "--quiet", "--json", out]
    )
    assert rc == 0, err
    d = json.loads(out.read_text())
    assert d["cost"]["engine"] == "footprint path"
    assert d["footprint"]["initial"] == [1, 2, 3, 4] and d["outcome"] == "aligned"
    assert "footprint (--dispense pattern)" in stdout


def test_path_footprint_over_its_budget_is_refused(run_cli, tmp_path):
    """A 4000 um chip's stateful path run is priced before any rotator is made: over the
    budget, one line naming the rotators and the fix."""
    from foundation import InputError
    from simulator.landscape import footprint_path_bytes
    from simulator.motion import require_footprint_fits
    from simulator.physics import Liquid
    from simulator.scene import Effects, Scene

    pattern = tmp_path / "fp4k.png"
    rc, _, err = run_cli(
        ["pattern", "four-pad", "--size", "4000", "--gap", "200", "--um-per-px", "4"]
        + ["-o", pattern]
    )
    assert rc == 0, err
    s = Scene.from_inputs(
        pattern,
        chip_size_um=4000,
        effects=Effects(meniscus=True),
        liquid=Liquid(volume_nl=500, dispense="pattern"),
    )
    need = footprint_path_bytes(s) / 2**20
    assert need > 50
    require_footprint_fits(s.replace(memory_budget_mb=need + 1), "path")
    with pytest.raises(InputError, match="on the path engine: the footprint state's rotators") as e:
        require_footprint_fits(s.replace(memory_budget_mb=need / 2), "path")
    assert "--memory-budget" in str(e.value) and "\n" not in str(e.value)
