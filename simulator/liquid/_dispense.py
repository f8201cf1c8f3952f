"""Where the process puts the droplet: the footprint a run starts from (``--dispense``).

``chip``: the liquid comes in under the chip and wets what it reaches (the pads within the
substrate reach ``d_s`` of the chip at its start), the inward branch.

``pattern`` (the droplet dispensed on the pattern before the chip is released onto it):
the pads the droplet wets before the chip touches it (docs/physics.md §3.5):

* a four-pad pattern (recognised from its pixels, :func:`four_pad_geometry`) at or above
  its critical volume (:func:`critical_volume`): one drop over the whole pattern, every
  pad wet;
* a four-pad below it: the drop splits into the drops the calculator finds just below the
  critical volume (:meth:`CriticalVolume.split_drops`, one per wetted pad), on the pads
  nearest the dispense point;
* any other pattern: the pads that a spherical cap of the droplet's volume, resting at
  the pads' contact angle and centred on the dispense point (the pattern's centre unless
  ``dispense_at_um`` is given), reaches: its footprint radius
  ``R = (3 V sin^3 t / (pi (2 - 3 cos t + cos^3 t)))^(1/3)``. The cap is the drop's shape
  before it feels the pattern's edges (gravity neglected, as everywhere in the model); a
  pad it touches wets, and the liquid then spreads over that pad.

The chip, released at its start, then takes that footprint through the relay at the start
pose (:meth:`simulator.landscape.FootprintPlanes.next_state`): wet pads beyond the reach
of the chip's wall dry at once.
"""

from __future__ import annotations

import math

import numpy as np

from foundation import InputError


def pad_distances_um(labels: np.ndarray, n_pads: int, um_per_px: float, at_um) -> np.ndarray:
    """(n_pads,) um: each pad's nearest pixel (its centre) to the point ``at_um`` (x, y um
    from the pattern's centre, y up), pads labelled 1..n in ``labels``.

    The nearest is the pixel holding the point, or a pixel on the pad's edge (one with a
    4-neighbour outside it): an inner pixel has a neighbour in the pad one pixel nearer
    along the axis where the point lies more than half a pixel off. Only those few pixels'
    distances are computed (the 4000 um four-pad at 2 um/px: 0.46 -> 0.05 s), and their
    minimum is the one over every pixel of the pad, bit for bit (tested)."""
    h, w = labels.shape
    s = um_per_px
    x0, y0 = float(at_um[0]), float(at_um[1])
    out = np.pad(labels, 1)
    edge = (
        (out[:-2, 1:-1] != labels)
        | (out[2:, 1:-1] != labels)
        | (out[1:-1, :-2] != labels)
        | (out[1:-1, 2:] != labels)
    )
    edge &= labels > 0
    r_at, c_at = math.floor(h / 2 - y0 / s), math.floor(x0 / s + w / 2)
    if 0 <= r_at < h and 0 <= c_at < w:
        edge[r_at, c_at] = labels[r_at, c_at] > 0
    rr, cc = np.nonzero(edge)
    d = np.hypot((cc + 0.5 - w / 2) * s - x0, (h / 2 - rr - 0.5) * s - y0)
    nearest = np.full(n_pads, np.inf)
    np.minimum.at(nearest, labels[rr, cc] - 1, d)
    return nearest


def dispensed_wet(scene, labels: np.ndarray, n_pads: int, at_um=None) -> tuple[np.ndarray, str]:
    """(wet pads, why) of the ``pattern`` protocol for ``scene`` (module docstring): a
    (n_pads,) boolean array in label order (1..n) and one sentence for reports."""
    from simulator.liquid._critical_volume import critical_volume
    from simulator.liquid._warnings import four_pad_geometry
    from simulator.physics import cap_radius_um

    m = scene.materials
    v = scene.liquid.volume_nl
    x0, y0 = (0.0, 0.0) if at_um is None else (float(at_um[0]), float(at_um[1]))
    nearest = pad_distances_um(labels, n_pads, scene.um_per_px, (x0, y0))
    four = four_pad_geometry(scene.pattern) if n_pads == 4 else None
    if four is not None:
        L, g = four
        cv = critical_volume(L, g, m.pad_angle_deg, m.substrate_angle_deg)
        if v >= cv.critical_volume_nl:
            return np.ones(n_pads, bool), (
                f"{v:g} nl is at or above the critical volume of the {L:.4g}/{g:.4g} um four-pad "
                f"({cv.critical_volume_nl:.3g} nl): one drop wets all four pads"
            )
        drops = len(cv.split_drops())
        wet = np.zeros(n_pads, bool)
        wet[np.argsort(nearest, kind="stable")[: max(drops, 1)]] = True
        return wet, (
            f"{v:g} nl is below the critical volume of the {L:.4g}/{g:.4g} um four-pad "
            f"({cv.critical_volume_nl:.3g} nl): the drop splits onto {max(drops, 1)} pad(s) nearest the dispense point"
        )
    r = cap_radius_um(v, m.pad_angle_deg)
    wet = nearest <= r
    if not wet.any():
        raise InputError(
            f"--dispense pattern: a {v:g} nl drop at ({x0:g}, {y0:g}) um (a cap of radius {r:.4g} um at the "
            f"pads' {m.pad_angle_deg:g} deg) touches no pad; give --dispense-at X,Y on a pad, or --dispense chip"
        )
    return wet, (
        f"a {v:g} nl cap at ({x0:g}, {y0:g}) um reaches {r:.4g} um (at the pads' {m.pad_angle_deg:g} deg): "
        f"it wets {int(wet.sum())} of {n_pads} pads"
    )


def dispensed_footprint(scene, labels: np.ndarray, n_pads: int) -> tuple[np.ndarray, str]:
    """(wet pads, why) before the chip arrives, for ``scene``'s protocol: :func:`dispensed_wet`
    for ``pattern``, no pad for ``chip`` (the liquid comes in under the chip)."""
    if scene.dispense == "pattern":
        return dispensed_wet(scene, labels, n_pads, scene.liquid.dispense_at_um)
    return np.zeros(n_pads, bool), (
        "the liquid comes in under the chip: it wets the pads the chip's liquid reaches"
    )
