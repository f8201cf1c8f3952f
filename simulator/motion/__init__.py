"""Motion on a landscape: the force field, the greedy and gradient steps, the overdamped and
inertial dynamics (docs/physics.md §4-§5), and the :class:`Trajectory` of one start.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
