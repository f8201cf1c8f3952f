"""``selfalign calibrate``: the scene's parameters fitted to the user's bench trials
(:func:`simulator.design.calibrate`)."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._flags import add_dynamics_args, add_scene_args, finite_limit
from simulator.core import METHODS
from simulator.physics import LINE_FRICTION_PA_S


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate",
        help="fit the model to bench trials: yields (and times) per nominal start",
        description=(
            "Fit scene parameters to a bench table TRIALS.csv (columns x_um,y_um,twist_deg,trials,aligned; "
            "optional time_s, sigma_x_um, sigma_y_um, sigma_twist_deg). Each candidate runs a Monte Carlo "
            "batch per row with the same placement draws for every candidate (common random numbers); "
            "the objective is the binomial log-likelihood of the bench's aligned counts plus a log-normal "
            "term on the median times. Optuna's TPE (seeded) proposes the candidates; the run is resumable "
            "from --out. Writes fitted.toml (a scene file), fit.json, bench.png and report.html."
        ),
    )
    p.add_argument(
        "trials_csv", metavar="TRIALS.csv", help="the bench table (see docs/guide/calibrate.md)"
    )
    add_scene_args(p)
    f = p.add_argument_group("the fit")
    f.add_argument(
        "--fit",
        required=True,
        metavar="NAME[,NAME...]",
        help="what to fit: receding_angle_deg, advancing_angle_deg (deg; the pads' hysteresis), "
        "volume_nl (nl), damping (x the Couette drag; dynamics), pad_angle_deg (deg)",
    )
    f.add_argument(
        "--bounds",
        action="append",
        metavar="NAME=LO:HI",
        help="search range of a fitted name (repeatable); defaults: receding_angle_deg 0:60 (at most the "
        "advancing angle), advancing_angle_deg 10:90, volume_nl 0.25-4 x the scene's, damping 10:10000, "
        "pad_angle_deg 5 to 1 below the substrate angle",
    )
    f.add_argument(
        "--trials",
        type=int,
        metavar="N",
        help="Optuna trials (default 40; a rerun with more continues)",
    )
    f.add_argument(
        "--draws",
        type=int,
        metavar="N",
        help="Monte Carlo placements per row and candidate (default 32)",
    )
    f.add_argument(
        "--spread",
        metavar="SX,SY,STWIST",
        help="placement noise (standard deviations: um, um, degrees) of the rows that give no sigma columns",
    )
    f.add_argument(
        "--profile",
        type=int,
        metavar="N",
        help="after the search, profile each parameter's likelihood at N values across its bounds, "
        "the others re-fitted at each (default 6; 0: none): the ranges then see a valley along which "
        "two parameters trade",
    )
    f.add_argument("--seed", type=int, help="seed of the draws and of the sampler (default 0)")
    f.add_argument(
        "--method",
        choices=METHODS,
        help="stepper (default: overdamped when the table gives time_s, else greedy)",
    )
    f.add_argument(
        "--time-sigma",
        type=finite_limit("--time-sigma", "natural log of time"),
        help="width of the log-time term (default 0.1: a 10 %% scatter of the median time)",
    )
    d = p.add_argument_group("dynamics")
    add_dynamics_args(
        d,
        {
            "--viscosity": "liquid viscosity in mPa s (default 1.0)",
            "--chip-thickness": "chip thickness in um (default 50)",
            "--chip-density": "chip density in kg/m^3 (default 1200)",
            "--damping-calibration": "override the damping: the Couette drag times this factor "
            "(default: none, the damping's documented terms)",
            "--line-friction": f"molecular-kinetic contact-line friction in Pa s (default "
            f"{LINE_FRICTION_PA_S:g}, fitted to the source's video; docs/physics.md §4)",
        },
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="results directory: new, empty, or holding this same fit (resumed)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from foundation import InputError
    from simulator.commands._flags import parse_pose
    from simulator.commands._request import SceneRequest
    from simulator.commands._scene import scene_document_from_args
    from simulator.commands.design import without_force
    from simulator.design import PROFILE, calibrate, read_trials

    try:
        table = read_trials(args.trials_csv)  # a bad table: refused before anything else
        spread = None
        if args.spread is not None:
            spread = parse_pose(args.spread, "--spread")
            if min(spread) < 0:
                raise InputError(f"--spread must be >= 0 (um, um, degrees), got {args.spread!r}")
        # the scene file read and validated and the flags over it: once for the whole command
        request = SceneRequest.from_args(args)
        doc, base = scene_document_from_args(request)
        result = calibrate(
            table,
            doc,
            args.fit,
            args.out,
            bounds=args.bounds,
            trials=args.trials,
            draws=32 if args.draws is None else args.draws,
            spread=spread,
            seed=0 if args.seed is None else args.seed,
            method=args.method,
            time_sigma=0.1 if args.time_sigma is None else args.time_sigma,
            quiet=args.quiet,
            base=base,
            profile=PROFILE if args.profile is None else args.profile,
            scene_name=args.scene or "(command-line flags)",
        )
    except InputError as err:
        raise InputError(without_force(str(err))) from None
    units = result["units"]
    print(
        f"calibrate {result['hash'][:12]}: {result['done']} of {result['trials']} trials over "
        f"{', '.join(result['fit'])}, {len(result['rows'])} rows x {result['draws']} draws ({result['method']}); "
        f"{result['profiled']} profile points; {result['failed']} failed; {result['run_s']:.1f} s"
    )
    for k, v in result["best"].items():
        r = result["range"][k]
        if not r["identified"]:
            edge = (
                " (not identified: the range covers most of its bounds; the table does not tell it, "
                "or another fitted name trades against it: fit fewer names)"
            )
        elif r["at_lower_bound"] or r["at_upper_bound"]:
            edge = " (reaches a bound: widen --bounds)"
        else:
            edge = ""
        print(
            f"best {k} = {v:.4g} {units[k]} (range {r['lo']:.4g} .. {r['hi']:.4g}, Delta log L <= 0.5){edge}"
        )
    print(
        f"log-likelihood {result['log_likelihood']:.3f} (trial {result['best_trial']})",
        file=sys.stdout,
    )
    print(f"wrote {args.out}/fitted.toml (and fit.json, bench.png, report.html, trials.csv)")
    return 0
