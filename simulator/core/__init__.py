"""The core every package stands on: units and reference constants, tolerances and the
numerical floor, finite-value checks, the defaults of the command line, and progress lines.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
