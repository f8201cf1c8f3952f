"""selfalign patterns: the alignment patterns and chips as images and exact geometry.

* :mod:`patterns.geometry`: exact shapes in micrometres (the design registry, defects and
  jagged edges), their rasters, and :class:`~patterns.geometry.Mask`, the image with its
  scale that every scene is made of;
* :mod:`patterns.layout`: GDSII, OASIS and DXF layouts read as exact geometry and written;
* here: reading and writing PNG masks (:func:`read_mask`, :func:`write_mask`), the
  parameters a generated PNG stores (:func:`parse_png_params`), and the check of an image
  that looks inverted (:func:`polarity_warning`);
* :mod:`patterns.library`: the bundled pattern library (``python -m patterns.library``).
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
