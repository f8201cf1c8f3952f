"""The physics a scene can declare: wetting weights (Young), the liquid and the chip body
(mechanics, damping), the finite meniscus, and contact-angle hysteresis (docs/physics.md §2-§5).
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
