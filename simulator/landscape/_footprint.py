"""The landscape of every footprint state: one energy plane set per pad, summed by state.

The energy is linear in the pattern, so the pattern's pads (its connected regions) are
correlated one at a time, each on the same pose grid, with the chip footprints the
footprint state needs (:mod:`simulator.physics`, ``FootprintRules``): the wall profile (a
wet pad the chip covers), and five counts of the pad's area within a distance of the chip
(covered, reached at ``d_s``, within the reach ``d_r``, and two either side of a band just
beyond it, which give the bridged pad's term and the line length there). The energy of a state is then the sum of
the wet pads' planes (:meth:`FootprintPlanes.landscape`), and the state at a pose the
relay of each pad (:meth:`FootprintPlanes.next_state`): no transform per event.

Cost: six correlations per pad and twist, against one for the stateless landscape
(docs/physics.md §3.5).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from patterns.errors import InputError
from patterns.mask import Mask
from simulator.scene import Scene

from ._build import build_landscape, scene_extent
from ._landscape import Landscape


def pad_labels(pattern: Mask) -> tuple[np.ndarray, int]:
    """The pattern's pads: its connected wettable regions (every pixel above 0, so that the
    pads' masks add up to the pattern exactly), labelled 1..n."""
    from scipy import ndimage

    labels, n = ndimage.label(pattern.data > 0)
    return labels, int(n)


def _variant(scene: Scene, pattern: Mask, profile) -> Scene:
    """``scene`` with another pattern and another chip footprint (the wall profile the builder
    correlates): a scene's ``wall_profile`` is derived once and cached on it, and here it is
    set before the builder first reads it."""
    s = scene.replace(pattern=pattern)
    s.__dict__["wall_profile"] = profile
    return s


def footprint_poses(scene: Scene) -> int:
    """Poses of the grid the pads' planes share (:func:`build_footprint_planes`): the scene's
    reach widened to the furthest count footprint (a band just beyond ``d_r``), so larger
    than the stateless landscape's when the receding angle is small. No rotation, no build."""
    from simulator.physics import FootprintRules

    from ._build import estimate_bytes

    prof = scene.wall_profile
    if prof is None:
        return estimate_bytes(scene) // np.dtype(scene.dtype).itemsize
    m = scene.materials
    rules = FootprintRules.of(prof, m.pad_receding_deg if scene.effects.hysteresis else None)
    wide = _variant(scene, scene.pattern, rules.count_profiles()["band_out"])
    return estimate_bytes(wide) // np.dtype(scene.dtype).itemsize


@dataclass(frozen=True, eq=False)
class FootprintPlanes:
    """Per-pad planes of one scene on one pose grid (module docstring).

    rules: the relay's reaches (:class:`simulator.physics.FootprintRules`). wet_energy:
    (pads, T, Ny, Nx) J, each pad's energy while it is wet (the wall profile's term where the
    chip covers some of it, the bridged term elsewhere; a pad whose smaller side is below the
    bridged term's band, ``FootprintRules.band_px`` and two steps, keeps the wall term
    everywhere: its far edge would lie inside the band). reached, within_reach: (pads, T, Ny,
    Nx) booleans, the relay's inputs. template: a landscape of the grid (its metadata).
    pad_area_um2, pad_centre_um: each pad's area and centroid (x, y um, y up).
    """

    rules: object
    wet_energy: np.ndarray
    reached: np.ndarray
    within_reach: np.ndarray
    template: Landscape
    pad_area_um2: np.ndarray
    pad_centre_um: np.ndarray
    labels: np.ndarray
    seconds: float

    @property
    def n_pads(self) -> int:
        return int(self.wet_energy.shape[0])

    def landscape(self, wet) -> Landscape:
        """The landscape of the footprint state ``wet`` ((pads,) booleans)."""
        w = np.asarray(wet, bool)
        t = self.template
        e = np.zeros(t.energy.shape, t.energy.dtype)
        for k in np.flatnonzero(w):
            e += self.wet_energy[k]
        return Landscape(
            energy=e,
            grid=t.grid,
            delta_gamma=t.delta_gamma,
            energy_scale_J=t.energy_scale_J,
            meniscus_height_um=t.meniscus_height_um,
            stats=dict(t.stats),
        )

    def node(self, pose) -> tuple[int, int, int]:
        """The grid node nearest ``pose`` (x_um, y_um, twist_deg), clipped to the grid."""
        g = self.template.grid
        it, iy, ix = (int(round(float(v))) for v in g.to_index(np.asarray(pose, float)))
        n_t, ny, nx = g.shape
        it = it % n_t if g.wrap else min(max(it, 0), n_t - 1)
        return it, min(max(iy, 0), ny - 1), min(max(ix, 0), nx - 1)

    def released_curve(self, dispensed, axis: str, through, start: float, stop: float) -> dict:
        """:meth:`Landscape.curve` where each sample is a chip released at that pose onto the
        footprint ``dispensed`` (its state: :meth:`next_state` there), not a continuation
        along the curve; ``wet`` holds each sample's wet pads (1..n)."""
        from ._landscape import curve_of

        ref = self.template.curve(axis, through, start, stop)  # the samples, checked
        v = ref["values"]
        poses = np.tile(np.asarray(through, float), (len(v), 1))
        poses[:, {"x": 0, "y": 1, "twist": 2}[axis]] = v
        states = [tuple(np.flatnonzero(self.next_state(dispensed, p)) + 1) for p in poses]
        e, force = np.empty(len(v)), np.empty(len(v))
        floor = 0.0
        for st in set(states):
            wet = np.zeros(self.n_pads, bool)
            wet[np.asarray(st, int) - 1] = True
            ls = self.landscape(wet)
            c = ls.curve(axis, through, start, stop)
            sel = np.array([s == st for s in states])
            e[sel], force[sel] = c["energy_J"][sel], c["force"][sel]
            floor = ls.noise_floor_J
        return curve_of(axis, v, e, force, floor) | {"wet": [list(map(int, s)) for s in states]}

    def next_state(self, wet, pose) -> np.ndarray:
        """The pads' state once the chip, with the footprint ``wet``, is at ``pose``."""
        from simulator.physics import relay

        n = self.node(pose)
        return relay(wet, self.reached[(slice(None), *n)], self.within_reach[(slice(None), *n)])


def build_footprint_planes(
    scene: Scene, backend: str = "auto", progress: bool = False, twists=None
) -> FootprintPlanes:
    """The per-pad planes of ``scene`` over its whole pose grid (module docstring).

    Needs the finite meniscus with free contact lines of a pixel or more
    (``scene.wall_profile``); the pads' receding angle is the hysteresis window's when the
    scene declares one, else their Young angle. ``twists``: only these (as
    :func:`build_landscape`'s), default the scene's whole twist axis.
    """
    from simulator.physics import STEP_PX, TOUCH_PX2, FootprintRules

    t0 = time.perf_counter()
    prof = scene.wall_profile
    if prof is None:
        raise InputError(
            "--dispense needs the finite meniscus with free contact lines (--meniscus, not --pinned) "
            f"of at least a pixel of height; give --meniscus, or a finer --resolution than {scene.um_per_px:g} um"
        )
    m = scene.materials
    rules = FootprintRules.of(prof, m.pad_receding_deg if scene.effects.hysteresis else None)
    labels, n = pad_labels(scene.pattern)
    counts = rules.count_profiles()
    extent = scene_extent(_variant(scene, scene.pattern, counts["band_out"]))
    data = scene.pattern.data
    s = scene.um_per_px
    h, w = data.shape
    pads, areas, centres, deep = [], [], [], []
    from scipy import ndimage

    for k, box in enumerate(ndimage.find_objects(labels), start=1):
        # deep enough for the bridged term: the pad's smaller side beyond the band and its steps
        deep.append(
            min(box[0].stop - box[0].start, box[1].stop - box[1].start)
            >= rules.band_px + 2 * STEP_PX
        )
        mk = np.where(labels == k, data, 0.0)
        pads.append(Mask(mk, s))
        rr, cc = np.nonzero(labels == k)
        wk = data[rr, cc]
        areas.append(float(wk.sum()) * s * s)
        centres.append(
            (
                float(((cc + 0.5 - w / 2) * wk).sum() / wk.sum()) * s,
                float(((h / 2 - rr - 0.5) * wk).sum() / wk.sum()) * s,
            )
        )
    # Pad by pad, each plane reduced to what the state needs as soon as it is made (the wet
    # energy in place, the counts to flags): the peak holds the pads' results, two planes
    # and a build.
    template = None
    wet_energy = reached = within = None

    def plane(k: int, name: str, profile) -> Landscape:
        return build_landscape(
            _variant(scene, pads[k], profile),
            twists=twists,
            backend=backend,
            extent=extent,
            label=f"footprint plane {name}, pad {k + 1} of {n}",
        )

    for k in range(n):
        ls = plane(k, "wall", prof)
        if template is None:
            template = ls
            shape = (n, *ls.energy.shape)
            wet_energy = np.empty(shape, ls.energy.dtype)
            reached, within = np.empty(shape, bool), np.empty(shape, bool)
        assert wet_energy is not None and reached is not None and within is not None
        jp = ls.joules_per_px2
        wet_energy[k] = ls.energy
        del ls
        reached[k] = plane(k, "reached", counts["reached"]).energy / jp >= TOUCH_PX2
        within[k] = plane(k, "within", counts["within"]).energy / jp >= TOUCH_PX2
        if not deep[
            k
        ]:  # a pad narrower than the band: its far edge would take from the bridged term
            continue
        bare = plane(k, "covered", counts["covered"]).energy / jp < TOUCH_PX2
        # bridged = jp [N(b) - (b - F_inf) l(b)], N(b) the mean of the band's two counts and
        # l(b) their difference over the step: a weighted sum of the two, made in place
        c = (rules.band_px - rules.f_inf) / STEP_PX
        bridged = plane(k, "band_in", counts["band_in"]).energy / jp
        bridged *= 0.5 + c
        outer = plane(k, "band_out", counts["band_out"]).energy / jp
        outer *= 0.5 - c
        bridged += outer
        del outer
        bridged *= jp
        np.copyto(wet_energy[k], bridged, where=bare)
        del bridged, bare
    assert template is not None and wet_energy is not None  # a pattern has a pad
    return FootprintPlanes(
        rules=rules,
        wet_energy=wet_energy,
        reached=reached,
        within_reach=within,
        template=template,
        pad_area_um2=np.asarray(areas),
        pad_centre_um=np.asarray(centres),
        labels=labels,
        seconds=time.perf_counter() - t0,
    )
