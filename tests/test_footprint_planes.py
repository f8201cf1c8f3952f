"""The footprint state's planes (docs/physics.md §3.5): the shadow rule between pads behind
one another (a near pad's strip under the bridge to a far pad has no line of its own), in
closed form on a synthetic two-pad pattern and on the bench's 730/100 four-pad, and the
shared-rotation build against pad-by-pad builds of the same footprints."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from patterns.geometry import Mask, pad_labels
from simulator.landscape import _footprint as fp, build_footprint_planes, build_landscape
from simulator.landscape._build import scene_extent
from simulator.landscape._correlator import NOISE_FACTOR
from simulator.landscape._footprint import _variant, footprint_pairs
from simulator.motion import simulate
from simulator.physics import STEP_PX, TOUCH_PX2, FootprintRules, Liquid, Materials
from simulator.physics._footprint import shadow_residual_deg, upstream_along, upstream_of
from simulator.scene import Effects, Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("footprint_planes")

LIB = Path(__file__).resolve().parents[1] / "patterns" / "library"
PX = 5.0


def two_pads(gap_um: float = 40.0) -> Scene:
    """Two 200 x 200 um pads in a row, ``gap_um`` apart, centred on the pattern (5 um/px),
    under a 300 um chip with a 20 um meniscus (1.8 nl), pads 30 deg receding at 10 deg."""
    d = np.zeros((60, 120))
    g = int(gap_um / 2 / PX)
    d[10:50, 60 + g : 100 + g] = 1  # pad 2: x in [gap/2, gap/2 + 200] um, y in [-100, 100] um
    d[10:50, 20 - g : 60 - g] = 1  # pad 1: its mirror image
    return Scene.from_inputs(
        Mask(d, PX),
        chip_size_um=300,
        effects=Effects(twist=False, meniscus=True, hysteresis=True),
        materials=Materials(pad_receding_deg=10.0, pad_advancing_deg=35.0),
        liquid=Liquid(volume_nl=1.8, dispense="pattern"),
    )


def fourpad(res: float, twist: bool = False, chip_um=730) -> Scene:
    return Scene.from_inputs(
        LIB / "four_pad_730_100.png",
        chip_size_um=chip_um,
        resolution_um=res,
        effects=Effects(twist=twist, meniscus=True, hysteresis=True),
        materials=Materials(pad_receding_deg=10.0, pad_advancing_deg=35.0),
        liquid=Liquid(volume_nl=20.0, dispense="pattern"),
    )


@pytest.fixture(scope="module")
def two():
    s = two_pads()
    return s, build_footprint_planes(s)


def _pair_plane(planes, near: int, far: int) -> np.ndarray:
    e = np.zeros(planes.template.energy.shape, planes.template.energy.dtype)
    for p in planes.pairs:
        if (p.near, p.far) == (near, far):
            e[p.box()] += p.energy
    return e


def test_upstream_of_follows_each_axis():
    pad = np.zeros((5, 6))
    pad[2, 3] = 1
    # +x: the pixels left of the pad on its row; -x: right of it; +y (up): rows below; -y: above
    assert np.argwhere(upstream_of(pad, 0)).tolist() == [[2, 0], [2, 1], [2, 2]]
    assert np.argwhere(upstream_of(pad, 2)).tolist() == [[2, 4], [2, 5]]
    assert np.argwhere(upstream_of(pad, 1)).tolist() == [[3, 3], [4, 3]]
    assert np.argwhere(upstream_of(pad, 3)).tolist() == [[0, 3], [1, 3]]


def test_upstream_along_follows_the_ray_and_mirrors():
    rng = np.random.default_rng(7)
    for w in (10, 11):  # even and odd widths: the rays are measured from the image's centre
        pad = rng.random((9, w)) > 0.8
        for k in range(4):  # along the axes, exactly the axis rule
            assert (upstream_along(pad, 90.0 * k) == upstream_of(pad, k)).all()
        for a in (2.0, 17.0, 44.0):  # the mirrored image's rays are the mirrored rays
            assert (upstream_along(pad[::-1], -a) == upstream_along(pad, a)[::-1]).all()
    one = np.zeros((9, 9), bool)
    one[2, 6] = True
    up = upstream_along(one, 45.0)
    # the pixel centres on the 45 deg line through the pad, before it, are upstream; none after
    assert all(up[2 + k, 6 - k] for k in range(1, 7)) and not up[1, 7] and not up[2, 6]


def test_the_shadow_turns_with_the_chip_side_in_steps():
    # the twist less its nearest quarter turn, rounded to the 2 deg step, in [-45, 45]
    got = shadow_residual_deg([0.0, 0.9, 1.1, 44.0, 46.0, -46.0, 89.4, 135.0])
    assert got.tolist() == [0.0, 0.0, 2.0, 44.0, -44.0, 44.0, 0.0, -44.0]


def test_two_pads_in_a_row_shadow_each_other_along_x(two):
    _, planes = two
    # pad 2 (right) lies upstream of pad 1 along -x, pad 1 upstream of pad 2 along +x
    assert sorted((p.near, p.far, p.axis) for p in planes.pairs) == [(0, 1, 0), (1, 0, 2)]


@pytest.mark.fft
def test_the_pair_term_is_the_near_strip_counted_whole_up_to_the_band(two):
    # Chip at X (um) on y = 0: its left edge at X - 150, pad 2's near edge at 20 um, so a strip
    # of pad 2 w = X - 170 wide lies outside the chip, under the bridge to pad 1 (wet, the
    # chip has left it across D = X - 130 um, within d_r). On the pixel lattice at twist 0 the term is
    # exactly Delta_gamma px^2 * 40 rows * sum over the strip's columns of N_b(s) - f(s),
    # s = 0.5, 1.5, ... px from the chip's outline (f the wall profile, N_b the count to the band).
    s, planes = two
    r = planes.rules
    c = r.count_profiles()
    jp = planes.template.joules_per_px2
    pair = _pair_plane(planes, 1, 0)
    # the FFT round-off bound, NOISE_FACTOR eps(dtype) of the plane's max |E| (rel= of the
    # value was tighter at the narrow strips, 1/6 of the plane's scale; an exact 0 held on
    # OpenCV's transforms only, SciPy's and JAX's leave -4e-18 J, 0.05 eps of the scale)
    floor = NOISE_FACTOR * float(np.finfo(s.dtype).eps) * float(np.abs(pair).max())
    for x_um in (210.0, 220.0, 230.0, 240.0):
        node = planes.node((x_um, 0.0, 0.0))
        si = np.arange(int(round((x_um - 170.0) / PX))) + 0.5
        n_b = 0.5 * (c["band_in"](si) + c["band_out"](si))
        expect = jp * 40 * float(np.sum(n_b - r.profile(si)))
        assert pair[node] == pytest.approx(expect, rel=0, abs=floor)
    # where the near pad's strip is within d_s of the chip, f = 1 = N_b: nothing to correct
    assert abs(pair[planes.node((170.0 + PX * int(r.d_s), 0.0, 0.0))]) <= floor


def test_a_near_pad_under_the_bridge_pulls_once(two):
    # Both pads wet, the chip covering pad 2 with a strip beyond d_p outside it and pad 1 left
    # behind across a gap under d_r: one wetted region, one line, at pad 1. The force is the
    # single edge's, |Delta_gamma| times pad 1's height (200 um); without the pair term pad 2's
    # own trailing line pulls as much again.
    s, planes = two
    wet = np.ones(2, bool)
    single = -abs(s.delta_gamma_N_m) * 200e-6
    ls = planes.landscape(wet)
    ls0 = dataclasses.replace(planes, pairs=()).landscape(wet)
    eps = float(np.finfo(s.dtype).eps)
    for x_um in (215.0, 225.0, 235.0):
        assert planes.next_state(wet, (x_um, 0.0, 0.0)).all()
        # energies ~ |dg| * 8,000 px^2, differences over 2 px ~ |dg| * 80 px^2: their round-off
        tol = NOISE_FACTOR * eps * 8000 / 80
        assert ls.force_at(x_um, 0.0, 0.0)[0] == pytest.approx(single, rel=tol)
        assert ls0.force_at(x_um, 0.0, 0.0)[0] == pytest.approx(2 * single, rel=tol)


def test_no_shadow_across_a_gap_the_rays_do_not_cross():
    # the two pads offset in y by more than their height: no ray along x or y joins them
    d = np.zeros((100, 120))
    d[5:45, 64:104] = 1
    d[55:95, 16:56] = 1
    s = two_pads().replace(pattern=Mask(d, PX))
    assert build_footprint_planes(s).pairs == ()


@pytest.fixture(scope="module")
def bench():
    s = fourpad(5.0)
    return s, build_footprint_planes(s)


def test_bench_730_100_beyond_436um_pulls_with_the_single_edge(bench):
    # The source's bench case at 5 um/px (730/100, 20 nl, pads receding at 10 deg), dispensed on
    # the pattern: beyond 436 um the near pads' strip outside the chip passes d_s, and under the
    # bridge to the wet far pads it has no line; the force is |Delta_gamma| times the far pads'
    # edge facing the chip, 2 x 315 um (one pixel row of it: the grid's resolution).
    s, planes = bench
    wet = np.ones(planes.n_pads, bool)
    single = -abs(s.delta_gamma_N_m) * 630e-6
    ls = planes.landscape(wet)
    ls0 = dataclasses.replace(planes, pairs=()).landscape(wet)
    for x_um in (440.0, 460.0, 480.0, 500.0, 520.0):
        assert planes.next_state(wet, (x_um, 0.0, 0.0)).all()  # the far pads stay wet
        f = ls.force_at(x_um, 0.0, 0.0)[0]
        assert f == pytest.approx(single, rel=PX / 630.0)
    # the defect the rule removes: twice the interior force once the strip passes d_p
    assert ls0.force_at(500.0, 0.0, 0.0)[0] == pytest.approx(2 * single, rel=PX / 630.0)


def test_bench_pairs_are_the_row_and_column_neighbours(bench):
    _, planes = bench
    labels, n = pad_labels(fourpad(5.0).pattern)
    centres = planes.pad_centre_um
    got = sorted((p.near, p.far) for p in planes.pairs)
    # each pad with the pads level with it in x or in y, never the diagonal one
    want = sorted(
        (a, b)
        for a in range(n)
        for b in range(n)
        if a != b
        and (abs(centres[a][0] - centres[b][0]) < 1.0 or abs(centres[a][1] - centres[b][1]) < 1.0)
    )
    assert got == want and len(got) == 8


def _reference(
    scene: Scene, twists=None
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]]:
    """The planes built pad by pad, one build_landscape per pad and footprint (the planes'
    definition, docs/physics.md §3.5): per pad, wet energy, reached, within, the covered count
    and the band's offset c."""
    assert scene.wall_profile is not None
    rules = FootprintRules.of(scene.wall_profile, scene.materials.pad_receding_deg)
    counts = rules.count_profiles()
    extent = scene_extent(_variant(scene, scene.pattern, counts["band_out"]))
    labels, n = pad_labels(scene.pattern)
    out = []
    for k in range(1, n + 1):
        pad = Mask(np.where(labels == k, scene.pattern.data, 0.0), scene.um_per_px)

        def build(profile, pad=pad):
            return build_landscape(_variant(scene, pad, profile), twists=twists, extent=extent)

        wall = build(scene.wall_profile)
        jp = wall.joules_per_px2
        cnt = {nm: build(counts[nm]).energy / jp for nm in counts}
        c = (rules.band_px - rules.f_inf) / STEP_PX
        bridged = jp * ((0.5 + c) * cnt["band_in"] + (0.5 - c) * cnt["band_out"])
        rows, cols = np.nonzero(labels == k)
        deep = min(np.ptp(rows), np.ptp(cols)) + 1 >= rules.band_px + 2 * STEP_PX
        # a pad narrower than the band keeps the wall term (its far edge would lie in the band)
        e = np.where(deep & (cnt["covered"] < TOUCH_PX2), bridged, wall.energy)
        out.append((e, cnt["reached"], cnt["within"], cnt["covered"], c))
    return out


#: A band of twists about 0 (their mirror twins among them) at 12 um/px, fine enough for the
#: bridged term (the pads deeper than its band).
TWISTS = np.arange(-4.0, 5.0)


@pytest.mark.parametrize("res, twists", [(10.0, None), (12.0, TWISTS)])
def test_the_shared_build_equals_pad_by_pad_builds(res, twists):
    # One rotation per footprint and twist for every pad, each pad on its own box of poses:
    # the same planes as one build_landscape per pad and footprint over the whole grid, to
    # the transforms' round-off (the bridged term weighs its two counts by c ~ 20: c times the
    # noise floor), and the same flags wherever a count is not within round-off of the threshold.
    s = fourpad(res, twists is not None)
    planes = build_footprint_planes(s, twists=twists)
    ref = _reference(s, twists)
    eps = float(np.finfo(s.dtype).eps)
    for k, (e, reached, within, covered, c) in enumerate(ref):
        scale = float(np.abs(e).max())
        near_count = NOISE_FACTOR * eps * max(float(covered.max()), 1.0)
        # the wall/bridged switch not on a knife edge
        clear = np.abs(covered - TOUCH_PX2) > near_count
        diff = np.abs(planes.wet_energy[k] - e)
        assert diff[clear].max() <= (2 * c + 1) * NOISE_FACTOR * eps * scale
        for got, cnt in ((planes.reached[k], reached), (planes.within_reach[k], within)):
            sure = np.abs(cnt - TOUCH_PX2) > NOISE_FACTOR * eps * max(float(cnt.max()), 1.0)
            assert np.array_equal(got[sure], cnt[sure] >= TOUCH_PX2)


def test_the_state_energy_is_mirror_symmetric_with_its_pairs():
    # The four-pad and the square chip are symmetric about y = 0: E(x, y, -a) = E(x, -y, a) for
    # every state, the pairs along x and along y (the twins' planes come from their partners'
    # transforms: sides +y and -y swap under the mirror).
    s = fourpad(12.0, twist=True)
    planes = build_footprint_planes(s, twists=TWISTS)
    e = planes.energy(np.ones(planes.n_pads, bool))
    tw = planes.template.twist_deg
    scale = float(np.abs(e).max())
    eps = float(np.finfo(s.dtype).eps)
    pairs_only = np.zeros_like(e)
    for p in planes.pairs:
        pairs_only[p.box()] += p.energy
    assert np.abs(pairs_only).max() > 0.01 * scale  # the pairs are there to be tested
    for i in range(len(tw)):
        j = int(np.argmin(np.abs(tw + tw[i])))
        if abs(tw[j] + tw[i]) > 1e-9:
            continue
        assert np.abs(e[j] - e[i][::-1]).max() <= 2 * NOISE_FACTOR * eps * scale
        assert np.abs(pairs_only[j] - pairs_only[i][::-1]).max() <= 2 * NOISE_FACTOR * eps * scale


@pytest.mark.parametrize("threads", ["1", "2", "4"])
def test_a_state_summed_in_blocks_of_twists_is_the_plain_sum(monkeypatch, threads):
    # FootprintPlanes.energy sums a state's planes in blocks of twists, one per thread: the
    # same terms in the same order at every pose, so the same floats as one pass over the
    # whole grid, for every state; blocks that cut a pair's twists, and a pair whose twists
    # are not in a row (added through their indices)
    monkeypatch.setenv("SELFALIGN_THREADS", threads)
    s = fourpad(12.0, twist=True)
    planes = build_footprint_planes(s, twists=TWISTS)
    p0 = planes.pairs[0]
    keep = np.arange(0, len(p0.twists), 2)  # every other twist: not a run
    assert len(keep) > 1
    scattered = dataclasses.replace(p0, energy=p0.energy[keep], twists=np.asarray(p0.twists)[keep])
    assert not isinstance(scattered.box()[0], slice)
    planes = dataclasses.replace(planes, pairs=(scattered, *planes.pairs[1:]))
    n_pads = planes.n_pads
    for bits in range(2**n_pads):
        wet = np.array([(bits >> k) & 1 for k in range(n_pads)], bool)
        plain = np.zeros(planes.template.energy.shape, planes.template.energy.dtype)
        for k in np.flatnonzero(wet):
            plain += planes.wet_energy[k]
        for p in planes.pairs:
            if wet[p.near] and wet[p.far]:
                plain[p.box()] += p.energy
        assert np.array_equal(planes.energy(wet), plain)


def test_the_pairs_are_priced_before_they_are_made(bench):
    # footprint_pairs lays the pairs' boxes out from the chip's half-widths, no rotation: as
    # many pairs as the build makes, and at least the poses it keeps (the build's boxes come
    # from the chip's signed distance, inside the priced ones), by no more than their margins
    s, planes = bench
    n_pairs, priced, per_twist = footprint_pairs(s)
    kept = sum(p.energy.size for p in planes.pairs)
    assert n_pairs == len(planes.pairs)
    assert per_twist == math.prod(planes.template.energy.shape[1:])
    assert kept <= priced <= 1.25 * kept


def test_no_local_minimum_where_a_corner_reaches_the_far_pad():
    # 730/50 at a 36 deg twist, every pad wet: the chip's corner covers the far pad (0) while
    # the rays from its facing side still cross the near pads' strips to it. The bridge to the
    # far pad does not break when the corner reaches it, so the near strips stay counted whole:
    # dropping the pairs' corrections there raised the energy by 0.24 nJ one step further in,
    # and greedy stopped in that step's well (the capture grid's 96 of 625 local minima).
    s = Scene.from_inputs(
        LIB / "four_pad_730_50.png",
        chip_size_um=730,
        resolution_um=5.0,
        effects=Effects(twist=True, meniscus=True),
        liquid=Liquid(volume_nl=20.0, dispense="pattern"),
        twist=TwistGrid(step_deg=3.0),
    )
    t = simulate(s, (180.0, -275.0, 36.0), "greedy")
    assert t.outcome == "aligned"
    assert abs(t.path[-1][2]) <= 3.0 + 1e-9


@pytest.mark.parametrize("chip_um, share", [(730, 4), ((730, 500), 2)])
def test_a_pattern_a_quarter_turn_takes_onto_itself_reuses_its_planes_turned(
    monkeypatch, chip_um, share
):
    # The four-pad under a square chip: a quarter turn takes every pad onto the next, every
    # pair onto another and each twist's chip onto itself (its rasters to their float64
    # round-off, its sides shifted by one), so three pads' planes and three pairs in four are
    # another's turned; under a 730 x 500 um chip only a half turn leaves the chip as it is,
    # and half of them are. The mirror y -> -y (then a turn) takes a pair at a twist onto
    # another at the opposite twist: fewer pairs still are transformed. Every build's planes
    # are those of a build that transforms every part, to the transforms' round-off (the
    # bridged term weighs its counts by c: c times it).
    s = fourpad(12.0, twist=True, chip_um=chip_um)
    calls = {"n": 0}
    correlate = fp._Part.correlate

    def counted(self, *args, **kwargs):
        calls["n"] += 1
        return correlate(self, *args, **kwargs)

    turns, mirror = fp._pattern_turns, fp._pattern_mirror

    def build(with_turns: bool, with_mirror: bool):
        monkeypatch.setattr(fp, "_pattern_turns", turns if with_turns else lambda *a: {})
        monkeypatch.setattr(fp, "_pattern_mirror", mirror if with_mirror else lambda *a: None)
        calls["n"] = 0
        planes = build_footprint_planes(s, twists=TWISTS)
        return planes, calls["n"]

    monkeypatch.setattr(fp._Part, "correlate", counted)
    direct, n_direct = build(False, False)
    turned, n_turned = build(True, False)
    mirrored, n_mirrored = build(False, True)
    both, n_both = build(True, True)
    assert share * n_turned == n_direct  # a quarter (a half) of the transforms
    # the mirror saves pairs' transforms (the 730 x 500 um chip has no pairs at these twists)
    assert not direct.pairs or (n_mirrored < n_direct and n_both < n_turned)
    assert s.wall_profile is not None
    rules = FootprintRules.of(s.wall_profile, s.materials.pad_receding_deg)
    c = abs(rules.band_px - rules.f_inf) / STEP_PX
    eps = float(np.finfo(s.dtype).eps)
    scale = float(np.abs(direct.wet_energy).max())
    diff = np.abs(turned.wet_energy - direct.wet_energy)
    assert 0 < diff.max() <= 2 * (2 * c + 1) * NOISE_FACTOR * eps * scale  # turned, not copied
    assert share == 2 or len(turned.pairs) >= 8  # the square chip's pairs are there to test
    # the mirror makes pairs only: the pads' planes are the direct or the turned ones exactly
    np.testing.assert_array_equal(mirrored.wet_energy, direct.wet_energy)
    np.testing.assert_array_equal(both.wet_energy, turned.wet_energy)
    for planes in (turned, mirrored, both):
        assert len(planes.pairs) == len(direct.pairs)
        for p, q in zip(planes.pairs, direct.pairs, strict=True):
            assert (p.near, p.far, p.axis, p.y0, p.x0) == (q.near, q.far, q.axis, q.y0, q.x0)
            np.testing.assert_array_equal(p.twists, q.twists)
            assert np.abs(p.energy - q.energy).max() <= 2 * NOISE_FACTOR * eps * scale
    # and the state's energy is turned onto itself by a quarter (a half) turn, pairs and all
    e = both.energy(np.ones(both.n_pads, bool))
    assert np.abs(np.rot90(e, 4 // share, axes=(1, 2)) - e).max() <= 2 * NOISE_FACTOR * eps * scale


def test_the_sides_of_a_square_chip_turn_and_mirror_onto_one_another():
    # A 41 px square on a 61 px canvas: each canvas pixel's side is the axis nearest its
    # outward normal; a pixel on a corner's diagonal is a tie, half on each of its two sides.
    # Outside the chip, a quarter turn shifts every side by one and keeps the ties, a mirror
    # maps each side's weights onto the mirrored side's; every pixel's weights sum to 1.
    from types import SimpleNamespace

    from scipy.ndimage import distance_transform_edt

    from simulator.landscape._footprint import _Sides, side_weights

    chip = np.zeros((61, 61), bool)
    chip[10:51, 10:51] = True
    sdf = distance_transform_edt(~chip) - distance_transform_edt(chip)
    sides = _Sides(SimpleNamespace(_sdf=sdf, shape=sdf.shape, _half=None))
    bins, ties = sides.bins, sides.ties
    rows, cols = np.mgrid[0:61, 0:61] - 30
    diagonal = np.abs(rows) == np.abs(cols)
    corner = (np.abs(rows) > 20) & (np.abs(cols) > 20)
    assert not ties[~diagonal].any() and ties[diagonal & corner].all()
    # a quarter turn counter-clockwise on the page (image rows run down) takes each pixel's
    # side to where the next side counter-clockwise lies: the turned sides are one short
    out = ~chip  # where the strips lie (inside, the centre's normal is undefined)
    assert np.array_equal(np.rot90(bins)[out], ((bins - 1) % 4)[out])
    assert np.array_equal(np.rot90(ties), ties)
    w = np.stack([side_weights(bins, ties, k) for k in range(4)])
    np.testing.assert_array_equal(w.sum(axis=0), 1.0)
    assert set(np.unique(w[:, ties])) == {0.0, 0.5}
    # the mirror y -> -y takes side k (normal at k * 90 deg) to side -k
    for k in range(4):
        np.testing.assert_array_equal(w[k][::-1][out], w[(-k) % 4][out])
    # and x -> -x takes side k to side 2 - k
    for k in range(4):
        np.testing.assert_array_equal(w[k][:, ::-1][out], w[(2 - k) % 4][out])


def test_the_pattern_turns_are_those_of_comparing_every_pad_with_every_pad():
    # _pattern_turns compares a pad only with the pads whose box is its box turned, and
    # _pattern_mirror with those on its box upside down: on 300 small random patterns (a pad,
    # some of its turned images, sometimes a stray pixel, some not square) they find what
    # comparing every pad's whole image with every other's finds.
    from types import SimpleNamespace

    from scipy.ndimage import label

    from simulator.landscape._turns import _pattern_mirror, _pattern_turns, _turn_image

    def every_pair(masks, data):
        valued = [np.where(mk, data, 0.0) for mk in masks]
        out = {}
        for m in (1, 2, 3):
            if m % 2 and data.shape[0] != data.shape[1]:
                continue
            image = []
            for v in valued:
                hit = [k for k, w in enumerate(valued) if np.array_equal(_turn_image(v, m), w)]
                if not hit:
                    break
                image.append(hit[0])
            else:
                out[m] = image
        return out

    rng = np.random.default_rng(0)
    grid = SimpleNamespace(shape=(1, 11, 11), x_first_px=-5, y_first_px=-5)
    found = mirrors = 0
    for _ in range(300):
        h = int(rng.integers(6, 14))
        w = h if rng.random() < 0.7 else int(rng.integers(6, 14))
        a = np.zeros((h, w))
        r0, c0 = rng.integers(0, h // 2), rng.integers(0, w // 2)
        a[r0 : r0 + 2, c0 : c0 + 3] = rng.choice([1.0, 0.5])
        for m in rng.choice([0, 1, 2, 3], size=int(rng.integers(0, 4))):
            if m and (m % 2 == 0 or h == w):
                a = np.maximum(a, _turn_image(a, int(m)))
        if rng.random() < 0.2:
            a[rng.integers(0, h), rng.integers(0, w)] = 1.0
        lab, n = label(a > 0)
        masks = [lab == k for k in range(1, n + 1)]
        want = every_pair(masks, a)
        assert _pattern_turns(masks, a, grid) == want
        found += bool(want)
        # and the mirror y -> -y likewise: each pad's whole image upside down against all
        valued = [np.where(mk, a, 0.0) for mk in masks]
        upside = [[k for k, w in enumerate(valued) if np.array_equal(v[::-1], w)] for v in valued]
        mirror_want = [h[0] for h in upside] if all(upside) else None
        assert _pattern_mirror(masks, a, grid) == mirror_want
        mirrors += mirror_want is not None
    assert found >= 50 and mirrors >= 20  # the symmetric ones are there to be found
