"""Choosing the droplet: meniscus height, overflow of protruding pads, critical volume, warnings.

Most failed self-alignments fail before any energy landscape matters: the drop splits
onto single pads, leaves a pad dry, or overflows the pad edge. This module holds the
calculators behind ``selfalign liquid`` and the checks the simulating commands run on
a ``--volume`` (:func:`scene_warnings`):

* :func:`height_report`: the flat-film meniscus height ``h = V / A`` (docs/physics.md §7)
  and whether the thin-film picture holds (``h`` against the chip's smallest side and
  the capillary length), with the parallelepiped meniscus' spring (C13);
* :func:`overflow_conditions` and :func:`overflow_report`: the no-overflow conditions
  (1)-(3) of docs/physics.md §9 for a protruding pad, over a range of chip angles;
* :func:`simulator.critical_volume.critical_volume`: the smallest drop that wets all four
  pads of a four-pad pattern (docs/physics.md §8), computed from a reduced drop model;
* :func:`four_pad_geometry`: a four-pad pattern recognised in any mask;
* :class:`Topography`: a protruding pad's edge angle and the angles the overflow check needs.

Units: lengths um, areas um^2, volumes nl (1 nl = 1e6 um^3), angles degrees, surface
tension N/m in Python (mN/m on the command line), forces N, stiffness N/m.

Modules: :mod:`simulator.liquid_calculators` (height, overflow, critical volume, the
numbers as typed) and :mod:`simulator.liquid_warnings` (the checks and warnings of a
scene); every name is importable from here.
"""

from __future__ import annotations

from simulator.liquid_calculators import (
    DEPENDS_ON_BIAS,
    THIN_FILM_FRACTION,
    OverflowConditions,
    Topography,
    capillary_length_um,
    check_surface_tension_mN_m,
    critical_volume_nl,
    dimensionless_volume,
    height_report,
    overflow_angle_deg,
    overflow_bias_um,
    overflow_conditions,
    overflow_report,
)
from simulator.liquid_calculators import DEPENDS_ON_CHIP_ANGLE as DEPENDS_ON_CHIP_ANGLE
from simulator.liquid_calculators import STANDARD_GRAVITY_M_S2 as STANDARD_GRAVITY_M_S2
from simulator.liquid_calculators import SURFACE_TENSION_RANGE_MN_M as SURFACE_TENSION_RANGE_MN_M
from simulator.liquid_warnings import (
    check_scene_volume,
    four_pad_geometry,
    pad_count,
    placement_biases,
    scene_warnings,
    volume_note,
)
from simulator.materials import meniscus_height_um as meniscus_height_um

__all__ = [
    "DEPENDS_ON_BIAS",
    "OverflowConditions",
    "THIN_FILM_FRACTION",
    "Topography",
    "capillary_length_um",
    "check_scene_volume",
    "check_surface_tension_mN_m",
    "critical_volume_nl",
    "dimensionless_volume",
    "four_pad_geometry",
    "height_report",
    "overflow_angle_deg",
    "overflow_bias_um",
    "overflow_conditions",
    "overflow_report",
    "pad_count",
    "placement_biases",
    "scene_warnings",
    "volume_note",
]
