"""The footprint state's planes at the poses a run visits: the path-cost engine for
``--dispense`` (docs/physics.md §3.5).

:func:`~simulator.landscape.build_footprint_planes` correlates every pad with the state's
chip footprints over the whole pose grid. A greedy or gradient run visits a thin tube of
it. Here the same quantities are computed only in the small boxes that follow the chip,
with the path-cost engine's machinery (:class:`~simulator.landscape.PathEnergy`): each
footprint at one twist is made at its band's pixels only and split into the part the chip's
side sums and the part the pattern's side sums (:func:`~simulator.landscape._pathband.footprint_band`),
and each pattern part (a pad, or a near pad's part upstream of a far one) has its own row
prefix sums and outline steps, cut to its bounding box (a pose reads only the rows the part
has). The energy is linear in the pattern, so each pad's counts and energies, and each
pair's correction, are the same sums of the same footprint functions of the chip's signed
distance as the FFT build's, on the same rotators (the same splines, cast to the scene's
dtype as the FFT engine correlates them):

* ``wall`` (the wall profile, a wet pad the chip covers), ``covered``, ``reached`` and
  ``within`` (the counts at 0, ``d_s`` and ``d_r``), each its own rotator's footprint;
* ``band``: the bridged term's one footprint, the band's two counts weighted
  (``w_in N(b - 1) + w_out N(b + 1)``, 1 inside the chip as both are);
* ``strip<side>``: the shadow rule's ``N_b - f`` kept on one side of the chip (0 inside and
  beyond the band), the side looked up as the FFT build's ``_Sides`` does.

:meth:`FootprintPath.box` returns a :class:`~simulator.landscape.FootprintPlanes` on a box of
the planes' grid (the same grid as the FFT build's), so the state's landscape, the relay's
flags and the pairs' corrections read as they do on the whole grid. Each (footprint, part,
twist) keeps its computed rows (a run's overlapping boxes pay for their shared poses once),
and a part that no pose of the box can reach is skipped (its sums are zero there). Per pad
and twist: the covered count first (where the chip covers the pad at every pose of the box,
the pad is reached and within reach there, and its energy is the wall term), the reach's
count where it is not, the reached count where some pose is within reach, and the wall or
the bridged term where the pad is covered or not.
"""

from __future__ import annotations

import time

import numpy as np

from simulator.core import UM2
from simulator.scene import Scene

from ._build import _box, _grid_of, energy_scale_J
from ._landscape import Landscape
from ._pathband import (
    SEGMENT_PAD,
    _inverse,
    band_outline,
    band_samples,
    footprint_band,
    pattern_outline,
)
from ._pathcost import PathEnergy, _Outline, keep_rows, read_rows, rows_to_compute
from ._rotation import ChipRotator, footprint_band_px

#: The footprints of the state by name (module docstring); the strips' names end in the side.
COUNTS = ("covered", "reached", "within")


class _Part:
    """One pattern part (a pad, or a near pad's part upstream of a far one) for
    :meth:`PathEnergy._rows`: its row prefix sums ``P`` (one column more: the row total,
    ``T``; one zero row more) and outline steps, cut to its bounding box, whose first row and
    column in the engine's crop are ``i0``, ``j0``."""

    __slots__ = ("P", "T", "hp", "wp", "_pattern_steps", "i0", "j0", "rows", "cols", "empty")

    def __init__(self, pat: np.ndarray, origin: tuple[int, int] = (0, 0)):
        """``pat``: the part's values; ``origin``: the engine's crop row and column of
        ``pat[0, 0]`` (a part given on a box of the crop holding it)."""
        rr, cc = np.flatnonzero(pat.any(axis=1)), np.flatnonzero(pat.any(axis=0))
        self.empty = rr.size == 0
        if self.empty:
            rr = cc = np.zeros(1, np.int64)
        i0, i1, j0, j1 = int(rr[0]), int(rr[-1]) + 1, int(cc[0]), int(cc[-1]) + 1
        sub = np.ascontiguousarray(pat[i0:i1, j0:j1], np.float64)
        hs, ws = sub.shape
        # zero rows beyond (never read) so that a read of SEGMENT_PAD columns fits in P
        self.P = np.zeros((hs + 1 + -(-SEGMENT_PAD // (ws + 1)), ws + 1), np.float64)
        np.cumsum(sub, axis=1, out=self.P[:hs, 1:])
        self.T = self.P[: hs + 1, ws].copy()
        self.hp, self.wp = hs, ws
        self._pattern_steps = pattern_outline(sub)
        if not self.empty:
            i0, i1, j0, j1 = i0 + origin[0], i1 + origin[0], j0 + origin[1], j1 + origin[1]
        self.i0, self.j0 = i0, j0
        self.rows, self.cols = (i0, i1 - 1), (j0, j1 - 1)


#: The least pattern value of a pad's anchor pixel (:meth:`FootprintPath._anchor`): above
#: TOUCH_PX2 by far more than a float64 sum's round-off.
ANCHOR_VALUE = 0.75

#: The part of a pair whose far pad no ray from the near one reaches (kept as any part is).
_NO_PART = _Part(np.zeros((1, 1)))


class _Rotators(dict):
    """The footprints' rotators by name, each made on first use by ``make(name)``."""

    def __init__(self, make):
        super().__init__()
        self._make = make

    def __missing__(self, name: str):
        rot = self[name] = self._make(name)
        return rot


class FootprintPath:
    """The footprint state's planes of ``scene`` at any pose of its planes' grid, computed
    on demand at the cost of the chip's outline (module docstring)."""

    def __init__(self, scene: Scene):
        from scipy import ndimage

        from simulator.physics import STEP_PX, FootprintRules

        from ._footprint import _area_centre, _pads_of, _Sides, _variant

        prof = scene.wall_profile
        if prof is None:
            from foundation import InputError

            raise InputError(
                "--dispense needs the finite meniscus with free contact lines (--meniscus, not --pinned) "
                f"of at least a pixel of height; give --meniscus, or a finer --resolution than {scene.um_per_px:g} um"
            )
        t0 = time.perf_counter()
        self.scene = scene
        m = scene.materials
        self.rules = rules = FootprintRules.of(
            prof, m.pad_receding_deg if scene.effects.hysteresis else None
        )
        counts = rules.count_profiles()
        # The planes' grid: the scene's, widened to the furthest count (as the FFT build's).
        self.wide = _variant(scene, scene.pattern, counts["band_out"])
        self.pe = PathEnergy(self.wide)
        self.axis = scene.twist_axis
        self.grid = self.pe.grid
        self.labels, self.n, masks, self.deep = _pads_of(scene, rules)
        self.masks = masks
        r0, r1, c0, c1 = _box(self.wide, None, extent=self.pe._extent)["crop"]
        self._crop = (r0, r1, c0, c1)
        data = scene.pattern.data
        self._data = data
        # Each pad on its bounding box (image rows, columns): its mask and its values there.
        boxes = ndimage.find_objects(self.labels)
        self._boxes = [(b[0].start, b[1].start) for b in boxes]
        self._bmask = [m[b[0], b[1]] for m, b in zip(masks, boxes, strict=True)]
        self._edges: dict = {}
        self.parts: dict = {
            k: self._part_box(np.where(self._bmask[k], self._box_values(k), 0.0), *self._boxes[k])
            for k in range(len(masks))
        }
        s = scene.um_per_px
        areas, centres = [], []
        for k in range(len(masks)):
            (i0, j0), bm = self._boxes[k], self._bmask[k]
            rr, cc = np.nonzero(bm)
            area, centre = _area_centre(
                self._box_values(k)[rr, cc], rr + i0, cc + j0, data.shape, s
            )
            areas.append(area)
            centres.append(centre)
        self.pad_area_um2, self.pad_centre_um = np.asarray(areas), np.asarray(centres)
        # One rotator per footprint on the whole axis's canvas (its smooth chip made once;
        # a footprint at one twist is then made at its band's pixels only).
        profiles = {"wall": prof} | {k: counts[k] for k in (*COUNTS, "band_in", "band_out")}
        # Each made when a footprint first needs it (a run whose chip covers every pad
        # throughout never counts the reach, :meth:`_covered_throughout`).
        twists = self.axis.values()
        self._profiles = profiles
        self._rots = _Rotators(
            lambda p: ChipRotator(
                scene.chip,
                twists,
                self.pe.parity,
                self.pe.chip_blur,
                self.pe.margin if self.pe.chip_blur else 0,
                profiles[p],
            )
        )
        self._sides = _Sides(self._rots["wall"])
        c_band = (rules.band_px - rules.f_inf) / STEP_PX
        self._w = (0.5 + c_band, 0.5 - c_band)
        self.scale = scene.delta_gamma_N_m * s**2 * UM2
        self.dtype = np.dtype(scene.dtype)
        self.energy_scale = energy_scale_J(scene)
        self._outlines: dict = {}
        self._strip_samples: tuple | None = None
        self._anchors: dict = {}
        self._shadows: dict = {}
        self._support: dict = {}
        self._cache: dict = {}
        self.poses = 0
        self.rotations = 0
        self.seconds = time.perf_counter() - t0

    @property
    def n_pads(self) -> int:
        return self.n

    # -- the footprints at one twist
    def _span(self, *names) -> tuple[float, float]:
        lo = min(self._rots[k].band_px[0] for k in names)
        hi = max(self._rots[k].band_px[1] for k in names)
        return lo, hi

    def _side_at(self, xi: np.ndarray, yi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The chip's side (``_Sides``) at points of the unrotated chip and whether it is a
        tie: its nearest pixel's."""
        b = self._sides.bins
        h, w = b.shape
        r = np.clip(np.rint(-yi + (h / 2 - 0.5)), 0, h - 1).astype(np.intp)
        c = np.clip(np.rint(xi + (w / 2 - 0.5)), 0, w - 1).astype(np.intp)
        return b[r, c], self._sides.ties[r, c]

    def outline(self, name: str, k: int) -> _Outline:
        """The footprint ``name`` at twist index ``k``, split for the path engine (kept)."""
        key = (name, k)
        o = self._outlines.get(key)
        if o is not None:
            return o
        tw = float(self.axis.values_at(np.asarray([k]))[0])
        rots = self._rots
        if name in ("wall", *COUNTS):
            rot = rots[name]
            r, c, v, band = footprint_band(rot, tw, self.dtype)
        elif name == "band":
            rot, rin = rots["band_out"], rots["band_in"]
            w_in, w_out = self._w

            def values(xi, yi, s):
                f = rin.profile_at(xi, yi) * w_in
                f += rot.profile_at(xi, yi) * w_out
                return f, np.ones(len(f), bool)

            r, c, v, band = footprint_band(
                rot, tw, self.dtype, values, self._span("band_in", "band_out"), 1.0
            )
        else:  # strip<side>: N_b - f on one side of the chip
            side = int(name[len("strip") :])
            rot = rots["band_out"]
            span = self._span("wall", "band_in", "band_out")
            bk, bl, f, (sides, ties) = self._strips(k, tw, span)
            from ._footprint import side_weights

            part = side_weights(sides, ties, side)  # half of a corner's tie on each side
            on = part > 0
            fo = (f[on] * part[on]).astype(f.dtype)
            r, c, v, band = band_outline(rot, tw, bk[on], bl[on], fo, self.dtype, span, 0.0)
        oy, ox = self._offset(rot)
        order = np.argsort(r, kind="stable")
        o = _Outline(
            r[order].astype(np.int64) + oy,
            c[order].astype(np.int64) + ox,
            v[order],
            (oy, ox),
            rot.shape,
            band,
        )
        # Where it is (pattern rows and columns at pose 0): a part beyond reads nothing.
        rows = [o.rows]
        cols = [o.cols]
        if len(band.seg_row):
            rows.append(band.seg_row + oy)
            cols += [band.seg_a + ox, band.seg_a + band.seg_len + ox]
        rr, cc = np.concatenate(rows), np.concatenate(cols)
        self._support[key] = (
            (int(rr.min()) - 1, int(rr.max()) + 1, int(cc.min()) - 1, int(cc.max()) + 1)
            if rr.size
            else None
        )
        self._outlines[key] = o
        self.rotations += 1
        return o

    def _offset(self, rot) -> tuple[int, int]:
        """The rotator's canvas's place at pose 0 in pattern coordinates (row, column): canvas
        row r lies on crop row r + oy at a pose's row 0 (every rotator of the chip has the
        same canvas)."""
        hc, wc = rot.shape
        origin = self.pe.origin
        oy, ox = origin[1] - hc / 2, origin[0] - wc / 2
        assert oy == int(oy) and ox == int(ox), "pixel grids of chip and pattern must coincide"
        return int(oy), int(ox)

    def _strips(self, k: int, tw: float, span) -> tuple:
        """The shadow rule's ``N_b - f`` at every pixel of its band at twist index ``k``
        (``tw`` deg), with the chip's side each pixel lies on (``_Sides``): (rows, columns,
        values, (sides, ties)), evaluated once for the four strips of that twist (each keeps its
        side's pixels; every value is the one a strip alone would evaluate there)."""
        kept = self._strip_samples
        if kept is not None and kept[0] == k:
            return kept[1]
        rot, rin, wall = self._rots["band_out"], self._rots["band_in"], self._rots["wall"]

        def values(xi, yi, s):
            f = 0.5 * (rin.profile_at(xi, yi) + rot.profile_at(xi, yi))
            f -= wall.profile_at(xi, yi)
            return f, np.ones(len(f), bool)

        bk, bl, f = band_samples(rot, tw, values, span)
        xi, yi = _inverse(rot, tw)(bk.astype(float), bl.astype(float))
        out = (bk, bl, f, self._side_at(xi, yi))
        self._strip_samples = (k, out)
        return out

    def drop_outlines(self, keep: set[int]) -> None:
        """Forget the footprints of twists not in ``keep`` (and their rows), as
        :meth:`PathEnergy.drop_outlines` (a run's boxes keep a band of twists)."""
        if len(self._outlines) <= 24 * max(1, len(keep)):
            return
        for key in [key for key in self._outlines if key[1] not in keep]:
            del self._outlines[key]
        for key in [key for key in self._cache if key[2] not in keep]:
            del self._cache[key]
        # the pairs' parts at the shadow residuals of the twists kept (a part of a pad on
        # a 4000 um chip at 2 um/px holds 6.5 MB of row sums)
        from simulator.physics import shadow_residual_deg

        twists = self.axis.values_at(np.asarray(sorted(keep), np.intp))
        residuals = {float(r) for r in np.atleast_1d(shadow_residual_deg(twists))}
        for key in [key for key in self.parts if isinstance(key, tuple)]:
            if key[3] not in residuals:
                del self.parts[key]

    # -- sums
    def _part(self, key):
        p = self.parts.get(key)
        if p is None:  # a pair's part: the near pad's pixels upstream of the far pad
            a, b, ax, r = key
            angle = ax * 90.0 + r
            p = self._upstream(a, b, angle) if self._may_shadow(a, b, angle) else _NO_PART
            self.parts[key] = p
        return p

    def _box_values(self, k: int) -> np.ndarray:
        """The pattern's values on pad ``k``'s bounding box (image rows and columns)."""
        (i0, j0), (hb, wb) = self._boxes[k], self._bmask[k].shape
        return self._data[i0 : i0 + hb, j0 : j0 + wb]

    def _part_box(self, values: np.ndarray, i0: int, j0: int) -> _Part:
        """The :class:`_Part` of ``values``, a box of the image whose first row and column are
        ``i0``, ``j0``: on the engine's crop, its rows upside down (image row r at crop row
        r1 - 1 - r), laid out on the part's own bounding box, not on the whole crop."""
        r0, r1, c0, c1 = self._crop
        hb, wb = values.shape
        a0, a1 = max(i0, r0), min(i0 + hb, r1)  # the box's image rows inside the crop
        b0, b1 = max(j0, c0), min(j0 + wb, c1)
        if a0 >= a1 or b0 >= b1:
            return _NO_PART
        sub = values[a0 - i0 : a1 - i0, b0 - j0 : b1 - j0][::-1]
        return _Part(sub, origin=(r1 - a1, b0 - c0))

    def _rays(self, k: int, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """(ray index, distance along it) at every pixel of pad ``k``'s bounding box:
        :func:`simulator.physics.ray_coordinates` of its rows and columns broadcast (the same
        arithmetic, element by element, as for the pixels listed one by one)."""
        from simulator.physics import ray_coordinates

        (i0, j0), (hb, wb) = self._boxes[k], self._bmask[k].shape
        rows, cols = np.arange(i0, i0 + hb)[:, None], np.arange(j0, j0 + wb)[None, :]
        return ray_coordinates(rows, cols, self._data.shape, angle_deg)

    def _edge(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of pad ``k``'s edge pixels: those with one of their eight neighbours
        outside the pad (or beyond the image). The furthest pixel of a pad along any ray of
        :func:`simulator.physics.ray_coordinates` is one of them: a ray's pixels, in their
        order along it, go column by column (row by row beyond 45 deg), each next to the one
        before, one of its eight neighbours, so the pad's last pixel on a ray has a
        neighbour outside it (docs/physics.md §3.5)."""
        e = self._edges.get(k)
        if e is None:
            from scipy import ndimage

            m = self._bmask[k]
            inner = ndimage.binary_erosion(m, np.ones((3, 3), bool), border_value=0)
            rr, cc = np.nonzero(m & ~inner)
            e = self._edges[k] = (rr + self._boxes[k][0], cc + self._boxes[k][1])
        return e

    def _upstream(self, a: int, b: int, angle_deg: float) -> _Part:
        """The part of pad ``a`` from which a ray at ``angle_deg`` reaches pad ``b`` beyond
        it: ``masks[a] & upstream_along(masks[b], angle_deg)`` (the FFT build's part,
        :func:`simulator.physics.upstream_along`), on the two pads' bounding boxes only."""
        from simulator.physics import ray_coordinates

        ray_b, along_b = ray_coordinates(*self._edge(b), self._data.shape, angle_deg)
        ray_a, along_a = self._rays(a, angle_deg)
        lo = min(int(ray_b.min()), int(ray_a.min()))
        far = np.full(max(int(ray_b.max()), int(ray_a.max())) - lo + 1, -np.inf)
        np.maximum.at(far, ray_b - lo, along_b)
        ray_a -= lo
        up = self._bmask[a] & (along_a < far[ray_a])
        return self._part_box(np.where(up, self._box_values(a), 0.0), *self._boxes[a])

    def _may_shadow(self, a: int, b: int, angle_deg: float) -> bool:
        """False where pad ``b`` lies wholly behind pad ``a`` or beside it along ``angle_deg``
        (their bounding boxes: no ray from ``a`` reaches ``b``), so the part is empty (kept:
        a run asks again at every box)."""
        key = (a, b, angle_deg)
        if key not in self._shadows:
            self._shadows[key] = self._boxes_shadow(a, b, angle_deg)
        return self._shadows[key]

    def _boxes_shadow(self, a: int, b: int, angle_deg: float) -> bool:
        """:meth:`_may_shadow`, from the pads' bounding boxes' corners."""
        if not hasattr(self, "_corners"):
            h, w = self._data.shape
            self._corners = {}
            for k in range(self.n):
                (i0, j0), (hb, wb) = self._boxes[k], self._bmask[k].shape
                xs = np.array([j0, j0 + wb]) - w / 2
                ys = h / 2 - np.array([i0 + hb, i0])
                self._corners[k] = np.array([(x, y) for x in xs for y in ys])
        t = np.radians(angle_deg)
        d = np.array([np.cos(t), np.sin(t)])
        n = np.array([-d[1], d[0]])
        pa, pb = self._corners[a], self._corners[b]
        if (pb @ d).max() <= (pa @ d).min():
            return False  # b lies behind a
        return (pb @ n).max() + 1 >= (pa @ n).min() and (pa @ n).max() + 1 >= (pb @ n).min()

    def _anchor(self, p: int) -> tuple[int, int] | None:
        """Pad ``p``'s deepest pixel of value at least :data:`ANCHOR_VALUE` (crop row and
        column; its largest distance from the pad's outside), or None (no such pixel)."""
        if p not in self._anchors:
            from scipy import ndimage

            vals = np.where(self._bmask[p], self._box_values(p), 0.0)
            depth = ndimage.distance_transform_cdt(np.pad(vals >= ANCHOR_VALUE, 1))[1:-1, 1:-1]
            a = None
            if depth.max() > 0:
                r, c = np.unravel_index(int(np.argmax(depth)), depth.shape)
                i0, j0 = self._boxes[p]
                # crop coordinates: rows upside down (as _part_box lays the parts out)
                r0, r1, c0, _ = self._crop
                a = (r1 - 1 - (i0 + int(r)), j0 + int(c) - c0)
            self._anchors[p] = a
        return self._anchors[p]

    def _covered_throughout(
        self, p: int, k: int, tw: float, y0: int, ny: int, x0: int, nx: int
    ) -> bool:
        """Whether the chip covers pad ``p`` (its covered count at least TOUCH_PX2) at every
        pose of the box, known without the count: the pad's anchor pixel (:meth:`_anchor`,
        value >= ANCHOR_VALUE > TOUCH_PX2) lies where the covered footprint is exactly 1
        (signed distance below its band, :attr:`ChipRotator.band_px`) at each of them, and the
        rest of the count is not negative. The count, summed, would say the same (in
        float64, far from the threshold)."""
        a = self._anchor(p)
        r0, r1, c0, c1 = self._crop
        if a is None or not (0 <= a[0] < r1 - r0 and 0 <= a[1] < c1 - c0):
            return False
        rot = self._rots["wall"]  # the chip's signed distance, shared by every footprint
        (oy, ox), (hc, wc) = self._offset(rot), rot.shape
        lo = footprint_band_px(self._profiles["covered"])[0]
        # the anchor's canvas pixel at each pose: crop row = canvas row + oy + pose row
        kr = a[0] - oy - np.arange(y0, y0 + ny)
        kc = a[1] - ox - np.arange(x0, x0 + nx)
        if kr.min() < 0 or kr.max() >= hc or kc.min() < 0 or kc.max() >= wc:
            return False
        xi, yi = _inverse(rot, tw)(kr[:, None].astype(float), kc[None, :].astype(float))
        return bool((rot.distance_at(xi.ravel(), yi.ravel()) < lo).all())

    def _reaches(self, name: str, key, k: int, y0: int, ny: int, x0: int, nx: int) -> bool:
        """Whether the footprint ``name`` at twist index ``k`` can touch the part ``key`` from
        some pose of the box (its rows and columns at pose 0, shifted by the box's)."""
        self.outline(name, k)
        sup, part = self._support[(name, k)], self._part(key)
        if sup is None or part.empty:
            return False
        rlo, rhi, clo, chi = sup
        return (
            rlo + y0 <= part.rows[1]
            and rhi + y0 + ny - 1 >= part.rows[0]
            and clo + x0 <= part.cols[1]
            and chi + x0 + nx - 1 >= part.cols[0]
        )

    def sums(self, name: str, key, k: int, y0: int, ny: int, x0: int, nx: int) -> np.ndarray:
        """(ny, nx) float64, unscaled (px^2): the footprint ``name`` at twist index ``k``
        correlated with the part ``key`` at the poses y0.., x0.. px, as the FFT build's
        correlation of the same footprint with the same part. Each row keeps one run of
        computed columns (as :meth:`PathEnergy.plane`)."""
        if not self._reaches(name, key, k, y0, ny, x0, nx):
            return np.zeros((ny, nx))
        rows = self._cache.setdefault((name, key, k), {})
        todo = rows_to_compute(rows, y0, ny, x0, nx)
        if todo:
            t0 = time.perf_counter()
            o, part = self.outline(name, k), self._part(key)
            for (xa, n), ys in todo.items():
                yy = np.asarray(ys, np.int64)
                e = self.pe._rows(o, yy - part.i0, xa - part.j0, n, part)
                self.poses += e.size
                keep_rows(rows, ys, xa, e)
            self.seconds += time.perf_counter() - t0
        return read_rows(rows, y0, ny, x0, nx, np.float64)

    def _energy(self, name, key, k, y0, ny, x0, nx) -> np.ndarray:
        return (self.sums(name, key, k, y0, ny, x0, nx) * self.scale).astype(self.dtype)

    # -- the planes of a box
    def box(self, twist_idx, center_px: tuple[int, int], half_px: int | None):
        """:class:`~simulator.landscape.FootprintPlanes` at the consecutive axis twists
        ``twist_idx`` (wrapped on a periodic axis) and the translations within ``half_px`` of
        ``center_px`` (``None``: the whole grid's): the grid the FFT build's planes have there
        (a box of it), the same pads' energies, relay flags and pairs' corrections."""
        from simulator.physics import TOUCH_PX2, shadow_residual_deg

        from ._footprint import FootprintPlanes, PairPlane

        t0 = time.perf_counter()
        twist_idx = [int(j) for j in twist_idx]
        na = self.axis.count
        twists = self.axis.values_at(np.asarray([j % na for j in twist_idx]))
        b = _box(self.wide, twists, center_px, half_px, extent=self.pe._extent)
        g = _grid_of(self.wide, b)
        n_t, ny, nx = g.shape
        y0, x0 = g.y_first_px, g.x_first_px
        n = self.n
        box = (y0, ny, x0, nx)
        wet = np.zeros((n, n_t, ny, nx), self.dtype)
        nb = -(-n // 8)
        reached = np.zeros((n_t, ny, nx, nb), np.uint8)
        within = np.zeros((n_t, ny, nx, nb), np.uint8)
        pair_planes: dict = {}
        for i, j in enumerate(twist_idx):
            k = j % na
            tw = float(twists[i])
            res = float(shadow_residual_deg(tw))
            covered = {}
            for p in range(n):
                bit, byte = np.uint8(1 << (p % 8)), p // 8
                # every pad's covered count: the pairs read the near pads' (the FFT build
                # makes it for the deep pads and the near ones; it is the same count)
                if self._covered_throughout(p, k, tw, *box):
                    cov = covered[p] = np.ones((ny, nx), bool)
                else:
                    cov = covered[p] = self.sums("covered", p, k, *box) >= TOUCH_PX2
                if cov.all():
                    r_, w_ = cov, cov
                else:
                    w_ = self.sums("within", p, k, *box) >= TOUCH_PX2
                    r_ = self.sums("reached", p, k, *box) >= TOUCH_PX2 if w_.any() else w_
                reached[i, ..., byte] |= np.where(r_, bit, np.uint8(0))
                within[i, ..., byte] |= np.where(w_, bit, np.uint8(0))
                if not self.deep[p]:
                    wet[p, i] = self._energy("wall", p, k, *box)
                    continue
                if cov.all():
                    wet[p, i] = self._energy("wall", p, k, *box)
                elif not cov.any():
                    wet[p, i] = self._energy("band", p, k, *box)
                else:
                    wet[p, i] = np.where(
                        cov,
                        self._energy("wall", p, k, *box),
                        self._energy("band", p, k, *box),
                    )
            # The shadow rule: N_b - f on the chip's side facing the pair's axis, with the
            # near pad's part upstream of the far one along that side's normal: the pairs
            # (near, far on its bridged term, axis) whose part is not empty at this residual
            # (the FFT build's _shadowed), where the near pad is covered (whether or not a corner
            # of the chip has reached the far one: the bridge to it holds).
            nearest = int(np.rint(tw / 90.0))
            for a in range(n):
                for bb in range(n):
                    if a == bb or not self.deep[bb]:
                        continue
                    keep = covered[a]
                    if not keep.any():
                        continue
                    for ax in range(4):
                        if not self._may_shadow(a, bb, ax * 90.0 + res):
                            continue
                        strip = f"strip{(ax - nearest) % 4}"
                        # the part lies in pad a: where the strip cannot reach the pad from
                        # any pose of the box, it cannot reach the part (its sums are zero),
                        # which is then not made
                        if not self._reaches(strip, a, k, *box):
                            continue
                        if self._part((a, bb, ax, res)).empty:
                            continue
                        c = self._energy(strip, (a, bb, ax, res), k, *box)
                        c[~keep] = 0
                        pair_planes.setdefault((a, bb, ax), []).append((i, c))
        template = Landscape(
            energy=wet[0] if n else np.zeros(g.shape, self.dtype),
            grid=g,
            delta_gamma=self.scene.delta_gamma_N_m,
            energy_scale_J=self.energy_scale,
            meniscus_height_um=self.scene.meniscus_height_um,
            stats={"backend": "path", "seconds": time.perf_counter() - t0},
        )
        return FootprintPlanes(
            rules=self.rules,
            wet_energy=wet,
            reached_bits=reached,
            within_bits=within,
            template=template,
            pad_area_um2=self.pad_area_um2,
            pad_centre_um=self.pad_centre_um,
            labels=self.labels,
            seconds=time.perf_counter() - t0,
            pairs=tuple(
                PairPlane(
                    a,
                    bb,
                    ax,
                    0,
                    0,
                    np.stack([c for _, c in v]),
                    np.asarray([i for i, _ in v], np.intp),
                )
                for (a, bb, ax), v in sorted(pair_planes.items())
            ),
        )

    def at(self, pose) -> tuple[np.ndarray, np.ndarray]:
        """(reached, within_reach): (pads,) booleans at the grid node nearest ``pose``
        (x_um, y_um, twist_deg), clipped to the grid (as :meth:`FootprintPlanes.next_state`)."""
        g = self.grid
        it, iy, ix = (int(round(float(v))) for v in g.to_index(np.asarray(pose, float)))
        n_t, ny, nx = g.shape
        it = it % n_t if g.wrap else min(max(it, 0), n_t - 1)
        iy, ix = min(max(iy, 0), ny - 1), min(max(ix, 0), nx - 1)
        pl = self.box([g.t_first + it], (g.x_first_px + ix, g.y_first_px + iy), 0)
        return pl.flags_at(0, 0, 0)

    def next_state(self, wet, pose) -> np.ndarray:
        """The pads' state once the chip, with the footprint ``wet``, is at ``pose``."""
        from simulator.physics import relay

        reached, within = self.at(pose)
        return relay(wet, reached, within)

    def close(self) -> None:
        """Nothing runs in the background (as :meth:`PathEnergy.close`)."""


#: The path engine's footprint state keeps six rotators' smooth chips (the wall profile,
#: three counts and the band's two) where the stateless run keeps one.
PATH_ROTATORS = 6


def footprint_path_bytes(scene) -> int:
    """What a ``--dispense`` run on the path engine holds besides the stateless run's: the
    smooth chips of its five more rotators (:class:`simulator.landscape.FootprintPath`; the
    rows and footprints it keeps are those of a run's band of twists, as the stateless
    engine's). Sizes only."""
    from ._rotation import smooth_bytes

    prof = scene.wall_profile
    if prof is None:
        return 0
    make, kept = smooth_bytes(scene.chip, scene.meniscus_height_px, 0, prof, (0, 0))
    return int((PATH_ROTATORS - 1) * kept + make)
