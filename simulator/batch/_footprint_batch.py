"""Many starts at once with the liquid's footprint as each start's state (``--dispense``).

Every lane carries its own footprint state (which pads are wet), as a single run does
(:mod:`simulator.motion`, the footprint run; docs/physics.md §3.5): the lanes start from
the state the process leaves, passed through the relay at their start pose. The lanes
that share a state run together, vmapped, on that state's landscape (summed from the pads'
planes, :class:`simulator.landscape.FootprintPlanes`) with the state's relay in the field:
a lane stops at the first pose where its state changes (status EVENT), takes the new
state, and goes on from that pose, from rest, with the lanes of its new state; every other
lane has ended. The largest group runs first, so the lanes an event moves join their new
state's group instead of a round of their own (each state's landscape is summed once for
them all). The steppers, the relay test, the stretch's step budget and the time left to a
dynamic run are those of the single run, so each lane's end equals
``simulate(scene, start, method)``'s start by start (tested), in whatever order the
groups run.

States are few (a pad wets or dries a few times a run), so a batch runs a handful of
compiled groups; it ends when no lane is left, a lane running at most
:data:`simulator.motion.MAX_EVENTS` + 1 times (one still changing then ran out of steps:
chattering on a relay's threshold). ``footprint_rounds`` is the most times a lane ran.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from foundation import progress_bar
from simulator.batch._stats import BatchResult
from simulator.core import FOOTPRINT_CHUNK

#: The first window's reach (degrees) beyond the starts' twists and the aligned pose's: twice
#: a single run's (:data:`simulator.motion.WINDOW_DEG`). A batch's lanes share one window, so
#: one lane that turns further makes the whole batch's planes again: of the benchmark's
#: 2,000 placements (``benchmarks/footprint.py --batch``) 26 came into the margin of a 10 deg
#: reach's window (43 twists) and none into that of a 20 deg reach's (63), and the second
#: build cost more than the first's 20 extra twists.
BATCH_WINDOW_DEG = 20.0


def _nodes(grid, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid nodes of fractional indices q (N, 3), as the steppers' relay test takes them
    (:func:`simulator.motion.relay_changes`): rounded, the twist wrapped on a periodic axis,
    every index clipped to the grid."""
    n_t, ny, nx = grid.shape
    i = np.round(np.asarray(q, float)).astype(np.int64)
    it = np.mod(i[:, 0], n_t) if grid.wrap else np.clip(i[:, 0], 0, n_t - 1)
    return it, np.clip(i[:, 1], 0, ny - 1), np.clip(i[:, 2], 0, nx - 1)


def _next_states(planes, wet: np.ndarray, q: np.ndarray, grid) -> np.ndarray:
    """Each lane's state ((N, pads) booleans) after arriving at q (N, 3) with ``wet``."""
    reached, within = planes.flags_at(*_nodes(grid, q))
    return reached | (wet & within)


def run_footprint_batch(
    scene,
    poses: np.ndarray,
    method: str,
    *,
    chunk: int,
    max_steps: int,
    progress: bool,
    workers: int,
    dynamics,
    planes=None,
    dispense: str | None = None,
):
    """:func:`simulator.batch.run_batch` with the footprint as each lane's state (module
    docstring). The checks and the pricing of the starts are the caller's; the pads'
    planes are priced here before any is made, or given (``planes``, of this scene: one
    build serves both protocols). ``dispense``: the protocol, default the scene's. Returns a :class:`BatchResult` whose
    ``stats`` add ``footprint_events`` (events per lane, summed), ``footprint_rounds``,
    ``footprint_planes_s`` and ``footprint_twists`` (the twists the planes held).

    Planes made here hold a window of twists around the starts' twists and the aligned
    pose's (:data:`BATCH_WINDOW_DEG`), as a single run's do
    (:func:`simulator.motion.twist_window`): each lane's
    relay stops it where it comes within :data:`simulator.motion.WINDOW_MARGIN_STEPS` of
    the window's side, and those lanes run again from their start on a window reaching
    :data:`simulator.motion.WINDOW_DEG` beyond it (the whole axis at most)."""
    from simulator.landscape import build_footprint_planes, global_minimum
    from simulator.motion import WINDOW_DEG, require_footprint_fits, twist_window

    t0 = time.perf_counter()
    if dispense is not None and dispense != scene.dispense:
        at = scene.liquid.dispense_at_um if dispense == "pattern" else None
        scene = scene.replace(
            liquid=dataclasses.replace(scene.liquid, dispense=dispense, dispense_at_um=at)
        )
    given = planes is not None
    centre: list[float] = []
    if not given:
        # priced for the whole axis first: a window that must widen is never refused later
        require_footprint_fits(scene)
        inner = scene.replace(
            liquid=dataclasses.replace(scene.liquid, dispense="none", dispense_at_um=None)
        )
        aligned = global_minimum(inner).twist_deg  # every pad wet: the stateless minimum
        centre = [float(poses[:, 2].min()), float(poses[:, 2].max()), aligned]
    n = len(poses)
    final = np.empty((n, 3))
    outcome = np.empty(n, np.int8)
    steps = np.zeros(n, np.int64)
    energy = np.empty(n)
    time_s = np.full(n, np.nan)
    events = np.zeros(n, np.int64)
    todo = np.arange(n)
    first = None
    rounds, planes_s, run_s, n_twists, t_land = 0, 0.0, 0.0, 0, 0.0
    shape: tuple[int, ...] = ()
    window = None if given else twist_window(scene, centre, BATCH_WINDOW_DEG)
    if not given:
        planes = build_footprint_planes(scene, progress=progress, twists=window)
    with progress_bar(progress, n, f"{method} (footprint)", "start") as bar:
        while True:
            n_twists = int(planes.template.energy.shape[0])
            part = _lanes_on(
                scene,
                planes,
                poses[todo],
                method,
                chunk,
                max_steps,
                workers,
                dynamics,
                bar,
                windowed=window is not None,
            )
            if first is None:
                first = part
                t_land = time.perf_counter() - t0 - part.run_s
            else:
                t_land += planes.seconds  # the wider window's build
            shape = part.shape
            planes_s += planes.seconds
            run_s += part.run_s
            rounds += part.rounds
            ok = ~part.escaped
            done = todo[ok]
            final[done], outcome[done], steps[done] = (
                part.final[ok],
                part.outcome[ok],
                part.steps[ok],
            )
            energy[done], time_s[done], events[done] = (
                part.energy[ok],
                part.time_s[ok],
                part.events[ok],
            )
            if ok.all():
                break
            todo = todo[~ok]
            # WINDOW_DEG beyond the window's sides, where those lanes went (rare: no
            # progress of its own inside the lanes' bar)
            assert window is not None  # only a window's margins are left
            centre += [float(window[0]), float(window[-1])]
            window = twist_window(scene, centre, WINDOW_DEG)
            planes = None  # dropped before the wider one is made: the price holds one
            planes = build_footprint_planes(scene, twists=window)
    assert first is not None
    dynamic = dynamics is not None
    return BatchResult(
        method=method,
        start=poses,
        final=final,
        outcome=outcome,
        steps=np.minimum(steps, np.iinfo(np.int32).max).astype(np.int32),
        energy_J=energy,
        period_deg=first.period_deg,
        optimum=first.optimum,
        stats={
            "landscape_s": t_land,
            "run_s": run_s,
            "starts_per_s": n / run_s,
            "steps_per_s": float(steps.sum()) / run_s,
            "chunk": min(chunk, FOOTPRINT_CHUNK),  # a stiff run's groups: up to ``chunk``
            "landscape_shape": shape,  # the last window's: every twist a lane stood on
            "stiff": False,
            "footprint_events": int(events.sum()),
            "footprint_rounds": rounds,
            "footprint_planes_s": planes_s,
            "footprint_twists": n_twists,
        },
        time_s=time_s if dynamic else None,
        error_limit=first.error_limit,
    )


@dataclasses.dataclass(frozen=True)
class _Part:
    """The lanes of one set of planes (:func:`_lanes_on`): per lane its end (final pose, um
    and deg), outcome, steps, energy (J), time (s, NaN for the steppers), events, and
    whether it left the planes' window of twists (its other values then unset); the
    reference landscape's shape, period, optimum and error limit; rounds and run time."""

    final: np.ndarray
    outcome: np.ndarray
    steps: np.ndarray
    energy: np.ndarray
    time_s: np.ndarray
    events: np.ndarray
    escaped: np.ndarray
    shape: tuple[int, ...]
    period_deg: float
    optimum: tuple[float, float, float]
    error_limit: dict | None
    rounds: int
    run_s: float


def _lanes_on(
    scene, planes, poses, method, chunk, max_steps, workers, dynamics, bar, *, windowed: bool
) -> _Part:
    """Every start of ``poses`` run in rounds on ``planes`` (module docstring). ``windowed``:
    the planes hold a window of the twist axis, whose margins (``WINDOW_MARGIN_STEPS`` at
    each side that is not the axis's end) a lane may not enter: it stops there, escaped."""
    import jax.numpy as jnp

    from simulator.batch._lanes import _check_starts_fit, _run_order, run_lanes
    from simulator.landscape import global_minimum
    from simulator.liquid import dispensed_footprint
    from simulator.motion import (
        EVENT,
        MAX_EVENTS,
        WINDOW_MARGIN_STEPS,
        Relay,
        error_limit,
        footprint_relay,
        interior,
        is_stiff,
        make_field,
        padded_buffer,
        pin_lines,
        remaining_params,
        wet_bits,
        window_sides,
    )
    from simulator.physics import align_tolerance, pin_per_index

    dynamic = dynamics is not None
    n_pads = planes.n_pads
    dispensed, _ = dispensed_footprint(scene, planes.labels, n_pads)
    reference = planes.landscape(np.ones(n_pads, bool))
    _check_starts_fit(reference, poses)
    reached, within = footprint_relay(planes)
    pin = pin_per_index(scene, reference.um_per_px, reference.twist_step_deg)
    lines = pin_lines(scene, reference.energy.dtype)
    tol = align_tolerance(reference, pin, floats=scene.wall_profile is not None)
    opt = global_minimum(scene, landscape=reference)  # "aligned": every pad wet
    # the force scale of every state's field: the scene's (every pad wet), as a single run's
    e_min = float(reference.energy.min())
    scale = -e_min if e_min < 0 else None
    grid = reference.grid
    best = grid.to_index(np.asarray(opt.pose))
    floor = reference.noise_floor_J  # every state's: the planes' energy scale
    # one padded array for every state's field: fresh pages for each state cost more than
    # summing its planes (0.15-0.5 s a state on the benchmark's 63 x 505 x 505 grid)
    padded = padded_buffer(grid.shape, reference.energy.dtype, grid.wrap, grid.cut)
    # the twist indices a lane may stand on: clear of the window's sides by the margin
    # (a side at the axis's own end is a wall the whole axis has as well)
    n_t = grid.shape[0]
    span = None
    if windowed:
        low, high = window_sides(scene, reference.twist_deg)
        lo = WINDOW_MARGIN_STEPS if low else -(2**30)
        hi = n_t - 1 - WINDOW_MARGIN_STEPS if high else 2**30
        span = np.array([lo, hi], np.int32)

    n = len(poses)
    q = grid.to_index(poses)
    q = np.round(q) if method == "greedy" else q  # as simulate()
    wet = _next_states(planes, np.broadcast_to(dispensed, (n, n_pads)), q, grid)
    t_off = np.zeros(n)
    steps = np.zeros(n, np.int64)
    events = np.zeros(n, np.int64)
    final_q = np.zeros((n, 3))
    outcome = np.empty(n, np.int8)
    energy = np.empty(n)
    time_s = np.full(n, np.nan)
    escaped = np.zeros(n, bool)
    active = np.ones(n, bool)
    passes = np.zeros(n, np.int64)  # how many times each lane ran: at most MAX_EVENTS + 1
    t1 = time.perf_counter()
    while True:
        # The lanes still to run, by state: the largest group runs first, and a lane whose
        # state changes joins its new state's lanes, run in a later group (each state's
        # landscape is made once for all the lanes on it then, not once per round of events).
        lanes = np.flatnonzero(active & (passes <= MAX_EVENTS))
        if not lanes.size:
            break
        keys = np.packbits(wet[lanes], axis=1, bitorder="little")
        _, group, sizes = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        members = lanes[group.ravel() == int(np.argmax(sizes))]
        passes[members] += 1
        state = wet[members[0]]
        # the state's landscape summed into the grid's one padded array: the field reads
        # it in place (JAX on the CPU aliases it), and the group before has ended; every
        # pad wet is the reference's, summed already
        inner = interior(padded)
        if state.all():
            inner[...] = reference.energy
        else:
            planes.energy(state, out=inner)
        fld = make_field(
            inner,
            grid,
            floor,
            best,
            pin,
            tol,
            scale,
            lines,
            padded=padded,
        )
        fld = fld._replace(
            relay=Relay(
                reached,
                within,
                jnp.asarray(wet_bits(state)),
                None if span is None else jnp.asarray(span),
            ),
        )
        stiff = bool(is_stiff(method, fld, grid, dynamics)) if dynamic else False
        params, per_lane = None, False
        if dynamic:
            # each lane has the time left to its own run (its stretches' sum)
            left = [remaining_params(dynamics, float(t)) for t in t_off[members]]
            params = type(dynamics)(
                *(
                    np.asarray([getattr(p, f) for p in left], np.float64)
                    for f in (
                        "mass_kg",
                        "inertia_kg_m2",
                        "damping_N_s_m",
                        "rot_damping_N_m_s",
                        "t_max_s",
                    )
                )
            )
            per_lane = True
        order = _run_order(q[members], np.asarray(best), grid)
        run = members[order]
        # every group in chunks of one compiled shape (FOOTPRINT_CHUNK lanes at most, a
        # small group padded to it): one compile for the batch, not one per group size; a
        # stiff run maps its lanes one after another (a padded lane costs a whole run), so
        # its groups are padded to a power of two only, from 32 (a few compiled shapes)
        lanes_min = min(chunk, FOOTPRINT_CHUNK)
        if stiff:
            lanes_min = min(chunk, max(32, 1 << (len(run) - 1).bit_length()))
        got = run_lanes(
            fld,
            grid,
            params,
            q[run],
            method,
            max_steps,
            stiff,
            lanes_min,
            workers,
            None,
            per_lane,
            lanes_min,
        )
        q_end, st, status, out, e, ts = got
        steps[run] += st
        energy[run] = e  # a lane's energy where its latest stretch ended
        moved = status == EVENT
        if span is not None:  # stopped at the window's margin: run again on a wider one
            it_end = np.round(q_end[:, 0])
            away = moved & ((it_end < span[0]) | (it_end > span[1]))
            escaped[run[away]] = True
            active[run[away]] = False
            moved &= ~away
        else:
            away = np.zeros(len(run), bool)
        new = _next_states(planes, wet[run], q_end, grid)
        changed = moved & (new != wet[run]).any(axis=1)
        t_end = t_off[run] + (ts if dynamic else 0.0)
        # an event: the lane goes on from that pose, from rest, on its new state
        ev = run[changed]
        events[ev] += 1
        wet[ev] = new[changed]
        q[ev] = np.round(q_end[changed]) if method == "greedy" else q_end[changed]
        t_off[ev] = t_end[changed]
        # an event with no change (the host's node and the device's disagree on a
        # half-integer index): the lane goes on from there on the same state
        same = run[moved & ~changed]
        q[same] = (
            np.round(q_end[moved & ~changed]) if method == "greedy" else q_end[moved & ~changed]
        )
        t_off[same] = t_end[moved & ~changed]
        done = ~moved & ~away
        if dynamic:  # a run whose time is up at an event ends there
            up = moved & (t_end >= float(dynamics.t_max_s))
            done |= up
            out = np.where(up, 4, out)
        end = run[done]
        final_q[end], outcome[end] = q_end[done], out[done]
        if dynamic:
            time_s[end] = np.minimum(t_end[done], float(dynamics.t_max_s))
        active[end] = False
        bar.update(int(done.sum()))
    left = np.flatnonzero(active)  # still changing state after MAX_EVENTS: ran out
    rounds = int(passes.max(initial=0))  # each lane's passes are its rounds of events
    if left.size:
        final_q[left], outcome[left] = q[left], 4
        bar.update(int(left.size))
    ox, oy, ot = (float(v) for v in opt.pose)
    return _Part(
        final=grid.to_pose(final_q),
        outcome=outcome,
        steps=steps,
        energy=energy,
        time_s=time_s,
        events=events,
        escaped=escaped,
        shape=tuple(int(v) for v in reference.energy.shape),
        period_deg=float(reference.period_deg),
        optimum=(ox, oy, ot),
        # around the aligned pose every pad is wet: the reference landscape's floor and grid
        error_limit=error_limit(scene, reference, pin=pin),
        rounds=rounds,
        run_s=time.perf_counter() - t1,
    )
