"""The ``[freeform]`` design file: what to optimise, checked whole before any JAX work.

A free-form design file has two tables::

    [scene]                      # a scene table without its pattern (the pattern is designed):
    chip = "chip.png"            # chip, materials, liquid, effects, twist, dtype, memory_budget_mb
    [scene.materials]
    pad_angle_deg = 30

    [freeform]
    size_um = [640, 640]         # the design canvas (width, height), centred on the target pose
    um_per_px = 4.0              # its pixel size (the scene is simulated at it)
    min_feature_um = 20          # smallest wettable width and dry gap the pattern may have
    keep_in = { design = "four-pad", size = 400, gap = 160 }   # must stay wettable
    keep_out = "dry.png"         # must stay dry (optional); a PNG of the canvas's size, a
                                 # generated design (offset_um = [x, y] moves it) or a list of them
    iterations = 150             # gradient steps (--trials overrides)
    seed = 0                     # the random edge perturbations' seed
    learning_rate = 0.1          # optax Adam's step on the design variables
    beta = [1.0, 16.0]           # the projection's sharpness, first and last iteration
    init = 0.5                   # initial density of the free pixels

    [freeform.objective]         # each term a weight (>= 0) and its settings
    capture = { weight = 1.0, radius_um = [40, 160] }
    gap = { weight = 1.0, radius_um = 30 }
    orientation = { weight = 1.0, twists_deg = [90, 180, 270] }
    stiffness = { weight = 0.0 }
    depth = { weight = 0.0 }
    area = { weight = 0.0 }

    [freeform.perturbation]      # the expected value under random edge perturbations
    samples = 2
    edge_um = 4.0
    length_um = 24

    [freeform.baseline]          # what the result is checked against (default: keep_in)
    design = "four-pad"          # or pattern = "file.png" (the canvas's size), or keep_in = true
    size = 400
    gap = 160

    [freeform.verify]            # the evaluator's settings for both patterns
    yield_starts = 2000
    capture_grid = 25
    placement_sigma = [40, 40, 2]   # um, um, degrees (default: evaluate's)
    method = "greedy"
    seed = 0

:func:`load_freeform` reads and checks it into a :class:`FreeformSpec` (one
:class:`~foundation.InputError` line per problem, nothing heavy imported).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from foundation import InputError, require, require_regular_file
from patterns import show_value
from patterns.geometry import Mask

__all__ = [
    "FREEFORM_KEYS",
    "TERMS",
    "FreeformSpec",
    "load_freeform",
    "price_freeform",
]

#: Keys of the [freeform] table (its sub-tables are objective, perturbation, baseline, verify).
FREEFORM_KEYS = (
    "size_um",
    "um_per_px",
    "min_feature_um",
    "keep_in",
    "keep_out",
    "iterations",
    "seed",
    "learning_rate",
    "beta",
    "init",
    "objective",
    "perturbation",
    "baseline",
    "verify",
)
#: The objective's terms and the settings each takes besides ``weight``.
TERMS = {
    "capture": ("radius_um", "temperature_N"),
    "gap": ("radius_um", "temperature_J"),
    "orientation": ("twists_deg", "temperature_J"),
    "stiffness": ("step_um",),
    "depth": (),
    "area": (),
}
PERTURBATION_KEYS = ("samples", "edge_um", "length_um")
VERIFY_KEYS = ("yield_starts", "capture_grid", "placement_sigma", "method", "seed")
#: Most iterations a file (or --trials) may ask for.
MAX_ITERATIONS = 100_000
#: Most perturbation samples per iteration.
MAX_SAMPLES = 64
#: The smallest minimum feature, in pixels: a filter narrower than this is no filter.
MIN_FEATURE_PX = 2.0
#: Largest design canvas side (px).
MAX_CANVAS_PX = 8192
#: What a free-form run holds at its peak (:func:`freeform_cost`), float32 (float64 doubles
#: it), fitted to the peak resident memory of runs of the worked example above the process's
#: before them (2048 x 2048 px canvas, 2187 x 2178 px FFT canvases; twists T and perturbation
#: samples S): 887 MB (T 1, S 0), 1,003 MB (T 1, S 2), 1,172 MB (T 4, S 0), 1,448 MB (T 4,
#: S 2); the differences give the per-twist and per-sample terms, the first the canvas term.
#: The priced bytes are 1.0 to 1.2 x the measured peaks from 128 to 2048 px (before, only the
#: twist terms were priced, at 32 + 16 B: 0.25 x the peak with one twist).
#:
#: Bytes per FFT canvas pixel, twist and perturbation sample of one gradient iteration: the
#: product of the pattern's spectrum with each chip's, its inverse and the window, kept for
#: the backward pass, and their cotangents (complex64 half spectra, float32 planes). Fitted:
#: 11.7 B.
FFT_BYTES_PER_PX = 16
#: Bytes per FFT canvas pixel and twist: the chip's spectrum (made in complex128 by numpy,
#: then held in JAX) and the planes' soft and hard minima of the final evaluation. Fitted: 9.2 B.
TWIST_BYTES_PER_PX = 12
#: Bytes per design-canvas pixel and perturbation sample: the white noise, its spectrum and
#: the smoothed field kept for the backward pass. Fitted: 7.9 B.
NOISE_BYTES_PER_PX = 8
#: Bytes per design-canvas pixel whatever the twists and samples: the spec's keep-in,
#: keep-out and baseline rasters and the chip side's probe (float64, 8 B each), the density
#: map's cone and noise spectra and its normalisation made in float64 by numpy (with their
#: temporaries, about 64 B) and held again in JAX (12 B), the design variables with Adam's
#: two moments and their gradient (16 B), the filter's forward and inverse transforms and
#: the projection kept for the backward pass (about 24 B), and the result: the last density
#: (float64), its binary pattern, the written mask (float64) and the opening's padded copies
#: (about 24 B). Fitted: 148 B.
CANVAS_BYTES_PER_PX = 160
#: What XLA's compilation of the gradient step and the first buffers hold whatever the canvas
#: (measured: 220 MB above the process at 128 px, where the arrays are a few MB).
XLA_FIXED_BYTES = 200 * 2**20
#: Seconds per design-canvas pixel to make the problem's arrays (the chip side and the density
#: map, numpy FFTs on one core; 5 s at 2048 x 2048 px), for the waiting line.
SETUP_S_PER_PX = 1.2e-6


@dataclass(frozen=True, eq=False)
class FreeformSpec:
    """A checked free-form design file (:func:`load_freeform`).

    scene: the scene at the design's pixel size, its pattern the baseline (the canvas's
    shape, centred on the target pose). keep_in, keep_out: (H, W) bool in image rows (row 0
    at the top, as :class:`patterns.geometry.Mask`). baseline: the pattern the result is checked
    against. terms: {name: {"weight": w, ...settings}} for every term of :data:`TERMS`
    (weight 0 for those not given). perturbation: samples, edge_um, length_um. verify:
    the evaluator's settings. files: the input files read (never written over).
    """

    source: str
    base_dir: Path
    scene: Any
    keep_in: np.ndarray
    keep_out: np.ndarray
    baseline: Mask
    baseline_label: str
    um_per_px: float
    min_feature_um: float
    iterations: int
    seed: int
    learning_rate: float
    beta: tuple[float, float]
    init: float
    terms: dict
    perturbation: dict
    verify: dict
    files: tuple[str, ...] = ()
    doc: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the design canvas in pixels."""
        return self.keep_in.shape  # type: ignore[return-value]

    @property
    def min_feature_px(self) -> float:
        return self.min_feature_um / self.um_per_px

    def with_iterations(self, n: int | None) -> FreeformSpec:
        """This spec with ``n`` iterations (``--trials``; None keeps the file's)."""
        if n is None:
            return self
        from dataclasses import replace

        return replace(self, iterations=_whole("--trials", n, 1, MAX_ITERATIONS))

    def twists_deg(self) -> tuple[float, ...]:
        """The twists whose planes the objective needs: 0 (the target) first, then the
        orientation term's (when weighted)."""
        o = self.terms["orientation"]
        return (0.0,) + (tuple(o["twists_deg"]) if o["weight"] > 0 else ())


# ----------------------------------------------------------------------- checks
def _number(where: str, v: Any, lo: float, hi: float, unit: str = "") -> float:
    ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
    require(
        ok and lo <= v <= hi,
        f"{where} = {show_value(v)}: must be a number from {lo:g} to {hi:g}{' ' + unit if unit else ''}",
    )
    return float(v)


def _whole(where: str, v: Any, lo: int, hi: int) -> int:
    require(
        isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi,
        f"{where} = {show_value(v)}: must be a whole number from {lo:,} to {hi:,}",
    )
    return int(v)


def _table(where: str, v: Any, keys: tuple[str, ...]) -> dict:
    require(isinstance(v, dict), f"{where} = {show_value(v)}: must be a table")
    bad = [k for k in v if k not in keys]
    require(
        not bad,
        f"{where} {bad[0] if bad else ''}: unknown key; {where} takes {', '.join(keys) or 'no keys'}",
    )
    return dict(v)


def _pair(where: str, v: Any, lo: float, hi: float, unit: str) -> tuple[float, float]:
    require(
        isinstance(v, list) and len(v) == 2,
        f"{where} = {show_value(v)}: must be two numbers [first, second] in {unit}",
    )
    return _number(where, v[0], lo, hi, unit), _number(where, v[1], lo, hi, unit)


# ----------------------------------------------------------------------- masks
def _design_mask(
    where: str, t: dict, shape: tuple[int, int], s: float, budget: float | None
) -> tuple[np.ndarray, dict]:
    """A generated design (patterns.geometry) rasterized on the canvas, moved by ``offset_um``."""
    from shapely import affinity

    from patterns.geometry import DESIGNS, build, design_record, rasterize

    t = dict(t)
    name = t.pop("design", None)
    require(
        isinstance(name, str) and name in DESIGNS,
        f"{where} design = {show_value(name)}: must be one of {', '.join(DESIGNS)}",
    )
    off = t.pop("offset_um", [0.0, 0.0])
    dx, dy = _pair(f"{where} offset_um", off, -1e7, 1e7, "um")
    try:
        geom = affinity.translate(build(name, **t), dx, dy)
        record = design_record(name, **t)
    except InputError as err:
        raise InputError(f"{where}: {err}") from None
    img = rasterize(geom, s, shape=shape, budget_mb=budget, what=f"{where}")
    h, w = shape
    half_w, half_h = w * s / 2, h * s / 2
    x0, y0, x1, y1 = geom.bounds
    require(
        x0 >= -half_w - 1e-9
        and x1 <= half_w + 1e-9
        and y0 >= -half_h - 1e-9
        and y1 <= half_h + 1e-9,
        f"{where}: the {name} design reaches beyond the design canvas ({2 * half_w:g} x {2 * half_h:g} um, "
        f"[freeform] size_um); make the canvas larger or the design smaller",
    )
    return img, record | {"offset_um": [dx, dy]}


def _png_mask(
    where: str, path: Path, shape: tuple[int, int], s: float, budget: float | None
) -> np.ndarray:
    from patterns import read_mask

    require(
        path.exists(),
        f"{where} = {str(path)!r}: the file does not exist; give a PNG of the canvas's size",
    )
    require_regular_file(path, "mask")
    m = read_mask(path, default_um_per_px=s, scale_flag="[freeform] um_per_px", budget_mb=budget)
    require(
        math.isclose(m.um_per_px, s, rel_tol=1e-6),
        f"{where} {path}: stored at {m.um_per_px:g} um/px but the design canvas is {s:g} um/px "
        "([freeform] um_per_px); save it at the canvas's scale",
    )
    require(
        m.shape == tuple(shape),
        f"{where} {path}: {m.shape[1]} x {m.shape[0]} px but the design canvas is {shape[1]} x {shape[0]} px "
        f"at {s:g} um/px ([freeform] size_um); give a mask of the canvas's size",
    )
    return m.data


def _mask(
    where: str, v: Any, shape: tuple[int, int], s: float, base: Path, budget, files: list
) -> tuple[np.ndarray, Any]:
    """(H, W) coverage of a keep-in/keep-out/baseline given as a path, a design table or a list
    of design tables; with its record (for result.json)."""
    if isinstance(v, str):
        p = (base / v).resolve()
        files.append(str(p))
        return _png_mask(where, p, shape, s, budget), str(p)
    items = v if isinstance(v, list) else [v]
    require(
        len(items) >= 1 and all(isinstance(t, dict) for t in items),
        f"{where} = {show_value(v)}: must be a PNG path, a design table "
        '({ design = "rectangle", width = 50, height = 50, offset_um = [0, 100] }) or a list of them',
    )
    out = np.zeros(shape)
    records = []
    for i, t in enumerate(items):
        img, rec = _design_mask(f"{where}[{i}]" if len(items) > 1 else where, t, shape, s, budget)
        out = np.maximum(out, img)
        records.append(rec)
    return out, records


# ----------------------------------------------------------------------- the file
def load_freeform(
    spec: str | Path | dict, base: str | Path | None = None, source: str | None = None
) -> FreeformSpec:
    """A :class:`FreeformSpec` from a design file (TOML) or its parsed dict.

    ``base``: the directory relative paths are read from (default: the file's, or the
    working directory for a dict). Every problem is one InputError line, raised before any
    JAX work: unknown keys, missing or wrongly sized masks, a minimum feature below two
    pixels, fewer than one iteration, an orientation objective for a chip that is
    symmetric under the turn asked for, and FFT canvases over the memory budget.
    """
    from simulator.scene import Scene, chip_symmetry, validate_scene

    if isinstance(spec, dict):
        doc, src = copy.deepcopy(spec), source or "design file"
        base_dir = Path(base or ".").resolve()
    else:
        from simulator.sweep import read_toml_file

        path = Path(spec)
        doc, src = read_toml_file(path, "design file"), source or str(path)
        base_dir = Path(base).resolve() if base is not None else path.resolve().parent
    bad = [k for k in doc if k not in ("scene", "freeform")]
    require(
        not bad,
        f"{src}: {bad[0] if bad else ''}: unknown table or key; a free-form design file has the "
        "tables [scene] (the chip, materials, liquid, effects, twist) and [freeform]",
    )
    scene_doc = doc.get("scene", {})
    require(isinstance(scene_doc, dict), f"{src}: scene must be a table ([scene])")
    scene_doc = dict(scene_doc)
    for k in ("pattern", "resolution_um", "um_per_px", "pattern_um_per_px", "invert", "layer"):
        require(
            k not in scene_doc,
            f"{src}: [scene] {k}: a free-form design has no pattern file (the pattern is designed) and "
            "takes its pixel size from [freeform] um_per_px; remove it",
        )
    validate_scene(scene_doc, source=f"{src} [scene]")
    require(
        any(k in scene_doc for k in ("chip", "chip_size_um")),
        f'{src}: [scene] needs the chip: chip = "chip.png" or chip_size_um = [W, H]',
    )
    ff = _table(f"{src}: [freeform]", doc.get("freeform"), FREEFORM_KEYS)
    w = f"{src}: [freeform]"
    for k in ("size_um", "um_per_px", "min_feature_um"):
        require(k in ff, f"{w} needs {k}")
    s = _number(f"{w} um_per_px", ff["um_per_px"], 1e-4, 1e4, "um per px")
    sz = ff["size_um"]
    width, height = (
        (sz, sz) if isinstance(sz, int | float) and not isinstance(sz, bool) else (None, None)
    )
    if width is None:
        width, height = _pair(f"{w} size_um", sz, 0, 1e7, "um")
    width = _number(f"{w} size_um", width, s, 1e7, "um")
    height = _number(f"{w} size_um", height, s, 1e7, "um")
    W, H = 2 * max(1, round(width / s / 2)), 2 * max(1, round(height / s / 2))
    require(
        abs(W * s - width) < 1e-6 * max(1.0, width)
        and abs(H * s - height) < 1e-6 * max(1.0, height),
        f"{w} size_um = {show_value(sz)}: must be an even number of pixels of {s:g} um "
        f"(e.g. {W * s:g} x {H * s:g} um)",
    )
    require(
        max(W, H) <= MAX_CANVAS_PX,
        f"{w} size_um: the canvas is {W} x {H} px at {s:g} um/px, more than {MAX_CANVAS_PX} px a side; "
        "use a coarser um_per_px",
    )
    mf = _number(f"{w} min_feature_um", ff["min_feature_um"], 0, 1e7, "um")
    require(
        mf / s >= MIN_FEATURE_PX,
        f"{w} min_feature_um = {mf:g} um is {mf / s:.3g} px at {s:g} um/px; the minimum feature must be at least "
        f"{MIN_FEATURE_PX:g} px ({MIN_FEATURE_PX * s:g} um): raise it or use a finer um_per_px",
    )
    require(
        mf / s <= min(H, W) / 2,
        f"{w} min_feature_um = {mf:g} um is more than half the design canvas; lower it or enlarge size_um",
    )
    iterations = _whole(f"{w} iterations", ff.get("iterations", 100), 1, MAX_ITERATIONS)
    seed = _whole(f"{w} seed", ff.get("seed", 0), 0, 2**31 - 1)
    lr = _number(f"{w} learning_rate", ff.get("learning_rate", 0.1), 1e-6, 100)
    b0, b1 = _pair(f"{w} beta", ff.get("beta", [1.0, 16.0]), 0.01, 1e4, "")
    require(b1 >= b0, f"{w} beta = {show_value(ff.get('beta'))}: the last must be >= the first")
    init = _number(f"{w} init", ff.get("init", 0.5), 0.01, 0.99)
    budget = scene_doc.get("memory_budget_mb")
    _price_canvas(src, (H, W), scene_doc.get("dtype", "float32"), budget)  # before any raster
    files: list[str] = []
    shape = (H, W)
    zero = np.zeros(shape)
    if "keep_in" in ff:
        keep_in_img, keep_in_rec = _mask(
            f"{w} keep_in", ff["keep_in"], shape, s, base_dir, budget, files
        )
    else:
        keep_in_img, keep_in_rec = zero, None
    if "keep_out" in ff:
        keep_out_img, _ = _mask(f"{w} keep_out", ff["keep_out"], shape, s, base_dir, budget, files)
    else:
        keep_out_img = zero
    keep_in, keep_out = keep_in_img >= 0.5, keep_out_img >= 0.5
    require(
        not np.any(keep_in & keep_out),
        f"{w}: keep_in and keep_out overlap on {int(np.sum(keep_in & keep_out)):,} px; a pixel cannot be both",
    )
    require(
        bool(np.any(~keep_in & ~keep_out)),
        f"{w}: keep_in and keep_out cover the whole canvas; nothing is left to design",
    )
    terms = _terms(w, ff.get("objective", {}), s)
    pert = _table(f"{w} [perturbation]", ff.get("perturbation", {}), PERTURBATION_KEYS)
    perturbation = {
        "samples": _whole(f"{w} [perturbation] samples", pert.get("samples", 0), 0, MAX_SAMPLES),
        "edge_um": _number(f"{w} [perturbation] edge_um", pert.get("edge_um", s), 0, 1e6, "um"),
        "length_um": _number(
            f"{w} [perturbation] length_um", pert.get("length_um", 4 * mf), s, 1e7, "um"
        ),
    }
    verify = _verify(w, ff.get("verify", {}))
    # the baseline
    bl = ff.get("baseline", {"keep_in": True})
    bl = _table(
        f"{w} [baseline]",
        bl,
        tuple(bl) if isinstance(bl, dict) and "design" in bl else ("pattern", "keep_in"),
    )
    if bl.get("keep_in", False) is True and len(bl) == 1:
        require(
            bool(keep_in.any()),
            f"{w} [baseline]: the baseline is the keep-in pads by default, but there are none; "
            'give [freeform.baseline] design = "..." or pattern = "file.png"',
        )
        base_img, label = keep_in_img, f"the keep-in pads ({_describe(keep_in_rec)})"
    elif "pattern" in bl:
        require(len(bl) == 1, f"{w} [baseline]: give pattern alone, or a design table")
        require(isinstance(bl["pattern"], str), f"{w} [baseline] pattern: must be a PNG path")
        base_img, label = _mask(
            f"{w} [baseline] pattern", bl["pattern"], shape, s, base_dir, budget, files
        )
    elif "design" in bl:
        base_img, rec = _mask(f"{w} [baseline]", bl, shape, s, base_dir, budget, files)
        label = _describe(rec)
    else:
        raise InputError(
            f'{w} [baseline]: give design = "..." (with its parameters), pattern = "file.png" or keep_in = true'
        )
    require(
        bool(np.any(base_img > 0)),
        f"{w} [baseline]: the baseline pattern has no wettable pixel; give one with pads",
    )
    baseline = Mask(base_img, s, params={"baseline": str(label)})
    scene = Scene.from_dict(scene_doc | {"pattern": baseline, "resolution_um": s}, base=base_dir)
    for k in ("chip",):
        if isinstance(scene_doc.get(k), str):
            files.append(str((base_dir / scene_doc[k]).resolve()))
    # the orientation objective, for a chip that no pattern can orient
    o = terms["orientation"]
    if o["weight"] > 0:
        require(
            scene.effects.twist,
            f"{w} [objective] orientation: needs twist ([scene.effects] twist = true)",
        )
        period, _ = chip_symmetry(scene.chip)
        for t in o["twists_deg"]:
            turns = t / period
            require(
                not math.isclose(turns, round(turns), abs_tol=1e-9),
                f"{w} [objective] orientation twists_deg: the chip is symmetric under a {period:g}-degree turn, so its "
                f"energy at {t:g} deg equals that at 0 deg for every pattern and no pattern can select the orientation; "
                "give the chip an asymmetric wettable feature (an index mark, one larger contact) or drop that twist",
            )
    out = FreeformSpec(
        source=src,
        base_dir=base_dir,
        scene=scene,
        keep_in=keep_in,
        keep_out=keep_out,
        baseline=baseline,
        baseline_label=str(label),
        um_per_px=s,
        min_feature_um=mf,
        iterations=iterations,
        seed=seed,
        learning_rate=lr,
        beta=(b0, b1),
        init=init,
        terms=terms,
        perturbation=perturbation,
        verify=verify,
        files=tuple(files),
        doc={"scene": scene_doc, "freeform": ff},
    )
    _check_regions(out)
    price_freeform(out)
    return out


def _describe(rec: Any) -> str:
    if rec is None:
        return "none"
    if isinstance(rec, str):
        return rec
    parts = []
    for r in rec if isinstance(rec, list) else [rec]:
        ps = ", ".join(
            f"{k} {v['value']:g} {v['unit']}".strip()
            for k, v in r["parameters"].items()
            if isinstance(v["value"], int | float)
        )
        off = r.get("offset_um", [0, 0])
        at = f" at ({off[0]:g}, {off[1]:g}) um" if any(off) else ""
        parts.append(f"{r['design']} {ps}{at}".strip())
    return "; ".join(parts)


def _terms(w: str, obj: Any, s: float) -> dict:
    obj = _table(f"{w} [objective]", obj, tuple(TERMS))
    out = {}
    for name, keys in TERMS.items():
        t = _table(f"{w} [objective] {name}", obj.get(name, {"weight": 0.0}), ("weight", *keys))
        d: dict[str, Any] = {
            "weight": _number(f"{w} [objective] {name} weight", t.get("weight", 1.0), 0, 1e6)
        }
        where = f"{w} [objective] {name}"
        if name == "capture":
            r0, r1 = _pair(f"{where} radius_um", t.get("radius_um", [2 * s, 10 * s]), 0, 1e7, "um")
            require(
                r1 > r0 and r1 >= 2 * s,
                f"{where} radius_um: the outer radius must exceed the inner and two pixels",
            )
            d["radius_um"] = [r0, r1]
        if name == "gap":
            d["radius_um"] = _number(f"{where} radius_um", t.get("radius_um", 4 * s), s, 1e7, "um")
        if name == "orientation":
            tw = t.get("twists_deg", [90, 180, 270])
            require(
                isinstance(tw, list) and 1 <= len(tw) <= 32,
                f"{where} twists_deg = {show_value(tw)}: must be a list of 1 to 32 twists in degrees",
            )
            vals = [_number(f"{where} twists_deg", v, -360, 360, "deg") for v in tw]
            require(
                all(abs(math.remainder(v, 360.0)) > 1e-9 for v in vals),
                f"{where} twists_deg: 0 (or a full turn) is the target's own orientation; give the other turns",
            )
            d["twists_deg"] = vals
        if name == "stiffness":
            d["step_um"] = _number(f"{where} step_um", t.get("step_um", s), s, 1e6, "um")
        for k in ("temperature_J", "temperature_N"):
            if k in keys and k in t:
                d[k] = _number(f"{where} {k}", t[k], 1e-300, 1e300, k.split("_")[1])
        out[name] = d
    require(
        any(v["weight"] > 0 for v in out.values()),
        f"{w} [objective]: give at least one term a weight > 0 ({', '.join(TERMS)})",
    )
    return out


def _verify(w: str, v: Any) -> dict:
    from simulator.core import METHODS

    v = _table(f"{w} [verify]", v, VERIFY_KEYS)
    method = v.get("method", "greedy")
    require(
        method in METHODS,
        f"{w} [verify] method = {show_value(method)}: must be one of {', '.join(METHODS)}",
    )
    sigma = v.get("placement_sigma")
    if sigma is not None:
        require(
            isinstance(sigma, list) and len(sigma) == 3,
            f"{w} [verify] placement_sigma = {show_value(sigma)}: must be [x_um, y_um, twist_deg]",
        )
        sigma = [_number(f"{w} [verify] placement_sigma", x, 0, 1e7) for x in sigma]
    return {
        "yield_starts": _whole(f"{w} [verify] yield_starts", v.get("yield_starts", 2000), 1, 10**7),
        "capture_grid": _whole(f"{w} [verify] capture_grid", v.get("capture_grid", 25), 2, 1001),
        "placement_sigma": sigma,
        "method": method,
        "seed": _whole(f"{w} [verify] seed", v.get("seed", 0), 0, 2**31 - 1),
    }


def _check_regions(spec: FreeformSpec) -> None:
    """The capture ring and the gap's ball must lie within the poses where the chip touches the canvas."""
    H, W = spec.shape
    s = spec.um_per_px
    reach = min(H, W) * s / 2
    c = spec.terms["capture"]
    if c["weight"] > 0:
        require(
            c["radius_um"][1] < reach,
            f"{spec.source}: [freeform] [objective] capture radius_um: the outer radius {c['radius_um'][1]:g} um "
            f"must lie within the design canvas's half-width {reach:g} um",
        )


def chip_canvas_px(spec: FreeformSpec) -> tuple[int, int]:
    """An upper bound on the chip's canvas (H, W) px over the twists the objective needs: its
    image (quarter turns) or its circumscribed circle (other twists), and the meniscus margin."""
    scene = spec.scene
    h, w = scene.chip.shape
    if all(abs(math.remainder(t, 90.0)) < 1e-9 for t in spec.twists_deg()):
        rad = max(h, w) / 2
    else:
        rad = math.hypot(h, w) / 2
    n = 2 * math.ceil(rad + scene.meniscus_margin_px) + 4
    return n, n


def freeform_cost(spec: FreeformSpec) -> dict:
    """What one free-form run holds at its peak, without refusing anything: ``bytes`` (the
    sum of the terms below), ``fft`` (nx, ny), ``twists``, ``samples`` and each term's bytes:
    ``planes`` (every twist's correlation for every perturbation sample, forward and backward),
    ``spectra`` (the chips' spectra and per-twist minima), ``noise`` (the perturbation
    fields), ``canvas`` (the arrays of the
    design canvas, :data:`CANVAS_BYTES_PER_PX`) and ``xla`` (:data:`XLA_FIXED_BYTES`)."""
    import scipy.fft as sfft

    H, W = spec.shape
    hc, wc = chip_canvas_px(spec)
    ny, nx = sfft.next_fast_len(H + hc), sfft.next_fast_len(W + wc, real=True)
    twists = len(spec.twists_deg())
    samples = max(1, spec.perturbation["samples"])
    item = 2 if spec.scene.dtype == "float64" else 1
    terms = {
        "planes": item * FFT_BYTES_PER_PX * ny * nx * twists * samples,
        "spectra": item * TWIST_BYTES_PER_PX * ny * nx * twists,
        "noise": item * NOISE_BYTES_PER_PX * H * W * spec.perturbation["samples"],
        "canvas": item * CANVAS_BYTES_PER_PX * H * W,
        "xla": XLA_FIXED_BYTES,
    }
    return {
        "bytes": int(sum(terms.values())),
        "fft": (nx, ny),
        "twists": twists,
        "samples": samples,
        **terms,
    }


def _price_canvas(src: str, shape: tuple[int, int], dtype: str, budget_mb: float | None) -> None:
    """InputError when the design canvas's own arrays (:data:`CANVAS_BYTES_PER_PX`, with
    :data:`XLA_FIXED_BYTES`) are over the memory budget: checked from the file's numbers,
    before the masks or the chip are rasterized (:func:`price_freeform` prices the whole run)."""
    from foundation import budget_bytes, fmt_bytes

    H, W = shape
    item = 2 if dtype == "float64" else 1
    need = item * CANVAS_BYTES_PER_PX * H * W + XLA_FIXED_BYTES
    budget = budget_bytes(budget_mb)
    if need > budget:
        raise InputError(
            f"{src}: one gradient iteration needs about {fmt_bytes(need)} or more (the arrays of the {W} x {H} px "
            f"canvas, {dtype}, before its FFT canvases) but the memory budget is {fmt_bytes(budget)}; use a coarser um_per_px "
            "or a smaller size_um, or raise --memory-budget ([scene] memory_budget_mb)"
        )


def price_freeform(spec: FreeformSpec, budget_mb: float | None = None) -> int:
    """Bytes a free-form run holds at its peak (:func:`freeform_cost`); InputError above the
    memory budget (``budget_mb``, else the scene's ``memory_budget_mb``), before any work."""
    from foundation import fmt_bytes

    c = freeform_cost(spec)
    need = c["bytes"]
    mb = spec.scene.memory_budget_mb if budget_mb is None else float(budget_mb)
    budget = mb * 2**20
    if need > budget:
        H, W = spec.shape
        nx, ny = c["fft"]
        twists, samples = c["twists"], c["samples"]
        raise InputError(
            f"{spec.source}: one gradient iteration needs about {fmt_bytes(need)} with what the run holds ({W} x {H} px canvas, "
            f"{twists} twist plane{'s' if twists != 1 else ''} x {samples} sample{'s' if samples != 1 else ''} "
            f"on {nx} x {ny} px FFT canvases, {spec.scene.dtype}) but the memory budget is {fmt_bytes(budget)}; "
            "use a coarser um_per_px, a smaller size_um, fewer perturbation samples or orientation twists, "
            "or raise --memory-budget ([scene] memory_budget_mb)"
        )
    return int(need)
