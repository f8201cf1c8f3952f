"""The liquid and the chip body, and the mechanics that follow from them.

Owns :class:`Liquid` (the droplet: surface tension, viscosity, density, volume, the
meniscus height and pinning) with the flat-slab height :func:`meniscus_height_um`,
:class:`Chip` (a cuboid body: mass, moment of inertia, polar moment), the Couette
damping estimates and their calibration (:data:`DAMPING_CALIBRATION`), and the
closed-form sheared-block meniscus (:func:`parallelepiped_force`,
:func:`parallelepiped_stiffness`) of docs/physics.md §3.3. Units as in
:mod:`simulator.physics` (constants from :mod:`simulator.core`), which
re-exports every name here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from foundation import InputError, positive
from simulator.core import (
    SU8_DENSITY_KG_M3,
    UM,
    UM2,
    UM3_PER_NL,
    WATER_DENSITY_KG_M3,
    WATER_SURFACE_TENSION_N_M,
    WATER_VISCOSITY_PA_S,
)

#: The former default multiplier on the Couette damping estimate, now the override
#: ``--damping-calibration 600`` (the default damping is the sum of its terms,
#: :func:`dissipation_terms`; what follows is the fit's record).
#:
#: The damping model (docs/physics.md §4). The chip slides on a film of height
#: ``h = V / A``; with the liquid held on the chip's edges and the substrate at rest, the
#: film is sheared, and the textbook (Newton, plane Couette) drag is ``c = mu A / h``, with
#: the twist analogue ``c_t = mu J / h`` (J the footprint's polar moment).
#: What else dissipates, estimated for the source's large set-up (730 um SU-8 chip, 20 nl
#: of water, h = 37.5 um, chip speed about 1.5 mm/s in the video):
#:
#: * unsteady shear: the film's viscous time ``h^2 / nu`` is 1.4 ms against the 0.1-0.3 s
#:   of the motion, so the linear (quasi-steady) profile holds and Couette is the film's
#:   drag; only a ring-down at ms periods would see the larger Stokes-layer drag;
#: * the meniscus wedges at the moving contact lines (Cox, "The dynamics of the spreading
#:   of liquids on a solid surface", 1986; de Gennes, "Wetting: statics and dynamics",
#:   1985): per unit length of line moving normal to itself ``3 mu ln(l / a) / theta`` (ln
#:   about 12, theta the 60 deg substrate angle): 0.034 Pa s, on the two edges across the
#:   motion ``c = 2 L * 0.034``, 3.5 times the film's Couette value;
#: * contact-line friction of the molecular-kinetic theory (Blake and Haynes, "Kinetics of
#:   liquid/liquid displacement", 1969): coefficients of 0.01-1 Pa s per unit length are
#:   reported for water, 1 to 100 times the Couette value here;
#: * squeeze flow: vertical motion of the chip, absent from the lateral model (it delays
#:   the start while the released chip settles on the droplet, which is not simulated).
#:
#: The lines add ``2 zeta L`` across a shift and ``zeta L^3 / 3`` in twist for a square,
#: the same ratio ``J / A = L^2 / 6`` as the film's, so one multiplier on both Couette values
#: is the model: how fast the chip twists per micrometre it moves does not depend on it.
#: Coupled chip-flow computations and measured alignments of water both show much more
#: damping than the uncoupled film (docs/physics.md §4; Mastrangeli, Zhou, Sariola and
#: Lambert, "Surface tension-driven self-alignment", Soft Matter 2017, review the models),
#: so the factor is fitted to a measurement rather than built from the terms above.
#:
#: Bare Couette (factor 1) makes the chip a very lightly damped oscillator. For the
#: source's two set-ups (docs/physics.md section 11) a 1-D model with the parallelepiped
#: force of section 3.3 gives:
#:
#: ==========================================  =========  ==========  ===========
#: set-up (SU-8 chip, water)                   zeta       factor 1    factor 30
#: ==========================================  =========  ==========  ===========
#: 200x200x50 um chip, 0.5 nl (h 12.5 um)      0.021      5 ms        0.2 ms
#: 730x730x50 um chip, 20 nl (h 37.5 um)       0.024      24 ms       1.7 ms
#: ==========================================  =========  ==========  ===========
#:
#: ``zeta = c / (2 sqrt(k0 m))`` is the damping ratio near alignment with
#: ``k0 = 2 gamma L / h``. The times are for settling within 1 um, starting
#: 40 um (small set-up) or 300 um (large set-up) off. With factor 1 the chip rings
#: for tens of periods (period 0.2 ms and 0.7 ms), and it would cross the 730 um
#: four-pad in about 2 ms.
#:
#: The fit: the source's high-speed video of the 730 um chip on the 730/100 four-pad with
#: 20 nl (docs/physics.md §6.4) shows it aligned about 1/3 s after release from a 500 um
#: x-bias, a mean speed of about 1.5 mm/s. On the finite meniscus (``--meniscus``, 2 um/px,
#: 1 deg twists) overdamped runs from the starts that reach alignment, (380 um, 0, 1 deg)
#: and (380, 5 um, 0), reach the floating floor after 540 and 615 ms at factor 1000 and,
#: the path being the same at any factor, after 324 and 369 ms at 600 (the inertial model:
#: 323 and 372 ms), with a peak speed of 2.0 mm/s on the pads. From 500 um the chip stops on
#: the meniscus's flat part (382-434 um: no force, and a twist decays on the way there) at
#: any factor that takes longer than a few ms (docs/physics.md §4). The motion is overdamped
#: creep (zeta about 14 at 600): the inertial integrator switches to an implicit solver for
#: it (see :func:`simulator.motion.simulate`). It is one fit to one video: fit your own
#: factor to a measured alignment time when you have one (30 gives zeta ~ 0.7, a visible
#: overshoot). It does not change where the chip ends up in the quasi-static simulator,
#: which has no time scale (docs/physics.md §3.2, limit 4).
DAMPING_CALIBRATION = 600.0


# ------------------------------------------------------------------- liquid and chip


def meniscus_height_um(volume_nl: float, area_um2: float) -> float:
    """Flat-slab meniscus height ``h = V / A`` in um (docs/physics.md §7).

    20 nl on 730 x 730 um gives 37.53 um; 0.5 nl on 200 x 200 um gives 12.5 um.
    """
    v = positive("droplet volume", volume_nl, "nl")
    a = positive("wetted area", area_um2, "um^2")
    return v * UM3_PER_NL / a


@dataclass(frozen=True)
class Liquid:
    """The alignment liquid (water by default) and its volume.

    Attributes:
        name: a label for reports.
        surface_tension_N_m: liquid/air surface tension, N/m.
        viscosity_Pa_s: dynamic viscosity, Pa s (water at 20 C: 1.0e-3).
        density_kg_m3: density, kg/m^3.
        volume_nl: droplet volume, nl. The default 20 nl is the source's four-pad
            volume (730 um pattern); the defect/jaggedness tests on 200 um used 0.5 nl.
            None: derived from the chip by the :class:`~simulator.scene.Scene` that holds
            the liquid (:func:`simulator.liquid.default_volume_nl`), as a scene file or the
            command line without a volume does; the scene then sets ``volume_derived``.
        volume_derived: the volume was derived from the chip, not given.
        height_um: the liquid's height under the chip (um) for the finite meniscus
            (:mod:`simulator.physics`; TOML ``meniscus_height_um``) and the film of the
            dynamics' damping alike; None = ``volume_nl`` over the chip's area.
        pinned: contact lines held at the pad edges (liquid confined by a superhydrophobic
            substrate): only liquid-air area changes, ``Delta_gamma = -2 gamma_LA``.
        dispense: where the process puts the liquid (``--dispense``, TOML ``dispense``), which
            makes the wetted footprint a state of the run (docs/physics.md §3.5):
            ``"pattern"`` (the droplet on the pattern before the chip arrives) or ``"chip"``
            (the liquid comes in under the chip); ``"none"``: the stateless footprint (every
            pad counted by its distance from the chip, as before the state existed); None
            (not given): ``"pattern"`` where the scene's meniscus has free contact lines,
            else stateless (:attr:`simulator.scene.Scene.dispense`).
        dispense_at_um: (x, y) um where a ``pattern`` droplet is dispensed (default the
            pattern's centre; ``--dispense-at X,Y``).
    """

    name: str = "water"
    surface_tension_N_m: float = WATER_SURFACE_TENSION_N_M
    viscosity_Pa_s: float = WATER_VISCOSITY_PA_S
    density_kg_m3: float = WATER_DENSITY_KG_M3
    volume_nl: float | None = 20.0
    height_um: float | None = None
    pinned: bool = False
    dispense: str | None = None
    dispense_at_um: tuple[float, float] | None = None
    volume_derived: bool = False

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "name", str(self.name))
        if self.dispense is not None and self.dispense not in ("pattern", "chip", "none"):
            raise InputError(
                f"dispense (--dispense) must be 'pattern', 'chip' or 'none', got {self.dispense!r}"
            )
        if self.dispense_at_um is not None:
            at = self.dispense_at_um
            try:
                xy = tuple(float(v) for v in at)
            except (TypeError, ValueError):
                xy = ()
            if len(xy) != 2 or not all(math.isfinite(v) for v in xy):
                raise InputError(
                    f"dispense point (--dispense-at X,Y) must be two finite numbers of um, got {at!r}"
                )
            if self.dispense in ("chip", "none"):
                raise InputError(
                    f"--dispense-at places a droplet dispensed on the pattern, not with --dispense {self.dispense}: "
                    "leave out one of the two"
                )
            set_(self, "dispense_at_um", xy)
        if not isinstance(self.pinned, bool | np.bool_):
            raise InputError(f"liquid pinned must be true or false, got {self.pinned!r}")
        set_(self, "pinned", bool(self.pinned))
        if self.height_um is not None:
            h = self.height_um
            if (
                isinstance(h, bool)
                or not isinstance(h, int | float | np.floating | np.integer)
                or not math.isfinite(h)
                or h <= 0
            ):
                raise InputError(
                    f"meniscus height (--meniscus-height) must be a positive, finite number of um, got {h!r}"
                )
            set_(self, "height_um", float(h))
        set_(
            self,
            "surface_tension_N_m",
            positive("surface tension", self.surface_tension_N_m, "N/m"),
        )
        set_(self, "viscosity_Pa_s", positive("viscosity", self.viscosity_Pa_s, "Pa s"))
        set_(self, "density_kg_m3", positive("liquid density", self.density_kg_m3, "kg/m^3"))
        if self.volume_nl is not None:
            set_(self, "volume_nl", positive("droplet volume", self.volume_nl, "nl"))

    def meniscus_height_um(self, area_um2: float) -> float:
        """The liquid's height (um) under a chip of wetted area ``area_um2``: ``height_um``
        when given, else ``h = V / A`` (:func:`meniscus_height_um`). The rule for every
        model that needs the height (a scene derives it once:
        :attr:`simulator.scene.Scene.liquid_height_um`)."""
        if self.height_um is not None:
            return self.height_um
        if self.volume_nl is None:
            raise InputError(
                "the droplet volume is derived from the chip by the scene: give --volume NL, or use the scene's liquid"
            )
        return meniscus_height_um(self.volume_nl, area_um2)


@dataclass(frozen=True)
class Chip:
    """A rectangular chip body (a cuboid), for mass and moment of inertia.

    Attributes:
        width_um, height_um: footprint along x and y, um.
        thickness_um: along z, um (the source's SU-8 chips: 50 um).
        density_kg_m3: body density, kg/m^3 (SU-8 about 1200, a value from outside the source).
    """

    width_um: float
    height_um: float
    thickness_um: float = 50.0
    density_kg_m3: float = SU8_DENSITY_KG_M3

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "width_um", positive("chip width", self.width_um, "um"))
        set_(self, "height_um", positive("chip height", self.height_um, "um"))
        set_(self, "thickness_um", positive("chip thickness", self.thickness_um, "um"))
        set_(self, "density_kg_m3", positive("chip density", self.density_kg_m3, "kg/m^3"))

    @property
    def area_um2(self) -> float:
        """Footprint area, um^2."""
        return self.width_um * self.height_um

    @property
    def mass_kg(self) -> float:
        """``rho w h t``, kg (200 x 200 x 50 um SU-8: 2.4e-9 kg)."""
        return self.density_kg_m3 * self.width_um * self.height_um * self.thickness_um * UM**3

    @property
    def moment_of_inertia_kg_m2(self) -> float:
        """About the vertical axis through the centre, ``m (w^2 + h^2) / 12``, kg m^2."""
        return self.mass_kg * (self.width_um**2 + self.height_um**2) * UM2 / 12.0

    @property
    def polar_moment_um4(self) -> float:
        """Polar second moment of the footprint about its centre, ``A (w^2 + h^2) / 12``, um^4."""
        return rectangle_polar_moment_um4(self.width_um, self.height_um)


# ----------------------------------------------------------------------------- damping


def rectangle_polar_moment_um4(width_um: float, height_um: float) -> float:
    """``J = integral of r^2 dA = A (w^2 + h^2) / 12`` of a centred rectangle, um^4."""
    w = positive("width", width_um, "um")
    h = positive("height", height_um, "um")
    return w * h * (w * w + h * h) / 12.0


def couette_damping(viscosity_Pa_s: float, wetted_area_um2: float, h_um: float) -> float:
    """Translational Couette damping ``c = mu A / h`` in N s/m (uncalibrated; docs/physics.md §4).

    Multiply by :data:`DAMPING_CALIBRATION` (or your own factor) before use.
    """
    mu = positive("viscosity", viscosity_Pa_s, "Pa s")
    a = positive("wetted area", wetted_area_um2, "um^2")
    h = positive("meniscus height", h_um, "um")
    return mu * a * UM2 / (h * UM)


def couette_torsional_damping(viscosity_Pa_s: float, polar_moment_um4: float, h_um: float) -> float:
    """Rotational Couette damping ``c_t = mu J / h`` in N m s, any footprint (uncalibrated).

    ``J`` is the polar second moment of the wetted footprint about the rotation axis, um^4.
    """
    mu = positive("viscosity", viscosity_Pa_s, "Pa s")
    j = positive("polar moment", polar_moment_um4, "um^4")
    h = positive("meniscus height", h_um, "um")
    return mu * j * UM2 * UM2 / (h * UM)


#: Molecular cut-off ``a`` of the wedge term's ``ln(l / a)`` (:func:`wedge_friction_Pa_s`), nm:
#: the size of a water molecule, where the continuum wedge ends (de Gennes 1985 takes
#: ``ln(l / a)`` of 10-15 for l a macroscopic size; with l the film height, 37.5 um, it is 10.5).
WEDGE_CUTOFF_NM = 1.0

#: Molecular-kinetic contact-line friction coefficient ``zeta``, Pa s (force per unit length
#: of contact line per unit normal speed, N/m per m/s), fitted to the source's video of the
#: 730/100 um four-pad (docs/physics.md §4): with the pads' window 10:35 deg and the droplet
#: dispensed on the pattern, 6 Pa s takes the chip from (500, 0-5 um, 0-2 deg) to the floor in
#: 0.32 s and from 380 um in 0.26 s (the video: aligned at about 0.33 s). Water on hydrophilic
#: oxide gives 0.01-0.1 Pa s (Johansson and Hess, "Molecular origin of contact line friction
#: in dynamic wetting", Phys. Rev. Fluids 3, 074201, 2018; Blake and Haynes 1969 for the
#: theory): the fit is 60 times that range's top. It is the one term that can set the time:
#: the film's terms are fixed by the water and the film's height, the wedges' cut-off enters
#: by a logarithm, and a wider hysteresis window stops the chip instead of slowing it.
LINE_FRICTION_PA_S = 6.0


def stokes_layer_factor(omega_rad_s: float, h_um: float, kinematic_viscosity_m2_s: float) -> float:
    """In-phase drag of a film of height h under a plate oscillating at ``omega``, over its
    steady Couette value ``mu A / h``: ``Re[kh coth(kh)]``, ``k = sqrt(i omega / nu)``
    (the unsteady, Stokes-layer correction; docs/physics.md §4). In real form, with
    ``x = h / delta``, ``delta = sqrt(2 nu / omega)`` the Stokes layer's thickness,
    ``x (sinh 2x + sin 2x) / (cosh 2x - cos 2x)``: 1 + 4 x^4 / 45 for a thin film (the
    quasi-steady limit), x for a thick one (the layer's ``mu A / delta``)."""
    if not (omega_rad_s >= 0 and math.isfinite(omega_rad_s)):
        raise InputError(f"angular frequency must be finite and >= 0 rad/s, got {omega_rad_s!r}")
    h = positive("film height", h_um, "um") * UM
    nu = positive("kinematic viscosity", kinematic_viscosity_m2_s, "m^2/s")
    kh = complex(math.sqrt(omega_rad_s / (2 * nu)), math.sqrt(omega_rad_s / (2 * nu))) * h
    if abs(kh) < 1e-3:
        return 1.0 + (omega_rad_s * h * h / nu) ** 2 / 45.0
    if kh.real > 20:  # coth -> 1 to double precision
        return kh.real
    import cmath

    return (kh / cmath.tanh(kh)).real


def wedge_friction_Pa_s(viscosity_Pa_s: float, angle_deg: float, h_um: float) -> float:
    """The viscous wedge at a moving contact line (Cox, J. Fluid Mech. 168, 169, 1986; de
    Gennes, Rev. Mod. Phys. 57, 827, 1985): ``3 mu ln(l / a) / theta`` per unit length of
    line per unit normal speed, Pa s, with ``l`` the film height, ``a`` =
    :data:`WEDGE_CUTOFF_NM` and ``theta`` the line's contact angle (radians; small-angle form,
    good to 10 % below 60 deg)."""
    mu = positive("viscosity", viscosity_Pa_s, "Pa s")
    th = math.radians(positive("contact angle", angle_deg, "deg"))
    ln = math.log(positive("film height", h_um, "um") * 1e3 / WEDGE_CUTOFF_NM)
    return 3.0 * mu * max(ln, 0.0) / th


def dissipation_terms(
    *,
    viscosity_Pa_s: float,
    density_kg_m3: float,
    surface_tension_N_m: float,
    area_um2: float,
    polar_moment_um4: float,
    h_um: float,
    mass_kg: float,
    line_um: tuple[float, float, float] | None,
    across_um: float,
    line_angle_deg: float,
    line_friction_Pa_s: float = LINE_FRICTION_PA_S,
) -> dict:
    """The chip's viscous dissipation, term by term (docs/physics.md §4): each term's
    translational (N s/m) and twist (N m s) damping, and their sums.

    * ``couette``: the sheared film, ``mu A / h`` and ``mu J / h``;
    * ``stokes``: the unsteady correction of the film at the chip's natural frequency near
      alignment, ``omega = sqrt(k / m)`` with the sheared block's stiffness
      ``k = gamma * across / h`` (docs/physics.md §3.3; ``across = oint |n_x| ds``, 2L on a
      square): Couette times ``stokes_layer_factor - 1``, the fastest motion the chip
      makes (its ring-down), so an upper bound for the creep;
    * ``wedge``: the wedges at the moving contact lines, :func:`wedge_friction_Pa_s` times
      the line integrals;
    * ``line``: molecular-kinetic line friction ``zeta`` (Pa s) times the same integrals.

    ``line_um``: the moving contact lines' ``oint n_x^2 ds``, ``oint n_y^2 ds`` (um) and
    ``oint ((z x r) . n)^2 ds`` (um^3), or None where no line moves (lines held at the pad
    edges); translation takes the mean of x and y (exact on a square)."""
    mu = viscosity_Pa_s
    c_film = couette_damping(mu, area_um2, h_um)
    ct_film = couette_torsional_damping(mu, polar_moment_um4, h_um)
    k = surface_tension_N_m * across_um * UM / (h_um * UM)
    omega = math.sqrt(k / mass_kg) if mass_kg > 0 and k > 0 else 0.0
    f = stokes_layer_factor(omega, h_um, mu / density_kg_m3)
    terms = {
        "couette": (c_film, ct_film),
        "stokes": (c_film * (f - 1.0), ct_film * (f - 1.0)),
    }
    if line_um is None:
        terms["wedge"] = terms["line"] = (0.0, 0.0)
    else:
        lx, ly, lt = line_um
        trans = 0.5 * (lx + ly) * UM
        twist = lt * UM**3
        zw = wedge_friction_Pa_s(mu, line_angle_deg, h_um)
        terms["wedge"] = (zw * trans, zw * twist)
        terms["line"] = (line_friction_Pa_s * trans, line_friction_Pa_s * twist)
    return {
        "terms": terms,
        "omega_rad_s": omega,
        "stokes_factor": f,
        "damping_N_s_m": sum(v[0] for v in terms.values()),
        "rot_damping_N_m_s": sum(v[1] for v in terms.values()),
    }


def couette_added_mass_kg(density_kg_m3: float, wetted_area_um2: float, h_um: float) -> float:
    """Liquid carried by a chip shearing a film: ``rho A h / 3`` in kg (docs/physics.md §4).

    The Couette profile ``u(z) = v z / h`` holds kinetic energy ``rho A h v^2 / 6``, the
    energy of a third of the film moving with the chip. Quasi-steady: valid once the motion
    is slower than the film's viscous time ``h^2 / nu`` (1.4 ms for 37.5 um of water).
    20 nl under a 730 um chip: 6.7e-9 kg, a fifth of the 50 um SU-8 chip's mass.
    """
    rho = positive("liquid density", density_kg_m3, "kg/m^3")
    a = positive("wetted area", wetted_area_um2, "um^2")
    h = positive("meniscus height", h_um, "um")
    return rho * a * UM2 * h * UM / 3.0


def couette_added_inertia_kg_m2(
    density_kg_m3: float, polar_moment_um4: float, h_um: float
) -> float:
    """The twist analogue of :func:`couette_added_mass_kg`: ``rho h J / 3`` in kg m^2."""
    rho = positive("liquid density", density_kg_m3, "kg/m^3")
    j = positive("polar moment", polar_moment_um4, "um^4")
    h = positive("meniscus height", h_um, "um")
    return rho * h * UM * j * UM2 * UM2 / 3.0


def couette_rotational_damping(
    viscosity_Pa_s: float, width_um: float, height_um: float, h_um: float
) -> float:
    """Rotational Couette damping of a rectangular footprint, ``mu A (w^2 + h^2) / (12 h)``, N m s."""
    return couette_torsional_damping(
        viscosity_Pa_s, rectangle_polar_moment_um4(width_um, height_um), h_um
    )


# ------------------------------------------------------------------ analytic formulas


def parallelepiped_force(
    x_um: float | np.ndarray, h_um: float, L_um: float, gamma: float = WATER_SURFACE_TENSION_N_M
) -> float | np.ndarray:
    """Restoring force of the sheared-block meniscus, ``-2 gamma L x / sqrt(x^2 + h^2)`` in N.

    docs/physics.md §3.3 [Eq. 6] and C13: tends to ``-2 gamma L`` for ``x >> h``, has slope
    ``-2 gamma L / h`` at 0 (:func:`parallelepiped_stiffness`) and equals
    ``-sqrt(2) gamma L`` at ``x = h``.

    Args:
        x_um: bias along the axis, um (scalar or array).
        h_um: meniscus height, um (> 0).
        L_um: edge length perpendicular to the shift, um.
        gamma: liquid/air surface tension, N/m.
    """
    h = positive("meniscus height", h_um, "um")
    length = positive("edge length", L_um, "um")
    g = positive("surface tension", gamma, "N/m")
    x = np.asarray(x_um, dtype=np.float64)
    f = -2.0 * g * length * UM * x / np.hypot(x, h)
    return float(f) if f.ndim == 0 else f


def parallelepiped_stiffness(
    h_um: float, L_um: float, gamma: float = WATER_SURFACE_TENSION_N_M
) -> float:
    """Small-bias stiffness ``k0 = 2 gamma L / h`` of the sheared-block meniscus, N/m."""
    h = positive("meniscus height", h_um, "um")
    length = positive("edge length", L_um, "um")
    return 2.0 * positive("surface tension", gamma, "N/m") * length / h
