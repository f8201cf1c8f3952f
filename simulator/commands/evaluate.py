"""``selfalign evaluate``: a complete assessment of a pattern a user drops in."""

from __future__ import annotations

import argparse
from pathlib import Path

from foundation import InputError, check_output_dir
from simulator.commands._flags import add_scene_args
from simulator.commands._liquid import liquid_checks
from simulator.commands._request import SceneRequest
from simulator.commands._scene import accuracy_check, scene_from_args
from simulator.core import AUTO_LANDSCAPE_MB, BATCH_METHODS, DYNAMIC_METHODS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluate",
        help="assess a pattern: minimum, forces, max bias, capture map, yield, HTML report",
        description=(
            "Assess a pattern PNG or layout (.gds, .oas, .dxf: see --layer, --chip-layer): where the chip ends up (global minimum), the restoring force and torque "
            "near alignment, plateaus and the maximum bias along x and y, the capture fraction over a grid of "
            "starts around the global minimum and the yield under placement noise around it (10 % of the chip size, "
            "2 deg). Writes summary.json, "
            "landscape.png, force.png, capture.png, pattern.png and report.html into --out. Without --chip, "
            "--chip-size or --chip-layer the chip is a rectangle the size of the pattern's wettable bounding box. Without "
            f"--resolution, a pattern whose landscape would exceed {AUTO_LANDSCAPE_MB:g} MB is simulated at a "
            "coarser whole multiple of its pixel size (the report says which). The capture and yield starts run greedy steps; "
            "--method gradient, overdamped or inertial chooses another stepper, the dynamics (the chip's mass and damping from "
            "the scene) also reporting the time each start takes to align (median, 90th percentile, time_to_align.png)."
        ),
    )
    p.add_argument(
        "image",
        nargs="?",
        metavar="PATTERN",
        help="the pattern PNG or layout (.gds, .oas, .dxf), or give --pattern / a TOML scene",
    )
    add_scene_args(p)
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output directory: new, or empty (never '.', an input's directory or a link)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace --out if it holds a previous selfalign output (and nothing else)",
    )
    p.add_argument(
        "--method",
        choices=BATCH_METHODS,
        default="greedy",
        help="how the capture and yield starts run: greedy, gradient, or the dynamics overdamped, inertial (default greedy)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.image and args.image.endswith(".toml") and not args.scene:
        args.scene, args.image = args.image, None
    if args.image:
        if args.pattern:
            raise InputError("give the pattern once: as PATTERN or with --pattern")
        args.pattern = args.image
    if not (args.pattern or args.scene):
        raise InputError("give the pattern PNG or layout: selfalign evaluate PATTERN.png --out DIR")
    # the scene file read and validated, the flags and inputs: once for the whole command
    request = SceneRequest.from_args(args)
    inputs = list(request.inputs)
    check_output_dir(args.out, "--out", args.force, inputs)  # before any work
    if not (args.chip or args.chip_size or args.chip_layer or args.scene):
        request = request.with_chip_size(_bbox_chip(args))
    scene = scene_from_args(request, note_frame=False, warn=False)
    layout = scene.pattern.params.get("layout")
    if layout:
        from patterns.layout import frame_note

        print(frame_note(layout))
    from foundation import compiling
    from simulator.landscape import require_landscape_fits, twist_axis

    twist_axis(scene)  # a twist step that gives too many twists fails before the announcement
    if (
        args.resolution is not None
    ):  # the pixel size stays: the landscape and footprint priced now (else after coarsening)
        require_landscape_fits(scene)
    if args.method in DYNAMIC_METHODS:
        from simulator.motion import DynamicsParams

        DynamicsParams.from_scene(scene)  # a liquid the model cannot take fails before compiling

    # The accuracy and droplet warnings once a given pixel size is priced: a refusal does not wait for them.
    accuracy_check(scene)
    liquid_warnings = liquid_checks(
        request, scene, args.method, _noise_biases(scene), "the placement-noise starts"
    )
    # JAX, the engine, matplotlib: imported when a run needs them.
    from simulator.batch import evaluate

    compiling(args.method, args.quiet)
    a = evaluate(
        scene,
        args.out,
        quiet=args.quiet,
        source=Path(args.pattern or args.scene).name,
        auto=args.resolution is None,
        force=args.force,
        inputs=tuple(inputs),
        liquid_warnings=liquid_warnings,
        method=args.method,
    )
    g, cap, yl, men = a.global_minimum, a.capture, a.yield_, a.meniscus
    b = a.max_bias_um
    if g.refined and men is not None:  # below the grid (finite meniscus): to 0.1 um and 0.1 degree
        x, y, t = (round(v, 1) + 0.0 for v in (g.x_um, g.y_um, g.twist_deg))
        k = men.stiffness
        tw = "" if k.twist_Nm_per_rad is None else f", twist {k.twist_Nm_per_rad:.3g} N m/rad"
        print(
            f"global minimum at ({x:.1f} um, {y:.1f} um, {t:.1f} deg), refined below the grid "
            f"(meniscus {men.meniscus_height_um:.3g} um)"
        )
        print(f"stiffness at alignment: x {k.x_N_per_m:.3g} N/m, y {k.y_N_per_m:.3g} N/m{tw}")
    else:
        print(f"global minimum at ({g.x_um:g} um, {g.y_um:g} um, {g.twist_deg:g} deg)")
    fl = men.floating_range if men is not None else None
    if fl:
        r = men.contact_line_reach_um if men is not None else None
        assert r is not None  # a chip floats on free contact lines, whose reach is known
        print(
            f"the chip floats on the well's floor: x {fl.x_from_um:g} to {fl.x_to_um:g} um, y {fl.y_from_um:g} to "
            f"{fl.y_to_um:g} um, twist {fl.twist_from_deg:g} to {fl.twist_to_deg:g} deg (free contact lines "
            f"{r.substrate:.3g} um beyond the chip on the substrate, {r.pad:.3g} um on a pad)"
        )
    print(
        f"max bias: +x {b.plus_x:g} um, -x {b.minus_x:g} um, +y {b.plus_y:g} um, -y {b.minus_y:g} um"
    )
    sg = yl.placement_sigma
    print(
        f"capture fraction {100 * cap.fraction:.1f} % of {cap.n} grid starts; yield {100 * yl.fraction:.1f} % "
        f"of {yl.n} starts under placement noise sigma {sg.x_um:g} um, {sg.y_um:g} um, {sg.twist_deg:g} deg "
        f"({args.method})"
    )
    for name, r in (a.protocols.by_protocol if a.protocols else {}).items():
        pb = r.max_bias_um
        print(
            f"--dispense {name}{' (this scene)' if name == scene.dispense else ''}: max bias +x {pb.plus_x:g} um, "
            f"-x {pb.minus_x:g} um, +y {pb.plus_y:g} um, -y {pb.minus_y:g} um; capture {100 * r.capture_fraction:.1f} %, "
            f"yield {100 * r.yield_fraction:.1f} % (each start released onto that protocol's footprint)"
        )
    from simulator.batch import ABSENT
    from simulator.motion import error_limit_words

    limit = None if a.error_limit is None else a.error_limit.to_dict()
    print(f"final-pose error of the aligned placement-noise starts {error_limit_words(limit)}")
    f = a.restoring_force_N
    print(
        f"restoring force probed at {f.bias_um:.3g} um from the minimum"
        + (" (one grid step beyond the floor)" if fl else "")
        + f": +x F_x {f.plus_x[0] * 1e6:.3g} uN, +y F_y {f.plus_y[1] * 1e6:.3g} uN"
    )
    if a.volume_window:
        from simulator.liquid import window_lines

        w = a.volume_window
        print(window_lines(w, w.get("volume_given"))[0])
    pics = "landscape.png, force.png, capture.png, pattern.png"
    if yl.time_to_align_s is not ABSENT:
        from simulator.commands.montecarlo import time_line

        t = yl.time_to_align_s
        print(f"{time_line(None if t is None else t.to_dict())} (placement-noise starts)")
        pics += ", time_to_align.png"
    print(f"wrote {Path(args.out) / 'report.html'} (and summary.json, {pics})")
    return 0


def _noise_biases(scene):
    """Per yield start of evaluate (its placement noise, seed 0), the larger of |x|, |y| in um."""
    from simulator.batch import NOISE_FRACTION, YIELD_STARTS, chip_size, random_starts
    from simulator.liquid import placement_biases

    w, h = chip_size(scene)
    return placement_biases(
        random_starts(YIELD_STARTS, (NOISE_FRACTION * w, NOISE_FRACTION * h, 0.0), seed=0)
    )


def _bbox_chip(args: argparse.Namespace) -> str:
    """Default chip: the size of the pattern's wettable bounding box (W x H um,
    :func:`patterns.geometry.default_chip_um`)."""
    from patterns import read_mask
    from patterns.geometry import default_chip_um
    from patterns.layout import LayoutSelection, is_layout, layout_geometry

    if is_layout(args.pattern):
        sel = LayoutSelection(
            layer=args.layer,
            cell=args.cell,
            dxf_units=args.dxf_units,
            max_polygons=args.max_polygons,
        )
        geometry = layout_geometry(args.pattern, sel, args.memory_budget)[0]
        return _chip_text(default_chip_um(geometry))
    own = (
        args.pattern_um_per_px is not None
    )  # the scale rule of Scene.from_inputs: a file's own scale wins
    scale, flag = (
        (args.pattern_um_per_px, "--pattern-um-per-px") if own else (args.um_per_px, "--um-per-px")
    )
    kw = (
        {"um_per_px": scale}
        if args.override_scale
        else {
            "default_um_per_px": scale,
            "scale_flag": flag,
            "missing_hint": "--um-per-px (or --pattern-um-per-px)",
        }
    )
    m = read_mask(
        args.pattern,
        invert=args.invert,
        max_mpx=args.max_image_mpx,
        budget_mb=args.memory_budget,
        **kw,
    )
    m.require_nonempty(f"pattern {args.pattern}")
    return _chip_text(default_chip_um(m))


def _chip_text(size: tuple[float, float]) -> str:
    """``--chip-size`` text that reads back as exactly ``size`` (the numbers a sweep's point
    takes for the same pattern), not rounded."""
    return f"{float(size[0])!r}x{float(size[1])!r}"
