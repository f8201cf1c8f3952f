"""Contact-angle hysteresis per pose, as the steppers read it (docs/physics.md §5.3).

The pinning force and torque come from the contact lines that slide over a wet pad at the
chip's *current* pose and footprint, not from the nominal pose: a direct sum over the
chip outline's elements (:func:`simulator.physics.pinning_lines`, pieces of half a pixel:
about 2,900 on a 730 um chip at 2 um/px), turned and moved with the chip, each reading the
pattern (bilinear, four pixels) ``d_p`` beyond it along its normal, and the pad's wet bit
where the run carries the footprint as its state (:class:`simulator.motion.Relay`). It is
evaluated inside the JAX steppers (every method, single runs and vmapped batches alike):
one gather of four pixels per element per evaluation, against 64 energies for the force.
A table of the shares over the pose grid would cost three values per pose and per
footprint state, and the states are not known before a run.

Units: the steppers compare ``|dE/dq_k|`` (J per index step) with the pinning work over
one grid step along (twist, y, x), in J: :func:`pin_at` returns that.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from simulator.core import UM, UM2
from simulator.motion._field import wet_pattern

if TYPE_CHECKING:
    from simulator.landscape import PoseGrid
    from simulator.motion._field import Field, Relay
    from simulator.scene import Scene


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "mids",
        "normals",
        "ds",
        "wt",
        "pattern",
        "labels",
        "reach_um",
        "f2",
        "um_per_px",
        "origin",
    ],
    meta_fields=[],
)
@dataclass(frozen=True)
class PinLines:
    """The outline's elements and the pattern a per-pose pinning reads (a pytree).

    mids, normals: (n, 2) um and unit vectors, about the chip centre at the nominal pose.
    ds: (n,) um; wt: (n,) um^2, ``|(z x r) . n| ds``.
    pattern: (H + 2, W + 2) the pattern's values with a ring of zeros (no bounds logic);
    labels: (H + 2, W + 2) int32, pad labels 1..n (0: substrate), ringed likewise.
    reach_um, f2 (N/m), um_per_px: scalars (traced: scenes differing in them share a compile).
    origin: (3,) the pose of the grid's node (0, 0, 0), (twist deg, y um, x um), set by
    :func:`simulator.motion.make_field` from its grid: traced, because a grid's origin is not
    part of the static grid's identity (boxes of one shape share a compiled stepper), and a
    pinning read from the static grid's origin would be the first box's in every later one.
    """

    mids: jax.Array
    normals: jax.Array
    ds: jax.Array
    wt: jax.Array
    pattern: jax.Array
    labels: jax.Array
    reach_um: jax.Array
    f2: jax.Array
    um_per_px: jax.Array
    origin: jax.Array


def pin_lines(scene: Scene, dtype: DTypeLike) -> PinLines | None:
    """The scene's :class:`PinLines` in ``dtype``, or None where no line can slide
    (:func:`simulator.physics.pinning_lines`)."""
    from simulator.motion._field import enable_float64
    from simulator.physics import pinning_lines

    d = pinning_lines(scene)
    if d is None:
        return None
    dt = np.dtype(dtype)
    if dt == np.float64:
        enable_float64()
    return PinLines(
        mids=jnp.asarray(d["mids"].astype(dt)),
        normals=jnp.asarray(d["normals"].astype(dt)),
        ds=jnp.asarray(d["ds"].astype(dt)),
        wt=jnp.asarray(d["wt"].astype(dt)),
        pattern=jnp.asarray(np.pad(d["pattern"], 1).astype(dt)),
        labels=jnp.asarray(np.pad(d["labels"], 1)),
        reach_um=jnp.asarray(d["reach_um"], dt),
        f2=jnp.asarray(d["f2"], dt),
        um_per_px=jnp.asarray(d["um_per_px"], dt),
        origin=jnp.zeros(3, dt),  # the field's grid sets it (make_field)
    )


def _wet_value(lines: PinLines, relay: Relay | None, r: jax.Array, c: jax.Array) -> jax.Array:
    """The pattern's value at integer (row, col) of the ringed arrays, 0 on a dry pad."""
    if relay is None:
        return lines.pattern[r, c]
    if relay.lines_pattern is not None:  # the state's pattern, made once (Field._replace)
        return relay.lines_pattern[r, c]
    return wet_pattern(lines.pattern[r, c], lines.labels[r, c], relay.wet)


def pin_at(field: Field, grid: PoseGrid, q: ArrayLike) -> jax.Array:
    """(3,) pinning work over one grid step along (twist, y, x), J, at fractional indices q
    (module docstring; :func:`simulator.physics.sliding_pinning_at` is its NumPy reference).
    Without :attr:`Field.lines`, the field's constant ``pin``."""
    lines = field.lines
    dt = field.dtype
    if lines is None:
        return field.pin.astype(dt)
    q = jnp.asarray(q, dt)
    s = jnp.asarray(grid.um_per_px, dt)
    t0, y0, x0 = lines.origin[0], lines.origin[1], lines.origin[2]
    x = x0 + q[2] * s
    y = y0 + q[1] * s
    a = jnp.deg2rad(t0 + (q[0] if grid.shape[0] > 1 else 0.0) * grid.twist_step_deg)
    c, sn = jnp.cos(a), jnp.sin(a)
    mx, my = lines.mids[:, 0], lines.mids[:, 1]
    nx = c * lines.normals[:, 0] - sn * lines.normals[:, 1]
    ny = sn * lines.normals[:, 0] + c * lines.normals[:, 1]
    px = c * mx - sn * my + x + lines.reach_um * nx
    py = sn * mx + c * my + y + lines.reach_um * ny
    hh, ww = lines.pattern.shape  # ringed: the image is (hh - 2, ww - 2)
    col = px / lines.um_per_px + (ww - 2) / 2 - 0.5 + 1.0
    row = (hh - 2) / 2 - 0.5 - py / lines.um_per_px + 1.0
    # outside the image: the ring's zeros (clipped indices land on the ring)
    col = jnp.clip(col, 0.0, ww - 1.0)
    row = jnp.clip(row, 0.0, hh - 1.0)
    r0 = jnp.clip(jnp.floor(row).astype(jnp.int32), 0, hh - 2)
    c0 = jnp.clip(jnp.floor(col).astype(jnp.int32), 0, ww - 2)
    fr = row - r0
    fc = col - c0
    relay = field.relay
    v = (
        (1 - fr) * (1 - fc) * _wet_value(lines, relay, r0, c0)
        + (1 - fr) * fc * _wet_value(lines, relay, r0, c0 + 1)
        + fr * (1 - fc) * _wet_value(lines, relay, r0 + 1, c0)
        + fr * fc * _wet_value(lines, relay, r0 + 1, c0 + 1)
    )
    on = jnp.clip(v, 0.0, 1.0)
    f2 = lines.f2
    step_m = s * UM
    p_x = f2 * jnp.sum(on * jnp.abs(nx) * lines.ds) * UM * step_m
    p_y = f2 * jnp.sum(on * jnp.abs(ny) * lines.ds) * UM * step_m
    p_t = f2 * jnp.sum(on * lines.wt) * UM2 * math.radians(grid.twist_step_deg)
    if grid.shape[0] == 1:
        p_t = jnp.zeros_like(p_t)
    return jnp.stack([p_t, p_y, p_x]).astype(dt)


def soft_threshold(g: ArrayLike, p: ArrayLike) -> jax.Array:
    """``sign(g) max(|g| - p, 0)``: the part of a force beyond its Coulomb bound ``p``."""
    return jnp.sign(g) * jnp.maximum(jnp.abs(g) - p, 0.0)
