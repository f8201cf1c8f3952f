"""The liquid checks of a scene whose ``--volume`` was given (:func:`scene_warnings`).

A typed volume that makes a drop, not a film, is refused (:func:`check_scene_volume`); the
warnings name a volume below the critical volume of a four-pad pattern (recognised in any
mask: :func:`four_pad_geometry`), a pattern of several pads, a film too thick for the
thin-film picture, and placements at or beyond the overflow bias of a protruding pad
(:func:`placement_biases`); :func:`volume_note` says when a method ignores the volume.
The numbers come from :mod:`simulator.liquid`.
"""

from __future__ import annotations

import functools

import numpy as np

from foundation import InputError
from simulator.core import DYNAMIC_METHODS, UM3_PER_NL
from simulator.liquid._calculators import THIN_FILM_FRACTION, height_report, overflow_conditions
from simulator.physics import meniscus_height_um


# --------------------------------------------------------------------- pattern shape
def four_pad_geometry(mask) -> tuple[float, float] | None:
    """``(L, g)`` in um when ``mask`` is a 2 x 2 four-pad pattern (docs/physics.md §6), else None.

    Recognised from the pixels (any PNG or layout): four separate, filled, equal square
    pads on a 2 x 2 layout whose outer square is L and whose cross-shaped gap is g wide.
    """
    from scipy import ndimage

    labels, n = _label(mask.data >= 0.5)
    if n != 4:
        return None
    s = mask.um_per_px
    boxes = ndimage.find_objects(labels)
    sides, filled = [], []
    for i, (rows, cols) in enumerate(boxes):
        h, w = rows.stop - rows.start, cols.stop - cols.start
        sides += [h, w]
        filled.append(float((labels[rows, cols] == i + 1).sum()) / (h * w))
    r0 = min(b[0].start for b in boxes)
    r1 = max(b[0].stop for b in boxes)
    c0 = min(b[1].start for b in boxes)
    c1 = max(b[1].stop for b in boxes)
    tol = 1.5 + 0.02 * max(sides)  # px
    if min(filled) < 0.95 or max(sides) - min(sides) > tol or abs((r1 - r0) - (c1 - c0)) > tol:
        return None
    L = (r1 - r0 + c1 - c0) / 2 * s
    p = float(np.mean(sides)) * s
    g = L - 2 * p
    if g <= 0:
        return None
    for rows, cols in boxes:  # each pad in one corner of the outer square
        if not (
            (rows.start - r0 < tol or r1 - rows.stop < tol)
            and (cols.start - c0 < tol or c1 - cols.stop < tol)
        ):
            return None
    return L, g


def scene_critical_volume(scene, four_pad: tuple[float, float] | None = None):
    """The critical volume (:func:`simulator.liquid.critical_volume`'s result) of a scene's
    four-pad pattern (docs/physics.md §8) with the scene's pad and substrate angles: None when
    the pads do not wet better than the substrate (no drop prefers them) or the pattern is not
    a four-pad. ``four_pad``: its ``(L, g)`` in um when known exactly (a generated design),
    else recognised in the raster (:func:`four_pad_geometry`). InputError when the angles give
    no critical volume. Computed once per pattern and angles in a process (a sweep's points)."""
    m = scene.materials
    if m.pad_angle_deg >= m.substrate_angle_deg:
        return None
    fp = four_pad if four_pad is not None else four_pad_geometry(scene.pattern)
    if fp is None:
        return None
    cv = _critical_volume(
        float(fp[0]), float(fp[1]), float(m.pad_angle_deg), float(m.substrate_angle_deg)
    )
    if isinstance(cv, InputError):
        raise InputError(str(cv))
    return cv


@functools.lru_cache(maxsize=256)
def _critical_volume(size_um: float, gap_um: float, pad_deg: float, sub_deg: float):
    """:func:`simulator.liquid.critical_volume`, or its InputError (no crossing found)."""
    from simulator.liquid._critical_volume import critical_volume

    try:
        return critical_volume(size_um, gap_um, pad_deg, sub_deg)
    except InputError as err:
        return err


def pad_count(mask) -> int:
    """Number of separate wettable regions (pads) of ``mask`` (pixels at least half covered)."""
    return _label(mask.data >= 0.5)[1]


def _label(wet: np.ndarray) -> tuple[np.ndarray, int]:
    """The connected regions of ``wet`` (scipy's labels): in 16 bits when they fit (a quarter
    of the memory of a 16-megapixel pattern's default 64-bit-wide labels), else 32."""
    from scipy import ndimage

    # scipy takes a dtype for ``output`` (and then returns the labels); its stub takes arrays only
    try:
        labels, n = ndimage.label(wet, output=np.uint16)  # pyright: ignore[reportCallIssue, reportArgumentType]
    except RuntimeError:  # more regions than 16 bits can number
        labels, n = ndimage.label(wet, output=np.int32)  # pyright: ignore[reportCallIssue, reportArgumentType]
    return labels, int(n)


def _footprint_um(mask) -> tuple[float, float]:
    from patterns.geometry import footprint_um

    return footprint_um(mask)


# --------------------------------------------------------------------- scene checks
def check_scene_volume(scene) -> None:
    """A typed volume whose film ``h = V / A`` is thicker than the chip's smallest side: InputError."""
    w, ht = _footprint_um(scene.chip)
    require_film(scene.liquid.volume_nl, w, ht, scene.chip.area_um2)


def require_film(
    volume_nl: float,
    w_um: float,
    h_um: float,
    area_um2: float | None = None,
    what: str | None = None,
) -> float:
    """The film height ``h = V / A`` (um) of a typed volume under a ``w_um`` x ``h_um`` chip (wetted area
    ``area_um2``, default w x h), or InputError when it is thicker than the chip's smallest side."""
    v = volume_nl
    area = w_um * h_um if area_um2 is None else area_um2
    h = meniscus_height_um(v, area)
    side = min(w_um, h_um)
    if h > side:
        fit = THIN_FILM_FRACTION * side * area / UM3_PER_NL
        under = what or f"the {w_um:g} x {h_um:g} um chip"
        raise InputError(
            f"--volume {v:g} nl under {under} is a film h = V / A = {h:.6g} um thick, more than the "
            f"chip's smallest side ({side:g} um): a drop, not a film; if you meant {v:g} pl, give --volume {v / 1000:g} "
            f"(1 nl = 1e6 um^3); a thin film (h below {100 * THIN_FILM_FRACTION:g} % of the side) takes at most {fit:.3g} nl"
        )
    return h


def volume_note(scene, method: str) -> str | None:
    """A note when ``method`` does not use the droplet volume (None when it does)."""
    if (
        getattr(scene.liquid, "height_um", None) is not None
    ):  # the height is given: the volume sets nothing
        return (
            f"--volume {scene.liquid.volume_nl:g} nl is not used by the {method} method: --meniscus-height gives the "
            "liquid's height (the meniscus's and the dynamics' damping's); it is used here only for the liquid checks"
        )
    if method in DYNAMIC_METHODS or getattr(scene.effects, "meniscus", False):
        return None
    return (
        f"--volume {scene.liquid.volume_nl:g} nl is not used by the {method} method (only overdamped and inertial "
        "use it, and --meniscus for the height); it is used here only for the liquid checks"
    )


def placement_biases(poses) -> np.ndarray:
    """Per start, the larger of |x| and |y| (um): the overhang over a pad edge.

    ``poses``: an (N, 3) array of poses, one pose, or a start grid (its x and y axes;
    the twists do not change the bias)."""
    if hasattr(poses, "x_um") and hasattr(poses, "y_um"):
        return np.maximum.outer(
            np.abs(np.asarray(poses.y_um)), np.abs(np.asarray(poses.x_um))
        ).ravel()
    p = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    return np.max(np.abs(p[:, :2]), axis=1)


def scene_warnings(scene, biases_um=None, placed: str = "the start") -> list[str]:
    """One-line warnings about the scene's liquid, for a scene whose volume was given.

    * the volume is below the critical volume of a four-pad pattern (the drop may split
      onto single pads or leave one dry); a pattern of several other pads is flagged too;
    * the film ``h = V / A`` under the chip is thicker than the thin-film picture allows
      (not when the scene computes a finite meniscus);
    * for a scene with :class:`Topography` (a protruding pad): placement biases
      ``biases_um`` (per start, :func:`placement_biases`; or a function giving them, called
      only when needed) at or beyond the overflow bias
      of docs/physics.md §9, unless condition (1) or (2) rules overflow out.
    """
    out = []
    m, v = scene.materials, scene.liquid.volume_nl
    fp = four_pad_geometry(scene.pattern)
    if fp is not None:
        try:
            cv = scene_critical_volume(scene, fp)
        except InputError as err:
            cv = None
            out.append(f"critical volume of this four-pad pattern not found ({err})")
        if cv is not None and v < cv.critical_volume_nl:
            out.append(
                f"droplet {v:g} nl is below the critical volume {cv.critical_volume_nl:.3g} nl of this four-pad pattern "
                f"(L {fp[0]:g} um, gap {fp[1]:g} um, {m.pad_angle_deg:g}/{m.substrate_angle_deg:g} deg): it may split onto "
                "single pads or leave a pad dry (selfalign liquid critical-volume)"
            )
    elif fp is None and (n := pad_count(scene.pattern)) > 1:
        out.append(
            f"the pattern has {n} separate pads: one drop must touch them all; the critical volume is computed "
            "for 2 x 2 four-pad patterns only, so check this one another way"
        )
    w, ht = _footprint_um(scene.chip)
    # The scene's one height (the meniscus's and the damping's): V / A, or --meniscus-height when given.
    rep = height_report(
        v,
        scene.chip.area_um2,
        (w, ht),
        m.surface_tension_N_m,
        scene.liquid.density_kg_m3,
        height_um=scene.liquid_height_um,
    )
    h = rep["meniscus_height_um"]
    if not rep["thin_film_holds"] and not getattr(scene.effects, "meniscus", False):
        out.append(
            "thick film: "
            + "; ".join(rep["thin_film_notes"])
            + " (--meniscus models the finite height)"
        )
    topo = getattr(scene, "topography", None)
    if topo is not None:
        adv = topo.pad_advancing_deg
        if adv is None:  # the hysteresis window's advancing angle, else the static pad angle
            adv = getattr(m, "pad_advancing_deg", None) or m.pad_angle_deg
        c = overflow_conditions(
            topo.edge_angle_deg,
            adv,
            0.0 if topo.chip_angle_deg is None else topo.chip_angle_deg,
            0.0,
            h,
        )
        safe = c.edge_confines or (topo.chip_angle_deg is not None and c.chip_dewets)
        if not safe:
            xo = c.overflow_bias_um
            b = biases_um() if callable(biases_um) else biases_um
            b = np.zeros(1) if b is None else np.atleast_1d(np.asarray(b, dtype=np.float64))
            over = float(np.mean(b >= xo))
            if over > 0:
                unknown = (
                    ""
                    if topo.chip_angle_deg is not None
                    else " (chip angle not given: condition 2 not counted on)"
                )
                where = f"{placed} is" if b.size == 1 else f"{100 * over:.3g} % of {placed} are"
                out.append(
                    f"overflow: {where} placed at or beyond the overflow bias {xo:.3g} um of the protruding pad (edge "
                    f"{topo.edge_angle_deg:g} deg, pad advancing {adv:g} deg, h {h:.3g} um; docs/physics.md §9){unknown}"
                )
    return out
