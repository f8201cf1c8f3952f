"""Types of ``foundation``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._errors import (
    InputError as InputError,
    positive as positive,
    require as require,
    require_regular_file as require_regular_file,
)
from ._finite import (
    require_finite as require_finite,
)
from ._hold import (
    hold as hold,
)
from ._outputs import (
    MARKER as MARKER,
    atomic_output as atomic_output,
    check_distinct as check_distinct,
    check_output_dir as check_output_dir,
    check_output_file as check_output_file,
    json_text as json_text,
    output_directory as output_directory,
    remove_pending as remove_pending,
    require_new_file as require_new_file,
    tree_listing as tree_listing,
)
from ._progress import (
    WAIT_ENV as WAIT_ENV,
    WAIT_S as WAIT_S,
    NoBar as NoBar,
    announce as announce,
    announce_once as announce_once,
    compiling as compiling,
    counter_bar as counter_bar,
    progress_bar as progress_bar,
    quiet_waits as quiet_waits,
    shows_wait as shows_wait,
    wait_line as wait_line,
    wait_threshold_s as wait_threshold_s,
)
from ._resources import (
    DEFAULT_BUDGET_CAP_MB as DEFAULT_BUDGET_CAP_MB,
    DEFAULT_MAX_IMAGE_MPX as DEFAULT_MAX_IMAGE_MPX,
    MB as MB,
    RASTER_BYTES_PER_PX as RASTER_BYTES_PER_PX,
    available_memory_bytes as available_memory_bytes,
    budget_bytes as budget_bytes,
    check_budget_mb as check_budget_mb,
    default_budget_mb as default_budget_mb,
    fmt_bytes as fmt_bytes,
    price_image as price_image,
    price_raster as price_raster,
    require_fits as require_fits,
)
