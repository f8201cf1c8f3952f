"""Design search: which alignment pattern to make, and the model fitted to a bench.

Two modes of ``selfalign design``: a search over a generated design's parameters (Optuna
trials run on Dask as sweep points are, :func:`search`), and a free-form pattern on the
pixel grid optimised by gradients through the JAX landscape (:func:`freeform`). Both
check their result with the evaluator against a baseline.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
