"""Types of ``patterns.geometry``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._defects import (
    DEFECT_TYPES as DEFECT_TYPES,
    constant_jagged as constant_jagged,
    defect as defect,
    defect_type as defect_type,
    random_jagged as random_jagged,
)
from ._designs import (
    DESIGNS as DESIGNS,
    REQUIRED as REQUIRED,
    Design as Design,
    build as build,
    design_record as design_record,
)
from ._mask import (
    Mask as Mask,
    default_chip_um as default_chip_um,
    footprint_um as footprint_um,
    nonzero_box as nonzero_box,
    pad_labels as pad_labels,
)
from ._raster import (
    canvas_shape as canvas_shape,
    coverage_steps as coverage_steps,
    mask_from_geometry as mask_from_geometry,
    rasterize as rasterize,
    to_pixel_frame as to_pixel_frame,
)
from ._shapes import (
    circle as circle,
    four_pad as four_pad,
    polygon as polygon,
    rectangle as rectangle,
    rotate_quarter as rotate_quarter,
    square as square,
)
