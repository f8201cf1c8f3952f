"""Design sweeps: the sweep file (spec and axes), a point and its task (frozen), one point's
evaluation, the Dask cluster, the resumable result store, its columns, and the report;
:func:`run_sweep` runs one.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
