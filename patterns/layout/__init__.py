"""Mask layouts (GDSII, OASIS, DXF) read as exact pattern geometry, and geometry written as
layouts (:func:`read_layout`, :func:`layout_geometry`, :func:`layout_masks`,
:func:`write_layout`). The rules (formats, cells, layers, units, merging, frame) are in
``patterns/layout/_read.py``'s notes and docs/guide/patterns.md.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
