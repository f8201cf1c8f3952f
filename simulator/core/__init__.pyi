"""Types of ``simulator.core``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._constants import (
    SU8_DENSITY_KG_M3 as SU8_DENSITY_KG_M3,
    UM as UM,
    UM2 as UM2,
    UM3_PER_NL as UM3_PER_NL,
    WATER_DENSITY_KG_M3 as WATER_DENSITY_KG_M3,
    WATER_SURFACE_TENSION_N_M as WATER_SURFACE_TENSION_N_M,
    WATER_VISCOSITY_PA_S as WATER_VISCOSITY_PA_S,
)
from ._defaults import (
    AUTO_LANDSCAPE_MB as AUTO_LANDSCAPE_MB,
    BATCH_METHODS as BATCH_METHODS,
    DEFAULT_CHUNK as DEFAULT_CHUNK,
    DEFAULT_DYNAMICS_CHUNK as DEFAULT_DYNAMICS_CHUNK,
    DEFAULT_MAX_STEPS as DEFAULT_MAX_STEPS,
    DISTRIBUTIONS as DISTRIBUTIONS,
    DYNAMIC_METHODS as DYNAMIC_METHODS,
    FOOTPRINT_CHUNK as FOOTPRINT_CHUNK,
    MAX_CHUNK as MAX_CHUNK,
    MAX_STARTS as MAX_STARTS,
    MAX_STEPS_LIMIT as MAX_STEPS_LIMIT,
    MAX_TWIST_DEG as MAX_TWIST_DEG,
    METHODS as METHODS,
    OUTCOMES as OUTCOMES,
    THREADS_ENV as THREADS_ENV,
    threads as threads,
)
from ._tolerances import (
    AREA_REL_TOL as AREA_REL_TOL,
    DEG_TOL as DEG_TOL,
    REL_TOL as REL_TOL,
    WHOLE_TOL as WHOLE_TOL,
    ceil_whole as ceil_whole,
    floor_whole as floor_whole,
    is_whole as is_whole,
    tiny as tiny,
)
