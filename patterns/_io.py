"""Pattern images on disk: read any Pillow-readable image into a Mask, write 16-bit PNGs.

Reading (:func:`read_mask`):

* White is wettable (1.0), black is substrate (0.0); grey levels are kept as values in
  [0, 1]: 8-bit / 255, 16-bit / 65535, 1-bit as 0 or 1. A colour image is read when its
  channels agree (a grey drawing stored as RGB, within :data:`CHANNEL_TOLERANCE` levels):
  as its luminance ``(299 R + 587 G + 114 B) / 1000`` (ITU-R 601, as Pillow's
  ``convert('L')``). One whose channels differ (a red-on-white drawing) is refused unless
  ``channel`` picks what is read: ``"red"``, ``"green"``, ``"blue"`` or ``"luminance"``
  (``--channel`` on the command line).
* A lossy format (JPEG) is read as it is, and ``Mask.params["lossy_format"]``
  names it: its compression speckle is then named as the cause of a "smallest feature"
  below a few pixels (:func:`simulator.scene.feature_warning`).
* Transparency (an alpha channel, or a tRNS chunk in palette/grey/RGB images) multiplies the
  value: a transparent pixel is never wettable. ``invert=True`` takes ``1 - value`` *before*
  the alpha is applied, so inverting a drawing on a transparent background keeps the
  background non-wettable.
* Scale: an explicit ``um_per_px`` wins. Otherwise the PNG's pHYs chunk (pixels per metre,
  unit "metre") gives ``um_per_px = 1e6 / px_per_m``; a pHYs with unit "unknown" only states
  an aspect ratio and is ignored. ``default_um_per_px`` is the scale of a file that stores
  none, and must agree with the scale of one that does (the command line's rule). pHYs stores whole pixels per metre, so a file written by
  :func:`write_mask` also records the exact scale in its ``selfalign`` text chunk, which
  refines the pHYs value when both agree.
* The ``selfalign`` text chunk (JSON), when present, becomes ``Mask.params``.

Writing (:func:`write_mask`): 16-bit greyscale (coverage survives to 1/65535), pHYs in
pixels per metre, the ``selfalign`` JSON text chunk, written atomically.
"""

from __future__ import annotations

import json
import math
import os
import struct
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, PngImagePlugin

from foundation import InputError, atomic_output, positive, price_image, require_regular_file
from patterns._metadata import parse_png_params
from patterns.geometry import Mask

__all__ = ["CHANNELS", "TEXT_KEY", "read_mask", "write_mask"]

#: Key of the PNG text chunk holding the generating parameters as JSON.
TEXT_KEY = "selfalign"

_UM_PER_M = 1e6
_SIXTEEN_BIT = {"I;16", "I;16L", "I;16B", "I;16N", "I"}

#: What ``channel`` may pick from a colour image (:func:`read_mask`, ``--channel``).
CHANNELS = ("red", "green", "blue", "luminance")
#: Largest difference (8-bit levels) between the channels of a pixel for a colour image to
#: count as grey (JPEG's chroma rounding of a grey drawing stays within a few levels).
CHANNEL_TOLERANCE = 8
#: Pillow formats whose compression changes the pixels.
LOSSY_FORMATS = ("JPEG", "MPO", "JPEG2000")


def _colour_value(
    rgb: np.ndarray, alpha: np.ndarray | None, channel: str | None, path: Path
) -> np.ndarray:
    """8-bit RGB (..., 3) -> value in [0, 1]: the ``channel`` picked, else the luminance of an
    image whose channels agree (pixels with some opacity; InputError otherwise)."""
    if channel is not None and channel != "luminance":
        return rgb[..., CHANNELS.index(channel)] / 255.0
    if channel is None:
        spread = rgb.max(axis=-1).astype(np.int16) - rgb.min(axis=-1)
        if alpha is not None:
            spread = spread[alpha > 0]
        worst = int(spread.max()) if spread.size else 0
        if worst > CHANNEL_TOLERANCE:
            raise InputError(
                f"{path}: a colour image whose channels differ (by up to {worst} of 255 levels), so "
                "its grey value is ambiguous; give --channel red, green or blue (the channel whose bright "
                "part is the pad) or --channel luminance, or save the drawing as greyscale"
            )
    return _luminance(rgb)


def _luminance(rgb: np.ndarray) -> np.ndarray:
    """8-bit RGB (..., 3) -> luminance in [0, 1], exact 1.0 for white."""
    r, g, b = (rgb[..., i].astype(np.int64) for i in range(3))
    return (299 * r + 587 * g + 114 * b) / (1000.0 * 255.0)


def _values(
    im: Image.Image, path: Path, channel: str | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Image -> (grey value in [0, 1], alpha in [0, 1] or None); a colour image through
    :func:`_colour_value` (``channel``)."""
    mode, trns = im.mode, im.info.get("transparency")
    if mode in _SIXTEEN_BIT:
        raw = np.asarray(im)  # uint16 or int32 as decoded: no wider copy
        wide = not (raw.dtype.kind == "u" and raw.dtype.itemsize <= 2)  # 16 bits hold 0..65535
        if wide and (raw.min() < 0 or raw.max() > 65535):
            raise InputError(
                f"{path}: 32-bit integer image with values outside 0..65535; save it as 8- or 16-bit grey"
            )
        alpha = None if trns is None else (raw != trns).astype(np.float64)
        value = np.divide(raw, 65535.0, dtype=np.float64)  # one pass: float64(v) / 65535
        del raw
        return value, alpha
    if mode == "F":  # the only mode whose values can leave [0, 1]
        value = np.asarray(im, dtype=np.float64)
        if value.min() < 0 or value.max() > 1 or not np.all(np.isfinite(value)):
            raise InputError(
                f"{path}: float image with values outside [0, 1]; save it as 8- or 16-bit grey"
            )
        return value, None
    if mode == "1" and trns is None:
        return np.asarray(im, dtype=np.float64), None
    if mode == "L" and trns is None:
        return np.asarray(im, dtype=np.float64) / 255.0, None
    if mode in ("1", "L", "LA", "La") and (mode in ("LA", "La") or trns is not None):
        la = np.asarray(im.convert("LA"), dtype=np.float64) / 255.0
        return la[..., 0], la[..., 1]
    if mode == "RGB" and trns is None:
        return _colour_value(np.asarray(im), None, channel, path), None
    # Palette, RGBA, RGB with tRNS, CMYK, YCbCr, LAB, HSV, ...: go through RGBA.
    with warnings.catch_warnings():
        warnings.simplefilter(
            "ignore", UserWarning
        )  # Pillow's note on palette transparency in bytes
        rgba = np.asarray(im.convert("RGBA"))
    alpha = rgba[..., 3] / 255.0
    return _colour_value(rgba[..., :3], alpha, channel, path), alpha


def _scale_from_file(
    info: dict,
    params: dict,
    path: Path,
    default: float | None = None,
    flag: str = "--um-per-px",
    hint: str | None = None,
) -> float:
    """um per px from the pHYs chunk (refined by the text chunk's exact value).

    A file without a usable scale takes ``default`` (the scale a flag gives for files that
    lack one), else InputError naming ``hint`` (default ``flag``). A file that stores a
    scale keeps it; a ``default`` that contradicts it is an InputError (the caller
    overrides stored scales by passing ``um_per_px`` to :func:`read_mask` instead).
    """
    hint = hint or flag
    dpi = info.get(
        "dpi"
    )  # Pillow sets 'dpi' only for pHYs with unit = metre (as px_per_m * 0.0254)
    if dpi is None:
        if default is not None:
            return default
        raise InputError(f"{path} has no scale (pHYs chunk); pass {hint}")
    px_per_m = [round(float(v) / 0.0254) for v in dpi]
    if px_per_m[0] <= 0 or px_per_m[1] <= 0:
        if default is not None:
            return default
        raise InputError(
            f"{path}: its pHYs chunk gives a non-positive scale ({px_per_m[0]} x {px_per_m[1]} px/m); pass {hint}"
        )
    if px_per_m[0] != px_per_m[1]:
        if default is not None:
            return default
        raise InputError(
            f"{path}: its pHYs chunk gives non-square pixels ({px_per_m[0]} x {px_per_m[1]} px/m); "
            f"resample to square pixels or pass {hint}"
        )
    exact = params.get("um_per_px")
    if isinstance(exact, int | float) and exact > 0 and round(_UM_PER_M / exact) == px_per_m[0]:
        stored = float(exact)
    else:
        stored = _UM_PER_M / px_per_m[0]
    if default is not None and not math.isclose(default, stored, rel_tol=1e-6):
        raise InputError(
            f"{path} stores its scale, {stored:g} um/px (pHYs chunk), but {flag} {default:g} contradicts it; "
            f"drop {flag} to use the file's scale, or add --override-scale to use {default:g} um/px"
        )
    return stored


def read_mask(
    path: str | os.PathLike,
    um_per_px: float | None = None,
    invert: bool = False,
    max_mpx: float | None = None,
    budget_mb: float | None = None,
    default_um_per_px: float | None = None,
    scale_flag: str = "--um-per-px",
    missing_hint: str | None = None,
    channel: str | None = None,
) -> Mask:
    """Read an image file as a :class:`~patterns.geometry.Mask` (see the module notes for the rules).

    Args:
        path: any Pillow-readable image (PNG expected); the first frame of multi-frame files.
        um_per_px: pixel size in micrometres; overrides the file's pHYs scale.
        default_um_per_px: pixel size for a file that stores no (usable) scale; one that
            contradicts the file's stored scale is an InputError naming ``scale_flag``
            (the command line's rule: a file's own scale wins, ``--override-scale`` aside).
        missing_hint: what the error for a file without a scale tells the user to pass
            (default ``scale_flag``).
        invert: take ``1 - value`` (for images where black marks the pad).
        channel: what to read from a colour image whose channels differ (:data:`CHANNELS`);
            None: such an image is an InputError (a grey one is read as its luminance).
        max_mpx: largest image in megapixels (default
            :data:`foundation.DEFAULT_MAX_IMAGE_MPX`); checked from the header,
            before the pixels are decoded.
        budget_mb: memory budget the decoded image must fit (default: the default budget).

    Raises:
        InputError: missing, unreadable, not a regular file or too large, or no usable scale.
    """
    path = Path(path)
    if um_per_px is not None:
        um_per_px = positive("--um-per-px", um_per_px, "um per px")
    if default_um_per_px is not None:
        default_um_per_px = positive(scale_flag, default_um_per_px, "um per px")
    if channel is not None and channel not in CHANNELS:
        raise InputError(f"channel must be one of {', '.join(CHANNELS)}, got {channel!r}")
    require_regular_file(path, "image")
    try:
        with warnings.catch_warnings():
            # Pillow warns above its own bomb limit; our limit (price_image) applies instead.
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            im = Image.open(path)
        with im:
            price_image(im.size[0], im.size[1], path, max_mpx, budget_mb)
            im.load()
            value, alpha = _values(im, path, channel)
            info = dict(im.info)
            lossy = im.format if im.format in LOSSY_FORMATS else None
    except InputError:
        raise
    except Image.DecompressionBombError as err:
        raise InputError(f"{path}: image too large to read safely ({err})") from None
    except MemoryError:
        raise InputError(f"{path}: not enough memory to decode this image; downsample it") from None
    except (OSError, SyntaxError, ValueError, EOFError, struct.error) as err:
        raise InputError(
            f"{path}: not a readable image ({type(err).__name__}: {err}); give a PNG file"
        ) from None
    params = parse_png_params(info.get(TEXT_KEY), path)
    scale = (
        um_per_px
        if um_per_px is not None
        else _scale_from_file(info, params, path, default_um_per_px, scale_flag, missing_hint)
    )
    if invert:
        value = 1.0 - value
    if alpha is not None:
        value = value * alpha
    if lossy:
        params = {**params, "lossy_format": lossy}
    return Mask(data=value, um_per_px=scale, params=params)


def write_mask(path: str | os.PathLike, mask: Mask, params: dict[str, Any] | None = None) -> Path:
    """Write ``mask`` as a 16-bit grey PNG with its scale (pHYs) and parameters (text chunk).

    Values are stored as ``round(65535 * value)``. ``params`` (default ``mask.params``) is
    stored as JSON under the ``selfalign`` key, with ``um_per_px`` set to the mask's scale.
    The file appears only once fully written. Returns the path.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"output {path}: is a directory; give a file name ending in .png")
    if path.suffix.lower() != ".png":
        raise InputError(f"output {path}: the file name must end in .png")
    record = dict(mask.params if params is None else params)
    record["um_per_px"] = mask.um_per_px
    px_per_m = round(_UM_PER_M / mask.um_per_px)
    if px_per_m < 1 or px_per_m > 2**31 - 1:
        raise InputError(
            f"um_per_px={mask.um_per_px:g} cannot be stored in a PNG pHYs chunk "
            f"(1 to 2^31-1 px per metre); use {_UM_PER_M / (2**31 - 1):.3g} <= um_per_px <= 1e6"
        )
    info = PngImagePlugin.PngInfo()
    info.add_text(TEXT_KEY, json.dumps(record, sort_keys=True))
    pixels = np.round(mask.data * 65535.0).astype(np.uint16)
    with atomic_output(path) as tmp:
        try:
            Image.fromarray(pixels).save(
                tmp,
                format="PNG",
                pnginfo=info,
                compress_level=9,
                dpi=(px_per_m * 0.0254, px_per_m * 0.0254),
            )  # Pillow writes pHYs from dpi
        except OSError as err:
            raise InputError(f"output {path}: cannot write ({err.strerror or err})") from None
    return path
