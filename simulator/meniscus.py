"""Finite meniscus: the liquid height the overlap model leaves out.

The overlap model (``E = Delta_gamma * A_ol``) is the thin-film limit: its energy has
a V-shaped cusp wherever a chip edge crosses a pattern edge, so the force at
alignment jumps from +F to -F, the stiffness there is infinite and a defect changes
the slope of the well but never the position of its bottom. A liquid bridge of
height ``h`` rounds every such cusp over a bias of about ``h``.

The model
---------
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
corners too; Surface Evolver is the referee (``validation/``, README).

Assumptions and regime: the liquid wets the chip and the pattern where the overlap
model says; gravity is neglected (``h`` well below the capillary length, 2.7 mm for
water); the walls are flat between contact lines a distance ``d`` apart, which holds
for ``h`` small against the chip (:data:`REGIME_FRACTION`: a warning beyond
``h > 0.2`` of the chip's smallest side, where Surface Evolver puts the torque 18 % above
the model's; an error beyond the side itself). With
``pinned`` the contact lines are held at the pad edges (a liquid confined by a
superhydrophobic substrate): only liquid-air area changes, ``Delta_gamma = -2
gamma_LA`` for every pad whatever its contact angle. Without it the contact lines
follow the wettability map and ``Delta_gamma`` comes from the contact angles, as in
the overlap model; the rounding over ``h`` is the same.

The height is the flat-slab estimate ``h = V / A`` (``A`` the chip's wetted area)
unless it is given directly.
"""

from __future__ import annotations

import math

import numpy as np

from patterns.errors import InputError

#: From this height (px) up the blur is applied to the chip, which is then rotated as a
#: smooth image; below it to the pattern (exact chip rasters; the h -> 0 limit to round-off).
CHIP_BLUR_MIN_PX = 1.0
#: Above this fraction of the chip's smallest side the flat-wall picture is stretched (warning).
REGIME_FRACTION = 0.2
#: The blurred pattern is kept (cropping, FFT padding, pose window) out to this many heights
#: beyond the pattern: the kernel's mass beyond r is h^2 / (r^2 + h^2), 10 % at 3 h; across a straight edge 2.6 % lies beyond 3 h.
MARGIN_HEIGHTS = 3.0


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
    return 2 * gamma_N_m * edge_um * (np.sqrt(x * x + h_um * h_um) - h_um) * 1e-12


def flat_wall_stiffness_N_m(edge_um: float, h_um: float, gamma_N_m: float) -> float:
    """Small-shift stiffness ``2 gamma L / h`` (N/m) of two straight edges of length L
    (:func:`simulator.materials.parallelepiped_stiffness`)."""
    from simulator.materials import parallelepiped_stiffness

    return parallelepiped_stiffness(h_um, edge_um, gamma_N_m)


def flat_wall_twist_stiffness_Nm(side_um: float, h_um: float, gamma_N_m: float) -> float:
    """Twist stiffness ``gamma L^3 / (3 h)`` (N m/rad) of a square of side L."""
    return gamma_N_m * side_um**3 / (3 * h_um) * 1e-12
