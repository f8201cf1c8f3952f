"""Parameters of the time-resolved dynamics (:mod:`simulator.motion`): mass, damping and
tolerances from the scene's chip and liquid, in SI units.

The model (docs/physics.md §4): the chip slides on a film of height ``h = V / A`` (droplet
volume over the chip's wetted footprint; the meniscus height when one is given, the same
height the finite meniscus's energy uses) held on its edges.

* mass ``m`` and moment ``I`` of the chip's body (footprint extruded to its thickness and
  density). The liquid the Couette profile carries along, ``rho_l A h / 3`` and
  ``rho_l J h / 3`` (:func:`simulator.physics.couette_added_mass_kg`, a fifth of a 730 um
  chip's mass at 20 nl), is left out for now: in the calibrated, overdamped motion it
  changes the times by well under 1 %, and adding it moved a float64 inertial run on the
  overlap four-pad (tests/test_robustness.py) into the explicit solver's step-size
  trouble, to be added once that is fixed;
* damping ``c = k mu A / h`` and ``c_t = k mu J / h``: the Couette drag of the film times the
  calibration ``k`` (:data:`simulator.physics.DAMPING_CALIBRATION`, 600, fitted to the
  source's video of a 730 um chip on 20 nl; what the factor stands for, the other
  dissipation estimated term by term and the fit are documented there).

J is the footprint's polar moment about the chip centre. The same factor multiplies both
dampings: the moving contact lines, the largest term besides the film, have the film's
twist-to-shift ratio ``J / A`` on a square.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from patterns.errors import InputError, positive
from simulator.core import UM, UM2
from simulator.physics import (
    DAMPING_CALIBRATION,
    Chip,
    Liquid,
    couette_damping,
    couette_torsional_damping,
)

#: Thinnest liquid film (um) the dynamics accept: 1e-6 nm. Real films are nm or more thick
#: (the Couette model itself needs a continuum liquid); much below this the damping
#: coefficient overflows the solver's float32 arithmetic (NaN times near 1e-30 um).
MIN_FILM_UM = 1e-9


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class DynamicsParams:
    """Mass, inertia and damping of the chip, in SI (a pytree: values may be traced).

    Attributes:
        mass_kg: chip mass m (inertial model only).
        inertia_kg_m2: moment of inertia I about the vertical axis (inertial model only).
        damping_N_s_m: translational damping c, N s/m.
        rot_damping_N_m_s: rotational damping c_t, N m s (per radian per second).
        t_max_s: the run stops (status MAX_STEPS) at this time, s.

    Build from materials with :meth:`from_physics`. Values given as Python numbers are
    checked here; traced values (under jit/vmap) are not.
    """

    mass_kg: float
    inertia_kg_m2: float
    damping_N_s_m: float
    rot_damping_N_m_s: float
    t_max_s: float = 1.0

    def __post_init__(self) -> None:
        units = {
            "mass_kg": "kg",
            "inertia_kg_m2": "kg m^2",
            "damping_N_s_m": "N s/m",
            "rot_damping_N_m_s": "N m s",
            "t_max_s": "s",
        }
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool):
                object.__setattr__(self, f.name, positive(f.name, v, units[f.name]))

    @classmethod
    def from_physics(
        cls,
        chip: Chip,
        liquid: Liquid,
        wetted_area_um2: float | None = None,
        calibration: float = DAMPING_CALIBRATION,
        t_max_s: float = 1.0,
        polar_moment_um4: float | None = None,
    ) -> DynamicsParams:
        """Couette damping of the liquid film under a rigid chip (docs/physics.md §4, §7).

        ``h = V / A`` (flat slab; the liquid's ``height_um`` when given), ``c = calibration * mu A / h`` and
        ``c_t = calibration * mu J / h``; mass and inertia of the chip's cuboid body (the
        liquid's added mass is left out: module docstring).

        Args:
            chip: the chip body (mass, moment of inertia, footprint).
            liquid: viscosity and droplet volume.
            wetted_area_um2: area A of the liquid film, um^2 (default: the chip footprint).
            calibration: multiplier on both Couette values; the default
                :data:`simulator.physics.DAMPING_CALIBRATION` (600) and why it exists
                are documented there. 1 gives the bare (lightly damped) estimate.
            t_max_s: time limit of a run, s.
            polar_moment_um4: polar second moment J of the film about the chip centre,
                um^4 (default: the chip's ``(w^2 + h^2)/12`` per unit area times A).
        """
        area = (
            chip.area_um2
            if wetted_area_um2 is None
            else positive("wetted area", wetted_area_um2, "um^2")
        )
        j = (
            area * (chip.width_um**2 + chip.height_um**2) / 12.0
            if polar_moment_um4 is None
            else positive("polar moment", polar_moment_um4, "um^4")
        )
        return cls._film(
            chip.mass_kg,
            chip.moment_of_inertia_kg_m2,
            area,
            j,
            liquid.meniscus_height_um(area),
            liquid,
            calibration,
            t_max_s,
        )

    @classmethod
    def from_scene(cls, scene, t_max_s: float = 1.0) -> DynamicsParams:
        """From a :class:`simulator.scene.Scene`: its chip footprint, liquid and calibration.

        The chip body is its wettable footprint (the mask, any shape, area coverage per
        pixel) extruded to ``scene.chip_thickness_um`` at ``scene.chip_density_kg_m3``;
        the liquid film covers the same footprint. Every length comes from the scene, derived
        once there: the area ``A`` of the chip's mask, its polar moment ``J = A rg^2`` with
        the radius of gyration of the pose grid (:attr:`~simulator.scene.Scene.chip_rg_px`)
        and the film height ``h`` of the meniscus
        (:attr:`~simulator.scene.Scene.liquid_height_um`: ``--meniscus-height`` when given,
        else ``V / A``).
        """
        s = float(scene.um_per_px)
        area = positive("chip footprint area", scene.chip.area_um2, "um^2")
        j = area * (scene.chip_rg_px * s) ** 2  # um^4
        rho_t = scene.chip_density_kg_m3 * scene.chip_thickness_um * UM  # kg/m^2
        return cls._film(
            rho_t * area * UM2,
            rho_t * j * UM2 * UM2,
            area,
            j,
            scene.liquid_height_um,
            scene.liquid,
            scene.damping_calibration,
            t_max_s,
        )

    @classmethod
    def _film(cls, mass, inertia, area, j, h, liquid, calibration, t_max_s) -> DynamicsParams:
        cal = positive("damping calibration", calibration)
        mu = liquid.viscosity_Pa_s
        if not h >= MIN_FILM_UM:
            if liquid.height_um is not None:
                raise InputError(
                    f"meniscus height {h:.3g} um (--meniscus-height) is thinner than {MIN_FILM_UM * 1e3:g} nm, where the damping "
                    f"overflows the solver (and no real film is that thin); give at least {MIN_FILM_UM:g} um"
                )
            raise InputError(
                f"droplet volume {liquid.volume_nl:g} nl spreads to a film {h:.3g} um thick under the chip "
                f"({area:,.0f} um^2), thinner than {MIN_FILM_UM * 1e3:g} nm, where the damping overflows the solver (and no real film is that thin); "
                f"use at least {MIN_FILM_UM * area * 1e-6:.3g} nl (--volume)"
            )
        return cls(
            mass_kg=mass,
            inertia_kg_m2=inertia,
            damping_N_s_m=cal * couette_damping(mu, area, h),
            rot_damping_N_m_s=cal * couette_torsional_damping(mu, j, h),
            t_max_s=t_max_s,
        )

    def damping_ratio(self, stiffness_N_m: float) -> float:
        """``zeta = c / (2 sqrt(k m))`` of the translation for a spring of stiffness k (N/m)."""
        return self.damping_N_s_m / (2.0 * math.sqrt(stiffness_N_m * self.mass_kg))


def default_tolerances(dtype) -> tuple[float, float]:
    """(rtol, atol in grid steps) for a dtype: ``sqrt(eps) / 30`` for both.

    float32: 1.2e-5, float64: 5e-10. Measured on the linear-spring tests: trajectory
    errors of at most 1e-5 (float32) and 2e-10 (float64) of the start offset. (That the
    mechanical energy never rises is enforced by the guarded controller, not by these.)
    """
    eps = float(jnp.finfo(dtype).eps)
    tol = math.sqrt(eps) / 30.0
    return tol, tol
