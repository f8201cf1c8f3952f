"""The dynamics' potential Phi: the landscape smoothed over +-1 grid step, and its exact gradient.

The potential Phi (why not the trilinear energy itself). The landscape is the overlap
energy, piecewise linear with a V-shaped cusp at alignment. Its trilinear interpolant
has a discontinuous gradient (no Lipschitz force: the chip would chatter across the
cusp), and the central-difference force of :func:`simulator.motion.gradient` is
continuous but is *not* the gradient of the interpolated energy: with it, each passage
of the cusp can raise ``E + kinetic`` by up to half of (force x one grid step) (measured
on a damped V-well: rises adding up to 4 such units), and an overdamped chip in a
lopsided well climbs to where the central difference vanishes. So the dynamics uses
one smoothed potential and its exact gradient::

    Phi(q) = mean of E_trilinear over the box q +- 1 grid step along each axis

(:func:`potential`). Along any single axis its gradient is exactly the central
difference of :func:`simulator.motion.gradient`; in 3-D it is that difference averaged
over the +-1 step square of the other two axes. Phi equals E wherever E is linear over
the box (everywhere more than one step from a kink of the landscape) and rounds each
kink over +-1 step: at an aligned square of side L px, ``Phi - E`` is ``1/(2L)`` of the
well depth per translation axis and ``twist_step_rad/4`` of it for the twist; a plateau
edge moves in by about one step. Phi is a tensor-product piecewise-quadratic spline of
the node energies (4 nodes per axis), C1, so the force is Lipschitz, and the mechanical
energy ``Phi + kinetic`` is a Lyapunov function of both models: it can only fall, by
``c v^2`` per unit time. The state reports both the landscape energy ``E``
(:func:`simulator.motion.interpolate`, comparable with the other steppers) and
``Phi``. For a quadratic landscape ``Phi = E + const`` exactly, so a linear spring is
reproduced without interpolation error (tested against closed forms).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from simulator.landscape import PoseGrid
from simulator.motion._field import PAD, Field

_OFFSETS = np.arange(-1, 3)  # the 4 nodes per axis in the support of Phi's kernel


def _kernel(t: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Phi's 1-D kernel: the hat function averaged over +-1, and its derivative.

    ``K(t) = (1/2) * integral_{t-1}^{t+1} hat(s) ds``: ``1/2 - t^2/4`` for ``|t| <= 1``,
    ``(2 - |t|)^2 / 4`` for ``1 <= |t| <= 2``, 0 beyond; C1, a partition of unity.
    """
    a = jnp.abs(t)
    inner = a <= 1
    k = jnp.where(inner, 0.5 - 0.25 * t * t, 0.25 * jnp.square(jnp.maximum(2.0 - a, 0.0)))
    dk = jnp.where(inner, -0.5 * t, -0.5 * jnp.sign(t) * jnp.maximum(2.0 - a, 0.0))
    return k, dk


def _node_energy(
    field: Field, grid: PoseGrid, it: jax.Array, iy: jax.Array, ix: jax.Array
) -> jax.Array:
    """Node energies for Phi, as :func:`simulator.motion.lookup` but finite: beyond an
    uncut x/y side 0 (no contact); beyond a cut side or the end of a non-periodic twist
    axis (walls, +inf there) the edge value is repeated, and the run stops with EDGE."""
    t, ny, nx = grid.shape
    (_, _), (y_lo, y_hi), (x_lo, x_hi) = grid.cut
    itw = jnp.mod(it, t) if grid.wrap else jnp.clip(it, 0, t - 1)

    def clip(
        i: jax.Array, n: int, lo_cut: bool, hi_cut: bool
    ) -> jax.Array:  # a cut side repeats its edge; an uncut one reads the pad's 0
        return jnp.clip(i, 0 if lo_cut else -PAD, n - 1 if hi_cut else n - 1 + PAD) + PAD

    return field.padded[itw + PAD, clip(iy, ny, y_lo, y_hi), clip(ix, nx, x_lo, x_hi)]


def potential_and_gradient(
    field: Field, grid: PoseGrid, q: ArrayLike
) -> tuple[jax.Array, jax.Array]:
    """``(Phi(q), dPhi/dq)`` at fractional indices q (3,) = (it, iy, ix); J and J per index step.

    Phi is the landscape energy averaged over ``q +- 1`` grid step along each axis (see
    the module docstring). A grid with one twist has no twist axis: Phi does not depend
    on ``it`` there.
    """
    dt = field.dtype
    q = jnp.asarray(q, dt)
    base = jnp.floor(q)
    frac = q - base
    b = base.astype(jnp.int32)
    off = jnp.asarray(_OFFSETS, jnp.int32)
    ws, dws, idx = [], [], []
    for k in range(3):
        w, dw = _kernel(frac[k] - off.astype(dt))
        if k == 0 and grid.shape[0] == 1:
            w, dw = jnp.asarray([0.0, 1.0, 0.0, 0.0], dt), jnp.zeros(4, dt)
            idx.append(jnp.zeros(4, jnp.int32))
        else:
            idx.append(b[k] + off)
        ws.append(w)
        dws.append(dw)
    e = _node_energy(
        field, grid, idx[0][:, None, None], idx[1][None, :, None], idx[2][None, None, :]
    )
    phi = jnp.einsum("i,j,k,ijk->", ws[0], ws[1], ws[2], e)
    grad = jnp.stack(
        [
            jnp.einsum("i,j,k,ijk->", dws[0], ws[1], ws[2], e),
            jnp.einsum("i,j,k,ijk->", ws[0], dws[1], ws[2], e),
            jnp.einsum("i,j,k,ijk->", ws[0], ws[1], dws[2], e),
        ]
    )
    return phi, grad


def potential(field: Field, grid: PoseGrid, q: ArrayLike) -> jax.Array:
    """Phi(q) in J (see :func:`potential_and_gradient`)."""
    return potential_and_gradient(field, grid, q)[0]
