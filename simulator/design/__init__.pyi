"""Types of ``simulator.design``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._mode import (
    design_mode as design_mode,
)
