"""Pictures and the HTML page of a design sweep (:mod:`simulator.sweep`).

* one swept axis: ``sweep_<axis>.png``, every metric against the parameter: the mean
  over the realizations with their range (min to max) as a band and each realization
  as a dot; failed points as red crosses on the axis;
* two swept axes: ``heatmap_<metric>.png`` per metric: a grid as cells (the mean over
  the realizations, printed in each cell; failed cells hatched), random samples as
  dots coloured by the value;
* more axes: ``effects_<metric>.png``, the metric against each axis in turn;
* ``report.html``: the sweep, its counts and times, the pictures and a table of the
  points, each linking its numbers (``points/NNNNN.json``).

Written atomically (:func:`simulator.render.save_figure`, :func:`foundation.atomic_output`).
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from simulator.sweep._columns import column_label, metric

#: Metrics drawn, when the table has them: column, label, factor to the plotted unit
#: (:func:`simulator.sweep.metric`).
METRICS = tuple(
    metric(c)
    for c in (
        "max_bias_x_um",
        "max_bias_y_um",
        "capture_fraction",
        "yield_fraction",
        "restoring_force_plus_x_x_N",
        "global_minimum_offset_um",
        "floating_half_width_um",
        "yield_time_to_align_median_s",
        "yield_time_to_align_p90_s",
    )
)
#: The most point rows the HTML table shows (the CSV has them all).
MAX_ROWS = 1000


def metrics(table) -> list[tuple[str, str, float]]:
    """The metrics to draw: :data:`METRICS` present with a finite value, and any stiffness column."""
    out = [m for m in METRICS if m[0] in table.columns]
    out += [
        metric(c)
        for c in table.columns
        if c.startswith("stiffness") and c not in {m[0] for m in out}
    ]
    ok = table[table["status"] == "ok"] if len(table) else table
    return [m for m in out if len(ok) and np.isfinite(np.asarray(ok[m[0]], float)).any()]


def _levels(values) -> tuple[list, bool]:
    """Distinct values in order, and whether they are numbers (else drawn as categories)."""
    vals = list(
        dict.fromkeys(
            v for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))
        )
    )
    numeric = all(isinstance(v, int | float | np.number) and not isinstance(v, bool) for v in vals)
    return (sorted(vals) if numeric else vals), numeric


def _fmt(v: float) -> str:
    if not np.isfinite(v):
        return ""
    a = abs(v)
    return f"{v:.3g}" if a < 1000 else f"{v:.0f}"


def _label(axis) -> str:
    return column_label(axis.column)


def plot_one_axis(table, axis, path: Path, mets) -> None:
    from simulator.render import pyplot, save_figure

    plt = pyplot()
    n = len(mets)
    cols = 2 if n > 1 else 1
    rows = -(-n // cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(5.2 * cols, 3.3 * rows), squeeze=False, layout="constrained"
    )
    levels, numeric = _levels(table[axis.column])
    pos = {v: (v if numeric else k) for k, v in enumerate(levels)}
    ok = table["status"] == "ok"
    for ax, (col, label, f) in zip(axes.flat, mets, strict=False):
        x = np.array([pos.get(v, np.nan) for v in table[axis.column]], float)
        y = np.asarray(table[col], float) * f
        m, lo, hi = [], [], []
        for v in levels:
            sel = (x == pos[v]) & ok.to_numpy() & np.isfinite(y)
            m.append(y[sel].mean() if sel.any() else np.nan)
            lo.append(y[sel].min() if sel.any() else np.nan)
            hi.append(y[sel].max() if sel.any() else np.nan)
        xs = [pos[v] for v in levels]
        if table["realization"].max() > 0:
            ax.fill_between(
                xs, lo, hi, color="tab:blue", alpha=0.18, lw=0, label="range over realizations"
            )
            ax.plot(x[ok], y[ok], ".", color="tab:blue", ms=3, alpha=0.6)
        ax.plot(
            xs,
            m,
            "-o",
            color="tab:blue",
            ms=4,
            label="mean" if table["realization"].max() > 0 else None,
        )
        bad = ~ok.to_numpy()
        if bad.any():
            ax.plot(
                x[bad],
                np.full(bad.sum(), np.nanmin(y) if np.isfinite(y).any() else 0.0),
                "x",
                color="tab:red",
                ms=7,
                mew=1.5,
                label="failed",
            )
        ax.set_xlabel(_label(axis))
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if not numeric:
            ax.set_xticks(xs, [str(v) for v in levels], rotation=20 if len(levels) > 4 else 0)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    for ax in axes.flat[n:]:
        ax.set_axis_off()
    fig.suptitle(f"sweep over {axis.name}", fontsize=11)
    save_figure(fig, path)


def plot_heatmap(table, ax_x, ax_y, col: str, label: str, f: float, path: Path, grid: bool) -> None:
    from matplotlib.patches import Rectangle

    from simulator.render import pyplot, save_figure

    plt = pyplot()
    ok = (table["status"] == "ok").to_numpy()
    y_all = np.asarray(table[col], float) * f
    if grid:
        xs, xnum = _levels(table[ax_x.column])
        ys, ynum = _levels(table[ax_y.column])
        ix = {v: k for k, v in enumerate(xs)}
        iy = {v: k for k, v in enumerate(ys)}
        total = np.zeros((len(ys), len(xs)))
        count = np.zeros((len(ys), len(xs)))
        failed = np.zeros((len(ys), len(xs)), bool)
        for vx, vy, v, good in zip(table[ax_x.column], table[ax_y.column], y_all, ok, strict=True):
            if good and np.isfinite(v):
                total[iy[vy], ix[vx]] += v
                count[iy[vy], ix[vx]] += 1
            elif not good:
                failed[iy[vy], ix[vx]] = True
        with np.errstate(invalid="ignore"):
            mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        fig, ax = plt.subplots(
            figsize=(1.2 + 0.9 * max(len(xs), 4), 1.4 + 0.62 * max(len(ys), 3)),
            layout="constrained",
        )
        finite = mean[np.isfinite(mean)]
        vmin, vmax = (finite.min(), finite.max()) if finite.size else (0.0, 1.0)
        if vmin == vmax:
            vmin, vmax = vmin - 0.5 * (abs(vmin) or 1), vmax + 0.5 * (abs(vmax) or 1)
        im = ax.imshow(
            np.ma.masked_invalid(mean),
            origin="lower",
            cmap="viridis",
            vmin=vmin,
            vmax=vmax,
            aspect="auto",
            extent=(-0.5, len(xs) - 0.5, -0.5, len(ys) - 0.5),
        )
        for (r, c), v in np.ndenumerate(mean):
            if np.isfinite(v):
                light = (v - vmin) / (vmax - vmin) < 0.6
                ax.text(
                    c,
                    r,
                    _fmt(v),
                    ha="center",
                    va="center",
                    fontsize=7.5,
                    color="white" if light else "black",
                )
            elif failed[r, c]:
                ax.add_patch(
                    Rectangle(
                        (c - 0.5, r - 0.5), 1, 1, fill=False, hatch="xx", edgecolor="tab:red", lw=0
                    )
                )
                ax.text(
                    c,
                    r,
                    "failed",
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="tab:red",
                    bbox={"boxstyle": "round,pad=0.2", "facecolor": "white", "edgecolor": "none"},
                )
        ax.set_xticks(
            range(len(xs)),
            [_fmt(v) if xnum else str(v) for v in xs],
            rotation=0 if len(xs) < 9 else 45,
        )
        ax.set_yticks(range(len(ys)), [_fmt(v) if ynum else str(v) for v in ys])
        reps = int(table["realization"].max()) + 1
        title = label + (f", mean of {reps} realizations" if reps > 1 else "")
    else:
        fig, ax = plt.subplots(figsize=(6.2, 4.6), layout="constrained")
        x = np.asarray(table[ax_x.column], float)
        y = np.asarray(table[ax_y.column], float)
        im = ax.scatter(
            x[ok], y[ok], c=y_all[ok], cmap="viridis", s=28, edgecolor="k", linewidth=0.3
        )
        if (~ok).any():
            ax.plot(x[~ok], y[~ok], "x", color="tab:red", ms=7, mew=1.5, label="failed")
            ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        title = label
    fig.colorbar(im, ax=ax, label=label, shrink=0.9)
    ax.set_xlabel(_label(ax_x))
    ax.set_ylabel(_label(ax_y))
    ax.set_title(title, fontsize=10)
    save_figure(fig, path)


def plot_effects(table, axes, col: str, label: str, f: float, path: Path) -> None:
    from simulator.render import pyplot, save_figure

    plt = pyplot()
    fig, axs = plt.subplots(
        1, len(axes), figsize=(3.6 * len(axes), 3.2), squeeze=False, layout="constrained"
    )
    ok = (table["status"] == "ok").to_numpy()
    y = np.asarray(table[col], float) * f
    for ax, a in zip(axs.flat, axes, strict=True):
        levels, numeric = _levels(table[a.column])
        pos = {v: (v if numeric else k) for k, v in enumerate(levels)}
        x = np.array([pos.get(v, np.nan) for v in table[a.column]], float)
        ax.plot(x[ok], y[ok], ".", ms=4, alpha=0.7)
        ax.set_xlabel(_label(a))
        ax.grid(alpha=0.3)
        if not numeric:
            ax.set_xticks(list(pos.values()), [str(v) for v in levels])
    axs.flat[0].set_ylabel(label)
    save_figure(fig, path)


def write_pictures(out: Path, spec, table) -> list[str]:
    """Every picture of the sweep into ``out``; returns their file names."""
    mets = metrics(table)
    swept = [a for a in spec.swept if a.column in table.columns]
    if not mets or not swept or not len(table):
        return []
    names = []
    if len(swept) == 1:
        name = f"sweep_{swept[0].name}.png"
        plot_one_axis(table, swept[0], out / name, mets)
        names.append(name)
    elif len(swept) == 2:
        for col, label, f in mets:
            name = f"heatmap_{col}.png"
            plot_heatmap(
                table, swept[0], swept[1], col, label, f, out / name, grid=spec.samples is None
            )
            names.append(name)
    else:
        for col, label, f in mets:
            name = f"effects_{col}.png"
            plot_effects(table, swept, col, label, f, out / name)
            names.append(name)
    return names


def _cell(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    if isinstance(v, float):
        return _fmt(v)
    return html.escape(str(v))


def write_report(out: Path, spec, table, stats: dict) -> list[str]:
    """The pictures and ``report.html``; returns the files written."""
    from foundation import atomic_output

    out = Path(out)
    pics = write_pictures(out, spec, table)
    e = html.escape
    width = max(5, len(str(spec.n_points - 1)))
    axis_cols = [a.column for a in spec.axes]
    shown = [c for c, _, _ in metrics(table)]
    head = "".join(
        f"<th>{e(c)}</th>"
        for c in ["point", "realization", *axis_cols, "status", *shown, "numbers"]
    )
    rows = []
    for _, r in table.head(MAX_ROWS).iterrows():
        link = f'<a href="points/{int(r["point"]):0{width}d}.json">json</a>'
        status = (
            "ok" if r["status"] == "ok" else f'<span class="err">error: {e(str(r["error"]))}</span>'
        )
        cells = [
            _cell(r["point"]),
            _cell(r["realization"]),
            *(_cell(r.get(c)) for c in axis_cols),
            status,
            *(_cell(r.get(c)) for c in shown),
            link,
        ]
        rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    more = (
        f"<p class='note'>The first {MAX_ROWS} of {len(table)} points; every point is in results.csv.</p>"
        if len(table) > MAX_ROWS
        else ""
    )
    axes = "".join(
        f"<tr><td><code>{e(a.name)}</code></td><td>{e(a.column)}</td><td>"
        + (
            e(", ".join(str(v) for v in a.values))
            if a.values is not None
            else f"{a.lo:g} to {a.hi:g} (sampled)"
        )
        + "</td></tr>"
        for a in spec.axes
    )
    n_ok = int((table["status"] == "ok").sum()) if len(table) else 0
    pps = stats.get("points_per_s")
    timing = (
        f"{stats['run_now']} points run now in {stats['run_s']:.1f} s ({pps:.2f} points/s"
        + (f" on {stats['workers']} Dask workers" if stats.get("workers") else " in one process")
        + f"; cluster start {stats['cluster_s']:.1f} s)"
        if pps
        else "no point run now"
    )
    design = spec.design
    pattern = (
        f"design <code>{e(design['name'])}</code> "
        + e(", ".join(f"{k} = {v}" for k, v in design["params"].items()))
        if design
        else "pattern files"
    )
    fx = dict(spec.scene.get("effects") or {})
    effects = ", ".join(
        f"{k} {'on' if v else 'off'}" for k, v in ({"twist": True, "meniscus": False} | fx).items()
    )
    noise = (
        "a draw of its own for every point"
        if spec.independent_noise
        else "the same draws for every design of one realization"
    )
    imgs = "".join(
        f'<figure><img src="{e(p)}" alt="{e(p)}"><figcaption>{e(p)}</figcaption></figure>'
        for p in pics
    )
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>selfalign sweep {e(spec.digest[:12])}</title>
<style>
body {{ font-family: system-ui, sans-serif; max-width: 1200px; margin: 2em auto; color: #222; line-height: 1.4; }}
h1 {{ font-size: 1.5em; }} h2 {{ font-size: 1.15em; margin-top: 1.6em; border-bottom: 1px solid #ccc; }}
table {{ border-collapse: collapse; margin: .5em 0; font-size: .9em; }} td, th {{ border: 1px solid #ccc; padding: 2px 8px; text-align: left; }}
img {{ max-width: 100%; border: 1px solid #ddd; }} figure {{ margin: 0; }} .note {{ color: #555; font-size: .9em; }}
.pics {{ display: grid; grid-template-columns: 1fr 1fr; gap: 1em; }} figcaption {{ font-size: .8em; color: #555; }}
.err {{ color: #b00; }}
</style></head><body>
<h1>selfalign design sweep <code>{e(spec.digest[:12])}</code></h1>
<p class="note">From {e(spec.source)}: {e(spec.shape_text())}, {spec.n_points} points; {pattern}. Each point is the assessment of
<code>selfalign evaluate</code> with the scene's effects ({e(effects)}): {spec.yield_starts} yield starts drawn with the point's
<code>point_seed</code> ({e(noise)}), a capture grid of {spec.capture_grid} starts per side.</p>
<h2>Points</h2>
<p><b>{n_ok}</b> ok, <b>{len(table) - n_ok}</b> failed, {spec.n_points - len(table)} not run; {e(timing)}.
Tables: <a href="results.parquet">results.parquet</a>, <a href="results.csv">results.csv</a> (one row per point, units in the column names);
the sweep: <a href="sweep.json">sweep.json</a>.</p>
<h2>Axes</h2>
<table><tr><th>axis</th><th>column</th><th>values</th></tr>{axes}</table>
<h2>Pictures</h2>
{f'<div class="pics">{imgs}</div>' if imgs else "<p>No picture: nothing swept, or no point succeeded.</p>"}
<h2>Every point</h2>
<table><tr>{head}</tr>{"".join(rows)}</table>{more}
<p class="note">Written by selfalign sweep. Positions in um of the chip centre from the pattern centre; forces in N in the tables.</p>
</body></html>
"""
    with atomic_output(out / "report.html") as tmp:
        tmp.write_text(page)
    return [*pics, "report.html"]
