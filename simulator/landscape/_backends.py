"""Which FFT backend a correlation runs in (SciPy's pocketfft, OpenCV's IPP transforms or
JAX), the environment variable that forces one, the threads that run twists side by side,
and the JAX backend's compiled correlation."""

from __future__ import annotations

import functools
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from foundation import InputError

BACKENDS = ("auto", "scipy", "opencv", "jax")


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


@functools.cache
def _pool(n: int) -> ThreadPoolExecutor:
    """The process's threads that run twists side by side (made once per count)."""
    return ThreadPoolExecutor(n, thread_name_prefix="selfalign-fft")


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
