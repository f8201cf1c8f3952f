"""Free-form design by gradients: the optimisation loop, the written pattern, the check.

:func:`freeform` runs optax's Adam on the design variables of
:mod:`simulator.design` (the density, its minimum-feature filter, the projection with its
sharpness raised over the iterations), the objective's gradient taken through the JAX
landscape (:func:`simulator.design.overlap_planes`) in one jit-compiled step; the edge
perturbations are fresh seeded fields each iteration (``jax.random.fold_in`` of the seed
and the iteration), so the seed fixes the result. The last projected density is made
binary at 0.5, opened and closed by a disk of the minimum feature (what that removed and
added is recorded), its keep-in set and keep-out cleared; that is the pattern written and
checked by the evaluator (:func:`simulator.batch.assess`) against the spec's baseline.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from patterns.geometry import Mask

if TYPE_CHECKING:
    from simulator.design._freeform._density import DensityMap
    from simulator.design._freeform._energy import ChipSide
    from simulator.design._freeform._objectives import Objective
    from simulator.design._freeform._spec import FreeformSpec

__all__ = [
    "FreeformResult",
    "Problem",
    "clean_pattern",
    "freeform",
    "make_problem",
    "orientation_gaps",
]


@dataclass(frozen=True, eq=False)
class Problem:
    """A spec made ready for JAX: the parametrisation, the chip side and the objective, and
    the jit-compiled functions of the design variables (:func:`make_problem`)."""

    spec: FreeformSpec
    density: DensityMap
    side: ChipSide
    objective: Objective
    dtype: str

    def arrays(self) -> dict:
        d = self.density.arrays(self.dtype)
        d["spectra"] = self.side.spectra(self.dtype)
        return d

    def evaluate(self, w: np.ndarray) -> tuple[float, dict]:
        """(objective, {term: physical value}) of a pattern ``w`` (H, W), without
        perturbations: the objective as optimised (soft minima), the terms also as plain
        minima (``..._min`` keys: the worst pose itself)."""
        import jax
        import jax.numpy as jnp

        obj = self.objective

        @jax.jit
        def both(w, spectra):
            planes = _planes(self, w, spectra)
            return obj.terms(planes, w), obj.terms(planes, w, hard=True)

        soft, hard = both(jnp.asarray(w, self.dtype), self.side.spectra(self.dtype))
        terms = obj.physical(soft)
        for k, v in obj.physical(hard).items():
            if k in ("capture_N", "gap_J", "orientation_J"):
                terms[k.replace("_", "_min_", 1)] = v
        return float(obj.total(soft)), terms


def _planes(problem: Problem, w, spectra):
    from simulator.design._freeform._energy import overlap_planes

    return overlap_planes(w, spectra, problem.side.index(), problem.side.fft)


def make_problem(spec) -> Problem:
    """The problem of a :class:`simulator.design.FreeformSpec` (the chip's rasters made)."""
    from simulator.design._freeform._density import density_map
    from simulator.design._freeform._energy import chip_side, enable_float64
    from simulator.design._freeform._objectives import make_objective

    enable_float64(spec.scene.dtype)  # a float64 scene stays float64
    s = spec.um_per_px
    p = spec.perturbation
    dmap = density_map(
        spec.keep_in,
        spec.keep_out,
        spec.min_feature_px,
        p["length_um"] / s / 2 if p["samples"] > 0 else 0.0,
    )
    side = chip_side(spec.scene, spec.shape, spec.twists_deg())
    obj = make_objective(spec.terms, side, spec.scene)
    return Problem(spec, dmap, side, obj, spec.scene.dtype)


def _loss_fn(problem: Problem):
    """loss(z, beta, key, arrays) -> (-objective averaged over the perturbations, terms)."""
    import jax
    import jax.numpy as jnp

    from simulator.design._freeform._density import noise_field, pattern_of

    dm, obj = problem.density, problem.objective
    shape, fft = dm.shape, dm.fft
    samples = problem.spec.perturbation["samples"]
    amp = problem.spec.perturbation["edge_um"] / problem.spec.um_per_px * dm.edge_slope_per_px

    def one(z, beta, arrays, shift):
        w = pattern_of(z, beta, arrays, shape, fft, shift)
        planes = _planes(problem, w, arrays["spectra"])
        t = obj.terms(planes, w)
        return obj.total(t), t

    def loss(z, beta, key, arrays):
        if samples == 0:
            total, t = one(z, beta, arrays, None)
            return -total, t
        keys = jax.random.split(key, samples)
        vals, ts = [], []
        for k in range(samples):  # a Python loop: samples is small and static
            shift = amp * noise_field(keys[k], arrays, shape, fft, dm.noise_scale)
            v, t = one(z, beta, arrays, shift)
            vals.append(v)
            ts.append(t)
        mean = {name: jnp.mean(jnp.stack([t[name] for t in ts])) for name in ts[0]}
        return -jnp.mean(jnp.stack(vals)), mean

    return loss


def betas(spec, n: int) -> np.ndarray:
    """The projection's sharpness at each of ``n`` iterations: geometric from the first to the last."""
    b0, b1 = spec.beta
    if n == 1:
        return np.array([b1])
    return b0 * (b1 / b0) ** (np.arange(n) / (n - 1))


@dataclass(frozen=True, eq=False)
class FreeformResult:
    """What :func:`freeform` found and measured.

    pattern: the written pattern (binary, at the scene's scale; its keep-in wettable and its
    keep-out dry). density: the last projected density (H, W) before it was made binary.
    history: per iteration ``iteration``, ``beta``, ``objective`` and each term in physical
    units (``capture_N``, ``gap_J``, ...), as averaged over that iteration's perturbations.
    cleanup: the pixels (and um^2) the opening removed and the closing added.
    before, after: (objective, terms) of the baseline and of the written pattern, without
    perturbations. verification: the evaluator's summaries of both and the orientation
    gaps of their landscapes (None when not verified). seconds_per_iteration: the mean time of
    a gradient iteration after the first (which compiles). layout: the GDSII file's check
    (None when nothing was written).
    """

    spec: object
    pattern: Mask
    density: np.ndarray
    history: dict
    cleanup: dict
    before: tuple
    after: tuple
    verification: dict | None
    seconds_per_iteration: float
    compile_seconds: float
    layout: dict | None = None
    files: list = field(default_factory=list)


def _disk(d_px: float) -> np.ndarray:
    r = d_px / 2
    n = int(math.floor(r))
    y, x = np.mgrid[-n : n + 1, -n : n + 1]
    return (x * x + y * y) <= r * r + 1e-9


def clean_pattern(
    w: np.ndarray, keep_in: np.ndarray, keep_out: np.ndarray, min_feature_px: float
) -> tuple[np.ndarray, dict]:
    """The binary pattern of a density ``w`` (>= 0.5), opened and closed by a disk of
    diameter ``min_feature_px`` (wettable parts narrower, and dry gaps narrower, removed),
    keep-in set and keep-out cleared (repeated until nothing changes, at most 4 times); with
    the pixels the opening removed and the closing added, against the thresholded density."""
    from scipy import ndimage

    disk = _disk(min_feature_px)
    p = disk.shape[0]
    raw = (w >= 0.5) | keep_in
    b = raw & ~keep_out
    for _ in range(4):
        padded = np.pad(b, p)
        opened = ndimage.binary_opening(padded, disk)
        closed = ndimage.binary_closing(opened, disk)[p:-p, p:-p]
        nb = (closed | keep_in) & ~keep_out
        if np.array_equal(nb, b):
            break
        b = nb
    removed = raw & ~b
    added = b & ~raw
    return b, {"removed_px": int(removed.sum()), "added_px": int(added.sum())}


def freeform(
    spec, out=None, *, iterations: int | None = None, quiet: bool = True, verify: bool = True
) -> FreeformResult:
    """Optimise the free-form pattern of ``spec`` (a :class:`simulator.design.FreeformSpec`,
    a design file or its dict) and check it against the baseline.

    Args:
        spec: what to design (:func:`simulator.design.load_freeform`).
        out: a results directory to write (``pattern.png``, ``pattern_mask.png``,
            ``pattern.gds``, ``history.csv``, ``history.png``, ``capture_before_after.png``,
            ``before/`` and ``after/`` (the evaluator's pictures), ``result.json``,
            ``report.html``), atomically; None writes nothing. It must be new, empty or a
            previous free-form output (replaced).
        iterations: overrides the spec's.
        quiet: no progress bar.
        verify: assess both patterns with the evaluator (the slow part).
    """
    from simulator.design._freeform._spec import FreeformSpec, load_freeform

    if not isinstance(spec, FreeformSpec):
        spec = load_freeform(spec)
    spec = spec.with_iterations(iterations)
    if out is None:
        return _run(spec, None, quiet, verify)
    from simulator.design._freeform._report import check_out, output_context, write_outputs

    check_out(out, spec)  # before any work
    with output_context(out, spec) as tmp:
        result = _run(spec, tmp, quiet, verify)
        result = write_outputs(result, tmp, quiet=quiet)
    return result


def _run(spec, pictures: Path | None, quiet: bool, verify: bool) -> FreeformResult:
    """The optimisation, the written pattern and (``verify``) its check; the evaluator's
    pictures into ``pictures``/before and /after when given."""
    import jax
    import optax

    from foundation import wait_line
    from simulator.design._freeform._spec import SETUP_S_PER_PX

    h, w = spec.shape
    wait_line(
        f"preparing the free-form design's {w} x {h} px canvas and the chip at "
        f"{len(spec.twists_deg())} twist{'s' if len(spec.twists_deg()) != 1 else ''}",
        SETUP_S_PER_PX * h * w * (1 + len(spec.twists_deg())) / 2,
    )
    problem = make_problem(spec)
    arrays = problem.arrays()
    loss = _loss_fn(problem)
    opt = optax.adam(spec.learning_rate)
    free_init = math.log(spec.init / (1 - spec.init))
    z = jax.numpy.full((h, w), free_init, dtype=problem.dtype)
    state = opt.init(z)

    @jax.jit
    def step(z, state, beta, key, arrays):
        (val, terms), grad = jax.value_and_grad(loss, has_aux=True)(z, beta, key, arrays)
        updates, state = opt.update(grad, state, z)
        return optax.apply_updates(z, updates), state, val, terms

    n = spec.iterations
    bs = betas(spec, n)
    root = jax.random.PRNGKey(spec.seed)
    hist: dict[str, list] = {"iteration": [], "beta": [], "objective": []}
    from foundation import progress_bar

    t_first = t0 = time.perf_counter()
    with progress_bar(not quiet, n, "free-form design", "it") as bar:
        for i in range(n):
            beta = jax.numpy.asarray(bs[i], problem.dtype)
            z, state, val, terms = step(z, state, beta, jax.random.fold_in(root, i), arrays)
            val = float(val)  # waits for the step
            if i == 0:
                t_first = time.perf_counter()
            hist["iteration"].append(i)
            hist["beta"].append(float(bs[i]))
            hist["objective"].append(-val)
            for k, v in problem.objective.physical(terms).items():
                hist.setdefault(k, []).append(v)
            bar.update(1)
            bar.set_postfix_str(f"objective {-val:.4g}, beta {bs[i]:.3g}", refresh=False)
    t_end = time.perf_counter()
    per_it = (t_end - t_first) / (n - 1) if n > 1 else t_end - t0
    from simulator.design._freeform._density import pattern_of

    dm = problem.density
    wait_line(
        "making the pattern binary and evaluating it and the baseline without perturbations",
        SETUP_S_PER_PX * h * w * (1 + len(spec.twists_deg())),
    )
    final = jax.jit(lambda z, b, a: pattern_of(z, b, a, dm.shape, dm.fft))
    density = np.asarray(final(z, bs[-1], arrays), np.float64)
    binary, cleanup = clean_pattern(density, spec.keep_in, spec.keep_out, spec.min_feature_px)
    px2 = spec.um_per_px**2
    cleanup |= {
        "removed_um2": cleanup["removed_px"] * px2,
        "added_um2": cleanup["added_px"] * px2,
        "min_feature_um": spec.min_feature_um,
    }
    pattern = Mask(
        binary.astype(np.float64),
        spec.um_per_px,
        params={"design": "freeform", "source": spec.source, "seed": spec.seed},
    )
    before = problem.evaluate(spec.baseline.data)
    after = problem.evaluate(pattern.data)
    result = FreeformResult(
        spec=spec,
        pattern=pattern,
        density=density,
        history={k: np.asarray(v) for k, v in hist.items()},
        cleanup=cleanup,
        before=before,
        after=after,
        verification=_verify(spec, pattern, quiet, pictures) if verify else None,
        seconds_per_iteration=per_it,
        compile_seconds=t_first - t0 - per_it if n > 1 else 0.0,
    )
    return result


def orientation_gaps(scene, twists_deg) -> dict:
    """The non-differentiable landscape's orientation gaps (J) of ``scene``: for each twist,
    the lowest energy over every translation at it minus the energy at the target (0, 0, 0)
    (:func:`simulator.landscape.build_landscape`, one twist at a time)."""
    from simulator.landscape import build_landscape

    ls0 = build_landscape(scene, twists=np.array([0.0]))
    e_t = float(ls0.energy_at(0.0, 0.0, 0.0))
    out = {}
    for t in twists_deg:
        ls = build_landscape(scene, twists=np.array([float(t)]))
        out[f"{t:g}"] = float(ls.energy.min()) - e_t
    return {"target_energy_J": e_t, "gap_J": out, "min_gap_J": min(out.values()) if out else None}


def _verify(spec, pattern: Mask, quiet: bool, pictures: Path | None = None) -> dict:
    """The evaluator's summary of the baseline and of the optimised pattern (same scene,
    same settings and draws), with their orientation gaps."""
    from simulator.batch import assess

    v = spec.verify
    out = {}
    twists = spec.terms["orientation"]["twists_deg"] if spec.scene.effects.twist else []
    for name, mask, sub in (("baseline", spec.baseline, "before"), ("optimised", pattern, "after")):
        scene = spec.scene.replace(pattern=mask)
        t0 = time.perf_counter()
        pics = None
        if pictures is not None:
            pics = pictures / sub
            pics.mkdir()
        summary = assess(
            scene,
            quiet=quiet,
            method=v["method"],
            seed=v["seed"],
            placement_sigma=v["placement_sigma"],
            yield_starts=v["yield_starts"],
            grid_cells=v["capture_grid"],
            pictures=pics,
        ).to_dict()
        summary["orientation"] = orientation_gaps(scene, twists) if twists else None
        summary["seconds"] = round(time.perf_counter() - t0, 2)
        out[name] = summary
    return out
