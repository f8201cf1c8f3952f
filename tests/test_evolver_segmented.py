"""Surface Evolver on the patterns users make (validation/evolver_fourpad.csv,
validation/evolver_defects.csv; made by ``make validate-segmented``; no Evolver needed here).

Two kinds of checks:

* the stored numbers are what they claim: symmetric where the set-up is, converged under
  refinement, forces consistent with the energies, the interior force of the four-pad the
  overlap model's closed form |Delta_gamma| (L - g) (docs/physics.md);
* the finite-meniscus model against them where it claims to agree: pinned single defects
  (pose within 30 % or 0.5 um, with its signs), the four-pad force away from the flat
  part's transitions (10 %), and with free contact lines the flat part that Surface
  Evolver's inward path finds (its onset within 10 um) and the float near alignment. Where
  it does not agree (the inner end of the 730/50 flat part, the outward branch's
  hysteresis, the defects' inward/outward asymmetry), docs/guide/meniscus.md says so with the numbers.
"""

from __future__ import annotations

import csv
import functools
import math
from pathlib import Path

import numpy as np
import pytest

from simulator.landscape import build_landscape, refine_minimum
from simulator.physics import Liquid
from simulator.scene import Effects, Scene, TwistGrid

#: Rerun by make test under each FFT backend (SELFALIGN_FFT_BACKEND; tests/conftest.py).
# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = [pytest.mark.fft, pytest.mark.xdist_group("evolver_segmented")]

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / "patterns" / "library"
GAMMA = 0.072  # N/m, the Evolver runs' surface tension


def _rows(name: str) -> list[dict[str, str]]:
    with (ROOT / "validation" / name).open(newline="") as f:
        return list(csv.DictReader(f))


FOURPAD = _rows(
    "evolver_fourpad.csv"
)  # each pose at its finest level, compared with the next coarser
LEVELS = _rows("evolver_fourpad_levels.csv")  # every pose at every level
DEFECTS = _rows("evolver_defects.csv")


def _path(name: str, level: str = "2") -> list[dict[str, str]]:
    """A continuation path at one refinement level (level 2 is complete for every path)."""
    return sorted(
        (r for r in LEVELS if r["path"] == name and r["level"] == level),
        key=lambda r: float(r["x_um"]),
    )


def _interior_N(gap: float, L: float = 730.0) -> float:
    """The overlap model's force inside a pad, |Delta_gamma| (L - g), at the Evolver runs' gamma (N)."""
    return abs(GAMMA * (math.cos(math.radians(60)) - math.cos(math.radians(30)))) * (L - gap) * 1e-6


# ----------------------------------------------------------------- the four-pad references
def test_fourpad_reference_covers_the_paths_asked_for():
    for gap in (50, 100):
        xs = [float(r["x_um"]) for r in _path(f"x_730_{gap}")]
        assert xs[0] == 0.0 and xs[-1] >= 500.0
        dense = [x for x in xs if 250.0 <= x <= 450.0]
        assert dense[0] <= 250.0 and dense[-1] >= 450.0 and max(np.diff(dense)) <= 10.0 + 1e-9
        r = _path(f"x_730_{gap}")[0]
        assert (
            float(r["L_um"]) == 730
            and float(r["g_um"]) == gap
            and float(r["volume_um3"]) == pytest.approx(2.0e7)
        )
        diag = _path(f"diag_730_{gap}")
        assert float(diag[-1]["x_um"]) == float(diag[-1]["y_um"]) == 300.0
    small = _path("x_200_20")
    assert (
        float(small[0]["L_um"]) == 200
        and float(small[0]["volume_um3"]) == pytest.approx(5.0e5)
        and float(small[-1]["x_um"]) >= 150
    )
    main = [
        r
        for r in FOURPAD
        if r["path"] in ("x_730_50", "x_730_100", "x_200_20", "diag_730_50", "diag_730_100")
    ]
    assert {r["theta_pad_deg"] for r in main} == {"30.0"} and {
        r["theta_sub_deg"] for r in main
    } == {"60.0"}


@pytest.mark.parametrize("gap", [50, 100])
def test_fourpad_force_vanishes_at_alignment_and_equals_the_overlap_slope_inside(gap):
    rows = _path(f"x_730_{gap}")
    inside = _interior_N(gap)
    assert abs(float(rows[0]["force_x_N"])) < 1e-3 * inside  # x = 0: mirror symmetry
    settled = [r for r in rows if r["flag"] != "newton_not_settled"]
    assert all(
        abs(float(r["force_y_N"])) < 1e-2 * inside for r in settled
    )  # no cross force on y = 0
    # Deep inside a pad (more than 2 h from every feature) the meniscus adds nothing: the
    # force is the overlap model's |Delta_gamma| (L - g), to 0.5 %.
    for r in rows:
        if 100 <= float(r["x_um"]) <= 250:
            assert -float(r["force_x_N"]) == pytest.approx(inside, rel=0.005), r["x_um"]


@pytest.mark.parametrize("gap,x0,x1", [(50, 100, 360), (100, 100, 300)])
def test_fourpad_forces_integrate_to_the_energy_difference(gap, x0, x1):
    # Independent numbers: the in-run force (an envelope derivative at each pose) integrated
    # along the path against the converged energies at the ends. A long baseline: each
    # pose's energy carries its own mesh's discretisation error (FOURPAD.md), which a
    # secant between neighbours would turn into a force error of 15 %.
    rows = [r for r in _path(f"x_730_{gap}") if x0 <= float(r["x_um"]) <= x1]
    xs = np.array([float(r["x_um"]) for r in rows]) * 1e-6
    work = -np.trapezoid([float(r["force_x_N"]) for r in rows], xs)
    de = float(rows[-1]["energy_J"]) - float(rows[0]["energy_J"])
    assert de == pytest.approx(work, rel=0.02)


def test_fourpad_730_50_is_converged_under_refinement():
    # Levels 2 and 3 at the poses run at both (8 of them): the force changes by less than
    # 0.4 uN of 17.9 (either force method: the envelope derivative, or central differences
    # of Newton-relaxed energies), the dip included.
    lv3 = [r for r in LEVELS if r["path"] == "x_730_50" and r["level"] == "3"]
    lv2 = {float(r["x_um"]): r for r in _path("x_730_50")}
    assert len(lv3) >= 8
    for r in lv3:
        q = lv2[float(r["x_um"])]
        change = min(abs(float(r[k]) - float(q[k])) for k in ("force_x_N", "force_x_fd_N"))
        assert change < 0.4e-6, (r["x_um"], change)


def test_fourpad_730_50_has_no_zero_force_part_and_its_dip_lies_beyond_the_overlap_flat_part():
    # What Surface Evolver finds with free contact lines: the overlap model's flat part
    # (340-390 um) becomes a dip of the force, shifted outwards (the liquid stays on the pads
    # the chip has left, then lets go), which keeps more than 60 % of the interior force.
    rows = _path("x_730_50")
    inside = _interior_N(50)
    near = [
        (float(r["x_um"]), -float(r["force_x_N"])) for r in rows if 330 <= float(r["x_um"]) <= 500
    ]
    x_min, f_min = min(near, key=lambda t: t[1])
    assert f_min > 0.6 * inside and 400 <= x_min <= 450


@pytest.mark.parametrize("gap", [50, 100])
def test_fourpad_liquid_stays_on_the_far_pads_past_the_overlap_flat_part_onset(gap):
    # The force keeps 90 % of its interior value past the overlap model's onset
    # p = (L - g) / 2 by more than 0.7 h, while the far pads stay wetted.
    rows = _path(f"x_730_{gap}")
    p = (730 - gap) / 2
    inside = _interior_N(gap)
    h = float(rows[0]["chip_height_um"])
    full = [
        r
        for r in rows
        if p < float(r["x_um"]) < p + 2 * h and -float(r["force_x_N"]) > 0.9 * inside
    ]
    assert full and max(float(r["x_um"]) for r in full) >= p + 0.7 * h
    assert all(r["left_pads_wetted"] == "True" for r in full)


INWARD = _rows("evolver_fourpad_inward.csv")


@pytest.mark.parametrize("gap,lo,hi", [(50, 370, 410), (100, 350, 420)])
def test_fourpad_coming_inward_the_chip_meets_a_flat_part_the_outward_path_does_not(gap, lo, hi):
    # The far pads' wetting has hysteresis. Coming inward from x = 500 um (the way a misplaced
    # chip moves) the liquid has not reached the left pads: its trailing contact line rides
    # on the gap, about 25 um beyond the chip edge, and nothing changes with x there, so the
    # force is near zero: a flat part, shifted outwards from the overlap model's (p to p + g)
    # by about that reach. Going outward the liquid still holds the left pads there and pulls.
    inward = {
        float(r["x_um"]): r
        for r in INWARD
        if r["path"] == f"x_730_{gap}_inward" and r["level"] == "1"
    }
    outward = {float(r["x_um"]): r for r in _path(f"x_730_{gap}", "1")}
    inside = _interior_N(gap)
    for x, r in inward.items():
        if lo <= x <= hi:
            assert (
                abs(float(r["force_x_N"])) < 0.15 * inside and r["left_pads_wetted"] == "False"
            ), x
        if 100 <= x <= 330:  # both branches wet every pad: the same force
            assert float(r["force_x_N"]) == pytest.approx(
                float(outward[x]["force_x_N"]), abs=0.04 * inside
            ), x
    assert (
        max(-float(outward[x]["force_x_N"]) for x in inward if lo <= x <= hi) > 0.3 * inside
    )  # outward still pulls there


# ----------------------------------------------------------------- the four-pad model comparison
@functools.cache
def _fourpad_landscapes(gap: int):
    base = Scene.from_inputs(
        LIB / f"four_pad_730_{gap}.png",
        chip_size_um=730,
        resolution_um=2.0,
        effects=Effects(twist=False),
        liquid=Liquid(volume_nl=20.0),
        window_um=520,
        dtype="float64",
    )
    return build_landscape(base.replace(effects=Effects(twist=False, meniscus=True)))


@pytest.mark.parametrize("gap", [50, 100])
def test_meniscus_model_within_10_percent_of_evolver_away_from_the_transitions(gap):
    ls = _fourpad_landscapes(gap)
    checked = 0
    p, h = (730 - gap) / 2, 37.5
    for r in _path(f"x_730_{gap}"):
        x = float(r["x_um"])
        if (
            100 <= x <= p - 2 * h or x >= p + gap + 2 * h + 25
        ):  # more than 2 h from the centre's rounding and the dip
            model = -float(ls.force_at(x, 0.0, 0.0)[0])
            assert model == pytest.approx(-float(r["force_x_N"]), rel=0.10), x
            checked += 1
    assert checked >= 6


def _inward(gap: int) -> dict[float, float]:
    """Surface Evolver's inward continuation (level 1): restoring force -F_x (N) by x (um),
    x = 0 left out (not relaxed after the last 50 um step, validation/FOURPAD_INWARD.md)."""
    return {
        float(r["x_um"]): -float(r["force_x_N"])
        for r in INWARD
        if r["path"] == f"x_730_{gap}_inward" and r["level"] == "1" and float(r["x_um"]) > 1
    }


def _onset(xs, fs, level: float) -> float:
    """Coming inward (x decreasing), the first x where the force falls below ``level``, by
    linear interpolation between samples."""
    pts = sorted(zip(xs, fs, strict=True), reverse=True)
    for (xa, fa), (xb, fb) in zip(pts, pts[1:], strict=False):
        if fa >= level > fb:
            return xb + (xa - xb) * (level - fb) / (fa - fb)
    raise AssertionError("the force never falls below the level")


@pytest.mark.parametrize("gap,least", [(50, 4.0), (100, 40.0)])
def test_meniscus_model_has_the_flat_part_where_evolver_has_one_and_its_onset_within_10_um(
    gap, least
):
    # Free contact lines (the wall profile, simulator/meniscus.py): on the gap the trailing
    # line stands on the substrate and nothing changes with x, so the force is zero there, as
    # in Surface Evolver's inward path. The onset, where the force coming inward falls
    # through half its interior value, within 10 um of Surface Evolver's. (The flat part ends
    # earlier than Surface Evolver's on the inner side: the model's far pads start pulling
    # when they come within the pad reach d_p, Surface Evolver's line snaps onto them at the
    # substrate reach d_s; on 730/50 that leaves 4 um of the 35 um, meniscus.py says why.)
    ls = _fourpad_landscapes(gap)
    inside = _interior_N(gap)
    xs = np.arange(250.0, 500.0, 2.0)
    model = np.array([-float(ls.force_at(x, 0.0, 0.0)[0]) for x in xs])
    flat = xs[np.abs(model) < 1e-3 * inside]
    assert flat.size and flat.max() - flat.min() >= least
    assert np.all(
        np.abs(model[(xs >= flat.min()) & (xs <= flat.max())]) < 1e-3 * inside
    )  # one flat part, no dips in it
    se = _inward(gap)
    assert all(
        abs(se[x]) < 0.15 * inside for x in se if flat.min() <= x <= flat.max()
    )  # Surface Evolver is flat there too
    m_on, s_on = _onset(xs, model, 0.5 * inside), _onset(list(se), list(se.values()), 0.5 * inside)
    assert abs(m_on - s_on) <= 10.0, (m_on, s_on)
    # The overlap model's flat part (p to p + g) ends about the line's reach further in.
    p = (730 - gap) / 2
    assert p + gap + 10 <= flat.max() <= p + gap + 40


@pytest.mark.parametrize("gap", [50, 100])
def test_meniscus_model_follows_evolver_inward_off_the_transitions_and_near_alignment(gap):
    ls = _fourpad_landscapes(gap)
    inside = _interior_N(gap)
    se = _inward(gap)
    for x, f in se.items():
        model = -float(ls.force_at(x, 0.0, 0.0)[0])
        if 100 <= x <= 330 or x >= 475:  # every line on one surface: the plateau force
            assert model == pytest.approx(f, rel=0.10), x
    # Near alignment the lines stand on the substrate beyond the pattern: no force within
    # the reach d_s = h cot(60 deg), then a pad edge takes the line (Surface Evolver, outward:
    # 2.4-2.5 uN at 25 um, 13.0-13.4 uN at 50 um).
    out = {float(r["x_um"]): -float(r["force_x_N"]) for r in _path(f"x_730_{gap}")}
    assert -float(ls.force_at(10.0, 0.0, 0.0)[0]) == 0.0
    assert -float(ls.force_at(25.0, 0.0, 0.0)[0]) == pytest.approx(out[25.0], abs=0.05 * inside)
    assert -float(ls.force_at(50.0, 0.0, 0.0)[0]) == pytest.approx(out[50.0], rel=0.15)


def test_free_contact_line_model_at_vanishing_height_is_the_overlap_landscape():
    base = Scene.from_inputs(
        LIB / "four_pad_730_50.png",
        chip_size_um=730,
        resolution_um=10.0,
        effects=Effects(twist=False),
        liquid=Liquid(height_um=1e-9),
        window_um=100,
        dtype="float64",
    )
    off, on = (
        build_landscape(base),
        build_landscape(base.replace(effects=Effects(twist=False, meniscus=True))),
    )
    assert on.meniscus_height_um == pytest.approx(1e-9) and not base.liquid.pinned
    assert np.max(np.abs(on.energy - off.energy)) <= 1e-12 * np.abs(off.energy).max()


# ----------------------------------------------------------------- the pinned defects
def test_defect_reference_is_symmetric_where_the_set_up_is():
    assert len(DEFECTS) == 14
    for r in DEFECTS:
        x, y, t = float(r["x_um"]), float(r["y_um"]), float(r["twist_deg"])
        if r["defect"] == "none":
            assert max(abs(x), abs(y), abs(t)) < 1e-6
        elif r["defect"] in ("A", "C"):  # middle defects: mirror symmetric about y = 0
            assert abs(y) < 1e-4 and abs(t) < 1e-3
            assert (x > 0) == (r["kind"] == "outward")
        assert (
            float(r["force_rel_2gL"]) < 1e-3 and float(r["torque_rel_2gL2"]) < 1e-3
        )  # an equilibrium
        assert (
            max(abs(float(r["dx_last_um"])), abs(float(r["dy_last_um"]))) < 0.01
            or r["defect"] == "none"
        )


def test_evolver_puts_an_inward_defect_nearer_the_centre_than_an_outward_one():
    pose = {(r["defect"], r["kind"], r["volume_nl"]): abs(float(r["x_um"])) for r in DEFECTS}
    for d in "ABC":
        for v in ("0.5", "0.9"):
            assert pose[(d, "inward", v)] < pose[(d, "outward", v)], (d, v)


@functools.cache
def _defect_minimum(d: str, kind: str, volume_nl: float) -> dict:
    sc = Scene.from_inputs(
        LIB / f"defect_{d}_{kind}.png",
        chip_size_um=200,
        effects=Effects(meniscus=True),
        liquid=Liquid(volume_nl=volume_nl, pinned=True),
        twist=TwistGrid(0.25, -3, 3),
        window_um=12,
        dtype="float64",
    )
    ls = build_landscape(sc)
    return refine_minimum(ls, *ls.global_minimum()[:3])


@pytest.mark.parametrize(
    "row",
    [r for r in DEFECTS if r["defect"] != "none"],
    ids=lambda r: f"{r['defect']}-{r['kind']}-{r['volume_nl']}nl",
)
def test_meniscus_model_puts_each_defect_minimum_where_evolver_does(row):
    m = _defect_minimum(row["defect"], row["kind"], float(row["volume_nl"]))
    for key, tol_abs in (("x_um", 0.5), ("y_um", 0.5), ("twist_deg", 0.1)):
        se = float(row[key])
        assert abs(m[key] - se) <= max(tol_abs, 0.3 * abs(se)), (key, m[key], se)
        if abs(se) > tol_abs:
            assert np.sign(m[key]) == np.sign(se), key
