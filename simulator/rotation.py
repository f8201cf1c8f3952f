"""Rotated chip rasters: exact geometry rasterized anew at every twist, or a chip PNG
resampled (bilinear), on one canvas with the pattern's pixel parity; mirror twins."""

from __future__ import annotations

import math

import numpy as np
from shapely import affinity

from patterns.mask import Mask, nonzero_box
from patterns.raster import rasterize


def _chip_reach_px(chip: Mask, twist: bool) -> tuple[float, float]:
    """Half-extent (x, y) in px of the chip's wettable area about its centre, over all twists."""
    h, w = chip.shape
    r0, r1, c0, c1 = nonzero_box(chip.data > 0)
    xs = np.array([c0, c1]) - w / 2
    ys = np.array([r0, r1]) - h / 2
    if not twist:
        return float(np.abs(xs).max()), float(np.abs(ys).max())
    if chip.geometry is not None:
        from shapely.geometry import Point

        rad = chip.geometry.hausdorff_distance(Point(0, 0)) / chip.um_per_px
    else:
        rad = math.hypot(np.abs(xs).max(), np.abs(ys).max())
    return rad, rad


def _rotated_extent_px(chip: Mask, twists: np.ndarray) -> tuple[float, float]:
    """Half-extent (x, y) in px of the chip's wettable area over the given twists."""
    h, w = chip.shape
    r0, r1, c0, c1 = nonzero_box(chip.data > 0)
    if chip.geometry is not None:
        bounds = np.array([affinity.rotate(chip.geometry, float(t), origin=(0, 0)).bounds for t in twists]) / chip.um_per_px
        return float(np.abs(bounds[:, [0, 2]]).max()), float(np.abs(bounds[:, [1, 3]]).max())
    xs = np.array([c0, c1, c1, c0]) - w / 2
    ys = h / 2 - np.array([r0, r0, r1, r1])
    a = np.radians(np.asarray(twists, float))[:, None]
    xr = xs * np.cos(a) - ys * np.sin(a)
    yr = xs * np.sin(a) + ys * np.cos(a)
    return float(np.abs(xr).max()), float(np.abs(yr).max())


class ChipRotator:
    """Rotated chip rasters on one fixed canvas, y-up, with the pattern's pixel parity."""

    def __init__(self, chip: Mask, twists: np.ndarray, parity: tuple[int, int]):
        self.chip = chip
        rx, ry = _rotated_extent_px(chip, twists)
        # Canvas (H, W) with W % 2 == parity so chip and pattern pixel grids coincide;
        # just large enough for the twists asked for (a band of twists needs less).
        self.shape = tuple(2 * math.ceil(r - 1e-9) + 2 + p for r, p in ((ry, parity[0]), (rx, parity[1])))

    def __call__(self, twist_deg: float) -> np.ndarray:
        c = self.chip
        if c.geometry is not None:
            g = c.geometry if twist_deg == 0 else affinity.rotate(c.geometry, twist_deg, origin=(0, 0))
            img = rasterize(g, c.um_per_px, shape=self.shape)
        else:
            img = self._resample(twist_deg)
        return img[::-1]  # y up

    def _resample(self, twist_deg: float) -> np.ndarray:
        import cv2

        h, w = self.chip.shape
        ho, wo = self.shape
        a = math.radians(twist_deg)
        ca, sa = math.cos(a), math.sin(a)
        # Output pixel centre (u, v) in y-down image coords -> physical (x, y) -> input.
        # Rotation by +a (CCW, y up) is (x, y) -> (x ca - y sa, x sa + y ca); inverse map:
        # x_in = x ca + y sa, y_in = -x sa + y ca, with y = -(v - cy).
        cxo, cyo, cxi, cyi = wo / 2 - 0.5, ho / 2 - 0.5, w / 2 - 0.5, h / 2 - 0.5
        m = np.array([[ca, -sa, 0.0], [sa, ca, 0.0]])
        m[0, 2] = cxi - ca * cxo + sa * cyo
        m[1, 2] = cyi - sa * cxo - ca * cyo
        out = cv2.warpAffine(
            self.chip.data, m, (wo, ho), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0
        )
        return np.clip(out, 0.0, 1.0)


def mirror_twins(mirror: bool, twists_deg: np.ndarray) -> dict[int, int]:
    """{i: j} for twists t_j = -t_i < 0 when the chip is mirror-symmetric about the x
    axis (``mirror``, :attr:`simulator.posegrid.TwistAxis.mirror`): its raster at -alpha
    is the one at +alpha upside down, so one forward transform serves both
    (:meth:`Correlator.__call__` ``mirror_out``)."""
    if len(twists_deg) < 2 or not mirror:
        return {}
    pos = {round(float(t), 9): i for i, t in enumerate(twists_deg)}
    return {i: pos[round(-float(t), 9)] for i, t in enumerate(twists_deg) if t > 0 and round(-float(t), 9) in pos}
