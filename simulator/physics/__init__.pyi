"""Types of ``simulator.physics``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._footprint import (
    DEFAULT_DISPENSE as DEFAULT_DISPENSE,
    DISPENSE as DISPENSE,
    DISPENSE_CHOICES as DISPENSE_CHOICES,
    SHADOW_STEP_DEG as SHADOW_STEP_DEG,
    STEP_PX as STEP_PX,
    TOUCH_PX2 as TOUCH_PX2,
    FootprintRules as FootprintRules,
    StepProfile as StepProfile,
    cap_radius_um as cap_radius_um,
    ray_coordinates as ray_coordinates,
    relay as relay,
    shadow_residual_deg as shadow_residual_deg,
    upstream_along as upstream_along,
    upstream_of as upstream_of,
)
from ._hysteresis import (
    align_tolerance as align_tolerance,
    contact_line_integrals_um as contact_line_integrals_um,
    line_dissipation_integrals_um as line_dissipation_integrals_um,
    line_reach_um as line_reach_um,
    parse_window as parse_window,
    pin_per_index as pin_per_index,
    pinning as pinning,
    pinning_force_per_length as pinning_force_per_length,
    pinning_lines as pinning_lines,
    sliding_pinning as sliding_pinning,
    sliding_pinning_at as sliding_pinning_at,
    sliding_shares as sliding_shares,
)
from ._mechanics import (
    DAMPING_CALIBRATION as DAMPING_CALIBRATION,
    LINE_FRICTION_PA_S as LINE_FRICTION_PA_S,
    WEDGE_CUTOFF_NM as WEDGE_CUTOFF_NM,
    Chip as Chip,
    Liquid as Liquid,
    couette_damping as couette_damping,
    couette_rotational_damping as couette_rotational_damping,
    couette_torsional_damping as couette_torsional_damping,
    dissipation_terms as dissipation_terms,
    meniscus_height_um as meniscus_height_um,
    parallelepiped_force as parallelepiped_force,
    parallelepiped_stiffness as parallelepiped_stiffness,
    stokes_layer_factor as stokes_layer_factor,
    wedge_friction_Pa_s as wedge_friction_Pa_s,
)
from ._meniscus import (
    CHIP_BLUR_MIN_PX as CHIP_BLUR_MIN_PX,
    WallProfile as WallProfile,
    flat_wall_energy_J as flat_wall_energy_J,
    flat_wall_stiffness_N_m as flat_wall_stiffness_N_m,
    flat_wall_twist_stiffness_Nm as flat_wall_twist_stiffness_Nm,
    kernel_image as kernel_image,
    kernel_spectrum as kernel_spectrum,
    margin_px as margin_px,
    regime_warning as regime_warning,
    require_height as require_height,
    signed_distance_px as signed_distance_px,
)
from ._reach import (
    ArcWall as ArcWall,
    FreeBridge as FreeBridge,
    arc_wall as arc_wall,
    curved_reaches as curved_reaches,
    free_bridge as free_bridge,
)
from ._wetting import (
    Materials as Materials,
    contact_angle_deg as contact_angle_deg,
    delta_gamma as delta_gamma,
    gamma_wet as gamma_wet,
)
