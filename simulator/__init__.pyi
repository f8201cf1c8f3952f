"""Types of the names ``simulator`` loads on first use (``simulator/__init__.py``), for editors
and type checkers."""

from __future__ import annotations

from simulator.batch import (
    BatchResult,
    StartGrid,
    assess,
    capture_map,
    evaluate,
    random_starts,
    run_batch,
    run_realizations,
    summarize,
)
from simulator.core import (
    UM2,
)
from simulator.design import (
    calibrate,
    read_trials,
)
from simulator.landscape import (
    GlobalMinimum,
    Landscape,
    build_landscape,
    estimate_bytes,
    global_minimum,
)
from simulator.motion import (
    Trajectory,
    simulate,
)
from simulator.physics import (
    Liquid,
    Materials,
)
from simulator.render import (
    plot_capture_map,
    plot_energy_curve,
    plot_forces,
    plot_landscape,
    plot_pattern,
    pyplot,
    save_figure,
    write_trajectory_gif,
)
from simulator.scene import (
    PRESETS,
    Effects,
    Scene,
    TwistGrid,
    apply_preset,
    feature_warning,
    smallest_feature_um,
)
from simulator.sweep import (
    load_sweep,
    run_sweep,
)
from simulator.testing import (
    overlap_um2 as exact_overlap_um2,
)

__version__: str
__all__ = [
    "BatchResult",
    "Effects",
    "GlobalMinimum",
    "Landscape",
    "Liquid",
    "Materials",
    "PRESETS",
    "Scene",
    "StartGrid",
    "Trajectory",
    "TwistGrid",
    "UM2",
    "apply_preset",
    "assess",
    "build_landscape",
    "calibrate",
    "capture_map",
    "estimate_bytes",
    "evaluate",
    "exact_overlap_um2",
    "feature_warning",
    "global_minimum",
    "load_sweep",
    "plot_capture_map",
    "plot_energy_curve",
    "plot_forces",
    "plot_landscape",
    "plot_pattern",
    "pyplot",
    "random_starts",
    "read_trials",
    "run_batch",
    "run_realizations",
    "run_sweep",
    "save_figure",
    "simulate",
    "smallest_feature_um",
    "summarize",
    "write_trajectory_gif",
]
