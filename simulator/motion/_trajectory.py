"""One trajectory from one start: the host side around the pure steppers.

:func:`simulate` builds only the part of the landscape a run needs (see
:class:`_Boxes`): the stepper runs on a box of translations and a band of twists,
stops with status EDGE when it reaches a side, and resumes from where it stopped
once the band (or box) has moved. Greedy and gradient stepping are memoryless, so the path
equals a run on the full landscape (tested), at a fraction of the cost
(``Trajectory.cost``, a :class:`~simulator.motion.RunCost`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp
import numpy as np

from foundation import InputError, compiling, shows_wait, wait_line
from simulator.core import (
    DEFAULT_MAX_STEPS,
    DEG_TOL,
    DYNAMIC_METHODS,
    MAX_TWIST_DEG,
    METHODS,
    OUTCOMES,
    UM,
    tiny,
)
from simulator.landscape import (
    GlobalMinimum,
    Landscape,
    PoseGrid,
    build_landscape,
    consecutive_runs,
    global_minimum,
)
from simulator.motion._cost import RunCost
from simulator.motion._field import field_and_grid
from simulator.motion._pinning import pin_lines
from simulator.motion._pricing import (
    BAND_PX,
    BAND_STEPS,
    RunPlan,
    _fit_box,
    _twist_band,
    plan_run,
    price_run,
)
from simulator.motion._steppers import RunState, flat_at, jitted
from simulator.motion._stepping import (
    CONVERGED,
    EDGE,
    EVENT,
    MAX_STEPS,
    classify,
    reference_gradient,
)
from simulator.physics import align_tolerance, pin_per_index
from simulator.scene import Scene

#: Largest |x|, |y| of a start in pixels (float32 holds every whole pixel up to 2**24, and
#: int32 grid indices have room); its largest |twist| is simulator.core's MAX_TWIST_DEG.
MAX_START_PX = 2**24
#: Seconds per landscape pose of the steps after a whole landscape is built (a dynamic run, or
#: a landscape given), for their waiting lines (:func:`simulator.core.wait_line`): the well's
#: floor labelled around the global minimum, the stepper's field (its padded copy of the
#: energy; a dynamic stepper's compile is said after it, :func:`simulator.core.compiling`),
#: and the classification of the run's end (plateau tests, the minimum, the limit).
#: Measured on the 730 um four-pad at 2 um/px (345 M poses) on a loaded 2-core machine:
#: 9-14 s, 3-4 s, 5.6-8.7 s; the rates are set lower, so that a line shows rather than a
#: wait passes silent.
FLOOR_S_PER_POSE, FIELD_S_PER_POSE, END_S_PER_POSE = 12e-9, 12e-9, 10e-9


@dataclass(frozen=True)
class Trajectory:
    """A path with its energy curve and outcome.

    path: (N, 3) poses (x_um, y_um, twist_deg), start first; twist unwrapped.
    energy_J: (N,) energy per recorded pose. t_s: (N,) times for dynamics, else None.
    steps: moves (stepping) or accepted solver steps (dynamics). time_s: final time
    (dynamics) or None. cost: the landscape computed against the full one, and the seconds
    (:class:`~simulator.motion.RunCost`; None for a run piece not yet packaged).
    """

    method: str
    outcome: str
    path: np.ndarray
    energy_J: np.ndarray
    steps: int
    time_s: float | None = None
    t_s: np.ndarray | None = None
    cost: RunCost | None = None
    #: The scene's global minimum (x_um, y_um, twist_deg) the outcome was measured against.
    optimum: tuple[float, float, float] | None = None
    #: With a finite meniscus, the final pose of a gradient or dynamic run refined below the
    #: grid (the minimum of the interpolated landscape next to it, :mod:`simulator.landscape`).
    refined: tuple[float, float, float] | None = None
    #: With ``--dispense``, the wetted footprint as the run's state: its ``initial`` wet pads
    #: and its ``events`` (docs/physics.md §3.5; :mod:`simulator.motion`).
    footprint: dict | None = None
    #: What limits the final pose's error (:func:`simulator.motion.error_limit`):
    #: ``{"by": "grid" | "floor" | "refined", "um": ...}``.
    error_limit: dict | None = None
    #: With free contact lines, the floor the chip floats on (x_um, y_um, twist_deg as
    #: [first, last], :meth:`simulator.landscape.Landscape.floor_range`); None when it does not float.
    floor: dict | None = None

    @property
    def start(self) -> tuple[float, float, float]:
        x, y, t = self.path[0]
        return float(x), float(y), float(t)

    @property
    def final(self) -> tuple[float, float, float]:
        x, y, t = self.path[-1]
        return float(x), float(y), float(t)

    def to_json(self) -> dict:
        def pose(p):
            return {"x_um": float(p[0]), "y_um": float(p[1]), "twist_deg": float(p[2])}

        path = []
        for i, p in enumerate(self.path):
            row = pose(p) | {"energy_J": float(self.energy_J[i])}
            if self.t_s is not None:
                row["t_s"] = float(self.t_s[i])
            path.append(row)
        return {
            "method": self.method,
            "outcome": self.outcome,
            "start": pose(self.path[0]),
            "final": pose(self.path[-1]),
            "steps": int(self.steps),
            "time_s": self.time_s,
            "path": path,
            "cost": {} if self.cost is None else self.cost.to_dict(),
            "optimum": None if self.optimum is None else pose(self.optimum),
            "final_refined": None if self.refined is None else pose(self.refined),
            "error_limit": self.error_limit,
            "floating_range": self.floor,
        } | ({} if self.footprint is None else {"footprint": self.footprint})


def radius_of_gyration_px(scene: Scene) -> float:
    """The chip's radius of gyration (px): :attr:`Scene.chip_rg_px`, derived once per scene
    (the pose grids of its landscapes carry it, and the dynamics' polar moment is built on it)."""
    return scene.chip_rg_px


def is_stiff(method: str, field, grid, params) -> bool:
    """An inertial run is stiff when inertia relaxes (m / c) much faster than the chip
    creeps one pixel under a typical force (overdamped, c s / F): then the IMEX solver
    (:func:`simulator.motion.stiff_solver`) takes ~100 steps where an explicit one takes ~10^4.
    Never with hysteresis: the friction's Moreau-Jean step takes the damping implicitly
    (:class:`simulator.motion.MoreauJean`), and a batch then runs vmapped."""
    if method != "inertial" or field.pinned:
        return False
    f_ref = float(reference_gradient(field, grid)) / (
        grid.um_per_px * UM
    )  # N (J per px -> J per m)
    tau_m = params.mass_kg / params.damping_N_s_m
    tau_c = params.damping_N_s_m * grid.um_per_px * UM / max(f_ref, tiny())
    return tau_m < 0.1 * tau_c


def simulate(
    scene: Scene,
    start: tuple[float, float, float],
    method: str = "greedy",
    max_steps: int = DEFAULT_MAX_STEPS,
    landscape: Landscape | None = None,
    band_steps: int = BAND_STEPS,
    band_px: int = BAND_PX,
    dynamics=None,
    backend: str = "auto",
    engine: str = "auto",
    reference: Landscape | None = None,
    relay=None,
    planes=None,
    path=None,
    plan: RunPlan | None = None,
) -> Trajectory:
    """Run one trajectory from ``start`` = (x_um, y_um, twist_deg).

    Args:
        scene: what to simulate.
        start: the initial pose. Greedy snaps it to the nearest grid pose.
        method: "greedy", "gradient", "overdamped" or "inertial".
        max_steps: bound on moves (or solver steps for dynamics).
        landscape: a precomputed landscape to run on (its global minimum decides
            "aligned"). Default: greedy and gradient build only what the run needs
            (:class:`_Boxes`: translations between the start and the centre plus
            ``band_px`` px, twists within ``band_steps`` steps of the chip's, each plane
            once); dynamics build the whole landscape (the chip may overshoot).
        dynamics: :class:`simulator.motion.DynamicsParams` for the dynamic methods
            (default: from the scene's chip, liquid and calibration).
        engine: how greedy and gradient compute the boxes they need without ``landscape``:
            "fft" (boxes holding the start and the centre, by FFT correlation), "path"
            (small boxes that follow the chip, pose by pose at the cost of the chip's
            outline, :class:`simulator.landscape.PathEnergy`) or "auto" (the path engine for
            chips large enough for it to be the faster, else the FFT engine,
            :func:`simulator.motion.choose_engine`). ``cost.engine`` says which ran.
        reference: with ``landscape``, the landscape whose global minimum and floor "aligned"
            is measured against, when that is not ``landscape`` itself (a footprint state's
            landscape, whose own minimum need not be the aligned pose).
        path: a footprint state's boxes for the path engine (:class:`simulator.motion.StateBoxes`,
            from :func:`simulator.motion.simulate_footprint`): the run steps on that state's
            energy in boxes that follow the chip, each with its relay, and stops at an event.
        plan: the run's :class:`simulator.motion.RunPlan` when the caller has made it
            (:func:`simulator.motion.plan_run` with this scene, start, method and bands):
            the run takes its engine and does not choose or price again (``engine`` is then
            not read). Refused (InputError) when made for another run, or with ``landscape``.
            Default: planned here.
    """
    _validate(scene, start, method, max_steps)
    if plan is not None:
        if landscape is not None:
            raise InputError(
                "a run plan is for a run without a landscape: give plan or landscape, not both"
            )
        plan.check(scene, start, method, band_steps, band_px, path is not None)
        engine = plan.engine
    if scene.dispense is not None and landscape is None:
        # The footprint as the run's state (docs/physics.md §3.5): on the pads' planes, or on
        # the path engine's boxes of each state.
        from simulator.motion._footprint_run import simulate_footprint

        return Trajectory(
            **simulate_footprint(
                scene,
                start,
                method,
                max_steps,
                dynamics,
                backend,
                simulate,
                planes=planes,
                engine=engine,
            )
        )
    decided = _plan(
        scene, start, method, landscape, band_steps, band_px, dynamics, engine, path, plan
    )
    ran = _run(
        scene,
        start,
        decided,
        max_steps,
        landscape,
        band_steps,
        band_px,
        backend,
        reference,
        relay,
        path,
    )
    return _package(scene, decided, ran, max_steps, landscape, backend, reference, relay, path)


def _validate(scene: Scene, start: tuple[float, float, float], method: str, max_steps: int) -> None:
    """The checks of :func:`simulate` before anything is decided: the method, the run's price
    (:func:`simulator.motion.price_run`) and the start pose's numbers and range."""
    if method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    price_run(scene, method, max_steps)
    if len(start) != 3 or not all(math.isfinite(v) for v in start):
        raise InputError(f"start pose must be three finite numbers (um, um, deg), got {start}")
    reach_um = MAX_START_PX * scene.um_per_px
    if max(abs(start[0]), abs(start[1])) > reach_um or abs(start[2]) > MAX_TWIST_DEG:
        raise InputError(
            f"start pose {tuple(start)} is out of range: |x| and |y| must be at most {reach_um:g} um "
            f"({MAX_START_PX} px) and |twist| at most {MAX_TWIST_DEG:g} deg"
        )


@dataclass
class _Plan:
    """What a run of :func:`simulate` was decided to be before it steps."""

    method: str
    #: overdamped or inertial: the whole landscape, built once
    dynamic: bool
    #: the engine chosen for the boxes ("fft", "path", ...; :func:`_run` names the one that ran)
    engine: str
    #: the dynamics' parameters (None for greedy and gradient)
    dynamics: Any
    #: when the run started (``cost.total_s``)
    t0: float


def _plan(
    scene: Scene,
    start: tuple[float, float, float],
    method: str,
    landscape: Landscape | None,
    band_steps: int,
    band_px: int,
    dynamics,
    engine: str,
    path,
    plan: RunPlan | None = None,
) -> _Plan:
    """The engine, the run priced against the memory budget and its start against the window
    (:func:`simulator.motion.plan_run`, or the caller's ``plan``, checked by :func:`simulate`),
    the dynamics' parameters, and the start twist checked against the run's twist axis."""
    dynamic = method in DYNAMIC_METHODS
    if plan is not None:
        engine = plan.engine
    elif landscape is None:
        engine = plan_run(
            scene, start, method, engine, band_steps, band_px, path is not None
        ).engine
    elif path is not None:
        engine = "path"
    if dynamic and dynamics is None:
        from simulator.motion._dynamics_params import DynamicsParams

        dynamics = DynamicsParams.from_scene(scene)
    t0 = time.perf_counter()
    ta = scene.twist_axis
    axis, wrap, step = (
        (ta.values(), ta.periodic, ta.grid_step_deg)
        if landscape is None
        else (landscape.twist_deg, landscape.wrap, landscape.twist_step_deg)
    )
    n = len(axis)
    if not wrap and n > 1 and not (axis[0] - step / 2 <= start[2] <= axis[-1] + step / 2):
        raise InputError(
            f"start twist {start[2]:g} deg is outside the twist range {axis[0]:g}..{axis[-1]:g} deg"
        )
    if n == 1 and abs(start[2] - axis[0]) > DEG_TOL:
        raise InputError(
            f"start twist {start[2]:g} deg: this scene has one twist ({axis[0]:g} deg, twist turned off), "
            f"so the start twist must be {axis[0]:g} deg; give that, or turn twist on"
        )
    return _Plan(method, dynamic, engine, dynamics, t0)


@dataclass
class _Ran:
    """What the stepping of :func:`_run` leaves for :func:`_package`."""

    #: the pieces joined, cut at ``max_steps``
    traj: Trajectory
    #: the stop code (MAX_STEPS when the steps ran out)
    status: int
    #: the last piece's stepper state, its field, grid and landscape (None: the run stopped
    #: where moving its box would not move the chip)
    state: RunState
    field: Any
    grid: Any
    ls: Landscape | None
    #: the pinning per index step and the tolerance of "aligned" the field was made with
    pin: tuple[float, float, float]
    tol: Any
    boxes: _BoxCost
    #: the path engine (None for the FFT engine, a landscape given, or dynamics)
    path_engine: Any
    #: the global minimum, when the path engine found it first (else None)
    opt: GlobalMinimum | None
    #: the engine that ran ("fft", "path" or "landscape")
    engine: str


def _run(
    scene: Scene,
    start: tuple[float, float, float],
    plan: _Plan,
    max_steps: int,
    landscape: Landscape | None,
    band_steps: int,
    band_px: int,
    backend: str,
    reference: Landscape | None,
    relay,
    path,
) -> _Ran:
    """The run: its boxes (or the whole landscape), the stepper on each until it stops away
    from a box's side, the pieces joined and cut at ``max_steps``."""
    method, dynamic, dynamics, engine = plan.method, plan.dynamic, plan.dynamics, plan.engine
    pose = np.asarray(start, float)
    boxes = _BoxCost()
    path_engine = None
    if landscape is None and not dynamic:
        from simulator.motion._pathrun import path_boxes

        if engine == "path":
            around, path_engine = path_boxes(scene, method, boxes, source=path)
    else:
        engine = "landscape" if landscape is not None else "fft"
    if path_engine is None:
        around = _box_landscapes(scene, band_steps, band_px, backend, boxes)
    scale, opt = None, None
    if path_engine is not None:
        from simulator.motion._pathrun import nominal_box

        # The global minimum first (its proof reads the nominal box, pose by pose): its energy
        # is the whole landscape's largest |E|, the force scale of a gradient step, which the
        # small boxes that follow the chip do not hold.
        plain = path_engine if path is None else path.plain
        opt = global_minimum(
            scene, evaluated=nominal_box(scene, plain), backend=backend, engine=plain
        )
        scale = -opt.energy_J if opt.energy_J < 0 else None
    elif reference is not None:
        # A footprint state's landscape: the force scale is the scene's (every pad wet, as
        # the path engine's global minimum gives it), not the state's own largest |E|, so
        # that a state with dry pads steps and stops as on the path engine.
        e_min = float(reference.energy.min())
        scale = -e_min if e_min < 0 else None
    next(around)
    pieces = []
    whole = landscape is not None or dynamic  # the run's landscape is the whole one
    # the pinning lines, made once for all the run's boxes (each box's dtype is the scene's;
    # a path-engine run on a 4000 um chip sets a field on 150 boxes, and the lines' pattern
    # and pad labels are millions of pixels)
    lines_of: dict = {}
    while True:
        if landscape is not None:
            ls = landscape
        elif dynamic:
            ls = build_landscape(scene, backend=backend)
            boxes.count(ls)
        else:
            ls = around.send(pose)
            if ls is None:  # moving the box would not move the chip: stop here
                break
        pin = pin_per_index(scene, ls.um_per_px, ls.twist_step_deg)
        # The tolerance of "aligned" only classifies the end (below), and is static in the
        # field: the boxes of a run step with one, so that the stepper compiles once.
        tol = (1.0, 1.0)
        if whole:
            wel = ls if reference is None else reference
            if scene.wall_profile is not None and not wel.floor_labelled:
                wait_line(
                    f"the well's floor around the global minimum ({wel.energy.size:,} poses)",
                    wel.energy.size * FLOOR_S_PER_POSE,
                )
            tol = align_tolerance(wel, pin, floats=scene.wall_profile is not None)
            wait_line(
                f"the {method} stepper's field on the landscape ({ls.energy.size:,} poses)",
                ls.energy.size * FIELD_S_PER_POSE,
            )
        dt = np.dtype(ls.energy.dtype)
        if dt not in lines_of:
            lines_of[dt] = pin_lines(scene, dt)
        field, grid = field_and_grid(ls, pin=pin, align_tol=tol, scale=scale, lines=lines_of[dt])
        if relay is not None:
            field = field._replace(relay=relay)
        elif path is not None:  # the state's relay on this box
            field = field._replace(relay=path.relay(ls, field.lines))
        if dynamic:  # said here, not before the landscape: the compile comes now
            compiling(method, quiet=not shows_wait(math.inf))
        run = jitted(method, is_stiff(method, field, grid, dynamics))
        state = run(field, grid, dynamics, jnp.asarray(grid.to_index(pose)), max_steps)
        pieces.append(_to_trajectory(method, state, grid))
        if int(state.status) != EDGE or landscape is not None or dynamic:
            break
        if sum(p.steps for p in pieces) >= max_steps:
            break
        pose = np.asarray(pieces[-1].final)
    if path_engine is not None:
        around.close()  # its counter of boxes
        path_engine.close()  # footprints made ahead for twists the run did not reach
    traj = _join(method, pieces)
    status = int(state.status)
    if traj.steps >= max_steps and (status != CONVERGED or traj.steps > max_steps):
        status = MAX_STEPS
        traj = Trajectory(
            method,
            "",
            traj.path[: max_steps + 1],
            traj.energy_J[: max_steps + 1],
            max_steps,
            traj.time_s,
            None if traj.t_s is None else traj.t_s[: max_steps + 1],
        )
    return _Ran(traj, status, state, field, grid, ls, pin, tol, boxes, path_engine, opt, engine)


def _package(
    scene: Scene,
    plan: _Plan,
    ran: _Ran,
    max_steps: int,
    landscape: Landscape | None,
    backend: str,
    reference: Landscape | None,
    relay,
    path,
) -> Trajectory:
    """The run's :class:`Trajectory`: its outcome (flatness where it ended, "aligned" against
    the scene's global minimum), its cost, the final pose refined below the grid and what
    limits its error."""
    method, dynamic, engine = plan.method, plan.dynamic, ran.engine
    traj, status, state = ran.traj, ran.status, ran.state
    field, grid, ls = ran.field, ran.grid, ran.ls
    pin, tol, boxes, path_engine, opt = ran.pin, ran.tol, ran.boxes, ran.path_engine, ran.opt
    whole = landscape is not None or dynamic  # the run's landscape is the whole one
    # Outcome: flatness where the run ended; "aligned" against the scene's global minimum
    # (simulator.landscape: the same pose every command uses, found without the full landscape).
    q_end = grid.to_index(np.asarray(traj.final))
    if whole:
        assert ls is not None  # a whole landscape's run has one
        wait_line(
            f"where the run ended: plateau, global minimum and error limit ({ls.energy.size:,} poses)",
            ls.energy.size * END_S_PER_POSE,
        )
    flat = bool(flat_at(field, grid, state.flat, q_end))
    if opt is None:
        opt = global_minimum(
            scene,
            landscape=reference
            if reference is not None
            else landscape
            if landscape is not None
            else (ls if dynamic else None),
            evaluated=boxes.built,
            backend=backend,
        )
    # The landscape around the global minimum: its floor, the hysteresis window and the
    # error's limit are read there (None: a grid run that needs none of them).
    well = (
        reference
        if reference is not None
        else landscape
        if landscape is not None
        else (ls if dynamic else None)
    )
    if landscape is None and not dynamic and (scene.wall_profile is not None or any(pin)):
        # Aligned anywhere on the floor the chip floats on, or within the hysteresis window:
        # measured around the global minimum as on the full landscape (a box that holds the
        # floor), not on the run's last box.
        from simulator.landscape import minimum_box

        near = minimum_box(
            scene, opt, engine=path_engine if path is None else path.plain, backend=backend
        )
        tol = align_tolerance(near, pin, floats=scene.wall_profile is not None)
        well = near
    if path_engine is not None:
        boxes.poses, boxes.planes, boxes.seconds = (
            path_engine.poses,
            path_engine.rotations,
            path_engine.seconds,
        )
    best = jnp.asarray(grid.to_index(np.asarray(opt.pose)), field.dtype)
    # the simulated time ran out, not the steps, with the chip creeping (classify)
    timed_out = (
        dynamic
        and traj.steps < max_steps
        and float(getattr(state, "kinetic", 0.0)) <= float(field.floor)
    )
    out = classify(
        field._replace(best=best, align_tol=tol),
        grid,
        q_end,
        float(traj.energy_J[-1]),
        status,
        flat,
        timed_out,
    )
    full = full_landscape_poses(scene) if landscape is None else landscape.energy.size
    cost = RunCost(
        engine=engine,
        poses_computed=int(boxes.poses),
        poses_full=int(full),
        fraction_of_full=boxes.poses / full,
        planes=boxes.planes,
        landscape_s=boxes.seconds,
        total_s=time.perf_counter() - plan.t0,
        minimum_poses=int(opt.poses),
        minimum_s=opt.seconds,
        minimum_how=opt.how,
    )
    refined = None
    outcome = OUTCOMES[int(out)]
    if (relay is not None or path is not None) and status == EVENT:
        outcome = "event"  # not an end: the footprint run goes on (simulate_footprint)
    from simulator.motion._accuracy import error_limit, floats

    floating = well is not None and floats(scene, well)
    if (
        scene.meniscus_height_um is not None
        and not any(pin)
        and method != "greedy"
        and outcome in ("aligned", "local_minimum")
        and not floating  # on a flat floor the interpolant's minimum is any pose of it
    ):
        from simulator.landscape import refine_minimum

        r = refine_minimum(ls, *traj.final)
        refined = (r["x_um"], r["y_um"], r["twist_deg"])
    return Trajectory(
        method,
        outcome,
        traj.path,
        traj.energy_J,
        traj.steps,
        traj.time_s,
        traj.t_s,
        cost,
        optimum=opt.pose,
        refined=refined,
        error_limit=error_limit(
            scene, well if well is not None else (ls if refined else None), refined=refined, pin=pin
        ),
        floor=well.floor_range() if floating and well is not None else None,
    )


@dataclass
class _BoxCost:
    """What the boxes of one run cost (poses, planes, seconds) and the landscapes built for
    the current box (reused to find the global minimum)."""

    poses: int = 0
    planes: int = 0
    seconds: float = 0.0
    built: list = field(default_factory=list)

    def count(self, ls: Landscape) -> None:
        self.poses += ls.energy.size
        self.planes += ls.energy.shape[0]
        self.seconds += ls.stats["seconds"]


def _outside(t: Landscape, pose_px: np.ndarray) -> bool:
    """The pose lies on or next to a cut side of the box ``t``: the box must grow."""
    s = t.um_per_px
    x, y = pose_px * s
    (xlo, xhi), (ylo, yhi) = t.cut[2], t.cut[1]
    return bool(
        (xlo and x <= t.x_um[0] + s)
        or (xhi and x >= t.x_um[-1] - s)
        or (ylo and y <= t.y_um[0] + s)
        or (yhi and y >= t.y_um[-1] - s)
    )


def _extent(t: Landscape) -> tuple[float, float, float, float]:
    """The translations (um) a box landscape spans: x first, x last, y first, y last."""
    return (float(t.x_um[0]), float(t.x_um[-1]), float(t.y_um[0]), float(t.y_um[-1]))


def _box_landscapes(scene: Scene, band_steps: int, band_px: int, backend: str, cost: _BoxCost):
    """The part of the landscape one run needs, built as the chip goes: a generator that
    is sent the chip's pose and yields the landscape around it (None: the same as last
    time, so moving the box would not move the chip).

    Translations: one square box holding the start, the aligned pose (0, 0) and a
    margin of ``band_px``; grown (and rebuilt) only if the chip leaves it.
    Twists: a band of +-``band_steps`` around the chip's twist, re-centred whenever
    the chip reaches its end; every twist plane of the box is computed once (the plane
    cache is this generator's own).
    """
    ta = scene.twist_axis
    n, s = ta.count, scene.um_per_px
    box, template, last = None, None, None
    stuck = False  # the box grew and the landscape did not: the window (window_um) cuts it, growing again is futile
    planes: dict[int, np.ndarray] = {}
    builds = 0  # landscapes built, for the waiting lines
    pose = yield
    while True:
        pose_px = np.round(pose[:2] / s)
        before = None
        if box is None or (template is not None and not stuck and _outside(template, pose_px)):
            before = None if template is None else _extent(template)
            box = _fit_box(box, pose_px, band_px)
            planes.clear()
            cost.built.clear()
        lo, hi = _twist_band(ta, pose[2], band_steps)
        if (lo, hi, box) == last:
            pose = yield None
            continue
        last = (lo, hi, box)
        want = list(range(lo, hi + 1))
        (cx, cy), half = box
        for run in consecutive_runs({j % n for j in want} - set(planes)):
            ls = build_landscape(
                scene,
                twists=ta.values_at(np.asarray(run)),
                center_px=(cx, cy),
                half_px=half,
                backend=backend,
                label=f"landscape box {builds + 1}",
            )
            builds += 1
            cost.count(ls)
            cost.built.append(ls)
            template = ls
            planes.update({j: ls.energy[i] for i, j in enumerate(run)})
        assert template is not None  # built on the first pass (its planes were empty)
        if before is not None and _extent(template) == before:
            stuck = True
        g = template.grid
        grid = PoseGrid(
            (len(want),) + g.shape[1:],
            g.um_per_px,
            ta,
            ta.periodic and len(want) == n,
            (ta.cut_of(lo, len(want)), g.cut[1], g.cut[2]),
            g.rg_px,
            g.x_first_px,
            g.y_first_px,
            lo,
        )
        pose = yield Landscape(
            energy=np.stack([planes[j % n] for j in want]),
            grid=grid,
            delta_gamma=template.delta_gamma,
            energy_scale_J=template.energy_scale_J,
            stats=template.stats,
        )


def reference_landscape(
    scene: Scene, backend: str = "auto", reach_steps: int = 2, half_px: int = 16
) -> Landscape:
    """A small box around the aligned pose (0, 0, 0) that locates the global minimum.

    Assumes the minimum lies within ``half_px`` px and ``reach_steps`` twist steps of
    (0, 0, 0), as for a chip on its own pattern; pass a full landscape to
    :func:`simulate` when it does not.
    """
    ta = scene.twist_axis
    n = ta.count
    if n > 1:
        k0 = int(np.argmin(np.abs(ta.values())))
        lo, hi = k0 - reach_steps, k0 + reach_steps
        if not ta.periodic:
            lo, hi = max(lo, 0), min(hi, n - 1)
        twists = None if (ta.periodic and hi - lo + 1 >= n) else ta.values_at(np.arange(lo, hi + 1))
    else:
        twists = None
    return build_landscape(scene, twists=twists, center_px=(0, 0), half_px=half_px, backend=backend)


def full_landscape_poses(scene: Scene) -> int:
    """Poses of the scene's full landscape (what a trajectory would cost without boxes)."""
    from simulator.landscape import estimate_bytes

    return estimate_bytes(scene) // np.dtype(scene.dtype).itemsize


def _to_trajectory(method: str, state: RunState, grid) -> Trajectory:
    n = int(state.step) + 1
    idx = np.asarray(state.path)[:n]
    energy = np.asarray(state.path_energy)[:n].astype(float)
    dynamic = method in DYNAMIC_METHODS
    t_s = np.asarray(state.path_t)[:n].astype(float) if dynamic else None
    time_s = float(state.time_s) if dynamic else None
    return Trajectory(method, "", grid.to_pose(idx), energy, n - 1, time_s, t_s)


def _join(method: str, pieces: list[Trajectory]) -> Trajectory:
    path = np.concatenate([pieces[0].path] + [p.path[1:] for p in pieces[1:]])
    energy = np.concatenate([pieces[0].energy_J] + [p.energy_J[1:] for p in pieces[1:]])
    steps = sum(p.steps for p in pieces)
    t_s = None
    if pieces[0].t_s is not None:
        offs, ts = 0.0, [pieces[0].t_s]
        for prev, p in zip(pieces, pieces[1:], strict=False):
            assert (
                prev.t_s is not None and p.t_s is not None
            )  # every piece of a dynamic run is timed
            offs += prev.t_s[-1]
            ts.append(p.t_s[1:] + offs)
        t_s = np.concatenate(ts)
    time_s = float(t_s[-1]) if t_s is not None else None
    return Trajectory(method, "", path, energy, steps, time_s, t_s)
