"""Types of ``simulator.design``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._calibrate._fit import (
    DRAWS as DRAWS,
    PROFILE as PROFILE,
    TIME_SIGMA as TIME_SIGMA,
    TRIALS as TRIALS,
    calibrate as calibrate,
    log_likelihood as log_likelihood,
    synthetic_trials as synthetic_trials,
)
from ._calibrate._params import (
    FITTABLE as FITTABLE,
    Fittable as Fittable,
    parse_bounds as parse_bounds,
    parse_fit as parse_fit,
)
from ._calibrate._report import (
    scene_toml as scene_toml,
)
from ._calibrate._table import (
    BenchTable as BenchTable,
    read_trials as read_trials,
    write_trials as write_trials,
)
from ._freeform._density import (
    DensityMap as DensityMap,
    density_map as density_map,
    pattern_of as pattern_of,
    project as project,
)
from ._freeform._energy import (
    ChipSide as ChipSide,
    chip_side as chip_side,
    overlap_planes as overlap_planes,
)
from ._freeform._objectives import (
    Objective as Objective,
    make_objective as make_objective,
    softmin as softmin,
)
from ._freeform._report import (
    feature_check as feature_check,
    pattern_polygons as pattern_polygons,
    read_gds_polygons as read_gds_polygons,
)
from ._freeform._run import (
    FreeformResult as FreeformResult,
    Problem as Problem,
    clean_pattern as clean_pattern,
    freeform as freeform,
    make_problem as make_problem,
    orientation_gaps as orientation_gaps,
)
from ._freeform._spec import (
    FreeformSpec as FreeformSpec,
    load_freeform as load_freeform,
    price_freeform as price_freeform,
)
from ._mode import (
    design_mode as design_mode,
)
from ._search._run import (
    best_trials as best_trials,
    search as search,
)
from ._search._spec import (
    SAMPLERS as SAMPLERS,
    Constraint as Constraint,
    Expression as Expression,
    SearchSpec as SearchSpec,
    load_search as load_search,
    parse_constraints as parse_constraints,
    parse_expression as parse_expression,
)
