"""``selfalign sweep``: a design sweep on Dask, resumable, with its table, pictures and page."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from simulator.commands._signals import sigterm_says_what_was_kept
from simulator.sweep import CONNECT_TIMEOUT_S, DEFAULT_MAX_POINTS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sweep",
        help="design sweep: the evaluate assessment over a grid or Latin hypercube of designs, on Dask",
        description=(
            "Run the assessment of `selfalign evaluate` (global minimum, restoring force, maximum bias per axis, "
            "capture fraction, yield under placement noise) for every point of a sweep file: a base scene, a "
            "generated design or pattern files, and axes (design parameters such as gap, size, sigma, seed; "
            "chip_size_um, volume_nl, pad_angle_deg, substrate_angle_deg, surface_tension_mN_m, "
            "placement_sigma_um, placement_sigma_deg, method, resolution_um, twist_step_deg). Points run on a local "
            "Dask cluster of single-threaded worker processes, or on --scheduler. Results go into --out as they "
            "finish (results.parquet, results.csv, points/*.json, pictures, report.html); rerunning the same "
            "sweep into the same --out skips the points done. A point that fails records its error and the sweep goes on."
        ),
    )
    p.add_argument(
        "sweep_file", metavar="SWEEP.toml", help="the sweep file (see docs/guide/sweeps.md)"
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="results directory: new, empty, or holding this same sweep (resumed)",
    )
    p.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="local Dask worker processes (default: one per core, at most one per point); "
        "0 runs the points in this process without Dask",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=f"run on the Dask cluster of this scheduler (tcp://HOST:PORT) instead of local "
        f"workers; its workers need selfalign and the pattern files (refused after {CONNECT_TIMEOUT_S:g} s if unreachable)",
    )
    p.add_argument(
        "--max-points",
        type=int,
        default=DEFAULT_MAX_POINTS,
        metavar="N",
        help=f"refuse a sweep of more points (default {DEFAULT_MAX_POINTS})",
    )
    p.add_argument(
        "--retry-failed",
        action="store_true",
        help="when resuming, run the points that failed again",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from simulator.sweep import kept_points, load_sweep, run_sweep

    spec = load_sweep(args.sweep_file)
    try:
        with sigterm_says_what_was_kept(args.out, "sweep", "point"):
            table = run_sweep(
                spec,
                args.out,
                workers=args.workers,
                scheduler=args.scheduler,
                max_points=args.max_points,
                retry_failed=args.retry_failed,
                quiet=args.quiet,
            )
    except KeyboardInterrupt:
        n = kept_points(args.out) if os.path.isdir(args.out) else 0
        print(
            f"selfalign sweep: interrupted; {n} finished point{'s are' if n != 1 else ' is'} kept in {args.out} "
            "(rerun the same command to resume)",
            file=sys.stderr,
        )
        return 130
    st = table.attrs["sweep"]
    where = f"{st['workers']} Dask workers" if st["workers"] else "this process"
    rate = f" ({st['points_per_s']:.2f} points/s on {where})" if st["points_per_s"] else ""
    print(
        f"sweep {st['hash'][:12]}: {st['points']} points ({spec.shape_text()}); {st['run_now']} run now{rate}, "
        f"{st['resumed']} done before; {st['failed']} failed"
    )
    pics = sorted(p.name for p in Path(args.out).glob("*.png"))
    print(
        f"wrote {Path(args.out) / 'results.parquet'} (and results.csv, report.html, points/*.json"
        + (f", {len(pics)} pictures" if pics else "")
        + ")"
    )
    return 0
