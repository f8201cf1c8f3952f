"""The differentiable landscape of a free-form pattern: the chip side made once by the
project's own rotator, the pattern side a JAX FFT correlation.

The energy is ``E(x, y, alpha) = Delta_gamma s^2 sum_p chip_alpha(p - (x, y)) w(p)``
(docs/physics.md §3.2, [Eq. 9]), where ``chip_alpha`` is the chip's raster at the twist, or
with a finite meniscus its liquid footprint (docs/physics.md §3.3): the wall profile of
free contact lines or the ``K_h`` blur, both made from the chip alone. The chip side is
fixed, so the energy is *linear* in the pattern ``w``: its gradient with respect to ``w`` is
one more correlation, which reverse-mode autodiff of the FFTs computes. The rasters come from
:func:`simulator.landscape.plan` (the same rotator, footprint and pixel grid as
:func:`simulator.landscape.build_landscape`), so the planes here equal that landscape's at
the same poses to round-off (tested). Below a pixel of meniscus the ``K_h`` blur is on the
pattern side, as in the build: its spectrum multiplies the pattern's.

Conventions: the pattern ``w`` is (H, W) in image rows (row 0 at the top), its centre the
physical origin (:class:`patterns.geometry.Mask`); a plane is ``[y, x]`` with y up, plane index
``(Y + ry, X + rx)`` for a chip centre at ``(X, Y)`` px from the origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from simulator.core import UM2

__all__ = ["ChipSide", "chip_side", "enable_float64", "overlap_planes"]


def enable_float64(dtype) -> None:
    """Let float64 arrays stay float64 in JAX (``jax_enable_x64``), switched on where a float64
    problem's arrays are made, as the steppers do; float32 still computes in float32."""
    if np.dtype(dtype) == np.float64:
        import jax

        if not jax.config.jax_enable_x64:  # pyright: ignore[reportAttributeAccessIssue]
            jax.config.update("jax_enable_x64", True)


@dataclass(frozen=True, eq=False)
class ChipSide:
    """The chip at the twists an objective needs, ready to correlate with a pattern.

    chips: (T, hc, wc) rasters or footprints, y up, centred, on the pattern's pixel grid.
    pattern_shape: (H, W) of the design canvas. fft: (ny, nx) of the transforms (linear,
    never circular: ny >= H + hc, nx >= W + wc). ry, rx: the planes hold ``Y`` in
    ``[-ry, ry]`` and ``X`` in ``[-rx, rx]`` px, every pose at which the chip touches the
    canvas. energy_per_px2_J: ``Delta_gamma s^2`` (J per px^2 of overlap, negative).
    kernel: the ``K_h`` spectrum on the pattern side (meniscus below a pixel), else None.
    chip_area_px2: the chip's (footprint's) sum at twist 0, the overlap scale.
    """

    twists_deg: tuple[float, ...]
    chips: np.ndarray
    pattern_shape: tuple[int, int]
    fft: tuple[int, int]
    ry: int
    rx: int
    um_per_px: float
    energy_per_px2_J: float
    kernel: np.ndarray | None
    chip_area_px2: float

    @property
    def plane_shape(self) -> tuple[int, int]:
        return 2 * self.ry + 1, 2 * self.rx + 1

    def spectra(self, dtype) -> object:
        """The chips' spectra for :func:`overlap_planes`: conj(rfft2(chip)) (times the
        ``K_h`` spectrum when the meniscus is on the pattern side), a jnp array."""
        import jax.numpy as jnp

        enable_float64(dtype)
        spec = np.conj(np.fft.rfft2(self.chips, s=self.fft))
        if self.kernel is not None:
            spec = spec * self.kernel[None]
        cdt = jnp.complex128 if np.dtype(dtype) == np.float64 else jnp.complex64
        return jnp.asarray(spec, cdt)

    def index(self) -> tuple[np.ndarray, np.ndarray]:
        """Row and column indices of the planes in the inverse transform (static)."""
        h, w = self.pattern_shape
        hc, wc = self.chips.shape[1:]
        dy, dx = (h - hc) // 2, (w - wc) // 2
        ny, nx = self.fft
        return (
            (np.arange(-self.ry, self.ry + 1) + dy) % ny,
            (np.arange(-self.rx, self.rx + 1) + dx) % nx,
        )


def chip_side(scene, pattern_shape: tuple[int, int], twists_deg) -> ChipSide:
    """The chip side of ``scene`` (its chip, meniscus and materials) for a design canvas of
    ``pattern_shape`` px at the scene's pixel size, at each of ``twists_deg``.

    Each twist's raster is the one :func:`simulator.landscape.build_landscape` correlates
    (:func:`simulator.landscape.plan` of the scene on a canvas of this shape), padded to one
    canvas for all twists.
    """
    from patterns.geometry import Mask
    from simulator.landscape import plan

    h, w = pattern_shape
    assert h % 2 == 0 and w % 2 == 0, "the design canvas has an even number of pixels a side"
    probe = scene.replace(pattern=Mask(np.ones((h, w)), scene.um_per_px))
    rasters, meniscus_px = [], 0.0
    for t in twists_deg:
        p = plan(probe, twists=np.array([float(t)]))
        rasters.append(np.asarray(p.rotator(float(t)), np.float64))
        meniscus_px = p.meniscus_px
    hc = max(r.shape[0] for r in rasters)
    wc = max(r.shape[1] for r in rasters)
    chips = np.zeros((len(rasters), hc, wc))
    for k, r in enumerate(rasters):
        # canvases of one parity (the pattern's) differ by even sizes: centred exactly
        oy, ox = (hc - r.shape[0]) // 2, (wc - r.shape[1]) // 2
        chips[k, oy : oy + r.shape[0], ox : ox + r.shape[1]] = r
    pad = 0
    if meniscus_px > 0:
        from simulator.physics import margin_px

        pad = 2 * margin_px(meniscus_px)
    fft = (sfft.next_fast_len(h + hc + pad), sfft.next_fast_len(w + wc + pad, real=True))
    kernel = None
    if meniscus_px > 0:
        from simulator.physics import kernel_spectrum

        kernel = kernel_spectrum(fft[0], fft[1], meniscus_px)
    return ChipSide(
        twists_deg=tuple(float(t) for t in twists_deg),
        chips=chips,
        pattern_shape=(h, w),
        fft=fft,
        ry=(h + hc) // 2 - 1,
        rx=(w + wc) // 2 - 1,
        um_per_px=scene.um_per_px,
        energy_per_px2_J=scene.delta_gamma_N_m * scene.um_per_px**2 * UM2,
        kernel=kernel,
        chip_area_px2=float(chips[0].sum()),
    )


def overlap_planes(w, spectra, index: tuple[np.ndarray, np.ndarray], fft: tuple[int, int]):
    """(T, 2 ry + 1, 2 rx + 1) overlaps (px^2) of the pattern ``w`` (H, W, image rows) with
    each chip of ``spectra`` (:meth:`ChipSide.spectra`) at every pose of the planes; the
    energy is ``energy_per_px2_J`` times it. A JAX function, linear in ``w``."""
    import jax.numpy as jnp

    rows, cols = index
    pw = jnp.fft.rfft2(w[::-1], s=fft)  # y up, as the chips
    full = jnp.fft.irfft2(spectra * pw[None], s=fft)
    return full[:, rows][:, :, cols]
