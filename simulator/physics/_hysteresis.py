"""Contact-angle hysteresis: contact lines that slide over a pad pin, so a chip can stop short.

A contact line that slides over a surface stays put while its contact angle lies between
the surface's receding and advancing angles, ``theta_r <= theta <= theta_a``. When a chip
moves, such a line on its leading side advances and one on its trailing side recedes;
the most force the pair can hold back, per unit length of line across the motion, is
the difference of their Young projections::

    f_pin = gamma (cos theta_r - cos theta_a)        (N/m, >= 0)

(Furmidge's sliding-drop criterion), ``f_pin / 2`` for each line. Summed over the whole
outline (:func:`pinning`, the bound if every line slid)::

    P_x = f_pin / 2 * oint |n_x| ds      (= f_pin * height of a rectangular chip)
    P_y = f_pin / 2 * oint |n_y| ds      (= f_pin * width)
    P_t = f_pin / 2 * oint |(z x r) . n| ds   (N m; = f_pin L^2 / 2 for a square of side L)

Which lines slide (docs/physics.md §5.3, :func:`sliding_shares`). A line held by an
edge does not slide: its angle changes within the edge's Gibbs window and the energy
model already holds that spring (the ``K_h`` blur, the wall profile's ramp), so only
lines that slide over a pad add the pad's hysteresis:

* the chip's own edge holds the top of every wall (a sharp edge pins): never;
* pinned scenes (``--pinned``, a pad edge against a hydrophobic substrate): the foot of
  every wall is held by a pad edge, so nothing slides and the pinning is zero. At
  0.9 nl on a 200 um square (h = 22.5 um) the wall's angle at the pad edge stays within
  the pad's window [31, 180) deg for shifts below h cot 31 deg = 37 um;
* free lines (:class:`simulator.physics.WallProfile`): a line on a pad stands
  ``d_p = h cot theta_p`` beyond the chip and slides over the pad with the chip; one that
  a pad edge holds (the edge between ``d_s`` and ``d_p`` beyond the chip) does not; one on
  the substrate at ``d_s`` slides over the substrate, whose hysteresis the scene does not
  give (zero). Without a meniscus the line is at the chip's edge (``d_p = 0``).

Each element of the outline counts with the pattern's value where its free line would
stand on a pad, ``d_p`` beyond it along its normal, at the chip's *current* pose and with
zero on a pad the footprint state has dry (:func:`sliding_pinning_at`, the NumPy reference
of :func:`simulator.motion.pin_at`, which the steppers evaluate per pose). At rest on a
same-size pad the shares are 0 (free lines stand on the substrate), in a pad wider than the
chip by more than ``d_p`` 1, without a meniscus 1/2 (the outline lies on the pad's edge:
half of it moves over the pad either way); a chip near its pad's edge has that side's line
held by the edge. :func:`sliding_shares` and :func:`pin_per_index` are the nominal pose's
(the align tolerance and the error limit read them).

The steppers use the sliding lines' forces as friction (docs/physics.md §4, §5.3): a
gradient or dynamic run stops where the restoring force along every axis is at most its
pinning force at the current pose, ``|dE/dq_k| <= P_k(q)``, and the chip is at rest (the
dynamics carry the pinning as Coulomb friction); a greedy move is taken only if the energy
it releases exceeds the pinning work ``sum_k P_k |dq_k|``. With zero hysteresis, or a
pinned scene, every rule is the one without hysteresis exactly. Where lines slide and the well is a spring of stiffness ``k``, the chip stops
about ``P / k`` short: for free lines in a pad wider than the chip, where the wall
profile's force ``|Delta_gamma| L f(u)`` falls to ``f_pin L``, ``f(u) = f_pin /
|Delta_gamma|``.
"""

from __future__ import annotations

import math

import numpy as np

from foundation import InputError
from patterns.geometry import Mask
from simulator.core import UM, UM2


def parse_window(text: str, flag: str = "--hysteresis") -> tuple[float, float]:
    """``RECEDING:ADVANCING`` in degrees -> (receding, advancing), checked."""
    parts = str(text).split(":")
    try:
        r, a = (float(p) for p in parts)
    except ValueError:
        raise InputError(
            f"{flag} must be RECEDING:ADVANCING contact angles in degrees, e.g. 31:50, got {text!r}"
        ) from None
    return require_window(r, a, flag)


def require_window(
    receding_deg: float, advancing_deg: float, flag: str = "--hysteresis"
) -> tuple[float, float]:
    for name, v in (("receding", receding_deg), ("advancing", advancing_deg)):
        if not (isinstance(v, int | float) and math.isfinite(v) and 0 <= v <= 180):
            raise InputError(
                f"{flag}: the {name} angle must be a contact angle in [0, 180] degrees, got {v!r}"
            )
    if receding_deg > advancing_deg:
        raise InputError(
            f"{flag}: the receding angle {receding_deg:g} deg is larger than the advancing angle {advancing_deg:g} deg; "
            "give RECEDING:ADVANCING with receding <= advancing"
        )
    return float(receding_deg), float(advancing_deg)


def pinning_force_per_length(gamma_N_m: float, receding_deg: float, advancing_deg: float) -> float:
    """``gamma (cos theta_r - cos theta_a)`` in N/m."""
    return gamma_N_m * (
        math.cos(math.radians(receding_deg)) - math.cos(math.radians(advancing_deg))
    )


def _outline_elements(chip: Mask, piece_um: float):
    """The chip's outline as small elements: (midpoints (n, 2) um, outward normals (n, 2),
    |n_x| ds, |n_y| ds in um, |(z x r) . n| ds in um^2), from its exact geometry (segments cut
    into pieces of at most ``piece_um``) or, for an image, from the mask's pixel edges (each
    weighted by its jump)."""
    if chip.geometry is not None:
        import shapely
        from shapely.geometry.polygon import orient

        mids, normals, wx, wy, wt = [], [], [], [], []
        for poly in shapely.get_parts(chip.geometry):
            poly = orient(
                poly, 1.0
            )  # exterior counter-clockwise, holes clockwise: outward normal (dy, -dx)
            for ring in (poly.exterior, *poly.interiors):
                c = np.asarray(ring.coords)
                for p0, p1 in zip(c[:-1], c[1:], strict=True):
                    d = p1 - p0
                    n_pieces = max(1, int(math.ceil(float(np.hypot(*d)) / piece_um)))
                    t = np.linspace(0.0, 1.0, n_pieces + 1)
                    pts = p0[None, :] + t[:, None] * d[None, :]
                    dd = np.diff(pts, axis=0)
                    # |n_x| ds = |dy|, |n_y| ds = |dx|; (z x r) . n ds = (-y, x) . (dy, -dx) = -(r . dr),
                    # linear along a piece: g(t) = (p0 + t d) . d, integrated exactly as |g|.
                    g0 = np.einsum("ij,ij->i", pts[:-1], dd)
                    g1 = np.einsum("ij,ij->i", pts[1:], dd)
                    same = g0 * g1 >= 0
                    with np.errstate(invalid="ignore", divide="ignore"):
                        cross = (g0 * g0 + g1 * g1) / (2 * np.abs(g1 - g0))
                    length = float(np.hypot(*d))
                    nrm = np.array([d[1], -d[0]]) / length if length > 0 else np.zeros(2)
                    mids.append(0.5 * (pts[:-1] + pts[1:]))
                    normals.append(np.broadcast_to(nrm, (n_pieces, 2)))
                    wx.append(np.abs(dd[:, 1]))
                    wy.append(np.abs(dd[:, 0]))
                    wt.append(np.where(same, 0.5 * (np.abs(g0) + np.abs(g1)), cross))
        if not mids:
            z = np.zeros((0, 2))
            return z, z, np.zeros(0), np.zeros(0), np.zeros(0)
        return (
            np.concatenate(mids),
            np.concatenate(normals),
            np.concatenate(wx),
            np.concatenate(wy),
            np.concatenate(wt),
        )
    s = chip.um_per_px
    a = np.asarray(chip.data, float)
    h, w = a.shape
    gx = np.diff(
        a, axis=1, prepend=0.0, append=0.0
    )  # (h, w + 1): jumps across vertical pixel edges
    gy = np.diff(
        a, axis=0, prepend=0.0, append=0.0
    )  # (h + 1, w): jumps down across horizontal ones
    xe = (np.arange(w + 1) - w / 2) * s  # vertical edges' x
    yc = (h / 2 - np.arange(h) - 0.5) * s  # rows' centre y (y up)
    xc = (np.arange(w) + 0.5 - w / 2) * s
    ye = (h / 2 - np.arange(h + 1)) * s  # horizontal edges' y
    iy, jx = np.nonzero(gx)
    vx = gx[iy, jx]  # > 0: the chip lies to the right, outward normal -x
    iy2, jx2 = np.nonzero(gy)
    vy = gy[iy2, jx2]  # > 0: the chip lies below (lower y), outward normal +y
    mids = np.concatenate([np.stack([xe[jx], yc[iy]], 1), np.stack([xc[jx2], ye[iy2]], 1)])
    normals = np.concatenate(
        [
            np.stack([-np.sign(vx), np.zeros_like(vx)], 1),
            np.stack([np.zeros_like(vy), np.sign(vy)], 1),
        ]
    )
    wx = np.concatenate([np.abs(vx) * s, np.zeros_like(vy)])
    wy = np.concatenate([np.zeros_like(vx), np.abs(vy) * s])
    # (z x r) . n ds: a vertical edge (normal x) at (xe, yc) contributes |y| |jump| s; a horizontal one |x|.
    wt = np.concatenate([np.abs(vx) * np.abs(yc[iy]) * s, np.abs(vy) * np.abs(xc[jx2]) * s])
    return mids, normals, wx, wy, wt


def contact_line_integrals_um(chip: Mask) -> tuple[float, float, float]:
    """(oint |n_x| ds, oint |n_y| ds in um, oint |(z x r) . n| ds in um^2) of the chip's outline,
    from its exact geometry or, for an image, from the mask's edges (pixel differences)."""
    _, _, wx, wy, wt = _outline_elements(chip, piece_um=math.inf)
    return float(wx.sum()), float(wy.sum()), float(wt.sum())


def line_dissipation_integrals_um(chip: Mask) -> tuple[float, float, float]:
    """(oint n_x^2 ds, oint n_y^2 ds in um, oint ((z x r) . n)^2 ds in um^3) of the chip's
    outline: what a line friction per unit length (normal to the line) adds to the damping
    along x, along y and in twist (docs/physics.md §4). A w x h rectangle: 2h, 2w and
    (w^3 + h^3) / 6 (a square of side L: 2L and L^3 / 3)."""
    if chip.geometry is not None:
        mids, normals, wx, wy, _ = _outline_elements(chip, piece_um=max(chip.um_per_px, 1e-3) / 4)
        ds = np.hypot(wx, wy)
        arm = normals[:, 1] * mids[:, 0] - normals[:, 0] * mids[:, 1]  # (z x r) . n
        # the arm changes by one per unit length along a straight piece: ds^2 / 12 beyond
        # the midpoint's square, exactly
        return (
            float((normals[:, 0] ** 2 * ds).sum()),
            float((normals[:, 1] ** 2 * ds).sum()),
            float(((arm**2 + ds**2 / 12.0) * ds).sum()),
        )
    mids, normals, wx, wy, _ = _outline_elements(chip, piece_um=math.inf)
    # pixel edges: a vertical edge (normal x) at height y adds y^2 ds, a horizontal one x^2 ds;
    # the edge's own extent adds s^2 / 12 per unit length
    s = chip.um_per_px
    arm2 = np.where(wx > 0, mids[:, 1] ** 2, mids[:, 0] ** 2) + s * s / 12.0
    return float(wx.sum()), float(wy.sum()), float((arm2 * (wx + wy)).sum())


def pinning_force_scale(scene) -> float:
    """``f_pin / 2`` in N/m: what one sliding line holds per unit length across the motion."""
    m = scene.materials
    return (
        pinning_force_per_length(m.surface_tension_N_m, m.pad_receding_deg, m.pad_advancing_deg) / 2
    )


def pinning(scene) -> tuple[float, float, float]:
    """(P_twist in N m, P_y in N, P_x in N) if *every* line of the chip's outline slid over a
    pad (the most the outline can hold), or zeros without hysteresis. The steppers use
    :func:`sliding_pinning`: only the lines that slide."""
    if not scene.effects.hysteresis:
        return 0.0, 0.0, 0.0
    f2 = pinning_force_scale(scene)
    sx, sy, st = contact_line_integrals_um(scene.chip)
    return f2 * st * UM2, f2 * sy * UM, f2 * sx * UM


def line_reach_um(scene) -> float:
    """Where a free contact line on a pad stands beyond the chip's edge, ``d_p = h cot theta_p``
    (um; :class:`simulator.physics.WallProfile`), 0 without a meniscus (the overlap model's
    line at the chip's edge)."""
    h = scene.meniscus_height_um
    if h is None:
        return 0.0
    from simulator.physics._meniscus import WallProfile

    m = scene.materials
    prof = WallProfile.from_angles(h, m.pad_angle_deg, m.substrate_angle_deg)
    return prof.pad_reach_px  # in the units of h: um


def sliding_shares(scene) -> tuple[float, float, float]:
    """(twist, y, x): the share of each axis's outline pinning (:func:`pinning`) whose contact
    lines slide over a pad when the chip rests at the nominal pose (0, 0, 0).

    Pinned scenes: none (0, 0, 0): every line is held by an edge, the chip's or the pad's.
    Free lines: an element of the outline slides over a pad when the pattern is pad where
    its free line stands, ``d_p`` beyond it (:func:`line_reach_um`); it counts with the
    pattern's value there (bilinear, 0 beyond the pattern; a grey pixel is partly pad).
    Where that is substrate, the line is held by a pad edge between ``d_s`` and ``d_p`` or
    stands on the substrate at ``d_s`` and slides over it: the substrate's hysteresis is not
    in the scene, so it adds nothing."""
    if scene.liquid.pinned:
        return 0.0, 0.0, 0.0
    from scipy.ndimage import map_coordinates

    s = scene.um_per_px
    mids, normals, wx, wy, wt = _outline_elements(scene.chip, piece_um=0.5 * s)
    p = mids + line_reach_um(scene) * normals
    pat = np.asarray(scene.pattern.data, float)
    hh, ww = pat.shape
    col = p[:, 0] / s + ww / 2 - 0.5
    row = hh / 2 - 0.5 - p[:, 1] / s
    on_pad = np.clip(map_coordinates(pat, [row, col], order=1, mode="constant", cval=0.0), 0.0, 1.0)

    def share(w):
        tot = float(w.sum())
        return float((w * on_pad).sum()) / tot if tot > 0 else 0.0

    return share(wt), share(wy), share(wx)


def pinning_lines(scene) -> dict | None:
    """What the per-pose pinning reads (docs/physics.md §5.3), host-side, or None where no
    line can slide over a pad: no hysteresis, a zero window, or a pinned scene.

    ``mids`` (n, 2) um and ``normals`` (n, 2): the outline's elements at the nominal pose,
    about the chip's centre (pieces of at most half a pixel); ``ds`` (n,) um their lengths;
    ``wt`` (n,) um^2 their ``|(z x r) . n| ds`` (the torque's arm, the same at every twist);
    ``reach_um`` where a free line stands beyond the chip (:func:`line_reach_um`);
    ``f2`` the force per unit length of one sliding line, N/m (:func:`pinning_force_scale`);
    ``pattern`` (H, W) the pattern's values and ``labels`` (H, W) int32 its pads (1..n, 0
    substrate: :func:`patterns.geometry.pad_labels`) at ``um_per_px``."""
    if not scene.effects.hysteresis or scene.liquid.pinned:
        return None
    f2 = pinning_force_scale(scene)
    if not f2 > 0:
        return None
    from patterns.geometry import pad_labels

    s = float(scene.um_per_px)
    mids, normals, wx, wy, wt = _outline_elements(scene.chip, piece_um=0.5 * s)
    pat = np.asarray(scene.pattern.data, float)
    labels, _ = pad_labels(scene.pattern)
    return {
        "mids": mids,
        "normals": normals,
        "ds": np.hypot(wx, wy),
        "wt": wt,
        "reach_um": float(line_reach_um(scene)),
        "f2": float(f2),
        "pattern": pat,
        "labels": labels.astype(np.int32),
        "um_per_px": s,
    }


def sliding_pinning_at(scene, pose, wet=None) -> tuple[float, float, float]:
    """(P_twist in N m, P_y in N, P_x in N) of the lines that slide over a *wet* pad with the
    chip at ``pose`` = (x um, y um, twist deg) (docs/physics.md §5.3): each element of the
    outline, turned and moved with the chip, counts with the wet pattern's value (bilinear)
    ``d_p`` beyond it along its normal, ``|n_x| ds`` for x, ``|n_y| ds`` for y and
    ``|(z x r) . n| ds`` for the twist. ``wet``: (pads,) booleans, the footprint state
    (``--dispense``), pad ``k`` the pattern's label ``k + 1``; None: every pad. The NumPy
    reference of what the steppers compute per pose (:func:`simulator.motion.pin_at`)."""
    lines = pinning_lines(scene)
    if lines is None:
        return 0.0, 0.0, 0.0
    from scipy.ndimage import map_coordinates

    x, y, a = (float(v) for v in pose)
    c, sn = math.cos(math.radians(a)), math.sin(math.radians(a))
    rot = np.array([[c, -sn], [sn, c]])
    m = lines["mids"] @ rot.T + np.array([x, y])
    n = lines["normals"] @ rot.T
    p = m + lines["reach_um"] * n
    pat = lines["pattern"]
    if wet is not None:
        keep = np.concatenate([[False], np.asarray(wet, bool)])
        pat = pat * keep[lines["labels"]]
    s = lines["um_per_px"]
    hh, ww = pat.shape
    col = p[:, 0] / s + ww / 2 - 0.5
    row = hh / 2 - 0.5 - p[:, 1] / s
    on = np.clip(
        map_coordinates(pat, [row, col], order=1, mode="grid-constant", cval=0.0), 0.0, 1.0
    )
    ds = lines["ds"]
    f2 = lines["f2"]
    return (
        f2 * float((on * lines["wt"]).sum()) * UM2,
        f2 * float((on * np.abs(n[:, 1]) * ds).sum()) * UM,
        f2 * float((on * np.abs(n[:, 0]) * ds).sum()) * UM,
    )


def sliding_pinning(scene) -> tuple[float, float, float]:
    """(P_twist in N m, P_y in N, P_x in N) of the lines that slide (:func:`sliding_shares`),
    or zeros without hysteresis: what the steppers stop against."""
    full = pinning(scene)
    if not any(full):
        return full
    shares = sliding_shares(scene)
    p_t, p_y, p_x = (float(p * k) for p, k in zip(full, shares, strict=True))
    return p_t, p_y, p_x


def pin_per_index(scene, um_per_px: float, twist_step_deg: float) -> tuple[float, float, float]:
    """Pinning work over one grid step along (twist, y, x), in J: the thresholds the
    steppers compare ``|dE/dq_k|`` (J per index step) with."""
    pt, py, px = sliding_pinning(scene)
    return pt * math.radians(twist_step_deg), py * um_per_px * UM, px * um_per_px * UM


#: A pinned chip within this many predicted stop distances of the minimum counts as aligned.
ALIGN_MARGIN = 3.0


def align_tolerance(
    ls, pin: tuple[float, float, float], floats: bool = False
) -> tuple[float, float]:
    """(twist steps, px) within which a run that stopped counts as aligned: one step, or with
    hysteresis :data:`ALIGN_MARGIN` times the distance ``P_k / c_k`` at which the well's
    restoring force (curvature ``c_k`` per step^2 at the landscape's minimum) equals the
    pinning force, whichever is larger. On the overlap model's V-shaped well ``c_k`` is
    large and the tolerance stays one step.

    ``floats``: the chip floats on the well's flat floor (free contact lines,
    :class:`simulator.physics.WallProfile`): a run that stops anywhere on the floor
    (:meth:`~simulator.landscape.Landscape.floor_extent`) is aligned, so the tolerance is at
    least the floor's reach from the minimum, and one step more (a continuous run stops on
    the interpolated edge of the floor, inside the cell beyond its last grid pose)."""
    tol = (1.0, 1.0)
    if floats:
        it, iy, ix = ls.minimum_index()
        (t0, t1), (y0, y1), (x0, x1) = ls.floor_extent()
        # The floor's last grid pose, and the cell beyond it, where a continuous run stops
        # on the interpolated edge of the floor.
        tol = (
            max(1.0, float(max(it - t0, t1 - it)) + 1.0),
            max(1.0, float(max(iy - y0, y1 - iy, ix - x0, x1 - ix)) + 1.0),
        )
    if not any(pin):
        return tol
    hyst = _hysteresis_tolerance(ls, pin)
    return max(tol[0], hyst[0]), max(tol[1], hyst[1])


def _hysteresis_tolerance(ls, pin: tuple[float, float, float]) -> tuple[float, float]:
    """:func:`align_tolerance` from the pinning alone (the curvature from three energies
    per axis, each read as float64: not the whole landscape converted)."""
    e = ls.energy
    it, iy, ix = ls.minimum_index()
    nt, ny, nx = e.shape
    d = []
    for k, (i, n) in enumerate(((it, nt), (iy, ny), (ix, nx))):
        if pin[k] <= 0 or n < 3:
            d.append(0.0)
            continue
        lo, hi = i - 1, i + 1
        if k == 0 and ls.wrap:
            lo, hi = lo % n, hi % n
        if lo < 0 or hi >= n:
            d.append(0.0)
            continue
        idx = [it, iy, ix]
        vals = []
        for j in (lo, i, hi):
            idx[k] = j
            vals.append(float(e[tuple(idx)]))
        c = vals[0] + vals[2] - 2 * vals[1]
        d.append(pin[k] / c if c > 0 else 0.0)
    return max(1.0, ALIGN_MARGIN * d[0]), max(1.0, ALIGN_MARGIN * max(d[1], d[2]))
