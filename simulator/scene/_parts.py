"""The small frozen records a :class:`~simulator.scene.Scene` holds besides its masks and materials.

Owns :class:`TwistGrid` (the twists of the pose grid: step and range, one symmetry period
of the chip by default) and :class:`Effects` (the physics the scene calls for: twist, the
finite meniscus, contact-angle hysteresis), each validated at construction. Both are
importable from :mod:`simulator.scene` as before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from foundation import InputError, positive, require
from simulator.core import MAX_TWIST_DEG


@dataclass(frozen=True)
class TwistGrid:
    """Twists on the pose grid, in degrees (CCW positive).

    ``min_deg``/``max_deg`` of None mean one full rotational-symmetry period of the
    chip, centred on zero (e.g. [-45, 45) for a square chip, [-90, 90) for a
    rectangle), which the steppers treat as periodic.
    """

    step_deg: float = 1.0
    min_deg: float | None = None
    max_deg: float | None = None

    def __post_init__(self) -> None:
        positive("twist step_deg", self.step_deg, "degrees")
        require(self.step_deg <= 90, f"twist step_deg must be <= 90 degrees, got {self.step_deg}")
        if (self.min_deg is None) != (self.max_deg is None):
            raise InputError("twist min_deg and max_deg must be given together (or neither)")
        if self.min_deg is not None and self.max_deg is not None:  # both or neither (above)
            for name, v in (("min_deg", self.min_deg), ("max_deg", self.max_deg)):
                require(
                    math.isfinite(v) and abs(v) <= MAX_TWIST_DEG,
                    f"twist {name} must be a finite angle within +-{MAX_TWIST_DEG} degrees, got {v}",
                )
            require(
                self.max_deg >= self.min_deg,
                f"twist max_deg ({self.max_deg}) must be >= min_deg ({self.min_deg})",
            )


@dataclass(frozen=True)
class Effects:
    """The physics a scene calls for; the engine computes nothing else.

    twist: rotate the chip (False: one rotation, twist fixed at 0).
    hysteresis: contact-angle hysteresis of the pad (``materials.pad_receding_deg`` /
        ``pad_advancing_deg``): the steppers stop where the restoring force falls below
        the contact lines' pinning force (:mod:`simulator.physics`).
    meniscus: a liquid of finite height (:mod:`simulator.physics`): every cusp of the
        overlap energy rounded over the meniscus height (False: the overlap model, h -> 0).
    """

    twist: bool = True
    meniscus: bool = False
    hysteresis: bool = False

    def __post_init__(self) -> None:
        for name in ("twist", "meniscus", "hysteresis"):
            if not isinstance(getattr(self, name), bool | np.bool_):
                raise InputError(
                    f"effects {name} must be true or false, got {getattr(self, name)!r}"
                )
