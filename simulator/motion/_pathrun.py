"""A greedy or gradient run at the cost of its path: small boxes of the landscape that
follow the chip, computed pose by pose (:class:`simulator.landscape.PathEnergy`), and the
choice between that and the FFT boxes (:func:`choose_engine`).

The steppers are today's, unchanged: each box is a landscape on the grid the FFT engine
would give, cut on its sides; the run stops at a cut side (status EDGE) and resumes in
the next box, centred on the chip (greedy and gradient are memoryless, so the path is the
path on the whole landscape). Poses that boxes share are computed once.
"""

from __future__ import annotations

import math

import numpy as np

from simulator.landscape import (
    Landscape,
    PathEnergy,
    PoseGrid,
    consecutive_runs,
    path_engine_supported,
)
from simulator.scene import Scene

ENGINES = ("auto", "fft", "path")
#: Half-width (px) and twist half-band (steps) of the boxes that follow the chip. Greedy
#: stops at a box's side, gradient 2 grid steps before it (its differences and interpolation
#: reach that far), so gradient needs wider boxes to move at all.
FOLLOW_BOX = {"greedy": (4, 1), "gradient": (6, 3)}
#: Measured costs per unit (2-core CPU): one FFT-correlated pose of a canvas, and one
#: gathered outline step of the path engine. "auto" takes the path engine when it is
#: cheaper by this factor.
FFT_UNIT, PATH_UNIT, AUTO_MARGIN = 25.0, 3.0, 4.0


def _chip_reach_px(scene: Scene) -> float:
    h, w = scene.chip.shape
    return 0.5 * math.hypot(h, w) + scene.meniscus_margin_px


def estimate(scene: Scene, start, method: str, band_steps: int, band_px: int) -> dict:
    """Rough work (arbitrary units) of one run with each engine, before anything is built:
    the FFT boxes (planes x canvas) and the path engine (poses along the path x outline steps)."""
    s = scene.um_per_px
    sx, sy = abs(start[0]) / s, abs(start[1]) / s
    ta = scene.twist_axis
    k_travel = 0.0
    if ta.count > 1:
        k_travel = abs(start[2]) / ta.step_deg
        if ta.periodic:
            k_travel = min(k_travel, ta.count / 2)
    rc = _chip_reach_px(scene)
    half = math.ceil((max(sx, sy) + 2 * band_px) / 2)
    planes = min(2 * band_steps + 1 + k_travel, ta.count)
    fft = planes * (2 * half + 2 * rc) ** 2 * FFT_UNIT
    h, t = FOLLOW_BOX.get(method, FOLLOW_BOX["gradient"])
    steps = max(sx, sy) + k_travel + 2 * h
    nnz = 14.0 * rc
    path = steps * 2 * (2 * h + 1) * min(2 * t + 1, ta.count) * nnz * PATH_UNIT
    return {"fft": fft, "path": path}


def choose_engine(scene: Scene, start, method: str, engine: str, band_steps: int, band_px: int) -> str:
    """"fft" or "path" for a greedy or gradient run without a landscape (``engine``: as asked,
    "auto": the path engine where it covers the scene and is cheaper by :data:`AUTO_MARGIN`)."""
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    ok, why = path_engine_supported(scene)
    if ok and scene.wall_profile is not None:
        # The energies agree (tested), but the outcome of a run that ends on the floor the
        # free lines float the chip on is classified on its last box, whose width decides it.
        ok, why = False, "a run on the free contact lines' floor is not classified the same yet"
    if engine == "path" and not ok:
        from patterns.errors import InputError

        raise InputError(f"the path-cost engine does not cover this scene: {why}")
    if engine != "auto":
        return engine
    if not ok:
        return "fft"
    e = estimate(scene, start, method, band_steps, band_px)
    return "path" if e["fft"] > AUTO_MARGIN * e["path"] else "fft"


def path_boxes(scene: Scene, method: str, cost):
    """(generator, engine): the generator is sent the chip's pose and yields the box around
    it (None when the box would be the last one again: the chip cannot move on), as
    :func:`simulator.motion._trajectory._box_landscapes` does."""
    pe = PathEnergy(scene)
    half, band = FOLLOW_BOX.get(method, FOLLOW_BOX["gradient"])

    def gen():
        ta = scene.twist_axis
        n, s = ta.count, scene.um_per_px
        last = None
        pose = yield
        while True:
            cx, cy = (int(v) for v in np.round(pose[:2] / s))
            k = int(round((pose[2] - float(ta.values_at(0))) / ta.step_deg)) if n > 1 else 0
            lo, hi = k - band, k + band
            if n == 1 or (ta.periodic and hi - lo + 1 >= n):
                lo, hi = 0, n - 1
            elif not ta.periodic:
                lo, hi = max(lo, 0), min(hi, n - 1)
            if (lo, hi, cx, cy) == last:
                pose = yield None
                continue
            last = (lo, hi, cx, cy)
            want = list(range(lo, hi + 1))
            planes: dict[int, np.ndarray] = {}
            template = None
            for run in consecutive_runs({j % n for j in want}):
                ls = pe.box(run, (cx, cy), half)
                template = ls
                planes.update({j: ls.energy[i] for i, j in enumerate(run)})
            g = template.grid
            grid = PoseGrid((len(want),) + g.shape[1:], g.um_per_px, ta, ta.periodic and len(want) == n,
                            (ta.cut_of(lo, len(want)), g.cut[1], g.cut[2]), g.rg_px, g.x_first_px, g.y_first_px, lo)
            pose = yield Landscape(energy=np.stack([planes[j % n] for j in want]), grid=grid, delta_gamma=template.delta_gamma,
                                   energy_scale_J=template.energy_scale_J, stats=template.stats)

    return gen(), pe


def nominal_box(scene: Scene, pe: PathEnergy) -> list[Landscape]:
    """The boxes :func:`simulator.landscape.global_minimum` looks in first, pose by pose."""
    return pe.nominal_boxes()
