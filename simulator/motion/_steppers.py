"""Every stepper behind one signature and one state: greedy, gradient, overdamped, inertial.

``stepper(method)(field, grid, params, start, max_steps, record)`` runs one start to its
end and returns a :class:`RunState`, whatever the method:

* ``field, grid``: the padded landscape and its static grid
  (:func:`simulator.motion.field_and_grid`);
* ``params``: the method's parameters (:class:`simulator.motion.DynamicsParams` for
  the dynamic methods; None for greedy and gradient);
* ``start``: (3,) grid indices (it, iy, ix), fractional; greedy rounds them;
* ``max_steps`` and ``record`` (static): the bound on moves or solver steps, and
  whether the path is kept (off for batches).

:func:`finish` applies the rules every caller shares: a run that used up its steps
without converging ran out of steps, and the outcome is :func:`classify`.
A batch is ``jax.vmap`` of the single run (:mod:`simulator.batch`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from simulator.core import DYNAMIC_METHODS, METHODS
from simulator.motion._stepping import (
    CONVERGED,
    MAX_STEPS,
    classify,
    gradient_descent,
    greedy,
    on_plateau,
)

if TYPE_CHECKING:
    import diffrax

    from simulator.landscape import PoseGrid
    from simulator.motion._dynamics import DynamicsState
    from simulator.motion._dynamics_params import DynamicsParams
    from simulator.motion._field import Field


class RunState(NamedTuple):
    """The end of one run, the same fields for every method.

    ``path[:step + 1]`` and ``path_energy[:step + 1]`` are the recorded trajectory (one
    row when not recorded); ``path_t`` its times (s) for the dynamic methods, NaN for
    the steppers, and ``time_s`` the final time (NaN for the steppers).
    """

    q: jax.Array  # (3,) final pose, fractional grid indices (it, iy, ix), it unwrapped
    energy: jax.Array  # landscape energy there, J
    step: jax.Array  # moves or accepted solver steps (int32)
    status: jax.Array  # CONVERGED / MAX_STEPS / EDGE (int32)
    flat: jax.Array  # stopped because the force was exactly zero (gradient; False otherwise)
    path: jax.Array  # (max_steps + 1, 3) fractional indices, or (1, 3)
    path_energy: jax.Array  # (max_steps + 1,) J, or (1,)
    path_t: jax.Array  # (max_steps + 1,) s, or (1,); NaN for the steppers
    time_s: jax.Array  # s; NaN for the steppers
    kinetic: jax.Array  # kinetic energy at the end, J (0 for the steppers)


def _greedy(
    field: Field,
    grid: PoseGrid,
    params: DynamicsParams | None,
    start: ArrayLike,
    max_steps: int,
    record: bool = True,
) -> RunState:
    s = greedy(field, grid, jnp.round(jnp.asarray(start)).astype(jnp.int32), max_steps, record)
    dt = field.dtype
    nan = jnp.full(s.path_energy.shape, jnp.nan, dt)
    return RunState(
        s.idx.astype(dt),
        s.energy,
        s.step,
        s.status,
        jnp.asarray(False),
        s.path.astype(dt),
        s.path_energy,
        nan,
        jnp.asarray(jnp.nan, dt),
        jnp.zeros((), dt),
    )


def _gradient(
    field: Field,
    grid: PoseGrid,
    params: DynamicsParams | None,
    start: ArrayLike,
    max_steps: int,
    record: bool = True,
) -> RunState:
    s = gradient_descent(field, grid, jnp.asarray(start), max_steps, record)
    dt = field.dtype
    nan = jnp.full(s.path_energy.shape, jnp.nan, dt)
    return RunState(
        s.q,
        s.energy,
        s.step,
        s.status,
        s.flat,
        s.path,
        s.path_energy,
        nan,
        jnp.asarray(jnp.nan, dt),
        jnp.zeros((), dt),
    )


def _dynamic(
    method: str,
    solver: diffrax.AbstractSolver | None,
    field: Field,
    grid: PoseGrid,
    params: DynamicsParams,
    start: ArrayLike,
    max_steps: int,
    record: bool = True,
) -> RunState:
    from simulator.motion._dynamics import inertial, overdamped

    fn = overdamped if method == "overdamped" else inertial
    s = fn(field, grid, params, jnp.asarray(start), max_steps, record, solver=solver)
    return RunState(
        s.q,
        s.energy,
        s.step,
        s.status,
        jnp.asarray(False),
        s.path,
        s.path_energy,
        s.path_t,
        s.time_s,
        s.kinetic,
    )


def stepper(method: str, stiff: bool = False) -> Callable[..., RunState]:
    """The run function of ``method`` with the shared signature (not jitted).

    ``stiff`` (inertial only) selects the IMEX solver (:func:`simulator.motion.stiff_solver`).
    """
    if method == "greedy":
        return _greedy
    if method == "gradient":
        return _gradient
    if method in DYNAMIC_METHODS:
        from simulator.motion._dynamics_ode import stiff_solver

        return functools.partial(
            _dynamic, method, stiff_solver() if stiff and method == "inertial" else None
        )
    raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")


@functools.cache
def jitted(method: str, stiff: bool = False) -> Callable[..., RunState]:
    """:func:`stepper` under ``jax.jit`` (grid, max_steps and record static), made once."""
    return jax.jit(stepper(method, stiff), static_argnames=("grid", "max_steps", "record"))


@functools.cache
def dynamics_jitted(method: str, stiff: bool = False) -> Callable[..., DynamicsState]:
    """The jitted dynamics function itself, returning its full
    :class:`simulator.motion.DynamicsState` (potential, kinetic energy, velocity), with
    the solver :func:`stepper` would choose; for diagnostics and tests."""
    from simulator.motion._dynamics import inertial, overdamped
    from simulator.motion._dynamics_ode import stiff_solver

    fn = overdamped if method == "overdamped" else inertial
    solver = stiff_solver() if stiff and method == "inertial" else None
    return jax.jit(
        functools.partial(fn, solver=solver), static_argnames=("grid", "max_steps", "record")
    )


def ran_out(step: jax.Array, status: jax.Array, max_steps: int) -> jax.Array:
    """The status with MAX_STEPS where a run used up its steps without converging."""
    return jnp.where((step >= max_steps) & (status != CONVERGED), MAX_STEPS, status)


def flat_at(field: Field, grid: PoseGrid, flat: jax.Array, q: ArrayLike) -> jax.Array:
    """Stopped on a plateau: zero force (the stepper's flag) or a flat direction at round(q)."""
    return flat | on_plateau(field, grid, jnp.round(jnp.asarray(q)).astype(jnp.int32))


def finish(
    field: Field, grid: PoseGrid, state: RunState, max_steps: int
) -> tuple[jax.Array, jax.Array]:
    """(status, outcome index into simulator.core.OUTCOMES) of a run, on the landscape it ran on."""
    status = ran_out(state.step, state.status, max_steps)
    # a dynamic run out of time, not steps, and creeping: a chip still carrying more kinetic
    # energy than the landscape resolves is passing through, not stopped (classify)
    timed_out = (
        jnp.isfinite(state.time_s)
        & (state.step < max_steps)
        & (jnp.asarray(state.kinetic, field.dtype) <= field.floor)
    )
    return status, classify(
        field,
        grid,
        state.q,
        state.energy,
        status,
        flat_at(field, grid, state.flat, state.q),
        timed_out,
    )
