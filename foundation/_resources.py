"""Resources priced before they are allocated: memory budget, image pixels, rasters.

Every array whose size a user controls (a decoded image, a raster of a chip or a
pattern, the twists of the pose grid, a path buffer, a batch of starts, curve samples,
the landscape) is priced in bytes *before* it is allocated, and refused with one line
that gives the estimate and the knob that shrinks it. The budget is the scene's
``memory_budget_mb`` (flag ``--memory-budget``), by default half the memory available
when the process starts, at most 8 GiB; it can never be set above the machine's memory.
"""

from __future__ import annotations

import functools
import math
import os
from pathlib import Path

from foundation._errors import InputError

#: Ceiling of the default memory budget (MiB).
DEFAULT_BUDGET_CAP_MB = 8192.0
#: Images larger than this (megapixels) are refused unless ``--max-image-mpx`` raises it.
DEFAULT_MAX_IMAGE_MPX = 64.0
#: Peak bytes per pixel while an image is decoded and turned into a float mask
#: (decoded RGBA, grey and alpha as float64, their product and the clipped copy).
IMAGE_BYTES_PER_PX = 48
#: Peak bytes per pixel of an exact raster (float64 coverage, the cumulative sum and
#: its temporaries).
RASTER_BYTES_PER_PX = 32

MB = 2**20


def _cgroup_limit_bytes() -> float:
    """The memory limit of this process's cgroup (v2 or v1), or inf."""
    for name in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(name).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            return float(text)
    return math.inf


@functools.cache
def machine_memory_bytes() -> float:
    """Physical memory of the machine (or the cgroup's limit when smaller), bytes; read once
    per process (every Scene checks its budget against it)."""
    try:
        total = float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        total = 16.0 * 2**30
    return min(total, _cgroup_limit_bytes())


def available_memory_bytes() -> float:
    """Memory available now (MemAvailable), bytes; the machine's memory if unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return min(float(line.split()[1]) * 1024, machine_memory_bytes())
    except (OSError, ValueError, IndexError):
        pass
    return machine_memory_bytes()


@functools.cache
def default_budget_mb() -> float:
    """Half of the memory available when first asked (once per process), at most 8 GiB (MiB)."""
    return float(min(DEFAULT_BUDGET_CAP_MB, available_memory_bytes() / MB / 2))


def check_budget_mb(value: float, name: str = "memory budget") -> float:
    """A budget in MiB that is finite, > 0 and at most the machine's memory, else InputError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number of MB, got {value!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise InputError(f"{name} must be a finite number of MB > 0, got {value!r}")
    total = machine_memory_bytes() / MB
    if v > total:
        raise InputError(
            f"{name} {v:,.0f} MB is more than this machine's memory ({total:,.0f} MB); give at most {total:,.0f} MB (--memory-budget)"
        )
    return v


def budget_bytes(budget_mb: float | None) -> float:
    """Bytes of ``budget_mb`` (None = :func:`default_budget_mb`)."""
    return (default_budget_mb() if budget_mb is None else float(budget_mb)) * MB


def fmt_bytes(n: float) -> str:
    """'1.2 GB', '340 MB', '1,000 MB', '12 kB' (powers of 1024, three significant digits
    below 1,000 and whole units above; 'an unbounded amount' for inf/nan)."""
    if not math.isfinite(n):
        return "an unbounded amount of memory"
    for unit, k in (("TB", 2**40), ("GB", 2**30), ("MB", 2**20), ("kB", 2**10)):
        if n >= k:
            v = n / k
            return f"{v:,.0f} {unit}" if v >= 999.5 else f"{v:.3g} {unit}"
    return f"{n:.0f} B"


def require_fits(what: str, nbytes: float, knob: str, budget_mb: float | None = None) -> None:
    """InputError unless ``nbytes`` (may be inf) fits the memory budget.

    Args:
        what: the thing priced, e.g. "the chip raster (1,000,000 x 1,000,000 px)".
        nbytes: its estimated peak size in bytes.
        knob: what shrinks it, e.g. "use a coarser --resolution".
        budget_mb: the budget (None = the default budget).
    """
    limit = budget_bytes(budget_mb)
    if not (nbytes <= limit):  # also catches nan
        raise InputError(
            f"{what} would need about {fmt_bytes(nbytes)} but the memory budget is {fmt_bytes(limit)}; {knob} (or raise --memory-budget)"
        )


def price_raster(
    shape_hw: tuple[float, float], um_per_px: float, what: str, budget_mb: float | None = None
) -> None:
    """Refuse a raster of (H, W) pixels (floats allowed, may be huge) that cannot fit."""
    h, w = (float(v) for v in shape_hw)
    n = h * w
    require_fits(
        f"{what} ({_px(w)} x {_px(h)} px at {um_per_px:g} um/px)",
        n * RASTER_BYTES_PER_PX,
        "use a coarser scale (--resolution or --um-per-px) or a smaller chip/pattern",
        budget_mb,
    )


def price_image(
    width: int,
    height: int,
    path: os.PathLike | str,
    max_mpx: float | None = None,
    budget_mb: float | None = None,
) -> None:
    """Refuse an image whose decoded size is over the pixel limit or the memory budget."""
    limit = DEFAULT_MAX_IMAGE_MPX if max_mpx is None else float(max_mpx)
    if not (math.isfinite(limit) and limit > 0):  # nan or inf would switch the guard off
        raise InputError(
            f"the image limit (--max-image-mpx, max_image_mpx) must be a finite number of megapixels > 0, got {max_mpx!r}"
        )
    mpx = width * height / 1e6
    if mpx > limit:
        raise InputError(
            f"{path}: {width} x {height} px ({mpx:,.1f} megapixels) is over the image limit of {limit:g} megapixels "
            f"(about {fmt_bytes(width * height * IMAGE_BYTES_PER_PX)} to read); downsample the image, or raise the limit with --max-image-mpx"
        )
    require_fits(
        f"reading {path} ({width} x {height} px)",
        width * height * IMAGE_BYTES_PER_PX,
        "downsample the image",
        budget_mb,
    )


def _px(v: float) -> str:
    return f"{v:,.0f}" if v < 1e15 else f"{v:.3g}"
