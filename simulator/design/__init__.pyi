"""Types of ``simulator.design``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._mode import (
    design_mode as design_mode,
)
from ._search import (
    best_trials as best_trials,
    search as search,
)
from ._search_spec import (
    SAMPLERS as SAMPLERS,
    Constraint as Constraint,
    Expression as Expression,
    SearchSpec as SearchSpec,
    load_search as load_search,
    parse_constraints as parse_constraints,
    parse_expression as parse_expression,
)
