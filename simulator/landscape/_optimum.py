"""The global minimum of a scene's energy: the pose every command calls "aligned".

One rule in every command (``simulate``, ``montecarlo``, ``evaluate``, ``demo``): the
global minimum is the grid pose of lowest energy over the scene's whole pose grid, and
ties (energies within the noise floor of the lowest) are decided by position: the tie
nearest the nominal pose (0, 0, 0) wins (:meth:`simulator.landscape.Landscape.minimum_index`,
:func:`simulator.landscape.nominal_order`). Where the whole landscape is at hand
(``montecarlo``, ``evaluate``, the dynamics) it is read off it
(:func:`landscape_minimum`). A single greedy or gradient run builds only boxes of the
landscape; :func:`global_minimum` then finds the same pose without building the rest,
and proves it:

1. The boxes already built (the run's) and the nominal box (+-16 px, +-2 twist steps
   around (0, 0, 0)) are searched.
2. *Absolute bound.* If their lowest energy reaches the lowest any pose can have,
   ``-|Delta_gamma| min(|P|, |C|)`` (within the noise floor), and the tie nearest the
   nominal pose lies in the nominal box, no pose elsewhere can be lower or win a tie:
   done. This is the chip on its own pattern (pads inside the chip, or the chip inside
   a pad).
3. *Cell bounds.* Otherwise the pose grid is cut into cells of k x k translations at each
   twist, and the overlap of every pose in a cell is bounded from above by one small
   correlation (:meth:`_Bounds.cells`). A cell whose bound cannot come within the noise
   floor of the lowest energy found holds no better pose and no tie, and is dropped.
   The most promising cell left is computed exactly (lowering the energy to beat), the
   bound is refined (k / 4) over the cells left, and what is left at the end is
   computed exactly. So every pose that could be lower, or tie, has been computed.

A finite meniscus from one pixel of height up is the overlap of the pattern with the
chip's footprint (the wall profile or the K_h-blurred chip, values in [0, 1], rotated by
the engine's own rotator), so the same bounds hold with the footprint in place of the chip
raster: its block maxima, and its mass in the absolute bound. Scenes the bound does not
cover (a meniscus below one pixel, whose blur is on the pattern's side; a repulsive pad,
Delta_gamma > 0) are searched over the whole landscape, built in chunks of twists that
fit the memory budget.

Modules: this one holds the result (:class:`GlobalMinimum`) and the search (steps 1 to
3, the pieces built and what is left to compute); the cell bound of step 3
(:class:`_Bounds`) is :mod:`simulator.landscape`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from simulator.landscape._landscape import (
    NOMINAL_BALL_PX,
    NOMINAL_PX_PER_STEP,
    Landscape,
    nominal_distance,
    nominal_order,
)
from simulator.landscape._overlap_bound import _Bounds, _delta_gamma
from simulator.landscape._pathcost import PathEnergy
from simulator.scene import Scene

#: Target number of cells per axis of the first (coarsest) cell bound.
CELLS_PER_AXIS = 128
#: Boxes of the search at most this many px from their centre are computed pose by pose when
#: the run has a path-cost engine (the nominal box, a floor's box); wider ones by FFT.
PATH_BOX_PX = 64
#: Cells left whose box (times its twists) holds at most this many poses are computed
#: exactly at once; larger sets are refined first (k / 4: 1/16 of the work per level).
EXACT_POSES = 20_000


@dataclass(frozen=True)
class GlobalMinimum:
    """The global minimum pose (x_um, y_um, twist_deg) and its energy (J).

    how: "landscape" (read off a landscape), "absolute bound", "cell bound" or "full
    landscape" (how :func:`global_minimum` proved it). poses: landscape poses computed to
    find it (beyond those it was given); seconds: the time it took.
    """

    x_um: float
    y_um: float
    twist_deg: float
    energy_J: float
    how: str = "landscape"
    poses: int = 0
    seconds: float = 0.0

    @property
    def pose(self) -> tuple[float, float, float]:
        return (self.x_um, self.y_um, self.twist_deg)


def landscape_minimum(ls: Landscape) -> GlobalMinimum:
    """The global minimum of ``ls`` (its own grid: the scene's when ``ls`` is the full landscape)."""
    return GlobalMinimum(*ls.global_minimum(), how="landscape")


def global_minimum(
    scene: Scene,
    landscape: Landscape | None = None,
    evaluated: tuple | list = (),
    backend: str = "auto",
    engine: PathEnergy | None = None,
) -> GlobalMinimum:
    """The global minimum of ``scene``'s energy over its whole pose grid.

    Args:
        scene: what to simulate.
        landscape: a landscape to read it off (its grid decides; pass the full landscape).
        evaluated: boxes of the scene's landscape already built (e.g. a trajectory's), reused.
        backend: as :func:`simulator.landscape.build_landscape`.
        engine: the run's :class:`~simulator.landscape.PathEnergy`, when it has one: small
            boxes are then computed pose by pose, and a meniscus footprint's mass and block
            maxima come from its sparse form, never from a rotation of the whole canvas.
    """
    if landscape is not None:
        return landscape_minimum(landscape)
    t0 = time.perf_counter()
    search = _Search(scene, backend, engine)
    for ls in evaluated:
        search.add(ls, counted=False)
    how = search.run()
    x, y, t, e = search.best()
    return GlobalMinimum(x, y, t, e, how=how, poses=search.poses, seconds=time.perf_counter() - t0)


def require_minimum_fits(scene: Scene, path_engine: bool = False) -> None:
    """Refuse (InputError), before a run that will need it, a global minimum that
    :func:`global_minimum` could not find within the memory budget: the bound's chip canvas
    and, with a meniscus, the chip's footprint (``path_engine``: the free contact lines'
    footprint comes from the run's :class:`PathEnergy`, never rotated onto the whole canvas);
    for a scene the bound does not cover (a repulsive pad, a meniscus below a pixel) one
    twist of the whole landscape, which the search then builds twist by twist. Sizes only:
    nothing rotated or transformed."""
    from simulator.landscape._build import _layout, require_landscape_fits

    if _full_search(scene):
        require_landscape_fits(scene, twists=scene.twist_axis.values()[:1])
        return
    lay = _layout(scene, None, (0, 0), None, check_budget=False)  # the footprint priced here
    rotated = bool(lay["chip_blur"]) and not (path_engine and scene.wall_profile is not None)
    _Bounds.require_fits(scene, lay["canvas"], rotated)


def minimum_box(
    scene: Scene,
    minimum: GlobalMinimum,
    engine: PathEnergy | None = None,
    backend: str = "auto",
) -> Landscape:
    """A box of the landscape around the global minimum that holds its floor: the poses within
    the noise floor of its energy, connected to it (:meth:`Landscape.floor_extent`, labelled as
    on the full landscape: across the twist axis's ends only where the box holds the whole
    axis). Grown (twice the half-width, or twice the band of twists) until the floor touches
    no side where the box stops short of the scene's grid, so its floor and its curvature at the
    minimum are the full landscape's. The first box holds the free contact lines' floor
    (``d_s`` beyond alignment, :class:`simulator.physics.WallProfile`). For the outcome of a
    run that did not build the whole landscape (:func:`simulator.motion.simulate`)."""
    from simulator.landscape._build import build_landscape
    from simulator.landscape._rotation import _chip_reach_px

    ta = scene.twist_axis
    n, s = ta.count, scene.um_per_px
    cx, cy = int(round(minimum.x_um / s)), int(round(minimum.y_um / s))
    k = 0
    if n > 1:
        k = int(round((minimum.twist_deg - float(ta.values_at(0))) / ta.step_deg))
        k = k % n if ta.periodic else min(max(k, 0), n - 1)
    reach = max(scene.wall_profile.substrate_reach_px, 0.0) if scene.wall_profile else 0.0
    half = int(math.ceil(reach)) + 4
    # The twist that moves the chip's corners by that reach.
    corner = math.hypot(*_chip_reach_px(scene.chip, False))
    steps = math.degrees(reach / max(corner, 1.0)) / ta.grid_step_deg if n > 1 else 0
    band = int(math.ceil(steps)) + 1
    while True:
        lo, hi = (max(k - band, 0), min(k + band, n - 1)) if n > 1 else (0, 0)
        twists = list(range(lo, hi + 1))
        if engine is not None and half <= PATH_BOX_PX:
            ls = engine.box(twists, (cx, cy), half)
        else:
            ls = build_landscape(
                scene,
                twists=ta.values_at(np.asarray(twists)),
                center_px=(cx, cy),
                half_px=half,
                backend=backend,
                label="the global minimum's floor",
            )
        (t0, t1), (y0, y1), (x0, x1) = ls.floor_extent()
        nt, ny, nx = ls.energy.shape
        twist_open = (t0 == 0 and lo > 0) or (t1 == nt - 1 and hi < n - 1)
        (ylo, yhi), (xlo, xhi) = ls.cut[1], ls.cut[2]
        xy_open = (
            (y0 == 0 and ylo)
            or (y1 == ny - 1 and yhi)
            or (x0 == 0 and xlo)
            or (x1 == nx - 1 and xhi)
        )
        if not (twist_open or xy_open):
            return ls
        band, half = band * (2 if twist_open else 1), half * (2 if xy_open else 1)


def _full_search(scene: Scene) -> bool:
    """Whether the search builds the whole landscape (no bound covers the scene)."""
    return _delta_gamma(scene) >= 0 or (
        getattr(scene.effects, "meniscus", False) and not _Bounds.covers_meniscus(scene)
    )


# ----------------------------------------------------------------------------- search
class _Piece:
    """A built box, reduced to its extent and its tie candidates (energies within the
    noise floor of its own lowest: a superset of its poses that tie the global minimum)."""

    def __init__(self, ls: Landscape, floor: float):
        e = ls.energy
        self.low = float(e.min())
        idx = np.flatnonzero(e <= self.low + floor)
        it, iy, ix = np.unravel_index(idx, e.shape)
        self.x, self.y, self.t, self.e = (
            ls.x_um[ix],
            ls.y_um[iy],
            ls.twist_deg[it],
            e.reshape(-1)[idx].astype(float),
        )
        s = ls.um_per_px
        self.rect = (ls.x_um[0] / s, ls.x_um[-1] / s, ls.y_um[0] / s, ls.y_um[-1] / s)
        self.twists = np.asarray(ls.twist_deg, float)


class _Search:
    def __init__(self, scene: Scene, backend: str, engine: PathEnergy | None = None):
        from simulator.landscape._build import energy_scale_J

        self.scene, self.backend, self.engine = scene, backend, engine
        ta = scene.twist_axis
        self.axis, self.wrap, self.period = ta.values(), ta.periodic, ta.period_deg
        self.step = ta.grid_step_deg
        self.s = scene.um_per_px
        eps = np.finfo(scene.dtype).eps
        from simulator.landscape._correlator import NOISE_FACTOR

        self.floor = float(NOISE_FACTOR * eps * max(energy_scale_J(scene), np.finfo(float).tiny))
        self.pieces: list[_Piece] = []
        self.poses = 0
        self.how = "nominal"  # the step of the proof, for the waiting lines

    # -- pieces
    def add(self, ls: Landscape, counted: bool = True) -> None:
        self.pieces.append(_Piece(ls, self.floor))
        _debug(
            f"piece {ls.energy.shape} at x {ls.x_um[0]:g}..{ls.x_um[-1]:g}, twists {ls.twist_deg[0]:g}..{ls.twist_deg[-1]:g}: low {self.pieces[-1].low:.6g}{'' if counted else ' (given)'}"
        )
        if counted:
            self.poses += int(ls.energy.size)

    def build(self, twist_idx, center_px: tuple[int, int], half_px: int | None) -> None:
        """Build the box at the axis twists ``twist_idx`` in chunks that fit a quarter of the budget."""
        from simulator.landscape._build import _box, build_landscape
        from simulator.landscape._posegrid import consecutive_runs

        twist_idx = sorted(
            {
                int(j) % len(self.axis) if self.wrap else int(j)
                for j in twist_idx
                if self.wrap or 0 <= j < len(self.axis)
            }
        )
        if not twist_idx:
            return
        if self.engine is not None and half_px is not None and half_px <= PATH_BOX_PX:
            for run in consecutive_runs(twist_idx):  # pose by pose
                self.add(self.engine.box(run, center_px, half_px))
            return
        one = _box(self.scene, self.axis[twist_idx[:1]], center_px, half_px)["landscape_bytes"]
        chunk = max(1, int(self.scene.memory_budget_mb * 2**20 / 4 // max(one, 1)))
        for run in consecutive_runs(twist_idx):  # each landscape holds one run of the twist axis
            for i in range(0, len(run), chunk):
                tw = self.axis[run[i : i + chunk]]
                self.add(
                    build_landscape(
                        self.scene,
                        twists=tw,
                        center_px=center_px,
                        half_px=half_px,
                        backend=self.backend,
                        label=f"global minimum: {self.how} box",
                    )
                )

    def low(self) -> float:
        return min(p.low for p in self.pieces)

    def best(self) -> tuple[float, float, float, float]:
        """The tie nearest the nominal pose among the poses within the floor of the lowest energy."""
        lo = self.low()
        parts = [(p.x, p.y, p.t, p.e) for p in self.pieces if p.low <= lo + self.floor]
        x, y, t, e = (np.concatenate(v) for v in zip(*parts, strict=True))
        keep = e <= lo + self.floor
        x, y, t, e = x[keep], y[keep], t[keep], e[keep]
        k = nominal_order(x, y, t, self.s, self.step, self.period)[0]
        return float(x[k]), float(y[k]), float(t[k]), float(e[k])

    def covered(self, j: int, x0, x1, y0, y1) -> np.ndarray:
        """Which px rectangles [x0, x1] x [y0, y1] (arrays) at axis twist j some piece holds."""
        tw = self.axis[j]
        out = np.zeros(np.shape(x0), bool)
        for p in self.pieces:
            d = p.twists - tw
            if self.wrap:
                d = np.mod(d + self.period / 2, self.period) - self.period / 2
            if not np.any(np.abs(d) <= 1e-6 * self.step):
                continue
            px0, px1, py0, py1 = p.rect
            out |= (px0 <= x0 + 1e-6) & (x1 <= px1 + 1e-6) & (py0 <= y0 + 1e-6) & (y1 <= py1 + 1e-6)
        return out

    # -- the search
    def run(self) -> str:
        scene = self.scene
        if _full_search(scene):
            return self._full()
        n = len(self.axis)
        k0 = int(np.argmin(np.abs(self.axis)))
        band = NOMINAL_BALL_PX // NOMINAL_PX_PER_STEP
        near = list(range(k0 - band, k0 + band + 1)) if n > 1 else [0]
        h = NOMINAL_BALL_PX
        if not all(
            self.covered(j % n if self.wrap else j, -h, h, -h, h)
            for j in near
            if self.wrap or 0 <= j < n
        ):
            self.build(near, (0, 0), h)  # the nominal box
        bounds = _Bounds(scene, self.engine)
        x, y, t, e = self.best()
        r, _ = nominal_distance(x, y, t, self.s, self.step, self.period)
        # An axis longer than one symmetry period holds poses equivalent to those near 0
        # outside the nominal box, which could win a tie: the bound alone does not settle it.
        one_period = self.wrap or n == 1 or self.axis[-1] - self.axis[0] < self.period - 1e-9
        if (
            one_period
            and r <= NOMINAL_BALL_PX
            and e <= bounds.scale * bounds.absolute_px() + self.floor
        ):
            return "absolute bound"
        return self._cells(bounds)

    def _cells(self, b: _Bounds) -> str:
        from foundation import progress_bar, shows_wait

        n = len(self.axis)
        k = max(2, math.ceil(max(b.ny, b.nx) / CELLS_PER_AXIS))
        regions = {
            j: None for j in range(n)
        }  # twist index -> translations (x0, x1, y0, y1) px left (None: all)
        first = True
        self.how = "cell-bound"
        while regions:
            with progress_bar(
                shows_wait(len(regions) * b.seconds_per_twist(k)),
                len(regions),
                f"global minimum: bound over {k} x {k} px cells",
                "twist",
            ) as bar:
                cand = {}
                for j, reg in regions.items():
                    cand[j] = b.cells(j, k, reg)
                    bar.update(1)
            # keep the cells that could hold a lower pose or a tie, and are not computed yet
            left = self._prune(cand, k, b)
            if not left:
                break
            j = min(left, key=lambda j: left[j][2].min())
            i = int(np.argmin(left[j][2]))
            # The most promising cell, computed exactly when it likely beats the best found so
            # far (its bound, less the bound's slack of about k px along the chip's outline,
            # still holds more overlap): the energy to beat drops, and most cells go.
            likely = left[j][2][i] / b.scale - k * b.perimeter_px() > self.low() / b.scale
            if first and likely:
                x0, x1, y0, y1 = (int(v) for v in b.cell_px(left[j][0][i], left[j][1][i], k))
                self.build(
                    range(j - 2, j + 3) if n > 1 else [0],
                    ((x0 + x1) // 2, (y0 + y1) // 2),
                    (max(x1 - x0, y1 - y0) + 1) // 2 + 8,
                )
                left = self._prune(left, k, b)
                if not left:
                    break
            first = False
            regions = {}
            for j, (mm, nn, _) in left.items():
                x0, x1, y0, y1 = b.cell_px(mm, nn, k)
                regions[j] = (int(x0.min()), int(x1.max()), int(y0.min()), int(y1.max()))
            union = _union(regions.values())
            poses = len(regions) * (union[1] - union[0] + 1) * (union[3] - union[2] + 1)
            _debug(
                f"level k={k}: {sum(len(v[0]) for v in left.values())} cells left at {len(left)} twists, {poses:,} poses to compute"
            )
            if k <= 4 or poses <= EXACT_POSES:
                self._exact(regions)
                break
            k = max(2, k // 4)
        return "cell bound"

    def _prune(self, cand: dict, k: int, b: _Bounds) -> dict:
        beat = self.low() + self.floor
        left = {}
        for j, (mm, nn, lo_e) in cand.items():
            keep = lo_e <= beat
            if not keep.any():
                continue
            mm, nn, lo_e = mm[keep], nn[keep], lo_e[keep]
            x0, x1, y0, y1 = b.cell_px(mm, nn, k)
            keep = ~self.covered(j, x0, x1, y0, y1)
            if keep.any():
                left[j] = (mm[keep], nn[keep], lo_e[keep])
        return left

    def _exact(self, regions: dict) -> None:
        """Compute the cells left: one box over their union at the twists that have any, or,
        when that box would be more than twice their own, one box per twist."""

        def square(r):
            return (int(math.ceil(max(r[1] - r[0], r[3] - r[2]) / 2)) + 1) * 2 + 1

        union = _union(regions.values())
        if len(regions) * square(union) ** 2 <= 2 * sum(square(r) ** 2 for r in regions.values()):
            groups = [(sorted(regions), union)]
        else:
            groups = [([j], r) for j, r in sorted(regions.items())]
        for twists, (x0, x1, y0, y1) in groups:
            self.build(
                twists,
                ((x0 + x1) // 2, (y0 + y1) // 2),
                int(math.ceil(max(x1 - x0, y1 - y0) / 2)) + 1,
            )

    def _full(self) -> str:
        self.how = "full-landscape"
        self.build(range(len(self.axis)), (0, 0), None)
        return "full landscape"


def _union(rects) -> tuple[int, int, int, int]:
    """The bounding box (x0, x1, y0, y1) of rectangles (x0, x1, y0, y1)."""
    r = np.array(list(rects))
    return int(r[:, 0].min()), int(r[:, 1].max()), int(r[:, 2].min()), int(r[:, 3].max())


def _debug(text: str) -> None:
    import os
    import sys

    if os.environ.get("SELFALIGN_OPTIMUM_DEBUG"):
        print(f"optimum: {text}", file=sys.stderr)
