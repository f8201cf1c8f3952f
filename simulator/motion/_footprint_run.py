"""A trajectory whose state is the pose and the liquid's footprint (``--dispense``).

The run starts from the footprint the process leaves (:mod:`simulator.liquid`,
``dispensed_wet``, or nothing for ``chip``), passed through the relay at the start pose
(the chip is released there). It then runs the method on the landscape of the current
state (:class:`simulator.landscape.FootprintPlanes`), and follows the path it takes pose
by pose: at the first pose where a pad's state changes (a dry pad reached by the
liquid's foot, a wet pad left beyond the reach of the chip's wall), the path is cut, the
state changes, and the run goes on from that pose on the new state's landscape. The
events are few (a pad wets or dries a few times a run), each costing one more run of
the stepper on a landscape summed from the pads' planes, no transform.

A dynamic run restarts from rest at each event: the film's damping makes the motion
overdamped near alignment (docs/physics.md §4), and the chip's speed at an event is
what it gains over about a pixel; the events are listed with their times.

A run that builds the FFT planes itself builds them over a window of twists around its
start and the aligned pose (:func:`twist_window`), and runs again on a wider one while its
path comes near the window's side (docs/physics.md §3.5).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from foundation import InputError
from simulator.core import DYNAMIC_METHODS

if TYPE_CHECKING:
    import jax

    from simulator.landscape import FootprintPlanes
    from simulator.motion import Trajectory  # the face: _trajectory is being split
    from simulator.motion._dynamics_params import DynamicsParams
    from simulator.scene import Scene

#: The process itself, with NumPy, SciPy and JAX loaded (what a run holds besides its arrays).
PROCESS_BYTES = 512 * 2**20

#: Events a run may take before it stops (a pad's state changes a few times a run; many
#: more means the chip is chattering on a relay's threshold).
MAX_EVENTS = 64

#: A run on the pads' FFT planes makes them over the twists within this much (degrees) of
#: its start's twist and of the aligned pose's (:func:`twist_window`), not over the whole
#: axis: a run turns little, and each twist's planes cost about twenty correlations.
WINDOW_DEG = 10.0
#: Twist steps between a run's path and its window's side: the steppers' interpolation reads
#: a block of 4 cells around a pose (:data:`simulator.motion.PAD`), so a path this far inside
#: reads only the window's planes, as it would the whole axis's. A path that comes nearer is
#: run again on a window reaching :data:`WINDOW_DEG` beyond where it went.
WINDOW_MARGIN_STEPS = 6


def _cut(tr: Trajectory, j: int) -> Trajectory:
    """The trajectory ``tr`` up to (not including) its pose ``j``."""
    t_s = None if tr.t_s is None else tr.t_s[:j]
    return dataclasses.replace(
        tr, outcome="", path=tr.path[:j], energy_J=tr.energy_J[:j], steps=j, time_s=None, t_s=t_s
    )


def footprint_budget_bytes(scene: Scene, n_pads: int, pairs: bool = True) -> int:
    """What the footprint state's planes hold at their peak: per pose, each pad's wet energy
    and two relay flags, and the shadow rule's pair planes on their boxes
    (:func:`simulator.landscape._footprint.footprint_pairs`, laid out as the build does); per
    pose of one twist, a chunk of twists' work (the pads' covered flags, the results being
    reduced) and each pad's and pair's correlator (its kernel and its threads' spectra, about
    eight values per pose); the relay's two flags packed a bit per pad, and the steppers' copy
    of them; during the run, the reference landscape (every pad wet), the
    current state's and the next one's being summed at an event; and the process with its
    engines (measured: the bench case at 5 um/px, 90 twists, 505 x 505 poses, 4 pads and 8
    pairs, peaked at 1,882 to 1,890 MB with the flags a byte per pad; at 2 um/px, 1,225 x 1,225
    poses, priced 8,370 MB, of which the pairs' planes 1,795 MB, peaked at 6,923 MB with the
    flags a bit per pad, 8,138 MB with a byte; with the shadow cast along the chip side's
    normal at each twist, 32 pairs on the twists where each exists and the poses that cover
    its near pad, priced 8,422 MB, of which the pairs' planes 1,911 MB, peaked at 7,537 MB;
    measured again with the pads at 10:35 deg, priced 8,032 MB, peaked at 7,040 MB).
    A pair's part is made, used and dropped in turn, so one pair's correlator is counted.
    ``pairs`` False: without the shadow rule's pairs (whose boxes take a pass over the
    twists to find), a lower bound that refuses an oversize scene at once."""
    from simulator.landscape import footprint_pairs, footprint_poses

    poses = footprint_poses(scene)
    if pairs:
        n_pairs, pair_poses, per_twist = footprint_pairs(scene)
    else:
        n_pairs, pair_poses = 0, 0
        per_twist = poses // max(1, scene.twist_axis.count)
    item = np.dtype(scene.dtype).itemsize
    n_parts = n_pads + min(n_pairs, 1)  # a pair's part is made, used and dropped in turn
    work = per_twist * (16 * (n_pads + 3 * item) + 8 * item * n_parts)
    words = -(-n_pads // 8)  # the relay's flags, a bit per pad, and their device copies
    held = poses * (n_pads * item + 4 * words + 3 * item) + pair_poses * item
    return int((held + work) * 1.15) + PROCESS_BYTES


def _proto(scene: Scene) -> str:
    """The scene's protocol as its flag reads, saying when it is the default."""
    return f"{scene.dispense}" + (" (the default)" if scene.liquid.dispense is None else "")


def require_footprint_fits(scene: Scene, engine: str = "fft") -> None:
    """Refuse (InputError) a ``--dispense`` run whose pads' planes exceed the memory budget,
    before any of them is made (no JAX, no transform); with ``engine`` "path", whose
    footprint state's rotators do (:func:`simulator.landscape.footprint_path_bytes`)."""
    from patterns.geometry import pad_labels

    if engine == "path":
        from simulator.landscape import footprint_path_bytes

        need = footprint_path_bytes(scene)
        if need > scene.memory_budget_mb * 2**20:
            raise InputError(
                f"--dispense {_proto(scene)} on the path engine: the footprint state's rotators would hold "
                f"{need / 2**20:,.0f} MB, over the memory budget of {scene.memory_budget_mb:,.0f} MB; give a coarser "
                "--resolution, raise --memory-budget, or run stateless with --dispense none"
            )
        return
    _, n = pad_labels(scene.pattern)
    need = footprint_budget_bytes(scene, n, pairs=False)  # at least this: refused at once
    least = need > scene.memory_budget_mb * 2**20
    if not least:
        need = footprint_budget_bytes(scene, n)
    if need > scene.memory_budget_mb * 2**20:
        raise InputError(
            f"--dispense {_proto(scene)}: the footprint state's planes for {n} pads would hold "
            f"{'at least ' if least else ''}"
            f"{need / 2**20:,.0f} MB, over the memory budget of {scene.memory_budget_mb:,.0f} MB; give a coarser "
            "--resolution, a smaller --window or a larger --twist-step, raise --memory-budget, or run stateless "
            "with --dispense none"
        )


def footprint_words(fp: dict) -> str:
    """One line on where the liquid was: wet at release, the events, wet at the end."""

    def pads(ids: Sequence[int]) -> str:
        return "none" if not ids else "pads " + ", ".join(str(i) for i in ids)

    ev = fp["events"]
    said = "; ".join(
        f"pad {e['pad']} {e['state']} at step {e['step']}"
        + (f" (t = {e['t_s'] * 1e3:.3g} ms)" if "t_s" in e else "")
        for e in ev[:6]
    ) + ("; ..." if len(ev) > 6 else "")
    return (
        f"footprint (--dispense {fp['dispense']}): {fp['why']}; wet at release: {pads(fp['initial'])}; "
        f"{len(ev)} event{'s' if len(ev) != 1 else ''}{': ' + said if ev else ''}; wet at the end: {pads(fp['final'])} "
        f"(reached within {fp['substrate_reach_um']:.3g} um, dries beyond {fp['wet_reach_um']:.3g} um at {fp['receding_deg']:.3g} deg receding)"
    )


def footprint_relay(planes: FootprintPlanes) -> tuple[jax.Array, jax.Array]:
    """The pads' relay flags of ``planes`` (:class:`simulator.landscape.FootprintPlanes`)
    for the steppers: (reached, within) as (T, Ny, Nx, W) uint8 device arrays, pad ``k`` in
    bit ``k % 8`` of byte ``k // 8`` (:class:`simulator.motion.Relay`), as the planes hold
    them."""
    import jax.numpy as jnp

    return jnp.asarray(planes.reached_bits), jnp.asarray(planes.within_bits)


def wet_bits(wet: Sequence[bool] | np.ndarray) -> np.ndarray:
    """A footprint state ((pads,) booleans) as the relay's (W,) uint8 bits."""
    return np.packbits(np.asarray(wet, bool), bitorder="little")


def remaining_params(dynamics: DynamicsParams | None, t_off: float) -> DynamicsParams | None:
    """The dynamics of a run's stretch that starts at ``t_off`` s: the time left to its
    ``t_max_s`` (a footprint run's time limit is the whole run's); None once none is left."""
    if dynamics is None or t_off == 0.0:
        return dynamics
    left = float(dynamics.t_max_s) - t_off
    return None if left <= 0.0 else dataclasses.replace(dynamics, t_max_s=left)


def footprint_engine(
    scene: Scene, start: Sequence[float], method: str, engine: str, planes: object = None
) -> str:
    """Which engine gives a ``--dispense`` run its per-pose planes: "path" (the footprint
    state in the path engine's boxes that follow the chip,
    :class:`simulator.landscape.FootprintPath`) or "fft" (the pads' planes over the whole
    grid, :func:`simulator.landscape.build_footprint_planes`). Greedy and gradient choose as
    their stateless runs do (:func:`simulator.motion.choose_engine`, ``engine`` "auto",
    "fft" or "path"); the dynamics, and a run given its ``planes``, take the planes."""
    if planes is not None or method not in ("greedy", "gradient"):
        if engine == "path" and planes is None:
            raise InputError(
                f"--engine path runs greedy and gradient; {method} builds the whole landscape (leave --engine out)"
            )
        return "fft"
    from simulator.motion._pathrun import choose_engine
    from simulator.motion._pricing import BAND_PX, BAND_STEPS

    return choose_engine(scene, start, method, engine, BAND_STEPS, BAND_PX)


def twist_window(scene: Scene, twists_deg: Sequence[float], half_deg: float) -> np.ndarray | None:
    """The twists of the scene's axis within ``half_deg`` of zero and of every twist in
    ``twists_deg`` (degrees): one run of the axis, symmetric about zero where the axis
    allows (a mirror-symmetric chip's twins, +alpha and -alpha, are then both in it, made
    from one transform as on the whole axis). ``half_deg`` is at least
    :data:`WINDOW_MARGIN_STEPS` + 4 twist steps, so that a run starting at one of
    ``twists_deg`` starts clear of the margin at the window's side on any axis. None: the
    whole axis (no twist, or a window that would hold nearly all of it)."""
    axis = scene.twist_axis
    if axis.count == 1:
        return None
    vals = axis.values()
    half = max(float(half_deg), (WINDOW_MARGIN_STEPS + 4) * float(axis.step_deg))
    reach = max(abs(float(t)) for t in (0.0, *twists_deg)) + half
    window = vals[np.abs(vals) <= reach + 1e-9 * max(1.0, reach)]
    if len(window) + 2 * WINDOW_MARGIN_STEPS >= axis.count:
        return None
    return window


def window_sides(scene: Scene, window: np.ndarray) -> tuple[bool, bool]:
    """Whether the low and the high side of ``window`` (its twists, degrees, ascending) cut
    the scene's twist axis: a side at the end of a bounded axis is a wall the whole axis has
    as well, which a run may come near."""
    vals, periodic = scene.twist_axis.values(), scene.twist_axis.periodic
    return bool(window[0] > vals[0] or periodic), bool(window[-1] < vals[-1] or periodic)


def _near_side(scene: Scene, window: np.ndarray, path: np.ndarray) -> bool:
    """Whether the twists of ``path`` ((n, 3) um, um, deg) come within
    :data:`WINDOW_MARGIN_STEPS` steps of a side of ``window`` that is not the axis's own end."""
    margin = WINDOW_MARGIN_STEPS * float(scene.twist_axis.step_deg)
    tw = np.asarray(path, float)[:, 2]
    low, high = window_sides(scene, window)
    return bool(
        (low and tw.min() < window[0] + margin) or (high and tw.max() > window[-1] - margin)
    )


def simulate_footprint(
    scene: Scene,
    start: Sequence[float],
    method: str,
    max_steps: int,
    dynamics: DynamicsParams | None,
    backend: str,
    simulate: Callable[..., Trajectory],
    planes: Any = None,
    engine: str = "fft",
) -> dict:
    """:func:`simulator.motion.simulate` with the footprint as the run's state (module
    docstring): the fields of the joined trajectory, ``footprint`` among them (where the
    liquid was), for the caller to make the trajectory of. ``simulate`` runs each stretch
    on a given landscape (the caller's own function, passed in), stopping where the state
    changes (its ``relay``); ``max_steps`` bounds each stretch between events, the dynamics'
    ``t_max_s`` the whole run. ``planes``: the scene's pads' planes, when given (built
    here otherwise). ``engine``: :func:`footprint_engine`'s choice; with "path" each stretch
    runs on the path engine's boxes of the current state (:class:`simulator.motion.StateBoxes`),
    the state's events and relay the same."""
    from simulator.landscape import build_footprint_planes

    t0 = time.perf_counter()
    engine = footprint_engine(scene, start, method, engine, planes)
    inner = scene.replace(
        liquid=dataclasses.replace(scene.liquid, dispense="none", dispense_at_um=None)
    )
    run = functools.partial(
        _run_states, scene, inner, start, method, max_steps, dynamics, backend, simulate, t0=t0
    )
    if engine == "path":
        from simulator.landscape import FootprintPath, PathEnergy

        # the state's planes at the poses the run visits (FootprintPath), and the stateless
        # engine for the global minimum's proof (the aligned pose, every pad wet)
        planes = FootprintPath(scene)
        path_src = (planes, PathEnergy(inner))
        return run(planes, path_src)
    if planes is not None:
        return run(planes, None)
    # The planes over a window of twists around the start and the aligned pose (priced for
    # the whole axis first: a window that must widen is never refused mid-run), widened and
    # the run made again while its path comes near the window's side.
    require_footprint_fits(scene)
    from simulator.landscape import global_minimum

    aligned = global_minimum(inner, backend=backend).twist_deg
    centre = [float(start[2]), aligned]
    built = 0.0
    while True:
        window = twist_window(scene, centre, WINDOW_DEG)
        planes = None  # a narrower window's planes dropped first: the price holds one
        planes = build_footprint_planes(scene, backend=backend, twists=window)
        built += planes.seconds
        out = run(planes, None)
        if window is None or not _near_side(scene, window, out["path"]):
            break
        # WINDOW_DEG beyond where the path went (it stopped at the window's side)
        centre += [float(out["path"][:, 2].min()), float(out["path"][:, 2].max())]
    out["cost"] = dataclasses.replace(
        out["cost"],
        footprint_planes_s=built,
        footprint_twists=scene.twist_axis.count if window is None else len(window),
    )
    return out


def _run_states(
    scene: Scene,
    inner: Scene,
    start: Sequence[float],
    method: str,
    max_steps: int,
    dynamics: DynamicsParams | None,
    backend: str,
    simulate: Callable[..., Trajectory],
    planes: Any,
    path_src: Any,
    *,
    t0: float,
) -> dict:
    """The run of :func:`simulate_footprint` on the pads' ``planes`` (FFT planes, or the
    path engine's :class:`~simulator.landscape.FootprintPath` with ``path_src``)."""
    from simulator.liquid import dispensed_footprint
    from simulator.motion._field import Relay

    proto = scene.dispense
    n = planes.n_pads  # the planes' own labelling: the pattern is not labelled again
    dispensed, why = dispensed_footprint(scene, planes.labels, n)
    if method in DYNAMIC_METHODS and dynamics is None:
        from simulator.motion._dynamics_params import DynamicsParams

        dynamics = DynamicsParams.from_scene(scene)
    # "aligned": against the minimum with every pad wet (the aligned pose on the whole
    # pattern), not the current state's (a state with only some pads wet has its own).
    # (the path engine: the scene's own global minimum, where every pad is covered and the
    # all-wet state's energy is the stateless one)
    reference = None if path_src else planes.landscape(np.ones(n, bool))
    reached, within = (None, None) if path_src else footprint_relay(planes)
    import jax.numpy as jnp  # after the planes' price and build (a refusal loads no JAX)

    wet = planes.next_state(dispensed, start)
    initial = wet.copy()
    pose = tuple(float(v) for v in start)
    pieces, events, done = [], [], 0
    t_off = 0.0
    last = None
    for _ in range(MAX_EVENTS + 1):
        if path_src:
            from simulator.motion._pathrun import StateBoxes

            tr = simulate(
                inner,
                pose,
                method=method,
                max_steps=max_steps,
                backend=backend,
                engine="path",
                path=StateBoxes(*path_src, wet),
            )
        else:
            assert reached is not None and within is not None  # the planes' relay
            tr = simulate(
                inner,
                pose,
                method=method,
                max_steps=max_steps,
                # every pad wet (the pattern protocol above the critical volume): the reference
                landscape=reference if wet.all() else planes.landscape(wet),
                dynamics=remaining_params(dynamics, t_off),
                backend=backend,
                reference=reference,
                relay=Relay(reached, within, jnp.asarray(wet_bits(wet))),
            )
        last = tr
        if tr.outcome != "event":
            pieces.append((tr, t_off))
            break
        # the stretch stopped at its last pose, where the state changes: the next starts there
        j = len(tr.path) - 1
        new = planes.next_state(wet, tr.path[j])
        pieces.append((_cut(tr, j), t_off))
        t_ev = None if tr.t_s is None else t_off + float(tr.t_s[j])
        for k in np.flatnonzero(new != wet):
            x, y, a = (float(v) for v in tr.path[j])
            events.append(
                {
                    "step": done + j,
                    **({} if t_ev is None else {"t_s": t_ev}),
                    "pad": int(k + 1),
                    "state": "wet" if new[k] else "dry",
                    "x_um": x,
                    "y_um": y,
                    "twist_deg": a,
                }
            )
        done += j
        if t_ev is not None:
            t_off = t_ev
        wet = new
        pose = tuple(float(v) for v in tr.path[j])
        if dynamics is not None and remaining_params(dynamics, t_off) is None:  # time is up
            pieces[-1] = (
                dataclasses.replace(_cut(tr, j + 1), steps=j),
                pieces[-1][1],
            )  # ends there
            last = None
            break
    else:
        last = None  # more events than MAX_EVENTS: chattering on a relay's threshold
    assert pieces  # the loop runs at least once
    path = np.concatenate([p.path for p, _ in pieces])
    energy = np.concatenate([p.energy_J for p, _ in pieces])
    steps = sum(p.steps for p, _ in pieces)
    t_s = None
    if pieces[0][0].t_s is not None:
        # each stretch's times are clamped to its own limit; their sum to the run's
        assert dynamics is not None  # a timed run is a dynamic one
        t_s = np.minimum(np.concatenate([p.t_s + off for p, off in pieces]), dynamics.t_max_s)
    time_s = None if t_s is None else float(t_s[-1])
    outcome = "max_steps" if last is None else last.outcome
    s = scene.um_per_px
    rules = planes.rules
    footprint = {
        "dispense": proto,
        "dispensed": [int(k + 1) for k in np.flatnonzero(dispensed)],
        "why": why,
        "initial": [int(k + 1) for k in np.flatnonzero(initial)],
        "events": events,
        "final": [int(k + 1) for k in np.flatnonzero(wet)],
        "pads": [
            {"pad": k + 1, "x_um": float(c[0]), "y_um": float(c[1]), "area_um2": float(a)}
            for k, (c, a) in enumerate(zip(planes.pad_centre_um, planes.pad_area_um2, strict=True))
        ],
        "substrate_reach_um": rules.d_s * s,
        "wet_reach_um": rules.d_r * s,
        "receding_deg": rules.receding_deg,
    }
    ref = pieces[-1][0] if last is None else last
    assert ref.cost is not None  # every piece is a packaged run
    cost = dataclasses.replace(
        ref.cost,
        engine="footprint path" if path_src is not None else "footprint planes",
        footprint_planes_s=planes.seconds,
        footprint_pieces=len(pieces),
        total_s=time.perf_counter() - t0,
    )
    return {
        "method": method,
        "outcome": outcome,
        "path": path,
        "energy_J": energy,
        "steps": steps,
        "time_s": time_s,
        "t_s": t_s,
        "cost": cost,
        "optimum": None if last is None else last.optimum,
        "refined": None if last is None else last.refined,
        "error_limit": ref.error_limit,
        "floor": ref.floor,
        "footprint": footprint,
    }
