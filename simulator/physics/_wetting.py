"""Materials, liquid, chip body, damping and the closed-form checks of docs/physics.md.

Units (one convention for the whole module):

* SI inside and out for material constants: surface tension and surface energy in
  N/m (= J/m^2; water is 0.0728 N/m = 72.8 mN/m), viscosity in Pa s, density in
  kg/m^3, mass in kg, force in N, damping in N s/m (translation) and N m s
  (rotation), energy in J.
* Lengths in micrometres (um), areas in um^2, droplet volumes in nanolitres
  (1 nl = 1e6 um^3), as everywhere else in selfalign.
* Angles in degrees at every public boundary; radians only inside.

Wetting weights follow Young's equation (docs/physics.md section 2): covering a unit
area of solid with liquid changes the energy by ``gamma_wet = -gamma_LA cos(theta)``,
and the overlap model only needs the pad/substrate difference ``Delta_gamma``. The
overlap energy of a pose is ``E = Delta_gamma * A_ol`` (section 3.2); with
``Delta_gamma < 0`` minimum energy is maximum overlap.

Modules: this one holds the wetting side (Young weights, :class:`Materials`); the units
and reference constants are :mod:`simulator.core`; the liquid, the chip body,
damping and the parallelepiped formulas are :mod:`simulator.physics`. Every name is
importable from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from foundation import InputError, positive
from simulator.core import (
    UM2,
    WATER_SURFACE_TENSION_N_M,
)

# --------------------------------------------------------------------------- checks


def contact_angle_deg(name: str, value: float) -> float:
    """``value`` as a contact angle in degrees, checked to lie in [0, 180]; the error names ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number of degrees, got {value!r}") from None
    if not (0.0 <= v <= 180.0):
        raise InputError(f"{name} must be a contact angle in [0, 180] degrees, got {value!r}")
    return v


def _cos_deg(theta_deg: float) -> float:
    # Exact at the angles users type most (90 deg gives 0, not 6e-17).
    return 0.0 if theta_deg == 90.0 else math.cos(math.radians(theta_deg))


# --------------------------------------------------------------------- Young weights


def gamma_wet(theta_deg: float, gamma_la: float = WATER_SURFACE_TENSION_N_M) -> float:
    """Energy per unit area of wetting a solid, ``-gamma_LA cos(theta)`` (docs/physics.md §2).

    Args:
        theta_deg: static contact angle of the liquid on the solid, degrees in [0, 180].
        gamma_la: liquid/air surface tension, N/m.

    Returns:
        ``gamma_SL - gamma_SA`` in N/m (J/m^2), with the dry solid as zero.
    """
    return -positive("surface tension", gamma_la, "N/m") * _cos_deg(
        contact_angle_deg("contact angle", theta_deg)
    )


def delta_gamma(gamma_la: float, theta_pad_deg: float, theta_substrate_deg: float) -> float:
    """``Delta_gamma = gamma_p - gamma_s = gamma_LA (cos theta_s - cos theta_p)`` in N/m.

    Negative when the pad wets better than the substrate (``theta_p < theta_s``),
    which is the case where the overlap model pulls the chip onto the pad.
    Water at 30/60 degrees gives -0.02665 N/m (docs/physics.md C14).
    """
    g = positive("surface tension", gamma_la, "N/m")
    tp = contact_angle_deg("pad contact angle", theta_pad_deg)
    ts = contact_angle_deg("substrate contact angle", theta_substrate_deg)
    return g * (_cos_deg(ts) - _cos_deg(tp))


@dataclass(frozen=True)
class Materials:
    """Liquid surface tension and the pad and substrate contact angles.

    Frozen and hashable, so it can be a static argument. The mask grey level
    ``v`` in [0, 1] is *graded wettability*: a pixel of grey ``v`` has the energy
    weight ``v * Delta_gamma`` per unit area, which is the weight of a pad with
    ``cos(theta) = cos(theta_s) + v (cos(theta_p) - cos(theta_s))`` (linear in
    ``cos theta``, not in ``theta``; see :meth:`equivalent_angle_deg`).
    Anti-aliased edge pixels use the same rule, so for them ``v`` is the covered
    fraction of the pixel.

    Attributes:
        surface_tension_N_m: liquid/air surface tension, N/m (water 0.0728).
        pad_angle_deg: contact angle on the pad (white), degrees in [0, 180].
        substrate_angle_deg: contact angle on the substrate (black), degrees in [0, 180].
        allow_repulsive: accept ``Delta_gamma >= 0`` (pad no more wettable than the
            substrate). The overlap simulator then *minimises* overlap or feels no
            force (docs/physics.md C14), so it is rejected unless you ask for it.
    """

    surface_tension_N_m: float = WATER_SURFACE_TENSION_N_M
    pad_angle_deg: float = 30.0
    substrate_angle_deg: float = 60.0
    allow_repulsive: bool = False
    #: The pad's receding and advancing contact angles (degrees) for contact-angle
    #: hysteresis (:mod:`simulator.physics`); None = not given.
    pad_receding_deg: float | None = None
    pad_advancing_deg: float | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(
            self,
            "surface_tension_N_m",
            positive("surface tension", self.surface_tension_N_m, "N/m"),
        )
        set_(self, "pad_angle_deg", contact_angle_deg("pad contact angle", self.pad_angle_deg))
        set_(
            self,
            "substrate_angle_deg",
            contact_angle_deg("substrate contact angle", self.substrate_angle_deg),
        )
        if (self.pad_receding_deg is None) != (self.pad_advancing_deg is None):
            raise InputError(
                "give the pad's receding and advancing angles together (--hysteresis RECEDING:ADVANCING)"
            )
        if self.pad_receding_deg is not None and self.pad_advancing_deg is not None:  # both or none
            from simulator.physics._hysteresis import require_window

            r, a = require_window(self.pad_receding_deg, self.pad_advancing_deg)
            set_(self, "pad_receding_deg", r)
            set_(self, "pad_advancing_deg", a)
        if not isinstance(self.allow_repulsive, bool | np.bool_):
            raise InputError(f"allow_repulsive must be true or false, got {self.allow_repulsive!r}")
        set_(self, "allow_repulsive", bool(self.allow_repulsive))
        dg = self.delta_gamma_N_m
        if dg >= 0 and not self.allow_repulsive:
            raise InputError(
                f"pad contact angle {self.pad_angle_deg:g} deg must be smaller than substrate contact angle "
                f"{self.substrate_angle_deg:g} deg: Delta_gamma = {dg * 1e3:+.2f} mN/m >= 0 would push the chip "
                "off the pad; swap the angles, or pass allow_repulsive=True to study that case"
            )
        if dg == 0:
            raise InputError(
                f"pad and substrate contact angles give no wettability contrast (pad {self.pad_angle_deg:g} deg, substrate "
                f"{self.substrate_angle_deg:g} deg: Delta_gamma = 0), so the energy is zero at every pose and nothing aligns; "
                "give different angles"
            )

    @property
    def delta_gamma_N_m(self) -> float:
        """``gamma_LA (cos theta_s - cos theta_p)`` in N/m; < 0 for an attracting pad."""
        return delta_gamma(self.surface_tension_N_m, self.pad_angle_deg, self.substrate_angle_deg)

    @property
    def joules_per_um2(self) -> float:
        """Energy of one um^2 of overlap, ``Delta_gamma * UM2`` J (E = this * A_ol[um^2])."""
        return self.delta_gamma_N_m * UM2

    def weight(self, v: float | np.ndarray) -> float | np.ndarray:
        """Energy per unit area (N/m) of mask grey level ``v`` in [0, 1]: ``v * Delta_gamma``."""
        return (
            np.asarray(v) * self.delta_gamma_N_m if np.ndim(v) else float(v) * self.delta_gamma_N_m
        )

    def equivalent_angle_deg(self, v: float) -> float:
        """Contact angle (degrees) of a uniform pad with the weight of grey level ``v``.

        ``arccos(cos theta_s + v (cos theta_p - cos theta_s))``: 0 gives the substrate
        angle, 1 the pad angle.
        """
        v = float(v)
        if not (0.0 <= v <= 1.0):
            raise InputError(f"grey level must lie in [0, 1], got {v!r}")
        cs, cp = _cos_deg(self.substrate_angle_deg), _cos_deg(self.pad_angle_deg)
        return math.degrees(math.acos(min(1.0, max(-1.0, cs + v * (cp - cs)))))


__all__ = ["Materials", "delta_gamma", "gamma_wet"]
