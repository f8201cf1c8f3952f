"""What a single run will need, priced before any work: JAX is not imported here.

The checks :func:`simulator.motion.simulate` and ``selfalign simulate`` run before anything
is compiled, rotated or transformed: the recorded path (:func:`price_run`), the start
inside the translation window (:func:`require_start_in_window`), and the first landscape,
the meniscus footprint and the global minimum's proof (:func:`require_run_fits`), with
the boxes' geometry they share with the run (the box around the start and the aligned pose,
the band of twists around the chip's). :func:`plan_run` decides and prices a run once and
returns its :class:`RunPlan`, which :func:`simulator.motion.simulate` takes (``plan=``)
instead of planning again. The command prices a run before it imports JAX, so a refusal
costs neither its import time nor its memory.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from foundation import InputError, require_fits
from simulator.core import DYNAMIC_METHODS, MAX_STEPS_LIMIT
from simulator.landscape import consecutive_runs
from simulator.scene import Scene, TwistAxis

__all__ = [
    "BAND_PX",
    "BAND_STEPS",
    "PATH_BYTES_PER_STEP",
    "RunPlan",
    "plan_run",
    "price_run",
    "require_run_fits",
    "require_start_in_window",
]

#: Peak bytes per recorded step of one run (device buffers, their host copies and the
#: Trajectory's float64 path and energies): stepping and dynamics.
PATH_BYTES_PER_STEP = {"stepping": 96, "dynamics": 320}
#: The boxes of a greedy or gradient run (:func:`simulate`): twists within this many steps
#: of the chip's, translations this many px beyond the start and the aligned pose.
BAND_STEPS, BAND_PX = 3, 48


def price_run(scene: Scene, method: str, max_steps: int) -> None:
    """Refuse, before anything is compiled or allocated, a ``max_steps`` that overflows the
    step counter or whose recorded path would not fit the scene's memory budget."""
    if isinstance(max_steps, bool) or not isinstance(max_steps, int | np.integer) or max_steps < 1:
        raise InputError(f"max steps must be a whole number >= 1, got {max_steps!r}")
    if max_steps > MAX_STEPS_LIMIT:
        raise InputError(
            f"max steps must be at most {MAX_STEPS_LIMIT:,} (the step counter is 32-bit), got {max_steps:,}"
        )
    per_step = PATH_BYTES_PER_STEP["dynamics" if method in DYNAMIC_METHODS else "stepping"]
    require_fits(
        f"the path of up to {max_steps:,} steps",
        float(max_steps + 1) * per_step,
        "use a smaller --max-steps",
        scene.memory_budget_mb,
    )


@dataclass(frozen=True)
class RunPlan:
    """A run of :func:`simulator.motion.simulate` without a landscape, decided and priced
    before any work (:func:`plan_run`): ``selfalign simulate`` prints its refusals and hands
    it to the run, which then neither chooses its engine nor prices its first landscape again.

    A plan belongs to the scene, start, method and bands it was made for: :meth:`check`
    refuses it with any other (the scene by identity: ``scene.replace(...)`` is another scene).
    """

    #: the engine the boxes are computed with: "fft" or "path" for greedy and gradient
    #: (:func:`simulator.motion.choose_engine`), the engine asked for the dynamics (they
    #: build the whole landscape)
    engine: str
    #: "greedy", "gradient", "overdamped" or "inertial"
    method: str
    #: the start pose (x_um, y_um, twist_deg), inside the translation window
    start: tuple[float, float, float]
    #: the run's boxes: twists within ``band_steps`` steps of the chip's, translations
    #: ``band_px`` px beyond the start and the aligned pose
    band_steps: int
    band_px: int
    #: the bytes of the first landscape's energy array (the first box and band of twists, or
    #: the whole landscape of the dynamics; 0 on the path engine, which builds no FFT box)
    landscape_bytes: int
    #: a footprint state's boxes on the path engine (:func:`plan_run`'s ``path``)
    path: bool = False
    #: the scene planned for (compared by identity, not shown)
    scene: Scene | None = field(default=None, compare=False, repr=False)

    def check(
        self,
        scene: Scene,
        start: Sequence[float],
        method: str,
        band_steps: int,
        band_px: int,
        path: bool,
    ) -> None:
        """InputError (one line) unless this plan was made for this run: the same scene
        object, start, method, bands and ``path``."""
        made = (self.start, self.method, self.band_steps, self.band_px, self.path)
        asked = (_pose(start), method, band_steps, band_px, path)
        if self.scene is not scene or made != asked:
            what = "scene" if self.scene is not scene else _differs(made, asked)
            raise InputError(
                f"the run plan was made for another {what}: call plan_run with the scene, start, "
                "method and bands the run is given (or leave plan out)"
            )


def _pose(start: Sequence[float]) -> tuple[float, float, float]:
    return float(start[0]), float(start[1]), float(start[2])


def _differs(made: tuple, asked: tuple) -> str:
    names = ("start", "method", "band_steps", "band_px", "path")
    return next(n for n, a, b in zip(names, made, asked, strict=True) if a != b)


def plan_run(
    scene: Scene,
    start,
    method: str,
    engine: str = "auto",
    band_steps: int = BAND_STEPS,
    band_px: int = BAND_PX,
    path: bool = False,
) -> RunPlan:
    """The plan of a run of :func:`simulate` without a landscape: its engine, its start
    checked against the window and its first landscape priced (:func:`require_run_fits`),
    before JAX is imported: the one plan of the library's run and of ``selfalign simulate``,
    made once (``simulate(..., plan=)`` takes it).

    Greedy and gradient take :func:`simulator.motion.choose_engine`'s engine (``engine``:
    "auto", "fft" or "path"), the dynamics ``engine`` unchanged (they build the whole
    landscape); ``path``: a footprint state's boxes, on the path engine. Returns the
    :class:`RunPlan`.
    """
    if path:
        engine = "path"
    elif method not in DYNAMIC_METHODS:
        from simulator.motion._pathrun import choose_engine

        engine = choose_engine(scene, start, method, engine, band_steps, band_px)
    require_start_in_window(scene, start)
    nbytes = require_run_fits(scene, start, method, band_steps, band_px, engine)
    return RunPlan(engine, method, _pose(start), band_steps, band_px, nbytes, path, scene)


def _fit_box(
    box: tuple[tuple[int, int], int] | None, pose_px: np.ndarray, margin: int
) -> tuple[tuple[int, int], int]:
    """The square box (centre px, half-width px) holding the start, the aligned pose (0, 0),
    the old box and a margin."""
    pts = [(0, 0), tuple(pose_px)]
    if box is not None:
        (cx, cy), h = box
        pts += [(cx - h, cy - h), (cx + h, cy + h)]
    pts = np.array(pts, float)
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    center = np.round((lo + hi) / 2).astype(int)
    return (int(center[0]), int(center[1])), int(np.ceil(((hi - lo) / 2).max()))


def require_start_in_window(scene: Scene, start: Sequence[float]) -> None:
    """InputError for a start beyond the scene's translation window (``window_um``): the pose grid
    ends there, so there is no landscape to step on (the run would grow its box forever)."""
    w = scene.window_um
    if w is not None and max(abs(start[0]), abs(start[1])) > w:
        raise InputError(
            f"start pose ({start[0]:g}, {start[1]:g}) um lies outside the translation window of +-{w:g} um "
            f"(--window / window_um); widen the window to at least {max(abs(start[0]), abs(start[1])):g} um, or leave it out"
        )


def _twist_band(ta: TwistAxis, twist_deg: float, band_steps: int) -> tuple[int, int]:
    """(first, last) axis index of the band of +-``band_steps`` twists around ``twist_deg`` (may
    run past the ends of a periodic axis; the whole axis when the band covers it)."""
    n = ta.count
    k = int(round((twist_deg - float(ta.values_at(0))) / ta.step_deg)) if n > 1 else 0
    lo, hi = k - band_steps, k + band_steps
    if n == 1 or (ta.periodic and hi - lo + 1 >= n):
        lo, hi = 0, n - 1
    elif not ta.periodic:
        lo, hi = max(lo, 0), min(hi, n - 1)
    return lo, hi


def require_run_fits(
    scene: Scene,
    start: Sequence[float],
    method: str,
    band_steps: int = BAND_STEPS,
    band_px: int = BAND_PX,
    engine: str = "fft",
) -> int:
    """Refuse (InputError), before anything is compiled, rotated or transformed, a run whose
    first landscape does not fit the memory budget: the first box and band of twists of a
    greedy or gradient run (:func:`simulate`), the whole landscape of the dynamics, each with
    the chip's meniscus footprint, and what the global minimum's proof after a greedy or
    gradient run needs at least. Boxes built later are priced as they come (in chunks of
    twists that fit). ``engine`` "path" (:func:`simulator.motion.choose_engine`): no FFT box;
    the chip's footprint and the global minimum's bound, which then takes the footprint from
    the engine. Returns the bytes of the first landscape's energy array (0 on the path engine)."""
    from simulator.landscape import require_landscape_fits, require_minimum_fits

    if method in DYNAMIC_METHODS:
        return require_landscape_fits(scene)
    if engine == "path":
        require_minimum_fits(scene, path_engine=True)  # the footprint priced there first
        return 0
    ta = scene.twist_axis
    (cx, cy), half = _fit_box(
        None, np.round(np.asarray(start[:2], float) / scene.um_per_px), band_px
    )
    lo, hi = _twist_band(ta, float(start[2]), band_steps)
    runs = consecutive_runs({j % ta.count for j in range(lo, hi + 1)})
    nbytes = 0
    if runs:  # else a start twist beyond the axis: refused by simulate with its own message
        longest = max(runs, key=len)
        nbytes = require_landscape_fits(
            scene, twists=ta.values_at(np.asarray(longest)), center_px=(cx, cy), half_px=half
        )
    require_minimum_fits(scene)
    return nbytes
