"""Linear (zero-padded, never circular) FFT cross-correlation of one pattern with
stacks of chips, windowed to the translations asked for: the :class:`Correlator`. Its sizes
and bytes are :mod:`~simulator.landscape._fftsize`'s, its backends
:mod:`~simulator.landscape._backends`'s; the symmetries between chips that save transforms
are :mod:`~simulator.landscape._symmetry`'s (:func:`chip_relations`, :func:`correlate_stack`).

The transform runs in SciPy's pocketfft on a CPU (measured faster than XLA's FFT on
a 2-core machine, see docs/benchmarks.md) and in JAX when JAX sees a GPU; ``backend=`` overrides.
On the CPU each twist goes through its own pipeline, one twist per thread, in a
transposed layout in which every 1-D transform runs along contiguous memory: forward
chip transforms skip the rows that are zero, and only the translation window asked
for is transformed back along x.
"""

from __future__ import annotations

import threading
from typing import NamedTuple

import numpy as np

from foundation import InputError
from simulator.core import threads
from simulator.landscape._backends import BACKENDS, _default_backend, _jax_correlation, _pool
from simulator.landscape._fftsize import Window, _padded, _slot_bytes, fft_shape
from simulator.landscape._spectra import _ccs, _pack_column, _unpack_column

#: Noise floor = NOISE_FACTOR * eps(dtype) * max|E|: a bound on FFT round-off
#: (measured worst case about 3 eps * max|E| in float32 on library patterns).
NOISE_FACTOR = 32.0


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
