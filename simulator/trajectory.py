"""One trajectory from one start: the host side around the pure steppers.

:func:`simulate` builds only the part of the landscape a run needs: a box of a
few twists and translations around the start, moved to the chip whenever the
stepper reaches one of its sides (status EDGE), after which the stepper resumes
from where it stopped. Greedy and gradient stepping are memoryless, so the path
equals a run on the full landscape (tested), at a fraction of the cost
(``Trajectory.cost``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from patterns.errors import InputError
from simulator import stepping
from simulator.landscape import Landscape, build_landscape, twist_axis
from simulator.scene import Scene

METHODS = ("greedy", "gradient", "overdamped", "inertial")
DEFAULT_MAX_STEPS = 5000


@dataclass(frozen=True)
class Trajectory:
    """A path with its energy curve and outcome.

    path: (N, 3) poses (x_um, y_um, twist_deg), start first; twist unwrapped.
    energy_J: (N,) energy per recorded pose. t_s: (N,) times for dynamics, else None.
    steps: moves (stepping) or accepted solver steps (dynamics). time_s: final time
    (dynamics) or None. cost: landscape twists computed vs the full axis, seconds.
    """

    method: str
    outcome: str
    path: np.ndarray
    energy_J: np.ndarray
    steps: int
    time_s: float | None = None
    t_s: np.ndarray | None = None
    cost: dict = field(default_factory=dict)

    @property
    def start(self) -> tuple[float, float, float]:
        return tuple(float(v) for v in self.path[0])

    @property
    def final(self) -> tuple[float, float, float]:
        return tuple(float(v) for v in self.path[-1])

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
            "cost": self.cost,
        }


def radius_of_gyration_px(scene: Scene) -> float:
    """sqrt(polar moment / area) of the chip's wettable footprint about its centre (px)."""
    d = scene.chip.data
    h, w = d.shape
    y, x = np.mgrid[0:h, 0:w]
    r2 = (x + 0.5 - w / 2) ** 2 + (y + 0.5 - h / 2) ** 2
    return float(math.sqrt((d * r2).sum() / d.sum()))


def _run(method: str, field, grid, start, max_steps: int, dyn_params=None):
    if method == "greedy":
        return _greedy_jit(field, grid, jnp.asarray(np.round(start), jnp.int32), max_steps)
    if method == "gradient":
        return _gradient_jit(field, grid, jnp.asarray(start), max_steps)
    from simulator import dynamics

    fn = dynamics.overdamped if method == "overdamped" else dynamics.inertial
    return fn(field, grid, dyn_params, jnp.asarray(start), max_steps)


_greedy_jit = jax.jit(stepping.greedy, static_argnames=("grid", "max_steps", "record"))
_gradient_jit = jax.jit(stepping.gradient_descent, static_argnames=("grid", "max_steps", "record", "min_step_px"))


def simulate(
    scene: Scene,
    start: tuple[float, float, float],
    method: str = "greedy",
    max_steps: int = DEFAULT_MAX_STEPS,
    landscape: Landscape | None = None,
    band_steps: int = 6,
    band_px: int = 48,
    dynamics=None,
    backend: str = "auto",
) -> Trajectory:
    """Run one trajectory from ``start`` = (x_um, y_um, twist_deg).

    Args:
        scene: what to simulate.
        start: the initial pose. Greedy snaps it to the nearest grid pose.
        method: "greedy", "gradient", "overdamped" or "inertial".
        max_steps: bound on moves (or solver steps for dynamics).
        landscape: a precomputed landscape to run on (its global minimum decides
            "aligned"). Default: greedy and gradient build only a box of
            +-``band_steps`` twists and +-``band_px`` px around the start, and move the
            box to the chip whenever it reaches a side; dynamics build the whole
            landscape (the chip may overshoot).
        dynamics: :class:`simulator.dynamics.DynamicsParams` for the dynamic methods
            (default: from the scene's chip, liquid and calibration).
    """
    if method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, int | np.integer) or max_steps < 1:
        raise InputError(f"max steps must be a whole number >= 1, got {max_steps!r}")
    if len(start) != 3 or not all(math.isfinite(v) for v in start):
        raise InputError(f"start pose must be three finite numbers (um, um, deg), got {start}")
    dynamic = method in ("overdamped", "inertial")
    if dynamic and dynamics is None:
        from simulator.dynamics import DynamicsParams

        dynamics = DynamicsParams.from_scene(scene)
    rg = radius_of_gyration_px(scene)
    t0 = time.perf_counter()
    axis, wrap, _ = twist_axis(scene) if landscape is None else (landscape.twist_deg, landscape.wrap, None)
    n = len(axis)
    step = axis[1] - axis[0] if n > 1 else 1.0
    if not wrap and n > 1 and not (axis[0] - step / 2 <= start[2] <= axis[-1] + step / 2):
        raise InputError(f"start twist {start[2]:g} deg is outside the twist range {axis[0]:g}..{axis[-1]:g} deg")
    s = scene.um_per_px
    pose = np.asarray(start, float)
    pieces, boxes, poses_computed, seconds = [], [], 0, 0.0
    while True:
        if landscape is not None:
            ls = landscape
        elif dynamic:
            ls = build_landscape(scene, backend=backend)
        else:
            k = int(round((pose[2] - axis[0]) / step)) if n > 1 else 0
            lo, hi = k - band_steps, k + band_steps
            if wrap and hi - lo + 1 >= n:
                twists = None
            else:
                lo, hi = (lo, hi) if wrap else (max(lo, 0), min(hi, n - 1))
                twists = axis[0] + step * np.arange(lo, hi + 1) if n > 1 else axis
            center = (int(round(pose[0] / s)), int(round(pose[1] / s)))
            box = (lo, hi, center)
            if box in boxes:  # moving the box would not move the chip: stop here
                break
            boxes.append(box)
            ls = build_landscape(scene, twists=twists, center_px=center, half_px=band_px, backend=backend)
        if ls is not landscape:
            poses_computed += ls.energy.size
            seconds += ls.stats["seconds"]
        field, grid = stepping.field_and_grid(ls, rg)
        state = _run(method, field, grid, grid.to_index(pose), max_steps, dynamics)
        pieces.append(_to_trajectory(method, state, grid))
        if int(state.status) != stepping.EDGE or landscape is not None or dynamic:
            break
        if sum(p.steps for p in pieces) >= max_steps:
            break
        pose = np.asarray(pieces[-1].final)
    traj = _join(method, pieces)
    status = int(state.status)
    if traj.steps >= max_steps and (status != stepping.CONVERGED or traj.steps > max_steps):
        status = stepping.MAX_STEPS
        traj = Trajectory(method, "", traj.path[: max_steps + 1], traj.energy_J[: max_steps + 1], max_steps, traj.time_s, None if traj.t_s is None else traj.t_s[: max_steps + 1])
    # Outcome: flatness where the run ended; "aligned" against the global minimum.
    q_end = grid.to_index(np.asarray(traj.final))
    flat = bool(getattr(state, "flat", False)) or bool(stepping.on_plateau(field, grid, np.round(q_end).astype(np.int32)))
    ref = landscape if landscape is not None else reference_landscape(scene, backend)
    ref_field, ref_grid = stepping.field_and_grid(ref, rg)
    q_ref = ref_grid.to_index(np.asarray(traj.final))
    out = stepping.classify(ref_field, ref_grid, q_ref, float(traj.energy_J[-1]), status, flat)
    full = full_landscape_poses(scene) if landscape is None else landscape.energy.size
    cost = {
        "poses_computed": int(poses_computed),
        "poses_full": int(full),
        "fraction_of_full": poses_computed / full,
        "boxes": len(boxes),
        "landscape_s": seconds,
        "total_s": time.perf_counter() - t0,
    }
    return Trajectory(method, stepping.OUTCOMES[int(out)], traj.path, traj.energy_J, traj.steps, traj.time_s, traj.t_s, cost)


def reference_landscape(scene: Scene, backend: str = "auto", reach_steps: int = 2, half_px: int = 16) -> Landscape:
    """A small box around the aligned pose (0, 0, 0) that locates the global minimum.

    Assumes the minimum lies within ``half_px`` px and ``reach_steps`` twist steps of
    (0, 0, 0), as for a chip on its own pattern; pass a full landscape to
    :func:`simulate` when it does not.
    """
    axis, wrap, _ = twist_axis(scene)
    n = len(axis)
    if n > 1:
        k0 = int(np.argmin(np.abs(axis)))
        lo, hi = k0 - reach_steps, k0 + reach_steps
        if not wrap:
            lo, hi = max(lo, 0), min(hi, n - 1)
        twists = None if (wrap and hi - lo + 1 >= n) else axis[0] + (axis[1] - axis[0]) * np.arange(lo, hi + 1)
    else:
        twists = None
    return build_landscape(scene, twists=twists, center_px=(0, 0), half_px=half_px, backend=backend)


def full_landscape_poses(scene: Scene) -> int:
    """Poses of the scene's full landscape (what a trajectory would cost without boxes)."""
    from simulator.landscape import plan

    return plan(scene)["landscape_bytes"] // np.dtype(scene.dtype).itemsize


def _to_trajectory(method: str, state, grid) -> Trajectory:
    n = int(state.step) + 1
    idx = np.asarray(state.path)[:n]
    energy = np.asarray(state.path_energy)[:n].astype(float)
    t_s = np.asarray(state.path_t)[:n].astype(float) if hasattr(state, "path_t") else None
    time_s = float(state.time_s) if hasattr(state, "time_s") else None
    return Trajectory(method, "", grid.to_pose(idx), energy, n - 1, time_s, t_s)


def _join(method: str, pieces: list[Trajectory]) -> Trajectory:
    path = np.concatenate([pieces[0].path] + [p.path[1:] for p in pieces[1:]])
    energy = np.concatenate([pieces[0].energy_J] + [p.energy_J[1:] for p in pieces[1:]])
    steps = sum(p.steps for p in pieces)
    t_s = None
    if pieces[0].t_s is not None:
        offs, ts = 0.0, [pieces[0].t_s]
        for prev, p in zip(pieces, pieces[1:], strict=False):
            offs += prev.t_s[-1]
            ts.append(p.t_s[1:] + offs)
        t_s = np.concatenate(ts)
    time_s = float(t_s[-1]) if t_s is not None else None
    return Trajectory(method, "", path, energy, steps, time_s, t_s)
