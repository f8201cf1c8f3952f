"""selfalign simulator: energy landscapes, trajectories and yields of capillary self-alignment.

The names users call are importable from here (``from simulator import Scene,
build_landscape, simulate``); each is loaded on first use, so ``import simulator``
is fast and imports neither JAX nor matplotlib. ``simulator/__init__.pyi`` declares their
types for editors and is their one list: each name is loaded from the package its stub line
names (:func:`_exports`). The packages behind them are the folders of ``simulator/``,
described in ``docs/architecture.md``; each package's ``__init__`` is its public face.

JAX: importing this package, or any of its modules, changes no JAX setting. The
first stepper run (:func:`simulator.motion.make_field`, which every trajectory and
batch goes through) and the GPU correlator switch on ``jax_enable_x64``, so that a
float64 landscape stays float64; float32 landscapes still compute in float32.
"""

from __future__ import annotations

import importlib
import os


def _read_stub() -> dict[str, str]:
    """Public name -> the package that defines it ("package:name" where the name differs),
    from the ``from simulator.PACKAGE import ...`` lines of ``__init__.pyi``."""
    import ast

    path = os.path.join(os.path.dirname(__file__), "__init__.pyi")
    with open(path, encoding="utf-8") as f:
        tree = ast.parse(f.read(), path)
    out = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("simulator."):
            for alias in node.names:
                name = alias.asname or alias.name
                out[name] = node.module if name == alias.name else f"{node.module}:{alias.name}"
    return out


def _exports() -> dict[str, str]:
    """The top-level names, read from the stub on first use: the stub is their one list.

    Read then, not at import: importing :mod:`ast` and parsing the stub take about 3 ms,
    several times what ``import simulator`` takes without them, and every ``selfalign``
    command imports this package. Sets ``_EXPORTS`` (name -> "package" or "package:name")
    and ``__all__``."""
    exports = globals().get("_EXPORTS")
    if exports is None:
        exports = globals()["_EXPORTS"] = _read_stub()
        globals()["__all__"] = sorted(exports)
    return exports


def _version() -> str:
    """The installed distribution's version, read on first use of ``__version__`` (reading
    the package metadata costs 0.05 s that every command would pay at start-up)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("selfalign")
    except PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"


def __getattr__(name: str):
    if name == "__version__":
        value = globals()[name] = _version()
        return value
    if name in ("_EXPORTS", "__all__"):
        _exports()
        return globals()[name]
    where = _exports().get(name)
    if where is None:
        raise AttributeError(f"module 'simulator' has no attribute {name!r}")
    module, _, attr = where.partition(":")
    value = getattr(importlib.import_module(module), attr or name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_exports()) | {"__all__", "__version__"})
