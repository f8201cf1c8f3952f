"""Types of ``patterns``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._io import (
    CHANNELS as CHANNELS,
    TEXT_KEY as TEXT_KEY,
    read_mask as read_mask,
    write_mask as write_mask,
)
from ._metadata import (
    MAX_PARAMS_CHARS as MAX_PARAMS_CHARS,
    MAX_PARAMS_DEPTH as MAX_PARAMS_DEPTH,
    MAX_PARAMS_ITEMS as MAX_PARAMS_ITEMS,
    check_nesting as check_nesting,
    parse_png_params as parse_png_params,
    show_key as show_key,
    show_value as show_value,
    validate_png_params as validate_png_params,
)
from ._polarity import (
    polarity_warning as polarity_warning,
)
