"""The steppers' view of a landscape, and exact reads of it.

Owns the :class:`Field` (the landscape padded on every side with what lies beyond it, a
JAX pytree; :func:`pad_energy`, :func:`make_field`, :func:`field_and_grid`) on its static
:class:`~simulator.landscape.PoseGrid`, and every look-up the steppers and
the dynamics make on it: energies at integer grid indices (:func:`lookup`, and the
(3, 3, 3) and (4, 4, 4) blocks of :func:`neighbourhood` and :func:`block`), trilinear
interpolation (:func:`interpolate`) and the noise-floored gradient (:func:`gradient`)
at fractional indices, and the tests on the grid's cut sides (:func:`at_cut_edge`,
:func:`clamp_start`). Index units as in :mod:`simulator.motion`, which holds the
steppers.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from simulator.landscape import Landscape, PoseGrid

if TYPE_CHECKING:
    from simulator.motion._pinning import PinLines


def enable_float64() -> None:
    """Let a float64 landscape stay float64 inside the steppers: JAX's ``jax_enable_x64``,
    switched on where a stepper's view of a landscape is made (:func:`make_field`), not
    when a module is imported. float32 landscapes still compute in float32."""
    if not jax.config.jax_enable_x64:  # pyright: ignore[reportAttributeAccessIssue]  (a flag JAX's Config stub does not list)
        jax.config.update("jax_enable_x64", True)


#: Cells of padding on every side of :attr:`Field.padded` (see :func:`pad_energy`): enough
#: for a (4, 4, 4) block around any clipped base index (:func:`block`).
PAD = 4


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["reached", "within", "wet", "twist_span", "lines_pattern"],
    meta_fields=[],
)
@dataclass(frozen=True)
class Relay:
    """The liquid's footprint relay a stepper reads (docs/physics.md §3.5): one bit per pad.

    reached, within: (T, Ny, Nx, W) uint8, the pads reached by the liquid's foot and the
        pads within the reach of the chip's wall at each node, bit ``k % 8`` of byte
        ``k // 8`` for pad ``k`` (:func:`simulator.motion.footprint_relay`).
    wet: (W,) uint8, the state the run is on (the landscape it steps on is that state's);
        a NumPy array works as well (the run moves it to the device).

    twist_span: (2,) int32, the first and last twist index a run may stand on, or None (any):
        on planes made over a window of the twist axis, the twists whose steppers read only
        the window's planes (:func:`simulator.motion.twist_window`).

    lines_pattern: the field's pinning lines' pattern with the dry pads' values zeroed
        (:func:`wet_pattern`), made by :meth:`Field._replace` as the relay is set unless
        given (a caller that sets one state's relay on many fields makes it once); a run's
        pinning then reads one array per line, not the pattern and its labels. None
        without lines, or where a relay is set other than by ``_replace``: the labels are
        read at each pose.

    A run on a field with a relay stops (status EVENT) at the first pose whose node would
    change the state: ``reached | (wet & within) != wet`` (:func:`relay_changes`), or whose
    twist index lies outside ``twist_span`` (the caller runs it again on a wider window).
    """

    reached: jax.Array
    within: jax.Array
    wet: jax.Array | np.ndarray
    twist_span: jax.Array | np.ndarray | None = None
    lines_pattern: jax.Array | None = None


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["padded", "floor", "best", "scale", "relay", "pin", "align_lim", "lines"],
    meta_fields=["pinned", "wide_tol"],
)
@dataclass(frozen=True)
class Field:
    """The landscape arrays a stepper reads, and the rules that end a run on them.

    padded: (T + 2 PAD, Ny + 2 PAD, Nx + 2 PAD) joules, ``[twist, y, x]``: the landscape
        with what lies beyond each side written in (:func:`pad_energy`), so a look-up is
        one gather with no bounds logic. Node (it, iy, ix) is ``padded[it + PAD, iy +
        PAD, ix + PAD]``.
    floor: noise floor (J): differences at or below it are ties.
    best: (3,) grid indices (it, iy, ix) of the global minimum.
    scale: max |E| over the landscape (J), the energy scale of force references.
    relay: the footprint state's :class:`Relay` (``--dispense``), or None: a run then never
        stops for an event (None is part of the pytree's structure: jit compiles the test
        in or out).
    pin: (3,) float64, contact-angle hysteresis, the pinning work over one grid step along
        (twist, y, x) in J (:mod:`simulator.physics`); zeros = none, today's stopping
        rules exactly.
    align_lim: (2,) float64, the (twist steps, px) within which a final pose counts as
        aligned (the align tolerance), plus 1e-6 index units of round-off.
    lines: the outline's elements and the pattern the per-pose pinning reads
        (:class:`simulator.motion.PinLines`, :func:`simulator.motion.pin_at`), or None: the
        constant ``pin`` (a field made by hand). The runs of a scene with hysteresis carry
        them (docs/physics.md §5.3).
    pinned: any pinning at all (static: jit compiles the rule in or out).
    wide_tol: an align tolerance wider than one step, a floor or a hysteresis window
        (static: jit compiles the rule that a run ending there is aligned in or out).

    The pinning values and the tolerance are traced, not static: scenes that differ only
    in their hysteresis window, their liquid height or the floor a chip floats on share
    one compiled stepper (a compile takes seconds; a calibration or a sweep runs many).
    Build a Field with :func:`make_field`, change one with :meth:`_replace` (which takes
    ``pin=`` and ``align_tol=`` as tuples and keeps the static flags in step).
    """

    padded: jax.Array
    floor: jax.Array
    best: jax.Array
    scale: jax.Array
    relay: Relay | None = None
    pin: jax.Array = None  # type: ignore[assignment]  (set by make_field)
    align_lim: jax.Array = None  # type: ignore[assignment]
    lines: PinLines | None = None
    pinned: bool = False
    wide_tol: bool = False

    @property
    def dtype(self) -> np.dtype:
        return self.padded.dtype

    @property
    def align_tol(self) -> tuple[float, float]:
        """The align tolerance (twist steps, px), host-side."""
        lim = np.asarray(self.align_lim, np.float64)
        return (float(lim[0]) - 1e-6, float(lim[1]) - 1e-6)

    def _replace(self, **changes: Any) -> Field:
        """A copy with some fields changed (as a NamedTuple's ``_replace``); ``pin`` and
        ``align_tol`` are given as tuples (:func:`pinning_fields`)."""
        pin = changes.pop("pin", None)
        tol = changes.pop("align_tol", None)
        if pin is not None or tol is not None:
            now_pin = tuple(np.asarray(self.pin, np.float64)) if pin is None else pin
            changes.update(pinning_fields(now_pin, self.align_tol if tol is None else tol))
        if "lines" in changes or "pinned" in changes:
            lines = changes.get("lines", self.lines)
            changes["pinned"] = lines is not None or bool(
                changes["pinned"]
                if "pinned" in changes
                else np.any(np.asarray(self.pin, np.float64))
            )
        relay = changes.get("relay", self.relay)
        lines = changes.get("lines", self.lines)
        if (
            relay is not None
            and lines is not None
            and ("lines" in changes or ("relay" in changes and relay.lines_pattern is None))
        ):
            changes["relay"] = replace(
                relay, lines_pattern=wet_pattern_jit(lines.pattern, lines.labels, relay.wet)
            )
        return replace(self, **changes)


def wet_pattern(pattern: ArrayLike, labels: ArrayLike, wet: ArrayLike) -> jax.Array:
    """The pinning lines' ``pattern`` values with those of the pads that are dry in ``wet``
    zeroed (``labels``: the pads' labels 1..n on the same pixels, 0 the substrate; ``wet``:
    the relay's (W,) uint8 bits, pad ``k`` in bit ``k % 8`` of byte ``k // 8``), element by
    element: the whole pattern (:attr:`Relay.lines_pattern`) or the pixels a pose reads."""
    pattern, labels, wet = jnp.asarray(pattern), jnp.asarray(labels), jnp.asarray(wet)
    k = jnp.maximum(labels - 1, 0)
    bit = (wet[k // 8] >> (k % 8).astype(wet.dtype)) & 1
    return jnp.where((labels > 0) & (bit > 0), pattern, jnp.zeros_like(pattern))


#: :func:`wet_pattern` compiled whole, for the state's pattern made on the host as a relay is
#: set (:meth:`Field._replace`, the path engine's boxes): one program instead of each of its
#: operations compiled on its own the first time (0.86 s against 0.05 s, measured).
wet_pattern_jit = jax.jit(wet_pattern)


def pinning_fields(pin: Sequence[float], align_tol: Sequence[float]) -> dict:
    """The :class:`Field` entries of a pinning work per grid step (J, twist/y/x) and an
    align tolerance (twist steps, px): float64 arrays and the two static flags. The
    tolerance's 1e-6 round-off is added here, in float64, as the rule always did."""
    pin = tuple(float(v) for v in pin)
    tol = (float(align_tol[0]), float(align_tol[1]))
    return {
        "pin": jnp.asarray(np.asarray(pin, np.float64)),
        "align_lim": jnp.asarray(np.asarray([tol[0] + 1e-6, tol[1] + 1e-6], np.float64)),
        "pinned": any(pin),
        "wide_tol": max(tol) > 1.0,
    }


def pad_energy(
    energy: np.ndarray,
    wrap: bool,
    cut: tuple[tuple[bool, bool], ...],
    out: np.ndarray | None = None,
) -> np.ndarray:
    """The landscape with PAD cells on every side holding what lies beyond it: past an
    uncut x/y side 0 (no contact); past a cut side, or the end of a non-periodic twist
    axis, +inf (a wall); a periodic twist axis wraps around. A corner is a wall when
    either of its sides is. Index clipping into the pad (:func:`lookup`) then gives the
    energy anywhere, however far outside.

    ``out``: a :func:`padded_buffer` of the same grid to write into (a run that makes many
    fields of one grid reuses one, and fresh pages cost more than the copy here); when
    ``energy`` is already its :func:`interior`, only the wrapped twists are written."""
    energy = np.asarray(energy)
    if out is None:
        out = padded_buffer(energy.shape, energy.dtype, wrap, cut)
    inner = interior(out)
    if not np.shares_memory(inner, energy):
        inner[...] = energy
    if wrap:  # each side's pad holds the twists at the other end (their x/y pads too)
        t = energy.shape[0]
        out[:PAD] = out[PAD + np.arange(-PAD, 0) % t]
        out[t + PAD :] = out[PAD + np.arange(t, t + PAD) % t]
    return out


def padded_buffer(
    shape: tuple[int, ...], dtype: DTypeLike, wrap: bool, cut: tuple[tuple[bool, bool], ...]
) -> np.ndarray:
    """An array for :func:`pad_energy`'s result on a (T, Ny, Nx) grid: its pads past the x/y
    sides and (on a non-periodic twist axis) past the twist axis's ends written, its
    :func:`interior` left to fill."""
    t, ny, nx = shape
    out = _aligned_empty((t + 2 * PAD, ny + 2 * PAD, nx + 2 * PAD), dtype)
    (_, _), (y_lo, y_hi), (x_lo, x_hi) = cut
    sides = (np.s_[:, :PAD, :], np.s_[:, -PAD:, :], np.s_[:, :, :PAD], np.s_[:, :, -PAD:])
    for side in sides:
        out[side] = 0
    for side, wall in zip(sides, (y_lo, y_hi, x_lo, x_hi), strict=True):
        if wall:  # the whole side, its corners too: a corner is a wall when either side is
            out[side] = np.inf
    if not wrap:
        out[:PAD] = np.inf
        out[-PAD:] = np.inf
    return out


#: Bytes the data of a :func:`padded_buffer` are aligned to: JAX on the CPU takes an array
#: so aligned as it is (``jax.device_put``, no copy) and copies one that is not, as NumPy's
#: own large arrays are not (16 bytes past a page's start). Measured on a (70, 515, 515)
#: float32 array, 74 MB: 3.6 ms aligned, 40-124 ms copied (40-72 ms of it the kernel's,
#: fresh pages), once per field (a batch makes one per footprint state).
ALIGN_BYTES = 64


def _aligned_empty(shape: tuple[int, ...], dtype: DTypeLike) -> np.ndarray:
    """An uninitialised C-contiguous array whose data start on :data:`ALIGN_BYTES`."""
    dt = np.dtype(dtype)
    n = int(np.prod(shape)) * dt.itemsize
    raw = np.empty(n + ALIGN_BYTES, np.uint8)
    start = -raw.ctypes.data % ALIGN_BYTES
    return raw[start : start + n].view(dt).reshape(shape)


def interior(padded: np.ndarray) -> np.ndarray:
    """The view of a :func:`padded_buffer` that holds the grid's own (T, Ny, Nx) energies."""
    return padded[PAD:-PAD, PAD:-PAD, PAD:-PAD]


def make_field(
    energy: ArrayLike,
    grid: PoseGrid,
    floor: ArrayLike,
    best: ArrayLike | Sequence[int],
    pin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    align_tol: tuple[float, float] = (1.0, 1.0),
    scale: float | None = None,
    lines: PinLines | None = None,
    padded: np.ndarray | None = None,
) -> Field:
    """A :class:`Field` from a (T, Ny, Nx) energy array (J) on ``grid``; ``scale``: its
    max |E| (default: the array's own; a box of a larger landscape passes the landscape's);
    ``lines``: the per-pose pinning's :class:`simulator.motion.PinLines` (or None);
    ``padded``: a :func:`padded_buffer` of the grid to pad ``energy`` in (:func:`pad_energy`),
    ``energy`` its :func:`interior` or not."""
    enable_float64()
    energy = np.asarray(energy)
    dt = energy.dtype
    if scale is None:
        scale = np.abs(energy).max() if energy.size else 0.0
    fields = pinning_fields(pin, align_tol)
    fields["pinned"] = fields["pinned"] or lines is not None
    if lines is not None:  # the grid's origin as data (PinLines.origin)
        lines = replace(
            lines,
            origin=jnp.asarray([grid.t0_deg, grid.y0_um, grid.x0_um], lines.origin.dtype),
        )
    return Field(
        # the padded array as it is, not a copy (ALIGN_BYTES): a batch writes the next
        # state's energies into it once this field's lanes have ended
        padded=jax.device_put(pad_energy(energy, grid.wrap, grid.cut, out=padded)),
        floor=jnp.asarray(floor, dt),
        best=jnp.asarray(best, dt),
        scale=jnp.asarray(scale, dt),
        lines=lines,
        **fields,
    )


def field_and_grid(
    ls: Landscape,
    rg_px: float | None = None,
    dtype: DTypeLike | None = None,
    pin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    align_tol: tuple[float, float] = (1.0, 1.0),
    scale: float | None = None,
    lines: PinLines | None = None,
) -> tuple[Field, PoseGrid]:
    """The stepper view of a landscape: its arrays and its pose grid. ``rg_px``: a radius of
    gyration in px other than the grid's own (a landscape's grid carries its scene's,
    :attr:`simulator.scene.Scene.chip_rg_px`); ``pin``: the pinning work per grid step (J,
    twist/y/x) of contact-angle hysteresis; ``scale``: the max |E| the force references
    use (:func:`make_field`; a small box passes its landscape's, so that a gradient run
    takes the steps it takes on the whole landscape); ``lines``: the per-pose pinning
    (:func:`simulator.motion.pin_lines`), which replaces ``pin`` in the steppers."""
    e = ls.energy if dtype is None else ls.energy.astype(dtype)
    it, iy, ix = (
        ls.minimum_index()
    )  # the global minimum: ties decided by position (Landscape.minimum_index)
    grid = ls.grid if rg_px is None else replace(ls.grid, rg_px=float(rg_px))
    return make_field(e, grid, ls.noise_floor_J, [it, iy, ix], pin, align_tol, scale, lines), grid


def relay_changes(field: Field, grid: PoseGrid, q: ArrayLike) -> jax.Array:
    """True where the footprint state would change at fractional indices q (the node
    round(q), the twist wrapped on a periodic axis, every index clipped to the grid):
    some pad reached that is dry, or some wet pad out of reach; or where the node's twist
    index (neither wrapped nor clipped) lies outside the relay's ``twist_span``. False
    without a relay."""
    r = field.relay
    if r is None:
        return jnp.asarray(False)
    n_t, ny, nx = grid.shape
    i = jnp.round(jnp.asarray(q)).astype(jnp.int32)
    it = jnp.mod(i[0], n_t) if grid.wrap else jnp.clip(i[0], 0, n_t - 1)
    iy, ix = jnp.clip(i[1], 0, ny - 1), jnp.clip(i[2], 0, nx - 1)
    new = r.reached[it, iy, ix] | (r.wet & r.within[it, iy, ix])
    changes = jnp.any(new != r.wet)
    if r.twist_span is None:
        return changes
    return changes | (i[0] < r.twist_span[0]) | (i[0] > r.twist_span[1])


# ----------------------------------------------------------------- look-ups
def lookup(field: Field, grid: PoseGrid, it: ArrayLike, iy: ArrayLike, ix: ArrayLike) -> jax.Array:
    """Energy at integer grid indices (broadcasting). Beyond an uncut x/y side: 0 (no
    contact); beyond a cut side or the end of a non-periodic twist axis: +inf (a wall
    the steppers never cross; they stop at a cut side first). One gather from
    :attr:`Field.padded`: indices past the pad are clipped into it, where the value is
    the same."""
    t, ny, nx = grid.shape
    itw = jnp.mod(it, t) if grid.wrap else jnp.clip(it, -PAD, t - 1 + PAD)
    return field.padded[
        itw + PAD, jnp.clip(iy, -PAD, ny - 1 + PAD) + PAD, jnp.clip(ix, -PAD, nx - 1 + PAD) + PAD
    ]


def _cube(field: Field, grid: PoseGrid, b: jax.Array, side: int) -> jax.Array:
    """Energies at ``b + (i, j, k)``, i, j, k in -1 .. side - 2, as a (side, side, side)
    array equal to :func:`lookup`'s values.

    One base index is clipped (far enough inside the pad that the whole cube stays in
    it, whose values equal those farther out), then the cube is read as side**2 rows of
    ``side`` cells of the flattened padded array: under vmap one gather of short slices,
    measured 1.45x faster per greedy step than 27 single look-ups."""
    t, ny, nx = grid.shape
    sy, st = nx + 2 * PAD, (ny + 2 * PAD) * (nx + 2 * PAD)
    itype = jnp.int32 if field.padded.size < 2**31 else jnp.int64
    lo, hi = PAD - 1, PAD - (side - 2)  # the cube reaches 1 cell below b, side - 2 above

    def clip(i: jax.Array, n: int) -> jax.Array:
        return jnp.clip(i, -lo, n - 1 + hi).astype(itype) + PAD

    itw = (jnp.mod(b[0], t).astype(itype) + PAD) if grid.wrap else clip(b[0], t)
    base = itw * st + clip(b[1], ny) * sy + clip(b[2], nx)
    span = range(-1, side - 1)
    rows = jnp.asarray([dt * st + dy * sy - 1 for dt in span for dy in span], itype)
    flat = field.padded.reshape(-1)
    return jax.vmap(lambda r: jax.lax.dynamic_slice(flat, (base + r,), (side,)))(rows).reshape(
        side, side, side
    )


def neighbourhood(field: Field, grid: PoseGrid, idx: jax.Array) -> jax.Array:
    """Energies at the 27 nodes ``idx + BLOCK_MOVES`` (the (3, 3, 3) block around idx,
    ``(dt, dy, dx)`` lexicographic), exactly as :func:`lookup` gives them (:func:`_cube`)."""
    return _cube(field, grid, idx, 3).reshape(27)


def at_cut_edge(grid: PoseGrid, q: jax.Array, margin: float = 0.0) -> jax.Array:
    """True where fractional indices q lie within ``margin`` of a cut side of the grid."""
    out = False
    for k, n in enumerate(grid.shape):
        lo, hi = grid.cut[k]
        if lo:
            out = out | (q[k] <= margin)
        if hi:
            out = out | (q[k] >= n - 1 - margin)
    return jnp.asarray(out)


def clamp_start(grid: PoseGrid, q: jax.Array) -> jax.Array:
    """A start past the end of a bounded (non-periodic) twist axis, e.g. a twist within
    half a step of the range that greedy rounds outward, starts at that end: beyond it
    lies a wall (+inf), which no energy output may show."""
    if grid.wrap:
        return q
    return q.at[0].set(jnp.clip(q[0], 0, grid.shape[0] - 1))


def _trilinear(
    f: jax.Array, corner_energy: Callable[[tuple[int, ...]], jax.Array], dtype: DTypeLike
) -> jax.Array:
    """Sum over the 8 cell corners of weight * ``corner_energy(corner)`` for fractions
    f (..., 3); a corner of weight 0 adds 0 even at a wall (0 * inf)."""
    total = jnp.zeros(f.shape[:-1], dtype)
    for corner in itertools.product((0, 1), repeat=3):
        w = jnp.ones(f.shape[:-1], dtype)
        for k, c in enumerate(corner):
            w = w * (f[..., k] if c else 1 - f[..., k])
        total = total + jnp.where(w > 0, w * corner_energy(corner), 0.0)
    return total


def interpolate(field: Field, grid: PoseGrid, q: ArrayLike) -> jax.Array:
    """Energy at fractional indices q = (it, iy, ix) by trilinear interpolation."""
    q = jnp.asarray(q, field.dtype)
    base = jnp.floor(q)
    b = base.astype(jnp.int32)
    return _trilinear(
        q - base,
        lambda c: lookup(field, grid, b[..., 0] + c[0], b[..., 1] + c[1], b[..., 2] + c[2]),
        field.dtype,
    )


def block(field: Field, grid: PoseGrid, b: jax.Array) -> jax.Array:
    """Energies at ``b + (i, j, k)``, i, j, k in -1..2: the (4, 4, 4) block that holds
    every corner of the trilinear interpolations at q and q +- one step along any axis,
    for b = floor(q) (:func:`_cube`)."""
    return _cube(field, grid, b, 4)


def gradient(field: Field, grid: PoseGrid, q: ArrayLike) -> jax.Array:
    """dE/dq (J per index unit) by central differences of one grid step; differences
    at or below the noise floor are 0, so plateaus are exactly flat. Next to a wall (the
    end of a bounded twist axis, a cut side) the one-sided difference away from the wall
    is used, so a chip at the end of its twist range still feels the torque back into
    the range.

    The seven trilinear interpolations (at q and q +- one step along each axis) read
    one (4, 4, 4) :func:`block` and share q's position within its cell."""
    dt = field.dtype
    q = jnp.asarray(q, dt)
    base = jnp.floor(q)
    f = q - base
    blk = block(field, grid, base.astype(jnp.int32))

    def interp(o: tuple[int, ...]) -> jax.Array:  # :func:`interpolate` at q + o, from the block
        return _trilinear(f, lambda c: blk[1 + o[0] + c[0], 1 + o[1] + c[1], 1 + o[2] + c[2]], dt)

    e0 = interp((0, 0, 0))
    out = []
    for k in range(3):
        step = [0, 0, 0]
        step[k] = 1
        ep = interp(tuple(step))
        step[k] = -1
        em = interp(tuple(step))
        fp, fm = jnp.isfinite(ep), jnp.isfinite(em)
        central = jnp.where(fp & fm, ep - em, 0.0) / 2
        one_sided = jnp.where(
            fm, e0 - jnp.where(fm, em, 0.0), jnp.where(fp, jnp.where(fp, ep, 0.0) - e0, 0.0)
        )
        de = jnp.where(fp & fm, central, jnp.where(jnp.isfinite(e0), one_sided, 0.0))
        # the floor applies to the energy difference actually taken (two steps or one)
        span = jnp.where(fp & fm, 2.0, 1.0)
        out.append(jnp.where(jnp.abs(de) * span <= field.floor, 0.0, de))
    if grid.shape[0] == 1:
        out[0] = jnp.zeros_like(out[0])
    return jnp.stack(out)
