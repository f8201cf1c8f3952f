"""Types of ``patterns.layout``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._formats import (
    DEFAULT_MAX_POLYGONS as DEFAULT_MAX_POLYGONS,
    DXF_UNITS as DXF_UNITS,
    SUFFIXES as SUFFIXES,
    LayoutSelection as LayoutSelection,
    is_layout as is_layout,
    layout_format as layout_format,
)
from ._read import (
    DEFAULT_UM_PER_PX as DEFAULT_UM_PER_PX,
    frame_note as frame_note,
    layout_chip_mask as layout_chip_mask,
    layout_geometry as layout_geometry,
    layout_masks as layout_masks,
    read_layout as read_layout,
)
from ._write import (
    WRITE_DXF_LAYER as WRITE_DXF_LAYER,
    WRITE_LAYER as WRITE_LAYER,
    snap as snap,
    write_layout as write_layout,
)
