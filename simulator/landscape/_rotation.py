"""Rotated chip rasters: exact geometry rasterized anew at every twist, or a chip PNG
resampled (bilinear), on one canvas with the pattern's pixel parity; mirror twins."""

from __future__ import annotations

import functools
import math
import weakref

import numpy as np
from shapely import affinity

from patterns.geometry import Mask, nonzero_box, rasterize
from simulator.core import ceil_whole
from simulator.scene import resampled_extent

#: Spline order of the blurred chip's rotation: quadratic B-splines are C1 (no kinks in the
#: energy against twist) at 9 taps a pixel, against 16 for cubic (measured 1.7x faster;
#: the same Surface Evolver ratios to 0.001).
SPLINE_ORDER = 2

#: Peak bytes per pixel of the smooth chip's own canvas (:func:`smooth_canvas`) while it is
#: made, with a margin over what tracemalloc measured: the free-contact-line footprint (the
#: chip rasterized, two distance transforms and the wall profile over them, 50 B/px) and the
#: ``K_h`` blur (its FFT canvas is twice as wide and high, 108 B/px).
SMOOTH_BYTES_PER_PX = {"profile": 64, "blur": 128}
#: Bytes per pixel of the smooth chip kept once made (the footprint, its signed distances and
#: its spline coefficients; the blurred chip and its coefficients).
SMOOTH_KEPT_BYTES_PER_PX = {"profile": 24, "blur": 16}
#: Peak bytes per pixel of the rotator's canvas while the smooth chip is rotated onto it
#: (coordinates, masks, spline taps: 79 B/px measured) and kept between rotations (32 B/px).
SMOOTH_ROTATE_BYTES_PER_PX = 112
#: Pixels per second of the smooth chip's canvas made (2 cores: about 3e6 measured); for the
#: waiting line (:func:`simulator.core.wait_line`).
SMOOTH_PX_PER_S = 2.5e6

#: Zeros kept around the free contact lines' footprint on its own canvas: the quadratic spline
#: prefilter's response decays by 0.17 a pixel, so the canvas's edge is 0.17^24 (4e-19) away.
SPLINE_PAD_PX = 24

#: The last smooth chip made (:meth:`ChipRotator._smooth_chip`): its key, a weak reference to
#: the chip it was made from (a chip freed and another made at its address is not it), and
#: the arrays. One entry: a run works on one chip.
_SMOOTH: dict = {}
#: The last chip's signed distance on its smooth canvas (:meth:`ChipRotator._blur`): the key
#: (the chip's id, canvas), a weak reference to the chip and the array (read only). The
#: footprints of one chip (the wall profile and the footprint state's counts) share it.
_SDF: dict = {}
#: The exact chips' rotated half-extents (:func:`_rotated_extent_px`), by the chip's geometry
#: (its WKB), pixel size and twists: a build lays out many boxes of one chip over the same
#: twists (the footprint state's pads and pairs: about a thousand), each rotating the polygon
#: once per twist otherwise. The 64 newest kept.
_EXTENTS: dict = {}


def _chip_reach_px(chip: Mask, twist: bool, um_per_px: float | None = None) -> tuple[float, float]:
    """Half-extent (x, y) in px of the chip's wettable area about its centre, over all twists
    (``um_per_px``: of the chip resampled to that pixel size, :func:`simulator.scene.resampled_extent`)."""
    if um_per_px is None:
        (h, w), (r0, r1, c0, c1) = chip.shape, nonzero_box(chip.data > 0)
    else:
        (h, w), (r0, r1, c0, c1) = resampled_extent(chip, um_per_px)
    xs = np.array([c0, c1]) - w / 2
    ys = np.array([r0, r1]) - h / 2
    if not twist:
        return float(np.abs(xs).max()), float(np.abs(ys).max())
    if chip.geometry is not None:
        from shapely.geometry import Point

        rad = chip.geometry.hausdorff_distance(Point(0, 0)) / (
            chip.um_per_px if um_per_px is None else um_per_px
        )
    else:
        rad = math.hypot(np.abs(xs).max(), np.abs(ys).max())
    return rad, rad


def _rotated_extent_px(chip: Mask, twists: np.ndarray) -> tuple[float, float]:
    """Half-extent (x, y) in px of the chip's wettable area over the given twists."""
    if chip.geometry is not None:  # exact: no pass over the raster
        key = (chip.geometry.wkb, chip.um_per_px, np.asarray(twists, float).tobytes())
        if key not in _EXTENTS:
            bounds = (
                np.array(
                    [affinity.rotate(chip.geometry, float(t), origin=(0, 0)).bounds for t in twists]
                )
                / chip.um_per_px
            )
            if len(_EXTENTS) >= 64:
                _EXTENTS.pop(next(iter(_EXTENTS)))
            _EXTENTS[key] = (
                float(np.abs(bounds[:, [0, 2]]).max()),
                float(np.abs(bounds[:, [1, 3]]).max()),
            )
        return _EXTENTS[key]
    h, w = chip.shape
    r0, r1, c0, c1 = nonzero_box(chip.data > 0)
    xs = np.array([c0, c1, c1, c0]) - w / 2
    ys = h / 2 - np.array([r0, r0, r1, r1])
    a = np.radians(np.asarray(twists, float))[:, None]
    xr = xs * np.cos(a) - ys * np.sin(a)
    yr = xs * np.sin(a) + ys * np.cos(a)
    return float(np.abs(xr).max()), float(np.abs(yr).max())


def canvas_shape(
    chip: Mask, twists: np.ndarray, parity: tuple[int, int], margin_px: int = 0
) -> tuple[int, int]:
    """(H, W) of the rotator's canvas: just large enough for the chip (grown by ``margin_px``)
    at the given twists, with W % 2 and H % 2 the pattern's parity (a size, nothing rasterized)."""
    rx, ry = _rotated_extent_px(chip, twists)
    rx, ry = rx + margin_px, ry + margin_px
    return (2 * ceil_whole(ry) + 2 + parity[0], 2 * ceil_whole(rx) + 2 + parity[1])


def smooth_canvas(
    chip: Mask, margin_px: int, parity: tuple[int, int], profile: bool = False
) -> tuple[int, int]:
    """(H, W) of the smooth chip's own canvas (:meth:`ChipRotator._blur`), one for every build
    of a scene, whatever the rotator's canvas. The ``K_h`` blur: the chip and its margin at
    every twist (the blur's long tail must not wrap around its FFT). The free contact lines'
    footprint (``profile``): the unrotated chip, its margin and :data:`SPLINE_PAD_PX` of zeros,
    a quarter of the area for a square chip (its distance transforms and spline prefilter are
    local: a wider canvas changes the footprint by 0.17^24 of its kinks, nothing)."""
    if profile:
        rx, ry = _chip_reach_px(chip, False)
        ho = 2 * ceil_whole(ry + margin_px + SPLINE_PAD_PX) + 2 + parity[0] % 2
        wo = 2 * ceil_whole(rx + margin_px + SPLINE_PAD_PX) + 2 + parity[1] % 2
        # A chip image is placed whole (not resampled) when it fits: as wide as its array.
        h, w = chip.shape
        return max(ho, h + (ho - h) % 2), max(wo, w + (wo - w) % 2)
    rad = max(_chip_reach_px(chip, True)) + margin_px
    side = int(2 * math.ceil(rad * math.sqrt(2)) + 4)
    return side + parity[0] % 2, side + parity[1] % 2


def smooth_cached(
    chip: Mask, blur_px: float, margin_px: int, profile, parity: tuple[int, int]
) -> bool:
    """Whether the smooth chip of these settings is made already (:data:`_SMOOTH`)."""
    key = (id(chip), float(blur_px), int(margin_px), profile, parity[0] % 2, parity[1] % 2)
    cached = _SMOOTH.get("entry")
    return cached is not None and cached[0] == key and cached[1]() is chip


def smooth_bytes(
    chip: Mask, blur_px: float, margin_px: int, profile, parity: tuple[int, int]
) -> tuple[int, int]:
    """(peak bytes while the smooth chip is made, 0 when it is made already; bytes kept)
    of a rotator with a meniscus footprint (both 0 without one): sizes only."""
    if not (blur_px > 0 or profile is not None):
        return 0, 0
    ho, wo = smooth_canvas(chip, margin_px, parity, profile is not None)
    kind = "blur" if profile is None else "profile"
    kept = ho * wo * SMOOTH_KEPT_BYTES_PER_PX[kind]
    make = (
        0
        if smooth_cached(chip, blur_px, margin_px, profile, parity)
        else ho * wo * SMOOTH_BYTES_PER_PX[kind]
    )
    return int(make), int(kept)


def footprint_band_px(profile) -> tuple[float, float]:
    """:attr:`ChipRotator.band_px` of a rotator of ``profile`` (a wall profile or count):
    it depends on the profile alone."""
    d_s = profile.substrate_reach_px
    return max(min(d_s, 0.0) - 3.0, d_s - 4.0), profile.pad_reach_px + 3.0


def _cropped_distance(big: np.ndarray, img: np.ndarray) -> np.ndarray | None:
    """The signed distance of ``img``'s chip (:func:`simulator.physics.signed_distance_px`)
    cut from ``big``, the same chip's on a larger canvas, where the cut is that distance
    exactly, else None: the canvases centred alike (an even difference of sizes), every
    pixel of the chip inside the cut and none on its edge, the cut's inside (negative
    distance) the image's, and the distances below the exact transform's limit. Then each
    pixel's nearest pixel across the outline lies in the cut on both canvases (beyond it a
    pixel is no nearer than the cut's edge, outside the chip), so the two transforms agree
    bit for bit. The footprint state's rotators and the stateless one differ in margin
    only: one distance transform serves them all (0.5 s on the 4000 um chip at 2 um/px)."""
    from simulator.physics import EDT_EXACT_PX

    (hb, wb), (h, w) = big.shape, img.shape
    dh, dw = hb - h, wb - w
    if dh < 0 or dw < 0 or dh % 2 or dw % 2:
        return None
    cut = big[dh // 2 : dh // 2 + h, dw // 2 : dw // 2 + w]
    inside = img >= 0.5
    edge = inside[0].any() or inside[-1].any() or inside[:, 0].any() or inside[:, -1].any()
    if edge or not inside.any() or not np.array_equal(cut < 0, inside):
        return None
    if np.count_nonzero(big < 0) != np.count_nonzero(inside):  # none beyond the cut
        return None
    if not np.abs(cut).max() < EDT_EXACT_PX:
        return None
    return cut.copy()


class ChipRotator:
    """Rotated chip rasters on one fixed canvas, y-up, with the pattern's pixel parity.

    With ``blur_px`` > 0 (the finite meniscus, :mod:`simulator.physics`) the chip is
    blurred by the meniscus kernel once, unrotated, on a canvas wider by ``margin_px``,
    and each twist rotates that smooth image by splines (:data:`SPLINE_ORDER`, sampled every
    :func:`coarse_step` px): a rasterized sharp
    edge blurred afterwards would sample the smooth field with a staircase of pixel
    coverage, which puts a spurious cusp into the energy at every twist where an edge
    crosses a pixel boundary.
    """

    def __init__(
        self,
        chip: Mask,
        twists: np.ndarray,
        parity: tuple[int, int],
        blur_px: float = 0.0,
        margin_px: int = 0,
        profile=None,
    ):
        self.chip = chip
        self.profile = profile
        self.blur_px = float(blur_px)
        # Pixels between the samples of the smooth image's rotation: coarse for the K_h blur
        # (smooth on the scale of h); every pixel for the wall profile, whose kinks where a pad
        # edge takes and releases the contact line coarse splines would round off.
        self.sample_px = coarse_step(self.blur_px) if profile is None else 1
        self.margin_px = int(margin_px)
        # Canvas (H, W) with W % 2 == parity so chip and pattern pixel grids coincide;
        # just large enough for the twists asked for (a band of twists needs less).
        self.shape = canvas_shape(chip, twists, parity, margin_px)
        # A chip image is resampled on the canvas of a full turn and cut to this one: OpenCV's
        # fixed-point bilinear weights (1/32 px) depend on where a pixel lies on the canvas, so
        # a band of twists (a smaller canvas) would otherwise get other rasters than the
        # whole axis, and a box of the landscape other energies than the full one.
        self._parity = parity
        self._blurred = self._coeffs = None  # the smooth chip and its spline coefficients
        if self.blur_px > 0 or profile is not None:
            self._smooth_chip()

    @functools.cached_property
    def _turn_shape(self) -> tuple[int, int]:
        """The canvas of a full turn (a chip image is resampled on it: see __init__)."""
        turn = 2 * ceil_whole(max(_chip_reach_px(self.chip, True))) + 2
        return (
            max(turn + self._parity[0], self.shape[0]),
            max(turn + self._parity[1], self.shape[1]),
        )

    def _smooth_chip(self) -> None:
        """The blurred chip (or the footprint of its free contact lines) and its spline
        coefficients: made once per chip and canvas, and kept for the next ChipRotator of the
        same chip (a trajectory builds one per box; the distance transform and the spline
        prefilter of a 4000 px chip take tens of seconds each)."""
        key = (
            id(self.chip),
            self.blur_px,
            self.margin_px,
            self.profile,
            self.shape[0] % 2,
            self.shape[1] % 2,
        )
        cached = _SMOOTH.get("entry")
        if cached is not None and cached[0] == key and cached[1]() is self.chip:
            self._blurred, self._half, self._sdf, self._coeffs = cached[2]
            return
        self._sdf = None
        from foundation import wait_line

        ho, wo = smooth_canvas(self.chip, self.margin_px, self.shape, self.profile is not None)
        w_um, h_um = (v * self.chip.um_per_px for v in self.chip.shape[::-1])
        how = "distance transform" if self.profile is not None else "K_h blur"
        wait_line(
            f"meniscus footprint of the {w_um:,.4g} x {h_um:,.4g} um chip ({how} of {wo:,} x {ho:,} px)",
            ho * wo / SMOOTH_PX_PER_S,
        )
        self._blurred = self._blur()
        from scipy import ndimage

        self._coeffs = ndimage.spline_filter(self._blurred, order=SPLINE_ORDER, mode="constant")
        _SMOOTH["entry"] = (
            key,
            weakref.ref(self.chip),
            (self._blurred, self._half, self._sdf, self._coeffs),
        )

    def _blur(self) -> np.ndarray:
        """The unrotated chip blurred by K_h, or its free-contact-line footprint (a
        :class:`simulator.physics.WallProfile`), on a canvas that holds it at every twist (y down)."""
        import scipy.fft as sfft

        from simulator.physics import kernel_spectrum

        c = self.chip
        # One canvas for every build of the scene (a band of twists, a box, the whole axis):
        # the K_h kernel's tail is long, and what of it wraps around a smaller FFT canvas
        # would make boxes differ from the landscape (by 3e-5 of the energy, measured).
        ho, wo = smooth_canvas(c, self.margin_px, self.shape, self.profile is not None)
        if c.geometry is not None:
            img = rasterize(c.geometry, c.um_per_px, shape=(ho, wo))
        else:
            h, w = c.shape
            img = np.zeros((ho, wo))
            r0, c0 = (ho - h) // 2, (wo - w) // 2
            if (
                (ho - h) % 2 or (wo - w) % 2 or r0 < 0 or c0 < 0
            ):  # cannot centre: resample onto the canvas
                img = self._resample(0.0, (ho, wo), c.data)
            else:
                img[r0 : r0 + h, c0 : c0 + w] = c.data
        if self.profile is not None:
            # Free contact lines: the wall profile of the distance from the chip's outline.
            from simulator.physics import signed_distance_px

            # the same chip on the same canvas: one distance transform for every footprint
            # of it (the footprint state's rotators, one per count, share it)
            key = (id(c), ho, wo)
            kept = _SDF.get("entry")
            sdf = None
            if kept is not None and kept[1]() is c:
                sdf = kept[2] if kept[0] == key else _cropped_distance(kept[2], img)
            if sdf is None:
                sdf = signed_distance_px(img)
                _SDF["entry"] = (key, weakref.ref(c), sdf)
            out = self.profile(sdf)
            self._sdf = sdf
        else:
            # Doubled FFT canvas: the kernel's tail does not wrap onto the chip.
            ny, nx = sfft.next_fast_len(2 * ho), sfft.next_fast_len(2 * wo, real=True)
            spec = sfft.rfft2(img, s=(ny, nx)) * kernel_spectrum(ny, nx, self.blur_px)
            # The blur's tails beyond the canvas land in the doubled part, never back on it.
            out = sfft.irfft2(spec, s=(ny, nx))[:ho, :wo]
        # Kept within the margin around the chip's box (the footprint's tail cut there).
        r0, r1, c0, c1 = nonzero_box(img > 0)
        m = self.margin_px
        half_x = max(wo / 2 - (c0 - m), (c1 + m) - wo / 2)
        half_y = max(ho / 2 - (r0 - m), (r1 + m) - ho / 2)
        self._half = (half_x, half_y)
        # A smooth cut (cos^2 over the outer third of the margin), so that no step is left
        # for the splines to ring on.
        xs = np.abs(np.arange(wo) + 0.5 - wo / 2)
        ys = np.abs(np.arange(ho) + 0.5 - ho / 2)
        out *= _taper(ys, half_y, m)[:, None] * _taper(xs, half_x, m)[None, :]
        return np.ascontiguousarray(out)

    def __call__(self, twist_deg: float) -> np.ndarray:
        c = self.chip
        if self._blurred is not None:  # the footprint of free lines comes clipped (profile_at)
            return self._spline_rotate(twist_deg)[::-1]
        if c.geometry is not None:
            g = (
                c.geometry
                if twist_deg == 0
                else affinity.rotate(c.geometry, twist_deg, origin=(0, 0))
            )
            img = rasterize(g, c.um_per_px, shape=self.shape)
        else:
            full = self._resample(twist_deg, self._turn_shape)
            (hf, wf), (h, w) = full.shape, self.shape
            img = full[(hf - h) // 2 : (hf - h) // 2 + h, (wf - w) // 2 : (wf - w) // 2 + w]
        return img[::-1]  # y up

    def _spline_rotate(self, twist_deg: float) -> np.ndarray:
        """The blurred chip rotated by ``twist_deg`` (CCW, y up) onto the canvas, by
        splines (exact sub-pixel positions: OpenCV quantizes them to 1/32 px, which shows
        as steps in the energy at small twists)."""
        from scipy import ndimage

        assert (
            self._blurred is not None and self._coeffs is not None
        )  # a smooth chip (_smooth_chip)
        h, w = self._blurred.shape
        a = math.radians(twist_deg)
        ca, sa = math.cos(a), math.sin(a)
        f = self.sample_px
        if f > 1:
            return self._coarse_rotate(ca, sa, f)
        xi, yi = self._unrotated(twist_deg)
        if self.profile is not None:
            return self.profile_at(xi, yi)
        # Only where the blurred chip is (its box, a margin beyond the chip): zero elsewhere.
        inside = (np.abs(xi) <= self._half[0]) & (np.abs(yi) <= self._half[1])
        out = np.zeros(self.shape)
        rows, cols = -yi[inside] + (h / 2 - 0.5), xi[inside] + (w / 2 - 0.5)
        coords = np.array([rows, cols])
        out[inside] = ndimage.map_coordinates(
            self._coeffs, coords, order=SPLINE_ORDER, mode="constant", cval=0.0, prefilter=False
        )
        return out

    def _unrotated(self, twist_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """(xi, yi) px: where each canvas pixel lies on the unrotated chip (about its centre,
        y up), the chip turned by ``twist_deg``."""
        if getattr(self, "_xy", None) is None:
            ho, wo = self.shape
            v, u = np.mgrid[0:ho, 0:wo].astype(float)
            self._xy = (
                u - (wo / 2 - 0.5),
                -(v - (ho / 2 - 0.5)),
            )  # physical, y up, about the centre
        a = math.radians(twist_deg)
        ca, sa = math.cos(a), math.sin(a)
        x, y = self._xy
        return x * ca + y * sa, -x * sa + y * ca  # inverse rotation

    @property
    def band_px(self) -> tuple[float, float]:
        """(lo, hi): the signed distances (px) between which the free contact lines' footprint
        is interpolated by splines; it is exactly 1 below ``lo`` and 0 above ``hi``: the
        profile's ramp (``d_s`` to ``d_p``) and 4 px (3 from the chip's edge, or from ``d_s``
        when that lies further out) for the splines' ringing about its kinks, which decays by
        0.17 a pixel (1e-5 of the footprint, at most, is left 4 px from ``d_s``: together 0.5 %
        of the noise floor on the 730 um chip at 1 um/px)."""
        assert self.profile is not None  # the free contact lines' footprint
        return footprint_band_px(self.profile)

    def distance_at(self, xi: np.ndarray, yi: np.ndarray, box: bool = True) -> np.ndarray:
        """The signed distance (px) from the chip's outline that the footprint of the free
        contact lines looks up for points (xi, yi) px of the unrotated chip (about its centre,
        y up): the nearest pixel's, and (``box``) +inf outside the footprint's box, where the
        footprint is 0."""
        assert self._sdf is not None  # made with the footprint (_blur)
        h, w = self._sdf.shape
        # The nearest pixel, as one flat index (in place: this runs on millions of points).
        r = np.negative(yi, dtype=float)
        r += h / 2 - 0.5
        np.clip(np.rint(r, out=r), 0, h - 1, out=r)
        c = np.add(xi, w / 2 - 0.5, dtype=float)
        np.clip(np.rint(c, out=c), 0, w - 1, out=c)
        r *= w
        r += c
        s = self._sdf.ravel().take(r.astype(np.intp))
        if not box:
            return s
        np.abs(xi, out=c)
        r = np.abs(yi, out=r)
        s[(c > self._half[0]) | (r > self._half[1])] = np.inf
        return s

    def profile_at(self, xi: np.ndarray, yi: np.ndarray, s: np.ndarray | None = None) -> np.ndarray:
        """The free contact lines' footprint at points (xi, yi) px of the unrotated chip
        (about its centre, y up), in [0, 1]: what a rotation puts on the canvas pixels that
        map there (``s``: their :meth:`distance_at`, when known)."""
        from scipy import ndimage

        assert self._coeffs is not None  # made by _smooth_chip
        h, w = self._coeffs.shape
        if s is None:
            s = self.distance_at(xi, yi)
        # The wall profile is 1 deep inside the chip and 0 beyond the pad reach: splines
        # only in the band between (band_px), exactly 1 and 0 elsewhere; the band is a few
        # per cent of the canvas.
        lo, hi = self.band_px
        band = (s >= lo) & (s <= hi)
        out = (s < lo).astype(float)
        out[band] = ndimage.map_coordinates(
            self._coeffs,
            np.array([-yi[band] + (h / 2 - 0.5), xi[band] + (w / 2 - 0.5)]),
            order=SPLINE_ORDER,
            mode="constant",
            cval=0.0,
            prefilter=False,
        )
        # The splines overshoot the wall profile's kinks by ~1e-4: clipped, the floor where
        # the footprint is 1 stays exactly 1 at every twist (no spurious minima).
        return np.clip(out, 0.0, 1.0)

    def _coarse_rotate(self, ca: float, sa: float, f: int) -> np.ndarray:
        """The rotation sampled every ``f`` px (where the blurred chip is smooth on the scale
        of 4 f px) and brought to every pixel by separable cubic B-splines: a fixed linear
        map of the coarse samples, so the result stays smooth in the twist."""
        from scipy import ndimage

        assert self._blurred is not None and self._coeffs is not None  # made by _smooth_chip
        ho, wo = self.shape
        h, w = self._blurred.shape
        # The coarse grid covers the smooth image at every twist (the radius of its cut box)
        # and a few samples of zeros beyond, whatever this canvas is: its spline prefilter
        # (mirror ends) then sees the same samples for a band of twists or a box as for the
        # whole landscape, so boxes and the landscape agree to round-off.
        reach = max(math.hypot(*self._half), (ho - 1) / 2, (wo - 1) / 2)
        ky = kx = int(math.ceil(reach / f)) + 4
        yk = (
            -f * np.arange(-ky, ky + 1, dtype=float)[:, None]
        )  # physical y of coarse rows (top row first)
        xk = f * np.arange(-kx, kx + 1, dtype=float)[None, :]
        xi, yi = xk * ca + yk * sa, -xk * sa + yk * ca
        coords = np.array([-yi + (h / 2 - 0.5), xi + (w / 2 - 0.5)])
        coarse = ndimage.map_coordinates(
            self._coeffs, coords, order=SPLINE_ORDER, mode="constant", cval=0.0, prefilter=False
        )
        c = ndimage.spline_filter(coarse, order=3, mode="mirror")
        out = _bspline_rows(c, (np.arange(ho) - (ho - 1) / 2) / f + ky)
        return _bspline_rows(out.T, (np.arange(wo) - (wo - 1) / 2) / f + kx).T

    def _resample(
        self,
        twist_deg: float,
        shape: tuple[int, int] | None = None,
        data: np.ndarray | None = None,
        cubic: bool = False,
    ) -> np.ndarray:
        import cv2

        data = self.chip.data if data is None else data
        h, w = data.shape
        ho, wo = self.shape if shape is None else shape
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
            data,
            m,
            (wo, ho),
            flags=(cv2.INTER_CUBIC if cubic else cv2.INTER_LINEAR) | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0.0,
        )
        return out if cubic else np.clip(out, 0.0, 1.0)


def _taper(d: np.ndarray, half: float, margin: float) -> np.ndarray:
    """1 within ``half - margin / 3`` of the centre, 0 beyond ``half``, cos^2 in between."""
    w = max(margin / 3.0, 1.0)
    t = np.clip((d - (half - w)) / w, 0.0, 1.0)
    return np.cos(0.5 * np.pi * t) ** 2


def coarse_step(blur_px: float) -> int:
    """Pixels between the samples of a blurred chip's rotation: its height over
    :data:`COARSE_HEIGHTS`, at least 1 (every pixel)."""
    return max(1, int(blur_px // COARSE_HEIGHTS))


#: A blurred chip is sampled every h / COARSE_HEIGHTS pixels when rotated (cubic B-splines
#: in between): measured within 3.5e-4 (of a chip value of 1) of the every-pixel rotation for h = 19 px.
COARSE_HEIGHTS = 4.0


def _bspline_rows(c: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Rows at fractional row coordinates ``u`` of cubic B-spline coefficients ``c``."""
    k0 = np.floor(u).astype(int)
    t = (u - k0)[:, None]
    t2, t3 = t * t, t * t * t
    w = ((1 - t) ** 3 / 6, (3 * t3 - 6 * t2 + 4) / 6, (-3 * t3 + 3 * t2 + 3 * t + 1) / 6, t3 / 6)
    n = c.shape[0]
    out = np.zeros((len(u), c.shape[1]))
    for j, wj in enumerate(w):
        out += wj * c[np.clip(k0 + j - 1, 0, n - 1)]
    return out


def mirror_twins(mirror: bool, twists_deg: np.ndarray) -> dict[int, int]:
    """{i: j} for twists t_j = -t_i < 0 when the chip is mirror-symmetric about the x
    axis (``mirror``, :attr:`simulator.landscape.TwistAxis.mirror`): its raster at -alpha
    is the one at +alpha upside down, so one forward transform serves both
    (:meth:`Correlator.__call__` ``mirror_out``)."""
    if len(twists_deg) < 2 or not mirror:
        return {}
    pos = {round(float(t), 9): i for i, t in enumerate(twists_deg)}
    return {
        i: pos[round(-float(t), 9)]
        for i, t in enumerate(twists_deg)
        if t > 0 and round(-float(t), 9) in pos
    }


def rotate_footprints(rotators: list[ChipRotator], twist_deg: float) -> list[np.ndarray]:
    """Several free-contact-line footprints of one chip at ``twist_deg``, each exactly as its
    rotator's own call gives it: where footprints share the canvas and the signed distance
    (the footprint state's wall and counts, :mod:`simulator.landscape._footprint`), the
    canvas's points on the unrotated chip and their distances are found once, not once per
    footprint; any other rotator is called on its own."""
    first = rotators[0]
    shared = all(
        r.profile is not None
        and r.sample_px == 1
        and r.shape == first.shape
        and r._sdf is not None
        and r._sdf is first._sdf
        for r in rotators
    )
    if not shared:
        return [r(twist_deg) for r in rotators]
    xi, yi = first._unrotated(twist_deg)
    near = first.distance_at(xi, yi, box=False)
    ax, ay = np.abs(xi), np.abs(yi)
    out = []
    for r in rotators:
        s = near.copy()
        s[(ax > r._half[0]) | (ay > r._half[1])] = np.inf  # beyond its box: no footprint
        out.append(r.profile_at(xi, yi, s)[::-1])
    return out
