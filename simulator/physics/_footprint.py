"""The liquid's footprint as a state of the run: which pads the liquid wets.

docs/physics.md §3.5 states the model; this module holds its rules and constants.

The finite meniscus with free contact lines (:mod:`simulator.physics`, the wall profile)
writes the energy as a sum over the pattern's pixels, ``Delta_gamma * sum_p f(s(p)) w(p)``
with ``s`` the distance from the chip's outline. That sum is exact for a pad edge with the
pad on the chip's side. It has no memory: a pad across a dry gap pulls from ``d_p`` in,
although the liquid's foot waits on the substrate until it touches the pad (at ``d_s``),
and a pad the chip leaves stops pulling at ``d_p``, although liquid left on it stays joined
to the chip by a wall until that wall's angle falls below the pad's receding angle.

The state is one bit per pad (a connected region of the pattern): wet or dry. Along one
ray from the chip's edge across a gap of width ``D`` to a pad, with flat walls
(docs/physics.md §3.3), the line stands on the substrate at ``d_s`` while the pad is dry,
and on the pad while it is wet. Minimising the wall over the line's position:

* a dry pad adds nothing, and becomes wet when the liquid's foot reaches it:
  some pixel of the pad within ``d_s`` of the chip (the snap Surface Evolver's inward
  path shows);
* a wet pad that the chip still covers (some pixel with ``s <= 0``) adds the wall
  profile's term, ``Delta_gamma * sum_{p in pad} f(s(p))``;
* a wet pad the chip has left across a gap ``D`` adds ``Delta_gamma (F_inf - D)`` per unit
  length of the chip's edge facing it, with ``F_inf = int_0^inf f(s) ds``: the full
  overlap force ``|Delta_gamma|`` per unit length pulls it back while the wall holds
  (the two forms agree for ``0 <= D <= d_s``, where the state switches between them);
  written over the pad's pixels this is
  ``Delta_gamma [N(b) - (b - F_inf) l(b)]`` for any ``b`` beyond the pad's near edge, with
  ``N(d)`` the pad's area within ``d`` of the chip and ``l(d) = dN/dd`` the length of the
  line ``s = d`` on the pad (exact for a pad at least ``b - D`` deep along the chip's
  normal; a narrower pad's far edge inside ``b`` takes from it);
* a wet pad becomes dry when none of it lies within the reach ``d_r = h cot(theta_r)``
  of the chip (``theta_r`` the pad's receding angle; the pad's own angle without
  hysteresis, so ``d_r = d_p``).

So each pad is a relay on its distance from the chip, with the hysteresis band
``d_s < D <= d_r``; where the chip is in that band, the state is what the history made it.

Pads behind one another (the shadow rule). Along a ray from the chip's edge the liquid
wall runs to the furthest wet pad it is joined to; a nearer pad under that wall is covered
by the liquid and has no line of its own on that ray. With a wet near pad ``A`` the chip
still covers and a wet far pad ``B`` it has left (``B`` on its bridged term), the ray's
energy is ``A``'s pixels counted whole up to the bridge (the strip of ``A`` outside the
chip is wetted pad, weight 1 instead of ``f(s)``) plus ``B``'s bridged term: the force
along the ray is the single edge's ``|Delta_gamma|`` (without the rule ``A``'s own trailing
line pulls too, up to twice that). The correction is a pairwise term, summed by state where
both pads are wet, ``Delta_gamma sum_{p in A, upstream of B} (N_b(s) - f(s))`` over the pixels
of ``A`` that a ray along the chip edge's outward normal carries on to ``B``
(:func:`upstream_of`), with ``N_b`` the count to the bridged term's band (``1 - f`` up to
it): a correlation of that part of ``A`` with the chip's footprint ``N_b - f`` kept on the
side of the chip whose normal the ray follows. Assumptions: rays along the chip edge's
normal (the signed distance's gradient, one of the chip's four sides: exact on a rectangular
chip's sides, its corners split on the diagonal), cast along the pattern's axis nearest that
normal (exact at zero twist; at a twist ``alpha`` the shadow's side edges are off by
``tan(alpha)`` times the gap); a near pad the chip has left keeps its own bridged term (it
would need the near pad narrower along the ray than ``d_r`` less the gap); pads in a row two
deep at most (three pads on one ray count the nearest one's strip twice).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simulator.core import UM3_PER_NL
from simulator.physics._meniscus import WallProfile

#: The two protocols of ``--dispense`` (scene key ``dispense``): the droplet on the pattern
#: before the chip arrives, or the liquid coming in under the chip.
DISPENSE = ("pattern", "chip")

#: What ``--dispense`` accepts: the two protocols, and ``none`` for the stateless footprint
#: (every pad counted by its distance from the chip, the model before the state existed).
DISPENSE_CHOICES = (*DISPENSE, "none")

#: The protocol of a scene that names none and whose meniscus has free contact lines (the
#: source's experiments, and most droplet processes, dispense the droplet on the pattern).
DEFAULT_DISPENSE = "pattern"

#: Width (px) of the smooth steps of the count footprints (:class:`StepProfile`), and of the
#: band whose difference gives the line length ``l(d_r)``.
STEP_PX = 2.0

#: A pad counts as reached at a pose when its area within the distance is at least this
#: many pixels (half a pixel: the smooth steps put a pad edge exactly on the line at 0.5 a pixel
#: of edge).
TOUCH_PX2 = 0.5


@dataclass(frozen=True)
class StepProfile(WallProfile):
    """A chip footprint that counts the pattern within ``at_px`` of the chip's outline:
    1 for ``s <= at_px - STEP_PX / 2``, 0 beyond ``at_px + STEP_PX / 2``, linear between
    (smooth enough for the rotator's splines, which interpolate it over the band of
    :attr:`substrate_reach_px` to :attr:`pad_reach_px`). Correlated with a pad, it gives
    ``N(d)``, the pad's area within ``d`` of the chip."""

    at_px: float = 0.0

    @property
    def substrate_reach_px(self) -> float:
        return self.at_px - STEP_PX / 2

    @property
    def pad_reach_px(self) -> float:
        return self.at_px + STEP_PX / 2

    def __call__(self, s_px: np.ndarray) -> np.ndarray:
        s = np.asarray(s_px, float)
        return np.clip((self.at_px + STEP_PX / 2 - s) / STEP_PX, 0.0, 1.0)


@dataclass(frozen=True)
class FootprintRules:
    """The reaches (px) of one scene's footprint relay (module docstring).

    profile: the scene's wall profile. receding_deg: the pads' receding angle (their Young
    angle without hysteresis). d_s: where a dry pad is reached. d_r: ``h cot(theta_r)``,
    beyond which a wet pad dries. f_inf: ``int_0^inf f(s) ds`` of the wall profile.
    """

    profile: WallProfile
    receding_deg: float
    d_s: float
    d_r: float
    f_inf: float

    @classmethod
    def of(cls, profile: WallProfile, receding_deg: float | None = None) -> FootprintRules:
        pad_deg = math.degrees(math.acos(max(-1.0, min(1.0, profile.cos_pad))))
        rec = pad_deg if receding_deg is None else float(receding_deg)
        d_s = profile.substrate_reach_px
        d_r = max(profile.reach_px(math.cos(math.radians(rec))), d_s + STEP_PX)
        # F_inf: 1 up to d_s, the ramp to d_p (quadrature on 1/64 px: the profile is smooth there)
        d_p = profile.pad_reach_px
        if d_p > d_s:
            s = np.linspace(d_s, d_p, max(65, int(64 * (d_p - d_s)) + 1))
            ramp = float(np.trapezoid(profile(s), s))
        else:
            ramp = 0.0
        return cls(profile, rec, float(d_s), float(d_r), max(d_s, 0.0) + ramp)

    @property
    def band_px(self) -> float:
        """Where the bridged term's band lies (px): two steps beyond ``d_r``, so that a wet pad
        (some of it within ``d_r``, which the smooth step counts up to ``d_r + STEP_PX / 2``)
        never has its near edge inside the band's steps (``b -+ STEP_PX / 2``, each
        ``STEP_PX`` wide)."""
        return self.d_r + 2 * STEP_PX

    def count_profiles(self) -> dict[str, StepProfile]:
        """The count footprints the relay and the bridged term need, by name: ``N(0)``
        (the chip covers the pad), ``N(d_s)`` (reached), ``N(d_r)`` (within reach), and
        ``N(b -+ STEP_PX / 2)`` at ``b`` = :attr:`band_px` (their mean is ``N(b)``, their
        difference over ``STEP_PX`` the line length ``l(b)``: the bridged term is
        ``Delta_gamma [N(b) - (b - F_inf) l(b)]``, the same for any ``b`` beyond the pad's
        near edge)."""
        p = self.profile
        base = dict(h_px=p.h_px, cos_pad=p.cos_pad, cos_substrate=p.cos_substrate)
        b = self.band_px
        return {
            "covered": StepProfile(**base, at_px=0.0),
            "reached": StepProfile(**base, at_px=self.d_s),
            "within": StepProfile(**base, at_px=self.d_r),
            "band_in": StepProfile(**base, at_px=b - STEP_PX / 2),
            "band_out": StepProfile(**base, at_px=b + STEP_PX / 2),
        }

    @property
    def margin_px(self) -> int:
        """Pixels beyond the chip the state's footprints reach (the widest count's)."""
        return max(self.profile.margin_px, self.count_profiles()["band_out"].margin_px)


def relay(wet: np.ndarray, reached: np.ndarray, within_reach: np.ndarray) -> np.ndarray:
    """The pads' state after the chip arrives at a pose: a pad reached by the liquid's foot
    is wet; a wet pad stays wet while some of it lies within the reach ``d_r``; every other
    pad is dry. ``wet``, ``reached``, ``within_reach``: (pads,) booleans."""
    wet = np.asarray(wet, bool)
    return np.asarray(reached, bool) | (wet & np.asarray(within_reach, bool))


#: The pattern's axes a shadow is cast along (:func:`upstream_of`): +x, +y, -x, -y (y up),
#: index k at angle k * 90 deg.
AXES = ((1, 0), (0, 1), (-1, 0), (0, -1))


def upstream_of(pad: np.ndarray, k: int) -> np.ndarray:
    """The pixels (of an image y down, like ``pad``) from which a ray along the pattern's axis
    ``k`` (:data:`AXES`) reaches ``pad`` beyond them: the shadow rule's upstream side of a far
    pad (module docstring), booleans."""
    b = np.asarray(pad) > 0
    out = np.zeros(b.shape, bool)
    if k == 0:  # +x: some pad pixel further right on the row
        out[:, :-1] = np.logical_or.accumulate(b[:, :0:-1], axis=1)[:, ::-1]
    elif k == 2:  # -x: further left
        out[:, 1:] = np.logical_or.accumulate(b[:, :-1], axis=1)
    elif k == 1:  # +y: further up, rows above
        out[1:] = np.logical_or.accumulate(b[:-1], axis=0)
    elif k == 3:  # -y: rows below
        out[:-1] = np.logical_or.accumulate(b[:0:-1], axis=0)[::-1]
    else:
        raise ValueError(f"axis index must be 0..3, got {k!r}")
    return out


#: Step (deg) of the shadow's direction at a twist (:func:`shadow_residual_deg`): the rays
#: follow the chip side's own normal, rounded to this step, so the shadow's side edges are
#: off by at most ``tan(SHADOW_STEP_DEG / 2)`` times the gap (1.7 um per 100 um).
SHADOW_STEP_DEG = 2.0


def shadow_residual_deg(twist_deg) -> np.ndarray:
    """The angle (deg) between the chip side facing a pattern axis and that axis at the
    twist ``twist_deg``: the twist less its nearest multiple of 90 deg, in [-45, 45], rounded
    to :data:`SHADOW_STEP_DEG` (the shadow is cast along ``axis * 90 deg`` plus it)."""
    t = np.asarray(twist_deg, float)
    r = t - 90.0 * np.rint(t / 90.0)
    return np.round(np.rint(r / SHADOW_STEP_DEG) * SHADOW_STEP_DEG, 9) + 0.0


def ray_coordinates(rows, cols, shape, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(ray index, distance along it, px) of pixels (``rows``, ``cols`` of an image of
    ``shape``, y down) for rays at ``angle_deg`` from +x (y up), one pixel wide: pixels share
    a ray where their centres lie within half a pixel of one line across it. Measured from
    the image's centre, so the rays of a mirrored image are the mirrored rays (at ``-angle``
    for an image upside down), and exact along the axes."""
    k = round(angle_deg / 90.0)
    if abs(angle_deg - 90.0 * k) < 1e-9:
        ca, sa = AXES[k % 4]
    else:
        a = math.radians(angle_deg)
        ca, sa = math.cos(a), math.sin(a)
    h, w = shape
    x = np.asarray(cols, float) + 0.5 - w / 2
    y = h / 2 - np.asarray(rows, float) - 0.5
    return np.floor(-sa * x + ca * y + 0.5).astype(np.int64), ca * x + sa * y


def upstream_along(pad: np.ndarray, angle_deg: float) -> np.ndarray:
    """The pixels (of an image y down, like ``pad``) from which a ray at ``angle_deg`` from
    +x (y up) reaches ``pad`` beyond them: the shadow rule's upstream side of a far pad
    along the chip side's normal (module docstring), booleans. A pixel is upstream where
    some pad pixel lies further along its ray (:func:`ray_coordinates`); at multiples of
    90 deg this is :func:`upstream_of`."""
    b = np.asarray(pad) > 0
    if not b.any():
        return np.zeros(b.shape, bool)
    rows, cols = np.mgrid[0 : b.shape[0], 0 : b.shape[1]]
    ray, along = ray_coordinates(rows, cols, b.shape, angle_deg)
    lo = ray.min()
    far = np.full(ray.max() - lo + 1, -np.inf)
    np.maximum.at(far, ray[b] - lo, along[b])
    return along < far[ray - lo]


def cap_radius_um(volume_nl: float, angle_deg: float) -> float:
    """The footprint radius (um) of a spherical cap of ``volume_nl`` resting at contact
    angle ``angle_deg``: ``V = pi R^3 (2 - 3 cos t + cos^3 t) / (3 sin^3 t)``."""
    t = math.radians(angle_deg)
    shape = math.pi * (2 - 3 * math.cos(t) + math.cos(t) ** 3) / (3 * math.sin(t) ** 3)
    return (volume_nl * UM3_PER_NL / shape) ** (1.0 / 3.0)
