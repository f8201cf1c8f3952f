"""Pictures: pattern and landscape plots, force and energy curves, capture maps, trajectory
GIFs, and the house style.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
