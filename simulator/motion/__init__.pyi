"""Types of ``simulator.motion``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._accuracy import (
    LIMITS as LIMITS,
    error_limit as error_limit,
    error_limit_words as error_limit_words,
    floats as floats,
    floor_reach_um as floor_reach_um,
    refined_limit_um as refined_limit_um,
)
from ._cost import (
    RunCost as RunCost,
)
from ._dynamics import (
    DynamicsState as DynamicsState,
    inertial as inertial,
    overdamped as overdamped,
)
from ._dynamics_ode import (
    MOREAU_TOL as MOREAU_TOL,
    REST_TOL_STEPS as REST_TOL_STEPS,
    MoreauJean as MoreauJean,
)
from ._dynamics_params import (
    DynamicsParams as DynamicsParams,
    dissipation as dissipation,
)
from ._field import (
    PAD as PAD,
    Field as Field,
    Relay as Relay,
    block as block,
    field_and_grid as field_and_grid,
    gradient as gradient,
    interior as interior,
    interpolate as interpolate,
    lookup as lookup,
    make_field as make_field,
    neighbourhood as neighbourhood,
    padded_buffer as padded_buffer,
    relay_changes as relay_changes,
)
from ._footprint_run import (
    MAX_EVENTS as MAX_EVENTS,
    WINDOW_DEG as WINDOW_DEG,
    WINDOW_MARGIN_STEPS as WINDOW_MARGIN_STEPS,
    footprint_budget_bytes as footprint_budget_bytes,
    footprint_engine as footprint_engine,
    footprint_relay as footprint_relay,
    footprint_words as footprint_words,
    remaining_params as remaining_params,
    require_footprint_fits as require_footprint_fits,
    twist_window as twist_window,
    wet_bits as wet_bits,
    window_sides as window_sides,
)
from ._pathrun import (
    ENGINES as ENGINES,
    StateBoxes as StateBoxes,
    choose_engine as choose_engine,
)
from ._pinning import (
    PinLines as PinLines,
    pin_at as pin_at,
    pin_lines as pin_lines,
    soft_threshold as soft_threshold,
)
from ._potential import (
    potential as potential,
    potential_and_gradient as potential_and_gradient,
)
from ._pricing import (
    RunPlan as RunPlan,
    plan_run as plan_run,
    price_run as price_run,
    require_run_fits as require_run_fits,
    require_start_in_window as require_start_in_window,
)
from ._steppers import (
    dynamics_jitted as dynamics_jitted,
    finish as finish,
    stepper as stepper,
)
from ._stepping import (
    BLOCK_MOVES as BLOCK_MOVES,
    CONVERGED as CONVERGED,
    EDGE as EDGE,
    EVENT as EVENT,
    GREEDY_MOVES as GREEDY_MOVES,
    MAX_STEPS as MAX_STEPS,
    STAY as STAY,
    TIE_RANK as TIE_RANK,
    classify as classify,
    gradient_descent as gradient_descent,
    greedy as greedy,
    on_plateau as on_plateau,
    reference_gradient as reference_gradient,
)
from ._trajectory import (
    Trajectory as Trajectory,
    is_stiff as is_stiff,
    radius_of_gyration_px as radius_of_gyration_px,
    simulate as simulate,
)
