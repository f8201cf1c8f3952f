"""The energy landscape E(x, y, twist): the pose grid, the chip's rotations, the FFT correlator,
the build (plan and memory budget), the :class:`Landscape` and its queries, sub-cell refinement,
and the global optimum with its overlap bound.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
