"""Numeric tolerances shared by the host-side (numpy, float64) maths, named once.

Two kinds live here:

* floors against division by zero or the log of zero: :func:`tiny`, the smallest
  normal number of the dtype in play (float64 for host-side numpy maths), not a
  literal such as ``1e-30`` whose size means nothing;
* slack for round-off, where floats that should be equal (or a float ratio that
  should be a whole number) differ in the last bits: :data:`WHOLE_TOL`,
  :data:`REL_TOL`, :data:`DEG_TOL` and the helpers :func:`floor_whole`,
  :func:`ceil_whole`, :func:`is_whole`.

Why 1e-9 for the slack: a twist axis has at most 2^20 steps
(:data:`simulator.landscape.MAX_TWISTS`), and summing or scaling that many float64
steps accumulates at most about ``2^20 * eps = 2.3e-10`` of a step, below 1e-9; no
input is meant to be a fraction of a step, a degree or a value as small as 1e-9 (the
finest twist step is 1e-4 degrees). So the slack absorbs round-off and nothing else.
Physical or model tolerances (a fraction of an area, a solver's stopping rule) are
named where they are used, except :data:`AREA_REL_TOL`, which two modules share.

Imports only numpy and math: any module may use it.
"""

from __future__ import annotations

import math

import numpy as np

#: Slack, in units of one step, when a float ratio of a span and a step (or a fractional
#: grid index) should be a whole number: far above float64 round-off (about 2^20 * eps
#: = 2.3e-10 after the most steps an axis may have) and far below any real fraction of a step.
WHOLE_TOL = 1e-9
#: Relative slack when two float values should be equal up to round-off
#: (``a <= b * (1 + REL_TOL)``): same size and reasons as :data:`WHOLE_TOL`.
REL_TOL = 1e-9
#: Absolute slack (degrees) when two twists computed by different routes should be equal:
#: twists are at most a few hundred degrees (round-off ~ 360 * eps = 8e-14 per operation),
#: and the finest twist step is 1e-4 degrees.
DEG_TOL = 1e-9
#: Relative slack (fraction of a geometry's area) under which two exact geometries count as
#: the same shape: above the round-off of shapely's clipping, far below any real difference
#: of shape (a one-pixel notch on a 10 000 px chip is 1e-4).
AREA_REL_TOL = 1e-9


def tiny(dtype=float) -> float:
    """The smallest positive normal number of ``dtype`` (float64 by default): the floor of a
    divisor or a log's argument that is never zero and never bends a physical value."""
    return float(np.finfo(dtype).tiny)


def floor_whole(x) -> int:
    """``floor(x)``, with an ``x`` within :data:`WHOLE_TOL` below a whole number taken as that
    number (``span / step`` of 0.3 / 0.1 is 2.9999999999999996: 3, not 2)."""
    return int(math.floor(x + WHOLE_TOL))


def ceil_whole(x) -> int:
    """``ceil(x)``, with an ``x`` within :data:`WHOLE_TOL` above a whole number taken as that number."""
    return int(math.ceil(x - WHOLE_TOL))


def is_whole(x) -> bool:
    """Whether ``x`` is a whole number up to :data:`WHOLE_TOL` (e.g. a period / step ratio)."""
    return bool(abs(x - round(x)) < WHOLE_TOL)
