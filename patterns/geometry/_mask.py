"""A rasterized wettability map with its scale, and the exact shape when known.

Conventions (used everywhere in selfalign):

* Physical frame: micrometres, origin at the nominal pattern centre, x right, y up,
  twist counter-clockwise positive, in degrees at the user boundary.
* Image frame: ``data[row, col]``, row 0 at the *top* (largest y). Pixel ``(r, c)``
  covers x in ``[(c - W/2) s, (c + 1 - W/2) s]`` and y in ``[(H/2 - r - 1) s, (H/2 - r) s]``
  with ``s = um_per_px``: the image centre is the physical origin. For even W and H
  the origin is a pixel corner, so shapes whose edges sit on whole micrometres at
  1 um/px rasterize exactly.
* Values are in [0, 1]: 1 = fully wettable pad, 0 = substrate; intermediate values are
  area coverage (anti-aliased edges) or graded wettability read from grey PNGs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from foundation import InputError, positive


@dataclass(frozen=True, eq=False)
class Mask:
    """A float mask in [0, 1] with its scale.

    Attributes:
        data: (H, W) float64 array in [0, 1], row 0 at the top (largest y).
        um_per_px: pixel size in micrometres.
        geometry: the exact shapely geometry (micrometres, centred) when known, else None.
        params: the parameters that generated it (design name, sizes), for provenance.
    """

    data: np.ndarray
    um_per_px: float
    geometry: Any = None
    params: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        raw = np.asarray(self.data)
        if np.iscomplexobj(raw):  # float64 would keep the real part and drop the rest
            raise InputError(
                f"mask must be a real-valued image, got complex values ({raw.dtype}); "
                "give the coverage in [0, 1] as real numbers (e.g. the array's .real or abs())"
            )
        try:
            data = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(
                f"mask must be an image of numbers in [0, 1], got an array of {raw.dtype}"
            ) from None
        if data.ndim != 2 or min(data.shape) < 1:
            raise InputError(f"mask must be a 2-D image, got shape {data.shape}")
        # Two passes over the pixels: a NaN makes min and max NaN, an infinity one of them.
        lo, hi = float(data.min()), float(data.max())
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise InputError(
                "mask contains NaN or infinite values; give an image with finite values in [0, 1]"
            )
        if lo < 0 or hi > 1:
            raise InputError(f"mask values must lie in [0, 1], got [{lo:g}, {hi:g}]")
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "um_per_px", positive("um_per_px", self.um_per_px, "um per px"))

    @property
    def shape(self) -> tuple[int, int]:
        return self.data.shape  # type: ignore[return-value]

    @property
    def area_um2(self) -> float:
        """Wettable area: sum of the mask times the pixel area (um^2)."""
        return float(self.data.sum()) * self.um_per_px**2

    @property
    def extent_um(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the image in the physical frame, for imshow."""
        h, w = self.shape
        s = self.um_per_px
        return (-w / 2 * s, w / 2 * s, -h / 2 * s, h / 2 * s)

    def require_nonempty(self, name: str, invert_flag: str | None = "--invert") -> Mask:
        """Raise InputError if the mask has no wettable pixel (naming the flag that inverts it)."""
        if not np.any(self.data > 0):
            fix = f", or use {invert_flag}" if invert_flag else ""
            raise InputError(
                f"{name}: the mask is all black (no wettable area); white marks the wettable area{fix}"
            )
        return self


def nonzero_box(data: np.ndarray) -> tuple[int, int, int, int]:
    """(row0, row1, col0, col1), end-exclusive, of the non-zero pixels of ``data``."""
    rows = np.flatnonzero(data.any(axis=1))
    cols = np.flatnonzero(data.any(axis=0))
    return rows[0], rows[-1] + 1, cols[0], cols[-1] + 1


def footprint_um(mask: Mask) -> tuple[float, float]:
    """Width and height (um) of a mask's wettable footprint: exact for geometry, else the
    bounding box of the pixels at least half covered (of every covered pixel when none is)."""
    if mask.geometry is not None:
        x0, y0, x1, y1 = mask.geometry.bounds
        return x1 - x0, y1 - y0
    d = mask.data >= 0.5
    if not d.any():
        d = mask.data > 0
    rows, cols = np.flatnonzero(d.any(axis=1)), np.flatnonzero(d.any(axis=0))
    s = mask.um_per_px
    return (cols[-1] + 1 - cols[0]) * s, (rows[-1] + 1 - rows[0]) * s


def default_chip_um(pattern) -> tuple[float, float]:
    """Width and height (um) of the chip a scene takes when none is given (``selfalign
    evaluate``, a sweep's point): a rectangle the size of the pattern's wettable bounding box,
    :func:`footprint_um` of the pattern's mask, or the bounds of its exact geometry (a layout
    or a generated design read before it is rasterized)."""
    if isinstance(pattern, Mask):
        return footprint_um(pattern)
    x0, y0, x1, y1 = pattern.bounds
    return x1 - x0, y1 - y0


def pad_labels(pattern: Mask) -> tuple[np.ndarray, int]:
    """The pattern's pads: its connected wettable regions (every pixel above 0, so that the
    pads' masks add up to the pattern exactly), labelled 1..n; (labels, n)."""
    from scipy import ndimage

    labels, n = ndimage.label(pattern.data > 0)
    return labels, int(n)
