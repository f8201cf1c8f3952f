"""selfalign simulator: energy landscapes, trajectories and yields of capillary self-alignment.

The names users call are importable from here (``from simulator import Scene,
build_landscape, simulate``); each is loaded on first use, so ``import simulator``
is fast and imports neither JAX nor matplotlib. ``simulator/__init__.pyi`` declares their
types for editors. The packages behind them (``simulator.core``, ``.scene``, ``.physics``,
``.liquid``, ``.landscape``, ``.motion``, ``.batch``, ``.sweep``, ``.render``, ``.testing``)
are described in ``docs/architecture.md``; each package's ``__init__`` is its public face.

JAX: importing this package, or any of its modules, changes no JAX setting. The
first stepper run (:func:`simulator.motion.make_field`, which every trajectory and
batch goes through) and the GPU correlator switch on ``jax_enable_x64``, so that a
float64 landscape stays float64; float32 landscapes still compute in float32.
"""

from __future__ import annotations

import importlib

#: Public name -> the module that defines it ("module:name" where the name differs).
_EXPORTS = {
    # what to simulate
    "Scene": "simulator.scene",
    "TwistGrid": "simulator.scene",
    "Effects": "simulator.scene",
    "Materials": "simulator.physics",
    "Liquid": "simulator.physics",
    "UM2": "simulator.core",
    # the energy landscape
    "build_landscape": "simulator.landscape",
    "estimate_bytes": "simulator.landscape",
    "Landscape": "simulator.landscape",
    "global_minimum": "simulator.landscape",
    "GlobalMinimum": "simulator.landscape",
    # trajectories and batches
    "simulate": "simulator.motion",
    "Trajectory": "simulator.motion",
    "run_batch": "simulator.batch",
    "StartGrid": "simulator.batch",
    "random_starts": "simulator.batch",
    "summarize": "simulator.batch",
    "capture_map": "simulator.batch",
    "run_realizations": "simulator.batch",
    "BatchResult": "simulator.batch",
    # assessment and accuracy
    "evaluate": "simulator.batch",
    "assess": "simulator.batch",
    "exact_overlap_um2": "simulator.testing:overlap_um2",
    "PRESETS": "simulator.scene",
    "apply_preset": "simulator.scene",
    "feature_warning": "simulator.scene",
    "smallest_feature_um": "simulator.scene",
    # design sweeps
    "run_sweep": "simulator.sweep",
    "load_sweep": "simulator.sweep",
    # the model fitted to a bench
    "calibrate": "simulator.design",
    "read_trials": "simulator.design",
    # pictures
    "plot_pattern": "simulator.render",
    "plot_landscape": "simulator.render",
    "plot_forces": "simulator.render",
    "plot_energy_curve": "simulator.render",
    "plot_capture_map": "simulator.render",
    "write_trajectory_gif": "simulator.render",
    "save_figure": "simulator.render",
    "pyplot": "simulator.render",
}

__all__ = sorted(_EXPORTS)


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
    where = _EXPORTS.get(name)
    if where is None:
        raise AttributeError(f"module 'simulator' has no attribute {name!r}")
    module, _, attr = where.partition(":")
    value = getattr(importlib.import_module(module), attr or name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS) | {"__version__"})
