"""Inputs that hung or broke their memory budget, and the messages of ``selfalign design``
(issue 36, the heavier items): one regression test (or a few) per item.

Bounds on time are generous ceilings over a cost the test also checks by counting (the
outline's calls into shapely do not grow with the pads); a process that must be stopped at
a known point holds there (``SELFALIGN_HOLD_AT``, patterns/hold.py) and is signalled once
its hold line is read from the pipe, so nothing waits on a clock.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import shapely
from cli_helpers import one_line_error  # noqa: F401  (tests/cli_helpers.py)
from shapely.geometry import Polygon

from patterns.errors import InputError
from patterns.mask import Mask


# ============================================================== 2. the outline of many tiny pads
def _tiny_pads(n_px: int) -> Mask:
    """One-pixel pads on a 3 px pitch: (n_px / 3)^2 pads."""
    a = np.zeros((n_px, n_px))
    a[::3, ::3] = 1.0
    return Mask(a, 1.0)


def _old_outline(mask: Mask):
    """The outline as it was made before (one symmetric difference per contour)."""
    from skimage import measure

    h, w = mask.shape
    s, d = mask.um_per_px, mask.data
    border_wet = max(d[0].max(), d[-1].max(), d[:, 0].max(), d[:, -1].max()) >= 0.5
    data, o = (np.pad(d, 1), 1) if border_wet else (d, 0)
    polys = []
    for c in measure.find_contours(data, 0.5):
        if len(c) < 4:
            continue
        x = (c[:, 1] - o + 0.5 - w / 2) * s
        y = (h / 2 - (c[:, 0] - o) - 0.5) * s
        p = shapely.make_valid(Polygon(np.column_stack([x, y])))
        if p.area > 0:
            polys.append(p)
    geom = polys[0]
    for p in polys[1:]:
        geom = geom.symmetric_difference(p)
    return geom


def _nested_and_random() -> list[np.ndarray]:
    from scipy import ndimage

    rng = np.random.default_rng(3)
    rings = np.zeros((41, 41))
    for k in range(0, 20, 4):  # pads in holes in pads, five deep
        rings[k : 41 - k, k : 41 - k] = 1
        rings[k + 2 : 39 - k, k + 2 : 39 - k] = 0
    blobs = ndimage.gaussian_filter(rng.random((80, 80)), 2)
    holed = np.ones((20, 20))
    holed[5:8, 5:8] = 0  # wet border: the image is padded dry
    return [
        _tiny_pads(30).data,
        rings,
        (rng.random((60, 60)) > 0.5).astype(float),
        (blobs > blobs.mean()).astype(float),
        holed,
    ]


@pytest.mark.parametrize("case", range(5))
def test_outline_equals_the_old_symmetric_differences(case):
    from simulator.scene._accuracy import _mask_outline

    m = Mask(_nested_and_random()[case], 1.0)
    new, old = _mask_outline(m), _old_outline(m)
    assert new.is_valid
    assert new.area == pytest.approx(old.area, rel=1e-12)
    assert new.symmetric_difference(old).area < 1e-9 * old.area


class _CountingShapely:
    """Stands in for the shapely module and counts the calls made through it."""

    def __init__(self):
        self.calls = 0

    def __getattr__(self, name):
        real = getattr(shapely, name)
        if not callable(real) or isinstance(real, type):
            return real

        def counted(*args, **kwargs):
            self.calls += 1
            return real(*args, **kwargs)

        return counted


def _outline_calls(monkeypatch, mask: Mask) -> int:
    import simulator.scene._accuracy as acc

    counter = _CountingShapely()
    with monkeypatch.context() as m:
        m.setattr(acc, "shapely", counter)
        acc._mask_outline(mask)
        with pytest.raises(InputError, match="no area to measure"):  # one-pixel pads are noise
            acc._smallest_feature_um(mask, acc.CORNER_DEG)
    return counter.calls


def test_outline_calls_into_shapely_do_not_grow_with_the_pads(monkeypatch):
    # 100 and 10,000 pads: the same number of (vectorised) calls; the old outline made one
    # symmetric difference per contour, each over everything merged so far (quadratic).
    assert _outline_calls(monkeypatch, _tiny_pads(30)) == _outline_calls(
        monkeypatch, _tiny_pads(300)
    )


def test_outline_of_ten_thousand_tiny_pads_is_quick():
    """The 300 x 300 px pattern of 10,000 one-pixel pads: the old outline ran over 150 s
    (900 pads: 4.8 s, growing as the square); now 0.3 s for the outline and 0.35 s for the
    whole feature measure on a 2-core machine. The ceiling, 30 s, is 50 x that."""
    from simulator.scene._accuracy import _mask_outline, smallest_feature_um

    m = _tiny_pads(300)
    t0 = time.perf_counter()
    g = _mask_outline(m)
    with pytest.raises(InputError, match="no area to measure"):
        smallest_feature_um(m)
    assert time.perf_counter() - t0 < 30.0
    assert len(g.geoms) == 10_000 and g.area == pytest.approx(10_000 * 0.5)


def test_outline_is_priced_before_it_is_made():
    from simulator.scene._accuracy import OUTLINE_BYTES_PER_VERTEX, price_outline

    m = _tiny_pads(300)
    assert price_outline(m, 1000.0) == 40_000  # four vertices per one-pixel pad
    with pytest.raises(InputError, match=r"outline of the pattern \(300 x 300 px, 40,000"):
        price_outline(m, 40_000 * OUTLINE_BYTES_PER_VERTEX / 2**20 / 2)
