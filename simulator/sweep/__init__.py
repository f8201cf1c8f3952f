"""Design sweeps: the sweep file (spec and axes), one point's evaluation, the Dask cluster,
the resumable result store, its columns, and the report.
"""

import sys
import types
from typing import Any

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)


class _CallableModule(types.ModuleType):
    """``simulator.sweep(...)`` works whether ``simulator.sweep`` is this package or its function."""

    def __call__(self, *args: Any, **kwargs: Any):
        return __getattr__("sweep")(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
