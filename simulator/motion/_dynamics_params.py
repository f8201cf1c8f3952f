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
* damping: the sum of its terms (:func:`simulator.physics.dissipation_terms`,
  :func:`dissipation`): the film's Couette drag ``mu A / h`` (``mu J / h`` in twist) with
  its unsteady correction, the wedges at the moving contact lines and their
  molecular-kinetic friction; or, where the scene gives ``damping_calibration`` k (the
  override), ``c = k mu A / h`` and ``c_t = k mu J / h`` (600,
  :data:`simulator.physics.DAMPING_CALIBRATION`, was the fit to the source's video).

J is the footprint's polar moment about the chip centre. Contact-angle hysteresis is not a
damping: it is friction, carried by the steppers (docs/physics.md §4).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from foundation import InputError, positive
from simulator.core import UM, UM2, UM3_PER_NL
from simulator.physics import (
    LINE_FRICTION_PA_S,
    Chip,
    Liquid,
    couette_damping,
    couette_torsional_damping,
    dissipation_terms,
)

if TYPE_CHECKING:
    from jax.typing import DTypeLike

    from simulator.scene import Scene

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
        calibration: float | None = None,
        t_max_s: float = 1.0,
        polar_moment_um4: float | None = None,
        line_angle_deg: float = 60.0,
        line_friction_Pa_s: float = LINE_FRICTION_PA_S,
        moving_lines: bool = True,
    ) -> DynamicsParams:
        """The damping of a rectangular chip on a film (docs/physics.md §4, §7).

        ``h = V / A`` (flat slab; the liquid's ``height_um`` when given). ``calibration``
        None: the sum of the documented terms (:func:`simulator.physics.dissipation_terms`:
        the film's Couette drag with its unsteady correction, the wedges and the line
        friction of the chip's outline, moving with it at ``line_angle_deg``); a number k:
        ``c = k mu A / h`` and ``c_t = k mu J / h`` (the Couette drag times k, as before the
        terms; 600 was the fit to the source's video). Mass and inertia of the chip's cuboid
        body (the liquid's added mass is left out: module docstring).

        Args:
            chip: the chip body (mass, moment of inertia, footprint).
            liquid: viscosity, density, surface tension and droplet volume.
            wetted_area_um2: area A of the liquid film, um^2 (default: the chip footprint).
            calibration: None (the terms) or the multiplier on both Couette values.
            t_max_s: time limit of a run, s.
            polar_moment_um4: polar second moment J of the film about the chip centre,
                um^4 (default: the chip's ``(w^2 + h^2)/12`` per unit area times A).
            line_angle_deg: the moving lines' contact angle (the wedge term), deg.
            line_friction_Pa_s: the molecular-kinetic line friction, Pa s.
            moving_lines: False where every line is held by an edge (no wedge, no line friction).
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
        w, hh = chip.width_um, chip.height_um
        lines = (2 * hh, 2 * w, (w**3 + hh**3) / 6.0) if moving_lines else None
        return cls._film(
            chip.mass_kg,
            chip.moment_of_inertia_kg_m2,
            area,
            j,
            liquid.meniscus_height_um(area),
            liquid,
            calibration,
            t_max_s,
            lines=lines,
            across_um=2 * hh,
            line_angle_deg=line_angle_deg,
            line_friction_Pa_s=line_friction_Pa_s,
        )

    @classmethod
    def from_scene(cls, scene: Scene, t_max_s: float = 1.0) -> DynamicsParams:
        """From a :class:`simulator.scene.Scene`: its chip footprint, liquid and damping.

        The chip body is its wettable footprint (the mask, any shape, area coverage per
        pixel) extruded to ``scene.chip_thickness_um`` at ``scene.chip_density_kg_m3``;
        the liquid film covers the same footprint. Every length comes from the scene, derived
        once there: the area ``A`` of the chip's mask, its polar moment ``J = A rg^2`` with
        the radius of gyration of the pose grid (:attr:`~simulator.scene.Scene.chip_rg_px`)
        and the film height ``h`` of the meniscus
        (:attr:`~simulator.scene.Scene.liquid_height_um`: ``--meniscus-height`` when given,
        else ``V / A``). The damping: ``scene.damping_calibration`` times Couette where one
        is given, else the terms (:func:`dissipation`).
        """
        b = _scene_body(scene)
        return cls._film(
            b["mass_kg"],
            b["inertia_kg_m2"],
            b["area_um2"],
            b["polar_moment_um4"],
            scene.liquid_height_um,
            scene.liquid,
            scene.damping_calibration,
            t_max_s,
            lines=b["lines"],
            across_um=b["across_um"],
            line_angle_deg=b["angle_deg"],
            line_friction_Pa_s=scene.line_friction_Pa_s,
        )

    @classmethod
    def _film(
        cls,
        mass: float,
        inertia: float,
        area: float,
        j: float,
        h: float,
        liquid: Liquid,
        calibration: float | None,
        t_max_s: float,
        *,
        lines: tuple[float, float, float] | None = None,
        across_um: float = 0.0,
        line_angle_deg: float = 60.0,
        line_friction_Pa_s: float = LINE_FRICTION_PA_S,
    ) -> DynamicsParams:
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
                f"use at least {MIN_FILM_UM * area / UM3_PER_NL:.3g} nl (--volume)"
            )
        if calibration is not None:
            cal = positive("damping calibration", calibration)
            return cls(
                mass_kg=mass,
                inertia_kg_m2=inertia,
                damping_N_s_m=cal * couette_damping(mu, area, h),
                rot_damping_N_m_s=cal * couette_torsional_damping(mu, j, h),
                t_max_s=t_max_s,
            )
        d = dissipation_terms(
            viscosity_Pa_s=mu,
            density_kg_m3=liquid.density_kg_m3,
            surface_tension_N_m=liquid.surface_tension_N_m,
            area_um2=area,
            polar_moment_um4=j,
            h_um=h,
            mass_kg=mass,
            line_um=lines,
            across_um=across_um,
            line_angle_deg=line_angle_deg,
            line_friction_Pa_s=line_friction_Pa_s,
        )
        return cls(
            mass_kg=mass,
            inertia_kg_m2=inertia,
            damping_N_s_m=d["damping_N_s_m"],
            rot_damping_N_m_s=d["rot_damping_N_m_s"],
            t_max_s=t_max_s,
        )

    def damping_ratio(self, stiffness_N_m: float) -> float:
        """``zeta = c / (2 sqrt(k m))`` of the translation for a spring of stiffness k (N/m)."""
        return self.damping_N_s_m / (2.0 * math.sqrt(stiffness_N_m * self.mass_kg))


def _scene_body(scene: Scene) -> dict:
    """The chip body and film of a scene, as :meth:`DynamicsParams.from_scene` documents them:
    ``area_um2``, ``polar_moment_um4`` (J = A rg^2), ``mass_kg``, ``inertia_kg_m2``, and its
    moving lines: ``lines`` (their integrals, or None where a pinned scene holds every line
    at an edge; the chip's outline moves its lines with it where they are free, a finite
    meniscus with free lines or the overlap model's line at the chip's edge), ``across_um``
    (oint |n_x| ds) and ``angle_deg`` (the substrate's, where a free line stands at rest,
    docs/physics.md §3.3)."""
    from simulator.physics import contact_line_integrals_um, line_dissipation_integrals_um

    s = float(scene.um_per_px)
    area = positive("chip footprint area", scene.chip.area_um2, "um^2")
    j = area * (scene.chip_rg_px * s) ** 2  # um^4
    rho_t = scene.chip_density_kg_m3 * scene.chip_thickness_um * UM  # kg/m^2
    across, _, _ = contact_line_integrals_um(scene.chip)
    return {
        "area_um2": area,
        "polar_moment_um4": j,
        "mass_kg": rho_t * area * UM2,
        "inertia_kg_m2": rho_t * j * UM2 * UM2,
        "lines": None if scene.liquid.pinned else line_dissipation_integrals_um(scene.chip),
        "across_um": across,
        "angle_deg": scene.materials.substrate_angle_deg,
    }


def dissipation(scene: Scene) -> dict:
    """The scene's damping term by term (:func:`simulator.physics.dissipation_terms`): what
    :meth:`DynamicsParams.from_scene` sums where no ``damping_calibration`` is given."""
    b = _scene_body(scene)
    return dissipation_terms(
        viscosity_Pa_s=scene.liquid.viscosity_Pa_s,
        density_kg_m3=scene.liquid.density_kg_m3,
        surface_tension_N_m=scene.liquid.surface_tension_N_m,
        area_um2=b["area_um2"],
        polar_moment_um4=b["polar_moment_um4"],
        h_um=scene.liquid_height_um,
        mass_kg=b["mass_kg"],
        line_um=b["lines"],
        across_um=b["across_um"],
        line_angle_deg=b["angle_deg"],
        line_friction_Pa_s=scene.line_friction_Pa_s,
    )


def default_tolerances(dtype: DTypeLike) -> tuple[float, float]:
    """(rtol, atol in grid steps) for a dtype: ``sqrt(eps) / 30`` for both.

    float32: 1.2e-5, float64: 5e-10. Measured on the linear-spring tests: trajectory
    errors of at most 1e-5 (float32) and 2e-10 (float64) of the start offset. (That the
    mechanical energy never rises is enforced by the guarded controller, not by these.)
    """
    eps = float(jnp.finfo(dtype).eps)
    tol = math.sqrt(eps) / 30.0
    return tol, tol
