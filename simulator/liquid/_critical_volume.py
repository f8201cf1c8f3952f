"""The critical droplet volume of a four-pad pattern, computed (docs/physics.md §8).

Too little liquid on a segmented pattern splits onto single pads or leaves a pad dry.
The *critical volume* is the smallest droplet for which one drop wetting all four pads
has a lower surface energy than the best split of the same liquid onto single pads.
:func:`critical_volume` computes it from a reduced model of the drop:

* **Energy.** A drop's energy is ``gamma (A_LV - sum_i cos(theta_i) A_i)``: its
  liquid/air area plus, by Young's equation, ``-gamma cos(theta)`` for every unit area of
  solid it wets (pads at the pad angle, the gap and the surroundings at the substrate's).
  Static (Young) angles; no gravity; no chip on top.
* **Shape.** Every drop is a spherical cap (constant curvature, the shape of a small
  drop) standing on a disc of the area of its footprint.
* **Footprint.** A centred square of side ``s`` that the drop chooses to minimise its
  energy: the whole-pattern drop on the pattern centre (``s >= g``, so it touches all four
  pads), a one-pad drop on its pad centre. The wetted areas are those of the square over
  the real pattern: the whole-pattern drop covers ``(s - g)^2`` of pad and the rest of the
  square is substrate (the gap cross, and beyond ``L`` the surroundings). Where the weight
  per area jumps (a pad edge) the minimum sits on the edge for a range of volumes: the
  contact line is pinned there while the cap's angle lies between the two sides' angles,
  which is Gibbs' condition (docs/physics.md §2), not an added rule.
* **Split.** A one-pad drop may spread past its pad onto the substrate, but not past the
  middle of the gap (``s <= p + g``): beyond, it touches its neighbour's liquid and the
  drops merge. The best split of a volume ``V`` onto the four pads (some may stay dry) is
  the min-plus convolution of the one-pad energy with itself, twice, on a volume grid: an
  exact minimum over the split, where the source used a genetic algorithm.
* **Critical volume.** The smallest ``V`` above which the whole-pattern drop is lower in
  energy than every split, found on a volume grid and interpolated linearly.

Lengths in um, volumes in um^3 inside and nl at the boundary (1 nl = 1e6 um^3), angles in
degrees, energies in J. The volume does not depend on the surface tension, and scales
with the cube of the pattern size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from foundation import InputError, positive
from simulator.core import UM2, UM3_PER_NL

#: Volume-grid points of the final pass (the split is exact on this grid).
GRID_POINTS = 1200
#: Footprint-grid points before the golden-section refinement.
FOOTPRINT_POINTS = 400
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
#: Relative slack (fraction of the edge's length) within which a drop's footprint side counts
#: as at a pad or pattern edge: above the golden-section search's ~1e-9, below any real gap.
EDGE_REL_TOL = 1e-6

METHOD = (
    "reduced spherical-cap model: each drop is a spherical cap on the area of a centred square "
    "footprint that minimises gamma (A_LV - sum cos(theta) A_wetted) with Young weights (pads at the "
    "pad angle, gap and surroundings at the substrate angle); one drop on the pattern centre "
    "touching all four pads against the best split onto single pads (min-plus convolution of the "
    "one-pad energy; a one-pad drop may spill up to the middle of the gap, then it merges); the "
    "critical volume is where the single drop becomes lower in energy"
)

ASSUMPTIONS = (
    "spherical caps on discs of the footprint's area (a drop pinned on a square is not spherical: "
    "the cap has a little less liquid/air area than the real drop)",
    "footprints are centred squares; the drop wets the gap under it at the substrate angle",
    "static (Young) contact angles: no hysteresis, no dynamics",
    "no gravity (drop smaller than the capillary length), no chip on top of the drop",
)


# ------------------------------------------------------------------ spherical caps
def cap_height_um(volume_um3, base_um2):
    """Height (um) of the spherical cap of volume ``V`` (um^3) on a disc of area ``B`` (um^2).

    Solves ``V = pi h (3 a^2 + h^2) / 6`` with ``a^2 = B / pi`` in closed form
    (``h = 2 a sinh(asinh(3 V / (pi a^3)) / 3)``, stable for thin and tall caps alike).
    """
    v, b = np.asarray(volume_um3, dtype=np.float64), np.asarray(base_um2, dtype=np.float64)
    a = np.sqrt(b / math.pi)
    return 2.0 * a * np.sinh(np.arcsinh(3.0 * v / (math.pi * a**3)) / 3.0)


def cap_area_um2(volume_um3, base_um2):
    """Liquid/air area (um^2) of that cap, ``pi (a^2 + h^2)``."""
    b = np.asarray(base_um2, dtype=np.float64)
    h = cap_height_um(volume_um3, b)
    return b + math.pi * h * h


def cap_angle_deg(volume_um3, base_um2):
    """Contact angle (degrees) of that cap at its rim, ``2 atan(h / a)``."""
    b = np.asarray(base_um2, dtype=np.float64)
    return np.degrees(2.0 * np.arctan2(cap_height_um(volume_um3, b), np.sqrt(b / math.pi)))


def free_cap_base_um2(volume_um3, angle_deg):
    """Base area (um^2) of the spherical cap of volume ``V`` with contact angle ``theta``
    (``V = pi a^3 t (3 + t^2) / 6``, ``t = tan(theta / 2)``)."""
    t = np.tan(np.radians(np.asarray(angle_deg, dtype=np.float64)) / 2.0)
    a = np.cbrt(6.0 * np.asarray(volume_um3, dtype=np.float64) / (math.pi * t * (3.0 + t * t)))
    return math.pi * a * a


# ------------------------------------------------------------------ the pattern
#: The pattern sizes (um) the calculation takes: 1 nm to 1 m (volumes go as L^3).
MIN_SIZE_UM, MAX_SIZE_UM = 1e-3, 1e6


@dataclass(frozen=True)
class FourPad:
    """A four-pad pattern (docs/physics.md §6) and its wetting.

    Attributes:
        size_um: outer side L of the pattern, gaps included, um.
        gap_um: width g of the cross-shaped gap, um (0 < g < L).
        pad_angle_deg, substrate_angle_deg: static contact angles, degrees; the pads must
            wet better than the substrate.
    """

    size_um: float
    gap_um: float
    pad_angle_deg: float
    substrate_angle_deg: float

    def __post_init__(self) -> None:
        L = positive("--size (pattern size L)", self.size_um, "um")
        g = positive("--gap", self.gap_um, "um")
        if (
            not MIN_SIZE_UM <= L <= MAX_SIZE_UM
        ):  # volumes go as L^3: 1e300 overflows, 1e-300 underflows to 0 nl
            raise InputError(
                f"--size {L:g} um is outside {MIN_SIZE_UM:g} to {MAX_SIZE_UM:g} um (1 nm to 1 m), where the "
                "volumes (L^3) stay numbers; give the pattern's outer side in um"
            )
        if g < MIN_SIZE_UM:  # a gap of 1e-200 um divides by zero in the gap's wetting
            raise InputError(
                f"--gap {g:g} um is below {MIN_SIZE_UM:g} um (1 nm); give the width of the gap in um"
            )
        if g >= L:
            raise InputError(
                f"--gap {g:g} um must be smaller than --size {L:g} um (the four pads are (L - g) / 2 wide)"
            )
        for flag, v in (
            ("--pad-angle", self.pad_angle_deg),
            ("--substrate-angle", self.substrate_angle_deg),
        ):
            if not (isinstance(v, int | float) and 0 < v < 180):
                raise InputError(f"{flag} must be a contact angle in (0, 180) degrees, got {v!r}")
        if self.pad_angle_deg >= self.substrate_angle_deg:
            raise InputError(
                f"--pad-angle {self.pad_angle_deg:g} deg must be smaller than --substrate-angle {self.substrate_angle_deg:g} deg: "
                "with pads no more wettable than the substrate nothing holds the drop on the pads, so there is no critical volume"
            )

    @property
    def pad_um(self) -> float:
        return (self.size_um - self.gap_um) / 2.0

    @property
    def cos_pad(self) -> float:
        return math.cos(math.radians(self.pad_angle_deg))

    @property
    def cos_substrate(self) -> float:
        return math.cos(math.radians(self.substrate_angle_deg))

    # Wetted pad area of a centred square footprint of side s (um^2).
    def middle_pad_area(self, s):
        return (np.clip(s, self.gap_um, self.size_um) - self.gap_um) ** 2

    def one_pad_area(self, s):
        return np.minimum(s, self.pad_um) ** 2

    def energy_um2(self, volume_um3, s, kind: str):
        """Energy / gamma (um^2) of a drop of volume V on a centred square footprint of side s."""
        area = self.middle_pad_area(s) if kind == "middle" else self.one_pad_area(s)
        return (
            cap_area_um2(volume_um3, s * s)
            - self.cos_pad * area
            - self.cos_substrate * (s * s - area)
        )

    def footprint_bounds(self, kind: str) -> tuple[float, float]:
        """Smallest and largest footprint side (um) of each kind of drop."""
        if kind == "middle":
            return self.gap_um, 4.0 * self.size_um
        return 1e-4 * self.pad_um, self.pad_um + self.gap_um


def minimise_footprint(
    pattern: FourPad, volumes_um3: np.ndarray, kind: str
) -> tuple[np.ndarray, np.ndarray]:
    """Lowest energy / gamma (um^2) and its footprint side (um) for each volume (um^3).

    A logarithmic grid of sides (pad edges, the gap and the pattern edge included
    exactly) finds the basin; golden-section search refines it to ~1e-9 of the side.
    """
    v = np.asarray(volumes_um3, dtype=np.float64)
    lo, hi = pattern.footprint_bounds(kind)
    kinks = [pattern.pad_um, pattern.pad_um + pattern.gap_um, pattern.size_um, pattern.gap_um]
    grid = np.unique(
        np.concatenate(
            [np.geomspace(lo, hi, FOOTPRINT_POINTS), [k for k in kinks if lo <= k <= hi]]
        )
    )
    e = pattern.energy_um2(v[:, None], grid[None, :], kind)
    i = np.argmin(e, axis=1)
    a, b = grid[np.maximum(i - 1, 0)], grid[np.minimum(i + 1, grid.size - 1)]
    for _ in range(50):  # golden-section search, both inner points recomputed
        c, d = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)
        left = pattern.energy_um2(v, c, kind) < pattern.energy_um2(v, d, kind)
        a, b = np.where(left, a, c), np.where(left, d, b)
    s = (a + b) / 2.0
    e_best = pattern.energy_um2(v, s, kind)
    g_best = e[np.arange(v.size), i]  # the grid point itself (a kink lies on the grid)
    take_grid = g_best < e_best
    return np.where(take_grid, g_best, e_best), np.where(take_grid, grid[i], s)


def min_plus(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``c[k] = min_j a[j] + b[k - j]`` and the minimising ``j`` (arrays on one uniform grid)."""
    n = a.size
    k = np.arange(n)
    j = np.arange(n)
    total = a[None, :] + np.where(
        k[:, None] >= j[None, :], b[np.clip(k[:, None] - j[None, :], 0, n - 1)], np.inf
    )
    arg = np.argmin(total, axis=1)
    return total[k, arg], arg


@dataclass(frozen=True)
class Energies:
    """Energies / gamma (um^2) on a uniform volume grid ``volumes_um3`` (from 0)."""

    volumes_um3: np.ndarray
    middle: np.ndarray
    middle_side_um: np.ndarray
    one: np.ndarray
    one_side_um: np.ndarray
    split: np.ndarray
    split_volumes_um3: np.ndarray  # (n, 4): the best split of each volume


def energies(pattern: FourPad, v_max_um3: float, points: int = GRID_POINTS) -> Energies:
    """Whole-pattern drop, one-pad drop and best split on ``points + 1`` volumes in [0, v_max]."""
    v = np.linspace(0.0, v_max_um3, points + 1)
    mid, mid_s = minimise_footprint(pattern, v[1:], "middle")
    one, one_s = minimise_footprint(pattern, v[1:], "one")
    one = np.concatenate([[0.0], one])
    two, j2 = min_plus(one, one)
    four, j4 = min_plus(two, two)
    k = np.arange(v.size)
    first, second = j4, k - j4  # volumes (grid steps) of the two pairs
    vols = np.stack([j2[first], first - j2[first], j2[second], second - j2[second]], axis=1) * (
        v[1] - v[0]
    )
    return Energies(
        v,
        np.concatenate([[np.inf], mid]),
        np.concatenate([[pattern.gap_um], mid_s]),
        one,
        np.concatenate([[0.0], one_s]),
        four,
        vols,
    )


def _crossing(en: Energies) -> float | None:
    """Smallest volume (um^3) above which the whole-pattern drop is never above the split."""
    d = en.middle - en.split
    above = np.flatnonzero(d > 0)
    if above.size == 0 or above[-1] == d.size - 1:
        return None
    i = above[-1]
    v0, v1 = en.volumes_um3[i], en.volumes_um3[i + 1]
    return float(v0 + (v1 - v0) * d[i] / (d[i] - d[i + 1]))


@dataclass(frozen=True)
class CriticalVolume:
    """The result of :func:`critical_volume` (units in the names; JSON by :meth:`to_json`)."""

    pattern: FourPad
    critical_volume_nl: float
    energies: Energies

    @property
    def volume_um3(self) -> float:
        return self.critical_volume_nl * UM3_PER_NL

    @property
    def dimensionless_volume(self) -> float:
        """``V_ND = V^(2/3) / A`` with the pattern area ``A = L^2`` (docs/physics.md §8)."""
        return self.volume_um3 ** (2.0 / 3.0) / self.pattern.size_um**2

    def _at(self, values: np.ndarray) -> float:
        return float(np.interp(self.volume_um3, self.energies.volumes_um3, values))

    def middle_drop(self) -> dict:
        """The whole-pattern drop at the critical volume: footprint, angle, pinning."""
        p, v = self.pattern, self.volume_um3
        s = float(minimise_footprint(p, np.array([v]), "middle")[1][0])
        return {
            "footprint_side_um": s,
            "apparent_angle_deg": float(cap_angle_deg(v, s * s)),
            "pinned_at_pattern_edge": bool(abs(s - p.size_um) < EDGE_REL_TOL * p.size_um),
        }

    def split_drops(self) -> list[dict]:
        """The best split just below the critical volume: one entry per wetted pad."""
        en, p = self.energies, self.pattern
        i = max(int(np.searchsorted(en.volumes_um3, self.volume_um3)) - 1, 1)
        out = []
        for vol in sorted(en.split_volumes_um3[i], reverse=True):
            if vol <= 0:
                continue
            s = float(minimise_footprint(p, np.array([vol]), "one")[1][0])
            out.append(
                {
                    "volume_nl": float(vol / UM3_PER_NL),
                    "footprint_side_um": s,
                    "apparent_angle_deg": float(cap_angle_deg(vol, s * s)),
                    "spills_past_pad": bool(s > p.pad_um * (1 + EDGE_REL_TOL)),
                    "touches_neighbour": bool(s >= (p.pad_um + p.gap_um) * (1 - EDGE_REL_TOL)),
                }
            )
        return out

    def to_json(self, surface_tension_N_m: float, density_kg_m3: float) -> dict:
        p = self.pattern
        from simulator.liquid._calculators import capillary_length_um

        lc = capillary_length_um(surface_tension_N_m, density_kg_m3)
        size = self.volume_um3 ** (1.0 / 3.0)
        bond = (size / lc) ** 2
        validity = [
            f"gravity neglected: the drop's size V^(1/3) = {size:.4g} um against the capillary length {lc:.4g} um "
            f"(Bond number {bond:.2g}{'; too large: treat the volume as a rough estimate' if bond > 0.1 else ''})",
            "surface tension does not enter: the volume holds for any liquid with these contact angles",
            "against the source's method run in Surface Evolver (docs/physics.md §8) the critical volume agrees within 15 % "
            "for pad angles of 30-88 deg and gaps of 5-20 %"
            + (
                "; outside that, treat it as rough (the centred drop can split into lobes on the pads' inner corners, "
                "which square footprints cannot represent)"
                if p.pad_angle_deg < 30 or p.gap_um > 0.25 * p.size_um
                else ""
            ),
            "static (Young) angles: contact-angle hysteresis, which lets a pad hold a drop up to its advancing angle, is not included",
        ]
        return {
            "critical_volume_nl": self.critical_volume_nl,
            "dimensionless_volume_V_ND": self.dimensionless_volume,
            "pattern": {
                "size_um": p.size_um,
                "gap_um": p.gap_um,
                "pad_um": p.pad_um,
                "relative_gap": p.gap_um / p.size_um,
                "area_um2": p.size_um**2,
                "pad_angle_deg": p.pad_angle_deg,
                "substrate_angle_deg": p.substrate_angle_deg,
            },
            "middle_drop": self.middle_drop(),
            "split_below_critical_volume": self.split_drops(),
            "energy_at_critical_volume_J": self._at(self.energies.middle)
            * surface_tension_N_m
            * UM2,
            "method": METHOD,
            "assumptions": list(ASSUMPTIONS),
            "validity": validity,
        }


def critical_volume(
    size_um: float,
    gap_um: float,
    pad_angle_deg: float,
    substrate_angle_deg: float,
    points: int = GRID_POINTS,
) -> CriticalVolume:
    """The critical volume (nl) of a four-pad pattern: see the module docstring.

    A first pass on a coarse volume grid brackets the crossing (the range doubles until
    the whole-pattern drop wins at its end); a second pass of ``points`` volumes up to
    1.25 times that estimate gives the answer.
    """
    pattern = FourPad(
        float(size_um), float(gap_um), float(pad_angle_deg), float(substrate_angle_deg)
    )
    v_max = 0.25 * pattern.size_um**3
    for _ in range(12):
        rough = _crossing(energies(pattern, v_max, 300))
        if rough is not None:
            break
        v_max *= 2.0
    else:
        raise InputError(
            "no critical volume found: the drop prefers to split at every volume up to "
            f"{v_max / UM3_PER_NL:.3g} nl; check the contact angles"
        )
    v_max = 1.25 * rough
    for _ in range(6):
        en = energies(pattern, v_max, points)
        v = _crossing(en)
        if v is not None:
            return CriticalVolume(pattern, v / UM3_PER_NL, en)
        v_max *= 1.5
    raise InputError("no critical volume found on the fine grid; check the contact angles")
