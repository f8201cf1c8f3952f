"""Linear (zero-padded, never circular) FFT cross-correlation of one pattern with
stacks of chips, windowed to the translations asked for; symmetries between chips
save transforms (:func:`chip_relations`, :func:`correlate_stack`).

The transform runs in SciPy's pocketfft on a CPU (measured faster than XLA's FFT on
a 2-core machine, see docs/benchmarks.md) and in JAX when JAX sees a GPU; ``backend=`` overrides.
Forward chip transforms skip the rows that are zero, and only the translation window
asked for is transformed back along x.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.fft as sfft

from patterns.errors import InputError
from patterns.mask import nonzero_box
from simulator.core import threads

BACKENDS = ("auto", "scipy", "jax")
#: Noise floor = NOISE_FACTOR * eps(dtype) * max|E|: a bound on FFT round-off
#: (measured worst case about 3 eps * max|E| in float32 on library patterns).
NOISE_FACTOR = 32.0


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


def fft_shape(
    pattern_shape: tuple[int, int], chip_shape: tuple[int, int], window: Window
) -> tuple[int, int]:
    """(ny, nx) of the transforms for a correlation window: sizes only, nothing allocated."""
    (hp, wp), (hc, wc) = pattern_shape, chip_shape
    # Alias-free: the partners m +- N of every wanted shift m lie outside the linear
    # support [-(hc - 1), hp - 1], and the window does not wrap onto itself.
    need_y = max(
        hp, hc, 2 * window.ry + 1, hp - (window.dy - window.ry), window.dy + window.ry + hc
    )
    need_x = max(
        wp, wc, 2 * window.rx + 1, wp - (window.dx - window.rx), window.dx + window.rx + wc
    )
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


class Workspace(NamedTuple):
    """Complex work arrays of a correlation, (chunk, ny, nx / 2 + 1), owned by the caller."""

    spec: np.ndarray
    mspec: np.ndarray | None  # for the chips' mirror images
    mkernel: np.ndarray | None  # the mirror images' kernel


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

    def __init__(
        self,
        pattern: np.ndarray,
        chip_shape: tuple[int, int],
        window: Window,
        dtype: str,
        backend: str = "auto",
        meniscus_px: float = 0.0,
    ):
        if backend not in BACKENDS:
            raise InputError(f"backend must be one of {BACKENDS}, got {backend!r}")
        self.backend = _default_backend() if backend == "auto" else backend
        self.dtype = np.dtype(dtype)
        self.window = window
        hc, wc = chip_shape
        self.ny, self.nx = fft_shape(pattern.shape, chip_shape, window)
        self.chip_shape = (hc, wc)
        self.out_shape = (2 * window.ry + 1, 2 * window.rx + 1)
        self.workers = threads()
        # corr[m] = sum_k c[k] p[k + m]. With the flipped chip f[k] = c[hc - 1 - k],
        # F(f) = e^{-i w (hc - 1)} conj(C); the window starts at m0 = dy - ry.
        # kernel = P * e^{+i w (hc - 1)} * e^{+i w m0} so that corr[m0 + j] = IFFT(kernel F(f))[j].
        ky = np.exp(2j * np.pi * np.fft.fftfreq(self.ny) * (hc - 1 + window.dy - window.ry))
        kx = np.exp(2j * np.pi * np.fft.rfftfreq(self.nx) * (wc - 1 + window.dx - window.rx))
        spec = sfft.fft(
            sfft.rfft(np.asarray(pattern, self.dtype), n=self.nx, axis=1, workers=self.workers),
            n=self.ny,
            axis=0,
            workers=self.workers,
        )
        cdt = spec.dtype
        if meniscus_px > 0:  # the finite meniscus: the pattern blurred by K_h (simulator.physics)
            from simulator.physics import kernel_spectrum

            spec *= kernel_spectrum(self.ny, self.nx, meniscus_px)
        self.kernel = (spec * ky[:, None] * kx[None, :]).astype(cdt)
        if self.backend == "jax":
            self._jax_fn = self._make_jax()

    def bytes_per_twist(self) -> int:
        return work_bytes((self.ny, self.nx), self.out_shape[0], self.dtype, 1, 1) - kernel_bytes(
            (self.ny, self.nx), self.dtype, 1
        )

    def workspace(self, chunk: int, mirror: bool = False) -> Workspace:
        """Work arrays for calls of up to ``chunk`` chips (with mirror images if ``mirror``).

        The caller owns them and passes them to every call of a build, so that no chunk
        allocates fresh pages; nothing is cached on the correlator.
        """
        cdt = np.result_type(self.dtype, np.complex64)
        shape = (int(chunk), self.ny, self.nx // 2 + 1)
        if not mirror:
            return Workspace(np.empty(shape, cdt), None, None)
        # The mirror images' kernel: kernel * exp(-2 pi i ky (hc - 1) / ny).
        ramp = np.exp(-2j * np.pi * np.fft.fftfreq(self.ny) * (self.chip_shape[0] - 1)).astype(
            self.kernel.dtype
        )
        return Workspace(np.empty(shape, cdt), np.empty(shape, cdt), self.kernel * ramp[:, None])

    def __call__(
        self,
        chips: np.ndarray,
        out: np.ndarray | None = None,
        scale: float = 1.0,
        mirror_out: np.ndarray | None = None,
        work: Workspace | None = None,
    ) -> np.ndarray:
        """(B, hc, wc) chips -> ``scale`` * correlation window (B, 2 ry + 1, 2 rx + 1), into ``out``.

        mirror_out: if given, (B, 2 ry + 1, 2 rx + 1) that receives the same for each
        chip's mirror image ``chips[:, ::-1]`` (its raster upside down), whose spectrum
        is the chip's with the row frequencies negated and a phase ramp: one forward
        transform serves both (docs/benchmarks.md, landscape: a mirror-symmetric chip at -alpha is the
        mirror image of itself at +alpha).
        work: the :meth:`workspace` to compute in (default: one made for this call).
        """
        chips = np.asarray(chips, dtype=self.dtype)
        if (
            work is None
            or work.spec.shape[0] < len(chips)
            or (mirror_out is not None and work.mspec is None)
        ):
            work = self.workspace(len(chips), mirror_out is not None)
        if out is None:
            out = np.empty((len(chips),) + self.out_shape, self.dtype)
        if self.backend == "jax":
            out[...] = np.asarray(self._jax_fn(chips)) * scale
            if mirror_out is not None:
                mirror_out[...] = np.asarray(self._jax_fn(chips[:, ::-1])) * scale
            return out
        flipped = chips[:, ::-1, ::-1]
        nz = np.asarray(flipped.any(axis=0))  # (hc, wc): which chip pixels any chip covers
        if not nz.any():
            out[...] = 0
            if mirror_out is not None:
                mirror_out[...] = 0
            return out
        # Zero rows around the chips are not transformed (the row pass is cut to the
        # rows that hold chip pixels, placed where they are, so no phase shift is due);
        # trailing zero columns are the transform's own padding.
        r0, r1, _, c1 = nonzero_box(nz)
        spec = work.spec[: len(chips)]
        spec[:, :r0] = 0
        spec[:, r1:] = 0
        spec[:, r0:r1] = sfft.rfft(flipped[:, r0:r1, :c1], n=self.nx, axis=2, workers=self.workers)
        spec = sfft.fft(spec, axis=1, workers=self.workers, overwrite_x=True)
        if mirror_out is not None:
            # The mirror image's flipped rows are f[hc - 1 - k]:
            # F'(ky) = exp(-2 pi i ky (hc - 1) / ny) F(-ky), the ramp folded into a kernel.
            mk, mspec = work.mkernel, work.mspec
            assert (
                mk is not None and mspec is not None
            )  # a mirror workspace (made above if not given)
            mspec = mspec[: len(chips)]
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

    def _make_jax(self):
        import jax
        import jax.numpy as jnp

        jax.config.update("jax_enable_x64", True)  # a float64 kernel stays float64

        kern = jnp.asarray(self.kernel)
        nx, ny = self.nx, self.ny
        nr, nc = self.out_shape
        run = _jax_correlation()
        return lambda chips: run(kern, chips, nx=nx, ny=ny, nr=nr, nc=nc)


@functools.cache
def _jax_correlation():
    """The JAX backend's correlation, compiled once per shape (the pattern's spectrum is an
    argument, not a constant: a new Correlator of the same sizes compiles nothing)."""
    import jax
    import jax.numpy as jnp

    @functools.partial(jax.jit, static_argnames=("nx", "ny", "nr", "nc"))
    def run(kern, chips, nx: int, ny: int, nr: int, nc: int):
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


def _correlate_into(
    cor: Correlator,
    stack: np.ndarray,
    energy: np.ndarray,
    idx: list[int],
    scale: float,
    mirror_idx: list[int] | None = None,
    work: Workspace | None = None,
) -> None:
    """``cor(stack)`` into ``energy[idx]`` (and the chips' mirror images into
    ``energy[mirror_idx]``), straight into views of ``energy`` where the indices run
    consecutively (mirror indices descending), through a copy otherwise."""
    out = energy[idx[0] : idx[-1] + 1] if _run(idx, 1) else None
    mirror = None
    if mirror_idx is not None:
        mirror = (
            energy[mirror_idx[-1] : mirror_idx[0] + 1][::-1]
            if _run(mirror_idx, -1)
            else np.empty((len(idx),) + energy.shape[1:], energy.dtype)
        )
    res = cor(stack, out=out, scale=scale, mirror_out=mirror, work=work)
    if out is None:
        energy[idx] = res
    if mirror_idx is not None and not _run(mirror_idx, -1):
        energy[mirror_idx] = mirror


def correlate_planes(
    cor: Correlator,
    rasters,
    count: int,
    out: np.ndarray,
    scale: float,
    work: Workspace | None,
    chunk: int,
    twins: dict[int, int] | None = None,
    repeats: dict[int, int] | None = None,
    flip_rows: int | None = None,
    verify=None,
    progress=None,
) -> tuple[int, int]:
    """Planes ``out[0:count]`` of a stack of chips, saving every transform their symmetry
    allows: the one symmetry-saving path of :func:`simulator.landscape.build_landscape` and
    :func:`correlate_stack`.

    Args:
        rasters: ``rasters(sel)`` -> the (len(sel), h, w) chips of planes ``sel``.
        twins: {i: j}: the chip of plane j is that of plane i upside down. Plane j comes
            from plane i's spectrum (``mirror_out``), or, with ``flip_rows``, is plane i
            upside down over its first ``flip_rows`` rows (the pattern is mirror-symmetric
            too and the window centred on y = 0): no transform at all.
        repeats: {j: i}: plane j equals plane i (a chip seen before), copied.
        verify: for chips whose twin relation is not exact by construction,
            ``verify(j, chip_i)`` -> the chip of plane j when it is *not* chip i upside
            down (that plane is then transformed directly), else None.
        progress: called with the number of planes done.

    Returns (planes from a twin's spectrum, planes copied upside down).
    """
    twins, repeats = twins or {}, repeats or {}
    paired = set(twins) | set(twins.values())
    singles = [i for i in range(count) if i not in paired and i not in repeats]
    pairs = sorted(twins.items())
    n_mirror = n_copied = 0
    for k in range(0, len(singles), chunk):
        sel = singles[k : k + chunk]
        _correlate_into(cor, rasters(sel), out, sel, scale, work=work)
        if progress:
            progress(len(sel))
    for k in range(0, len(pairs), chunk):
        sel = pairs[k : k + chunk]
        pos, neg = [a for a, _ in sel], [b for _, b in sel]
        stack = rasters(pos)
        if flip_rows is not None:
            _correlate_into(cor, stack, out, pos, scale, work=work)
            for a, b in sel:
                out[b, :flip_rows] = out[a, :flip_rows][::-1]
            n_copied += len(sel)
        else:
            _correlate_into(cor, stack, out, pos, scale, mirror_idx=neg, work=work)
            n_mirror += len(sel)
        if verify is not None:
            for b, img in zip(neg, stack, strict=True):
                direct = verify(b, img)
                if direct is not None:
                    cor(direct[None], out=out[b : b + 1], scale=scale, work=work)
                    if flip_rows is None:
                        n_mirror -= 1
                    else:
                        n_copied -= 1
        if progress:
            progress(2 * len(sel))
    for j, i in repeats.items():
        out[j] = out[i]
    return n_mirror, n_copied


def correlate_stack(
    pattern: np.ndarray,
    chips: np.ndarray,
    dtype: str = "float32",
    backend: str = "auto",
    chunk: int = 8,
) -> np.ndarray:
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
    # Every other chip repeats a first one, or its twin (the first upside down).
    repeats = {
        i: (twin[j] if mirrored else j)
        for i, (j, mirrored) in enumerate(rel)
        if i != j and twin.get(j) != i
    }
    out = np.empty((t, 2 * win.ry + 1, 2 * win.rx + 1), cor.dtype)
    work = cor.workspace(min(chunk, max(t, 1)), mirror=not pattern_mirror and bool(twin))
    H, W = hp + hc - 1, wp + wc - 1  # the full layout (a window of out)

    def rasters(sel: list[int]) -> np.ndarray:
        return chips[sel[0] : sel[-1] + 1] if _run(sel, 1) else chips[sel]

    correlate_planes(
        cor,
        rasters,
        t,
        out,
        1.0,
        work,
        chunk,
        twins=twin,
        repeats=repeats,
        flip_rows=H if pattern_mirror else None,
    )
    return out[:, :H, :W]
