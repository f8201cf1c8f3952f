"""The energy landscape E[twist, y, x] by FFT cross-correlation.

Model (PHYSICS.md 3.2): ``E(x, y, a) = Delta_gamma * sum_p chip_a(p - (x, y)) * w(p)``
with ``w`` the pattern mask (1 on pads, grey levels graded, 0 on substrate), so that
``E = Delta_gamma * A_ol`` in joules. For each twist the whole translation plane is
one linear (zero-padded, never circular) cross-correlation.

Conventions:

* Landscape arrays are indexed ``[twist, y, x]`` with y *ascending* (physics frame,
  y up); ``x_um[ix] = (ix - rx) * um_per_px``, ``y_um[iy] = (iy - ry) * um_per_px``.
  The chip pose is its centre relative to the pattern's nominal centre (the image
  centre), twist counter-clockwise positive, in degrees.
* A chip given as exact geometry is rasterized anew at every twist (exact area
  coverage); a chip PNG is rotated by bilinear resampling (OpenCV ``warpAffine``),
  which keeps its area to within 1 % for chips of 5 px and more (a 120 x 60 px chip: 0.5 %,
  tested) but not for tiny ones (measured: +12.5 % for 1 px, -8 % for 2 px, -3 % for 3 px);
  give tiny chips as geometry.
* The twist axis covers one rotational-symmetry period of the chip by default
  (90 degrees for a square) and is then periodic (``wrap=True``).

Engine: the pattern spectrum is computed once; twists are processed in chunks so
that peak memory stays under the scene's budget. The transform runs in SciPy's
pocketfft on a CPU (measured faster than XLA's FFT on this 2-core machine, see
README) and in JAX when JAX sees a GPU; ``backend=`` overrides. Forward chip
transforms skip the rows that are zero, and only the translation window asked for
is transformed back along x.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft
from shapely import affinity

from patterns.errors import InputError
from patterns.mask import Mask
from patterns.raster import rasterize
from patterns.resources import fmt_bytes
from simulator.feedback import progress_bar
from simulator.scene import Scene

UM2_TO_M2 = 1e-12
BACKENDS = ("auto", "scipy", "jax")
#: Noise floor = NOISE_FACTOR * eps(dtype) * max|E|: a bound on FFT round-off
#: (measured worst case about 3 eps * max|E| in float32 on library patterns).
NOISE_FACTOR = 32.0


# --------------------------------------------------------------------- symmetry
def chip_symmetry(chip: Mask) -> tuple[float, bool]:
    """(rotational period in degrees, mirror-symmetric about the x axis) of a chip.

    From the exact geometry when known, else from the raster (exact comparison).
    """
    if chip.geometry is not None:
        g = chip.geometry
        tol = 1e-9 * max(g.area, 1e-12)

        def same(other) -> bool:
            return g.symmetric_difference(other).area <= tol

        period = next((p for p in (90.0, 180.0) if same(affinity.rotate(g, p, origin=(0, 0)))), 360.0)
        return period, same(affinity.scale(g, 1.0, -1.0, origin=(0, 0)))
    d = chip.data
    if d.shape[0] == d.shape[1] and np.array_equal(np.rot90(d), d):
        period = 90.0
    elif np.array_equal(d[::-1, ::-1], d):
        period = 180.0
    else:
        period = 360.0
    return period, bool(np.array_equal(d[::-1], d))


def axis_step(axis: np.ndarray) -> float:
    """Spacing of an evenly spaced axis, from its ends: ``axis[1] - axis[0]`` carries the
    round-off of both values (0.010000000000000009 for -0.5 + 0.01 k), which grows with the
    index and puts 50 steps of 0.01 degrees from -0.5 at 4e-16 instead of 0. 1.0 for one value."""
    n = len(axis)
    return float(axis[-1] - axis[0]) / (n - 1) if n > 1 else 1.0


#: Most twists a pose grid may have (0.0001 degree steps over a 90 degree period).
MAX_TWISTS = 2**20
#: Most samples of one energy curve.
MAX_CURVE_SAMPLES = 10**7


def _require_twist_count(scene: Scene, span_deg: float) -> None:
    """Refuse a twist axis of more than MAX_TWISTS twists before any array is made."""
    tg = scene.twist
    n = span_deg / tg.step_deg
    if not n <= MAX_TWISTS:
        raise InputError(
            f"twist step {tg.step_deg:g} deg gives {n:.3g} twists over {span_deg:g} deg, more than {MAX_TWISTS:,} "
            f"(the landscape would need {fmt_bytes(n * 4)} for every translation); use a larger --twist-step or a narrower twist range"
        )


def twist_axis(scene: Scene) -> tuple[np.ndarray, bool, float]:
    """(twists in degrees, periodic?, chip symmetry period) for the scene's grid."""
    period, _ = chip_symmetry(scene.chip)
    if not scene.effects.twist:
        return np.zeros(1), False, period
    tg = scene.twist
    _require_twist_count(scene, period if tg.min_deg is None else tg.max_deg - tg.min_deg)
    step = tg.step_deg
    n_period = period / step
    divides = abs(n_period - round(n_period)) < 1e-9
    if tg.min_deg is None or (divides and tg.max_deg - tg.min_deg + step >= period - 1e-9):
        if divides:
            n = round(n_period)  # one period, centred on and always containing 0
            return step * (np.arange(n) - n // 2), True, period
        n = int(math.floor(period / step / 2 + 1e-9))
        return step * np.arange(-n, n + 1), False, period
    n = int(math.floor((tg.max_deg - tg.min_deg) / step + 1e-9)) + 1
    return tg.min_deg + step * np.arange(n), False, period


# --------------------------------------------------------------------- rotation
def _nonzero_box(data: np.ndarray) -> tuple[int, int, int, int]:
    rows = np.flatnonzero(data.any(axis=1))
    cols = np.flatnonzero(data.any(axis=0))
    return rows[0], rows[-1] + 1, cols[0], cols[-1] + 1


def _chip_reach_px(chip: Mask, twist: bool) -> tuple[float, float]:
    """Half-extent (x, y) in px of the chip's wettable area about its centre, over all twists."""
    h, w = chip.shape
    r0, r1, c0, c1 = _nonzero_box(chip.data > 0)
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
    r0, r1, c0, c1 = _nonzero_box(chip.data > 0)
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
        self.count = 0  # rotations computed (the engine's "exactly one" check reads this)

    def __call__(self, twist_deg: float) -> np.ndarray:
        self.count += 1
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


# --------------------------------------------------------------------- correlation
def _default_backend() -> str:
    try:
        import jax

        return "jax" if jax.default_backend() != "cpu" else "scipy"
    except Exception:  # pragma: no cover - jax is a dependency
        return "scipy"


@dataclass(frozen=True)
class Window:
    """Output translations X in [-rx, rx], Y in [-ry, ry] px, with pattern/chip offsets."""

    rx: int
    ry: int
    dx: int  # pattern column of chip column 0 at X = 0
    dy: int


def fft_shape(pattern_shape: tuple[int, int], chip_shape: tuple[int, int], window: Window) -> tuple[int, int]:
    """(ny, nx) of the transforms for a correlation window: sizes only, nothing allocated."""
    (hp, wp), (hc, wc) = pattern_shape, chip_shape
    # Alias-free: the partners m +- N of every wanted shift m lie outside the linear
    # support [-(hc - 1), hp - 1], and the window does not wrap onto itself.
    need_y = max(hp, hc, 2 * window.ry + 1, hp - (window.dy - window.ry), window.dy + window.ry + hc)
    need_x = max(wp, wc, 2 * window.rx + 1, wp - (window.dx - window.rx), window.dx + window.rx + wc)
    return sfft.next_fast_len(need_y, real=False), sfft.next_fast_len(need_x, real=True)


def kernel_bytes(fft: tuple[int, int], dtype, chunks: int) -> int:
    """Bytes of the stored pattern spectrum and its mirror-image copy."""
    ny, nx = fft
    return ny * (nx // 2 + 1) * 2 * np.dtype(dtype).itemsize * 2


def work_bytes(fft: tuple[int, int], out_rows: int, dtype, chunk: int, chunks: int) -> int:
    """Working memory of a correlation in ``chunks`` chunks of ``chunk`` twists (bytes):
    the kernels, and per twist two complex spectra and the real window rows."""
    ny, nx = fft
    item = np.dtype(dtype).itemsize
    per_twist = ny * (nx // 2 + 1) * 2 * item * 2 + out_rows * nx * item
    return kernel_bytes(fft, dtype, chunks) + chunk * per_twist


class Correlator:
    """Linear cross-correlation of one fixed pattern with a stack of chips, windowed.

    ``corr[b, Y + ry, X + rx] = sum_{k,l} chip[b, k, l] * pattern[k + Y + dy, l + X + dx]``
    for the arrays as given (both in the same row orientation).

    How the passes are kept few (the transforms are memory-bound): the chip is
    flipped before its forward transform, so its spectrum already is the conjugate
    the correlation needs; the phase ramps of that flip, and the roll that puts the
    window at index 0 (so the window is a plain slice, not a gather), are folded
    once into the stored pattern spectrum ``kernel``. Zero rows around each chunk of
    chips are not transformed. One multiply per twist remains.
    """

    def __init__(self, pattern: np.ndarray, chip_shape: tuple[int, int], window: Window, dtype: str, backend: str = "auto"):
        if backend not in BACKENDS:
            raise InputError(f"backend must be one of {BACKENDS}, got {backend!r}")
        self.backend = _default_backend() if backend == "auto" else backend
        self.dtype = np.dtype(dtype)
        self.window = window
        hc, wc = chip_shape
        self.ny, self.nx = fft_shape(pattern.shape, chip_shape, window)
        self.chip_shape = (hc, wc)
        self.out_shape = (2 * window.ry + 1, 2 * window.rx + 1)
        self.workers = os.cpu_count() or 1
        # corr[m] = sum_k c[k] p[k + m]. With the flipped chip f[k] = c[hc - 1 - k],
        # F(f) = e^{-i w (hc - 1)} conj(C); the window starts at m0 = dy - ry.
        # kernel = P * e^{+i w (hc - 1)} * e^{+i w m0} so that corr[m0 + j] = IFFT(kernel F(f))[j].
        ky = np.exp(2j * np.pi * np.fft.fftfreq(self.ny) * (hc - 1 + window.dy - window.ry))
        kx = np.exp(2j * np.pi * np.fft.rfftfreq(self.nx) * (wc - 1 + window.dx - window.rx))
        spec = sfft.fft(sfft.rfft(np.asarray(pattern, self.dtype), n=self.nx, axis=1, workers=self.workers), n=self.ny, axis=0, workers=self.workers)
        cdt = spec.dtype
        self.kernel = (spec * ky[:, None] * kx[None, :]).astype(cdt)
        self._fy = np.fft.fftfreq(self.ny)
        if self.backend == "jax":
            self._jax_fn = self._make_jax()

    def bytes_per_twist(self) -> int:
        return work_bytes((self.ny, self.nx), self.out_shape[0], self.dtype, 1, 1) - kernel_bytes((self.ny, self.nx), self.dtype, 1)

    def __call__(self, chips: np.ndarray, out: np.ndarray | None = None, scale: float = 1.0, mirror_out: np.ndarray | None = None) -> np.ndarray:
        """(B, hc, wc) chips -> ``scale`` * correlation window (B, 2 ry + 1, 2 rx + 1), into ``out``.

        mirror_out: if given, (B, 2 ry + 1, 2 rx + 1) that receives the same for each
        chip's mirror image ``chips[:, ::-1]`` (its raster upside down), whose spectrum
        is the chip's with the row frequencies negated and a phase ramp: one forward
        transform serves both (PHYSICS.md: a mirror-symmetric chip at -alpha is the
        mirror image of itself at +alpha).
        """
        chips = np.asarray(chips, dtype=self.dtype)
        if out is None:
            out = np.empty((len(chips),) + self.out_shape, self.dtype)
        if self.backend == "jax":
            out[...] = np.asarray(self._jax_fn(chips)) * scale
            if mirror_out is not None:
                mirror_out[...] = np.asarray(self._jax_fn(chips[:, ::-1])) * scale
            return out
        flipped = chips[:, ::-1, ::-1]
        nz = flipped.any(axis=0)
        if not nz.any():
            out[...] = 0
            if mirror_out is not None:
                mirror_out[...] = 0
            return out
        # Zero rows around the chips are not transformed (the row pass is cut to the
        # rows that hold chip pixels, placed where they are, so no phase shift is due);
        # trailing zero columns are the transform's own padding.
        r0, r1, _, c1 = _nonzero_box(nz)
        spec = self._buffer("_buf", len(chips))
        spec[:, :r0] = 0
        spec[:, r1:] = 0
        spec[:, r0:r1] = sfft.rfft(flipped[:, r0:r1, :c1], n=self.nx, axis=2, workers=self.workers)
        spec = sfft.fft(spec, axis=1, workers=self.workers, overwrite_x=True)
        if mirror_out is not None:
            # The mirror image's flipped rows are f[hc - 1 - k]:
            # F'(ky) = exp(-2 pi i ky (hc - 1) / ny) F(-ky), the ramp folded into a kernel.
            mk = self._mirror_kernel()
            mspec = self._buffer("_mbuf", len(chips))
            np.multiply(spec[:, :1], mk[:1], out=mspec[:, :1])
            np.multiply(spec[:, :0:-1], mk[1:], out=mspec[:, 1:])  # rows ky -> -ky mod ny
            self._inverse(mspec, mirror_out, scale)
        spec *= self.kernel
        self._inverse(spec, out, scale)
        return out

    def _inverse(self, spec: np.ndarray, out: np.ndarray, scale: float) -> None:
        """out = scale * window of the inverse transform of spec (overwritten)."""
        spec = sfft.ifft(spec, axis=1, workers=self.workers, overwrite_x=True)
        rows, cols = self.out_shape
        # The last pass one twist at a time, straight into ``out``: measured 1.3-2x faster
        # than one batched call and a batch-sized temporary.
        for k in range(len(spec)):
            res = sfft.irfft(spec[k, :rows], n=self.nx, axis=1, workers=self.workers)
            np.multiply(res[:, :cols], scale, out=out[k], casting="unsafe")

    def _buffer(self, name: str, b: int) -> np.ndarray:
        """A reused complex work array (B, ny, nx/2 + 1): no fresh pages per chunk."""
        buf = getattr(self, name, None)
        if buf is None or buf.shape[0] < b:
            cdt = np.result_type(self.dtype, np.complex64)
            buf = np.empty((b, self.ny, self.nx // 2 + 1), cdt)
            setattr(self, name, buf)
        return buf[:b]

    def _mirror_kernel(self) -> np.ndarray:
        """kernel * exp(-2 pi i ky (hc - 1) / ny): the mirror images' kernel, made once."""
        if getattr(self, "_mkernel", None) is None:
            ramp = np.exp(-2j * np.pi * self._fy * (self.chip_shape[0] - 1)).astype(self.kernel.dtype)
            self._mkernel = self.kernel * ramp[:, None]
        return self._mkernel

    def _make_jax(self):
        import jax
        import jax.numpy as jnp

        kern = jnp.asarray(self.kernel)
        nx, ny = self.nx, self.ny
        nr, nc = self.out_shape

        @jax.jit
        def run(chips):
            spec = jnp.fft.fft(jnp.fft.rfft(chips[:, ::-1, ::-1], n=nx, axis=2), n=ny, axis=1)
            a = jnp.fft.ifft(kern * spec, axis=1)[:, :nr]
            return jnp.fft.irfft(a, n=nx, axis=2)[:, :, :nc]

        return run


#: Rasters equal to within this (per pixel) count as the same chip: rasters of a
#: symmetric chip one period apart, or mirror twins, differ by float round-off only.
SAME_CHIP_TOL = 1e-9


def chip_relations(chips: np.ndarray, tol: float = SAME_CHIP_TOL) -> list[tuple[int, bool]]:
    """For each chip i, ``(j, mirrored)``: chip i equals chip j <= i (``mirrored`` False;
    j == i for a chip seen first) or chip j upside down (``chips[j, ::-1]``, True).

    Candidates are found by hashing cheap row and column profiles (a row profile
    reverses under the mirror, a column profile over a mirror-symmetric set of rows does
    not change), then confirmed pixel by pixel within ``tol``; a near miss is just a new
    chip.
    """
    chips = np.asarray(chips)
    if not np.issubdtype(chips.dtype, np.floating):
        chips = chips.astype(np.float64)
    t, h, w = chips.shape
    if t == 0:
        return []
    cols = np.unique(np.linspace(0, w - 1, min(w, 16)).round().astype(int))
    rows = np.unique(np.r_[np.arange(0, h, 8), h - 1 - np.arange(0, h, 8)])
    row_prof = np.round(chips[:, :, cols].sum(axis=2, dtype=np.float64), 6)
    col_prof = np.round(chips[:, rows, :].sum(axis=1, dtype=np.float64), 6)
    tmp = np.empty((h, w), chips.dtype)

    def close(a: np.ndarray, b: np.ndarray) -> bool:
        np.subtract(a, b, out=tmp)
        return max(-float(tmp.min()), float(tmp.max())) <= tol

    seen: dict[tuple[bytes, bytes], int] = {}
    out: list[tuple[int, bool]] = []
    for i in range(t):
        cp = col_prof[i].tobytes()
        rel = (i, False)
        j = seen.get((row_prof[i].tobytes(), cp))
        if j is not None and close(chips[i], chips[j]):
            rel = (j, False)
        else:
            j = seen.get((row_prof[i, ::-1].tobytes(), cp))
            if j is not None and close(chips[i], chips[j, ::-1]):
                rel = (j, True)
        if rel[0] == i:
            seen.setdefault((row_prof[i].tobytes(), cp), i)
        out.append(rel)
    return out


def _run(idx: list[int], step: int) -> bool:
    """True if idx is a run of consecutive indices with this step (+1 or -1)."""
    return idx == list(range(idx[0], idx[0] + step * len(idx), step))


def correlate_stack(pattern: np.ndarray, chips: np.ndarray, dtype: str = "float32", backend: str = "auto", chunk: int = 8) -> np.ndarray:
    """Full linear cross-correlation of ``pattern`` (H, W) with each of ``chips`` (T, h, w).

    ``out[t, m + h - 1, n + w - 1] = sum_{k,l} chips[t, k, l] * pattern[k + m, l + n]``,
    i.e. what ``cv2.matchTemplate(TM_CCORR)`` gives on a pattern zero-padded by the chip
    size, for every shift.

    Symmetries save transforms (:func:`chip_relations`, equal within
    :data:`SAME_CHIP_TOL`): a chip that repeats (a symmetric chip one period apart) is
    not transformed again; a chip that is another upside down (a mirror-symmetric chip
    at -alpha and +alpha) gets its spectrum from its twin's; and when the pattern too is
    mirror-symmetric (rows), the twin's correlation is the other's upside down (no
    transform at all).
    """
    pattern, chips = np.asarray(pattern), np.asarray(chips)
    (hp, wp), (t, hc, wc) = pattern.shape, chips.shape
    # Window m in [-(hc - 1), hp - 1]: centre dy = (hp - hc)/2, half-width ry = (hp + hc)/2 - 1;
    # a zero row/column appended to the pattern makes both whole.
    py, px = (hp - hc) % 2, (wp - wc) % 2
    hq, wq = hp + py, wp + px
    win = Window(rx=(wq + wc) // 2 - 1, ry=(hq + hc) // 2 - 1, dx=(wq - wc) // 2, dy=(hq - hc) // 2)
    cor = Correlator(np.pad(pattern, ((0, py), (0, px))), (hc, wc), win, dtype, backend)
    rel = chip_relations(chips)
    twin = {}  # first chip -> a chip that is its mirror image
    for i, (j, mirrored) in enumerate(rel):
        if mirrored:
            twin.setdefault(j, i)
    pf = np.asarray(pattern, np.float64)
    pattern_mirror = bool(np.abs(pf - pf[::-1]).max() <= SAME_CHIP_TOL)
    out = np.empty((t, 2 * win.ry + 1, 2 * win.rx + 1), cor.dtype)
    H, W = hp + hc - 1, wp + wc - 1  # the full layout (a window of out)
    firsts = [i for i in range(t) if rel[i][0] == i]
    paired = [i for i in firsts if i in twin and not pattern_mirror]
    for group, mirror in (([i for i in firsts if i not in paired], False), (paired, True)):
        for k in range(0, len(group), chunk):
            sel = group[k : k + chunk]
            stack = chips[sel[0] : sel[-1] + 1] if _run(sel, 1) else chips[sel]
            _correlate_into(cor, stack, out, sel, 1.0, mirror_idx=[twin[i] for i in sel] if mirror else None)
    done = set(firsts) | {twin[i] for i in paired}
    for i, (j, mirrored) in enumerate(rel):
        if i in done:
            continue
        if not mirrored:
            out[i] = out[j]
        elif j in twin and twin[j] in done:
            out[i] = out[twin[j]]
        else:  # pattern mirror-symmetric: corr of the mirror image = corr upside down
            out[i, :H] = out[j, :H][::-1]
    return out[:, :H, :W]


# --------------------------------------------------------------------- landscape
@dataclass(frozen=True, eq=False)
class Landscape:
    """Energy on the pose grid, with the grid and what it cost.

    Attributes:
        energy: (T, Ny, Nx) joules, ``[twist, y, x]``, y ascending.
        x_um, y_um: (Nx,), (Ny,) translations of the chip centre (um), ascending.
        twist_deg: (T,) twists (degrees), ascending, evenly spaced.
        wrap: the twist axis covers one full symmetry period and is periodic.
        period_deg: the chip's rotational symmetry period (degrees).
        um_per_px: translation step (um).
        delta_gamma: pad minus substrate wetting energy (N/m, negative).
        energy_scale_J: the largest |E| the scene can reach, |Delta_gamma| min(|P|, |C|)
            (PHYSICS.md C8); the noise floor scales with it, so every box or band of one
            scene shares one floor (0 = take max|E| of this grid).
        cut: ((t_lo, t_hi), (y_lo, y_hi), (x_lo, x_hi)): True where the grid was cut
            short on that side (a box or band of a larger grid), so the energy beyond it
            is unknown. Beyond an uncut x/y side the chip no longer touches the pattern
            and the energy is exactly 0; beyond an uncut end of a non-periodic twist
            axis lies the end of the twist range the scene asked for.
        stats: what the build did (rotations, seconds, bytes, backend, FFT size).
    """

    energy: np.ndarray
    x_um: np.ndarray
    y_um: np.ndarray
    twist_deg: np.ndarray
    wrap: bool
    period_deg: float
    um_per_px: float
    delta_gamma: float
    cut: tuple = ((False, False), (False, False), (False, False))
    energy_scale_J: float = 0.0
    stats: dict = field(default_factory=dict)

    @property
    def full_reach(self) -> bool:
        """The translation window holds every pose where the chip touches the pattern."""
        return not any(self.cut[1] + self.cut[2])

    # -- scales
    @property
    def joules_per_px2(self) -> float:
        return self.delta_gamma * self.um_per_px**2 * UM2_TO_M2

    @property
    def twist_step_deg(self) -> float:
        return axis_step(self.twist_deg)

    @property
    def noise_floor_J(self) -> float:
        """Energy differences at or below this are round-off: steppers treat them as ties.

        ``NOISE_FACTOR * eps(dtype) * energy_scale_J``: FFT round-off is bounded by a few
        eps times the largest value (measured 3.3 eps in float32), so 32 eps leaves a
        10x margin while staying far below any real one-pixel energy change.
        """
        eps = np.finfo(self.energy.dtype).eps
        scale = self.energy_scale_J or float(np.abs(self.energy).max())
        return float(NOISE_FACTOR * eps * max(scale, np.finfo(float).tiny))

    def overlap_um2(self, energy_J: np.ndarray | float) -> np.ndarray | float:
        """Overlap area (um^2) for an energy (J): A = E / Delta_gamma."""
        return np.asarray(energy_J) / (self.delta_gamma * UM2_TO_M2)

    # -- grid coordinates
    def fractional_index(self, x_um, y_um, twist_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Continuous (it, iy, ix) grid coordinates of poses (twist wrapped if periodic)."""
        ix = (np.asarray(x_um, float) - self.x_um[0]) / self.um_per_px
        iy = (np.asarray(y_um, float) - self.y_um[0]) / self.um_per_px
        it = (np.asarray(twist_deg, float) - self.twist_deg[0]) / self.twist_step_deg
        if self.wrap:
            it = np.mod(it, len(self.twist_deg))
        return it, iy, ix

    def energy_at(self, x_um, y_um, twist_deg) -> np.ndarray:
        """Energy (J) at continuous poses by trilinear interpolation on the grid.

        Along a periodic twist axis the interpolation wraps. Outside the window the
        energy is 0 (no contact) when the window has full reach, else InputError.
        """
        it, iy, ix = self.fractional_index(x_um, y_um, twist_deg)
        return trilinear(self.energy, it, iy, ix, self.wrap, self.cut)

    def gradient_at(self, x_um, y_um, twist_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dE/dx, dE/dy) in J/m and dE/dtwist in J/rad, by central differences of one grid step.

        Energy differences below the noise floor are round-off and give exactly 0
        (a plateau is flat, not noisy).
        """
        s, dt = self.um_per_px, self.twist_step_deg
        e, floor = self.energy_at, self.noise_floor_J
        x, y, t = (np.asarray(v, float) for v in (x_um, y_um, twist_deg))

        def diff(a, b, h):
            d = a - b
            return np.where(np.abs(d) <= floor, 0.0, d) / h

        gx = diff(e(x + s, y, t), e(x - s, y, t), 2 * s * 1e-6)
        gy = diff(e(x, y + s, t), e(x, y - s, t), 2 * s * 1e-6)
        if len(self.twist_deg) > 1:
            gt = diff(e(x, y, t + dt), e(x, y, t - dt), 2 * math.radians(dt))
        else:
            gt = np.zeros_like(gx)
        return gx, gy, gt

    def force_at(self, x_um, y_um, twist_deg) -> tuple[np.ndarray, np.ndarray]:
        """Restoring force (Fx, Fy) in N: F = -grad E (PHYSICS.md 3.4)."""
        gx, gy, _ = self.gradient_at(x_um, y_um, twist_deg)
        return -gx, -gy

    def torque_at(self, x_um, y_um, twist_deg) -> np.ndarray:
        """Restoring torque about z in N m: tau = -dE/dtwist (twist in radians, CCW +)."""
        return -self.gradient_at(x_um, y_um, twist_deg)[2]

    def global_minimum(self) -> tuple[float, float, float, float]:
        """(x_um, y_um, twist_deg, energy_J) of the lowest grid pose (first in index order on ties)."""
        it, iy, ix = np.unravel_index(int(np.argmin(self.energy)), self.energy.shape)
        return float(self.x_um[ix]), float(self.y_um[iy]), float(self.twist_deg[it]), float(self.energy[it, iy, ix])

    def curve(self, axis: str, through: tuple[float, float, float], start: float, stop: float) -> dict:
        """Energy, force and plateaus along one axis through a pose.

        Args:
            axis: "x", "y" (um) or "twist" (degrees).
            through: the pose (x_um, y_um, twist_deg) the line passes through.
            start, stop: range along the axis, sampled at the grid step.

        Returns:
            dict with ``values`` (the axis samples), ``energy_J``, ``force`` (N along x/y,
            N m for twist: minus the derivative along the axis), ``plateaus`` (list of
            [start, end] ranges where the chip touches the pattern but the force is zero:
            energy differences below the noise floor, see :meth:`gradient_at`) and
            ``no_contact`` (ranges where the chip does not touch the pattern at all).
        """
        if axis not in ("x", "y", "twist"):
            raise InputError(f"curve axis must be x, y or twist, got {axis!r}")
        step = self.twist_step_deg if axis == "twist" else self.um_per_px
        if not (math.isfinite(start) and math.isfinite(stop) and stop > start):
            raise InputError(f"curve range must be finite with --to > --from, got {start} .. {stop}")
        samples = (stop - start) / step + 1
        if not samples <= MAX_CURVE_SAMPLES:
            raise InputError(
                f"the curve from {start:g} to {stop:g} at steps of {step:g} would have {samples:.3g} samples "
                f"(about {fmt_bytes(samples * 96)}), more than {MAX_CURVE_SAMPLES:,}; narrow --from/--to"
            )
        n = int(math.floor((stop - start) / step + 1e-9)) + 1
        v = start + step * np.arange(n)
        x, y, t = (np.full(n, float(c)) for c in through)
        {"x": x, "y": y, "twist": t}[axis][:] = v
        e = self.energy_at(x, y, t)
        gx, gy, gt = self.gradient_at(x, y, t)
        force = -{"x": gx, "y": gy, "twist": gt}[axis]
        detached = np.abs(e) <= self.noise_floor_J  # the chip no longer touches the pattern
        return {
            "axis": axis,
            "values": v,
            "energy_J": e,
            "force": force,
            "plateaus": runs(v, (force == 0) & ~detached),
            "no_contact": runs(v, detached),
        }


def runs(values: np.ndarray, flat: np.ndarray, min_points: int = 3) -> list[list[float]]:
    """[start, end] ranges of ``values`` where ``flat`` holds for >= ``min_points`` samples in a row."""
    out, i, n = [], 0, len(values)
    while i < n:
        if flat[i]:
            j = i
            while j + 1 < n and flat[j + 1]:
                j += 1
            if j - i + 1 >= min_points:
                out.append([float(values[i]), float(values[j])])
            i = j + 1
        else:
            i += 1
    return out


def trilinear(e: np.ndarray, it, iy, ix, wrap: bool, cut=((False, False),) * 3) -> np.ndarray:
    """Trilinear interpolation of ``e[t, y, x]`` at fractional indices (numpy, host side).

    Beyond an uncut x/y side the value is 0 (no contact); beyond a cut side, or past
    the ends of a non-periodic twist axis, InputError.
    """
    nt, ny, nx = e.shape
    it, iy, ix = np.broadcast_arrays(*(np.asarray(a, float) for a in (it, iy, ix)))
    inside = (iy >= 0) & (iy <= ny - 1) & (ix >= 0) & (ix <= nx - 1)
    unknown = (cut[1][0] & (iy < 0)) | (cut[1][1] & (iy > ny - 1)) | (cut[2][0] & (ix < 0)) | (cut[2][1] & (ix > nx - 1))
    if not wrap and nt > 1:
        unknown |= (it < -1e-9) | (it > nt - 1 + 1e-9)
    if np.any(unknown):
        raise InputError("pose outside the landscape's pose grid; widen the window (window_um) or the twist range")
    x0 = np.clip(np.floor(ix), 0, max(nx - 2, 0)).astype(int)
    y0 = np.clip(np.floor(iy), 0, max(ny - 2, 0)).astype(int)
    fx, fy = np.clip(ix - x0, 0, 1), np.clip(iy - y0, 0, 1)
    x1, y1 = np.minimum(x0 + 1, nx - 1), np.minimum(y0 + 1, ny - 1)
    if nt == 1:
        t0 = t1 = np.zeros_like(x0)
        ft = np.zeros_like(fx)
    elif wrap:
        t0 = np.floor(it).astype(int) % nt
        ft = it - np.floor(it)
        t1 = (t0 + 1) % nt
    else:
        t0 = np.clip(np.floor(it), 0, nt - 2).astype(int)
        ft = np.clip(it - t0, 0, 1)
        t1 = t0 + 1

    def plane(t):
        return (
            e[t, y0, x0] * (1 - fx) * (1 - fy)
            + e[t, y0, x1] * fx * (1 - fy)
            + e[t, y1, x0] * (1 - fx) * fy
            + e[t, y1, x1] * fx * fy
        )

    val = plane(t0) * (1 - ft) + plane(t1) * ft
    return np.where(inside, val, 0.0)


def _axis_box(full: int, limit: int | None, center: int, half: int | None) -> tuple[int, int, bool, bool]:
    """(centre, half-width, cut below, cut above) of a window on an axis of reach ``full``.

    ``limit`` caps the half-width about 0 (the scene's window); ``center``/``half`` ask
    for a box; the box is clamped to the reach and kept symmetric about its centre.
    """
    lim = full if limit is None else min(full, limit)
    center = min(max(center, -lim), lim)  # beyond the reach nothing touches: clamp
    lo, hi = (-lim, lim) if half is None else (max(center - half, -lim), min(center + half, lim))
    if (hi - lo) % 2:
        # An odd span has no centre pixel: grow it by one, on the side not at the reach.
        # (Shrinking the side at the reach cut it: a wall of +inf where the energy is 0,
        # so a start beyond the reach reported an infinite energy.)
        lo, hi = (lo - 1, hi) if hi == lim else (lo, hi + 1)
    return (lo + hi) // 2, (hi - lo) // 2, lo > -full, hi < full


def _twist_cut(axis: np.ndarray, wrap: bool, twists: np.ndarray) -> tuple[bool, bool]:
    """Which ends of ``twists`` cut a longer twist axis short."""
    if len(axis) == 1:
        return False, False
    if wrap:
        return (len(twists) < len(axis),) * 2
    eps = 1e-9 * max(1.0, abs(axis).max())
    return bool(twists[0] > axis[0] + eps), bool(twists[-1] < axis[-1] - eps)


def energy_scale_J(scene: Scene) -> float:
    """The largest |E| the scene can reach, ``|Delta_gamma| min(|P|, |C|)`` in J (PHYSICS.md C8)."""
    return abs(scene.materials.delta_gamma_N_m) * min(scene.pattern.area_um2, scene.chip.area_um2) * UM2_TO_M2


def _check_energy_range(scene: Scene) -> None:
    """Refuse a scene whose energies in joules the dtype cannot hold as normal numbers.

    Three values must be normal (not subnormal, not infinite): the energy of one fully
    overlapping pixel (the factor every correlation is multiplied by), the noise floor
    (the smallest energy difference that counts) and the largest energy, with a margin
    of 2**10 for sums and differences. Otherwise float32 silently loses the landscape:
    XLA flushes subnormals to zero, so a weak scene would look like "no contact"
    everywhere. In float32 one pixel of overlap must be worth 1.2e-38 J or more
    (|Delta_gamma| >= 1.2e-26 N/m at 1 um/px, 1.2e-20 N/m at 1e-3 um/px) and no energy more
    than 3.3e35 J (water at 30/60 degrees: 2.7e-14 J per um^2). In float64, anything physical.
    A scene with Delta_gamma = 0 (``allow_repulsive``) has no energy at all and passes.
    """
    fi = np.finfo(scene.dtype)
    dg = abs(scene.materials.delta_gamma_N_m)
    if dg == 0:
        return
    pixel = dg * scene.um_per_px**2 * UM2_TO_M2
    largest = energy_scale_J(scene)
    floor = NOISE_FACTOR * float(fi.eps) * largest
    if min(pixel, floor) < fi.tiny or largest > fi.max / 2**10:
        m = scene.materials
        raise InputError(
            f"the energies of this scene are outside what {scene.dtype} holds: one pixel of overlap is "
            f"{pixel:.3g} J, the noise floor {floor:.3g} J and the largest energy {largest:.3g} J, but they "
            f"must lie between {float(fi.tiny):.3g} and {float(fi.max) / 2**10:.3g} J (surface tension "
            f"{m.surface_tension_N_m:g} N/m, contact angles {m.pad_angle_deg:g}/{m.substrate_angle_deg:g} deg, "
            f"{scene.um_per_px:g} um/px); use dtype float64, or check the surface tension and the scale"
        )


def estimate_bytes(scene: Scene, twists: np.ndarray | None = None) -> int:
    """Bytes the landscape array of ``scene`` would take (before building it; nothing is rotated)."""
    return _box(scene, twists)["landscape_bytes"]


def _refuse_over_budget(scene: Scene, need: float, n_twists: int, ny: int, nx: int) -> None:
    """InputError unless ``need`` bytes fit ``scene.memory_budget_mb``."""
    if need > scene.memory_budget_mb * 2**20:
        raise InputError(
            f"the landscape needs about {need / 2**20:,.0f} MB ({n_twists} twists x "
            f"{ny} x {nx} poses, {scene.dtype}) but the memory budget is "
            f"{scene.memory_budget_mb:,.0f} MB; use a coarser scale (--um-per-px), a larger twist step "
            "or narrower twist range, a smaller translation window (window_um), or raise memory_budget_mb"
        )


def _box(scene: Scene, twists: np.ndarray | None, center_px: tuple[int, int] = (0, 0), half_px: int | None = None) -> dict:
    """Twists and translation box of a build, and its landscape bytes: sizes only, no rotation."""
    all_twists, wrap, period = twist_axis(scene)
    twists = all_twists if twists is None else np.asarray(twists, float)
    pat = scene.pattern.data
    r0, r1, c0, c1 = _nonzero_box(pat > 0)
    h, w = pat.shape
    # Cropped pattern, y-up; origin (physical 0, 0) in pixel-corner coordinates.
    origin = (w / 2 - c0, r1 - h / 2)
    reach = (max(w / 2 - c0, c1 - w / 2), max(h / 2 - r0, r1 - h / 2))
    chip_rx, chip_ry = _chip_reach_px(scene.chip, scene.effects.twist)
    limit = None if scene.window_um is None else math.ceil(scene.window_um / scene.um_per_px - 1e-9)
    cx, rx, x_lo, x_hi = _axis_box(math.ceil(reach[0] + chip_rx - 1e-9), limit, int(center_px[0]), half_px)
    cy, ry, y_lo, y_hi = _axis_box(math.ceil(reach[1] + chip_ry - 1e-9), limit, int(center_px[1]), half_px)
    nbytes = len(twists) * (2 * ry + 1) * (2 * rx + 1) * np.dtype(scene.dtype).itemsize
    return {
        "twists": twists, "all_twists": all_twists, "wrap": wrap, "period": period, "origin": origin,
        "crop": (r0, r1, c0, c1), "x": (cx, rx, x_lo, x_hi), "y": (cy, ry, y_lo, y_hi), "landscape_bytes": int(nbytes),
    }


def require_landscape_fits(scene: Scene, twists: np.ndarray | None = None) -> None:
    """Refuse (InputError) a landscape over the memory budget or with too many twists, cheaply
    (no rotation, no allocation): for commands to call before announcing a long run."""
    b = _box(scene, twists)
    _, rx, _, _ = b["x"]
    _, ry, _, _ = b["y"]
    _refuse_over_budget(scene, b["landscape_bytes"], len(b["twists"]), 2 * ry + 1, 2 * rx + 1)


def plan(scene: Scene, twists: np.ndarray | None = None, center_px: tuple[int, int] = (0, 0), half_px: int | None = None) -> dict:
    """Everything the build will do, computed without allocating the landscape.

    Refuses (InputError) a landscape over the scene's memory budget before any chip
    rotation is computed.
    """
    b = _box(scene, twists, center_px, half_px)
    twists, all_twists, wrap, period, origin = b["twists"], b["all_twists"], b["wrap"], b["period"], b["origin"]
    (r0, r1, c0, c1), (cx, rx, x_lo, x_hi), (cy, ry, y_lo, y_hi) = b["crop"], b["x"], b["y"]
    _refuse_over_budget(scene, b["landscape_bytes"], len(twists), 2 * ry + 1, 2 * rx + 1)
    pat = scene.pattern.data
    parity = (int((2 * origin[1]) % 2), int((2 * origin[0]) % 2))
    rot = ChipRotator(scene.chip, twists, parity)
    hc, wc = rot.shape
    dx, dy = origin[0] - wc / 2 + cx, origin[1] - hc / 2 + cy
    assert dx == int(dx) and dy == int(dy), "pixel grids of chip and pattern must coincide"
    win = Window(rx=rx, ry=ry, dx=int(dx), dy=int(dy))
    # Keep only the pattern rows/columns some chip pose in the window can reach.
    pat_up = pat[r0:r1, c0:c1][::-1]
    ya, yb = max(0, win.dy - win.ry), min(pat_up.shape[0], win.dy + win.ry + hc)
    xa, xb = max(0, win.dx - win.rx), min(pat_up.shape[1], win.dx + win.rx + wc)
    if yb <= ya or xb <= xa:  # no pose of the box touches the pattern
        ya, yb, xa, xb = 0, 1, 0, 1
    pat_up = pat_up[ya:yb, xa:xb]
    win = Window(rx=win.rx, ry=win.ry, dx=win.dx - xa, dy=win.dy - ya)
    nbytes = b["landscape_bytes"]
    return {
        "twists": twists,
        "wrap": wrap and len(twists) == len(all_twists),
        "period": period,
        "pattern_up": pat_up,
        "rotator": rot,
        "window": win,
        "center_px": (cx, cy),
        "cut": (_twist_cut(all_twists, wrap, twists), (y_lo, y_hi), (x_lo, x_hi)),
        "landscape_bytes": int(nbytes),
    }


def build_landscape(
    scene: Scene,
    twists: np.ndarray | None = None,
    center_px: tuple[int, int] = (0, 0),
    half_px: int | None = None,
    backend: str = "auto",
    chunk: int = 8,
    progress: bool = False,
) -> Landscape:
    """Compute E[twist, y, x] (J) for the scene, or for a subset of its twists.

    Args:
        scene: what to simulate.
        twists: twist values (degrees) to compute; default the scene's whole twist axis.
            A twist-free scene computes exactly one rotation.
        center_px, half_px: compute only the box of translations within ``half_px`` px of
            ``center_px`` (x, y px from the pattern centre), clamped to the reach; default
            the scene's whole window.
        backend: "auto" (SciPy on CPU, JAX on GPU), "scipy" or "jax".
        chunk: twists transformed together (memory per chunk is reported in stats).
        progress: show a progress bar over twist chunks.

    Raises:
        InputError: the landscape would exceed ``scene.memory_budget_mb``.
    """
    t_start = time.perf_counter()
    p = plan(scene, twists, center_px, half_px)
    win, rot = p["window"], p["rotator"]
    _check_energy_range(scene)
    # Sizes first, allocation after: an over-budget request fails before any transform.
    chunk = max(1, min(chunk, len(p["twists"])))
    fft = fft_shape(p["pattern_up"].shape, rot.shape, win)
    # A chunk of mirror twins works on twice the twists (the twins' spectra and windows).
    per_chunk = chunk * (2 if mirror_twins(scene.chip, p["twists"]) else 1)
    need = p["landscape_bytes"] + work_bytes(fft, 2 * win.ry + 1, scene.dtype, per_chunk, -(-len(p["twists"]) // chunk))
    _refuse_over_budget(scene, need, len(p["twists"]), 2 * win.ry + 1, 2 * win.rx + 1)
    cor = Correlator(p["pattern_up"], rot.shape, win, scene.dtype, backend)
    twists_deg = p["twists"]
    scale = scene.materials.delta_gamma_N_m * scene.um_per_px**2 * UM2_TO_M2
    energy = np.empty((len(twists_deg), 2 * win.ry + 1, 2 * win.rx + 1), dtype=scene.dtype)
    twins = mirror_twins(scene.chip, twists_deg)
    singles = [i for i in range(len(twists_deg)) if i not in twins and i not in twins.values()]
    pairs = sorted(twins.items())
    exact = scene.chip.geometry is not None
    # Pattern mirror-symmetric too (about y = 0) and the window centred on y = 0:
    # E(x, y, -alpha) = E(x, -y, +alpha), the twin's plane upside down, no transform.
    pat = scene.pattern.data
    copy = exact and p["center_px"][1] == 0 and bool(np.abs(pat - pat[::-1]).max() <= SAME_CHIP_TOL)
    n_mirror = n_copied = 0
    with progress_bar(progress, len(twists_deg), "landscape", "twist") as bar:
        for i in range(0, len(singles), chunk):
            sel = singles[i : i + chunk]
            _correlate_into(cor, np.stack([rot(twists_deg[k]) for k in sel]), energy, sel, scale)
            bar.update(len(sel))
        for i in range(0, len(pairs), chunk):
            sel = pairs[i : i + chunk]
            pos, neg = [a for a, _ in sel], [b for _, b in sel]
            stack = np.stack([rot(twists_deg[a]) for a in pos])
            if copy:
                _correlate_into(cor, stack, energy, pos, scale)
                for a, b in sel:
                    energy[b] = energy[a, ::-1]
                n_copied += len(sel)
            else:
                _correlate_into(cor, stack, energy, pos, scale, mirror_idx=neg)
                n_mirror += len(sel)
            if not exact:
                # The raster at -alpha is the one at +alpha upside down for exact,
                # mirror-symmetric geometry; a resampled PNG chip is checked pixel by pixel.
                for b, img in zip(neg, stack, strict=True):
                    direct = rot(twists_deg[b])
                    if np.abs(direct - img[::-1]).max() > SAME_CHIP_TOL:
                        cor(direct[None], out=energy[b : b + 1], scale=scale)
                        n_mirror -= 1
            bar.update(2 * len(sel))
    s = scene.um_per_px
    cx, cy = p["center_px"]
    return Landscape(
        energy=energy,
        x_um=(np.arange(2 * win.rx + 1) - win.rx + cx) * s,
        y_um=(np.arange(2 * win.ry + 1) - win.ry + cy) * s,
        twist_deg=twists_deg,
        wrap=p["wrap"],
        period_deg=p["period"],
        um_per_px=s,
        delta_gamma=scene.materials.delta_gamma_N_m,
        cut=p["cut"],
        energy_scale_J=energy_scale_J(scene),
        stats={
            "rotations": rot.count,
            "mirrored_twists": n_mirror,  # spectrum from the twin's transform
            "copied_twists": n_copied,  # the twin's plane upside down
            "seconds": time.perf_counter() - t_start,
            "bytes": energy.nbytes,
            "backend": cor.backend,
            "fft_shape": (cor.ny, cor.nx),
            "chip_canvas": rot.shape,
        },
    )


def _correlate_into(cor: Correlator, stack: np.ndarray, energy: np.ndarray, idx: list[int], scale: float, mirror_idx: list[int] | None = None) -> None:
    """``cor(stack)`` into ``energy[idx]`` (and the chips' mirror images into
    ``energy[mirror_idx]``), straight into views of ``energy`` where the indices run
    consecutively (mirror indices descending), through a copy otherwise."""
    out = energy[idx[0] : idx[-1] + 1] if _run(idx, 1) else None
    mirror = None
    if mirror_idx is not None:
        mirror = energy[mirror_idx[-1] : mirror_idx[0] + 1][::-1] if _run(mirror_idx, -1) else np.empty((len(idx),) + energy.shape[1:], energy.dtype)
    res = cor(stack, out=out, scale=scale, mirror_out=mirror)
    if out is None:
        energy[idx] = res
    if mirror_idx is not None and not _run(mirror_idx, -1):
        energy[mirror_idx] = mirror


def mirror_twins(chip: Mask, twists_deg: np.ndarray) -> dict[int, int]:
    """{i: j} for twists t_j = -t_i < 0 when the chip is mirror-symmetric about the x
    axis: its raster at -alpha is the one at +alpha upside down, so one forward
    transform serves both (:meth:`Correlator.__call__` ``mirror_out``)."""
    if len(twists_deg) < 2 or not chip_symmetry(chip)[1]:
        return {}
    pos = {round(float(t), 9): i for i, t in enumerate(twists_deg)}
    return {i: pos[round(-float(t), 9)] for i, t in enumerate(twists_deg) if t > 0 and round(-float(t), 9) in pos}


def twists_around(scene: Scene, twist_values, margin_steps: int = 1) -> np.ndarray:
    """The contiguous part of the scene's twist axis that queries at ``twist_values`` need.

    Interpolation needs the two grid twists around a value, and a torque (central
    difference) one step more on each side. Returns the whole axis when the needed
    part wraps around a periodic axis.
    """
    axis, wrap, period = twist_axis(scene)
    if len(axis) == 1:
        return axis
    step = axis_step(axis)
    vals = np.atleast_1d(np.asarray(twist_values, float))
    if wrap:
        vals = (vals - axis[0]) % period + axis[0]
    k = (vals - axis[0]) / step
    lo = int(math.floor(k.min() + 1e-9)) - margin_steps
    hi = int(math.ceil(k.max() - 1e-9)) + margin_steps
    if lo < 0 or hi > len(axis) - 1:
        if wrap:
            return axis
        lo, hi = max(lo, 0), min(hi, len(axis) - 1)
        if not (axis[0] - 1e-9 <= vals.min() and vals.max() <= axis[-1] + 1e-9):
            raise InputError(
                f"twist {vals.min():g}..{vals.max():g} deg is outside the scene's twist range "
                f"{axis[0]:g}..{axis[-1]:g} deg; widen the twist range"
            )
    return axis[lo : hi + 1]
