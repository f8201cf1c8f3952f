"""``selfalign demo``: one real scene end to end, what ``make demo`` runs.

A 730 um square chip released beyond one pad of the library's four-pad pattern
(L = 730 um, gap 50 um, pads 340 um), turned by 8 degrees. Along x it starts on the
plateau 340 < x < 390 um, where an untwisted chip feels no force (docs/physics.md §6.3); it
escapes by turning (6.4) and aligns. The same x-bias with neither y-bias nor twist
stays stuck (check C9), which the summary reports for comparison.

Writes into ``--out`` (default ``out``): ``demo.gif`` (the animated trajectory),
``demo_energy.png`` (energy against step), ``trajectory.json``, ``summary.txt`` and
the evaluation report of the pattern, ``report/report.html`` (see ``selfalign evaluate``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING

from foundation import announce, atomic_output, check_output_dir, compiling, output_directory
from patterns.library import library_path
from simulator.core import UM2
from simulator.scene import Scene

if TYPE_CHECKING:
    from simulator.motion import Trajectory

#: The demo scene: library pattern, square chip side (um), start pose (um, um, deg).
PATTERN = "four_pad_730_50"
CHIP_UM = 730.0
START = (380.0, 120.0, 8.0)
#: The same x-bias without y-bias or twist: stuck on the plateau (docs/physics.md C9).
STUCK_START = (380.0, 0.0, 0.0)
METHOD = "greedy"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="a worked example: a chip escaping a four-pad plateau by twisting (GIF, plot, JSON, summary)",
        description=(
            f"Simulate a {CHIP_UM:g} um chip released at ({START[0]:g} um, {START[1]:g} um, {START[2]:g} deg) "
            f"on the library pattern {PATTERN} ({METHOD} stepping) and write demo.gif, demo_energy.png, "
            "trajectory.json and summary.txt into --out. Takes well under a minute."
        ),
    )
    p.add_argument(
        "--out", default="out", metavar="DIR", help="output directory: new or empty (default: out)"
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace --out if it holds a previous selfalign output (and nothing else)",
    )
    p.add_argument(
        "--quiet",
        action="store_true",
        help="print only the results (no progress bars or waiting messages)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    # JAX: imported when the run needs it (selfalign --help starts without it).
    from simulator.motion import simulate

    out = check_output_dir(args.out, "--out", args.force)  # before any work
    scene = demo_scene()
    compiling(METHOD, args.quiet)
    traj = simulate(scene, START, method=METHOD)
    stuck = simulate(scene, STUCK_START, method=METHOD)
    from simulator.commands.simulate import end_line

    print(end_line(scene, traj))
    from simulator.batch import evaluate

    with output_directory(out, "--out", args.force, command="demo") as tmp:
        files = write_trajectory_files(tmp, scene, traj, args.quiet)
        evaluate(scene, tmp / "report", quiet=args.quiet, source=f"{PATTERN}.png")
        files.append(tmp / "report" / "report.html")
        files.append(
            write_summary(tmp / "summary.txt", scene, traj, stuck, time.perf_counter() - t0, files)
        )
    for path in files:
        print(f"wrote {out / path.relative_to(tmp)}")
    return 0


def demo_scene() -> Scene:
    """The library four-pad pattern (730 um, gap 50 um) with a 730 um square chip, water, 30/60 deg."""
    return Scene.from_inputs(library_path(PATTERN), chip_size_um=CHIP_UM)


def write_trajectory_files(out: Path, scene: Scene, traj: Trajectory, quiet: bool) -> list[Path]:
    """trajectory.json, demo_energy.png and demo.gif; returns their paths."""
    from simulator.commands._outputs import write_json
    from simulator.render import plot_energy_curve, write_trajectory_gif

    paths = [out / "trajectory.json", out / "demo_energy.png", out / "demo.gif"]
    write_json(paths[0], traj.to_json())
    plot_energy_curve(traj, paths[1])
    announce("drawing the animation...", quiet)
    write_trajectory_gif(scene, traj, paths[2], quiet=quiet)
    return paths


def write_summary(
    path: Path, scene: Scene, traj: Trajectory, stuck: Trajectory, seconds: float, files: list[Path]
) -> Path:
    """A short text summary of the scene, the run and the comparison run."""
    m = scene.materials
    um2 = m.delta_gamma_N_m * UM2  # J per um^2 of overlap
    gap = scene.pattern.params.get("parameters", {}).get("gap", {}).get("value", 50.0)
    pad = (CHIP_UM - gap) / 2
    p0, p1 = traj.path[0], traj.path[-1]
    e0, e1 = traj.energy_J[0], traj.energy_J[-1]
    c = traj.cost
    assert c is not None  # a packaged run has its cost
    h, w = scene.pattern.shape
    s = stuck.final
    lines = [
        "selfalign demo: a chip escaping a four-pad plateau by twisting (docs/physics.md §6.3, §6.4)",
        "",
        f"pattern      library {PATTERN}: four-pad, L = {CHIP_UM:g} um, gap {gap:g} um, pads {pad:g} um; "
        f"{w} x {h} px at {scene.um_per_px:g} um/px",
        f"chip         {CHIP_UM:g} x {CHIP_UM:g} um square, whole underside wettable",
        f"materials    surface tension {m.surface_tension_N_m * 1e3:g} mN/m, contact angle {m.pad_angle_deg:g} deg on pads, "
        f"{m.substrate_angle_deg:g} deg on the substrate: Delta_gamma = {m.delta_gamma_N_m:.4g} N/m",
        f"method       {METHOD}: moves of 1 um in x and y and {scene.twist.step_deg:g} deg in twist to the lowest neighbour",
        f"start        x = {p0[0]:g} um, y = {p0[1]:g} um, twist = {p0[2]:g} deg "
        f"(beyond one pad: untwisted, the x-force is zero for {pad:g} < x < {pad + gap:g} um)",
        f"outcome      {traj.outcome} after {traj.steps} steps",
        f"final pose   x = {p1[0] + 0.0:.2f} um, y = {p1[1] + 0.0:.2f} um, twist = {p1[2] + 0.0:.2f} deg",
        f"largest turn {float(abs(traj.path[:, 2]).max()):g} deg on the way (the twist that lets it leave the plateau)",
        f"energy       {e0 * 1e9:.4g} nJ -> {e1 * 1e9:.4g} nJ (overlap {e0 / um2:,.0f} -> {e1 / um2:,.0f} um^2)",
        f"landscape    {c.poses_computed:,} of {c.poses_full:,} poses computed ({100 * c.fraction_of_full:.2g} %), "
        f"{c.landscape_s:.2f} s",
        f"comparison   from ({STUCK_START[0]:g} um, {STUCK_START[1]:g} um, {STUCK_START[2]:g} deg), no y-bias and no twist: "
        f"{stuck.outcome} at ({s[0] + 0.0:.2f} um, {s[1] + 0.0:.2f} um, {s[2] + 0.0:.2f} deg) after {stuck.steps} steps",
        f"run time     {seconds:.1f} s",
        "",
        "files        " + ", ".join(p.relative_to(path.parent).as_posix() for p in [*files, path]),
        "",
    ]
    with atomic_output(path) as tmp:
        tmp.write_text("\n".join(lines))
    return path
