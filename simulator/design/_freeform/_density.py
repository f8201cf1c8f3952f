"""The free-form pattern's parametrisation: design variables to a wettability map, as
topology optimisation does it.

Per pixel of the design canvas a free variable ``z``; then

1. the density ``rho = sigmoid(z)`` in (0, 1), set to 1 on the keep-in pixels and 0 on the
   keep-out ones (so added area grows smoothly out of the pads and stays clear of the
   dry areas);
2. the minimum-feature filter: a cone (linear hat) of radius ``R`` = the minimum feature,
   normalised by the filtered canvas (a uniform density stays uniform up to the canvas's
   edge); features narrower than about ``R`` are averaged away;
3. optionally a random smooth field added (the edge perturbations of the robust objective,
   :func:`noise_field`): shifting the filtered density by ``a`` moves an edge by about
   ``a / slope``, the filtered step's slope at its middle (:attr:`DensityMap.edge_slope_per_px`);
4. the smoothed Heaviside projection ``(tanh(b eta) + tanh(b (x - eta))) / (tanh(b eta) +
   tanh(b (1 - eta)))`` with ``eta = 0.5`` and a sharpness ``b`` raised over the iterations
   (continuation): grey at first, nearly binary at the end;
5. keep-in forced to 1 and keep-out to 0.

Every step is smooth in ``z``, so the energy's gradient flows back to the variables. The
arrays are numpy here (made once); the maps are JAX functions of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

__all__ = ["DensityMap", "density_map", "noise_field", "pattern_of", "project"]

#: The projection's threshold.
ETA = 0.5


def cone_kernel(radius_px: float) -> np.ndarray:
    """The cone filter ``max(0, R - r)`` on a (2 ceil(R) + 1)^2 grid, summing to 1."""
    n = int(math.ceil(radius_px))
    r = np.hypot(*np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1)))
    k = np.maximum(0.0, radius_px - r)
    return k / k.sum()


def _spectrum(kernel: np.ndarray, fft: tuple[int, int]) -> np.ndarray:
    """rfft2 of a centred odd kernel, its centre moved to index (0, 0): a convolution with
    it needs no shift."""
    n = kernel.shape[0] // 2
    full = np.zeros(fft)
    full[: 2 * n + 1, : 2 * n + 1] = kernel
    return np.fft.rfft2(np.roll(full, (-n, -n), axis=(0, 1)))


@dataclass(frozen=True, eq=False)
class DensityMap:
    """The fixed arrays of the parametrisation (:func:`density_map`).

    keep_in, keep_out: (H, W) bool (image rows). filter_spec: the cone's spectrum on the
    (ny, nx) padded canvas; norm: the filtered canvas indicator (H, W). noise_spec: the
    Gaussian smoothing of the perturbation fields (None without perturbations), noise_scale
    its normalisation to unit variance. edge_slope_per_px: the filtered straight edge's
    slope at its middle (1/px).
    """

    shape: tuple[int, int]
    fft: tuple[int, int]
    radius_px: float
    keep_in: np.ndarray
    keep_out: np.ndarray
    filter_spec: np.ndarray
    norm: np.ndarray
    noise_spec: np.ndarray | None
    noise_scale: float
    edge_slope_per_px: float

    def arrays(self, dtype) -> dict:
        """The arrays the JAX maps take (as jnp arrays of ``dtype``)."""
        import jax.numpy as jnp

        from simulator.design._freeform._energy import enable_float64

        enable_float64(dtype)
        cdt = jnp.complex128 if np.dtype(dtype) == np.float64 else jnp.complex64
        out = {
            "keep_in": jnp.asarray(self.keep_in),
            "keep_out": jnp.asarray(self.keep_out),
            "filter_spec": jnp.asarray(self.filter_spec, cdt),
            "norm": jnp.asarray(self.norm, dtype),
        }
        if self.noise_spec is not None:
            out["noise_spec"] = jnp.asarray(self.noise_spec, cdt)
        return out


def density_map(
    keep_in: np.ndarray, keep_out: np.ndarray, radius_px: float, noise_length_px: float = 0.0
) -> DensityMap:
    """The parametrisation's arrays for a canvas with these masks, a filter of radius
    ``radius_px`` and perturbation fields correlated over ``noise_length_px`` (0: none)."""
    h, w = keep_in.shape
    k = cone_kernel(radius_px)
    n = k.shape[0] // 2
    g = int(math.ceil(3 * noise_length_px)) if noise_length_px > 0 else 0
    pad = max(n, g)
    fft = (sfft.next_fast_len(h + 2 * pad), sfft.next_fast_len(w + 2 * pad, real=True))
    spec = _spectrum(k, fft)
    ones = np.zeros(fft)
    ones[:h, :w] = 1.0
    norm = np.fft.irfft2(np.fft.rfft2(ones) * spec, s=fft)[:h, :w]
    # A straight edge filtered: the kernel's marginal (column sums) at its centre.
    slope = float(k.sum(axis=0)[n])
    noise_spec, noise_scale = None, 1.0
    if noise_length_px > 0:
        r = np.arange(-g, g + 1)
        gk = np.exp(-0.5 * (r[:, None] ** 2 + r[None, :] ** 2) / noise_length_px**2)
        noise_spec = _spectrum(gk, fft)
        noise_scale = float(1.0 / math.sqrt((gk**2).sum()))
    return DensityMap(
        (h, w),
        fft,
        float(radius_px),
        np.asarray(keep_in, bool),
        np.asarray(keep_out, bool),
        spec,
        np.maximum(norm, 1e-12),
        noise_spec,
        noise_scale,
        slope,
    )


def project(x, beta, eta: float = ETA):
    """The smoothed Heaviside projection of ``x`` (0 -> 0, 1 -> 1, sharper with ``beta``)."""
    import jax.numpy as jnp

    a = jnp.tanh(beta * eta)
    return (a + jnp.tanh(beta * (x - eta))) / (a + jnp.tanh(beta * (1.0 - eta)))


def _conv(x, spec, shape: tuple[int, int], fft: tuple[int, int]):
    import jax.numpy as jnp

    h, w = shape
    return jnp.fft.irfft2(jnp.fft.rfft2(x, s=fft) * spec, s=fft)[:h, :w]


def filtered(z, arrays: dict, shape: tuple[int, int], fft: tuple[int, int]):
    """The filtered density of the design variables ``z`` (H, W)."""
    import jax
    import jax.numpy as jnp

    rho = jax.nn.sigmoid(z)
    rho = jnp.where(arrays["keep_in"], 1.0, jnp.where(arrays["keep_out"], 0.0, rho))
    return _conv(rho, arrays["filter_spec"], shape, fft) / arrays["norm"]


def noise_field(key, arrays: dict, shape: tuple[int, int], fft: tuple[int, int], scale: float):
    """A random smooth field of unit standard deviation (Gaussian-correlated white noise)."""
    import jax

    white = jax.random.normal(key, fft, dtype=arrays["norm"].dtype)
    return _conv(white, arrays["noise_spec"], shape, fft) * scale


def pattern_of(z, beta, arrays: dict, shape, fft, shift=None):
    """The wettability map (H, W) in [0, 1] of ``z``: filtered, shifted by ``shift`` (a field
    in density units, or None), projected, with the keep-in at 1 and the keep-out at 0."""
    import jax.numpy as jnp

    x = filtered(z, arrays, shape, fft)
    if shift is not None:
        x = x + shift
    w = project(x, beta)
    return jnp.where(arrays["keep_in"], 1.0, jnp.where(arrays["keep_out"], 0.0, w))
