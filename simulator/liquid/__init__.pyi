"""Types of ``simulator.liquid``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._calculators import (
    DEPENDS_ON_BIAS as DEPENDS_ON_BIAS,
    DEPENDS_ON_CHIP_ANGLE as DEPENDS_ON_CHIP_ANGLE,
    STANDARD_GRAVITY_M_S2 as STANDARD_GRAVITY_M_S2,
    SURFACE_TENSION_RANGE_MN_M as SURFACE_TENSION_RANGE_MN_M,
    THIN_FILM_FRACTION as THIN_FILM_FRACTION,
    OverflowConditions as OverflowConditions,
    Topography as Topography,
    capillary_length_um as capillary_length_um,
    check_surface_tension_mN_m as check_surface_tension_mN_m,
    critical_volume_nl as critical_volume_nl,
    dimensionless_volume as dimensionless_volume,
    height_report as height_report,
    overflow_angle_deg as overflow_angle_deg,
    overflow_bias_um as overflow_bias_um,
    overflow_conditions as overflow_conditions,
    overflow_report as overflow_report,
)
from ._critical_volume import (
    GRID_POINTS as GRID_POINTS,
    FourPad as FourPad,
    cap_angle_deg as cap_angle_deg,
    cap_area_um2 as cap_area_um2,
    cap_height_um as cap_height_um,
    critical_volume as critical_volume,
    free_cap_base_um2 as free_cap_base_um2,
    min_plus as min_plus,
    minimise_footprint as minimise_footprint,
)
from ._dispense import (
    dispensed_footprint as dispensed_footprint,
    dispensed_wet as dispensed_wet,
)
from ._warnings import (
    check_scene_volume as check_scene_volume,
    four_pad_geometry as four_pad_geometry,
    pad_count as pad_count,
    placement_biases as placement_biases,
    require_film as require_film,
    scene_critical_volume as scene_critical_volume,
    scene_warnings as scene_warnings,
    volume_note as volume_note,
)
from ._window import (
    DEFAULT_FILM_FRACTION as DEFAULT_FILM_FRACTION,
    default_volume_nl as default_volume_nl,
    volume_window as volume_window,
    window_lines as window_lines,
)
