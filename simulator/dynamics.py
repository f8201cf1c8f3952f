"""Time-resolved dynamics of the chip on the energy landscape (PHYSICS.md section 4).

Two steppers with the shape of :mod:`simulator.stepping` (pure functions of
``(field, grid, params, start, max_steps, record)``, a static :class:`~simulator.stepping.Grid`,
a NamedTuple state out, jit- and vmap-able):

* :func:`overdamped`: ``c v = F``, ``c_t w = tau`` (first order, no inertia);
* :func:`inertial`: ``m a = F - c v``, ``I alpha = tau - c_t w`` (PHYSICS.md 4, Eq. 10).

F and tau are minus the gradient of the potential Phi below, converted to SI: one x or y
index step is ``grid.um_per_px`` um, one twist index step is ``grid.twist_step_deg``
degrees (radians inside). Positions are in grid-index units ``(it, iy, ix)`` as in
:mod:`simulator.stepping` (``it`` unwrapped on a periodic twist axis); times in seconds.

The potential Phi: :mod:`simulator.potential` (the landscape averaged over +-1 grid step,
C1, with an exact gradient; why, and what it changes, is written there).

Integration: ``diffrax.diffeqsolve`` with Tsit5 (explicit 5th-order Runge-Kutta with an
embedded error estimate) and a PID step-size controller, in nondimensional time (unit
``tau``, below) with the state measured from the start, so that ``rtol``/``atol`` are
relative to the displacement and ``atol`` is in grid steps; defaults from the dtype
(:func:`default_tolerances`). The controller is guarded (:class:`_GuardedController`): a
step is also rejected when it raises ``Phi + kinetic`` by more than the noise floor or
moves more than one grid step along any axis, so the energy never rises along the
recorded path by construction and no step jumps over a feature of the landscape. The
problem is not stiff for the calibrated water parameters (damping ratio about 0.6,
twist and translation rates within a factor of a few). For heavily overdamped
*inertial* runs (damping ratio >> 1) pass ``solver=diffrax.Kvaerno5()`` (measured at
damping ratio 50: 176 steps, where Tsit5 runs out of 4000) or use :func:`overdamped`.
Steps are recorded at every accepted solver step (``SaveAt(steps=True)``, a
``max_steps`` buffer).

Stopping: a diffrax boolean event ends the run (status CONVERGED) at the end of the
first step where (a) the force along every axis, expressed as the energy change over
one grid step, ``|dPhi/dq_k|``, is at most the landscape's noise floor, and (b) the
kinetic energy is at most the noise floor (the speed whose kinetic energy is
round-off); where the integrator's position tolerance is coarser than the floor (float64)
the threshold is the work of the reference force over that tolerance instead (see
``_stop_flags``). The same test at the start ends a run with no force before any step (a
no-contact start). Reaching a cut side of the grid (``grid.cut``: the window or twist
band was cut from a larger one; :func:`simulator.stepping.at_cut_edge`), or passing the
end of a non-periodic twist axis (a wall), ends it with status EDGE, as for the other
steppers; within two steps of such a side Phi repeats the edge energies. Running out of
``t_max_s`` or ``max_steps`` gives MAX_STEPS.

Why diffrax and not a hand-written loop: events, step recording, step rejection (through
the controller) and vmap all work (the event is a per-member predicate; a vmapped batch
runs until its last member stops). A batch is ``jax.vmap`` of the single run, as for the
other steppers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from patterns.errors import InputError
from simulator.stepping import (
    CONVERGED,
    EDGE,
    MAX_STEPS,
    Field,
    Grid,
    at_cut_edge,
    clamp_start,
    interpolate,
    on_plateau,
    reference_gradient,
)

# A float64 landscape stays float64 inside the steppers (documented in simulator/__init__.py).
jax.config.update("jax_enable_x64", True)



# Parameters (simulator.dynamics_params) and the potential Phi (simulator.potential), re-exported.
from simulator.dynamics_params import MIN_FILM_UM, DynamicsParams, default_tolerances  # noqa: E402, F401
from simulator.potential import potential, potential_and_gradient  # noqa: E402, F401


# ----------------------------------------------------------------- state
class DynamicsState(NamedTuple):
    """Final state of a dynamics run; ``path*[:step + 1]`` is the recorded trajectory.

    Rows of the path buffers past ``step`` are NaN. With ``record=False`` the buffers
    hold only the start (one row).
    """

    q: jax.Array  # (3,) fractional indices (it, iy, ix), it unwrapped
    v: jax.Array  # (3,) velocity, index steps per second
    energy: jax.Array  # landscape energy E(q) (stepping.interpolate), J
    potential: jax.Array  # Phi(q), J
    kinetic: jax.Array  # kinetic energy, J (0 for the overdamped model)
    time_s: jax.Array  # time at the end of the run, s
    step: jax.Array  # accepted solver steps (int32)
    status: jax.Array  # CONVERGED / MAX_STEPS / EDGE (int32)
    path: jax.Array  # (max_steps + 1, 3) fractional indices at t0 and each accepted step
    path_energy: jax.Array  # (max_steps + 1,) landscape energy E, J
    path_potential: jax.Array  # (max_steps + 1,) Phi, J
    path_kinetic: jax.Array  # (max_steps + 1,) kinetic energy, J
    path_t: jax.Array  # (max_steps + 1,) times, s
    flat: jax.Array  # converged on a plateau (stepping.on_plateau at the nearest node)


class _Coeffs(NamedTuple):
    """Per-axis coefficients (it, iy, ix) in nondimensional time s = t / tau."""

    q0: jax.Array  # start, index steps
    drive: jax.Array  # overdamped: tau / (c_k s_k^2); inertial: tau^2 / (m_k s_k^2)
    damp: jax.Array  # inertial: c_k tau / m_k
    ke: jax.Array  # kinetic energy per (index step / tau)^2: m_k s_k^2 / (2 tau^2)
    tau: jax.Array  # time unit, s
    f_ref: jax.Array  # reference |dE/dq| per axis, J per index step
    rtol: jax.Array  # step-size controller tolerances (atol in index steps)
    atol: jax.Array


def _axis_scales(grid: Grid) -> np.ndarray:
    """SI length of one index step along (it, iy, ix): radians, metres, metres."""
    return np.array(
        [math.radians(grid.twist_step_deg), grid.um_per_px * 1e-6, grid.um_per_px * 1e-6]
    )


def _reference_force(field: Field, grid: Grid, dt) -> jax.Array:
    """Typical |dE/dq| per index step (J), as in stepping.gradient_descent: a chip edge of
    length 2 rg sliding over a pad, for x and y; times the arc per twist step for twist."""
    g = jnp.maximum(reference_gradient(field, grid), jnp.finfo(dt).tiny / jnp.finfo(dt).eps)
    return g * jnp.asarray([max(grid.twist_px_per_step, 1e-6), 1.0, 1.0], dt)


def _active(grid: Grid, dt) -> jax.Array:
    return jnp.asarray([grid.shape[0] > 1, True, True], dt)


def _stop_flags(field: Field, grid: Grid, co: _Coeffs, q, grad, kinetic):
    """(converged, at_edge) at pose q with Phi gradient ``grad`` and kinetic energy (J).

    converged: the force along every axis, as the energy change over one grid step
    ``|dPhi/dq_k|``, and the kinetic energy are both at most ``max(floor, f_ref * delta)``
    (kinetic: with the smallest active ``f_ref``). ``delta = atol + rtol * max|q - q0|`` is
    the position error the step-size controller allows per step, in grid steps; below
    it an explicit solver cannot resolve the approach to rest (it hovers at that size
    instead of converging), and ``f_ref * delta`` is the work of the reference force over
    that distance. In float32 the noise floor is the larger term; in float64 the
    tolerance term keeps runs finite.
    at_edge: on or past a cut side of the grid (as the other steppers), or past the end
    of a non-periodic twist axis (a wall)."""
    delta = co.atol + co.rtol * jnp.max(jnp.abs(q - co.q0))
    f_stop = jnp.maximum(field.floor, co.f_ref * delta)
    active = _active(grid, q.dtype) > 0
    ke_stop = jnp.maximum(field.floor, jnp.min(jnp.where(active, co.f_ref, jnp.inf)) * delta)
    converged = jnp.all(jnp.abs(grad) <= f_stop) & (kinetic <= ke_stop)
    if any(grid.pin):
        # Hysteresis (simulator.hysteresis): pinned where no axis's force beats its pinning
        # force and the kinetic energy left is below the pinning work over one grid step.
        pin = jnp.asarray(grid.pin, q.dtype)
        work = jnp.min(jnp.where(active & (pin > 0), pin, jnp.inf))
        converged = converged | (jnp.all(jnp.abs(grad) <= jnp.maximum(pin, f_stop)) & (kinetic <= jnp.maximum(work, ke_stop)))
    edge = at_cut_edge(grid, q)
    if not grid.wrap and grid.shape[0] > 1:
        edge = edge | (q[0] < 0) | (q[0] > grid.shape[0] - 1)
    return converged, edge


# ----------------------------------------------------------------- vector fields
def _vf_overdamped(s, y, args):
    field, grid, co = args  # grid arrives through args as a static (hashable) leaf
    _, grad = potential_and_gradient(field, grid, co.q0 + y)
    return -co.drive * grad


def _vf_inertial(s, y, args):
    field, grid, co = args
    d, u = y
    _, grad = potential_and_gradient(field, grid, co.q0 + d)
    return u, -co.drive * grad - co.damp * u


def _split(y, inertial: bool):
    return y if inertial else (y, jnp.zeros_like(y))


def _energy(field: Field, grid: Grid, q):
    """Landscape energy E (:func:`simulator.stepping.interpolate`) at q, read at the nearest
    point of the grid where q has passed a wall (a cut side, an end of a bounded twist
    axis): the run stops there with EDGE and reports the edge value, as Phi repeats it,
    never the wall's +inf."""
    lo, hi = [], []
    for k, n in enumerate(grid.shape):
        walls = (True, True) if k == 0 and not grid.wrap else grid.cut[k]
        lo.append(0.0 if walls[0] else -np.inf)
        hi.append(n - 1.0 if walls[1] else np.inf)
    return interpolate(field, grid, jnp.clip(q, jnp.asarray(lo, q.dtype), jnp.asarray(hi, q.dtype)))


def _save(y, args, inertial: bool):
    field, grid, co = args
    d, u = _split(y, inertial)
    q = co.q0 + d
    phi, _ = potential_and_gradient(field, grid, q)
    return {
        "q": q,
        "v": u / co.tau,
        "energy": _energy(field, grid, q),
        "potential": phi,
        "kinetic": jnp.sum(co.ke * u * u),
    }


def _stop(y, args, inertial: bool):
    field, grid, co = args
    d, u = _split(y, inertial)
    q = co.q0 + d
    _, grad = potential_and_gradient(field, grid, q)
    converged, edge = _stop_flags(field, grid, co, q, grad, jnp.sum(co.ke * u * u))
    return converged | edge


# Module-level functions (not closures made per call), so that eager calls hit
# diffrax's compilation cache: it keys on function identity.
def _save_overdamped(s, y, args):
    return _save(y, args, False)


def _save_inertial(s, y, args):
    return _save(y, args, True)


def _stop_overdamped(s, y, args, **kwargs):
    return _stop(y, args, False)


def _stop_inertial(s, y, args, **kwargs):
    return _stop(y, args, True)


def _mechanical(y, args, inertial: bool):
    """Mechanical energy Phi + kinetic (J) of a solver state."""
    field, grid, co = args
    d, u = _split(y, inertial)
    return potential_and_gradient(field, grid, co.q0 + d)[0] + jnp.sum(co.ke * u * u)


class _GuardedController(diffrax.AbstractAdaptiveStepSizeController):
    """A PID controller that also rejects a step which (a) raises the mechanical energy
    more than the noise floor above the lowest value accepted so far or (b) moves more
    than one grid step along any axis.

    Why: the force is piecewise linear between grid nodes. A step that spans several
    cells can skip a narrow feature (a plateau, a ridge, the cusp) while the embedded
    error estimate, which assumes a smooth right-hand side, stays small: measured, a
    lightly damped chip crossing a four-pad-like plateau gained 0.2 pixel-forces of
    energy in one 44 px step. Capping the motion at one cell per step makes every kink
    visible to the estimate (the same step bound as the greedy and gradient steppers);
    the energy test makes the Lyapunov property hold on every accepted step. A rejected
    step is retried from the same point with a shorter step; after an accepted step the
    next one is capped so that at the same speed it moves about 0.9 grid steps.
    """

    inner: diffrax.PIDController
    rtol: float
    atol: float
    norm: Callable
    inertial: bool = eqx.field(static=True)

    def wrap(self, direction):
        return self

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        t1, inner = self.inner.init(terms, t0, t1, y0, dt0, args, func, error_order)
        return t1, (inner, _mechanical(y0, args, self.inertial))

    def adapt_step_size(
        self, t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state
    ):
        # The state carries the lowest mechanical energy accepted so far: the rise is
        # measured from it, not from the last step, so rises within the floor cannot add
        # up over a long (lightly damped, ringing) run (measured before: 3 floors above
        # the lowest value after 4700 steps).
        controller_state, lowest = controller_state
        keep, next_t0, next_t1, made_jump, state, result = self.inner.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state
        )
        field = args[0]
        d0, _ = _split(y0, self.inertial)
        d1, _ = _split(y1_candidate, self.inertial)
        moved = jnp.max(jnp.abs(d1 - d0))
        h1 = _mechanical(y1_candidate, args, self.inertial)
        rise = h1 - lowest
        ok = (rise <= field.floor) & (moved <= 1.0) & jnp.isfinite(rise)
        dt = t1 - t0
        veto = keep & ~ok
        shrink = jnp.clip(0.9 / jnp.maximum(moved, 1e-30), 0.1, 0.5)
        next_t0 = jnp.where(veto, t0, next_t0)
        next_t1 = jnp.where(veto, t0 + dt * shrink, next_t1)
        state = jax.tree_util.tree_map(
            lambda old, new: jnp.where(veto, old, new) if isinstance(new, jax.Array) else new,
            controller_state,
            state,
        )
        keep = keep & ok
        lowest = jnp.where(keep, jnp.minimum(lowest, h1), lowest)
        cap = dt * 0.9 / jnp.maximum(moved, 1e-30)
        next_t1 = jnp.where(keep, next_t0 + jnp.minimum(next_t1 - next_t0, cap), next_t1)
        return keep, next_t0, next_t1, made_jump, (state, lowest), result


# ----------------------------------------------------------------- steppers
def _run(
    field, grid, params, start, max_steps, record, inertial, rtol, atol, solver
) -> DynamicsState:
    if not isinstance(max_steps, int) or max_steps < 1:
        raise InputError(f"max_steps must be a positive integer (static), got {max_steps!r}")
    dt = field.dtype
    d_rtol, d_atol = default_tolerances(dt)
    rtol = d_rtol if rtol is None else rtol
    atol = d_atol if atol is None else atol
    # The SI products m s^2 and c s^2 (about 1e-21 and 1e-17 for a 200 um chip at 1 um/px)
    # are formed in float64: in float32 they underflow to 0 for light or weakly damped
    # chips (XLA flushes subnormals), which made tau = 0 and the end time infinite. Only
    # the nondimensional coefficients, of the order of the landscape's energies, are cast
    # to the field's dtype; tau and the end time are clamped to that dtype's range.
    wide = jax.dtypes.canonicalize_dtype(jnp.float64)
    scale = jnp.asarray(_axis_scales(grid), wide)
    active = _active(grid, wide)
    f_ref = _reference_force(field, grid, dt)
    f_ref_w = f_ref.astype(wide)
    mass = jnp.stack(
        [
            jnp.asarray(params.inertia_kg_m2, wide),
            jnp.asarray(params.mass_kg, wide),
            jnp.asarray(params.mass_kg, wide),
        ]
    )
    damping = jnp.stack(
        [
            jnp.asarray(params.rot_damping_N_m_s, wide),
            jnp.asarray(params.damping_N_s_m, wide),
            jnp.asarray(params.damping_N_s_m, wide),
        ]
    )
    ms2, cs2 = mass * scale * scale, damping * scale * scale
    if inertial:
        # Time to move one step from rest under the reference force, fastest axis.
        tau = jnp.min(jnp.where(active > 0, jnp.sqrt(ms2 / f_ref_w), jnp.inf))
        drive = active * tau * tau / ms2
        damp = active * damping * tau / mass
        ke = active * ms2 / (2.0 * tau * tau)
    else:
        # Time to move one step at the reference force (terminal speed), fastest axis.
        tau = jnp.min(jnp.where(active > 0, cs2 / f_ref_w, jnp.inf))
        drive = active * tau / cs2
        damp = jnp.zeros(3, wide)
        ke = jnp.zeros(3, wide)
    fi = jnp.finfo(dt)
    s_end = jnp.minimum(jnp.asarray(params.t_max_s, wide) / tau, float(fi.max) / 2**10).astype(dt)
    tau = jnp.maximum(tau, float(fi.tiny)).astype(dt)
    drive, damp, ke = drive.astype(dt), damp.astype(dt), ke.astype(dt)
    q0 = clamp_start(grid, jnp.asarray(start, dt))
    co = _Coeffs(
        q0=q0,
        drive=drive,
        damp=damp,
        ke=ke,
        tau=tau,
        f_ref=f_ref,
        rtol=jnp.asarray(rtol, dt),
        atol=jnp.asarray(atol, dt),
    )
    zeros = jnp.zeros(3, dt)
    y0 = (zeros, zeros) if inertial else zeros
    term = diffrax.ODETerm(_vf_inertial if inertial else _vf_overdamped)
    save_fn = _save_inertial if inertial else _save_overdamped
    saveat = (
        diffrax.SaveAt(t0=True, steps=True, fn=save_fn)
        if record
        else diffrax.SaveAt(t1=True, fn=save_fn)
    )
    pid = diffrax.PIDController(rtol=rtol, atol=atol)
    sol = diffrax.diffeqsolve(
        term,
        diffrax.Tsit5() if solver is None else solver,
        t0=jnp.asarray(0.0, dt),
        t1=s_end,
        dt0=None,
        y0=y0,
        args=(field, grid, co),
        saveat=saveat,
        stepsize_controller=_GuardedController(
            inner=pid, rtol=pid.rtol, atol=pid.atol, norm=pid.norm, inertial=inertial
        ),
        event=diffrax.Event(_stop_inertial if inertial else _stop_overdamped),
        max_steps=max_steps,
        throw=False,
    )
    step = jnp.asarray(sol.stats["num_accepted_steps"], jnp.int32)
    ys = sol.ys
    if record:
        final = jax.tree_util.tree_map(lambda a: a[step], ys)
        t_final = sol.ts[step]
    else:
        final = jax.tree_util.tree_map(lambda a: a[0], ys)
        t_final = sol.ts[0]
    q = final["q"]
    _, grad = potential_and_gradient(field, grid, q)
    converged, edge = _stop_flags(field, grid, co, q, grad, final["kinetic"])
    status = jnp.where(edge, EDGE, jnp.where(converged, CONVERGED, MAX_STEPS)).astype(jnp.int32)
    flat = converged & ~edge & on_plateau(field, grid, jnp.round(q).astype(jnp.int32))
    if record:
        filled = jnp.arange(max_steps + 1) <= step

        def buf(a):
            a = a[: max_steps + 1]
            mask = filled.reshape((-1,) + (1,) * (a.ndim - 1))
            return jnp.where(mask, a, jnp.nan)

        path, pe, pp, pk = buf(ys["q"]), buf(ys["energy"]), buf(ys["potential"]), buf(ys["kinetic"])
        pt = buf(sol.ts * tau)
    else:
        phi0, _ = potential_and_gradient(field, grid, q0)
        path, pe, pp = q0[None], _energy(field, grid, q0)[None], phi0[None]
        pk, pt = jnp.zeros(1, dt), jnp.zeros(1, dt)
    return DynamicsState(
        q=q,
        v=final["v"],
        energy=final["energy"],
        potential=final["potential"],
        kinetic=final["kinetic"],
        time_s=t_final * tau,
        step=step,
        status=status,
        path=path,
        path_energy=pe,
        path_potential=pp,
        path_kinetic=pk,
        path_t=pt,
        flat=flat,
    )


def overdamped(
    field: Field,
    grid: Grid,
    params: DynamicsParams,
    start,
    max_steps: int,
    record: bool = True,
    *,
    rtol: float | None = None,
    atol: float | None = None,
    solver=None,
) -> DynamicsState:
    """First-order (viscous) dynamics ``c v = F``, ``c_t w = tau`` from rest at ``start``.

    Args:
        field, grid: the landscape (:func:`simulator.stepping.field_and_grid`); grid static.
        params: damping (mass and inertia are unused) and ``t_max_s``; traced.
        start: (3,) fractional grid indices (it, iy, ix).
        max_steps: solver steps at most, accepted or rejected; the size of the path
            buffers (static).
        record: keep the path (static; off for large batches).
        rtol, atol: step-size controller tolerances (static); atol in grid steps.
            Default: :func:`default_tolerances` of the field's dtype.
        solver: a diffrax solver (static; default ``diffrax.Tsit5()``).

    Returns the final :class:`DynamicsState` (``kinetic`` is 0: no inertia). jit with
    ``static_argnames=("grid", "max_steps", "record")``; a batch is ``jax.vmap`` over
    ``start`` (and, if wanted, ``params``).
    """
    return _run(field, grid, params, start, max_steps, record, False, rtol, atol, solver)


def inertial(
    field: Field,
    grid: Grid,
    params: DynamicsParams,
    start,
    max_steps: int,
    record: bool = True,
    *,
    rtol: float | None = None,
    atol: float | None = None,
    solver=None,
) -> DynamicsState:
    """Second-order dynamics ``m a = F - c v``, ``I alpha = tau - c_t w`` from rest at ``start``.

    Arguments and result as for :func:`overdamped`; ``params`` supplies mass and
    moment of inertia as well. Mechanical energy ``potential + kinetic`` falls
    monotonically (up to the noise floor) along the recorded path.
    """
    return _run(field, grid, params, start, max_steps, record, True, rtol, atol, solver)


__all__ = [
    "DynamicsParams",
    "DynamicsState",
    "default_tolerances",
    "inertial",
    "overdamped",
    "potential",
    "potential_and_gradient",
]
