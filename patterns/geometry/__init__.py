"""Exact pattern geometry and its rasters: shapely polygons in micrometres, centred on the
nominal pattern, and :class:`Mask`, an image in [0, 1] with its pixel size.

The ideal shapes (:func:`square`, :func:`four_pad`, ...), the defect and jagged designs
(:func:`defect`, :func:`random_jagged`, ...), the registry of named designs
(:data:`DESIGNS`, :func:`build`, :func:`design_record`), and the exact-coverage raster
(:func:`mask_from_geometry`, :func:`rasterize`). Conventions: docs/physics.md §1.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
