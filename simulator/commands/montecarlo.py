"""``selfalign montecarlo``: many starts on one landscape: yield, outcomes, errors, capture map."""

from __future__ import annotations

import argparse
import contextlib
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from foundation import InputError, atomic_output, json_text, require_finite
from simulator.batch import StartGrid
from simulator.commands._flags import add_scene_args, parse_pose
from simulator.commands._liquid import liquid_checks
from simulator.commands._outputs import add_force_arg, check_outputs
from simulator.commands._request import SceneRequest
from simulator.commands._scene import accuracy_check, scene_from_args
from simulator.core import (
    BATCH_METHODS as METHODS,
    DEFAULT_CHUNK,
    DEFAULT_DYNAMICS_CHUNK,
    DEFAULT_MAX_STEPS,
    DISTRIBUTIONS,
    DYNAMIC_METHODS,
    FOOTPRINT_CHUNK,
    MAX_STARTS,
    MAX_STEPS_LIMIT,
)
from simulator.landscape import axis_step
from simulator.render import plot_capture_map  # matplotlib is imported when it draws

MAP_SUFFIXES = (".png", ".svg", ".pdf")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "montecarlo",
        help="many starts at once: yield, outcome counts, final-pose errors, capture map",
        description=(
            "Run many start poses down one energy landscape (built once) and report the yield "
            "(fraction aligned), the outcome counts and the final-pose errors, measured from the "
            "global minimum that 'aligned' refers to (printed with them). Starts: a regular --grid "
            "(capture map, maximum bias) or --random placements around a nominal pose. With --method "
            "overdamped or inertial the starts run the time-resolved dynamics (the chip's mass, inertia and "
            "damping from the scene, as in simulate) and the time each start takes to align is reported: "
            "its median and 90th percentile, per start in --csv, a histogram in --time-plot."
        ),
    )
    add_scene_args(p)
    s = p.add_argument_group("starts (one of --grid or --random)")
    s.add_argument(
        "--grid",
        metavar="X0:X1:DX,Y0:Y1:DY[,TWISTS]",
        help="regular grid of starts, ends included, in um; each axis one value or a range; "
        "TWISTS one twist or T0:T1:DT in degrees (default 0)",
    )
    s.add_argument("--random", metavar="N", help="N random starts (N >= 1; 1e6 is accepted)")
    s.add_argument(
        "--spread",
        metavar="SX,SY,STWIST",
        help="placement spread in um, um, degrees: standard deviations (normal) or half-widths (uniform)",
    )
    s.add_argument(
        "--around",
        metavar="X,Y,TWIST",
        help="nominal pose the random starts scatter around (default 0,0,0)",
    )
    s.add_argument(
        "--distribution",
        choices=DISTRIBUTIONS,
        help="random start distribution per coordinate (default normal)",
    )
    s.add_argument(
        "--seed", type=int, help="seed of numpy.random.default_rng for --random (default 0)"
    )
    r = p.add_argument_group("runs")
    r.add_argument(
        "--method",
        choices=METHODS,
        help="stepper: greedy, gradient, or the dynamics overdamped, inertial (default greedy)",
    )
    r.add_argument(
        "--max-steps",
        type=int,
        help=f"bound on moves (solver steps for the dynamics) per start (default {DEFAULT_MAX_STEPS})",
    )
    r.add_argument(
        "--chunk",
        type=int,
        help=f"starts per compiled batch (default {DEFAULT_CHUNK}, dynamics {DEFAULT_DYNAMICS_CHUNK}; "
        f"a batch with the footprint state, --dispense pattern or chip: at most {FOOTPRINT_CHUNK}); "
        "results do not depend on it",
    )
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    o = p.add_argument_group("outputs (written only when the whole run succeeds)")
    o.add_argument("--json", help="summary statistics as JSON")
    o.add_argument(
        "--csv",
        help="one row per start: start and final pose, outcome, steps (dynamics: and time_to_align_s)",
    )
    o.add_argument("--map", help="capture map picture (.png, .svg or .pdf; needs --grid)")
    o.add_argument(
        "--time-plot",
        metavar="PICTURE",
        help="histogram of the time to align of the aligned starts (.png, .svg or .pdf; needs --method overdamped or inertial)",
    )
    add_force_arg(o)
    p.set_defaults(func=run)


# --------------------------------------------------------------------- parsing
def _number(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise InputError(f"{what}: {text!r} is not a finite number")
    return v


def _range(text: str, what: str):
    parts = text.split(":")
    if len(parts) == 1:
        return _number(parts[0], what)
    if len(parts) != 3:
        raise InputError(f"{what} must be one value or START:STOP:STEP, got {text!r}")
    return tuple(_number(v, what) for v in parts)


def parse_grid(text: str) -> StartGrid:
    """'X0:X1:DX,Y0:Y1:DY[,TWISTS]' (um, um, degrees; ends included) -> StartGrid."""
    parts = text.split(",")
    if len(parts) not in (2, 3):
        raise InputError(
            f"--grid must be X0:X1:DX,Y0:Y1:DY[,TWISTS] (um, um, degrees), got {text!r}"
        )
    names = ("--grid x", "--grid y", "--grid twist")
    axes = [_range(v.strip(), n) for v, n in zip(parts, names, strict=False)]
    try:
        return StartGrid.from_ranges(*axes)
    except InputError as err:
        raise InputError(f"--grid {text!r}: {err}") from None


def parse_count(text: str) -> int:
    """'1000' or '1e6' -> a whole number of starts in [1, MAX_STARTS]."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v == int(v) and 1 <= v <= MAX_STARTS):
        raise InputError(
            f"--random N must be a whole number from 1 to {MAX_STARTS:,}, got {text!r}"
        )
    return int(v)


def parse_spread(text: str) -> tuple[float, float, float]:
    sx, sy, st = parse_pose(text, "--spread")
    if min(sx, sy, st) < 0:
        raise InputError(f"--spread must be >= 0 (um, um, degrees), got {text!r}")
    return sx, sy, st


def _options(args: argparse.Namespace, doc: dict) -> dict:
    """Flags over the TOML scene's [montecarlo] table (``doc``: the scene file's document,
    the request's)."""
    table = doc.get("montecarlo", {})
    if not isinstance(table, dict):
        raise InputError("[montecarlo] in the scene file must be a table")
    allowed = {
        "grid",
        "random",
        "spread",
        "around",
        "distribution",
        "seed",
        "method",
        "max_steps",
        "chunk",
    }
    unknown = set(table) - allowed
    if unknown:
        raise InputError(f"unknown [montecarlo] keys {sorted(unknown)}; allowed: {sorted(allowed)}")
    # A kind of starts given as a flag replaces the scene's, with the keys that belong to it.
    if args.grid is not None:
        table = {
            k: v
            for k, v in table.items()
            if k not in ("random", "spread", "around", "distribution", "seed")
        }
    if args.random is not None:
        table = {k: v for k, v in table.items() if k != "grid"}

    def pick(flag: str, key: str, default=None):
        v = getattr(args, flag)
        return v if v is not None else table.get(key, default)

    def text(v):
        return (
            ",".join(str(x) for x in v)
            if isinstance(v, list | tuple)
            else (None if v is None else str(v))
        )

    opt = {
        "grid": text(pick("grid", "grid")),
        "random": text(pick("random", "random")),
        "spread": text(pick("spread", "spread")),
        "around": text(pick("around", "around")),
        "distribution": pick("distribution", "distribution"),
        "seed": pick("seed", "seed"),
        "method": pick("method", "method", "greedy"),
        "max_steps": pick("max_steps", "max_steps", DEFAULT_MAX_STEPS),
        "chunk": pick("chunk", "chunk", None),
    }
    if opt["method"] not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}, got {opt['method']!r}")
    if opt["chunk"] is None:
        opt["chunk"] = DEFAULT_DYNAMICS_CHUNK if opt["method"] in DYNAMIC_METHODS else DEFAULT_CHUNK
    if opt["distribution"] not in (None, *DISTRIBUTIONS):
        raise InputError(
            f"distribution must be one of {', '.join(DISTRIBUTIONS)}, got {opt['distribution']!r}"
        )
    for key in ("max_steps", "chunk"):
        v = opt[key]
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise InputError(f"--{key.replace('_', '-')} must be a whole number >= 1, got {v!r}")
        if v > MAX_STEPS_LIMIT:
            raise InputError(
                f"--{key.replace('_', '-')} must be at most {MAX_STEPS_LIMIT:,}, got {v:,}"
            )
    seed = opt["seed"]
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise InputError(f"--seed must be a whole number >= 0, got {seed!r}")
    return opt


def _starts(opt: dict):
    """(StartGrid or (N, 3) poses, JSON description, seed) from the options."""
    from simulator.batch import random_starts

    if (opt["grid"] is None) == (opt["random"] is None):
        raise InputError(
            "give exactly one of --grid X0:X1:DX,Y0:Y1:DY[,TWISTS] or --random N --spread SX,SY,STWIST"
        )
    if opt["grid"] is not None:
        extra = [k for k in ("spread", "around", "distribution", "seed") if opt[k] is not None]
        if extra:
            raise InputError(f"--{extra[0]} applies to --random starts, not to --grid")
        g = parse_grid(opt["grid"])
        desc = {"kind": "grid", "spec": opt["grid"], "shape": list(g.shape)} | {
            k: _axis_doc(getattr(g, k)) for k in ("x_um", "y_um", "twist_deg")
        }
        return g, desc, None
    n = parse_count(opt["random"])
    if opt["spread"] is None:
        raise InputError("--random needs --spread SX,SY,STWIST (um, um, degrees)")
    spread = parse_spread(opt["spread"])
    around = parse_pose(opt["around"], "--around") if opt["around"] is not None else (0.0, 0.0, 0.0)
    dist = opt["distribution"] or "normal"
    seed = 0 if opt["seed"] is None else int(opt["seed"])
    poses = random_starts(n, spread, seed, around=around, distribution=dist)
    keys = ("x_um", "y_um", "twist_deg")
    desc = {
        "kind": "random",
        "distribution": dist,
        "spread": dict(zip(keys, spread, strict=True)),
        "spread_means": "standard deviation" if dist == "normal" else "half-width",
        "around": dict(zip(keys, around, strict=True)),
    }
    return poses, desc, seed


def _axis_doc(values: Sequence[float]) -> dict:
    step = axis_step(np.asarray(values)) if len(values) > 1 else None
    return {"from": values[0], "to": values[-1], "step": step, "count": len(values)}


#: The command's output flags (attribute names), its request's output plan.
OUTPUTS = ("json", "csv", "map", "time_plot")


def _check_outputs(
    args: argparse.Namespace, request: SceneRequest, is_grid: bool, method: str
) -> None:
    """Fail before any work when an output cannot or must not be written."""
    check_outputs(request)
    if args.map:
        if not is_grid:
            raise InputError(
                "--map needs --grid starts (a capture map is drawn over the start grid)"
            )
        if Path(args.map).suffix.lower() not in MAP_SUFFIXES:
            raise InputError(f"--map {args.map}: the picture must end in {', '.join(MAP_SUFFIXES)}")
    if args.time_plot:
        if method not in DYNAMIC_METHODS:
            raise InputError(
                f"--time-plot needs --method overdamped or inertial (the {method} stepper has no time)"
            )
        if Path(args.time_plot).suffix.lower() not in MAP_SUFFIXES:
            raise InputError(
                f"--time-plot {args.time_plot}: the picture must end in {', '.join(MAP_SUFFIXES)}"
            )


# --------------------------------------------------------------------- run
def run(args: argparse.Namespace) -> int:
    # JAX, the engine, matplotlib: imported when a run needs them, after its pricing (a
    # refusal, and selfalign --help, start without).
    from simulator.batch import capture_map, price_dynamics_lanes, summarize, time_histogram
    from simulator.core import OUTCOMES, threads

    # the scene file read and validated, the flags, inputs and outputs: once for the whole command
    request = SceneRequest.from_args(args, OUTPUTS)
    opt = _options(args, request.document)
    starts, desc, seed = _starts(opt)
    grid = starts if isinstance(starts, StartGrid) else None
    _check_outputs(args, request, grid is not None, opt["method"])
    scene = scene_from_args(request, warn=False)
    from foundation import compiling
    from simulator.landscape import require_landscape_fits

    require_landscape_fits(scene)
    if opt["method"] in DYNAMIC_METHODS:
        n = starts.size if isinstance(starts, StartGrid) else len(starts)  # as grid is not None
        price_dynamics_lanes(
            min(opt["chunk"], n) * max(1, min(threads(), -(-n // opt["chunk"]))),
            scene.memory_budget_mb,
        )
        from simulator.motion import DynamicsParams  # JAX: once the batch is priced

        DynamicsParams.from_scene(scene)  # a liquid the model cannot take fails before compiling
    # The accuracy and droplet warnings once the run is priced: a refusal does not wait for them.
    accuracy_check(scene)
    from simulator.liquid import placement_biases

    liquid_warnings = liquid_checks(
        request, scene, opt["method"], lambda: placement_biases(starts), "the starts"
    )

    from simulator.batch import run_batch

    compiling(opt["method"], args.quiet)
    result = run_batch(
        scene,
        starts,
        opt["method"],
        chunk=opt["chunk"],
        max_steps=opt["max_steps"],
        progress=not args.quiet,
    )
    summary = summarize(result, grid)
    st = result.stats
    doc = summary | {
        "seed": seed,
        "starts": desc,
        "max_steps": opt["max_steps"],
        "scene": {
            "pattern": str(args.pattern or request.document.get("pattern")),
            "um_per_px": scene.um_per_px,
            "chip_area_um2": scene.chip.area_um2,
            "twist_step_deg": scene.twist.step_deg if scene.effects.twist else None,
            "dtype": scene.dtype,
            "meniscus_height_um": scene.meniscus_height_um,
            "pinned": scene.liquid.pinned,
            "dispense": scene.dispense,
            "hysteresis_deg": (
                {
                    "receding": scene.materials.pad_receding_deg,
                    "advancing": scene.materials.pad_advancing_deg,
                }
                if scene.effects.hysteresis
                else None
            ),
        },
        "landscape_shape": list(st["landscape_shape"]),
        "landscape_s": st["landscape_s"],
        "run_s": st["run_s"],
        "starts_per_s": st["starts_per_s"],
        "liquid_warnings": liquid_warnings,
    }
    if result.time_s is not None:
        doc["time_to_align_histogram"] = time_histogram(result.time_to_align_s)
    if "footprint_events" in st:  # the footprint as each start's state (--dispense)
        doc["footprint"] = {
            "dispense": scene.dispense,
            "events": st["footprint_events"],
            "rounds": st["footprint_rounds"],
            "planes_s": st["footprint_planes_s"],
            "twists": st["footprint_twists"],  # the twists the pads' planes were made over
        }
    require_finite(doc, "montecarlo summary")
    require_finite({"start": result.start, "final": result.final}, "montecarlo starts")
    _print_summary(summary | {"seed": seed}, result, desc, st)
    if "footprint" in doc:
        fp = doc["footprint"]
        print(
            f"footprint (--dispense {fp['dispense']}): each start carries its own wet pads; "
            f"{fp['events']:,} state changes over {fp['rounds']} rounds; pads' planes built in {fp['planes_s']:.1f} s "
            f"over {fp['twists']} of the {scene.twist_axis.count} twists"
        )
    with contextlib.ExitStack() as stack:  # every output, or none
        if args.csv:
            write_csv(stack.enter_context(atomic_output(args.csv)), result, OUTCOMES)
        if args.json:
            stack.enter_context(atomic_output(args.json)).write_text(json_text(doc))
        if args.time_plot:  # moved into place with the files above, when every output is ready
            from simulator.batch import time_histogram, time_stats
            from simulator.render import plot_time_to_align

            times = result.time_to_align_s
            plot_time_to_align(
                time_histogram(times),
                time_stats(times),
                stack.enter_context(atomic_output(args.time_plot)),
                title=_time_title(args, summary),
            )
        if args.map:
            assert grid is not None  # _check_outputs refuses --map without --grid
            plot_capture_map(
                capture_map(result, grid), grid, scene, args.map, title=_map_title(args, summary)
            )
    for flag in ("csv", "json", "map", "time_plot"):
        if getattr(args, flag):
            print(f"wrote {getattr(args, flag)}")
    return 0


def _print_summary(summary: dict, result, desc: dict, st: dict) -> None:
    from simulator.motion import error_limit_words

    n = summary["n"]
    if desc["kind"] == "grid":
        t, ny, nx = desc["shape"]
        what = f"grid {nx} x {ny} (x, y){f' x {t} twists' if t > 1 else ''}"
    else:
        sp, ar = desc["spread"], desc["around"]
        what = (
            f"random {desc['distribution']} around {ar['x_um']:g} um, {ar['y_um']:g} um, {ar['twist_deg']:g} deg, "
            f"{desc['spread_means']}s {sp['x_um']:g} um, {sp['y_um']:g} um, {sp['twist_deg']:g} deg, seed {summary['seed']}"
        )
    shape = " x ".join(str(v) for v in st["landscape_shape"])
    print(
        f"{result.method}: {n:,} starts ({what}); landscape {shape} (twist, y, x) in {st['landscape_s']:.2f} s; runs {st['run_s']:.2f} s incl. compilation ({st['starts_per_s']:,.0f} starts/s)"
    )
    c = summary["outcomes"]
    print(f"yield: {100 * summary['yield']:.2f} % aligned ({c['aligned']:,} of {n:,} starts)")
    print("outcomes (starts): " + ", ".join(f"{k} {v:,}" for k, v in c.items()))
    e_um, e_deg = summary["aligned_error_um"], summary["aligned_error_deg"]
    if e_um["x"] is not None:
        g = summary["error_target"]
        print(
            f"final-pose error of the aligned starts from the global minimum ({g['x_um']:g} um, {g['y_um']:g} um, "
            f"{g['twist_deg']:g} deg), mean +- std (max |error|): "
            f"x {e_um['x']['mean']:.3g} +- {e_um['x']['std']:.3g} um ({e_um['x']['max_abs']:.3g} um), "
            f"y {e_um['y']['mean']:.3g} +- {e_um['y']['std']:.3g} um ({e_um['y']['max_abs']:.3g} um), "
            f"twist {e_deg['twist']['mean']:.3g} +- {e_deg['twist']['std']:.3g} deg ({e_deg['twist']['max_abs']:.3g} deg); "
            + error_limit_words(summary.get("error_limit"))
        )
    if "time_to_align_s" in summary:
        print(time_line(summary["time_to_align_s"]))
    if "max_bias_um" in summary:
        b, lim = summary["max_bias_um"], summary["max_bias_limited_by_grid"]
        if any(v is not None for v in b.values()):
            items = [
                f"{k} {'n/a' if v is None else f'{v:g} um'}{' (grid edge: at least)' if lim[k] else ''}"
                for k, v in b.items()
            ]
            print("max bias at twist 0 (every grid start up to it aligned): " + ", ".join(items))


def time_line(t: dict | None) -> str:
    """The printed line on the time to align of the aligned starts (ms)."""
    if t is None:
        return "time to align: no start aligned"
    return (
        f"time to align ({t['n']:,} aligned starts, simulated): median {1e3 * t['median']:.3g} ms, "
        f"90th percentile {1e3 * t['p90']:.3g} ms, max {1e3 * t['max']:.3g} ms"
    )


def write_csv(path: Path, result, outcomes) -> None:
    """One row per start: start pose, final pose (twist unwrapped), outcome name, steps, and
    for the dynamics the time to align in seconds (empty where the start did not align)."""
    names = np.asarray(outcomes)[result.outcome]
    times = result.time_to_align_s
    head = (
        "start_x_um,start_y_um,start_twist_deg,final_x_um,final_y_um,final_twist_deg,outcome,steps"
        + (",time_to_align_s" if times is not None else "")
        + "\n"
    )
    with open(path, "w") as f:
        f.write(head)
        for i in range(0, result.n, 65536):
            s, e = result.start[i : i + 65536], result.final[i : i + 65536]
            t = (
                [""] * len(s)
                if times is None
                else [
                    "," + (f"{v:.10g}" if np.isfinite(v) else "")
                    for v in times[i : i + 65536].tolist()
                ]
            )
            rows = [
                f"{a[0]:.10g},{a[1]:.10g},{a[2]:.10g},{b[0]:.10g},{b[1]:.10g},{b[2]:.10g},{o},{k}{tt}\n"
                for a, b, o, k, tt in zip(
                    s.tolist(),
                    e.tolist(),
                    names[i : i + 65536],
                    result.steps[i : i + 65536].tolist(),
                    t,
                    strict=True,
                )
            ]
            f.write("".join(rows))


# --------------------------------------------------------------------- picture
def _map_title(args: argparse.Namespace, summary: dict) -> str:
    name = (
        Path(args.pattern).name if args.pattern else (Path(args.scene).name if args.scene else "")
    )
    return f"{name}: capture map, {summary['method']}, yield {100 * summary['yield']:.1f} % of {summary['n']:,} starts"


def _time_title(args: argparse.Namespace, summary: dict) -> str:
    name = (
        Path(args.pattern).name if args.pattern else (Path(args.scene).name if args.scene else "")
    )
    return f"{name}: time to align, {summary['method']}, {summary['outcomes']['aligned']:,} of {summary['n']:,} starts aligned"
