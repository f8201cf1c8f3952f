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
* :func:`simulator.liquid.critical_volume`: the smallest drop that wets all four
  pads of a four-pad pattern (docs/physics.md §8), computed from a reduced drop model;
* :func:`four_pad_geometry`: a four-pad pattern recognised in any mask;
* :class:`Topography`: a protruding pad's edge angle and the angles the overflow check needs;
* :func:`volume_window`: the usable droplet volumes of a scene (critical volume, thin-film
  and overflow limits), and :func:`default_volume_nl`, the volume a scene that gives none takes.

Units: lengths um, areas um^2, volumes nl (1 nl = 1e6 um^3), angles degrees, surface
tension N/m in Python (mN/m on the command line), forces N, stiffness N/m.

Internals: ``_calculators`` (height, overflow, the numbers as typed), ``_critical_volume``
(the reduced drop model) and ``_warnings`` (the checks and warnings of a scene), ``_window`` (the volume window and the
default volume); every
name is imported from here.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
