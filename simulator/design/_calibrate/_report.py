"""The outputs of a calibration: ``fitted.toml`` (a scene file every command reads),
``fit.json``, ``bench.png`` (bench against model per row) and ``report.html``, written
together or not at all (:func:`foundation.atomic_output` for each, moved into place
when every one is ready)."""

from __future__ import annotations

import contextlib
import html
import json
import math
from pathlib import Path

from simulator.design._calibrate._params import FITTABLE, with_values

__all__ = ["scene_toml", "write_outputs"]


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"not a finite number: {v!r}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string is a JSON string
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise ValueError(f"cannot write {type(v).__name__} to TOML")


def scene_toml(doc: dict, header: str = "") -> str:
    """A scene document as TOML text (top-level keys, then one table per sub-dict)."""
    lines = [f"# {line}" for line in header.splitlines()] if header else []

    def emit(d: dict, prefix: str) -> None:
        for k, v in d.items():
            if not isinstance(v, dict):
                lines.append(f"{k} = {_toml_value(v)}")
        for k, v in d.items():
            if isinstance(v, dict):
                name = f"{prefix}{k}"
                lines.append("")
                lines.append(f"[{name}]")
                emit(v, name + ".")

    emit(doc, "")
    return "\n".join(lines) + "\n"


def _plot(result: dict, path: Path) -> None:
    """Yield per row, bench (binomial 1-sigma bars, Wilson) against the fitted model (and
    the scene as given); with times, a second panel of the median time to align."""
    from simulator.render import pyplot

    plt = pyplot()
    rows = result["rows"]
    has_t = any(r["bench_time_s"] is not None for r in rows)
    fig, axes = plt.subplots(1, 2 if has_t else 1, figsize=(11 if has_t else 7, 4.2), squeeze=False)
    ax = axes[0, 0]
    x = list(range(1, len(rows) + 1))
    lo, hi, y = [], [], []
    for r in rows:
        n, k = r["trials"], r["aligned"]
        p = k / n
        z = 1.0
        c = (p + z * z / (2 * n)) / (1 + z * z / n)
        h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
        y.append(p)
        lo.append(max(0.0, p - (c - h)))
        hi.append(max(0.0, (c + h) - p))
    ax.errorbar(
        x, y, yerr=[lo, hi], fmt="o", color="black", capsize=3, label="bench (1-sigma, Wilson)"
    )
    ax.plot(
        x,
        [r["model_yield"] for r in rows],
        "s",
        color="tab:blue",
        mfc="none",
        ms=8,
        label="fitted model",
    )
    if rows and rows[0]["baseline_yield"] is not None:
        ax.plot(
            x, [r["baseline_yield"] for r in rows], "x", color="tab:grey", label="scene as given"
        )
    ax.set_xticks(
        x,
        [f"{r['x_um']:g},{r['y_um']:g},{r['twist_deg']:g}" for r in rows],
        rotation=45,
        ha="right",
        fontsize=8,
    )
    ax.set_xlabel("row: nominal start x, y (um), twist (deg)")
    ax.set_ylabel("yield (aligned fraction)")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    best = ", ".join(f"{k} = {v:.4g} {result['units'][k]}" for k, v in result["best"].items())
    ax.set_title(f"bench against model: {best}", fontsize=9)
    if has_t:
        ax = axes[0, 1]
        xs = [i for i, r in zip(x, rows, strict=True) if r["bench_time_s"] is not None]
        ax.plot(
            xs,
            [1e3 * r["bench_time_s"] for r in rows if r["bench_time_s"] is not None],
            "o",
            color="black",
            label="bench median",
        )
        xm = [i for i, r in zip(x, rows, strict=True) if r["model_time_s"] is not None]
        ax.plot(
            xm,
            [1e3 * r["model_time_s"] for r in rows if r["model_time_s"] is not None],
            "s",
            color="tab:blue",
            mfc="none",
            ms=8,
            label="fitted model median",
        )
        ax.set_xticks(x, [str(r["row"]) for r in rows], fontsize=8)
        ax.set_xlabel("row (line in the table)")
        ax.set_ylabel("time to align (ms)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(f"times: log-normal term, width {result['time_sigma']:g}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def _range_note(r: dict) -> str:
    if not r.get("identified", True):
        return " (not identified: the table does not tell it, or a fitted name trades against it)"
    if r["at_lower_bound"] or r["at_upper_bound"]:
        return " (reaches a bound)"
    return ""


def _page(result: dict) -> str:
    e = html.escape
    units = result["units"]
    prm = "".join(
        f"<tr><td><code>{e(k)}</code></td><td>{v:.4g} {e(units[k])}</td>"
        f"<td>{result['range'][k]['lo']:.4g} .. {result['range'][k]['hi']:.4g}"
        f"{_range_note(result['range'][k])}</td>"
        f"<td>{result['bounds'][k][0]:.4g} .. {result['bounds'][k][1]:.4g}</td>"
        f"<td>{'' if result['baseline'] is None else format(result['baseline'][k], '.4g')}</td></tr>"
        for k, v in result["best"].items()
    )

    def cell(v, f="{:.3g}"):
        return "" if v is None else f.format(v)

    rows = "".join(
        f"<tr><td>{r['row']}</td><td>{r['x_um']:g}, {r['y_um']:g}, {r['twist_deg']:g}</td>"
        f"<td>{r['aligned']} / {r['trials']} ({100 * r['bench_yield']:.1f} %)</td>"
        f"<td>{cell(r['model_yield'] and 100 * r['model_yield'], '{:.1f} %') if r['model_yield'] is not None else ''}</td>"
        f"<td>{cell(r['bench_time_s'] and 1e3 * r['bench_time_s'])}</td><td>{cell(r['model_time_s'] and 1e3 * r['model_time_s'])}</td>"
        f"<td>{cell(r['log_likelihood'], '{:.2f}')}</td></tr>"
        for r in result["rows"]
    )
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>selfalign calibrate {e(result["hash"][:12])}</title>
<style>body{{font-family:sans-serif;max-width:70em;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:.2em .6em;text-align:left}}</style></head><body>
<h1>Calibration against {e(result["source"])}</h1>
<p>Fit {e(result["hash"][:12])}: {result["done"]} of {result["trials"]} trials (Optuna TPE, seed {result["seed"]})
and {result.get("profiled", 0)} points of the parameters' likelihood profiles,
{result["failed"]} failed; {len(result["rows"])} rows, {result["draws"]} Monte Carlo placements per row and
candidate, the same placements for every candidate; method {e(result["method"])}; scene {e(result["scene"])}.
Best: trial {result["best_trial"]}, log-likelihood {result["log_likelihood"]:.3f}
(yield {result["log_likelihood_yield"]:.3f}, time {result["log_likelihood_time"]:.3f}).</p>
<table><tr><th>parameter</th><th>best</th><th>range (Delta log L &le; 0.5)</th><th>bounds</th><th>scene as given</th></tr>{prm}</table>
<p>Range: {e(result["range_means"])}; {result["trials_in_range"]} trials in it.</p>
<p><img src="bench.png" alt="bench against model per row" style="max-width:100%"></p>
<table><tr><th>row</th><th>start x, y (um), twist (deg)</th><th>bench aligned</th><th>model yield</th>
<th>bench time (ms)</th><th>model time (ms)</th><th>log L</th></tr>{rows}</table>
<p>Files: <code>fitted.toml</code> (the scene with the fitted values: <code>selfalign simulate fitted.toml ...</code>),
<code>fit.json</code>, <code>trials.csv</code>.</p>
</body></html>
"""


def write_outputs(out: Path, result: dict, doc: dict, *, pictures: bool = True) -> list[str]:
    """``fitted.toml``, ``fit.json`` and (``pictures``) ``bench.png`` and ``report.html``
    into ``out``, all or none."""
    from foundation import atomic_output, json_text, require_finite

    fitted = with_values(doc, result["best"])
    head = (
        f"selfalign calibrate {result['hash'][:12]}: the scene fitted to {result['source']}\n"
        + "\n".join(
            f"{k} = {v:.6g} {FITTABLE[k].unit} (range {result['range'][k]['lo']:.4g}..{result['range'][k]['hi']:.4g})"
            for k, v in result["best"].items()
        )
    )
    require_finite({k: v for k, v in result.items() if k in ("best", "log_likelihood")}, "fit.json")
    names = ["fitted.toml", "fit.json"] + (["bench.png", "report.html"] if pictures else [])
    with contextlib.ExitStack() as stack:
        tmp = {n: stack.enter_context(atomic_output(out / n)) for n in names}
        Path(tmp["fitted.toml"]).write_text(scene_toml(fitted, head))
        Path(tmp["fit.json"]).write_text(json_text(result))
        if pictures:
            _plot(result, Path(tmp["bench.png"]))
            Path(tmp["report.html"]).write_text(_page(result))
    return names
