"""Look-ups on the padded landscape give, everywhere, the energy the boundary rules define."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from simulator.landscape import PoseGrid
from simulator.motion import (
    BLOCK_MOVES,
    GREEDY_MOVES,
    PAD,
    STAY,
    TIE_RANK,
    block,
    gradient,
    interior,
    interpolate,
    lookup,
    make_field,
    neighbourhood,
    on_plateau,
    padded_buffer,
)
from simulator.motion._field import ALIGN_BYTES

T, NY, NX = 4, 5, 6


def reference(e: np.ndarray, wrap: bool, cut, it, iy, ix) -> float:
    """The boundary rules written out (stepping.lookup's docstring): beyond an uncut x/y
    side 0; beyond a cut side or a non-periodic twist end +inf; twist wraps if periodic."""
    (_, _), (y_lo, y_hi), (x_lo, x_hi) = cut
    wall = (y_lo and iy < 0) or (y_hi and iy >= NY) or (x_lo and ix < 0) or (x_hi and ix >= NX)
    if wrap:
        it = it % T
    elif not 0 <= it < T:
        wall = True
    if wall:
        return np.inf
    if not (0 <= iy < NY and 0 <= ix < NX):
        return 0.0
    return float(e[it, iy, ix])


def grid_for(wrap: bool, cut) -> PoseGrid:
    return PoseGrid.uniform(
        (T, NY, NX),
        wrap=wrap,
        cut=cut,
        um_per_px=1.0,
        twist_step_deg=1.0,
        period_deg=90.0,
        rg_px=3.0,
    )


CASES = [
    (wrap, ((False, False), (ylo, yhi), (xlo, xhi)))
    for wrap in (True, False)
    for ylo, yhi, xlo, xhi in [
        (False, False, False, False),
        (True, True, True, True),
        (True, False, False, True),
        (False, True, True, False),
    ]
]


@pytest.mark.parametrize("wrap, cut", CASES)
def test_lookup_and_neighbourhood_follow_the_boundary_rules_far_outside(wrap, cut):
    rng = np.random.default_rng(1)
    e = -rng.uniform(1, 2, (T, NY, NX)).astype(np.float32)
    grid = grid_for(wrap, cut)
    field = make_field(e, grid, 1e-9, [0, 0, 0])
    assert field.padded.shape == (T + 2 * PAD, NY + 2 * PAD, NX + 2 * PAD)
    # every node from 9 cells outside to 9 cells past the far side, on every axis
    pts = np.array(
        list(itertools.product(range(-9, T + 9), range(-9, NY + 9), range(-9, NX + 9))), np.int32
    )
    got = np.asarray(
        lookup(field, grid, jnp.asarray(pts[:, 0]), jnp.asarray(pts[:, 1]), jnp.asarray(pts[:, 2]))
    )
    want = np.array([reference(e, wrap, cut, *p) for p in pts], np.float32)
    np.testing.assert_array_equal(got, want)
    # the (3, 3, 3) and (4, 4, 4) blocks read from one clipped base index hold the look-ups
    sample = pts[::7]
    nb = np.asarray(
        jax.jit(jax.vmap(neighbourhood, (None, None, 0)), static_argnums=1)(
            field, grid, jnp.asarray(sample)
        )
    )
    want = [[reference(e, wrap, cut, *(p + m)) for m in BLOCK_MOVES] for p in sample]
    np.testing.assert_array_equal(nb, np.array(want, np.float32))
    blk = np.asarray(
        jax.jit(jax.vmap(block, (None, None, 0)), static_argnums=1)(
            field, grid, jnp.asarray(sample)
        )
    )
    offsets = list(itertools.product(range(-1, 3), repeat=3))
    want = [[reference(e, wrap, cut, *(p + np.array(o))) for o in offsets] for p in sample]
    np.testing.assert_array_equal(blk.reshape(len(sample), 64), np.array(want, np.float32))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_field_holds_its_padded_buffer_without_a_copy(dtype):
    # simulator.motion._field.ALIGN_BYTES: a padded buffer's data start on 64 bytes, which
    # JAX on the CPU takes as they are (a copy of a batch's field cost 40-124 ms a state):
    # the field's array is the buffer, and a state written into it is what the field reads
    grid = PoseGrid.uniform((3, NY, NX), um_per_px=1.0, twist_step_deg=1.0, rg_px=3.0)
    buf = padded_buffer(grid.shape, dtype, grid.wrap, grid.cut)
    assert buf.ctypes.data % ALIGN_BYTES == 0 and buf.flags.c_contiguous
    interior(buf)[...] = -1.0
    field = make_field(interior(buf), grid, 1e-9, [0, 0, 0], padded=buf)
    assert field.padded.dtype == dtype
    np.testing.assert_array_equal(np.asarray(field.padded), buf)
    if jax.default_backend() == "cpu":  # on a GPU the field is the buffer's copy on the device
        assert field.padded.unsafe_buffer_pointer() == buf.ctypes.data
        interior(buf)[1, 2, 3] = -7.0
        assert float(lookup(field, grid, 1, 2, 3)) == -7.0


@pytest.mark.parametrize("wrap, cut", CASES)
@pytest.mark.parametrize("n_t", [1, 2, PAD, 9])
def test_a_padded_buffer_used_again_gives_the_field_of_its_new_landscape(wrap, cut, n_t):
    # A batch's states, one after another in one padded array (the energy summed into its
    # interior): the field of each is the one made from scratch, whatever the array held,
    # on periodic twist axes shorter than the pad too (the pad then wraps more than once).
    rng = np.random.default_rng(2)
    shape = (n_t, NY, NX)
    grid = PoseGrid.uniform(
        shape,
        wrap=wrap,
        cut=cut,
        um_per_px=1.0,
        twist_step_deg=90.0 / n_t,
        period_deg=90.0,
        rg_px=3.0,
    )
    buf = padded_buffer(shape, np.float32, wrap, cut)
    for _ in range(2):
        e = -rng.uniform(1, 2, shape).astype(np.float32)
        fresh = np.asarray(make_field(e, grid, 1e-9, [0, 0, 0]).padded)
        interior(buf)[...] = e
        reused = np.asarray(make_field(interior(buf), grid, 1e-9, [0, 0, 0], padded=buf).padded)
        np.testing.assert_array_equal(reused, fresh)
        # the pads written out: np.pad's rules (uncut 0, cut +inf, twist wrapped or +inf)
        want = np.pad(e, ((0, 0), (PAD, PAD), (PAD, PAD)))
        (_, _), (y_lo, y_hi), (x_lo, x_hi) = cut
        for side, wall in zip(
            (np.s_[:, :PAD], np.s_[:, -PAD:], np.s_[:, :, :PAD], np.s_[:, :, -PAD:]),
            (y_lo, y_hi, x_lo, x_hi),
            strict=True,
        ):
            if wall:
                want[side] = np.inf
        twist_pad = ((PAD, PAD), (0, 0), (0, 0))
        want = (
            np.pad(want, twist_pad, mode="wrap")
            if wrap
            else np.pad(want, twist_pad, constant_values=np.inf)
        )
        np.testing.assert_array_equal(fresh, want)
        # what the states before left: their energies and, on a periodic axis, their wrapped
        # twists (nothing of them may show through)
        interior(buf)[...] = np.nan
        if wrap:
            buf[:PAD] = buf[-PAD:] = np.nan


def test_on_plateau_sees_a_flat_direction_and_not_a_strict_minimum():
    e = np.zeros((T, NY, NX), np.float32)
    e[:, 2, :] = -1.0  # a valley along x: flat in x, rising in y
    grid = grid_for(True, ((False, False), (True, True), (True, True)))
    field = make_field(e, grid, 1e-6, [0, 2, 0])
    assert bool(on_plateau(field, grid, jnp.asarray([1, 2, 3])))
    e2 = e.copy()
    e2[1, 2, 3] = -2.0  # a strict minimum
    field2 = make_field(e2, grid, 1e-6, [1, 2, 3])
    assert not bool(on_plateau(field2, grid, jnp.asarray([1, 2, 3])))


def test_block_layout_and_tie_ranks_describe_the_same_moves():
    assert sorted(map(tuple, BLOCK_MOVES)) == list(map(tuple, BLOCK_MOVES))  # lexicographic
    assert tuple(BLOCK_MOVES[STAY]) == (0, 0, 0) and TIE_RANK[STAY] == 0
    np.testing.assert_array_equal(GREEDY_MOVES[TIE_RANK], BLOCK_MOVES)
    assert sorted(TIE_RANK.tolist()) == list(range(27))


def gradient_from_interpolate(field, grid, q):
    """The central differences of stepping.gradient written with seven separate
    :func:`interpolate` calls (each stencil point's own cell and fraction)."""
    e0 = interpolate(field, grid, q)
    out = []
    for k in range(3):
        d = jnp.zeros(3, q.dtype).at[k].set(1.0)
        ep, em = interpolate(field, grid, q + d), interpolate(field, grid, q - d)
        fp, fm = jnp.isfinite(ep), jnp.isfinite(em)
        de = jnp.where(fp & fm, (ep - em) / 2, jnp.where(fm, e0 - em, jnp.where(fp, ep - e0, 0.0)))
        out.append(jnp.where(jnp.isfinite(e0) | (fp & fm), de, 0.0))
    return jnp.stack(out)


@pytest.mark.parametrize("wrap, cut", CASES)
def test_gradient_from_one_block_equals_seven_interpolations(wrap, cut):
    rng = np.random.default_rng(2)
    e = -rng.uniform(1, 2, (T, NY, NX))
    grid = grid_for(wrap, cut)
    field = make_field(e, grid, 1e-12, [0, 0, 0])
    # inside, across every side, and far outside
    qs = np.concatenate(
        [
            rng.uniform(-1.5, 1.5, (60, 3)) + np.array([T, NY, NX]) * rng.uniform(0, 1, (60, 3)),
            rng.uniform(-12, 14, (60, 3)),
        ]
    )
    qs = np.concatenate([qs, np.floor(qs[:20])])  # on nodes: fractions exactly 0
    batch = [
        jax.jit(jax.vmap(g, (None, None, 0)), static_argnums=1)
        for g in (gradient, gradient_from_interpolate)
    ]
    got, want = (np.asarray(b(field, grid, jnp.asarray(qs))) for b in batch)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
