"""The droplet's usable volume window of a pattern and chip, and the default volume.

:func:`volume_window` puts the droplet calculators of :mod:`simulator.liquid` together for
one scene (``selfalign liquid window``, and the evaluate report):

* **lower limits**: the critical volume of a four-pad pattern (recognised in the mask,
  :func:`~simulator.liquid.four_pad_geometry`; below it the drop may split onto single
  pads or leave one dry, docs/physics.md §8), and with a protruding pad
  (:class:`~simulator.liquid.Topography`) and a placement bias the overflow limit: the
  film whose overflow bias ``h / tan(edge - pad advancing)`` equals the bias
  (condition (3) of docs/physics.md §9 needs ``h > bias tan(edge - pad advancing)``),
  unless conditions (1) or (2) rule overflow out;
* **upper limit**: the thin-film limit, the volume whose film ``h = V / A`` is
  :data:`~simulator.liquid.THIN_FILM_FRACTION` of the chip's smallest side (and of the
  capillary length): beyond it the overlap model is off within about ``h`` of every
  feature (docs/physics.md §7).

:func:`default_volume_nl` is the volume a scene takes when none is given (``--volume``,
``[liquid] volume_nl``): the film ``h`` = :data:`DEFAULT_FILM_FRACTION` of the chip's
smallest side, half the thin-film limit (on the source's 730 um chip 19.5 nl, the source's
20 nl within 3 %).

Volumes in nl (1 nl = 1e6 um^3), lengths um, angles degrees.
"""

from __future__ import annotations

import math

from simulator.core import UM3_PER_NL
from simulator.liquid._calculators import THIN_FILM_FRACTION, capillary_length_um

#: The default film: ``h`` this share of the chip's smallest side (half the thin-film limit).
DEFAULT_FILM_FRACTION = 0.05


def default_volume_nl(area_um2: float, smallest_side_um: float) -> float:
    """The droplet volume (nl) of a scene that gives none: the film ``h = V / A`` of
    :data:`DEFAULT_FILM_FRACTION` of the chip's smallest side over its wetted area."""
    return DEFAULT_FILM_FRACTION * float(smallest_side_um) * float(area_um2) / UM3_PER_NL


def volume_window(scene, bias_um: float | None = None, biased: str = "the placement") -> dict:
    """The usable droplet volumes of ``scene`` (its pattern, chip, materials, topography):
    JSON-ready, units in the keys.

    Keys: ``lower_nl`` (the largest lower limit, None without one), ``upper_nl`` (the
    thin-film limit), ``usable`` (lower below upper), ``critical_volume_nl`` (None where the
    pattern has none: ``critical_volume_note`` says why), ``thin_film_limit_nl``,
    ``overflow_limit_nl`` (None where it does not apply: ``overflow_note``), the film
    heights of each (``*_film_um``), ``chip_area_um2``, ``smallest_side_um``, ``volume_nl``
    (the scene's) with its film ``film_um`` and ``in_window``, and ``default_volume_nl``
    (:func:`default_volume_nl`). ``bias_um``: the placement bias (um) the overflow limit
    is computed for; ``biased`` names it in the note.
    """
    from foundation import InputError
    from patterns.geometry import footprint_um
    from simulator.liquid._calculators import overflow_bias_um
    from simulator.liquid._warnings import four_pad_geometry, pad_count, scene_critical_volume

    m = scene.materials
    area = float(scene.chip.area_um2)
    side = float(min(footprint_um(scene.chip)))

    def film(v: float | None) -> float | None:
        return None if v is None else v * UM3_PER_NL / area

    # critical volume (four-pad patterns)
    cv, cv_note = None, None
    fp = four_pad_geometry(scene.pattern)
    if fp is not None:
        if m.pad_angle_deg < m.substrate_angle_deg:
            try:
                found = scene_critical_volume(scene, fp)
                assert found is not None  # a four-pad whose pads wet better than the substrate
                cv = found.critical_volume_nl
                cv_note = (
                    f"a four-pad pattern (L {fp[0]:g} um, gap {fp[1]:g} um, pad/substrate angles "
                    f"{m.pad_angle_deg:g}/{m.substrate_angle_deg:g} deg): below the critical volume the drop may split "
                    "onto single pads or leave a pad dry (docs/physics.md §8)"
                )
            except InputError as err:
                cv_note = f"a four-pad pattern, but its critical volume was not found ({err})"
        else:
            cv_note = "a four-pad pattern whose pads do not wet better than the substrate: no critical volume"
    else:
        n = pad_count(scene.pattern)
        cv_note = (
            "a single pad: one drop wets it, no critical volume"
            if n <= 1
            else f"{n} separate pads: the critical volume is computed for 2 x 2 four-pad patterns only"
        )
    # thin-film limit
    lc = capillary_length_um(m.surface_tension_N_m, scene.liquid.density_kg_m3)
    h_max = THIN_FILM_FRACTION * min(side, lc)
    thin = h_max * area / UM3_PER_NL
    thin_note = (
        f"the film h = V / A stays within {100 * THIN_FILM_FRACTION:g} % of the chip's smallest side ({side:g} um)"
        + (" and of the capillary length" if lc < side else "")
        + f": h at most {h_max:.4g} um over the {area:,.0f} um^2 chip (docs/physics.md §7)"
    )
    # overflow limit (protruding pads)
    over, over_note = None, "no protruding pad (give --edge-angle for the overflow check)"
    topo = getattr(scene, "topography", None)
    if topo is not None:
        adv = topo.pad_advancing_deg
        if adv is None:
            adv = getattr(m, "pad_advancing_deg", None) or m.pad_angle_deg
        edge = topo.edge_angle_deg
        if edge <= adv:
            over_note = f"condition (1) holds (edge {edge:g} deg <= pad advancing {adv:g} deg): no overflow at any volume"
        elif topo.chip_angle_deg is not None and edge < adv + topo.chip_angle_deg:
            over_note = (
                f"condition (2) holds (edge {edge:g} deg < pad advancing {adv:g} + chip {topo.chip_angle_deg:g} deg): "
                "the chip de-wets first, no overflow at any volume"
            )
        elif edge - adv >= 90:
            over_note = f"edge {edge:g} deg - pad advancing {adv:g} deg >= 90 deg: the liquid overflows at any bias and volume"
        elif bias_um is None:
            over_note = (
                "a protruding pad: give --bias UM (the placement bias) for the overflow limit"
            )
        else:
            b = abs(float(bias_um))
            h_over = b * math.tan(math.radians(edge - adv))
            over = h_over * area / UM3_PER_NL
            xo = overflow_bias_um(1.0, edge, adv)  # per um of film
            over_note = (
                f"{biased} at {b:.3g} um stays below the overflow bias h / tan(edge {edge:g} - pad advancing {adv:g} deg) "
                f"= {xo:.3g} h when h > {h_over:.4g} um (condition (3), docs/physics.md §9)"
            )
    lows = [v for v in (cv, over) if v is not None]
    lower = max(lows) if lows else None
    v = float(scene.liquid.volume_nl)
    return {
        "lower_nl": lower,
        "upper_nl": thin,
        "usable": lower is None or lower < thin,
        "critical_volume_nl": cv,
        "critical_volume_film_um": film(cv),
        "critical_volume_note": cv_note,
        "thin_film_limit_nl": thin,
        "thin_film_limit_film_um": h_max,
        "thin_film_note": thin_note,
        "overflow_limit_nl": over,
        "overflow_limit_film_um": film(over),
        "overflow_note": over_note,
        "bias_um": None if bias_um is None else abs(float(bias_um)),
        "chip_area_um2": area,
        "smallest_side_um": side,
        "volume_nl": v,
        "film_um": v * UM3_PER_NL / area,
        "in_window": (lower is None or v >= lower) and v <= thin,
        "default_volume_nl": default_volume_nl(area, side),
        "default_rule": f"the film h = {100 * DEFAULT_FILM_FRACTION:g} % of the chip's smallest side (half the thin-film limit)",
    }


def window_lines(w: dict, volume_given: bool | None = None) -> list[str]:
    """The window as printed lines (``selfalign liquid window``, the evaluate report): the
    window, each limit with its reasoning, the volume in use. ``volume_given``: whether
    the scene's volume was typed (True) or derived (False); None says neither."""
    lo, hi = w["lower_nl"], w["upper_nl"]
    if lo is None:
        head = f"usable droplet volume: up to {hi:.3g} nl (no lower limit applies: see below)"
    elif w["usable"]:
        head = f"usable droplet volume: {lo:.3g} to {hi:.3g} nl"
    else:
        head = f"no usable droplet volume: the lower limit {lo:.3g} nl is above the thin-film limit {hi:.3g} nl"
    cv = w["critical_volume_nl"]
    lines = [
        head,
        (
            f"  critical volume {cv:.3g} nl (film {w['critical_volume_film_um']:.3g} um): {w['critical_volume_note']}"
            if cv is not None
            else f"  critical volume: none, {w['critical_volume_note']}"
        ),
        f"  thin-film limit {hi:.3g} nl: {w['thin_film_note']}",
        (
            f"  overflow limit {w['overflow_limit_nl']:.3g} nl (film {w['overflow_limit_film_um']:.3g} um): {w['overflow_note']}"
            if w["overflow_limit_nl"] is not None
            else f"  overflow limit: none, {w['overflow_note']}"
        ),
    ]
    how = (
        "as given"
        if volume_given
        else f"derived from the chip: {w['default_rule']}"
        if volume_given is False
        else "the scene's"
    )
    lines.append(
        f"droplet volume {w['volume_nl']:.3g} nl ({how}; film {w['film_um']:.3g} um): "
        + ("inside the window" if w["in_window"] else "outside the window")
    )
    return lines
