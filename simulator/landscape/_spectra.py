"""OpenCV's packed real spectra (CCS): a half spectrum packed into a real array, and the
Hermitian columns packed and unpacked, for the OpenCV pipeline of
:class:`simulator.landscape.Correlator`."""

from __future__ import annotations

import numpy as np


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
