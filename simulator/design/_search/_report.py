"""The outputs of a design search besides its table (:func:`simulator.design.search`).

* ``history.png``: every objective per trial (feasible, infeasible, failed), the best so
  far, and the baseline;
* ``pareto.png``: with several objectives the trials in objective space, the Pareto front
  highlighted; with one, the objective against each searched parameter;
* ``best.png``: the best design's pattern beside the baseline's, in um;
* ``best.gds``: the best design's exact polygons (um, :func:`patterns.layout.write_layout`,
  as ``selfalign pattern`` writes a layout);
* ``best.json``: the best trial's parameters, design, objectives and assessment, with the
  baseline's, and with several objectives the whole front;
* ``report.html``: the search, the best against the baseline, the pictures and the trials.

Written atomically (:func:`simulator.render.save_figure`, :func:`foundation.atomic_output`).
"""

from __future__ import annotations

import html
import json
import math
import re
from pathlib import Path

import numpy as np

from simulator.sweep import PointTask, metric

#: The evaluator's numbers set side by side for the best design and the baseline: column,
#: label, factor to the unit shown (:func:`simulator.sweep.metric`).
COMPARED = tuple(
    metric(c)
    for c in (
        "max_bias_x_um",
        "max_bias_y_um",
        "capture_fraction",
        "yield_fraction",
        "stiffness_x_N_per_m",
        "stiffness_y_N_per_m",
        "restoring_force_plus_x_x_N",
        "restoring_force_bias_um",
        "error_limit_um",
        "global_minimum_offset_um",
        "floating_half_width_um",
        "yield_error_x_mean_abs_um",
        "volume_nl",
        "critical_volume_nl",
    )
)
#: The same per footprint protocol, for a scene with ``dispense`` (docs/physics.md §3.5).
PROTOCOL_COMPARED = tuple(
    (f"protocols_{name}_{c}", f"--dispense {name}: {label}", factor)
    for name in ("pattern", "chip")
    for c, label, factor in map(metric, ("max_bias_x_um", "capture_fraction", "yield_fraction"))
)
#: The most trial rows the HTML table shows (the CSV has them all).
MAX_ROWS = 1000


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, float | np.floating):
        v = float(v) + 0.0  # no -0
        return f"{v:.4g}" if abs(v) < 1e5 else f"{v:.4e}"
    return html.escape(str(v))


def _row(table, trial: int) -> dict | None:
    sel = table[table["trial"] == trial]
    return None if not len(sel) else sel.iloc[0].to_dict()


def _row_of(table, trial: int) -> dict:
    """The row of a trial the table holds (a best trial, a member of the front)."""
    row = _row(table, trial)
    assert row is not None, f"trial {trial} is not in the table"
    return row


def _labels(spec) -> list[str]:
    return [f"{o.direction} {o.expression.text}" for o in spec.objectives]


# ----------------------------------------------------------------------- pictures
def plot_history(table, spec, path: Path) -> None:
    """Each objective per trial, the best feasible value so far, and the baseline's value."""
    from simulator.render import pyplot, save_figure

    plt = pyplot()
    k = len(spec.objectives)
    fig, axes = plt.subplots(k, 1, figsize=(7.2, 2.9 * k), squeeze=False, layout="constrained")
    trials = table[table["kind"] == "search"]
    base = _row(table, 0)
    done = (trials["state"] == "complete").to_numpy()
    feas = trials["feasible"].astype(bool).to_numpy()
    t = trials["trial"].to_numpy()
    for j, (ax, o) in enumerate(zip(axes[:, 0], spec.objectives, strict=True)):
        col = f"objective_{j + 1}"
        y = np.asarray(trials[col], dtype=float)
        ax.plot(t[done & feas], y[done & feas], "o", ms=4, color="tab:blue", label="feasible")
        if (done & ~feas).any():
            ax.plot(
                t[done & ~feas], y[done & ~feas], "x", ms=6, color="tab:orange", label="infeasible"
            )
        if (~done).any():
            floor = np.nanmin(y) if np.isfinite(y).any() else 0.0
            ax.plot(
                t[~done],
                np.full((~done).sum(), floor),
                "x",
                ms=7,
                mew=1.5,
                color="tab:red",
                label="failed",
            )
        if k == 1 and (done & feas).any():
            sign = 1.0 if o.direction == "maximize" else -1.0
            vals = np.where(done & feas, sign * y, -np.inf)
            run = np.maximum.accumulate(vals)
            keep = np.isfinite(run)
            ax.step(
                t[keep],
                sign * run[keep],
                where="post",
                color="tab:green",
                lw=1.6,
                label="best so far",
            )
        if base is not None and base.get("state") == "complete":
            ax.axhline(base[col], color="0.3", ls="--", lw=1, label="baseline (trial 0)")
        ax.set_ylabel(f"objective {j + 1}")
        ax.set_title(f"{o.direction} {o.expression.text}", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[-1, 0].set_xlabel("trial")
    save_figure(fig, path)


def _front_line(ax, x, y) -> None:
    order = np.argsort(x)
    ax.plot(x[order], y[order], "-", color="tab:red", lw=1, alpha=0.6)


def plot_pareto(table, spec, best: list[int], path: Path) -> None:
    """Several objectives: each pair in objective space, the front in red. One objective: the
    objective against each searched parameter, the best trial in red, the baseline's line."""
    from simulator.render import pyplot, save_figure

    plt = pyplot()
    trials = table[(table["kind"] == "search") & (table["state"] == "complete")]
    feas = trials["feasible"].astype(bool).to_numpy()
    front = trials["trial"].isin(best).to_numpy()
    base = _row(table, 0)
    k = len(spec.objectives)
    if k > 1:
        pairs = [(a, b) for a in range(k) for b in range(a + 1, k)]
        fig, axes = plt.subplots(
            1, len(pairs), figsize=(5.4 * len(pairs), 4.4), squeeze=False, layout="constrained"
        )
        for ax, (a, b) in zip(axes[0], pairs, strict=True):
            x = np.asarray(trials[f"objective_{a + 1}"], dtype=float)
            y = np.asarray(trials[f"objective_{b + 1}"], dtype=float)
            ax.plot(
                x[feas & ~front],
                y[feas & ~front],
                "o",
                ms=4,
                color="tab:blue",
                alpha=0.6,
                label="feasible",
            )
            if (~feas).any():
                ax.plot(x[~feas], y[~feas], "x", ms=5, color="tab:orange", label="infeasible")
            ax.plot(x[front], y[front], "o", ms=7, color="tab:red", label="Pareto front")
            if front.sum() > 1 and k == 2:
                _front_line(ax, x[front], y[front])
            if base is not None and base.get("state") == "complete":
                ax.plot(
                    [base[f"objective_{a + 1}"]],
                    [base[f"objective_{b + 1}"]],
                    "*",
                    ms=13,
                    color="0.25",
                    label="baseline",
                )
            ax.set_xlabel(_labels(spec)[a], fontsize=8)
            ax.set_ylabel(_labels(spec)[b], fontsize=8)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        fig.suptitle("trials in objective space", fontsize=11)
    else:
        axes_ = [a for a in spec.searched if a.column in trials.columns]
        n = max(1, len(axes_))
        fig, axes = plt.subplots(1, n, figsize=(4.6 * n, 3.8), squeeze=False, layout="constrained")
        y = np.asarray(trials["objective_1"], dtype=float)
        for ax, a in zip(axes[0], axes_, strict=False):
            raw = trials[a.column].tolist()
            numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in raw)
            levels = list(dict.fromkeys(raw))
            x = (
                np.asarray(raw, dtype=float)
                if numeric
                else np.array([levels.index(v) for v in raw], float)
            )
            ax.plot(x[feas], y[feas], "o", ms=4, color="tab:blue", alpha=0.7, label="feasible")
            if (~feas).any():
                ax.plot(x[~feas], y[~feas], "x", ms=6, color="tab:orange", label="infeasible")
            ax.plot(x[front], y[front], "o", ms=9, mfc="none", mew=2, color="tab:red", label="best")
            if base is not None and base.get("state") == "complete":
                ax.axhline(base["objective_1"], color="0.3", ls="--", lw=1, label="baseline")
            if not numeric:
                ax.set_xticks(range(len(levels)), [str(v) for v in levels])
            from simulator.sweep import column_label

            ax.set_xlabel(column_label(a.column))
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        axes[0][0].set_ylabel(_labels(spec)[0], fontsize=8)
        fig.suptitle("the objective against each searched parameter", fontsize=11)
    save_figure(fig, path)


def _task(spec, values: dict) -> PointTask:
    """The task of the design of search ``values`` (its first realization), as a trial runs it."""
    sw = spec.sweep
    return sw.task(sw.point(values, 0, 0))


def plot_best(spec, best_values: dict, base_values: dict | None, title: str, path: Path) -> None:
    """The best design's pattern (as its trial's scene rasterizes it) beside the baseline's."""
    from simulator.render import pyplot, save_figure
    from simulator.sweep import point_scene

    plt = pyplot()
    panels = [("best: " + title, best_values)]
    if base_values is not None:
        panels.insert(0, ("baseline (trial 0)", base_values))
    fig, axes = plt.subplots(
        1, len(panels), figsize=(4.8 * len(panels), 4.6), squeeze=False, layout="constrained"
    )
    im = None
    for ax, (label, values) in zip(axes[0], panels, strict=True):
        mask = point_scene(_task(spec, values))[0].pattern
        im = ax.imshow(
            mask.data, extent=mask.extent_um, cmap="gray", vmin=0, vmax=1, interpolation="nearest"
        )
        ax.plot([0], [0], "+", color="C3", ms=10, mew=1.5)
        ax.set(xlabel="x (µm)", ylabel="y (µm)")
        ax.set_title(f"{label}\n({mask.um_per_px:g} µm/px)", fontsize=9)
    assert im is not None  # one panel at least
    fig.colorbar(im, ax=list(axes[0]), shrink=0.8, label="wettability (1 = pad)")
    save_figure(fig, path)


# ----------------------------------------------------------------------- files
def _design_of(spec, values: dict) -> dict | None:
    from simulator.sweep import design_params

    if spec.sweep.design is None:
        return None
    task = _task(spec, values)
    return {
        "name": spec.sweep.design["name"],
        "params": design_params(task),
        "margin_um": spec.sweep.design["margin_um"],
    }


def _json_row(row: dict | None) -> dict | None:
    if row is None:
        return None
    out = {}
    for k, v in row.items():
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, float) and not math.isfinite(v):
            v = None
        out[k] = v
    return out


def _row_json(table, trial: int) -> dict:
    """:func:`_row_of` as the JSON holds it (:func:`_json_row`)."""
    row = _json_row(_row_of(table, trial))
    assert row is not None
    return row


def _values(spec, row: dict) -> dict:
    return {
        a.name: row[a.column]
        for a in spec.sweep.axes
        if a.column in row
        and row[a.column] is not None
        and not (isinstance(row[a.column], float) and math.isnan(row[a.column]))
    }


def write_best(out: Path, spec, table, best: list[int]) -> list[str]:
    """``best.json`` (always), and with a best design ``best.png`` and ``best.gds``."""
    from foundation import atomic_output, json_text

    written = []
    base = _json_row(_row(table, 0))
    doc: dict = {"best": None, "baseline": None}
    if base is not None:
        doc["baseline"] = {
            "trial": 0,
            "design": _design_of(spec, spec.baseline_values() or {}),
            "row": base,
        }
    top = None
    if best:
        top = best[0]
        if len(spec.objectives) > 1:  # the front member best on the first objective
            sub = table[table["trial"].isin(best)]
            asc = spec.objectives[0].direction == "minimize"
            top = int(
                sub.sort_values(["objective_1", "trial"], ascending=[asc, True]).iloc[0]["trial"]
            )
        row = _json_row(_row_of(table, top))
        assert row is not None
        values = _values(spec, row)
        doc["best"] = {
            "trial": top,
            "values": values,
            "design": _design_of(spec, values),
            "objectives": [
                {
                    "direction": o.direction,
                    "expression": o.expression.text,
                    "value": row[f"objective_{j + 1}"],
                }
                for j, o in enumerate(spec.objectives)
            ],
            "constraints": [
                {"constraint": c.text, "violation": row[f"constraint_{j + 1}"]}
                for j, c in enumerate(spec.constraints)
            ],
            "row": row,
        }
        if len(spec.objectives) > 1:
            doc["pareto_front"] = [
                {
                    "trial": t,
                    "values": _values(spec, _row_of(table, t)),
                    "objectives": [
                        _row_json(table, t)[f"objective_{j + 1}"]
                        for j in range(len(spec.objectives))
                    ],
                }
                for t in best
            ]
        title = f"trial {top}, " + ", ".join(
            f"{k} = {_fmt(v)}" for k, v in values.items() if k in {a.name for a in spec.searched}
        )
        plot_best(spec, values, spec.baseline_values() if base else None, title, out / "best.png")
        written.append("best.png")
        if spec.sweep.design is not None:
            from patterns.layout import write_layout
            from simulator.sweep import point_geometry

            geometry, _ = point_geometry(_task(spec, values))
            write_layout(out / "best.gds", geometry, cell=spec.sweep.design["name"])
            written.append("best.gds")
            doc["best"]["gds_area_um2"] = geometry.area
    with atomic_output(out / "best.json") as tmp:
        tmp.write_text(json_text(doc, indent=1, default=str))
    return ["best.json", *written]


def _compare_table(spec, table, top: int | None) -> str:
    base, best = _row(table, 0), _row(table, top) if top is not None else None
    if best is None and base is None:
        return "<p>No trial finished.</p>"
    cols = [
        (f"objective_{j + 1}", f"objective {j + 1}: {lab}", 1.0)
        for j, lab in enumerate(_labels(spec))
    ]
    cols += [c for c in COMPARED + PROTOCOL_COMPARED if c[0] in table.columns]
    shown = {c[0] for c in cols}
    for c in spec.constraints:  # every column a constraint reads, as the table holds it
        for name in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", c.text):
            if name in table.columns and name not in shown:
                shown.add(name)
                cols.append((name, f"constraint {c.text}: {name}", 1.0))
    rows = []
    for col, label, f in cols:
        cells = []
        for r in (base, best):
            v = None if r is None else r.get(col)
            cells.append(
                _fmt(
                    v * f
                    if isinstance(v, int | float) and v is not None and math.isfinite(v)
                    else v
                )
            )
        rows.append(f"<tr><td>{html.escape(label)}</td><td>{cells[0]}</td><td>{cells[1]}</td></tr>")
    params = []
    for a in spec.searched:
        bv = spec.baseline_settings().get(a.name, "(default)") if base is not None else ""
        params.append(
            f"<tr><td><code>{html.escape(a.name)}</code></td><td>{_fmt(bv)}</td>"
            f"<td>{_fmt(best.get(a.column)) if best else ''}</td></tr>"
        )
    head = (
        f"<tr><th></th><th>baseline (trial 0)</th><th>best (trial {top})</th></tr>"
        if top is not None
        else "<tr><th></th><th>baseline (trial 0)</th><th>best: none</th></tr>"
    )
    return f"<table>{head}{''.join(params)}{''.join(rows)}</table>"


def write_search_report(out: Path, spec, table, stats: dict) -> list[str]:
    """The pictures, the best design's files and ``report.html``; returns the files written."""
    from foundation import atomic_output

    out = Path(out)
    best = stats["best"]
    pics = []
    if len(table) and (table["kind"] == "search").any():
        plot_history(table, spec, out / "history.png")
        plot_pareto(table, spec, best, out / "pareto.png")
        pics = ["history.png", "pareto.png"]
    files = write_best(out, spec, table, best)
    top = json.loads((out / "best.json").read_text())["best"]
    top = top["trial"] if top else None
    e = html.escape
    shown = [c for c, _, _ in COMPARED if c in table.columns]
    cols = [
        "trial",
        "kind",
        *[a.column for a in spec.searched],
        "state",
        "same_as",
        *[f"objective_{j + 1}" for j in range(len(spec.objectives))],
        "feasible",
        *shown,
    ]
    cols = [c for c in cols if c in table.columns]
    width = 5
    body = []
    for _, r in table.head(MAX_ROWS).iterrows():
        cls = ' class="best"' if r.get("best") else ""
        cells = [_fmt(r.get(c)) for c in cols]
        if r.get("state") != "complete":
            cells[cols.index("state")] = f'<span class="err">fail: {e(str(r.get("error")))}</span>'
        link = f'<a href="trials/{int(r["trial"]):0{width}d}.json">json</a>'
        body.append(f"<tr{cls}>" + "".join(f"<td>{c}</td>" for c in [*cells, link]) + "</tr>")
    more = (
        f"<p class='note'>The first {MAX_ROWS} of {len(table)} trials; every trial is in trials.csv.</p>"
        if len(table) > MAX_ROWS
        else ""
    )
    objectives = "".join(
        f"<li>{e(o.direction)} <code>{e(o.expression.text)}</code></li>" for o in spec.objectives
    )
    constraints = (
        "".join(f"<li><code>{e(c.text)}</code></li>" for c in spec.constraints) or "<li>none</li>"
    )
    axes = "".join(
        f"<tr><td><code>{e(a.name)}</code></td><td>{e(a.column)}</td><td>"
        + (
            e(", ".join(str(v) for v in a.values))
            if a.values is not None
            else f"{a.lo:g} to {a.hi:g} (continuous)"
        )
        + "</td></tr>"
        for a in spec.searched
    )
    n_fail = int((table["state"] != "complete").sum()) if len(table) else 0
    n_feas = (
        int(((table["kind"] == "search") & table["feasible"].astype(bool)).sum())
        if len(table)
        else 0
    )
    exhausted = (
        f" Every one of the space's {stats['space_size']} designs was tried, so the search stopped there."
        if stats.get("exhausted")
        else ""
    )
    front = ""
    if len(spec.objectives) > 1:
        front = f"<p>Pareto front: trials {e(', '.join(str(t) for t in best)) or 'none'} (highlighted below).</p>"
    note = ""
    if (
        top is not None
        and (b := _row(table, 0)) is not None
        and b.get("state") == "complete"
        and b.get("feasible")
    ):
        o = spec.objectives[0]
        bv, tv = b["objective_1"], _row_of(table, top)["objective_1"]
        if (bv > tv) if o.direction == "maximize" else (bv < tv):
            note = "<p class='err'>The baseline does better on the first objective than every trial.</p>"
    imgs = "".join(
        f'<figure><img src="{p}" alt="{p}"><figcaption>{p}</figcaption></figure>'
        for p in [*pics, *(["best.png"] if "best.png" in files else [])]
    )
    rate = (
        f"{stats['evaluated_now']} designs evaluated now in {stats['run_s']:.1f} s"
        + (f" on {stats['workers']} Dask workers" if stats.get("workers") else " in one process")
        if stats.get("evaluated_now")
        else "no design evaluated now"
    )
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>selfalign design search {e(spec.digest[:12])}</title>
<style>
body {{ font-family: system-ui, sans-serif; max-width: 1200px; margin: 2em auto; color: #222; line-height: 1.4; }}
h1 {{ font-size: 1.5em; }} h2 {{ font-size: 1.15em; margin-top: 1.6em; border-bottom: 1px solid #ccc; }}
table {{ border-collapse: collapse; margin: .5em 0; font-size: .9em; }} td, th {{ border: 1px solid #ccc; padding: 2px 8px; text-align: left; }}
img {{ max-width: 100%; border: 1px solid #ddd; }} figure {{ margin: 0; }} .note {{ color: #555; font-size: .9em; }}
.pics {{ display: grid; grid-template-columns: 1fr 1fr; gap: 1em; }} figcaption {{ font-size: .8em; color: #555; }}
.err {{ color: #b00; }} tr.best {{ background: #e6f4e6; font-weight: bold; }}
</style></head><body>
<h1>selfalign design search <code>{e(spec.digest[:12])}</code></h1>
<p class="note">From {e(spec.source)}: {stats["trials"]} trials of Optuna's {e(spec.sampler)} sampler (seed {spec.seed}) over
{e(", ".join(a.name for a in spec.searched))}; each trial is the assessment of <code>selfalign evaluate</code> as a sweep point
({f"the mean of {spec.sweep.realizations} realizations, " if spec.sweep.realizations > 1 else ""}{spec.sweep.yield_starts} yield starts,
a capture grid of {spec.sweep.capture_grid} per side). Trial 0 is the baseline: the file's [design] and [scene] values.</p>
<h2>Objectives and constraints</h2>
<ul>{objectives}</ul><p>Constraints (a trial that misses one is recorded, never best):</p><ul>{constraints}</ul>
<h2>Trials</h2>
<p><b>{stats["done"]}</b> trials, {n_feas} feasible, {n_fail} failed; {e(rate)}.{e(exhausted)}
Tables: <a href="trials.parquet">trials.parquet</a>, <a href="trials.csv">trials.csv</a>; the search: <a href="search.json">search.json</a>;
the best design: <a href="best.json">best.json</a>{', <a href="best.gds">best.gds</a>' if "best.gds" in files else ""}.</p>
{front}
<h2>The best design against the baseline</h2>
{_compare_table(spec, table, top)}{note}
<h2>Search space</h2>
<table><tr><th>axis</th><th>column</th><th>values</th></tr>{axes}</table>
<h2>Pictures</h2>
{f'<div class="pics">{imgs}</div>' if imgs else "<p>No picture: no trial finished.</p>"}
<h2>Every trial</h2>
<table><tr>{"".join(f"<th>{e(c)}</th>" for c in [*cols, "numbers"])}</tr>{"".join(body)}</table>{more}
<p class="note">Written by selfalign design. Positions in um; forces in N in the tables.</p>
</body></html>
"""
    with atomic_output(out / "report.html") as tmp:
        tmp.write_text(page)
    return [*pics, *files, "report.html"]
