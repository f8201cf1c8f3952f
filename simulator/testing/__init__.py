"""Exact references for tests and accuracy studies: the overlap area of polygons, computed
exactly (no raster), and the trajectories it implies.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
