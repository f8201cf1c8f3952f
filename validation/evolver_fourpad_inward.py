#!/usr/bin/env python3
"""Surface Evolver: INWARD continuation over the four-pad pattern (hysteresis check).

Companion of ``validation/evolver_fourpad.py`` (imported as a module, not modified): same
set-up (chip of side L = 730 um over a four-pad pattern, pads 30 deg, substrate 60 deg,
free substrate contact line on the smoothed wettability map, chip edges pinned, free chip
height, V = 20 nl), same schedule (``evolver_fourpad.Schedule``) and same in-run envelope
force, but the path of poses runs the other way: the chip starts offset at x = 500 um
(y = 0) and moves INWARD

    x = 500, 475, 450, 440, 430, ..., 300, 250, 200, 150, 100, 50, 0

in one Evolver process, each pose starting from the previous converged surface.  The first
surface is the harness's own first-pose surface (``evolver_fourpad.datafile``): vertical
walls from the chip edges down to z = 0, i.e. the liquid initially covers exactly the chip
footprint ``[x - L/2, x + L/2] x [-L/2, L/2]`` = ``[135, 865] x [-365, 365]`` at x = 500,
which does not reach the left pads (``x <= -g/2``).  The outward path of the harness
(x = 0 -> 500) is on the other side of any hysteresis loop; this script compares the two.

Output: ``validation/evolver_fourpad_inward.csv`` (the harness's pose-CSV columns, a
``direction`` column = ``inward``, then the per-level fields of the harness's level CSV that
the pose CSV lacks; one row per path, level and pose; rewritten atomically after every
pose) and ``validation/FOURPAD_INWARD.md`` (set-up, side-by-side table against the outward
rows of ``validation/evolver_fourpad_levels.csv`` at the same level and x).

Run::

    python validation/evolver_fourpad_inward.py --gaps 50,100 --levels 1
    python validation/evolver_fourpad_inward.py --gaps 100 --levels 2 --append
    python validation/evolver_fourpad_inward.py --report      # only rewrite the .md

Stdlib + numpy (through the harness).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import hashlib
import math
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.dont_write_bytecode = True  # leave validation/__pycache__ alone
sys.path.insert(0, str(HERE))
import evolver_fourpad as ef  # noqa: E402
import numpy as np  # noqa: E402

OUT = HERE / "evolver_fourpad_inward.csv"
MD = HERE / "FOURPAD_INWARD.md"
OUTWARD_LEVELS = HERE / "evolver_fourpad_levels.csv"
OUTWARD_POSES = HERE / "evolver_fourpad.csv"
NOTES_MARK = "<!-- notes: text below this line is kept when the report is regenerated -->"

EXTRA = [c for c in ef.LEVEL_COLUMNS if c not in ef.COLUMNS]
COLUMNS = list(ef.COLUMNS) + ["direction"] + EXTRA


def inward_xs() -> list[float]:
    return (
        [500.0, 475.0, 450.0]
        + [float(x) for x in range(440, 299, -10)]
        + [250.0, 200.0, 150.0, 100.0, 50.0, 0.0]
    )


DIAG = "_x0diag"
# diagnostic tail after the last pose (x = 0): each entry is run, then reported (pose 24, 25, ...)
DIAG_STEPS = (
    ("one more harness qrelax round", "qrelax"),
    ("g 1000 (conjugate gradient), Newton loop", "g 1000; qconv"),
    (
        "u; V; g 2000; u; V; Newton loop; g 1000; Newton loop",
        "u; V; g 2000; u; V; qconv; g 1000; qconv",
    ),
)


def inward_paths(gaps: list[float], diag: bool = False, stop: float = 0.0) -> list[ef.Path_]:
    """The inward paths (ending at x = ``stop``); with ``diag`` the last pose is followed by
    the ``DIAG_STEPS`` (more relaxation at that x, each reported)."""
    xs = [x for x in inward_xs() if x >= stop]
    xs = xs + ([xs[-1]] * len(DIAG_STEPS) if diag else [])
    return [
        ef.Path_(f"x_730_{g:g}_inward", 730.0, g, 2.0e7, tuple((x, 0.0) for x in xs)) for g in gaps
    ]


def n_main(p: ef.Path_) -> int:
    """Poses of ``p`` before its diagnostic tail (a tail repeats the last pose)."""
    k = len(DIAG_STEPS)
    if (
        len(p.poses) > k
        and len({p.poses[i] for i in range(len(p.poses) - k - 1, len(p.poses))}) == 1
    ):
        return len(p.poses) - k
    return len(p.poses)


def diag_name(p: ef.Path_) -> str:
    x = p.poses[-1][0]
    return p.name + (DIAG if abs(x) < 1e-9 else f"_x{x:g}diag")


def is_diag(name: str) -> bool:
    return name.endswith("diag")


def diag_path(p: ef.Path_) -> ef.Path_:
    return dataclasses.replace(p, name=diag_name(p), poses=p.poses[n_main(p) :])


_harness_command_file = ef.command_file


def command_file_with_diag(p: ef.Path_, s: ef.Schedule) -> str:
    """The harness's command file for the inward poses, then the diagnostic tail."""
    n = n_main(p)
    text = _harness_command_file(dataclasses.replace(p, poses=p.poses[:n]), s)
    if len(p.poses) == n:
        return text
    assert text.endswith("quit 0\n")
    text = text[: -len("quit 0\n")]
    for k, (_, cmd) in enumerate(DIAG_STEPS):
        text += f"qpose := {n + k}; {cmd}; qreport\n"
    return text + "quit 0\n"


_last_edges: dict[int, object] = {}
_harness_cl_stats = ef.contact_line_stats


def cl_stats_keep(edges, L, g):
    """The harness's contact_line_stats, plus: where the left contact line reaches beyond its
    crossing of y = 0 (printed for the diagnostic poses)."""
    st = _harness_cl_stats(edges, L, g)
    x0 = st["cl_xmin_y0_um"]
    pts = edges[:, :2]
    far = pts[pts[:, 0] < x0 - 5.0]
    _last_edges["lobe"] = (
        len(far),
        float(far[:, 1].min()) if len(far) else float("nan"),
        float(far[:, 1].max()) if len(far) else float("nan"),
        float(pts[:, 0].min()),
        float(pts[np.argmin(pts[:, 0]), 1]),
    )
    return st


def harness_sha() -> str:
    return hashlib.sha256(Path(ef.__file__).read_bytes()).hexdigest()[:16]


# ----------------------------------------------------------------------------
# rows


def out_rows(lrows: list[dict[str, str]], paths: list[ef.Path_]) -> list[dict[str, str]]:
    """One row per (path, level, pose): the harness's pose row of that level (compared with
    the next coarser level when there is one), plus direction and the extra level fields."""
    rows: list[dict[str, str]] = []
    names = []
    for r in lrows:
        if r["path"] not in names:
            names.append(r["path"])
    meta = {p.name: p for p in paths}
    for name in names:
        mine = [r for r in lrows if r["path"] == name]
        if is_diag(name):  # repeated poses: level rows as they are, in run order
            p = meta.get(name)
            for lr in mine:
                row = {
                    **lr,
                    "theta_pad_deg": ef._f(p.theta_p if p else ef.Path_.theta_p),
                    "theta_sub_deg": ef._f(p.theta_s if p else ef.Path_.theta_s),
                    "direction": "inward",
                }
                rows.append({k: row.get(k, "") for k in COLUMNS})
            continue
        levels = sorted({int(r["level"]) for r in mine})
        for lev in levels:
            sub = [r for r in mine if int(r["level"]) <= lev]
            src = {(r["x_um"], r["y_um"]): r for r in mine if int(r["level"]) == lev}
            for pr in ef.pose_rows(sub, paths):
                if pr["level"] != str(lev):
                    continue
                lr = src.get((pr["x_um"], pr["y_um"]), {})
                row = {**pr, "direction": "inward", **{k: lr.get(k, "") for k in EXTRA}}
                rows.append({k: row.get(k, "") for k in COLUMNS})
    return rows


def level_rows_from_out(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    """Back to the harness's level rows; undo the flags that ``pose_rows`` adds (the level flag
    is ok / volume_drift / newton_not_settled [;cl_stats_error] / failed: ...)."""
    out = []
    for r in rows:
        lr = {k: r.get(k, "") for k in ef.LEVEL_COLUMNS}
        if lr["flag"] == "single_level" or lr["flag"].startswith("prev_level_"):
            lr["flag"] = "ok"
        out.append(lr)
    return out


# ----------------------------------------------------------------------------
# report


DF_BIG = 1.0  # uN; "differs" threshold of the report


def _xk(s: str) -> float:  # pose x as a key (the path's x carries 1e-13 round-off)
    return round(_fl(s), 3) + 0.0


def _fl(s: str) -> float:
    try:
        return float(s)
    except (TypeError, ValueError):
        return float("nan")


def _uN(s: str) -> str:
    v = _fl(s)
    return "" if math.isnan(v) else f"{v * 1e6:+.3f}"


def _w(s: str) -> str:
    return {"True": "yes", "False": "no"}.get(s, "-" if not s else s)


def _num(v: float, fmt: str) -> str:
    return "" if math.isnan(v) else format(v, fmt)


def _flag(s: str) -> str:
    return "" if s in ("ok", "single_level", "") else s.replace("newton_not_settled", "nns")


def report(runtime_note: str = "") -> str:
    inn = ef.read_csv(OUT) if OUT.exists() else []
    outl = ef.read_csv(OUTWARD_LEVELS) if OUTWARD_LEVELS.exists() else []
    outp = ef.read_csv(OUTWARD_POSES) if OUTWARD_POSES.exists() else []
    L = [
        "# Four-pad chip: inward vs outward continuation (force hysteresis along x)",
        "",
        f"Generated by `validation/evolver_fourpad_inward.py` on {dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC; "
        f"harness `validation/evolver_fourpad.py` sha256 {harness_sha()}… (imported, not modified).",
        "",
        "## Set-up",
        "",
        "* Same model and schedule as `evolver_fourpad.py` (its `Path_`, `Schedule`, `datafile`, "
        "`command_file`, `run_path`, `contact_line_stats`, `level_row`, `pose_rows`): chip L = 730 um over "
        "four pads (outer size 730 um, cross-shaped gap g = 50 or 100 um), pads 30 deg, substrate 60 deg, "
        "smoothing width 4 um, V = 2.0e7 um^3 (20 nl), chip edges pinned, free chip height (`chipz` "
        "optimizing parameter), free substrate contact line; F_x = in-run envelope derivative "
        "(+-0.05 um shear, Lagrange-corrected), `force_x_fd_N` = +-2.5 um relaxed finite difference; "
        "gamma = 0.072 N/m.",
        "* Path: x = 500, 475, 450, 440, 430, ..., 300, 250, 200, 150, 100, 50, 0 um (y = 0) in one Evolver "
        "process, each pose started from the previous converged surface (chip moved, free vertices "
        "translated, then the harness's `qrelax`).  All these x are poses of the outward path too.",
        "* Initial surface at x = 500: the harness's first-pose datafile, i.e. vertical walls from the chip "
        "edges to z = 0 at h0 = V/L^2 = 37.5 um: the liquid starts covering exactly the chip footprint "
        "x in [135, 865], |y| <= 365, which does NOT reach the left pads (x <= -g/2).  It is then relaxed "
        "(`U; g 50; u; V; g 50; qconv`, refined to the level with `qrelax` after each `r`) before pose 0 is "
        "reported.",
        "* Outward values: `validation/evolver_fourpad_levels.csv`, rows `x_730_<g>` at the SAME refinement "
        "level (level 1 vs level 1, level 2 vs level 2).  `left wet` = harness's `left_pads_wetted` "
        "(wetted area on the sharp left pads > 1 um^2); `xmin(y=0)` = leftmost contact-line crossing of "
        "y = 0 (the left pads start at x = -g/2).",
        "* Flags: `nns` = newton_not_settled (last hessian_seek still lowered E by more than the "
        "harness's tolerance).",
        "",
    ]
    inn_paths = []
    for r in inn:
        key = (r["path"], r["level"])
        if key not in inn_paths and not is_diag(r["path"]):
            inn_paths.append(key)
    summary: list[str] = []
    inn_paths.sort(key=lambda t: (_fl(t[0].split("_")[2]), int(t[1])))
    for name, lev in inn_paths:
        g = name.split("_")[2]
        oname = f"x_730_{g}"
        orows = {
            _xk(r["x_um"]): r
            for r in outl
            if r["path"] == oname and r["level"] == lev and r["energy_gamma_um2"]
        }
        irows = [r for r in inn if r["path"] == name and r["level"] == lev]
        L += [
            f"## g = {g} um, level {lev}",
            "",
            "| x um | F_x out uN | F_x in uN | dF in-out uN | F_fd out | F_fd in | left wet out/in | "
            "xmin(y=0) out/in um | chip z out/in um | E in-out gamma um^2 | s/pose in | flags out/in |",
            "|---:|---:|---:|---:|---:|---:|:---:|---:|---:|---:|---:|:---|",
        ]
        diffs = []
        for r in irows:
            if not r["energy_gamma_um2"]:
                L.append(f"| {_xk(r['x_um']):g} | | FAILED | | | | | | | | | {r['flag']} |")
                continue
            o = orows.get(_xk(r["x_um"]), {})
            fi, fo = _fl(r["force_x_N"]) * 1e6, _fl(o.get("force_x_N", "")) * 1e6
            dF = fi - fo
            dE = _fl(r["energy_gamma_um2"]) - _fl(o.get("energy_gamma_um2", ""))
            wi, wo = r["left_pads_wetted"], o.get("left_pads_wetted", "")
            L.append(
                f"| {_xk(r['x_um']):g} | {_num(fo, '+.3f')} | {fi:+.3f} | {_num(dF, '+.3f')} | "
                f"{_uN(o.get('force_x_fd_N', ''))} | {_uN(r['force_x_fd_N'])} | {_w(wo)}/{_w(wi)} | "
                f"{_num(_fl(o.get('cl_xmin_y0_um', '')), '.1f')}/{_num(_fl(r['cl_xmin_y0_um']), '.1f')} | "
                f"{_num(_fl(o.get('chip_height_um', '')), '.2f')}/{_num(_fl(r['chip_height_um']), '.2f')} | "
                f"{_num(dE, '+.0f')} | {_num(_fl(r['seconds']), '.1f')} | "
                f"{_flag(o.get('flag', ''))}/{_flag(r['flag'])} |"
            )
            if wi != wo or (not math.isnan(dF) and abs(dF) > DF_BIG):
                diffs.append((_xk(r["x_um"]), fo, fi, dF, wo, wi, dE))
        secs = [_fl(r["seconds"]) for r in irows if r["seconds"]]
        L += [
            "",
            f"{len([r for r in irows if r['energy_gamma_um2']])} of {len(inward_xs())} poses finished; "
            f"inward wall time {sum(secs):.0f} s ({sum(secs) / max(len(secs), 1):.1f} s/pose, first pose "
            f"includes the set-up and refinement).",
            "",
        ]
        if diffs:
            L.append(
                f"Poses where the branches differ (left-pad wetting differs, or |dF| > {DF_BIG:g} uN; "
                "for scale: away from the loop the two branches agree to ~0.1-0.8 uN at level 1, "
                "which is the mesh/relaxation noise of this level):"
            )
            L.append("")
            for x, fo, fi, dF, wo, wi, dE in diffs:
                L.append(
                    f"* x = {x:g}: F_x out {fo:+.3f}, in {fi:+.3f} uN (dF {dF:+.3f} uN"
                    + (f", {100 * dF / abs(fo):+.0f} %" if abs(fo) > 1 else "")
                    + f"); left pads wetted out/in {_w(wo)}/{_w(wi)}; E_in - E_out = {dE:+.0f} gamma um^2"
                )
            L.append("")
        else:
            L += [f"No pose differs by wetting state or by more than {DF_BIG:g} uN.", ""]
        summary.append(f"{name} L{lev}: {len(diffs)} differing poses")
    diag = [r for r in inn if is_diag(r["path"])]
    if diag:
        L += [
            "## Diagnostic: further relaxation at a fixed pose (x = 0, 380, 400)",
            "",
            f"Paths `*{DIAG}`: in the same Evolver run, after the inward path's last pose (x = 0 for `*_x0diag`, X for `*_x<X>diag`), "
            "these steps, each followed by the harness's report: "
            + "; ".join(f"row {k}: `{c}` ({d})" for k, (d, c) in enumerate(DIAG_STEPS))
            + ".  Row -1 = the "
            "inward pose itself as the path reached it (for `*_x0diag` copied from the main table; "
            "`*_x<X>diag` paths ran the inward path only down to x = X, same poses as the main path).",
            "",
            "| path | level | row | x um | F_x uN | E gamma um^2 | xmin(y=0) | xmax(y=0) | chip z | last dE | flag |",
            "|:---|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---|",
        ]
        seq = []
        for r in diag:
            key = (r["path"], r["level"])
            n_d = sum(1 for q in diag if (q["path"], q["level"]) == key)
            if n_d == len(DIAG_STEPS) and not any(key == (q["path"], q["level"]) for q in seq):
                seq += [
                    {**q, "path": r["path"]}
                    for q in inn
                    if q["path"] == r["path"][: -len(DIAG)]
                    and q["level"] == r["level"]
                    and q["energy_gamma_um2"]
                    and abs(_fl(q["x_um"])) < 1e-6
                ]
            seq.append(r)
        k = {}
        for r in seq:
            key = (r["path"], r["level"])
            k[key] = k.get(key, -2) + 1
            L.append(
                f"| {r['path']} | {r['level']} | {k[key]} | {_xk(r['x_um']):g} | {_uN(r['force_x_N'])} | "
                f"{_num(_fl(r['energy_gamma_um2']), '.1f')} | {_num(_fl(r['cl_xmin_y0_um']), '.2f')} | "
                f"{_num(_fl(r['cl_xmax_y0_um']), '.2f')} | {_num(_fl(r['chip_height_um']), '.3f')} | "
                f"{_num(_fl(r['last_newton_dE']), '.2g')} | {r['flag']} |"
            )
        L.append("")
    if outp:
        L += [
            "Outward pose CSV `validation/evolver_fourpad.csv` (finest level per pose) was read for "
            "reference only; the tables above compare level by level.",
            "",
        ]
    if runtime_note:
        L += ["## Runtime", "", runtime_note, ""]
    L += [
        "## Rerun",
        "",
        "```",
        "python validation/evolver_fourpad_inward.py --gaps 50,100 --levels 1          # ~2-4 min per gap",
        "python validation/evolver_fourpad_inward.py --gaps 100 --levels 2 --append    # ~5-10 min (also run: --gaps 50)",
        "python validation/evolver_fourpad_inward.py --gaps 50,100 --levels 1 --x0-diag --append  # + x=0 diagnostics",
        "python validation/evolver_fourpad_inward.py --gaps 100 --levels 2 --diag-at 380 --append # loop-pose diagnostic",
        "python validation/evolver_fourpad_inward.py --gaps 50 --levels 2 --diag-at 400 --append",
        "python validation/evolver_fourpad_inward.py --gaps 50 --levels 2 --diag-at 0 --append",
        "python validation/evolver_fourpad_inward.py --report       # only this file (and re-normalise the CSV)",
        "```",
        "",
        "`--deadline HH:MM` (UTC) stops starting paths after that time and kills a running one then; the "
        "CSV is rewritten after every pose, so finished poses are kept.",
        "",
    ]
    old_notes = ""
    if MD.exists():
        txt = MD.read_text()
        if NOTES_MARK in txt:
            old_notes = txt.split(NOTES_MARK, 1)[1]
    L.append(NOTES_MARK)
    return "\n".join(L) + (old_notes if old_notes else "\n")


def write_md(runtime_note: str = "") -> None:
    text = report(runtime_note)
    tmp = MD.with_suffix(".md.tmp")
    tmp.write_text(text)
    tmp.replace(MD)


# ----------------------------------------------------------------------------


def _seconds_to(deadline: str | None) -> float:
    if not deadline:
        return float("inf")
    now = dt.datetime.now(dt.UTC)
    hh, mm = (int(t) for t in deadline.split(":"))
    d = now.replace(hour=hh, minute=mm, second=0, microsecond=0)
    return (d - now).total_seconds()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--gaps", default="50,100", help="comma-separated gaps (um) of the L=730 pattern"
    )
    ap.add_argument(
        "--levels", default="1", help="comma-separated refinement levels (each a separate process)"
    )
    ap.add_argument(
        "--append",
        action="store_true",
        help="keep the rows already in the CSV (other paths/levels)",
    )
    ap.add_argument(
        "--diag-at",
        type=float,
        default=None,
        metavar="X",
        help="run the inward path only down to X, then DIAG_STEPS at X; only pose X and the "
        "diagnostic poses are recorded (path *_x<X>diag); the main rows are not touched",
    )
    ap.add_argument(
        "--x0-diag",
        action="store_true",
        help="after the last pose (x = 0) run DIAG_STEPS (more relaxation), reported as path *_x0diag",
    )
    ap.add_argument(
        "--report", action="store_true", help="only rewrite FOURPAD_INWARD.md from the CSVs"
    )
    ap.add_argument(
        "--deadline",
        default=None,
        help="HH:MM UTC: start no path after it, kill a running one at it",
    )
    ap.add_argument(
        "--timeout", type=float, default=ef.Schedule.timeout_s, help="seconds per Evolver process"
    )
    args = ap.parse_args(argv)
    known = inward_paths([50.0, 100.0]) + [diag_path(p) for p in inward_paths([50.0, 100.0], True)]
    if args.report:
        if OUT.exists():  # normalise (idempotent): level rows -> rows again
            ef.write_csv_atomic(
                OUT, COLUMNS, out_rows(level_rows_from_out(ef.read_csv(OUT)), known)
            )
        write_md()
        print(f"wrote {MD}", file=sys.stderr)
        return 0
    ef.find_evolver()
    gaps = [float(t) for t in args.gaps.split(",")]
    levels = [int(t) for t in args.levels.split(",")]
    if args.diag_at is not None:
        run = inward_paths(gaps, True, args.diag_at)
    else:
        run = inward_paths(gaps, args.x0_diag)
    paths = (
        inward_paths([50.0, 100.0])
        + [diag_path(p) for p in inward_paths([50.0, 100.0], True)]
        + [diag_path(p) for p in run if n_main(p) < len(p.poses)]
    )
    ef.command_file = command_file_with_diag  # in this process only; the harness file is untouched
    ef.contact_line_stats = cl_stats_keep
    lrows = level_rows_from_out(ef.read_csv(OUT)) if args.append and OUT.exists() else []

    def flush() -> None:
        ef.write_csv_atomic(OUT, COLUMNS, out_rows(lrows, paths))

    failed = 0
    t_all = time.perf_counter()
    notes = []
    for p in run:
        for lev in levels:
            left = _seconds_to(args.deadline)
            if left < 60:
                print(f"deadline: not starting {p.name} level {lev}", file=sys.stderr)
                notes.append(f"{p.name} level {lev}: not started (deadline)")
                continue
            s = ef.Schedule(level=lev, timeout_s=min(args.timeout, left))
            nm = n_main(p)
            if args.diag_at is not None:
                names = (diag_name(p),)
            else:
                names = (p.name, diag_name(p)) if args.x0_diag else (p.name,)
            lrows[:] = [r for r in lrows if not (r["path"] in names and r["level"] == str(lev))]
            print(
                f"{p.name} level {lev}: {len(p.poses)} poses (harness sha {harness_sha()})",
                file=sys.stderr,
                flush=True,
            )

            def on_pose(rec: dict, p=p, nm=nm) -> None:
                if args.diag_at is not None and rec["pose"] < nm - 1:
                    return  # poses of the main path: not recorded (see the main rows)
                if rec["pose"] >= nm or args.diag_at is not None:
                    lrows.append(ef.level_row(diag_path(p), rec))
                    k = rec["pose"] - nm
                    if k < 0:
                        flush()
                        return
                    n, y0, y1, xm, ym = _last_edges.get("lobe", (0, 0, 0, 0, 0))
                    print(
                        f"  diag x={p.poses[-1][0]:g} step {k} ({DIAG_STEPS[k][0]}): FX={rec['FX']:.4g} E={rec['E']:.3f} "
                        f"xmin_y0={rec.get('cl_xmin_y0_um', float('nan')):.2f} xmin={xm:.2f} at y={ym:.1f}; "
                        f"{n} CL vertices left of xmin_y0-5 in y [{y0:.1f}, {y1:.1f}]",
                        file=sys.stderr,
                        flush=True,
                    )
                else:
                    lrows.append(ef.level_row(p, rec))
                    if rec["pose"] == nm - 1 and "lobe" in _last_edges:
                        n, y0, y1, xm, ym = _last_edges["lobe"]
                        print(
                            f"  x=0 contact line: xmin={xm:.2f} at y={ym:.1f}; {n} CL vertices left of "
                            f"xmin_y0-5 in y [{y0:.1f}, {y1:.1f}]",
                            file=sys.stderr,
                            flush=True,
                        )
                flush()

            tp = time.perf_counter()
            recs, err = ef.run_path(p, s, on_pose, sys.stderr)
            wall = time.perf_counter() - tp
            msg = f"{p.name} level {lev}: {len(recs)} poses in {wall:.0f} s" + (
                f"; FAILED: {err}" if err else ""
            )
            print(msg, file=sys.stderr, flush=True)
            notes.append(msg)
            if err:
                failed += 1
                done = {r["X"] for r in recs}
                for x, y in p.poses:
                    if not any(abs(x - a) < 1e-6 for a in done):
                        lrows.append(
                            {
                                **{k: "" for k in ef.LEVEL_COLUMNS},
                                "path": diag_name(p) if args.diag_at is not None else p.name,
                                "L_um": ef._f(p.L),
                                "g_um": ef._f(p.g),
                                "volume_um3": ef._f(p.volume),
                                "level": str(lev),
                                "x_um": ef._f(x),
                                "y_um": ef._f(y),
                                "flag": "failed: " + err.replace("\n", " ")[:200],
                            }
                        )
                        break
                flush()
    print(f"wrote {OUT}; wall {time.perf_counter() - t_all:.0f} s", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
