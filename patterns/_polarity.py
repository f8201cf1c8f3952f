"""Whether a pattern image looks drawn the wrong way round (the pad in black).

White marks the wettable pad (``_io``, :func:`~patterns.read_mask`). A drawing whose wettable area touches all
four borders of its image (the white is the background around dark pads), or covers more than
:data:`MOST_OF_IMAGE` of it (an all-white image, a pad drawn in black on a small white frame),
is most likely inverted: :func:`polarity_warning` says so in one line and suggests ``--invert``
(or dropping it when it was given). It is a warning, not a refusal: a pad cropped to its own
image is drawn that way on purpose.
"""

from __future__ import annotations

import numpy as np

from patterns.geometry import Mask

#: The share of the image, wettable, above which a pattern looks inverted (the library's
#: patterns cover at most 83 % of their images).
MOST_OF_IMAGE = 0.9


def polarity_warning(mask: Mask, inverted: bool = False, flag: str = "--invert") -> str | None:
    """One line when ``mask`` (a pattern image as read) looks inverted, else None.

    Wettable: pixels at least half covered. ``inverted``: the image was read with ``flag``
    (the warning then suggests dropping it)."""
    wet = mask.data >= 0.5
    share = float(wet.mean())
    borders = wet[0].any() and wet[-1].any() and wet[:, 0].any() and wet[:, -1].any()
    if not (borders or share > MOST_OF_IMAGE):
        return None
    why = (
        "touches all four image borders"
        + (f" and covers {share:.0%} of the image" if share > MOST_OF_IMAGE else "")
        if borders
        else f"covers {share:.0%} of the image"
    )
    fix = (
        f"read without {flag} if the pad is white"
        if inverted
        else f"give {flag} if the pad is drawn in black"
    )
    if not np.any(mask.data < 0.5):
        why = "covers the whole image (no substrate to align to)"
    return (
        f"the pattern's wettable (white) area {why}: is the drawing inverted? {fix} "
        "(white = wettable pad)"
    )
