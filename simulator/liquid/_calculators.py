"""The droplet calculators behind ``selfalign liquid``: meniscus height, overflow, critical volume.

* :func:`height_report`: the flat-film meniscus height ``h = V / A`` (docs/physics.md §7)
  and whether the thin-film picture holds, with the parallelepiped meniscus' spring (C13);
* :func:`overflow_conditions` and :func:`overflow_report`: the no-overflow conditions
  (1)-(3) of docs/physics.md §9 for a protruding pad, over a range of chip angles;
* :class:`Topography`: a protruding pad's edge angle and the angles the overflow check needs;
* :func:`critical_volume_nl` and :func:`dimensionless_volume`: ``V_crit = (V_ND A)^(3/2)``
  (docs/physics.md §8) and its inverse;
* the numbers as typed: :func:`check_surface_tension_mN_m`, :func:`capillary_length_um`.

Units as in :mod:`simulator.liquid`. The checks of a scene are in :mod:`simulator.liquid`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from foundation import InputError, positive
from simulator.core import UM, UM3_PER_NL, WATER_DENSITY_KG_M3, WATER_SURFACE_TENSION_N_M
from simulator.physics import contact_angle_deg, meniscus_height_um

#: The thin-film (overlap) picture needs the film much thinner than the chip: at most
#: this fraction of the chip's smallest side, and of the capillary length.
THIN_FILM_FRACTION = 0.1
#: Surface tensions a user can mean, in mN/m (hexane 18, water 72.8, mercury 485).
SURFACE_TENSION_RANGE_MN_M = (1.0, 1000.0)
STANDARD_GRAVITY_M_S2 = 9.80665


# --------------------------------------------------------------------- numbers as typed
def check_surface_tension_mN_m(value: float, where: str = "--surface-tension") -> float:
    """``value`` (mN/m) if it lies in 1-1000 mN/m, else InputError with the likely fix."""
    v = positive(where, value, "mN/m")
    lo, hi = SURFACE_TENSION_RANGE_MN_M
    if v < lo:
        raise InputError(
            f"{where} {v:g} mN/m is below {lo:g} mN/m, lower than any liquid: it looks like N/m; "
            f"give {v * 1000:g} (mN/m; water is 72.8)"
        )
    if v > hi:
        raise InputError(
            f"{where} {v:g} mN/m is above {hi:g} mN/m, more than any liquid (mercury is 485): it looks like "
            f"uN/m; give {v / 1000:g} (mN/m; water is 72.8)"
        )
    return v


def capillary_length_um(
    surface_tension_N_m: float = WATER_SURFACE_TENSION_N_M,
    density_kg_m3: float = WATER_DENSITY_KG_M3,
) -> float:
    """``sqrt(gamma / (rho g))`` in um (water: 2.73 mm); below it gravity does not shape a drop."""
    g = positive("surface tension", surface_tension_N_m, "N/m")
    rho = positive("liquid density", density_kg_m3, "kg/m^3")
    return math.sqrt(g / (rho * STANDARD_GRAVITY_M_S2)) / UM


# --------------------------------------------------------------------- meniscus height
def height_report(
    volume_nl: float,
    area_um2: float,
    sides_um: tuple[float, float] | None = None,
    surface_tension_N_m: float = WATER_SURFACE_TENSION_N_M,
    density_kg_m3: float = WATER_DENSITY_KG_M3,
    bias_um: float | None = None,
    height_um: float | None = None,
) -> dict:
    """The flat-film meniscus height and whether the thin-film picture holds (units in the keys).

    ``height_um``: the height when it is known already (a scene's,
    :attr:`simulator.scene.Scene.liquid_height_um`); default ``V / A``.

    ``sides_um`` (the chip's width and height) adds the comparison with the smallest side
    and the parallelepiped meniscus of docs/physics.md §3.3 for a shift along x (edge length
    = the chip's height): its small-bias stiffness ``2 gamma L / h``, its large-bias limit
    ``-2 gamma L`` and, with ``bias_um``, the force ``-2 gamma L x / sqrt(x^2 + h^2)``.
    """
    from simulator.physics import parallelepiped_force, parallelepiped_stiffness

    h = meniscus_height_um(volume_nl, area_um2) if height_um is None else float(height_um)
    lc = capillary_length_um(surface_tension_N_m, density_kg_m3)
    out: dict = {
        "volume_nl": float(volume_nl),
        "area_um2": float(area_um2),
        "meniscus_height_um": h,
        "capillary_length_um": lc,
        "h_over_capillary_length": h / lc,
    }
    notes = []
    if h > THIN_FILM_FRACTION * lc:
        notes.append(
            f"h = {h:.4g} um is more than {THIN_FILM_FRACTION:g} of the capillary length ({lc:.4g} um): gravity flattens the film"
        )
    if sides_um is not None:
        w, ht = sides_um
        side = min(w, ht)
        out |= {
            "chip_width_um": w,
            "chip_height_um": ht,
            "smallest_side_um": side,
            "h_over_smallest_side": h / side,
        }
        if h > side:
            notes.append(
                f"h = {h:.4g} um is more than the chip's smallest side ({side:g} um): this is a drop, not a film under the chip"
            )
        elif h > THIN_FILM_FRACTION * side:
            notes.append(
                f"h = {h:.4g} um is {100 * h / side:.3g} % of the chip's smallest side ({side:g} um), more than "
                f"{100 * THIN_FILM_FRACTION:g} %: the overlap model is off within about h of every feature"
            )
        g = surface_tension_N_m
        out["parallelepiped"] = {
            "edge_length_um": ht,
            "stiffness_N_per_m": parallelepiped_stiffness(h, ht, g),
            "force_limit_N": -2.0 * g * ht * UM,
        }
        if bias_um is not None:
            out["parallelepiped"] |= {
                "bias_um": float(bias_um),
                "force_N": parallelepiped_force(bias_um, h, ht, g),
            }
    out["thin_film_holds"] = not notes
    out["thin_film_notes"] = notes
    return out


# --------------------------------------------------------------------- overflow (docs/physics.md §9)
def _edge_angle(name: str, value: float) -> float:
    """A solid wedge angle in (0, 180] degrees (90 = vertical wall, 180 = no edge), else InputError.

    0 is no solid at all: its overflow angle, 180 + the pad's advancing angle, is no angle a liquid has.
    """
    v = contact_angle_deg(name, value)
    if not v > 0:
        raise InputError(
            f"{name} must be a solid wedge angle in (0, 180] degrees (90 = a vertical wall, 180 = no edge), "
            f"got {value!r}: a wedge of 0 degrees is no solid"
        )
    return v


def overflow_angle_deg(theta_edge_deg: float, theta_adv_pad_deg: float) -> float:
    """Apparent angle at which liquid spills over a pad edge, ``(180 - theta_edge) + theta_adv_pad``.

    docs/physics.md §9 [Eq. 22]; ``theta_edge`` is the solid wedge angle (90 = vertical wall).
    """
    te = _edge_angle("edge angle", theta_edge_deg)
    ta = contact_angle_deg("pad advancing angle", theta_adv_pad_deg)
    return 180.0 - te + ta


def overflow_bias_um(h_um: float, theta_edge_deg: float, theta_adv_pad_deg: float) -> float:
    """Bias beyond which liquid overflows a protruding pad, ``h / tan(theta_edge - theta_adv_pad)``, um.

    docs/physics.md §9 [Eq. 23] and C12 (h 12.5 um, 90 deg, 60 deg -> 21.65 um). Returns
    ``math.inf`` when ``theta_edge <= theta_adv_pad`` (the overflow angle is >= 180
    and cannot be reached: condition 1), and 0 when ``theta_edge - theta_adv_pad >= 90``
    (the flat-face meniscus is already past the pinning window at zero bias).
    """
    h = positive("meniscus height", h_um, "um")
    diff = _edge_angle("edge angle", theta_edge_deg) - contact_angle_deg(
        "pad advancing angle", theta_adv_pad_deg
    )
    if diff <= 0:
        return math.inf
    if diff >= 90:
        return 0.0
    return h / math.tan(math.radians(diff))


@dataclass(frozen=True)
class OverflowConditions:
    """Which of the three no-overflow conditions of docs/physics.md §9 hold.

    Attributes:
        edge_confines: (1) ``theta_edge <= theta_adv_pad``: the edge can never be overrun.
        chip_dewets: (2) ``theta_edge < theta_adv_pad + theta_chip``: the chip de-wets
            before the liquid reaches the overflow angle.
        bias_below_overflow: (3) ``theta_edge > theta_adv_pad`` and ``|bias| < overflow_bias_um``
            (the condition applies only when (1) does not: its formula is meaningless there).
        overflow_bias_um: the bias of condition (3), um (inf under condition 1).
    """

    edge_confines: bool
    chip_dewets: bool
    bias_below_overflow: bool
    overflow_bias_um: float

    @property
    def holding(self) -> tuple[int, ...]:
        """Numbers (1, 2, 3) of the conditions that hold."""
        flags = (self.edge_confines, self.chip_dewets, self.bias_below_overflow)
        return tuple(i + 1 for i, f in enumerate(flags) if f)

    @property
    def overflows(self) -> bool:
        """True when none of the conditions holds: the liquid overflows, alignment fails."""
        return not self.holding


def overflow_conditions(
    theta_edge_deg: float,
    theta_adv_pad_deg: float,
    theta_chip_deg: float,
    bias_um: float,
    h_um: float,
) -> OverflowConditions:
    """Evaluate the no-overflow conditions (1)-(3) of docs/physics.md §9 for one placement.

    Args:
        theta_edge_deg: solid wedge angle of the pad edge, degrees (90 = vertical wall).
        theta_adv_pad_deg: advancing contact angle on the pad, degrees.
        theta_chip_deg: the chip's *advancing* angle when the chip is placed with a
            bias, or its *receding* angle when it is placed without bias and then
            dragged sideways (the stricter case), degrees.
        bias_um: lateral bias, um (its magnitude is used).
        h_um: meniscus height, um (e.g. :func:`meniscus_height_um`).
    """
    te = _edge_angle("edge angle", theta_edge_deg)
    ta = contact_angle_deg("pad advancing angle", theta_adv_pad_deg)
    tc = contact_angle_deg("chip contact angle", theta_chip_deg)
    x = abs(float(bias_um))
    if not math.isfinite(x):
        raise InputError(f"bias must be a finite number of um, got {bias_um!r}")
    xo = overflow_bias_um(h_um, te, ta)
    return OverflowConditions(
        edge_confines=te <= ta,
        chip_dewets=te < ta + tc,
        bias_below_overflow=te > ta and x < xo,
        overflow_bias_um=xo,
    )


DEPENDS_ON_BIAS = "depends on the bias"
DEPENDS_ON_CHIP_ANGLE = "depends on the chip angle"


def _verdict(edge: float, adv: float, chip: float, h: float, bias: float | None) -> dict:
    """Conditions and verdict for one chip angle; without a bias condition 3 is left open."""
    c = overflow_conditions(edge, adv, chip, 0.0 if bias is None else bias, h)
    holding = [i for i in c.holding if bias is not None or i != 3]
    if holding:
        verdict: bool | str = False
    elif bias is not None:
        verdict = True
    else:
        verdict = DEPENDS_ON_BIAS if edge > adv and c.overflow_bias_um > 0 else True
    return {"conditions_holding": holding, "overflows": verdict}


def overflow_report(
    pad_advancing_deg: float,
    chip_angle_deg: float | tuple[float, float],
    edge_angle_deg: float,
    h_um: float,
    bias_um: float | None = None,
) -> dict:
    """The no-overflow conditions of docs/physics.md §9 and the verdict (units in the keys).

    ``overflows`` is True, False, or ``"depends on the bias"`` when only condition (3) can
    hold and no bias is given (then ``overflow_bias_um`` is the largest safe bias). A chip
    angle range ``(lo, hi)`` reports the verdict over the range: condition (2) switches at
    ``theta_chip = theta_edge - theta_adv_pad`` (``condition_2_switch_chip_angle_deg``), and
    ``over_chip_angle_range`` lists the pieces with one verdict each.
    """
    adv = contact_angle_deg("--pad-advancing", pad_advancing_deg)
    edge = _edge_angle("--edge-angle", edge_angle_deg)
    h = positive("--meniscus-height", h_um, "um")
    if bias_um is not None and not math.isfinite(float(bias_um)):
        raise InputError(f"--bias must be a finite number of um, got {bias_um!r}")
    xo = overflow_bias_um(h, edge, adv)
    out: dict = {
        "pad_advancing_deg": adv,
        "edge_angle_deg": edge,
        "meniscus_height_um": h,
        "overflow_angle_deg": overflow_angle_deg(edge, adv),
        "overflow_bias_um": None if math.isinf(xo) else xo,
        "bias_um": None if bias_um is None else abs(float(bias_um)),
    }
    switch = edge - adv  # condition 2 holds for chip angles strictly above this
    if not isinstance(chip_angle_deg, tuple):
        chip = contact_angle_deg("--chip-angle", chip_angle_deg)
        return out | {"chip_angle_deg": chip} | _verdict(edge, adv, chip, h, bias_um)
    lo, hi = (contact_angle_deg("--chip-angle", v) for v in chip_angle_deg)
    if hi < lo:
        raise InputError(
            f"--chip-angle {lo:g}:{hi:g}: the range must go from the smaller angle to the larger"
        )
    pieces: list[dict] = []
    if lo <= switch < hi:
        below = _verdict(edge, adv, switch, h, bias_um)  # at the switch itself condition 2 fails
        above = _verdict(edge, adv, hi, h, bias_um)
        pieces = [
            {"chip_angle_from_deg": lo, "chip_angle_to_deg": switch} | below,
            {"chip_angle_from_deg": switch, "chip_angle_to_deg": hi, "from_excluded": True} | above,
        ]
    else:
        pieces = [
            {"chip_angle_from_deg": lo, "chip_angle_to_deg": hi}
            | _verdict(edge, adv, lo, h, bias_um)
        ]
    verdicts = {str(p["overflows"]) for p in pieces}
    out |= {
        "chip_angle_deg": {"from": lo, "to": hi},
        "condition_2_switch_chip_angle_deg": switch if lo <= switch < hi else None,
        "over_chip_angle_range": pieces,
        "conditions_holding": sorted(
            set.intersection(*(set(p["conditions_holding"]) for p in pieces))
        ),
        "overflows": pieces[0]["overflows"] if len(verdicts) == 1 else DEPENDS_ON_CHIP_ANGLE,
    }
    return out


@dataclass(frozen=True)
class Topography:
    """A protruding pad: what the overflow check of docs/physics.md §9 needs (degrees).

    Attributes:
        edge_angle_deg: solid wedge angle of the pad edge (90 = vertical wall).
        pad_advancing_deg: advancing contact angle on the pad (None: the materials' advancing
            angle when the scene gives the pad's hysteresis, else its static pad angle).
        chip_angle_deg: the chip's advancing angle (placed with a bias), or its receding
            angle for the stricter case (placed without bias and dragged); None: unknown,
            so condition (2) is not counted on.
    """

    edge_angle_deg: float
    pad_advancing_deg: float | None = None
    chip_angle_deg: float | None = None

    def __post_init__(self) -> None:
        _edge_angle("edge_angle_deg (--edge-angle)", self.edge_angle_deg)
        if self.pad_advancing_deg is not None:
            contact_angle_deg("pad_advancing_deg (--pad-advancing)", self.pad_advancing_deg)
        if self.chip_angle_deg is not None:
            contact_angle_deg("chip_angle_deg (--chip-angle)", self.chip_angle_deg)


# --------------------------------------------------------------------- critical volume (docs/physics.md §8)
def critical_volume_nl(v_nd: float, area_um2: float) -> float:
    """Critical droplet volume ``V_crit = (V_ND A)^(3/2)`` of a segmented pattern, nl.

    docs/physics.md §8 [Eq. 17]. ``V_ND`` is dimensionless and comes from a fit for the
    contact angles and relative gap in question (or from
    :func:`simulator.liquid.critical_volume`); ``A`` is the pattern area in um^2,
    so ``(V_ND A)^(3/2)`` is in um^3 and is divided by 1e6.
    """
    v = positive("dimensionless volume V_ND", v_nd)
    a = positive("pattern area", area_um2, "um^2")
    return (v * a) ** 1.5 / UM3_PER_NL


def dimensionless_volume(volume_nl: float, area_um2: float) -> float:
    """Inverse of :func:`critical_volume_nl`: ``V_ND = V^(2/3) / A`` with V in um^3."""
    v = positive("droplet volume", volume_nl, "nl")
    a = positive("pattern area", area_um2, "um^2")
    return (v * UM3_PER_NL) ** (2.0 / 3.0) / a
