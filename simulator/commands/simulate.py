"""``selfalign simulate``: one trajectory, its energy curve and outcome."""

from __future__ import annotations

import argparse
import contextlib

import numpy as np

from foundation import InputError, atomic_output, compiling
from simulator.commands._flags import add_dynamics_args, add_scene_args, parse_pose
from simulator.commands._liquid import liquid_checks
from simulator.commands._outputs import add_force_arg, check_outputs, write_json
from simulator.commands._request import SceneRequest
from simulator.commands._scene import accuracy_check, scene_from_args
from simulator.core import AREA_REL_TOL, DEFAULT_MAX_STEPS, DEG_TOL, DYNAMIC_METHODS, METHODS
from simulator.physics import LINE_FRICTION_PA_S


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="one trajectory from a start pose: path, energy curve, outcome",
        description=(
            "Move the chip from --start down the energy landscape and report where it ends. "
            "greedy: 1 px / 1 twist-step moves to the lowest neighbour (docs/physics.md §5.2); "
            "gradient: steps along the force; overdamped / inertial: time-resolved dynamics "
            "with Couette damping (times in seconds)."
        ),
    )
    add_scene_args(p)
    p.add_argument("--start", metavar="X,Y,TWIST", help="initial pose in um, um, degrees")
    p.add_argument("--method", choices=METHODS, default=None, help="stepper (default greedy)")
    p.add_argument(
        "--max-steps",
        type=int,
        default=None,
        help=f"bound on moves or solver steps (default {DEFAULT_MAX_STEPS})",
    )
    p.add_argument(
        "--engine",
        choices=("auto", "fft", "path"),
        default="auto",
        help="how greedy and gradient compute the energies they step on: fft (boxes of the landscape "
        "holding the start and the centre, by FFT correlation), path (small boxes that follow the chip, "
        "pose by pose at the cost of the chip's outline: seconds instead of minutes for chips of "
        "thousands of px; exact geometry, chip images and the free contact lines' footprint, not the "
        "K_h-blurred meniscus or a meniscus below one pixel) or auto (path where it covers the scene: "
        "for chips of at least 1000 x 1000 px greedy, 2000 x 2000 px gradient, and for every chip "
        "with free contact lines; default). With --dispense the same choice: path computes the "
        "footprint state (each pad's energy and relay, the shadow pairs) at the poses the run visits, "
        "fft builds the pads' planes over the whole grid. "
        "The JSON's cost.engine says which ran",
    )
    d = p.add_argument_group("liquid and chip body (dynamic methods)")
    add_dynamics_args(
        d,
        {
            "--viscosity": "liquid viscosity in mPa s (default 1.0, water)",
            "--chip-thickness": "chip thickness in um (default 50)",
            "--chip-density": "chip density in kg/m^3 (default 1200, SU-8)",
            "--damping-calibration": "override the damping: the film's Couette drag times this "
            "factor (600 was the fit to the source's video before the damping's terms; default: "
            "none, the sum of the film's Couette drag with its unsteady correction, the contact "
            "lines' wedges and their molecular-kinetic friction, docs/physics.md section 4)",
            "--line-friction": f"molecular-kinetic contact-line friction coefficient in Pa s "
            f"(default {LINE_FRICTION_PA_S:g}, fitted to the source's video: 60 times the top of "
            f"water on hydrophilic oxide's 0.01-0.1; docs/physics.md §4)",
        },
    )
    o = p.add_argument_group("outputs")
    o.add_argument("--json", help="write the trajectory as JSON")
    o.add_argument(
        "--csv",
        help="write the path as CSV, one row per step: step, x_um, y_um, twist_deg, energy_J "
        "(and t_s for the dynamic methods)",
    )
    o.add_argument("--plot", help="write the energy-versus-step (or time) curve as PNG")
    o.add_argument(
        "--gif",
        help="write an animation of the chip moving over the pattern (GIF, at most 120 frames)",
    )
    o.add_argument(
        "--quiet",
        action="store_true",
        help="print only the results (no progress bars or waiting messages)",
    )
    add_force_arg(o)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # Priced before JAX is imported: a refusal costs neither its import time nor its memory.
    from simulator.motion import plan_run, price_run

    # the scene file read and validated, the flags, inputs and outputs: once for the whole command
    request = SceneRequest.from_args(args, OUTPUTS)
    sim = request.document.get("simulate", {})
    start_text = args.start or (",".join(str(v) for v in sim["start"]) if "start" in sim else None)
    if start_text is None:
        raise InputError("give the start pose with --start X,Y,TWIST (um, um, degrees)")
    start = parse_pose(start_text, "--start")
    method = args.method or sim.get("method", "greedy")
    max_steps = (
        args.max_steps if args.max_steps is not None else sim.get("max_steps", DEFAULT_MAX_STEPS)
    )
    _check_outputs(request)
    scene = scene_from_args(request, warn=False)
    price_run(scene, method, max_steps)
    if args.engine == "path" and method in DYNAMIC_METHODS:
        raise InputError(
            f"--engine path runs greedy and gradient; {method} builds the whole landscape (leave --engine out)"
        )
    # the library's plan: the engine, the start in the window, the first landscape (or what
    # the path engine needs) priced before any work, once; the run takes this plan
    plan = plan_run(scene, start, method, args.engine)
    if scene.dispense is not None:
        # the pads' planes over the whole grid, or the path engine's rotators (it computes
        # the visited poses only)
        from simulator.motion import require_footprint_fits

        require_footprint_fits(scene, plan.engine)
    if method in DYNAMIC_METHODS:
        from simulator.motion import DynamicsParams  # JAX: once the run is priced

        DynamicsParams.from_scene(scene)  # a liquid the model cannot take fails before compiling
    # The accuracy and droplet warnings once the run is priced: a refusal does not wait for them.
    accuracy_check(scene)
    from simulator.liquid import placement_biases

    liquid_warnings = liquid_checks(request, scene, method, placement_biases(start), "the start")
    from simulator.motion import simulate  # JAX, imported when the run goes ahead

    if method not in DYNAMIC_METHODS:  # a dynamic run says it after its landscape
        compiling(method, args.quiet)
    traj = simulate(scene, start, method=method, max_steps=max_steps, plan=plan)
    print(end_line(scene, traj))
    if traj.footprint is not None:
        from simulator.motion import footprint_words

        print(footprint_words(traj.footprint))
    if traj.refined is not None:
        r = [round(v, 1) + 0.0 for v in traj.refined]
        print(
            f"refined below the grid (meniscus {scene.meniscus_height_um:.3g} um): ({r[0]:.1f} um, {r[1]:.1f} um, {r[2]:.1f} deg)"
        )
    for line in accuracy_lines(traj):
        print(line)
    c = traj.cost
    if c is not None and c.poses_computed:
        print(
            f"landscape computed: {c.poses_computed:,} of {c.poses_full:,} poses ({100 * c.fraction_of_full:.3g} %), {c.landscape_s:.2f} s"
            + (" (path engine)" if c.engine == "path" else "")
        )
    written = []
    with contextlib.ExitStack() as stack:  # every output, or none: each is moved into place
        # only when all are complete (a full disk on the GIF keeps no JSON either)
        def into(path):
            written.append(path)
            return stack.enter_context(atomic_output(path))

        if args.json:
            write_json(
                into(args.json),
                traj.to_json()
                | {
                    "liquid_warnings": liquid_warnings,
                    "meniscus_height_um": scene.meniscus_height_um,
                },
            )
        if args.csv:
            write_path_csv(into(args.csv), traj)
        if args.plot:
            from simulator.render import plot_energy_curve

            plot_energy_curve(traj, into(args.plot))
        frames = None
        if args.gif:
            from simulator.render import write_trajectory_gif

            frames = write_trajectory_gif(scene, traj, into(args.gif), quiet=args.quiet)
    for path in written:
        print(
            f"wrote {path}"
            + (f" ({frames} frame{'s' if frames != 1 else ''})" if path == args.gif else "")
        )
    return 0


def write_path_csv(path, traj) -> None:
    """The path, one row per recorded pose (the start is step 0), units in the header."""
    from simulator.commands._outputs import write_csv

    p = traj.path
    cols, vals = (
        ["step", "x_um", "y_um", "twist_deg", "energy_J"],
        [np.arange(len(p)), p[:, 0], p[:, 1], p[:, 2], traj.energy_J],
    )
    if traj.t_s is not None:
        cols.append("t_s")
        vals.append(traj.t_s)
    write_csv(path, cols, vals)


def end_line(scene, traj) -> str:
    """'greedy: aligned at (x um, y um, t deg) after N steps', with the equivalent twist and
    the chip's symmetry when the chip ended turned by a symmetry period or more (a square
    at 90 deg is the square at 0 deg), and the global minimum it was measured against."""
    f = [round(v, 2) + 0.0 for v in traj.final]  # no "-0.00"
    time_txt = ""
    if traj.time_s is not None:  # the simulated time: ms below a second ("1e+03 ms" read badly)
        ms = traj.time_s * 1e3
        time_txt = f", {ms:.3g} ms" if float(f"{ms:.3g}") < 1e3 else f", {traj.time_s:.3g} s"
    period = scene.twist_axis.period_deg
    same = round(float(np.mod(traj.final[2] + period / 2, period) - period / 2), 2) + 0.0
    twin = (
        f" (twist {f[2]:g} deg = {same:g} deg for {chip_symmetry_words(scene, period)})"
        if abs(same - f[2]) > DEG_TOL
        else ""
    )
    line = f"{traj.method}: {traj.outcome} at ({f[0]:.2f} um, {f[1]:.2f} um, {f[2]:.2f} deg){twin} after {traj.steps} steps{time_txt}"
    if traj.optimum is not None and traj.outcome != "aligned":
        g = [round(v, 2) + 0.0 for v in traj.optimum]
        line += f"; the global minimum is at ({g[0]:g} um, {g[1]:g} um, {g[2]:g} deg)"
    return line


def accuracy_lines(traj) -> list[str]:
    """The floor the chip floats on (when it does) and the final-pose error from the global
    minimum with what limits it (:func:`simulator.motion.error_limit`)."""
    from simulator.motion import error_limit_words

    out = []
    fl = traj.floor
    if fl:
        (x0, x1), (y0, y1), (t0, t1) = fl["x_um"], fl["y_um"], fl["twist_deg"]
        out.append(
            f"the chip floats on the well's floor: x {x0:g} to {x1:g} um, y {y0:g} to {y1:g} um, twist {t0:g} to "
            f"{t1:g} deg (no restoring force there: a run that stops on it is aligned)"
        )
    if traj.optimum is not None and traj.error_limit and traj.outcome == "aligned":
        p = traj.refined if traj.refined is not None else traj.final
        d = float(np.hypot(p[0] - traj.optimum[0], p[1] - traj.optimum[1]))
        out.append(
            f"final-pose error from the global minimum {d:.3g} um, {error_limit_words(traj.error_limit)}"
        )
    return out


def chip_symmetry_words(scene, period: float) -> str:
    """'a square chip', 'a rectangular chip', or 'a chip with 90-degree symmetry'."""
    g = scene.chip.geometry
    if g is not None and period in (90.0, 180.0):
        x0, y0, x1, y1 = g.bounds
        if abs(g.area - (x1 - x0) * (y1 - y0)) <= AREA_REL_TOL * g.area:
            return "a square chip" if period == 90.0 else "a rectangular chip"
    return f"a chip with {period:g}-degree symmetry"


#: The command's output flags (attribute names), its request's output plan.
OUTPUTS = ("json", "csv", "plot", "gif")


def _check_outputs(request: SceneRequest) -> None:
    """Fail before any work when an output cannot or must not be written."""
    check_outputs(request)
    gif, plot = request.output("--gif"), request.output("--plot")
    if gif and not gif.lower().endswith(".gif"):
        raise InputError(f"--gif {gif}: the animation must end in .gif")
    if plot and not plot.lower().endswith((".png", ".svg", ".pdf")):
        raise InputError(f"--plot {plot}: the picture must end in .png, .svg or .pdf")
