"""Exact pattern geometry: analytic areas, conventions, symmetry and bad input."""

import math

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import Point

from foundation import InputError
from patterns.geometry import (
    DEFECT_TYPES,
    DESIGNS,
    build,
    circle,
    constant_jagged,
    defect,
    defect_type,
    design_record,
    four_pad,
    polygon,
    random_jagged,
    rectangle,
    rotate_quarter,
    square,
)


def same_shape(a, b, tol=1e-9):
    return a.symmetric_difference(b).area <= tol


def mirror_x(g):  # mirror in the y-axis: x -> -x
    return affinity.scale(g, -1, 1, origin=(0, 0))


# ---------------------------------------------------------------------------- simple shapes


def test_square_and_rectangle_are_centred_with_exact_area():
    assert square(200).bounds == (-100, -100, 100, 100)
    assert square(200).area == 40000
    r = rectangle(30, 10)
    assert r.bounds == (-15, -5, 15, 5) and r.area == 300
    assert r.exterior.is_ccw


@pytest.mark.parametrize("segments", [8, 64, 1024])
def test_circle_area_is_exact_and_polygon_hugs_the_circle(segments):
    c = circle(100, segments=segments)
    assert c.area == pytest.approx(math.pi * 50**2, rel=1e-12)
    assert len(c.exterior.coords) == segments + 1
    if segments == 1024:
        radii = np.hypot(*np.asarray(c.exterior.coords).T)
        assert np.all(np.abs(radii - 50) < 50 * 3.2e-6)
        assert c.hausdorff_distance(Point(0, 0).buffer(50, quad_segs=4096)) < 50 * 3.2e-6


def test_circle_has_the_square_symmetries():
    c = circle(37)
    assert same_shape(c, rotate_quarter(c, 1), 0) and same_shape(c, mirror_x(c), 1e-9)


def test_four_pad_pads_and_area():
    L, g = 730, 50
    fp = four_pad(L, g)
    p = (L - g) / 2
    assert fp.geom_type == "MultiPolygon" and len(fp.geoms) == 4
    assert fp.area == 4 * p**2 == 462400
    assert sorted(pad.bounds for pad in fp.geoms) == sorted(
        (x0, y0, x0 + p, y0 + p) for x0 in (-L / 2, g / 2) for y0 in (-L / 2, g / 2)
    )


@pytest.mark.parametrize("L,g", [(730, 50), (730, 100), (710, 50), (710, 100), (200, 20)])
def test_four_pad_is_four_fold_and_mirror_symmetric(L, g):
    fp = four_pad(L, g)
    assert fp.area == pytest.approx(4 * ((L - g) / 2) ** 2, rel=1e-15)
    for k in (1, 2, 3):
        assert same_shape(fp, rotate_quarter(fp, k), 0)
    assert same_shape(fp, affinity.rotate(fp, 90, origin=(0, 0)), 1e-9)
    assert same_shape(fp, mirror_x(fp), 0)


def test_rotate_quarter_is_exact():
    g = polygon([(1.1, 0.3), (7.7, 0.3), (2.2, 5.9)])
    assert shapely.equals_exact(rotate_quarter(rotate_quarter(g, 1), 3), g, tolerance=0)
    assert rotate_quarter(Point(1, 0), 1).coords[0] == (0, 1)


# ---------------------------------------------------------------------------- defects


@pytest.mark.parametrize("name", sorted(DEFECT_TYPES))
@pytest.mark.parametrize("kind,sign", [("inward", -1), ("outward", +1)])
def test_defect_type_area(name, kind, sign):
    expected = {"A": 100, "B": 900, "C": 3600}[name]
    assert defect_type(name, kind).area == pytest.approx(40000 + sign * expected, abs=1e-9)


@pytest.mark.parametrize("edge,k", [("right", 0), ("top", 1), ("left", 2), ("bottom", 3)])
@pytest.mark.parametrize("position", ["middle", "corner"])
@pytest.mark.parametrize("kind", ["inward", "outward"])
def test_defect_edges_are_quarter_turns_of_the_right_edge(edge, k, position, kind):
    right = defect(kind=kind, position=position, edge="right", height=30, width=60)
    assert same_shape(
        defect(kind=kind, position=position, edge=edge, height=30, width=60),
        rotate_quarter(right, k),
        0,
    )


@pytest.mark.parametrize(
    "edge,corner_bounds",
    [
        ("right", (100, 40, 130, 100)),  # upper end of the right edge (+y)
        ("top", (-100, 100, -40, 130)),  # left end of the top edge (-x)
        ("left", (-130, -100, -100, -40)),  # lower end of the left edge (-y)
        ("bottom", (40, -130, 100, -100)),  # right end of the bottom edge (+x)
    ],
)
def test_corner_defect_sits_at_the_counter_clockwise_end(edge, corner_bounds):
    g = defect(kind="outward", position="corner", edge=edge, height=30, width=60)
    assert g.difference(square(200)).bounds == pytest.approx(corner_bounds)


def test_middle_defect_apex_is_over_the_middle_of_the_base():
    g = defect(kind="inward", position="middle", height=60, width=120)
    assert square(200).difference(g).bounds == pytest.approx((40, -60, 100, 60))
    assert g.boundary.distance(Point(40, 0)) < 1e-12


# docs/physics.md C11: exact polygon overlap of a 200 um chip with right-edge defects.
@pytest.mark.parametrize(
    "name,kind,values",
    [
        ("C", "outward", (40000, 39919, 39800, 39688.75, 39688.75)),
        ("C", "inward", (36400, 36200, 36319, 36086.95, 36086.95)),
        ("B", "outward", (40000, 39859, 39800, 39656.97, 39727.88)),
        ("B", "inward", (39100, 38900, 38959, 38827.65, 38758.44)),
    ],
)
def test_defect_overlap_check_values_c11(name, kind, values):
    pattern, chip = defect_type(name, kind), square(200)
    poses = [(0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1)]
    got = [
        pattern.intersection(affinity.translate(affinity.rotate(chip, a, origin=(0, 0)), x, y)).area
        for x, y, a in poses
    ]
    assert got == pytest.approx(values, abs=0.01)


# ---------------------------------------------------------------------------- jagged edges


@pytest.mark.parametrize("a", [1.7, 3.2, 4, 5, 15])
def test_centred_constant_jagged_keeps_the_nominal_area(a):
    assert constant_jagged(200, amplitude=a).area == pytest.approx(40000, abs=1e-8)


@pytest.mark.parametrize("pitch", [7.0, 9.3, 30.0])
def test_nominal_area_for_any_pitch_with_flanks_up_to_45_degrees(pitch):
    assert constant_jagged(200, amplitude=3.5, pitch=pitch).area == pytest.approx(40000, abs=1e-8)


@pytest.mark.parametrize("a", [1.7, 5, 15])
def test_outward_teeth_move_the_mean_edge_out_by_half_the_amplitude(a):
    assert constant_jagged(200, amplitude=a, teeth="outward").area == pytest.approx(
        40000 + 4 * 200 * a / 2, abs=1e-8
    )


def test_constant_jagged_teeth_have_the_requested_amplitude_and_pitch():
    g = constant_jagged(200, amplitude=5)
    xmin, ymin, xmax, ymax = g.bounds
    assert (xmin, ymin, xmax, ymax) == pytest.approx((-102.5, -102.5, 102.5, 102.5))
    # Zero phase: the right edge crosses the nominal line at its midpoint, tips every 10 um.
    for y, x in [(0, 100), (2.5, 102.5), (7.5, 97.5), (12.5, 102.5), (-2.5, 97.5)]:
        assert g.boundary.distance(Point(x, y)) < 1e-9


@pytest.mark.parametrize("phase", ["zero", "peak"])
@pytest.mark.parametrize("a", [1.7, 15])
def test_constant_jagged_is_four_fold_symmetric(phase, a):
    g = constant_jagged(200, amplitude=a, phase=phase)
    for k in (1, 2, 3):
        assert same_shape(g, rotate_quarter(g, k), 1e-9)


def test_peak_phase_is_also_mirror_symmetric_and_zero_phase_is_chiral():
    peak, zero = (
        constant_jagged(200, amplitude=3.2, phase="peak"),
        constant_jagged(200, amplitude=3.2),
    )
    assert same_shape(peak, mirror_x(peak), 1e-9)
    assert not same_shape(zero, mirror_x(zero), 1.0)
    assert constant_jagged(200, amplitude=5, phase="peak").area == pytest.approx(
        40000, abs=1e-8
    )  # 20 pitches


def test_random_jagged_is_reproducible_and_seed_dependent():
    a, b = random_jagged(200, sigma=4, seed=7), random_jagged(200, sigma=4, seed=7)
    assert shapely.equals_exact(a, b, tolerance=0)
    c = random_jagged(200, sigma=4, seed=8)
    assert a.symmetric_difference(c).area > 100


@pytest.mark.parametrize("sigma", [1, 2, 4, 8])
def test_random_jagged_follows_the_documented_draw(sigma):
    L, p, seed = 200, 4 * sigma, 3
    n = math.floor(L / p)
    h = np.random.default_rng(seed).normal(0, sigma, size=(4, n))
    g = random_jagged(L, sigma=sigma, seed=seed)
    t = (np.arange(n) - (n - 1) / 2) * p
    for k in range(1, n - 1):  # interior teeth of every edge: apex and base points on the boundary
        for e in range(4):
            apex = rotate_quarter(Point(L / 2 + h[e, k], t[k]), e)
            base = rotate_quarter(Point(L / 2, t[k] + p / 2), e)
            assert g.boundary.distance(apex) < 1e-9 and g.boundary.distance(base) < 1e-9
    # The mean edge line stays near the nominal square: area within a few sigma * L per edge.
    assert abs(g.area - L**2) < 4 * L * sigma


def test_random_jagged_polyline_profile_goes_peak_to_peak():
    g = random_jagged(200, sigma=2, seed=1, profile="polyline")
    h = np.random.default_rng(1).normal(0, 2, size=(4, 25))
    mid = Point(
        100 + (h[0, 10] + h[0, 11]) / 2, (10 - 12) * 8 + 4
    )  # midway between peaks 10 and 11
    assert g.boundary.distance(mid) < 1e-9


# ---------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: square(-1), r"size must be a finite number > 0"),
        (lambda: square(0), r"size must be a finite number > 0"),
        (lambda: square(float("nan")), r"size .*nan"),
        (lambda: square(float("inf")), r"size must be a finite"),
        (lambda: rectangle(10, -2), r"height"),
        (lambda: circle(10, segments=30), r"segments must be a multiple of 4"),
        (lambda: four_pad(100, 100), r"gap=100 um must be smaller than size=100 um"),
        (lambda: four_pad(100, 150), r"gap=150"),
        (lambda: four_pad(100, 0), r"gap must be a finite number > 0"),
        (lambda: defect(kind="inward", height=10, width=250), r"width=250 um.*width <= size=200"),
        (lambda: defect(kind="inward", height=101, width=20), r"height=101 um.*size/2 = 100"),
        (
            lambda: defect(kind="sideways", height=10, width=20),
            r"kind must be one of inward, outward",
        ),
        (
            lambda: defect(kind="inward", position="top", height=10, width=20),
            r"position must be one of middle, corner",
        ),
        (
            lambda: defect(kind="inward", edge="up", height=10, width=20),
            r"edge must be one of right, top, left, bottom",
        ),
        (lambda: defect_type("D", "inward"), r"defect type must be one of A, B, C"),
        (
            lambda: constant_jagged(200, amplitude=50),
            r"amplitude=50 um is too large.*< size/4 = 50",
        ),
        (lambda: constant_jagged(200, amplitude=5, pitch=300), r"pitch=300 um must not exceed"),
        (lambda: constant_jagged(200, amplitude=5, teeth="up"), r"teeth must be one of"),
        (
            lambda: constant_jagged(200, amplitude=5, phase="half"),
            r"phase must be one of zero, peak",
        ),
        (lambda: random_jagged(200, sigma=60, seed=1), r"pitch=240 um must not exceed"),
        (
            lambda: random_jagged(200, sigma=40, pitch=20, seed=0),
            r"sigma=40 um with seed=0 cuts the 200 um pattern apart",
        ),
        (lambda: random_jagged(200, sigma=2, seed=-1), r"seed must be an integer >= 0"),
        (
            lambda: random_jagged(200, sigma=2, seed=1.5),  # pyright: ignore[reportArgumentType] - on purpose
            r"seed must be an integer >= 0",
        ),
        (lambda: polygon([(0, 0), (1, 0)]), r"at least 3 distinct points, got 2"),
        (
            lambda: polygon([(0, 0), (10, 0), (0, 10), (10, 10)]),
            r"points: the polygon is not simple",
        ),
        (lambda: polygon([(0, 0), (1, 1), (2, 2)]), r"points"),
        (lambda: polygon([(0, 0), (1, float("nan")), (2, 0)]), r"points must be finite"),
    ],
)
def test_impossible_geometry_raises_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_polygon_accepts_closed_rings_and_orients_them():
    g = polygon([(0, 0), (0, 10), (10, 0), (0, 0)])  # clockwise, closed
    assert g.area == 50 and g.exterior.is_ccw


# ---------------------------------------------------------------------------- registry


def test_registry_names_and_parameters():
    assert list(DESIGNS) == [
        "square",
        "rectangle",
        "circle",
        "four-pad",
        "defect",
        "constant-jagged",
        "random-jagged",
        "polygon",
    ]
    flags = {name: [p.flag for p in d.params] for name, d in DESIGNS.items()}
    assert flags["four-pad"] == ["--size", "--gap"]
    assert flags["defect"] == ["--size", "--kind", "--position", "--edge", "--height", "--width"]
    assert flags["random-jagged"][:4] == ["--size", "--sigma", "--pitch", "--seed"]
    for design in DESIGNS.values():
        assert design.description and all(p.help for p in design.params)
        assert all(p.unit == "um" for p in design.params if p.kind in ("length", "points"))


def test_build_matches_the_builders_and_fills_defaults():
    assert same_shape(build("four-pad", size=730, gap=50), four_pad(730, 50), 0)
    assert same_shape(
        build("defect", kind="outward", height="30", width=60, position="corner"),
        defect_type("B", "outward"),
        0,
    )
    assert same_shape(
        build("polygon", points="0,0; 10,0; 0,10"), polygon([(0, 0), (10, 0), (0, 10)]), 0
    )
    rec = design_record("constant-jagged", amplitude=1.7)
    assert rec["design"] == "constant-jagged"
    assert rec["parameters"]["pitch"] == {"value": 3.4, "unit": "um"}
    assert rec["parameters"]["size"] == {"value": 200.0, "unit": "um"}
    assert rec["parameters"]["teeth"] == {"value": "centred", "unit": ""}


@pytest.mark.parametrize(
    "name,params,match",
    [
        ("hexagon", {}, r"unknown design 'hexagon'; choose one of square, "),
        ("four-pad", {"size": 730}, r"design four-pad needs gap"),
        (
            "four-pad",
            {"size": 730, "gap": 50, "pitch": 3},
            r"design four-pad has no parameter pitch",
        ),
        ("square", {"size": "big"}, r"size must be a number, got 'big'"),
        ("random-jagged", {"sigma": 2, "seed": "x"}, r"seed must be an integer >= 0"),
        ("polygon", {"points": "0,0;1"}, r"cannot read point '1'"),
    ],
)
def test_build_rejects_bad_parameters(name, params, match):
    with pytest.raises(InputError, match=match):
        build(name, **params)
