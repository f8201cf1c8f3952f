"""Types of ``simulator.render``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._animation import (
    TrajectoryAnimation as TrajectoryAnimation,
    chip_outline as chip_outline,
    frame_indices as frame_indices,
    write_trajectory_gif as write_trajectory_gif,
)
from ._figures import (
    plot_capture_map as plot_capture_map,
    plot_energy_curve as plot_energy_curve,
    plot_forces as plot_forces,
    plot_landscape as plot_landscape,
    plot_pattern as plot_pattern,
    plot_time_to_align as plot_time_to_align,
)
from ._style import (
    CHIP_COLOUR as CHIP_COLOUR,
    PATH_COLOUR as PATH_COLOUR,
    PLATEAU_COLOUR as PLATEAU_COLOUR,
    pyplot as pyplot,
    save_figure as save_figure,
)
