"""Linear (zero-padded, never circular) FFT cross-correlation of one pattern with
stacks of chips, windowed to the translations asked for; symmetries between chips
save transforms (:func:`chip_relations`, :func:`correlate_stack`).

The transform runs in SciPy's pocketfft on a CPU (measured faster than XLA's FFT on
a 2-core machine, see docs/benchmarks.md) and in JAX when JAX sees a GPU; ``backend=`` overrides.
On the CPU each twist goes through its own pipeline, one twist per thread, in a
transposed layout in which every 1-D transform runs along contiguous memory: forward
chip transforms skip the rows that are zero, and only the translation window asked
for is transformed back along x.
"""

from __future__ import annotations

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from foundation import InputError
from simulator.core import threads

BACKENDS = ("auto", "scipy", "opencv", "jax")
#: Noise floor = NOISE_FACTOR * eps(dtype) * max|E|: a bound on FFT round-off
#: (measured worst case about 3 eps * max|E| in float32 on library patterns).
NOISE_FACTOR = 32.0


#: Environment variable that forces the backend of every correlation asked for with
#: ``backend="auto"`` (the default): ``scipy``, ``opencv`` or ``jax``; unset or ``auto``,
#: the choice below. The test suite runs its numerical tests under each (Makefile).
BACKEND_ENV = "SELFALIGN_FFT_BACKEND"


def forced_backend() -> str | None:
    """The backend ``SELFALIGN_FFT_BACKEND`` forces, or None (unset, empty or ``auto``)."""
    v = os.environ.get(BACKEND_ENV, "").strip().lower()
    if v in ("", "auto"):
        return None
    if v not in BACKENDS:
        raise InputError(
            f"{BACKEND_ENV}={v!r} is not an FFT backend; set it to one of scipy, opencv, jax, or unset it"
        )
    return v


def _default_backend(dtype) -> str:
    """The backend ``SELFALIGN_FFT_BACKEND`` forces; else JAX where it sees a GPU; else
    OpenCV's transforms for float32 where OpenCV runs them in Intel's IPP (measured faster
    than pocketfft: docs/benchmarks.md), else SciPy's."""
    forced = forced_backend()
    if forced is not None:
        return forced
    try:
        import jax

        if jax.default_backend() != "cpu":
            return "jax"
    except Exception:  # pragma: no cover - jax is a dependency
        pass
    return "opencv" if np.dtype(dtype) == np.float32 and _ipp() else "scipy"


@functools.cache
def _ipp() -> bool:
    """Whether OpenCV's transforms run in Intel's IPP (its x86-64 wheels)."""
    import cv2

    return bool(cv2.ipp.useIPP())


@dataclass(frozen=True)
class Window:
    """Output translations X in [-rx, rx], Y in [-ry, ry] px, with pattern/chip offsets."""

    rx: int
    ry: int
    dx: int  # pattern column of chip column 0 at X = 0
    dy: int


def fft_shape(
    pattern_shape: tuple[int, int],
    chip_shape: tuple[int, int],
    window: Window,
    backend: str = "scipy",
) -> tuple[int, int]:
    """(ny, nx) of the transforms for a correlation window: sizes only, nothing allocated
    (for OpenCV's transforms, ``backend="opencv"``, even sizes of its own fast lengths)."""
    (hp, wp), (hc, wc) = pattern_shape, chip_shape
    # Alias-free: the partners m +- N of every wanted shift m lie outside the linear
    # support [-(hc - 1), hp - 1], and the window does not wrap onto itself.
    need_y = max(
        hp, hc, 2 * window.ry + 1, hp - (window.dy - window.ry), window.dy + window.ry + hc
    )
    need_x = max(
        wp, wc, 2 * window.rx + 1, wp - (window.dx - window.rx), window.dx + window.rx + wc
    )
    if backend == "opencv":
        return _even_dft_size(need_y), _even_dft_size(need_x)
    return next_fast_len(need_y, real=False), next_fast_len(need_x, real=True)


def next_fast_len(n: int, real: bool = False) -> int:
    """The smallest length >= ``n`` pocketfft transforms fastest: :func:`scipy.fft.next_fast_len`
    (lengths whose prime factors are at most 11, at most 5 for real transforms), without
    importing SciPy's FFT package: a run's pricing needs the sizes, not the transforms."""
    primes = (2, 3, 5) if real else (2, 3, 5, 7, 11)
    m = max(int(n), 1)
    while True:
        rest = m
        for p in primes:
            while rest % p == 0:
                rest //= p
        if rest == 1:
            return m
        m += 1


def _even_dft_size(need: int) -> int:
    """OpenCV's fast size (2^a 3^b 5^c) >= need, even (its packed spectra, :func:`_ccs`)."""
    import cv2

    n = cv2.getOptimalDFTSize(need)
    while n % 2:
        n = cv2.getOptimalDFTSize(n + 1)
    return n


def _ccs(half: np.ndarray, nx: int) -> np.ndarray:
    """The (ny, nx / 2 + 1) half spectrum of a real 2-D transform in OpenCV's packed real
    layout (CCS, ny and nx even): columns 1 .. nx - 2 hold (Re, Im) of x frequencies
    1 .. nx / 2 - 1 for every row; columns 0 and nx - 1 hold x frequencies 0 and nx / 2,
    whose spectra are Hermitian along y, packed as Re Y0, Re Y1, Im Y1, ..., Re Y(ny / 2)."""
    ny = half.shape[0]
    out = np.empty((ny, nx), np.real(half).dtype)
    out[:, 1 : nx - 1 : 2] = np.real(half[:, 1 : nx // 2])
    out[:, 2 : nx - 1 : 2] = np.imag(half[:, 1 : nx // 2])
    for c, k in ((0, 0), (nx - 1, nx // 2)):
        _pack_column(out[:, c], half[: ny // 2 + 1, k])
    return out


def _pack_column(dst: np.ndarray, z: np.ndarray) -> None:
    """A Hermitian column's frequencies 0 .. ny / 2 (``z``) into its CCS column ``dst``."""
    ny = len(dst)
    dst[0] = np.real(z[0])
    dst[1 : ny - 1 : 2] = np.real(z[1 : ny // 2])
    dst[2 : ny - 1 : 2] = np.imag(z[1 : ny // 2])
    dst[ny - 1] = np.real(z[ny // 2])


def _unpack_column(src: np.ndarray) -> np.ndarray:
    """A CCS column's frequencies 0 .. ny / 2, complex (inverse of :func:`_pack_column`)."""
    ny = len(src)
    z = np.zeros(ny // 2 + 1, np.result_type(src.dtype, np.complex64))
    z[0] = src[0]
    z[1 : ny // 2] = src[1 : ny - 1 : 2] + 1j * src[2 : ny - 1 : 2]
    z[ny // 2] = src[ny - 1]
    return z


def _padded(n: int, dtype) -> int:
    """Row length (elements) of a work array whose rows hold ``n``: 64 bytes more, so that
    the row stride is never a multiple of 4 KiB (a column walk over rows 4 KiB apart
    thrashes the cache: the transposes measured 4.6x slower at 1024 x 513)."""
    return n + 64 // np.dtype(dtype).itemsize


def kernel_bytes(fft: tuple[int, int], dtype, chunks: int) -> int:
    """Bytes of the stored pattern spectrum and its mirror-image copy."""
    ny, nx = fft
    return ny * (nx // 2 + 1) * 2 * np.dtype(dtype).itemsize * 2


def _slot_bytes(fft: tuple[int, int], out_rows: int, chip_rows: int, dtype) -> int:
    """Bytes one thread's pipeline holds: its spectrum and its mirror image's (transposed),
    the window rows transposed back, and SciPy's results of the forward row pass and of
    the last inverse pass."""
    ny, nx = fft
    nh, item = nx // 2 + 1, np.dtype(dtype).itemsize
    cbytes = 2 * item
    return (
        2 * nh * _padded(ny, dtype) * cbytes
        + out_rows * _padded(nh, dtype) * cbytes
        + chip_rows * nh * cbytes
        + out_rows * nx * item
    )


def work_bytes(fft: tuple[int, int], out_rows: int, dtype, chunk: int, chunks: int) -> int:
    """Working memory of a correlation in ``chunks`` chunks of ``chunk`` twists (bytes):
    the kernels, and one pipeline (:func:`_slot_bytes`) per thread that runs at once
    (at most one per twist of a chunk)."""
    slots = max(1, min(threads(), chunk))
    return kernel_bytes(fft, dtype, chunks) + slots * _slot_bytes(fft, out_rows, fft[0], dtype)


class Slot(NamedTuple):
    """One thread's work arrays, views of arrays with padded rows (:func:`_padded`).
    SciPy: the spectrum ``spec`` and its mirror image's ``mspec``, (nx / 2 + 1, ny)
    transposed (x frequency, y), and ``rows`` (window rows, nx / 2 + 1). OpenCV: (ny, nx)
    arrays each transformed in place (chip, packed spectrum :func:`_ccs`, window), so a
    thread works in one array (``rows`` None)."""

    spec: np.ndarray
    mspec: np.ndarray | None
    rows: np.ndarray | None


class Workspace(NamedTuple):
    """Work arrays of a correlation, owned by the caller: one :class:`Slot` per thread, and
    for mirror outputs the mirror images' kernel (SciPy) or phase ramp over the y
    frequencies (OpenCV); None without mirror outputs."""

    slots: tuple[Slot, ...]
    mkernel: np.ndarray | None


@functools.cache
def _pool(n: int) -> ThreadPoolExecutor:
    """The process's threads that run twists side by side (made once per count)."""
    return ThreadPoolExecutor(n, thread_name_prefix="selfalign-fft")


def _rfft_rows(sfft, pattern: np.ndarray, nx: int, workers: int) -> np.ndarray:
    """The real transform along x (length ``nx``) of every row of ``pattern``: of the rows
    between its first and last that hold pixels, the others' transforms being zero (a pad,
    or a part of one, on its box: a fraction of the rows; the same numbers as the whole)."""
    held = np.flatnonzero(pattern.any(axis=1))
    if len(held) == 0 or held[-1] + 1 - held[0] == pattern.shape[0]:
        return sfft.rfft(pattern, n=nx, axis=1, workers=workers)
    r0, r1 = int(held[0]), int(held[-1]) + 1
    part = sfft.rfft(pattern[r0:r1], n=nx, axis=1, workers=workers)
    out = np.zeros((pattern.shape[0], part.shape[1]), part.dtype)
    out[r0:r1] = part
    return out


class Correlator:
    """Linear cross-correlation of one fixed pattern with a stack of chips, windowed.

    ``corr[b, Y + ry, X + rx] = sum_{k,l} chip[b, k, l] * pattern[k + Y + dy, l + X + dx]``
    for the arrays as given (both in the same row orientation).

    How the passes are kept few and fast (measured in docs/benchmarks.md). On the CPU
    each twist runs its own pipeline on one thread, the threads taking twists in turn.
    The roll that puts the window at index 0 (so the window is a plain slice, not a
    gather) and the transforms' normalisation are folded once into the stored kernel.

    * ``backend="opencv"`` (float32 on x86-64 by default): OpenCV's 2-D real transform
      of the chip written into a canvas of zeros, one multiply by the packed kernel
      ``kernel_ccs`` (conjugating the chip's spectrum), the inverse, the window copied
      out. OpenCV runs these transforms in Intel's IPP.
    * ``backend="scipy"`` (pocketfft): the chip's rows that hold pixels go through a
      real transform along x; the result is written transposed (x frequency, y) and
      conjugated in the same pass, so the transform along y runs along contiguous
      memory and gives the conjugate spectrum the correlation needs; one multiply by
      the stored kernel ``kernel_t``, the inverse along y, the window's rows transposed
      back, and the inverse along x.
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
        self.dtype = np.dtype(dtype)
        self.backend = _default_backend(self.dtype) if backend == "auto" else backend
        self.window = window
        hc, wc = chip_shape
        self.ny, self.nx = fft_shape(pattern.shape, chip_shape, window, self.backend)
        self.chip_shape = (hc, wc)
        self.out_shape = (2 * window.ry + 1, 2 * window.rx + 1)
        self.workers = threads()
        # SciPy's FFT imported here, once, not at the top: pricing a run needs no transform.
        import scipy.fft as sfft

        self._sfft = sfft
        spec = sfft.fft(
            _rfft_rows(sfft, np.asarray(pattern, self.dtype), self.nx, self.workers),
            n=self.ny,
            axis=0,
            workers=self.workers,
        )
        cdt = spec.dtype
        if meniscus_px > 0:  # the finite meniscus: the pattern blurred by K_h (simulator.physics)
            from simulator.physics import kernel_spectrum

            spec *= kernel_spectrum(self.ny, self.nx, meniscus_px)
        # corr[m] = sum_k c[k] p[k + m]: CORR = conj(C) P. The window starts at
        # m0 = dy - ry: corr[m0 + j] = IFFT(P e^{+i w m0} conj(C))[j].
        fy, fx = np.fft.fftfreq(self.ny), np.fft.rfftfreq(self.nx)
        m0y, m0x = window.dy - window.ry, window.dx - window.rx
        ky, kx = np.exp(2j * np.pi * fy * m0y), np.exp(2j * np.pi * fx * m0x)
        if self.backend == "jax":
            # The JAX pipeline transforms the flipped chip f[k] = c[hc - 1 - k], whose
            # spectrum is e^{-i w (hc - 1)} conj(C): the kernel takes e^{+i w (hc - 1)} too.
            ky = ky * np.exp(2j * np.pi * fy * (hc - 1))
            kx = kx * np.exp(2j * np.pi * fx * (wc - 1))
            self.kernel = (spec * ky[:, None] * kx[None, :]).astype(cdt)
            self._jax_fn = self._make_jax()
        elif self.backend == "opencv":
            # OpenCV's inverse is not normalised: 1 / (ny nx) goes into the kernel.
            norm = 1.0 / (self.ny * self.nx)
            half = spec * (ky[:, None] * norm) * kx[None, :]
            self.kernel_ccs = _ccs(half, self.nx).astype(self.dtype)
        else:
            # Stored transposed, (nx / 2 + 1, ny), as the pipeline's spectra are.
            self.kernel_t = np.ascontiguousarray((spec * ky[:, None] * kx[None, :]).T, cdt)

    def bytes_per_twist(self) -> int:
        """Work bytes of one pipeline (one thread's twist at a time)."""
        return _slot_bytes((self.ny, self.nx), self.out_shape[0], self.chip_shape[0], self.dtype)

    def workspace(self, chunk: int, mirror: bool = False) -> Workspace:
        """Work arrays for calls of up to ``chunk`` chips (with mirror images if ``mirror``):
        one pipeline per thread that runs at once (at most ``chunk``).

        The caller owns them and passes them to every call of a build, so that no chunk
        allocates fresh pages; nothing is cached on the correlator.
        """
        if self.backend == "jax":
            return Workspace((), None)
        n_slots = max(1, min(self.workers, int(chunk)))
        ny, nh = self.ny, self.nx // 2 + 1
        if self.backend == "opencv":
            nx, padded = self.nx, (ny, _padded(self.nx, self.dtype))

            def packed() -> Slot:
                # Padded rows here too: measured 4-7 % faster transforms at 1024 x 1024.
                return Slot(
                    np.empty(padded, self.dtype)[:, :nx],
                    np.empty(padded, self.dtype)[:, :nx] if mirror else None,
                    None,
                )

            # The mirror image's spectrum: e^{-i w (hc - 1)} C(-ky) (see __call__).
            ramp = np.exp(-2j * np.pi * np.fft.fftfreq(ny) * (self.chip_shape[0] - 1))
            return Workspace(tuple(packed() for _ in range(n_slots)), ramp if mirror else None)
        cdt = np.result_type(self.dtype, np.complex64)
        rows = self.out_shape[0]

        def slot() -> Slot:
            spec = np.empty((nh, _padded(ny, cdt)), cdt)[:, :ny]
            mspec = np.empty((nh, _padded(ny, cdt)), cdt)[:, :ny] if mirror else None
            return Slot(spec, mspec, np.empty((rows, _padded(nh, cdt)), cdt)[:, :nh])

        slots = tuple(slot() for _ in range(n_slots))
        if not mirror:
            return Workspace(slots, None)
        # The mirror images' kernel: kernel * exp(+2 pi i ky (hc - 1) / ny), per y frequency.
        ramp = np.exp(2j * np.pi * np.fft.fftfreq(ny) * (self.chip_shape[0] - 1))
        return Workspace(slots, self.kernel_t * ramp.astype(self.kernel_t.dtype)[None, :])

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
        if out is None:
            out = np.empty((len(chips),) + self.out_shape, self.dtype)
        if self.backend == "jax":
            out[...] = np.asarray(self._jax_fn(chips)) * scale
            if mirror_out is not None:
                mirror_out[...] = np.asarray(self._jax_fn(chips[:, ::-1])) * scale
            return out
        if work is None or not work.slots or (mirror_out is not None and work.mkernel is None):
            work = self.workspace(len(chips), mirror_out is not None)
        slots = work.slots[: max(1, min(len(work.slots), len(chips)))]
        # Threads share the cores: one twist per thread; a lone twist gets them all.
        workers = max(1, self.workers // len(slots))
        todo, lock = iter(range(len(chips))), threading.Lock()
        one = self._one_cv if self.backend == "opencv" else self._one

        def run(slot: Slot) -> None:
            while True:
                with lock:
                    k = next(todo, None)
                if k is None:
                    return
                mk = None if mirror_out is None else mirror_out[k]
                one(chips[k], out[k], scale, slot, workers, mk, work.mkernel)

        if len(slots) == 1:
            run(slots[0])
        else:
            for f in [_pool(len(slots)).submit(run, s) for s in slots]:
                f.result()
        return out

    def _one_cv(
        self,
        chip: np.ndarray,
        out: np.ndarray,
        scale: float,
        slot: Slot,
        workers: int,
        mirror_out: np.ndarray | None,
        ramp: np.ndarray | None,
    ) -> None:
        """One chip's pipeline in OpenCV (IPP): its window into ``out``, and its mirror
        image's into ``mirror_out`` from the same forward transform."""
        import cv2

        hc, wc = self.chip_shape
        rows, cols = out.shape
        spec = slot.spec  # one array per thread, transformed in place (a small working set)
        spec[:hc, :wc] = chip
        spec[:hc, wc:] = 0
        spec[hc:] = 0
        # In place: one array per thread (two threads' separate arrays did not fit the
        # cache: 25 % more CPU per twist at 1024 x 1024, measured).
        cv2.dft(spec, spec)
        if mirror_out is not None:
            assert ramp is not None and slot.mspec is not None
            mspec = slot.mspec
            self._mirror_ccs(spec, mspec, ramp)
            cv2.mulSpectrums(self.kernel_ccs, mspec, 0, mspec, conjB=True)
            cv2.idft(mspec, mspec, flags=cv2.DFT_REAL_OUTPUT)
            np.multiply(mspec[:rows, :cols], scale, out=mirror_out)
        cv2.mulSpectrums(self.kernel_ccs, spec, 0, spec, conjB=True)  # kernel * conj(C)
        cv2.idft(spec, spec, flags=cv2.DFT_REAL_OUTPUT)
        np.multiply(spec[:rows, :cols], scale, out=out)

    def _mirror_ccs(self, spec: np.ndarray, mspec: np.ndarray, ramp: np.ndarray) -> None:
        """The packed spectrum of the chip upside down, c'[k] = c[hc - 1 - k], from the
        chip's: C'(ky) = e^{-i w (hc - 1)} C(-ky) (``ramp`` over the y frequencies)."""
        ny, nx = spec.shape
        cdt = np.result_type(spec.dtype, np.complex64)
        pairs, mpairs = spec[:, 1 : nx - 1].view(cdt), mspec[:, 1 : nx - 1].view(cdt)
        mpairs[0] = pairs[0]
        np.multiply(pairs[:0:-1], ramp[1:, None].astype(cdt), out=mpairs[1:])
        for c in (0, nx - 1):  # Hermitian columns: C(-ky) = conj(C(ky))
            z = _unpack_column(spec[:, c])
            _pack_column(mspec[:, c], ramp[: ny // 2 + 1] * np.conj(z))

    def _one(
        self,
        chip: np.ndarray,
        out: np.ndarray,
        scale: float,
        slot: Slot,
        workers: int,
        mirror_out: np.ndarray | None,
        mkernel: np.ndarray | None,
    ) -> None:
        """One chip's pipeline (module docstring): its window into ``out``, and its mirror
        image's into ``mirror_out`` from the same forward transform."""
        rows = np.flatnonzero(chip.any(axis=1))
        if rows.size == 0:
            out[...] = 0
            if mirror_out is not None:
                mirror_out[...] = 0
            return
        # Zero rows around the chip are not transformed (the rows that hold pixels keep
        # their place, so no phase shift is due); trailing zero columns are the
        # transform's own padding.
        r0, r1 = int(rows[0]), int(rows[-1]) + 1
        c1 = int(np.flatnonzero(chip[r0:r1].any(axis=0))[-1]) + 1
        spec, rows_work = slot.spec, slot.rows
        assert rows_work is not None
        sfft = self._sfft
        part = sfft.rfft(chip[r0:r1, :c1], n=self.nx, axis=1, workers=workers)
        spec[:, :r0] = 0
        spec[:, r1:] = 0
        np.conjugate(part.T, out=spec[:, r0:r1])
        # conj(FFT_y(R)) = unnormalized backward transform of conj(R): conj(C), in place.
        sfft.ifft(spec, axis=1, norm="forward", workers=workers, overwrite_x=True)
        if mirror_out is not None:
            # The mirror image c'[k] = c[hc - 1 - k]: conj(C')(ky) = e^{+i w (hc - 1)}
            # conj(C)(-ky), the ramp folded into ``mkernel``.
            assert mkernel is not None and slot.mspec is not None
            np.multiply(spec[:, :1], mkernel[:, :1], out=slot.mspec[:, :1])
            np.multiply(spec[:, :0:-1], mkernel[:, 1:], out=slot.mspec[:, 1:])
            self._inverse(slot.mspec, rows_work, mirror_out, scale, workers)
        np.multiply(spec, self.kernel_t, out=spec)
        self._inverse(spec, rows_work, out, scale, workers)

    def _inverse(
        self, spec: np.ndarray, rows: np.ndarray, out: np.ndarray, scale: float, workers: int
    ) -> None:
        """out = scale * window of the inverse transform of the transposed ``spec``
        (overwritten; ``rows`` is the window rows' work array)."""
        sfft = self._sfft
        sfft.ifft(spec, axis=1, workers=workers, overwrite_x=True)
        np.copyto(rows, spec[:, : len(rows)].T)
        res = sfft.irfft(rows, n=self.nx, axis=1, workers=workers)
        np.multiply(res[:, : out.shape[1]], scale, out=out, casting="unsafe")

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
    # Both profiles over one mirror-symmetric set of rows, a quarter of the stack (a row
    # profile over every row read all of it: 0.12 s for 181 chips of 512 x 512 px).
    rows = np.unique(np.r_[np.arange(0, h, 8), h - 1 - np.arange(0, h, 8)])
    sub = chips[:, rows, :]
    row_prof = np.round(sub.sum(axis=2, dtype=np.float64), 6)
    col_prof = np.round(sub.sum(axis=1, dtype=np.float64), 6)
    tmp = np.empty((h, w), chips.dtype)

    def close(i: int, j: int, mirrored: bool) -> bool:
        """chips[i] == chips[j] (upside down if mirrored) within tol: the sampled rows first."""
        if np.abs(sub[i] - (sub[j, ::-1] if mirrored else sub[j])).max() > tol:
            return False
        np.subtract(chips[i], chips[j, ::-1] if mirrored else chips[j], out=tmp)
        return max(-float(tmp.min()), float(tmp.max())) <= tol

    # Every first chip under its profiles' key; a key can hold more than one (profiles
    # that agree on the sampled rows only), each then checked in turn.
    seen: dict[tuple[bytes, bytes], list[int]] = {}
    out: list[tuple[int, bool]] = []
    for i in range(t):
        cp = col_prof[i].tobytes()
        key = (row_prof[i].tobytes(), cp)
        twin_key = (row_prof[i, ::-1].tobytes(), cp)
        rel = next(((j, False) for j in seen.get(key, ()) if close(i, j, False)), None)
        if rel is None:
            rel = next(((j, True) for j in seen.get(twin_key, ()) if close(i, j, True)), None)
        if rel is None:
            seen.setdefault(key, []).append(i)
            rel = (i, False)
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
    self_twins: tuple[int, ...] = (),
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
        self_twins: planes whose chip is its own mirror image (a mirror-symmetric chip at
            twist 0): with ``flip_rows`` they are mirror-symmetric too, and are made so
            exactly (the mean of the plane and its flip), so that a start on the mirror
            line stays on it (the transforms' round-off alone breaks the symmetry).
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
    if flip_rows is not None:
        for i in self_twins:
            plane = out[i, :flip_rows]
            plane += plane[::-1].copy()
            plane *= 0.5
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
