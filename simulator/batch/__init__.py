"""Many starts at once: start grids and placement noise, Monte Carlo batches and realizations,
their statistics, and the evaluation of a pattern (capture map, yield, stiffness).
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
