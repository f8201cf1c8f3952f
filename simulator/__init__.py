"""selfalign simulator: energy landscapes, trajectories and yields of capillary self-alignment.

The names users call are importable from here (``from simulator import Scene,
build_landscape, simulate``); each is loaded on first use, so ``import simulator``
is fast and imports neither JAX nor matplotlib. See ``docs/architecture.md`` for the
modules behind them.

JAX: importing this package, or any of its modules, changes no JAX setting. The
first stepper run (:func:`simulator.stepping.make_field`, which every trajectory and
batch goes through) and the GPU correlator switch on ``jax_enable_x64``, so that a
float64 landscape stays float64; float32 landscapes still compute in float32.
"""

from __future__ import annotations

import importlib

#: Public name -> the module that defines it ("module:name" where the name differs).
_EXPORTS = {
    # what to simulate
    "Scene": "simulator.scene", "TwistGrid": "simulator.scene", "Effects": "simulator.scene",
    "Materials": "simulator.materials", "Liquid": "simulator.materials", "UM2": "simulator.materials",
    # the energy landscape
    "build_landscape": "simulator.engine", "estimate_bytes": "simulator.engine", "Landscape": "simulator.landscape",
    "global_minimum": "simulator.optimum", "GlobalMinimum": "simulator.optimum",
    # trajectories and batches
    "simulate": "simulator.trajectory", "Trajectory": "simulator.trajectory",
    "run_batch": "simulator.montecarlo", "StartGrid": "simulator.montecarlo", "random_starts": "simulator.montecarlo",
    "summarize": "simulator.montecarlo", "capture_map": "simulator.montecarlo", "run_realizations": "simulator.montecarlo",
    "BatchResult": "simulator.montecarlo",
    # assessment and accuracy
    "evaluate": "simulator.evaluate", "assess": "simulator.evaluate", "exact_overlap_um2": "simulator.reference:overlap_um2",
    "PRESETS": "simulator.accuracy", "apply_preset": "simulator.accuracy", "feature_warning": "simulator.accuracy",
    "smallest_feature_um": "simulator.accuracy",
    # design sweeps
    "sweep": "simulator.sweep", "load_sweep": "simulator.sweep",
    # pictures
    "plot_pattern": "simulator.render", "plot_landscape": "simulator.render", "plot_forces": "simulator.render",
    "plot_energy_curve": "simulator.render", "plot_capture_map": "simulator.render", "write_trajectory_gif": "simulator.render",
    "save_figure": "simulator.render", "pyplot": "simulator.render",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    where = _EXPORTS.get(name)
    if where is None:
        raise AttributeError(f"module 'simulator' has no attribute {name!r}")
    module, _, attr = where.partition(":")
    value = getattr(importlib.import_module(module), attr or name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
