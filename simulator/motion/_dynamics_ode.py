"""The ODE the dynamics integrate, as diffrax sees it.

Owns the per-axis coefficients in nondimensional time (:class:`_Coeffs`, from
:func:`_axis_scales`, :func:`_reference_force`, :func:`_active`), the stopping test
(:func:`_stop_flags`), the vector fields of the overdamped and inertial models, what is
saved at each step (:func:`_save`, with the landscape energy :func:`_energy`), the stop
event (:func:`_stop`) and the guarded step-size controller (:class:`_GuardedController`:
no rise of ``Phi + kinetic`` above the floor, at most one grid step per step). The
physics, units and rules are those of :mod:`simulator.motion`, which runs the solver
(``diffrax.diffeqsolve``) on these pieces.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.typing import ArrayLike, DTypeLike

from simulator.core import UM
from simulator.landscape import PoseGrid
from simulator.motion._field import Field, at_cut_edge, interpolate, relay_changes
from simulator.motion._pinning import pin_at, soft_threshold
from simulator.motion._potential import _OFFSETS, _kernel, _node_energy, potential_and_gradient
from simulator.motion._stepping import reference_gradient


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


#: What the vector fields, saves and stop tests get as ``args``: the field, its (static)
#: grid and the coefficients.
_Args = tuple[Field, PoseGrid, _Coeffs]
#: A solver state: ``(d, u)`` (displacement and velocity, index steps) for the inertial
#: model, ``d`` alone for the overdamped one (:func:`_split` makes both a pair).
_Y = Any


def _axis_scales(grid: PoseGrid) -> np.ndarray:
    """SI length of one index step along (it, iy, ix): radians, metres, metres."""
    return np.array([math.radians(grid.twist_step_deg), grid.um_per_px * UM, grid.um_per_px * UM])


def _reference_force(field: Field, grid: PoseGrid, dt: DTypeLike) -> jax.Array:
    """Typical |dE/dq| per index step (J), as in stepping.gradient_descent: a chip edge of
    length 2 rg sliding over a pad, for x and y; times the arc per twist step for twist."""
    g = jnp.maximum(reference_gradient(field, grid), jnp.finfo(dt).tiny / jnp.finfo(dt).eps)
    return g * jnp.asarray([max(grid.twist_px_per_step, 1e-6), 1.0, 1.0], dt)


def _active(grid: PoseGrid, dt: DTypeLike) -> jax.Array:
    return jnp.asarray([grid.shape[0] > 1, True, True], dt)


def _stop_flags(
    field: Field,
    grid: PoseGrid,
    co: _Coeffs,
    q: jax.Array,
    grad: jax.Array,
    kinetic: jax.Array,
) -> tuple[jax.Array, jax.Array]:
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
    if field.pinned:
        # Hysteresis (docs/physics.md §5.3): the chip sticks where no axis's force beats its
        # static pinning at the current pose by more than the force the run resolves, and it
        # is at rest. The friction is in the equations of motion (Coulomb: the overdamped
        # velocity is the force beyond the pinning, the inertial step sets a velocity that
        # the pinning can stop to zero), so a stuck chip has no speed left.
        pin = pin_at(field, grid, q)
        converged = converged | (jnp.all(jnp.abs(grad) <= pin + f_stop) & (kinetic <= ke_stop))
    converged = converged | _near_rest(field, grid, q, grad, kinetic)
    edge = at_cut_edge(grid, q)
    if not grid.wrap and grid.shape[0] > 1:
        edge = edge | (q[0] < 0) | (q[0] > grid.shape[0] - 1)
    return converged, edge


#: A run also stops when Phi's stable rest point lies within this many grid steps along
#: every axis (:func:`_near_rest`).
REST_TOL_STEPS = 0.05


def _hessian(field: Field, grid: PoseGrid, q: ArrayLike) -> jax.Array:
    """Phi's Hessian at q (J per index step squared), one-sided where it jumps.

    Phi is C1 and piecewise quadratic (:mod:`simulator.motion`): its second derivative
    along an axis jumps at every grid line. Within a cell (``frac`` in [0, 1)) the kernel's
    second derivative on the four nodes is ``(1/2, -1/2, -1/2, 1/2)``; the mixed terms use
    the kernel's (continuous) first derivative. Autodiff of the gradient takes a branch of
    ``abs`` and ``maximum`` at a grid line that belongs to no cell (on a node it returned
    the energy itself, 1e5 times the true curvature)."""
    dt = field.dtype
    q = jnp.asarray(q, dt)
    base = jnp.floor(q)
    frac = q - base
    b = base.astype(jnp.int32)
    off = jnp.asarray(_OFFSETS, jnp.int32)
    d2 = jnp.asarray([0.5, -0.5, -0.5, 0.5], dt)
    ws, dws, d2s, idx = [], [], [], []
    for k in range(3):
        w, dw = _kernel(frac[k] - off.astype(dt))
        if k == 0 and grid.shape[0] == 1:
            ws.append(jnp.asarray([0.0, 1.0, 0.0, 0.0], dt))
            dws.append(jnp.zeros(4, dt))
            d2s.append(jnp.zeros(4, dt))
            idx.append(jnp.zeros(4, jnp.int32))
        else:
            ws.append(w)
            dws.append(dw)
            d2s.append(d2)
            idx.append(b[k] + off)
    e = _node_energy(
        field, grid, idx[0][:, None, None], idx[1][None, :, None], idx[2][None, None, :]
    )

    def term(a: int, c: int) -> jax.Array:
        f = [ws[0], ws[1], ws[2]]
        if a == c:
            f[a] = d2s[a]
        else:
            f[a], f[c] = dws[a], dws[c]
        return jnp.einsum("i,j,k,ijk->", f[0], f[1], f[2], e)

    return jnp.stack([jnp.stack([term(a, c) for c in range(3)]) for a in range(3)])


def _near_rest(
    field: Field, grid: PoseGrid, q: jax.Array, grad: jax.Array, kinetic: jax.Array
) -> jax.Array:
    """True where the chip is at rest within :data:`REST_TOL_STEPS` of a stable rest point.

    Near a stable rest point the force falls linearly with the distance to it, so the
    chip approaches it exponentially and the force test of :func:`_stop_flags` (at the
    noise floor) is met only after many time constants. Where Phi's Hessian H (active
    axes) is positive definite, the rest point is ``q - H^-1 grad``; the run stops when
    that step is at most :data:`REST_TOL_STEPS` along every axis and the kinetic energy
    could lift the chip at most that far up the softest direction
    (``kinetic <= lambda_min tol^2 / 2``). Measured: the floating floor of the wall-profile
    meniscus (730/100 four-pad, 20 nl) is approached on the rounded edge of Phi, one grid
    step wide, with a time constant of 0.2 s at 5 um/px; runs from (300, 0, 0) ran out of
    their second inside the floor."""
    active = _active(grid, q.dtype) > 0
    mask = active[:, None] & active[None, :]
    h = jnp.where(mask, _hessian(field, grid, q), 0.0)
    h = 0.5 * (h + h.T)
    scale = jnp.maximum(jnp.max(jnp.abs(h)), jnp.finfo(q.dtype).tiny)
    h = jnp.where(mask, h, jnp.eye(3, dtype=q.dtype) * scale)  # inactive axes: stiff, no motion
    lam = jnp.linalg.eigvalsh(h)[0]
    step = jnp.linalg.solve(h, jnp.where(active, grad, 0.0))
    tol = jnp.asarray(REST_TOL_STEPS, q.dtype)
    return (lam > 0) & jnp.all(jnp.abs(step) <= tol) & (kinetic <= 0.5 * lam * tol * tol)


# ----------------------------------------------------------------- vector fields
def _vf_overdamped(s: ArrayLike, y: jax.Array, args: _Args) -> jax.Array:
    field, grid, co = args  # grid arrives through args as a static (hashable) leaf
    q = co.q0 + y
    _, grad = potential_and_gradient(field, grid, q)
    if field.pinned:  # static: Coulomb friction, c v = F - P sign(v) (docs/physics.md §4)
        return -co.drive * soft_threshold(grad, pin_at(field, grid, q))
    return -co.drive * grad


def _vf_inertial(
    s: ArrayLike, y: tuple[jax.Array, jax.Array], args: _Args
) -> tuple[jax.Array, jax.Array]:
    field, grid, co = args
    d, u = y
    _, grad = potential_and_gradient(field, grid, co.q0 + d)
    return u, -co.drive * grad - co.damp * u


# The inertial model split for an IMEX solver (:data:`IMEX`): the force is the explicit
# term, the kinematics and the damping (linear, with a constant Jacobian) the implicit one.
# The implicit solve then never sees the force: the force is piecewise smooth (its
# Jacobian jumps at every grid line) and, in float32, quantized by the rounding of the
# position q0 + d (one unit in the last place of an index of a few hundred is 1.5e-5 to
# 6e-5 grid steps; times a stiff axis, such as the rounded V of the energy across y = 0 of
# a four-pad chip, a jump of 1e-5 of the reference force). A Newton iteration on the whole
# vector field (Kvaerno5) stalled on those jumps, or oscillated across them, and each
# failed solve rejected the step and cut it five-fold: the step-size collapse of the
# calibrated (heavily damped) inertial runs.
def _vf_force(
    s: ArrayLike, y: tuple[jax.Array, jax.Array], args: _Args
) -> tuple[jax.Array, jax.Array]:
    """Explicit part of the split inertial model: ``(0, -drive * grad Phi)``."""
    field, grid, co = args
    d, u = y
    _, grad = potential_and_gradient(field, grid, co.q0 + d)
    return jnp.zeros_like(u), -co.drive * grad


def _vf_damping(
    s: ArrayLike, y: tuple[jax.Array, jax.Array], args: _Args
) -> tuple[jax.Array, jax.Array]:
    """Implicit part of the split inertial model: ``(u, -damp * u)``, linear in the state."""
    field, grid, co = args
    d, u = y
    return u, -co.damp * u


#: The IMEX (additive Runge-Kutta) solvers the inertial model is split for.
IMEX = (diffrax.KenCarp3, diffrax.KenCarp4, diffrax.KenCarp5)

#: Tolerance of the implicit stages' Newton (chord) iteration, relative and absolute, in
#: units of the state. The implicit part is linear, so one iteration solves it to round-off
#: and this tolerance only decides when to stop: the iteration stops once a correction is
#: below 1e-4 of it (diffrax's VeryChord, float32) and must see that happen above round-off
#: (eps / 1e-2 = 1.2e-5 < 1e-4). With the step-size controller's own tolerances (1.2e-5 in
#: float32) the corrections stall at round-off, a unit in the last place, and the solve
#: fails (measured: corrections repeating at 2.6e-4 of the tolerance).
ROOT_TOL = 1e-2


def stiff_solver() -> diffrax.KenCarp5:
    """The solver for heavily damped inertial runs: diffrax KenCarp5 (IMEX, 5th order) on
    the split model, with a Newton tolerance the implicit stages can meet (:data:`ROOT_TOL`)."""
    return diffrax.KenCarp5(root_finder=diffrax.VeryChord(rtol=ROOT_TOL, atol=ROOT_TOL))


def _weighted_rms(weights: jax.Array, err: tuple[jax.Array, jax.Array]) -> jax.Array:
    """RMS norm of the scaled error ``(d, u)`` with the velocity errors weighted per axis."""
    d, u = err
    return optx.rms_norm((d, weights * u))


def error_norm(co: _Coeffs) -> jax.tree_util.Partial:
    """The step-size controller's norm for the inertial state ``(d, u)``.

    A velocity error matters through the distance it carries the chip before the damping
    removes it: ``1 / damp`` time units where ``damp > 1`` (heavy damping), about one
    time unit otherwise. So velocity errors are weighted by ``1 / max(1, damp)``: lightly
    damped runs keep the plain RMS norm; in heavily damped ones the velocity, slaved to the
    force (``u = drive F / damp``), is not asked for more relative accuracy than the force
    has (its round-off, up to the landscape's noise floor, was 3e-5 of the velocity while
    the tolerance asked for 1.2e-5: the steps shrank to a twentieth of a grid step)."""
    return jax.tree_util.Partial(_weighted_rms, 1.0 / jnp.maximum(co.damp, 1.0))


def _split(y: _Y, inertial: bool) -> tuple[jax.Array, jax.Array]:
    return y if inertial else (y, jnp.zeros_like(y))


def _energy(field: Field, grid: PoseGrid, q: jax.Array) -> jax.Array:
    """Landscape energy E (:func:`simulator.motion.interpolate`) at q, read at the nearest
    point of the grid where q has passed a wall (a cut side, an end of a bounded twist
    axis): the run stops there with EDGE and reports the edge value, as Phi repeats it,
    never the wall's +inf."""
    lo, hi = [], []
    for k, n in enumerate(grid.shape):
        walls = (True, True) if k == 0 and not grid.wrap else grid.cut[k]
        lo.append(0.0 if walls[0] else -np.inf)
        hi.append(n - 1.0 if walls[1] else np.inf)
    return interpolate(field, grid, jnp.clip(q, jnp.asarray(lo, q.dtype), jnp.asarray(hi, q.dtype)))


def _save(y: _Y, args: _Args, inertial: bool) -> dict[str, jax.Array]:
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


def _stop(y: _Y, args: _Args, inertial: bool) -> jax.Array:
    field, grid, co = args
    d, u = _split(y, inertial)
    q = co.q0 + d
    _, grad = potential_and_gradient(field, grid, q)
    converged, edge = _stop_flags(field, grid, co, q, grad, jnp.sum(co.ke * u * u))
    return converged | edge | relay_changes(field, grid, q)


# Module-level functions (not closures made per call), so that eager calls hit
# diffrax's compilation cache: it keys on function identity.
def _save_overdamped(s: ArrayLike, y: _Y, args: _Args) -> dict[str, jax.Array]:
    return _save(y, args, False)


def _save_inertial(s: ArrayLike, y: _Y, args: _Args) -> dict[str, jax.Array]:
    return _save(y, args, True)


def _stop_overdamped(s: ArrayLike, y: _Y, args: _Args, **kwargs: Any) -> jax.Array:
    return _stop(y, args, False)


def _stop_inertial(s: ArrayLike, y: _Y, args: _Args, **kwargs: Any) -> jax.Array:
    return _stop(y, args, True)


def _mechanical(y: _Y, args: _Args, inertial: bool) -> jax.Array:
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

    # The overrides below keep diffrax's signatures unannotated: the type checker takes
    # their parameter and return types from the base class (diffrax's own type aliases).

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


#: Local error per step (grid steps, relative and absolute) the first-order Moreau-Jean step
#: is held to (:class:`MoreauJean`); halving it moves the end pose and time by less than
#: tests/test_friction.py allows.
MOREAU_TOL = 1e-4


class MoreauJean(diffrax.AbstractAdaptiveSolver):
    """The inertial model with Coulomb friction (contact-angle hysteresis, docs/physics.md
    §4), stepped without regularizing the friction: a Moreau-Jean step, the time-stepping
    of non-smooth mechanics (Moreau 1988; Jean 1999).

    Per axis, with the force taken at the step's start (explicit) and the damping and the
    friction at its end (implicit)::

        u* = u0 - h drive grad Phi(q0)
        u1 = sign(u*) max(|u*| - h fr, 0) / (1 + h damp)      fr = drive P(q0)
        d1 = d0 + h u1

    ``P(q0)`` the pinning at the step's start pose (:func:`simulator.motion.pin_at`). The
    friction's set-valued law (any force in [-P, P] at rest) is solved exactly, so a chip
    whose force stays within the pinning keeps ``u = 0`` to the last bit and one beyond it
    slides with ``P`` subtracted: no ``tanh(v / v_eps)``, no stiffness from it, and the
    damping (implicit) is stable at any step. First order; the error estimate (for the
    step-size controller) is the difference from the trapezoidal step, ``h (u1 - u0) / 2``
    in position and ``h (a1 - a0) / 2`` in velocity (``a`` the smooth part of the
    acceleration, force and damping, at the step's two ends): second order in ``h``.
    """

    term_structure = diffrax.AbstractTerm
    interpolation_cls = diffrax.LocalLinearInterpolation

    # Unannotated overrides: their types are diffrax's, from the base class (as above).

    def order(self, terms):
        return 1

    def error_order(self, terms):
        return 2

    def init(self, terms, t0, t1, y0, args):
        return None

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        field, grid, co = args
        h = t1 - t0
        d0, u0 = y0
        q0 = co.q0 + d0
        _, g0 = potential_and_gradient(field, grid, q0)
        fr = co.drive * pin_at(field, grid, q0)
        ustar = u0 - h * co.drive * g0
        u1 = soft_threshold(ustar, h * fr) / (1.0 + h * co.damp)
        d1 = d0 + h * u1
        _, g1 = potential_and_gradient(field, grid, co.q0 + d1)
        a0 = -co.drive * g0 - co.damp * u0
        a1 = -co.drive * g1 - co.damp * u1
        y1 = (d1, u1)
        err = (0.5 * h * (u1 - u0), 0.5 * h * (a1 - a0))
        return y1, err, dict(y0=y0, y1=y1), None, diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)
