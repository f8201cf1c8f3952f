"""Peak memory of a call, for the benchmarks: the rise of this process's peak RSS.

Linux VmHWM, reset through /proc/self/clear_refs where allowed (so earlier peaks do not
hide the call's), else the ``ru_maxrss`` delta. Counts numpy and JAX buffers alike.
"""

from __future__ import annotations

import resource


def _status_kb(field: str) -> int | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def mark() -> dict:
    """Reset the peak-RSS counter if allowed and remember the memory in use now."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        reset = True
    except OSError:
        reset = False
    return {
        "reset": reset,
        "rss_kb": _status_kb("VmRSS") or 0,
        "maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
    }


def peak_mb(before: dict) -> float:
    """MB by which the peak RSS rose over the memory in use at :func:`mark`."""
    if before["reset"]:
        hwm = _status_kb("VmHWM")
        if hwm is not None:
            return max(0.0, (hwm - before["rss_kb"]) / 1024)
    return max(
        0.0, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before["maxrss_kb"]) / 1024
    )
