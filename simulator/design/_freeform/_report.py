"""What a free-form design writes: the pattern (PNG, mask, GDSII), its history, the
evaluator's check beside the baseline's, ``result.json`` and ``report.html``.

The GDSII polygons are the written raster's pixels merged (exact, in um, the pattern frame
of :class:`patterns.geometry.Mask`) and simplified by half a pixel, well below the minimum feature
(at least two pixels). :func:`feature_check` measures, on the polygons read back from the
file, what an opening and a closing by a disk of the minimum feature (its radius less one
pixel of slack) change: a wettable part or a dry gap narrower than the feature would move by its
length, a raster opened and closed by that disk moves by a pixel or two. The keep-in pads
and keep-out areas are the user's shapes, written as given (sharp corners and all), and
not counted. Nothing heavy is imported until a picture is drawn.
"""

from __future__ import annotations

import contextlib
import csv
import html
import json
import math
from pathlib import Path

import numpy as np

from foundation import MARKER, InputError, check_output_dir, json_text, output_directory

__all__ = [
    "COMMAND",
    "FEATURE_TOL_PX",
    "check_out",
    "feature_check",
    "output_context",
    "pattern_polygons",
    "read_gds_polygons",
    "write_outputs",
]

#: The command recorded in the output's marker: such a directory may be replaced by a rerun.
COMMAND = "design freeform"
#: How far (px) an opening or closing by the minimum feature (its radius less a pixel) may move the
#: written polygons: pixel stairs and the half-pixel simplification.
FEATURE_TOL_PX = 2.0


def _previous(out: Path) -> bool:
    try:
        return json.loads((out / MARKER).read_text()).get("command") == COMMAND
    except (OSError, ValueError, AttributeError):
        return False


def check_out(out, spec) -> None:
    """Refuse, before any work, an ``--out`` that is not new, empty or a previous free-form output."""
    out = Path(out)
    check_output_dir(out, "--out", _previous(out), spec.files)


@contextlib.contextmanager
def output_context(out, spec):
    """The atomic output directory (a previous free-form output in ``out`` is replaced).

    The temporary directories that killed runs into ``out`` left beside it are removed first,
    and this run's own is locked while it is written (:mod:`simulator.design._leftovers`)."""
    from simulator.design._leftovers import hold_directory, remove_dead_directories

    out = Path(out)
    remove_dead_directories(out)
    with output_directory(out, "--out", _previous(out), spec.files, command=COMMAND) as tmp:
        with hold_directory(tmp):
            yield tmp


# ------------------------------------------------------------------------------ geometry
def pattern_polygons(binary: np.ndarray, um_per_px: float, simplify_px: float = 0.5):
    """The wettable pixels of ``binary`` (H, W, image rows) as shapely polygons in um (x
    right, y up, origin at the canvas centre), merged and simplified by ``simplify_px``."""
    import shapely

    h, w = binary.shape
    s = float(um_per_px)
    x0, y0, x1, y1 = [], [], [], []
    for r in range(h):
        d = np.diff(np.r_[0, binary[r].astype(np.int8), 0])
        starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        top = (h / 2 - r) * s
        x0 += list((starts - w / 2) * s)
        x1 += list((ends - w / 2) * s)
        y0 += [top - s] * len(starts)
        y1 += [top] * len(starts)
    if not x0:
        return shapely.MultiPolygon()
    boxes = shapely.box(np.array(x0), np.array(y0), np.array(x1), np.array(y1))
    merged = shapely.union_all(boxes)
    return shapely.make_valid(merged.simplify(simplify_px * s, preserve_topology=True))


def _directed(a, b, step: float) -> float:
    """The largest distance from a point of ``a`` (its boundary sampled every ``step``) to ``b``."""
    import shapely

    if a.is_empty:
        return 0.0
    if b.is_empty:
        return math.inf
    pts = shapely.get_coordinates(shapely.segmentize(a.boundary, step))
    return float(np.max(shapely.distance(shapely.points(pts), b))) if len(pts) else 0.0


def feature_check(
    geometry, min_feature_um: float, um_per_px: float, keep_in=None, keep_out=None
) -> dict:
    """How far an opening and a closing by a disk of diameter ``min_feature_um`` (its radius
    less one pixel) move ``geometry`` (um): the largest distance from what the opening removes
    to the wettable area left (a wettable part narrower than the feature moves by its length),
    and from what the closing fills to the dry area left (a dry gap narrower than the feature). What lies on the
    keep-in pads (``keep_in``, geometry in um: the user's own shapes, kept as given, sharp
    corners and all) is not counted for the opening, nor what lies on ``keep_out`` for the
    closing. ``ok`` when both stay within :data:`FEATURE_TOL_PX` pixels."""
    import shapely

    s = um_per_px
    r = max(min_feature_um / 2 - s, 0.25 * min_feature_um)
    opened = geometry.buffer(-r, quad_segs=16).buffer(r, quad_segs=16)
    removed = geometry.difference(opened)
    closed = geometry.buffer(r, quad_segs=16).buffer(-r, quad_segs=16)
    added = closed.difference(geometry)
    if keep_in is not None and not keep_in.is_empty:
        removed = removed.difference(keep_in.buffer(s))
    if keep_out is not None and not keep_out.is_empty:
        added = added.difference(keep_out.buffer(s))
    # Slivers thinner than a tenth of a pixel are the buffers' round-off.
    removed = shapely.union_all([g for g in shapely.get_parts(removed) if g.area > 0.1 * s * s])
    added = shapely.union_all([g for g in shapely.get_parts(added) if g.area > 0.1 * s * s])
    # Gaps are the dry side's features: the closing's additions measured, as the opening's
    # removals are, against what is left of their own side (the dry area around, bounded).
    x0, y0, x1, y1 = closed.bounds if not closed.is_empty else (0.0, 0.0, 0.0, 0.0)
    m = 4 * r + s
    dry = shapely.box(x0 - m, y0 - m, x1 + m, y1 + m).difference(closed)
    d_open = _directed(removed, opened, s / 4)
    d_close = _directed(added, dry, s / 4)
    tol = FEATURE_TOL_PX * s
    return {
        "polygons": len(shapely.get_parts(geometry)),
        "disk_diameter_um": 2 * r,
        "opening_moves_um": d_open if math.isfinite(d_open) else None,
        "closing_moves_um": d_close,
        "tolerance_um": tol,
        "ok": bool(d_open <= tol and d_close <= tol),
    }


def read_gds_polygons(path):
    """The written pattern read back (layer 1/0 of its one cell) as one shapely geometry, um:
    the project's layout reader (:func:`patterns.layout.read_layout`), as a user's GDSII is read."""
    from patterns.layout import read_layout

    lay = read_layout(path)
    return lay.geometry(lay.key("1/0"))


# ------------------------------------------------------------------------------ outputs
def write_outputs(result, tmp: Path, quiet: bool = True):
    """Write every output of ``result`` into ``tmp`` (the atomic directory); returns the
    result with its ``layout`` check and ``files``."""
    from dataclasses import replace

    from patterns import write_mask
    from patterns.layout import write_layout

    spec = result.spec
    write_mask(tmp / "pattern_mask.png", result.pattern)
    geom = pattern_polygons(result.pattern.data >= 0.5, spec.um_per_px)
    if geom.is_empty:
        raise InputError(
            f"{spec.source}: the optimised pattern has no wettable pixel; nothing to write"
        )
    write_layout(tmp / "pattern.gds", geom, cell="FREEFORM")
    layout = feature_check(
        read_gds_polygons(tmp / "pattern.gds"),
        spec.min_feature_um,
        spec.um_per_px,
        keep_in=pattern_polygons(spec.keep_in, spec.um_per_px, 0.0),
        keep_out=pattern_polygons(spec.keep_out, spec.um_per_px, 0.0),
    )
    layout["simplify_um"] = 0.5 * spec.um_per_px
    result = replace(result, layout=layout)
    _write_history(result, tmp)
    _plot_patterns(result, tmp / "pattern.png")
    _plot_history(result, tmp / "history.png")
    if result.verification is not None:
        _plot_captures(tmp, tmp / "capture_before_after.png")
    doc = result_json(result)
    from foundation import require_finite

    require_finite(doc, "free-form result")
    (tmp / "result.json").write_text(json_text(doc))
    (tmp / "report.html").write_text(_html(doc))
    files = sorted(p.relative_to(tmp).as_posix() for p in tmp.rglob("*") if p.is_file())
    return replace(result, files=files)


def _write_history(result, tmp: Path) -> None:
    keys = list(result.history)
    with open(tmp / "history.csv", "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(keys)
        for i in range(len(result.history["iteration"])):
            wr.writerow([_num(result.history[k][i]) for k in keys])


def _num(v) -> str:
    v = float(v)
    return str(int(v)) if v.is_integer() and abs(v) < 1e15 else f"{v:.9g}"


def _plot_patterns(result, path: Path) -> None:
    from simulator.render import pyplot, save_figure

    plt = pyplot()
    spec = result.spec
    s = spec.um_per_px
    h, w = spec.shape
    ext = (-w / 2 * s, w / 2 * s, -h / 2 * s, h / 2 * s)
    x = (np.arange(w) + 0.5 - w / 2) * s
    y = (h / 2 - np.arange(h) - 0.5) * s
    chip = spec.scene.chip
    ch, cw = chip.shape
    cx = (np.arange(cw) + 0.5 - cw / 2) * chip.um_per_px
    cy = (ch / 2 - np.arange(ch) - 0.5) * chip.um_per_px
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.8), constrained_layout=True)
    for ax, data, title in (
        (axes[0], spec.baseline.data, "baseline"),
        (axes[1], result.pattern.data, "optimised (written)"),
    ):
        ax.imshow(data, extent=ext, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        if spec.keep_in.any():
            ax.contour(x, y, spec.keep_in.astype(float), [0.5], colors="C0", linewidths=1.2)
        if spec.keep_out.any():
            ax.contour(x, y, spec.keep_out.astype(float), [0.5], colors="C3", linewidths=1.2)
        ax.contour(cx, cy, chip.data, [0.5], colors="C1", linewidths=1.0, linestyles="--")
        ax.plot([0], [0], "+", color="C1", ms=10, mew=1.5)
        ax.set(xlabel="x (µm)", ylabel="y (µm)", title=f"{title}, {s:g} µm/px")
        ax.set(xlim=ext[:2], ylim=ext[2:])
    axes[1].plot([], [], color="C0", label="keep-in (wettable)")
    axes[1].plot([], [], color="C3", label="keep-out (dry)")
    axes[1].plot([], [], color="C1", ls="--", label="chip's wettable area at the target")
    axes[1].legend(loc="upper right", fontsize=8, framealpha=0.8)
    fig.suptitle(
        f"free-form pattern: white = wettable pad; minimum feature {spec.min_feature_um:g} µm",
        fontsize=11,
    )
    save_figure(fig, path)


def _plot_history(result, path: Path) -> None:
    from simulator.render import pyplot, save_figure

    plt = pyplot()
    h = result.history
    terms = [k for k in h if k not in ("iteration", "beta", "objective")]
    n = 1 + len(terms)
    fig, axes = plt.subplots(n, 1, figsize=(7, 1.9 * n + 0.6), sharex=True, constrained_layout=True)
    axes = np.atleast_1d(axes)
    it = h["iteration"]
    axes[0].plot(it, h["objective"], color="k")
    axes[0].set_ylabel("objective")
    b = axes[0].twinx()
    b.plot(it, h["beta"], color="C7", ls=":", lw=1)
    b.set_ylabel("β (projection)", color="C7")
    for ax, k, c in zip(axes[1:], terms, ("C0", "C1", "C2", "C3", "C4", "C5"), strict=False):
        name, unit = _split_unit(k)
        ax.plot(it, h[k], color=c)
        ax.set_ylabel(f"{name}\n({unit})")
    axes[-1].set_xlabel("iteration")
    axes[0].set_title(
        "objective and its terms per iteration (mean over the edge perturbations)", fontsize=10
    )
    save_figure(fig, path)


def _split_unit(key: str) -> tuple[str, str]:
    for unit in ("_N_per_m", "_um2", "_J", "_N"):
        if key.endswith(unit):
            return key[: -len(unit)], unit[1:].replace("_per_", "/").replace("um2", "µm²")
    return key, ""


def _plot_captures(tmp: Path, path: Path) -> None:
    from matplotlib.image import imread

    from simulator.render import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2), constrained_layout=True)
    for ax, name, title in ((axes[0], "before", "baseline"), (axes[1], "after", "optimised")):
        ax.imshow(imread(tmp / name / "capture.png"))
        ax.set_axis_off()
        ax.set_title(title)
    save_figure(fig, path, dpi=150)


# ------------------------------------------------------------------------------ the record
def _key_numbers(summary: dict | None) -> dict | None:
    if summary is None:
        return None
    b = summary["max_bias_um"]
    out = {
        "capture_fraction": summary["capture"]["fraction"],
        "yield_fraction": summary["yield"]["fraction"],
        "yield_outcomes": summary["yield"]["outcomes"],
        "max_bias_min_um": min(b.values()),
        "global_minimum": {
            k: summary["global_minimum"][k]
            for k in ("x_um", "y_um", "twist_deg", "energy_J", "refined")
            if k in summary["global_minimum"]
        },
        "grid": {  # the pose grid's steps: the report shows the minimum to them
            "um": summary["settings"]["um_per_px"],
            "twist_deg": summary["settings"].get("twist_step_deg"),
        },
    }
    if summary.get("stiffness"):
        out["stiffness"] = summary["stiffness"]
    if summary.get("orientation"):
        out["orientation_min_gap_J"] = summary["orientation"]["min_gap_J"]
    return out


def result_json(result) -> dict:
    """The record of a free-form design (``result.json``): settings, timing, cleanup, the
    written layout's check, the objective's terms and the evaluator's numbers, before
    (baseline) and after (optimised)."""
    spec = result.spec
    v = result.verification
    return {
        "source": spec.source,
        "settings": spec.doc,
        "canvas_px": list(spec.shape),
        "um_per_px": spec.um_per_px,
        "min_feature_um": spec.min_feature_um,
        "iterations": spec.iterations,
        "seed": spec.seed,
        "twists_deg": list(spec.twists_deg()),
        "perturbation": spec.perturbation,
        "seconds_per_iteration": result.seconds_per_iteration,
        "compile_seconds": result.compile_seconds,
        "baseline": spec.baseline_label,
        "cleanup": result.cleanup,
        "layout": result.layout,
        "objective": {
            "baseline": {"objective": result.before[0], **result.before[1]},
            "optimised": {"objective": result.after[0], **result.after[1]},
        },
        "evaluation": None
        if v is None
        else {
            "baseline": _key_numbers(v["baseline"]),
            "optimised": _key_numbers(v["optimised"]),
            "summaries": v,
        },
        "final": {k: float(a[-1]) for k, a in result.history.items()},
    }


def _fmt(v, unit: str = "") -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float) and v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
        return f"{v:.4g} {unit}".strip()
    return f"{v:.4g} {unit}".strip()


def _pose_text(numbers: dict) -> str:
    """The global minimum as ``(x, y, twist)``, to the pose grid's steps (``grid``) when it is a
    grid pose, to 0.1 µm and 0.1° when refined below the grid (as ``evaluate`` prints it): a
    baseline's minimum on the centre reads (0, 0, 0), not the refinement's round-off
    (4.9e-08, 6.5e-08, -3.2e-07)."""
    g = numbers["global_minimum"]
    grid = numbers.get("grid") or {}
    refined = g.get("refined", False)
    steps = (
        (0.1, 0.1, 0.1)
        if refined or not grid
        else (grid["um"], grid["um"], grid.get("twist_deg") or 0.1)
    )
    vals = (
        round(round(v / d) * d, 6) + 0.0
        for v, d in zip((g["x_um"], g["y_um"], g["twist_deg"]), steps, strict=True)
    )
    return "({:g}, {:g}, {:g})".format(*vals)


def _rows(doc: dict) -> str:
    e = doc["evaluation"]
    o = doc["objective"]
    rows = []
    if e is not None:
        b, a = e["baseline"], e["optimised"]
        rows += [
            (
                "capture fraction (grid around the minimum)",
                f"{100 * b['capture_fraction']:.1f} %",
                f"{100 * a['capture_fraction']:.1f} %",
            ),
            (
                "yield under placement noise",
                f"{100 * b['yield_fraction']:.1f} %",
                f"{100 * a['yield_fraction']:.1f} %",
            ),
            (
                "smallest maximum bias",
                _fmt(b["max_bias_min_um"], "µm"),
                _fmt(a["max_bias_min_um"], "µm"),
            ),
            (
                "global minimum (x µm, y µm, twist °)",
                _pose_text(b),
                _pose_text(a),
            ),
        ]
        if "stiffness" in a and "stiffness" in b:
            rows.append(
                (
                    "stiffness at alignment, x / y (N/m)",
                    f"{b['stiffness']['x_N_per_m']:.3g} / {b['stiffness']['y_N_per_m']:.3g}",
                    f"{a['stiffness']['x_N_per_m']:.3g} / {a['stiffness']['y_N_per_m']:.3g}",
                )
            )
        if "orientation_min_gap_J" in a:
            rows.append(
                (
                    "orientation gap: lowest energy turned minus target's (landscape)",
                    _fmt(b.get("orientation_min_gap_J"), "J"),
                    _fmt(a.get("orientation_min_gap_J"), "J"),
                )
            )
    for k in o["optimised"]:
        rows.append(
            (f"objective term {k}", _fmt(o["baseline"].get(k)), _fmt(o["optimised"].get(k)))
        )
    return "".join(
        f"<tr><th>{html.escape(n)}</th><td>{html.escape(x)}</td><td>{html.escape(y)}</td></tr>"
        for n, x, y in rows
    )


def _html(doc: dict) -> str:
    e = html.escape
    c, lay = doc["cleanup"], doc["layout"]
    check = (
        f"every polygon survives an opening, and every gap a closing, by a {lay['disk_diameter_um']:.3g} µm disk "
        f"(the minimum feature's, its radius less a pixel) within {lay['tolerance_um']:.3g} µm, the keep-in pads and keep-out areas as given: "
        f"opening moves them by at most {_fmt(lay['opening_moves_um'], 'µm')}, closing by {_fmt(lay['closing_moves_um'], 'µm')}"
        f" — <b>{'respected' if lay['ok'] else 'NOT respected'}</b>"
    )
    pics = (
        '<h2>Capture maps, baseline and optimised</h2><img src="capture_before_after.png" alt="capture maps">'
        '<p class="note">The evaluator\'s pictures of each: <a href="before/landscape.png">baseline landscape</a>, '
        '<a href="before/force.png">forces</a>; <a href="after/landscape.png">optimised landscape</a>, '
        '<a href="after/force.png">forces</a>.</p>'
        if doc["evaluation"]
        else "<p>Not verified (no evaluation was run).</p>"
    )
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>selfalign free-form design: {e(doc["source"])}</title>
<style>
body {{ font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; color: #222; line-height: 1.4; }}
table {{ border-collapse: collapse; margin: .5em 0; }} td, th {{ border: 1px solid #ccc; padding: 3px 10px; text-align: left; }}
img {{ max-width: 100%; border: 1px solid #ddd; }} .note {{ color: #555; font-size: .9em; }}
</style></head><body>
<h1>Free-form design of <code>{e(doc["source"])}</code></h1>
<p class="note">A pattern on a {doc["canvas_px"][1]} x {doc["canvas_px"][0]} px canvas at {doc["um_per_px"]:g} µm/px,
optimised by {doc["iterations"]} gradient iterations (optax Adam, seed {doc["seed"]}, {doc["seconds_per_iteration"] * 1e3:.3g} ms per
iteration after {doc["compile_seconds"]:.3g} s of compilation) through the differentiable landscape at twists
{", ".join(f"{t:g}" for t in doc["twists_deg"])}°, then checked by the evaluator (capture map, yield by Monte Carlo)
beside the baseline: {e(doc["baseline"])}.</p>
<h2>Baseline and optimised, side by side</h2>
<table><tr><th></th><th>baseline</th><th>optimised</th></tr>{_rows(doc)}</table>
<img src="pattern.png" alt="baseline and optimised patterns">
<p>Minimum feature {doc["min_feature_um"]:g} µm: the thresholded density was opened and closed by a disk of that
diameter, which removed {c["removed_px"]:,} px ({c["removed_um2"]:,.0f} µm²) and added {c["added_px"]:,} px
({c["added_um2"]:,.0f} µm²). The GDSII file (<code>pattern.gds</code>, {lay["polygons"]} polygons, simplified by
{lay["simplify_um"]:g} µm): {check}.</p>
{pics}
<h2>Objective history</h2><img src="history.png" alt="objective per iteration">
<p class="note">Written by selfalign: result.json (every number, units in the key names), history.csv,
pattern_mask.png (the pattern as the pattern readers take it, with its scale), pattern.gds.</p>
</body></html>
"""
