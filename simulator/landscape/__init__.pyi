"""Types of ``simulator.landscape``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._build import (
    build_landscape as build_landscape,
    estimate_bytes as estimate_bytes,
    plan as plan,
    require_landscape_fits as require_landscape_fits,
    scene_extent as scene_extent,
)
from ._correlator import (
    Correlator as Correlator,
)
from ._fftsize import (
    Window as Window,
)
from ._footprint import (
    FootprintPlanes as FootprintPlanes,
    build_footprint_planes as build_footprint_planes,
    footprint_pairs as footprint_pairs,
    footprint_poses as footprint_poses,
)
from ._landscape import (
    MAX_CURVE_SAMPLES as MAX_CURVE_SAMPLES,
    Landscape as Landscape,
    runs as runs,
    trilinear as trilinear,
)
from ._optimum import (
    GlobalMinimum as GlobalMinimum,
    global_minimum as global_minimum,
    minimum_box as minimum_box,
    require_minimum_fits as require_minimum_fits,
)
from ._pathcost import (
    PathEnergy as PathEnergy,
    path_engine_supported as path_engine_supported,
)
from ._pathfoot import (
    FootprintPath as FootprintPath,
    footprint_path_bytes as footprint_path_bytes,
)
from ._posegrid import (
    PoseGrid as PoseGrid,
    axis_step as axis_step,
    consecutive_runs as consecutive_runs,
    twist_axis as twist_axis,
    twists_around as twists_around,
)
from ._refine import (
    refine_minimum as refine_minimum,
    stiffness as stiffness,
)
from ._symmetry import (
    chip_relations as chip_relations,
    correlate_stack as correlate_stack,
)
