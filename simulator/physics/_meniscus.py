"""Finite meniscus: the liquid height the overlap model leaves out.

The overlap model (``E = Delta_gamma * A_ol``) is the thin-film limit: its energy has
a V-shaped cusp wherever a chip edge crosses a pattern edge, so the force at
alignment jumps from +F to -F, the stiffness there is infinite and a defect changes
the slope of the well but never the position of its bottom. A liquid bridge of
height ``h`` rounds every such cusp over a bias of about ``h``.

Two footprints: ``K_h`` for contact lines pinned at the pad edges (``pinned``), and the
wall profile for free contact lines (the default), each derived below.

Pinned contact lines: the K_h blur
----------------------------------
Consider one straight chip edge over one parallel pattern edge, offset by ``d``
along their normal, with the liquid pinned on both (the flat-wall, "parallelepiped"
picture). The liquid-air wall between them is a plane strip of height ``h`` and
width ``d``, so per unit length of edge its area is ``sqrt(d^2 + h^2)``, against
``|d|`` in the thin-film limit. The two differ by a convolution::

    sqrt(d^2 + h^2) = (|.| * k_h)(d),   k_h(s) = h^2 / (2 (s^2 + h^2)^(3/2))

(both sides are even, have the second derivative ``h^2 / (d^2 + h^2)^(3/2)`` and
agree as ``|d| -> inf``); ``k_h`` is a normalised Student-t density with two degrees of
freedom. Its isotropic two-dimensional version, the bivariate t density

    K_h(r) = h^2 / (pi (r^2 + h^2)^2),   Fourier transform  K^(q) = (h q) K_1(h q)

(``K_1`` the modified Bessel function of the second kind), has ``k_h`` as its
profile across any straight line. So the model is

    E_h(x, y, alpha) = Delta_gamma * sum_p chip_alpha(p - (x, y)) * (w * K_h)(p)

the overlap energy of the chip with the pattern blurred by ``K_h``: the liquid
footprint is wider than the pattern's edges by a width of order ``h``. Equivalently,
every twist plane of the overlap landscape is convolved with ``K_h`` (K_h is
isotropic, so blurring the pattern or the rotated chip is the same thing). It is
built by the same FFT correlation: the pattern's spectrum is multiplied once by
``K^``, which costs nothing per twist.

What it gives (``L`` a side of a square chip on an identical pad, ``gamma`` the
energy per unit length of edge, ``|Delta_gamma| / 2``; with pinned contact lines
``Delta_gamma = -2 gamma_LA`` and ``gamma = gamma_LA``):

* a shift ``x`` along one side: ``E(x) - E(0) = 2 gamma L (sqrt(x^2 + h^2) - h)`` per
  straight pair of edges, stiffness ``2 gamma L / h``, force saturating at ``2 gamma L``;
* a twist ``alpha``: every point of an edge moves by ``alpha s`` across it, so the
  twist stiffness is ``gamma L^3 / (3 h)``; regular polygons are isotropic;
* as ``h -> 0``, ``K^ -> 1`` and the overlap landscape returns to round-off.

Where the edges end (the chip's corners), the blur also acts along the edge: the
effective edge is shorter by about ``h``, so the stiffness of a square is
``(2 gamma L / h)(1 - 2 h / (pi L))`` and its saturated force ``2 gamma (L - h)``
(measured and tested: a deficit of order ``h / L``). A real meniscus rounds its
corners too; Surface Evolver is the referee (``validation/``, docs/guide/meniscus.md).

Assumptions and regime: the liquid wets the chip and the pattern where the overlap
model says; gravity is neglected (``h`` well below the capillary length, 2.7 mm for
water); the walls are flat between contact lines a distance ``d`` apart, which holds
for ``h`` small against the chip (:data:`REGIME_FRACTION`: a warning beyond
``h > 0.2`` of the chip's smallest side, where Surface Evolver puts the torque 18 % above
the model's; an error beyond the side itself). With
``pinned`` the contact lines are held at the pad edges (a liquid confined by a
superhydrophobic substrate): only liquid-air area changes, ``Delta_gamma = -2
gamma_LA`` for every pad whatever its contact angle. Without it the contact lines
are free on the wettability map, ``Delta_gamma`` comes from the contact angles, and the
footprint is the wall profile below, not the ``K_h`` blur.

The height is the flat-slab estimate ``h = V / A`` (``A`` the chip's wetted area)
unless it is given directly.

Free contact lines: the wall profile
------------------------------------
Without ``pinned`` the liquid's contact line on the substrate is free: it stands where
the wall meets the surface at the surface's own contact angle. With the chip's edge
holding the top of a flat wall of height ``h``, a contact line a distance ``c`` beyond
the chip edge costs, per unit length of edge, ``gamma sqrt(c^2 + h^2)`` of liquid-air wall
and wets ``c`` of the surface under it. On a surface of Young angle ``theta`` the wall's
energy is lowest at the reach ``c = h cot(theta)``. So on the usual wettable substrate
the liquid reaches ``d_s = h cot(theta_s)`` beyond the chip, and on a pad the further
``d_p = h cot(theta_p)``. Between the two, a pad edge holds the contact line (Gibbs'
criterion: the wall's angle lies between the pad's and the substrate's).

Take one pad edge a distance ``u`` beyond a chip edge, with the pad on the chip's side.
Minimising over the contact line's position gives the energy against ``u``. Its slope
is ``Delta_gamma f(u)``, with the *wall profile*

    f(u) = 1                                                  u <= d_s
    f(u) = (cos theta_p - u / sqrt(u^2 + h^2)) / (cos theta_p - cos theta_s)   d_s <= u <= d_p
    f(u) = 0                                                  u >= d_p

(``f`` falls from 1 to 0 while the edge holds the line). Summed over every pattern edge,
this is the overlap energy of the pattern with a *liquid footprint* ``f(s)``. Here ``s``
is the signed distance of a point from the chip's outline (negative inside):

    E_h(x, y, alpha) = Delta_gamma * sum_p f(s_alpha(p - (x, y))) * w(p)

It is built like the overlap landscape: the footprint is computed once from the
unrotated chip (a Euclidean distance transform of its raster), rotated with the chip,
and correlated with the pattern. What it gives:

* a chip on a same-size pad floats freely for ``|x| < d_s`` (both lines on the substrate),
  then the force rises to ``|Delta_gamma| L`` over ``d_s < |x| < d_p``;
* a gap that the liquid's line can cross on the substrate (the four-pad's cross): zero force
  while the line is on the gap. This is the flat part of the overlap model, moved outwards by
  about ``d_s``. The pads beyond the line do not pull: ``f`` is zero beyond ``d_p``, so no tail;
* ``theta_p -> 0``, ``theta_s -> 180`` deg: ``f(u) = (1 - u / sqrt(u^2 + h^2)) / 2``, the
  pinned profile of ``k_h`` above. The pinned model is that limit (held at the pad edges
  whatever the angles); the pinned scenes keep the ``K_h`` blur, a superposition of edges that
  also gives the corners as Surface Evolver does;
* ``h -> 0``: ``f`` tends to the chip's indicator, the overlap landscape.

Assumptions: every chip edge holds its wall (a sharp edge pins); each edge's wall is
flat and independent of the other edges (the ends of an edge are rounded by the distance
field, radially about a corner). The profile is the equilibrium of one edge over one pad
edge. Where two pad edges lie within ``d_p`` of one chip edge, their responses add.
That holds for a pad the line leaves (the four-pad's outer ramp). It does not hold for a
pad across a dry gap: there the real line snaps onto the pad when it touches it at
``d_s``, but the sum makes it start pulling from ``d_p``. On the 730/50 four-pad this
shortens the flat part (validation/FOURPAD_INWARD.md; docs/physics.md §3.3). The reach
uses the flat-slab ``h`` and straight walls. Surface Evolver's curved walls reach a little
further (25 um against 21.7 um on the 730 um chip at 20 nl). The model describes a chip
coming in from its placement offset: the liquid wets what the chip has reached. A chip
pulled outwards from alignment keeps the far pads wet longer (a hysteresis that Surface
Evolver shows and that the model leaves out).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from foundation import InputError
from simulator.core import UM2

#: From this height (px) up the blur is applied to the chip, which is then rotated as a
#: smooth image; below it to the pattern (exact chip rasters; the h -> 0 limit to round-off).
CHIP_BLUR_MIN_PX = 1.0
#: Above this fraction of the chip's smallest side the flat-wall picture is stretched (warning).
REGIME_FRACTION = 0.2
#: The blurred pattern is kept (cropping, FFT padding, pose window) out to this many heights
#: beyond the pattern: the kernel's mass beyond r is h^2 / (r^2 + h^2), 10 % at 3 h; across a straight edge 2.6 % lies beyond 3 h.
MARGIN_HEIGHTS = 3.0


#: The wall profile's footprint is cut (smoothly) beyond this many heights from the chip: a
#: pad angle below 5.7 deg would otherwise reach further than 10 h.
REACH_CAP_HEIGHTS = 10.0


@dataclass(frozen=True)
class WallProfile:
    """The liquid footprint around a chip with free contact lines (module docstring).

    h_px: the meniscus height in pixels; cos_pad, cos_substrate: the cosines of the pad's
    and the substrate's Young angles (pad more wettable: ``cos_pad > cos_substrate``).
    """

    h_px: float
    cos_pad: float
    cos_substrate: float

    @classmethod
    def from_angles(cls, h_px: float, pad_deg: float, substrate_deg: float) -> WallProfile:
        return cls(
            float(h_px), math.cos(math.radians(pad_deg)), math.cos(math.radians(substrate_deg))
        )

    def reach_px(self, cos_theta: float) -> float:
        """``h cot(theta)``: where a free line on a surface of this angle stands beyond the
        chip edge (negative under the chip for theta > 90 deg), at most :data:`REACH_CAP_HEIGHTS` h."""
        c = min(cos_theta, 1.0)
        cap = REACH_CAP_HEIGHTS * self.h_px
        if c >= 1.0:
            return cap
        return max(-cap, min(cap, self.h_px * c / math.sqrt(1.0 - c * c)))

    @property
    def substrate_reach_px(self) -> float:
        """``d_s = h cot(theta_s)`` (px)."""
        return self.reach_px(self.cos_substrate)

    @property
    def pad_reach_px(self) -> float:
        """``d_p = h cot(theta_p)`` (px): beyond it the footprint is zero."""
        return self.reach_px(self.cos_pad)

    @property
    def ramp_px(self) -> float:
        """``d_p - d_s`` (px): the width over which a pad edge holds the line."""
        return self.pad_reach_px - self.substrate_reach_px

    @property
    def margin_px(self) -> int:
        """Pixels kept beyond the chip for the footprint: its reach and a smooth cut after it."""
        return int(math.ceil(max(self.pad_reach_px, 0.0) * 1.5)) + 2

    def __call__(self, s_px: np.ndarray) -> np.ndarray:
        """``f(s)`` at signed distances ``s`` (px, negative inside the chip)."""
        s = np.asarray(s_px, float)
        h = self.h_px
        out = np.array(s <= self.substrate_reach_px, dtype=float)
        # The ramp only between the reaches (a band along the outline: a few per cent of a
        # footprint's canvas of tens of megapixels), 1 before it and 0 beyond.
        ramp = np.asarray((s > self.substrate_reach_px) & (s < self.pad_reach_px))
        v = s[ramp]
        with np.errstate(invalid="ignore", divide="ignore"):
            f = (self.cos_pad - v / np.sqrt(v * v + h * h)) / (self.cos_pad - self.cos_substrate)
        out[ramp] = np.clip(f, 0.0, 1.0)
        return out


def signed_distance_px(img: np.ndarray) -> np.ndarray:
    """Signed distance (px, negative inside) of every pixel centre from the outline of the
    region ``img >= 0.5``: a Euclidean distance transform, the outline half a pixel beyond
    the last pixel centre inside."""
    inside = np.asarray(img) >= 0.5
    if not inside.any():
        return np.full(inside.shape, np.inf)
    out = _edt(~inside)
    out -= 0.5
    inn = _edt(inside)
    inn -= 0.5
    return np.where(inside, -inn, out)


#: Distances (px) below which :func:`_edt` is exact: their squares, whole numbers, are told apart
#: in float32 (beyond, the footprint is flat: 1 inside the chip, 0 far outside).
EDT_EXACT_PX = 2048.0


def _edt(mask: np.ndarray) -> np.ndarray:
    """Euclidean distance (px, float64) of every pixel of ``mask`` to the nearest pixel outside
    it: SciPy's ``distance_transform_edt``, by OpenCV's exact transform (Felzenszwalb's, about
    8x faster and a fifth of the memory). OpenCV returns float32; a squared distance between
    pixel centres is a whole number, so rounding the square gives SciPy's value exactly up to
    :data:`EDT_EXACT_PX`."""
    if mask.all():
        from scipy.ndimage import distance_transform_edt

        return distance_transform_edt(mask)
    import cv2

    d = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    d = d.astype(np.float64)
    sq = np.multiply(d, d)  # whole-canvas passes in place: this runs on tens of megapixels
    np.sqrt(np.rint(sq, out=sq), out=sq)
    np.copyto(d, sq, where=d < EDT_EXACT_PX)
    return d


def kernel_spectrum(ny: int, nx: int, h_px: float, dtype=np.float64) -> np.ndarray:
    """``K^(q) = (h q) K_1(h q)`` on the (ny, nx // 2 + 1) grid of a real 2-D FFT.

    q is the angular wavenumber (rad/px) of each bin; K^(0) = 1 (the kernel is
    normalised), K^ -> 1 everywhere as h -> 0.
    """
    from scipy.special import k1e

    fy = np.fft.fftfreq(ny)[:, None]
    fx = np.fft.rfftfreq(nx)[None, :]
    q = float(h_px) * 2 * np.pi * np.sqrt(fy * fy + fx * fx)
    with np.errstate(invalid="ignore", over="ignore", under="ignore"):
        out = np.where(q > 0, q * k1e(np.where(q > 0, q, 1.0)) * np.exp(-q), 1.0)
    return out.astype(dtype)


def kernel_image(h_px: float, radius_px: int) -> np.ndarray:
    """``K_h`` sampled on a (2 r + 1)^2 pixel grid (per px^2; for tests and pictures)."""
    r = np.arange(-radius_px, radius_px + 1, dtype=float)
    rr = r[:, None] ** 2 + r[None, :] ** 2
    return h_px**2 / (np.pi * (rr + h_px**2) ** 2)


def margin_px(h_px: float) -> int:
    """Pixels kept around the pattern for the blurred footprint (:data:`MARGIN_HEIGHTS` h)."""
    return int(math.ceil(MARGIN_HEIGHTS * h_px)) if h_px > 0 else 0


def require_height(h_um: float, chip_min_side_um: float, flag: str = "--meniscus-height") -> float:
    """The meniscus height, checked: positive, finite, at most the chip's smallest side."""
    try:
        h = float(h_um)
    except (TypeError, ValueError):
        raise InputError(f"{flag} must be a number of um, got {h_um!r}") from None
    if not math.isfinite(h) or h <= 0:
        raise InputError(f"{flag} must be a positive, finite height in um, got {h_um!r}")
    if h > chip_min_side_um:
        raise InputError(
            f"meniscus height {h:.4g} um ({flag}) is larger than the chip's smallest side {chip_min_side_um:.4g} um: "
            "the thin-film picture no longer holds; use a smaller --volume or --meniscus-height"
        )
    return h


def regime_warning(h_um: float, chip_min_side_um: float) -> str | None:
    """A one-line warning when ``h`` is beyond the model's stated regime, else None."""
    if h_um > REGIME_FRACTION * chip_min_side_um:
        return (
            f"meniscus height {h_um:.3g} um is more than {REGIME_FRACTION:g} of the chip's smallest side "
            f"({chip_min_side_um:.3g} um): the flat-wall meniscus model is stretched there (corner effects of order h/L)"
        )
    return None


def flat_wall_energy_J(x_um, edge_um: float, h_um: float, gamma_N_m: float) -> np.ndarray:
    """Flat-wall energy of a shift ``x`` across two straight edges of length ``edge_um``:
    ``2 gamma L (sqrt(x^2 + h^2) - h)`` in J (um in, J out)."""
    x = np.asarray(x_um, float)
    return 2 * gamma_N_m * edge_um * (np.sqrt(x * x + h_um * h_um) - h_um) * UM2


def flat_wall_stiffness_N_m(edge_um: float, h_um: float, gamma_N_m: float) -> float:
    """Small-shift stiffness ``2 gamma L / h`` (N/m) of two straight edges of length L
    (:func:`simulator.physics.parallelepiped_stiffness`)."""
    from simulator.physics._mechanics import parallelepiped_stiffness

    return parallelepiped_stiffness(h_um, edge_um, gamma_N_m)


def flat_wall_twist_stiffness_Nm(side_um: float, h_um: float, gamma_N_m: float) -> float:
    """Twist stiffness ``gamma L^3 / (3 h)`` (N m/rad) of a square of side L."""
    return gamma_N_m * side_um**3 / (3 * h_um) * UM2
