"""The sizes and bytes of a correlation, computed before anything is allocated: the
translation window (:class:`Window`), the transforms' lengths (:func:`fft_shape`, pocketfft's
and OpenCV's fast lengths) and the memory a correlation holds (:func:`work_bytes`), which a
run's pricing needs without importing an FFT."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simulator.core import threads


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
