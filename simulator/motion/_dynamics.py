"""Time-resolved dynamics of the chip on the energy landscape (docs/physics.md section 4).

Two steppers with the shape of :mod:`simulator.motion` (pure functions of
``(field, grid, params, start, max_steps, record)``, a static :class:`~simulator.landscape.PoseGrid`,
a NamedTuple state out, jit- and vmap-able):

* :func:`overdamped`: ``c v = F``, ``c_t w = tau`` (first order, no inertia);
* :func:`inertial`: ``m a = F - c v``, ``I alpha = tau - c_t w`` (docs/physics.md §4, Eq. 10).

F and tau are minus the gradient of the potential Phi below, converted to SI: one x or y
index step is ``grid.um_per_px`` um, one twist index step is ``grid.twist_step_deg``
degrees (radians inside). Positions are in grid-index units ``(it, iy, ix)`` as in
:mod:`simulator.motion` (``it`` unwrapped on a periodic twist axis); times in seconds.

The potential Phi: :mod:`simulator.motion` (the landscape averaged over +-1 grid step,
C1, with an exact gradient; why, and what it changes, is written there).

Integration: ``diffrax.diffeqsolve`` with Tsit5 (explicit 5th-order Runge-Kutta with an
embedded error estimate) and a PID step-size controller, in nondimensional time (unit
``tau``, below) with the state measured from the start, so that ``rtol``/``atol`` are
relative to the displacement and ``atol`` is in grid steps; defaults from the dtype
(:func:`default_tolerances`). The controller is guarded (:class:`_GuardedController`): a
step is also rejected when it raises ``Phi + kinetic`` by more than the noise floor or
moves more than one grid step along any axis, so the energy never rises along the
recorded path by construction and no step jumps over a feature of the landscape.

Heavily damped inertial runs (the calibrated water parameters: the velocity relaxes in
``m / c``, microseconds, while the chip creeps a grid step in milliseconds) are stiff for an
explicit solver. Pass ``solver=stiff_solver()`` (what :mod:`simulator.motion` does when
:func:`simulator.motion.is_stiff` says so): diffrax KenCarp5, an IMEX Runge-Kutta method,
on the model split into the force (explicit) and the kinematics with the damping
(implicit, linear). Its Newton iteration then solves a linear system and never sees the
force, which is only piecewise smooth and, in float32, quantized by the rounding of the
position (an implicit solver on the whole field, Kvaerno5, stalled on those jumps and cut
its steps to nothing in the middle of a pad: 2 174 steps for 29 um of a 730 um four-pad
chip). In the inertial model the controller weights velocity errors by ``1 / max(1,
damp)`` (:func:`simulator.motion.error_norm`): the distance a velocity error carries
the chip before the damping removes it; lightly damped runs keep the plain RMS norm.
Steps are recorded at every accepted solver step (``SaveAt(steps=True)``, a
``max_steps`` buffer).

Stopping: a diffrax boolean event ends the run (status CONVERGED) at the end of the
first step where (a) the force along every axis, expressed as the energy change over
one grid step, ``|dPhi/dq_k|``, is at most the landscape's noise floor, and (b) the
kinetic energy is at most the noise floor (the speed whose kinetic energy is
round-off); where the integrator's position tolerance is coarser than the floor (float64)
the threshold is the work of the reference force over that tolerance instead (see
``_stop_flags``). It also ends where the chip is at rest within
:data:`simulator.motion.REST_TOL_STEPS` (1/20) of a grid step of a stable rest point
of Phi (positive-definite Hessian; :func:`simulator.motion._near_rest`): the force
falls linearly towards such a point and the force test alone waited out the whole
exponential approach (on the rounded edge of the floor a finite meniscus floats the chip
on, time constants of 0.2 s: runs ran out of ``t_max_s`` there). The same tests at the
start end a run with no force before any step (a
no-contact start). Reaching a cut side of the grid (``grid.cut``: the window or twist
band was cut from a larger one; :func:`simulator.motion.at_cut_edge`), or passing the
end of a non-periodic twist axis (a wall), ends it with status EDGE, as for the other
steppers; within two steps of such a side Phi repeats the edge energies. Running out of
``t_max_s`` or ``max_steps`` gives MAX_STEPS.

Why diffrax and not a hand-written loop: events, step recording, step rejection (through
the controller) and vmap all work (the event is a per-member predicate; a vmapped batch
runs until its last member stops). A batch is ``jax.vmap`` of the single run, as for the
other steppers.

Modules: this one holds the result (:class:`DynamicsState`), the solver run and the two
steppers; the ODE's pieces (coefficients, vector fields, saved quantities, stop event,
the guarded controller) are :mod:`simulator.motion`.
"""

from __future__ import annotations

from typing import NamedTuple

import diffrax
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.typing import ArrayLike

from foundation import InputError
from simulator.landscape import PoseGrid
from simulator.motion._dynamics_ode import (
    IMEX,
    MOREAU_TOL,
    MoreauJean,
    _active,
    _axis_scales,
    _Coeffs,
    _energy,
    _GuardedController,
    _reference_force,
    _save_inertial,
    _save_overdamped,
    _stop_flags,
    _stop_inertial,
    _stop_overdamped,
    _vf_damping,
    _vf_force,
    _vf_inertial,
    _vf_overdamped,
    error_norm,
)

# Parameters (simulator.motion) and the potential Phi (simulator.motion), re-exported.
from simulator.motion._dynamics_params import MIN_FILM_UM, DynamicsParams, default_tolerances  # noqa: E402, F401
from simulator.motion._field import Field, clamp_start, relay_changes
from simulator.motion._potential import potential, potential_and_gradient  # noqa: E402, F401
from simulator.motion._stepping import CONVERGED, EDGE, EVENT, MAX_STEPS, on_plateau


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


# ----------------------------------------------------------------- steppers
def _run(
    field: Field,
    grid: PoseGrid,
    params: DynamicsParams,
    start: ArrayLike,
    max_steps: int,
    record: bool,
    inertial: bool,
    rtol: float | None,
    atol: float | None,
    solver: diffrax.AbstractSolver | None,
) -> DynamicsState:
    if not isinstance(max_steps, int) or max_steps < 1:
        raise InputError(f"max_steps must be a positive integer (static), got {max_steps!r}")
    dt = field.dtype
    d_rtol, d_atol = default_tolerances(dt)
    moreau = inertial and field.pinned  # static: hysteresis as friction, MoreauJean
    # The first-order Moreau-Jean step is held to its own tolerance (MOREAU_TOL, grid steps
    # per step) unless one is given; at the dtype's (5e-10 in float64) it would take steps
    # of a fifth of m / c. The stop test keeps the dtype's.
    s_tol = (MOREAU_TOL if moreau else d_rtol) if rtol is None else rtol
    a_tol = (MOREAU_TOL if moreau else d_atol) if atol is None else atol
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
    if moreau:
        # static: contact-angle hysteresis as Coulomb friction, stepped exactly (MoreauJean)
        solver = MoreauJean()
    if isinstance(solver, IMEX):
        if not inertial:
            raise InputError(
                "an IMEX solver (KenCarp) splits the inertial model; the overdamped one has no damping term to split"
            )
        term = diffrax.MultiTerm(diffrax.ODETerm(_vf_force), diffrax.ODETerm(_vf_damping))
    else:
        term = diffrax.ODETerm(_vf_inertial if inertial else _vf_overdamped)
    save_fn = _save_inertial if inertial else _save_overdamped
    saveat = (
        diffrax.SaveAt(t0=True, steps=True, fn=save_fn)
        if record
        else diffrax.SaveAt(t1=True, fn=save_fn)
    )
    pid = diffrax.PIDController(
        rtol=s_tol, atol=a_tol, norm=error_norm(co) if inertial else optx.rms_norm
    )
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
            inner=pid, rtol=s_tol, atol=a_tol, norm=pid.norm, inertial=inertial
        ),
        event=diffrax.Event(_stop_inertial if inertial else _stop_overdamped),
        max_steps=max_steps,
        throw=False,
    )
    step = jnp.asarray(sol.stats["num_accepted_steps"], jnp.int32)
    ts, ys = sol.ts, sol.ys
    assert ts is not None and ys is not None  # saveat asks for both
    if record:
        final = jax.tree_util.tree_map(lambda a: a[step], ys)
        t_final = ts[step]
    else:
        final = jax.tree_util.tree_map(lambda a: a[0], ys)
        t_final = ts[0]
    # Times in seconds: the nondimensional end s_end = t_max / tau times tau, both rounded to
    # the field's dtype, can land one ulp past t_max (float32: 1.00000012 s for 1 s). A run
    # never reports a time past its own limit: times are clamped to the largest value of the
    # dtype at or below t_max.
    t_max_w = jnp.asarray(params.t_max_s, wide)
    t_cap = t_max_w.astype(dt)
    t_cap = jnp.where(t_cap.astype(wide) > t_max_w, jnp.nextafter(t_cap, jnp.zeros((), dt)), t_cap)
    q = final["q"]
    _, grad = potential_and_gradient(field, grid, q)
    converged, edge = _stop_flags(field, grid, co, q, grad, final["kinetic"])
    # the footprint state changing here (a field with a relay) outranks rest: the run goes on
    status = jnp.where(
        edge,
        EDGE,
        jnp.where(relay_changes(field, grid, q), EVENT, jnp.where(converged, CONVERGED, MAX_STEPS)),
    ).astype(jnp.int32)
    flat = converged & ~edge & on_plateau(field, grid, jnp.round(q).astype(jnp.int32))
    if record:
        filled = jnp.arange(max_steps + 1) <= step

        def buf(a: jax.Array) -> jax.Array:
            a = a[: max_steps + 1]
            mask = filled.reshape((-1,) + (1,) * (a.ndim - 1))
            return jnp.where(mask, a, jnp.nan)

        path, pe, pp, pk = buf(ys["q"]), buf(ys["energy"]), buf(ys["potential"]), buf(ys["kinetic"])
        pt = buf(jnp.minimum(ts * tau, t_cap))
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
        time_s=jnp.minimum(t_final * tau, t_cap),
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
    grid: PoseGrid,
    params: DynamicsParams,
    start: ArrayLike,
    max_steps: int,
    record: bool = True,
    *,
    rtol: float | None = None,
    atol: float | None = None,
    solver: diffrax.AbstractSolver | None = None,
) -> DynamicsState:
    """First-order (viscous) dynamics ``c v = F``, ``c_t w = tau`` from rest at ``start``.

    Args:
        field, grid: the landscape (:func:`simulator.motion.field_and_grid`); grid static.
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
    grid: PoseGrid,
    params: DynamicsParams,
    start: ArrayLike,
    max_steps: int,
    record: bool = True,
    *,
    rtol: float | None = None,
    atol: float | None = None,
    solver: diffrax.AbstractSolver | None = None,
) -> DynamicsState:
    """Second-order dynamics ``m a = F - c v``, ``I alpha = tau - c_t w`` from rest at ``start``.

    Arguments and result as for :func:`overdamped`; ``params`` supplies mass and
    moment of inertia as well. Mechanical energy ``potential + kinetic`` falls
    monotonically (up to the noise floor) along the recorded path.
    """
    return _run(field, grid, params, start, max_steps, record, True, rtol, atol, solver)


__all__ = ["DynamicsState", "inertial", "overdamped"]
