"""Whether a chip and a pattern are of plausible scales for each other, checked before any work.

Two slips a user makes with sizes in micrometres, caught when a scene is built (every command
and :meth:`~simulator.scene.Scene.from_inputs` pass here, before a landscape is computed):

* a chip or a pattern off by about 1000 from the other (millimetres typed for micrometres, a
  scale in mm or nm per pixel): refused, naming the likely unit and the value to give;
* a chip smaller than :data:`MIN_CHIP_PX` pixels of the simulation grid: refused (the grid
  cannot carry its shape; the answers would be the pixels' noise).

A chip much larger than the pattern's whole image (its smaller side above
:data:`LARGE_CHIP_RATIO` times the image's larger side) is legitimate but rarely meant: it
covers every pad over a wide range of poses, where the overlap energy is flat (a plateau, no
restoring force); :func:`scale_warning` says so in one line.
"""

from __future__ import annotations

import math

import numpy as np

from foundation import InputError
from patterns.geometry import Mask, footprint_um

#: Fewest pixels of the simulation grid the chip's smaller side may span.
MIN_CHIP_PX = 3.0
#: A chip and a pattern whose sizes differ by a factor within this factor of 1000 (either way)
#: are refused as a unit slip: 250 to 4000 times.
SLIP_SPREAD = 4.0
#: The chip's smaller side above this many times the pattern image's larger side: a warning.
LARGE_CHIP_RATIO = 2.0
#: Sizes (um) beyond which a chip is implausible: below, a size typed in mm; from the second
#: (100 mm) on, in nm.
CHIP_PLAUSIBLE_UM = (5.0, 1e5)


def _is_slip(ratio: float) -> int:
    """+1 when ``ratio`` is about 1000, -1 when about 1/1000, else 0."""
    k = math.log10(ratio)
    spread = math.log10(SLIP_SPREAD)
    if abs(k - 3) <= spread:
        return 1
    if abs(k + 3) <= spread:
        return -1
    return 0


def check_scales(
    pattern: Mask,
    chip_um: tuple[float, float],
    um_per_px: float,
    chip_from: str,
) -> None:
    """Refuse a chip of ``chip_um`` (width, height of its wettable footprint, um) on ``pattern``
    when one of them is off by about 1000 from the other, or when the chip's smaller side spans
    fewer than :data:`MIN_CHIP_PX` pixels of ``um_per_px`` (the simulation grid).

    ``chip_from``: how the chip was given, for the fix: ``"size"`` (``--chip-size``),
    ``"image"`` (``--chip``, its scale) or ``"layout"`` (a chip layer).

    Raises:
        InputError: one line naming the likely unit and the fix.
    """
    if pattern.geometry is None and not np.any(pattern.data > 0):
        return  # an empty pattern is refused as such (Scene)
    pw, ph = footprint_um(pattern)
    p_side, c_side = max(pw, ph), max(chip_um)
    c_text = f"{chip_um[0]:g} x {chip_um[1]:g} um"
    slip = _is_slip(c_side / p_side) if p_side > 0 and c_side > 0 else 0
    lo, hi = CHIP_PLAUSIBLE_UM
    if slip:
        times = "smaller than" if slip < 0 else "larger than"
        what = f"the {c_text} chip is about 1000 times {times} the pattern ({p_side:.4g} um across)"
        chip_odd = c_side < lo if slip < 0 else c_side >= hi
        if chip_odd:
            f = 1000.0 if slip < 0 else 1e-3
            unit = "mm" if slip < 0 else "nm"
            if chip_from == "size":
                fix = f"--chip-size takes um: give --chip-size {chip_um[0] * f:g}" + (
                    f"x{chip_um[1] * f:g}" if chip_um[0] != chip_um[1] else ""
                )
            elif chip_from == "image":
                fix = f"--chip-um-per-px takes um per px: multiply the chip image's scale by {f:g}"
            else:
                fix = "check the layout's units (--dxf-units for a DXF)"
            raise InputError(f"{what}: a chip size in {unit}? {fix}")
        unit = "nm" if slip < 0 else "mm"
        f = 1e-3 if slip < 0 else 1000.0
        if "layout" in pattern.params:
            fix = f"check the layout's units (a DXF: --dxf-units {unit})"
        else:
            fix = (
                f"--um-per-px takes um per px: give --um-per-px {pattern.um_per_px * f:g} "
                "(with --override-scale if the file stores a scale)"
            )
        raise InputError(f"{what}: the pattern's scale in {unit} per px? {fix}")
    c_min = min(chip_um)
    if c_min < MIN_CHIP_PX * um_per_px:
        raise InputError(
            f"the {c_text} chip spans {c_min / um_per_px:.2g} px at {um_per_px:g} um/px, fewer than "
            f"{MIN_CHIP_PX:g}: its shape is lost on the grid; give its size in um (--chip-size W[xH]) "
            f"or a pixel of at most {c_min / MIN_CHIP_PX:.3g} um (--resolution)"
        )


def scale_warning(pattern: Mask, chip: Mask) -> str | None:
    """A one-line warning when the chip's smaller side is more than :data:`LARGE_CHIP_RATIO`
    times the pattern image's larger side, else None: the chip then covers every pad over a
    range of poses where the energy is flat."""
    cw, ch = footprint_um(chip)
    x0, x1, y0, y1 = pattern.extent_um
    img = max(x1 - x0, y1 - y0)
    if min(cw, ch) <= LARGE_CHIP_RATIO * img:
        return None
    pw, ph = footprint_um(pattern)
    reach = (min(cw, ch) - max(pw, ph)) / 2
    return (
        f"the {cw:g} x {ch:g} um chip is {min(cw, ch) / img:.3g} times the pattern's whole image "
        f"({x1 - x0:g} x {y1 - y0:g} um): it covers every pad wherever it is within about {reach:.4g} um "
        "of the centre, where the energy is flat (a plateau: no restoring force, runs stop at once); "
        "check --chip-size (um) and the pattern's scale"
    )
