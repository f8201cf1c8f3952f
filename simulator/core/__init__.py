"""The simulator's core: units and reference constants, tolerances and the numerical floor,
and the defaults of the command line. The project's plumbing (errors, outputs, resources,
finite-value checks, progress lines) is the ``foundation`` package below it.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
