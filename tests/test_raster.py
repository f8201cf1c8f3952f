"""Exact area-coverage rasterization against shapely's per-pixel polygon clipping."""

import numpy as np
import pytest
import shapely
from hypothesis import assume, given, settings, strategies as st
from shapely import affinity
from shapely.geometry import Point, Polygon, box

from foundation import InputError
from patterns.geometry import canvas_shape, mask_from_geometry, rasterize, to_pixel_frame


def shapely_coverage(geometry, um_per_px, shape):
    """Reference: exact intersection area of every pixel box with the geometry."""
    h, w = shape
    g = to_pixel_frame(geometry, um_per_px, shape)
    rows, cols = np.mgrid[0:h, 0:w]
    boxes = shapely.box(cols, rows, cols + 1, rows + 1)
    return shapely.area(shapely.intersection(boxes, g))


def test_square_on_pixel_grid_is_exact_binary():
    m = rasterize(box(-100, -100, 100, 100), 1.0)
    assert m.shape == (200, 200)
    assert np.array_equal(m, np.ones((200, 200)))


def test_origin_is_image_centre_and_y_points_up():
    # A square in the upper-right quadrant lands in the top-right of the image.
    m = rasterize(box(0, 0, 10, 10), 1.0, shape=(40, 40))
    assert m[10:20, 20:30].sum() == 100 and m.sum() == 100


@pytest.mark.parametrize("angle", [0.0, 7.3, 30.0, 45.0, 89.0])
@pytest.mark.parametrize("um_per_px", [0.7, 1.0, 2.5])
def test_rotated_rectangle_matches_shapely_per_pixel(angle, um_per_px):
    g = affinity.rotate(box(-23.3, -11.1, 19.7, 13.9), angle, origin=(0, 0))
    m = rasterize(g, um_per_px)
    ref = shapely_coverage(g, um_per_px, m.shape)
    np.testing.assert_allclose(m, ref, atol=1e-12)
    assert m.sum() * um_per_px**2 == pytest.approx(g.area, rel=1e-12)


def test_polygon_with_hole_and_multipolygon():
    g = Polygon([(0, 0), (30, 5), (12, 27), (-9, 14)]).difference(Point(8, 10).buffer(5))
    g = g.union(box(-40, -40, -25, -20))
    m = rasterize(g, 0.8)
    np.testing.assert_allclose(m, shapely_coverage(g, 0.8, m.shape), atol=1e-12)


def test_geometry_beyond_canvas_is_cut_not_wrapped():
    g = box(-30, -5, 30, 5)
    m = rasterize(g, 1.0, shape=(20, 20))
    assert m.sum() == pytest.approx(20 * 10)
    np.testing.assert_allclose(m, shapely_coverage(g, 1.0, (20, 20)), atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    pts=st.lists(
        st.tuples(st.integers(-20000, 20000), st.integers(-20000, 20000)),
        min_size=3,
        max_size=9,
    ),
    s=st.floats(0.3, 3.0),
)
def test_random_polygons_match_shapely(pts, s):
    # Coordinates on a 1e-3 um lattice; self-intersecting draws are made valid.
    g = Polygon([(x / 1000, y / 1000) for x, y in pts]).buffer(0)
    assume(g.is_valid and g.area > 1e-3)
    m = rasterize(g, s)
    np.testing.assert_allclose(m, shapely_coverage(g, s, m.shape), atol=1e-9)


def test_canvas_shape_is_even_and_symmetric():
    assert canvas_shape(box(-365, -365, 365, 365), 1.0) == (730, 730)
    assert canvas_shape(box(0, 0, 10, 3), 1.0) == (6, 20)
    assert canvas_shape(box(-5, -5, 5, 5), 1.0, margin_um=3) == (16, 16)


def test_mask_keeps_geometry_and_area():
    g = Point(0, 0).buffer(50, quad_segs=64)
    mask = mask_from_geometry(g, 1.3, margin_um=2)
    assert mask.geometry is g
    assert mask.area_um2 == pytest.approx(g.area, rel=1e-12)


def test_bad_scale_raises():
    with pytest.raises(InputError, match="um_per_px must be a finite number > 0"):
        rasterize(box(0, 0, 1, 1), 0.0)
    with pytest.raises(InputError, match="empty"):
        canvas_shape(Polygon(), 1.0)


def test_a_raster_costs_one_canvas():
    """The coverage is summed in place: rasterizing allocates one float64 canvas (and the
    outline's pieces), not the three of a copy per step (a 4000 px chip: 128 MB, not 490)."""
    import tracemalloc

    n = 1200
    tracemalloc.start()
    try:
        raster = rasterize(box(-n / 2 + 0.3, -n / 2 + 0.3, n / 2 - 0.3, n / 2 - 0.3), 1.0, (n, n))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert raster.shape == (n, n) and raster.flags.c_contiguous
    assert peak < 1.25 * raster.nbytes
    # the fractional edges of the inset square: area exact
    assert raster.sum() == pytest.approx((n - 0.6) ** 2, rel=1e-12)


@pytest.mark.parametrize("um_per_px", [0.3, 1.0, 2.5])
def test_a_rectangle_is_the_product_of_its_covered_rows_and_columns(um_per_px):
    """An axis-aligned rectangle (every ``--chip-size`` chip) is rasterized as the product of
    the lengths each row and column covers: the edge accumulation's values to round-off,
    shapely's per-pixel areas, and exactly 0 and 1 when its edges lie on the pixel grid."""
    from patterns.geometry._raster import _coverage, _rectangle

    rng = np.random.default_rng(7)
    for _ in range(20):
        x0, y0 = rng.uniform(-30, 0, 2)
        x1, y1 = rng.uniform(0.01, 30, 2)
        g = box(x0, y0, x1, y1)
        shape = (2 * int(rng.integers(1, 40)), 2 * int(rng.integers(1, 40)))
        m = rasterize(g, um_per_px, shape=shape)
        assert _rectangle(to_pixel_frame(g, um_per_px, shape)) is not None
        np.testing.assert_allclose(
            m, _coverage(to_pixel_frame(g, um_per_px, shape), shape), atol=1e-12
        )
        np.testing.assert_allclose(m, shapely_coverage(g, um_per_px, shape), atol=1e-12)
    on_grid = box(-10, -7, 12, 9)
    m = rasterize(on_grid, 1.0, shape=(40, 40))
    assert np.array_equal(m, _coverage(to_pixel_frame(on_grid, 1.0, (40, 40)), (40, 40)))
    assert set(np.unique(m)) == {0.0, 1.0} and m.sum() == 22 * 16


def test_only_a_rectangle_takes_the_product():
    """A rotated box, a box with a hole, two boxes, an L and a triangle on three corners of
    its bounding box are not rectangles: they go through the edge accumulation."""
    from patterns.geometry._raster import _rectangle

    not_rectangles = [
        affinity.rotate(box(0, 0, 4, 4), 10),
        box(0, 0, 4, 4).difference(box(1, 1, 2, 2)),
        box(0, 0, 4, 4).union(box(5, 0, 8, 2)),
        box(0, 0, 4, 4).union(box(4, 0, 8, 2)),
        Polygon([(0, 0), (4, 0), (4, 4)]),
    ]
    assert all(_rectangle(g) is None for g in not_rectangles)
    assert _rectangle(box(1, 2, 3, 5)) == (1, 2, 3, 5)
