"""``selfalign energy``: overlap, energy, force and torque at poses, and 1-D curves."""

from __future__ import annotations

import argparse
import contextlib
import sys

import numpy as np

from foundation import InputError, atomic_output
from simulator.commands._flags import add_scene_args, parse_pose
from simulator.commands._outputs import add_force_arg, check_outputs, write_json
from simulator.commands._request import SceneRequest
from simulator.commands._scene import accuracy_check, scene_from_args


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "energy",
        help="energy, force and torque at poses; energy curves with plateaus",
        description=(
            "Overlap area (um^2), energy (J), force (N) and torque (N m) of the chip at the "
            "poses given with --at, and optionally a curve along x, y (um) or twist (deg) "
            "through the first pose. Only the twists these queries need are computed."
        ),
    )
    add_scene_args(p)
    p.add_argument(
        "--at",
        action="append",
        default=[],
        metavar="X,Y,TWIST",
        help="pose in um, um, degrees (repeatable)",
    )
    p.add_argument(
        "--curve",
        choices=("x", "y", "twist"),
        help="also sample a curve along this axis through the first --at pose",
    )
    p.add_argument(
        "--from", dest="start", type=float, help="curve start (um, or degrees for twist)"
    )
    p.add_argument("--to", dest="stop", type=float, help="curve end (um, or degrees for twist)")
    p.add_argument("--json", help="write the results as JSON to this file")
    p.add_argument(
        "--csv",
        help="write the poses (kind 'pose') and the curve samples (kind 'curve') as CSV: kind, x_um, "
        "y_um, twist_deg, overlap_um2, energy_J, force_x_N, force_y_N, torque_Nm",
    )
    p.add_argument(
        "--quiet",
        action="store_true",
        help="print only the results (no waiting messages; the warnings stay)",
    )
    add_force_arg(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # The engine: imported when a run needs it (selfalign --help starts without it).
    from simulator.landscape import build_landscape, twists_around

    poses = [parse_pose(a, "--at") for a in args.at] or ([(0.0, 0.0, 0.0)] if args.curve else [])
    if not poses:
        raise InputError(
            "give at least one pose with --at X,Y,TWIST (um, um, degrees), or a --curve"
        )
    if args.curve and (args.start is None or args.stop is None):
        raise InputError("--curve needs --from A --to B (um for x/y, degrees for twist)")
    # the scene file read and validated, the flags, inputs and outputs: once for the whole command
    request = SceneRequest.from_args(args, ("json", "csv"))
    check_outputs(request)
    scene = scene_from_args(request, warn=False)
    twists = [p[2] for p in poses]
    if args.curve == "twist":
        twists += [args.start, args.stop]
    # Priced before any work (the accuracy warning's pattern outline among it), then warned.
    from simulator.landscape import require_landscape_fits

    if scene.dispense is not None:
        from simulator.motion import require_footprint_fits

        require_footprint_fits(scene)
    else:
        require_landscape_fits(scene, twists=twists_around(scene, twists))
    accuracy_check(scene)
    if (
        scene.meniscus_height_um is not None
        and scene.liquid.volume_derived
        and scene.liquid.height_um is None
    ):
        from simulator.commands._liquid import derived_volume_words

        print(f"note: {derived_volume_words(scene)}", file=sys.stderr)
    x, y, t = (np.array(v) for v in zip(*poses, strict=True))
    planes = dispensed = None
    if scene.dispense is not None:
        # Each pose is a chip released there onto the footprint the process left (docs/physics.md §3.5).
        from simulator.landscape import build_footprint_planes
        from simulator.liquid import dispensed_footprint

        planes = build_footprint_planes(scene, twists=twists_around(scene, twists))
        dispensed, why = dispensed_footprint(scene, planes.labels, planes.n_pads)
        print(f"footprint (--dispense {scene.dispense}): {why}; each pose is a chip released there")
        ls = planes.template
        wet_at = [planes.next_state(dispensed, p) for p in poses]
        energy, fx, fy, torque = (np.empty(len(poses)) for _ in range(4))
        summed = {}  # one summed landscape per state the poses share, not one per pose
        for i, w in enumerate(wet_at):
            lw = summed.get(key := tuple(w.tolist()))
            if lw is None:
                lw = summed[key] = planes.landscape(w)
            energy[i] = lw.energy_at(x[i], y[i], t[i])
            fxi, fyi = lw.force_at(x[i], y[i], t[i])
            fx[i], fy[i], torque[i] = fxi, fyi, lw.torque_at(x[i], y[i], t[i])
    else:
        ls = build_landscape(scene, twists=twists_around(scene, twists))
        wet_at = None
        energy = ls.energy_at(x, y, t)
        fx, fy = ls.force_at(x, y, t)
        torque = ls.torque_at(x, y, t)
    area = ls.overlap_um2(energy)
    fx, fy, torque = fx + 0.0, fy + 0.0, torque + 0.0  # no "-0" in the output
    rows = []
    for i, (px, py, pt) in enumerate(poses):
        rows.append(
            {
                "x_um": px,
                "y_um": py,
                "twist_deg": pt,
                "overlap_um2": float(area[i]),
                "energy_J": float(energy[i]),
                "force_N": [float(fx[i]), float(fy[i])],
                "torque_Nm": float(torque[i]),
            }
            | (
                {}
                if wet_at is None
                else {"wet_pads": [int(k) + 1 for k in np.flatnonzero(wet_at[i])]}
            )
        )
        print(
            f"pose ({px:g} um, {py:g} um, {pt:g} deg): overlap {area[i]:,.1f} um^2, energy {energy[i]:.6e} J, "
            f"force ({fx[i]:.4e}, {fy[i]:.4e}) N, torque {torque[i]:.4e} N m"
            + (
                ""
                if wet_at is None
                else "; wet pads: "
                + (", ".join(str(k + 1) for k in np.flatnonzero(wet_at[i])) or "none")
            )
        )
    result = {
        "poses": rows,
        "delta_gamma_N_m": ls.delta_gamma,
        "meniscus_height_um": ls.meniscus_height_um,
        "um_per_px": ls.um_per_px,
        "twist_step_deg": ls.twist_step_deg if len(ls.twist_deg) > 1 else None,
        "noise_floor_J": ls.noise_floor_J,
        "dtype": scene.dtype,
    }
    cur = None
    if args.curve:
        cur = (
            ls.curve(args.curve, poses[0], args.start, args.stop)
            if planes is None
            else planes.released_curve(dispensed, args.curve, poses[0], args.start, args.stop)
        )
        unit = "deg" if args.curve == "twist" else "um"
        funit = "Nm" if args.curve == "twist" else "N"
        result["curve"] = {
            "axis": args.curve,
            f"values_{unit}": cur["values"].tolist(),
            "energy_J": cur["energy_J"].tolist(),
            "overlap_um2": ls.overlap_um2(cur["energy_J"]).tolist(),
            f"force_{funit}": cur["force"].tolist(),
            f"plateaus_{unit}": cur["plateaus"],
            f"flat_steps_{unit}": cur["flat_steps"],
            f"no_contact_{unit}": cur["no_contact"],
        } | ({"wet_pads": cur["wet"]} if "wet" in cur else {})
        print(
            f"curve along {args.curve} through the first pose, {cur['values'][0]:g} to {cur['values'][-1]:g} {unit}, {len(cur['values'])} samples"
        )
        for v, e, f in _sampled(cur):
            e = 0.0 if abs(e) <= ls.noise_floor_J else e  # round-off beyond contact reads as 0
            f = f + 0.0
            print(
                f"  {args.curve} = {v:10.3f} {unit}: energy {e:.6e} J, {'torque' if unit == 'deg' else 'force'} {f:.4e} {funit.replace('Nm', 'N m')}"
            )
        if cur["plateaus"]:
            print(
                "plateaus (zero force, energy changes below the noise floor): "
                + ", ".join(f"[{a:g}, {b:g}] {unit}" for a, b in cur["plateaus"])
            )
        else:
            print("plateaus: none")
        if cur["flat_steps"]:
            print(
                "flat steps (the energy changes below the noise floor from one sample to the "
                "next: a chip moving through stops there): "
                + ", ".join(f"[{a:g}, {b:g}] {unit}" for a, b in cur["flat_steps"])
            )
        if cur["no_contact"]:
            print(
                "no contact (chip off the pattern): "
                + ", ".join(f"[{a:g}, {b:g}] {unit}" for a, b in cur["no_contact"])
            )
    with contextlib.ExitStack() as stack:  # both outputs, or none (moved into place together)
        if args.json:
            write_json(stack.enter_context(atomic_output(args.json)), result)
        if args.csv:
            _write_csv(stack.enter_context(atomic_output(args.csv)), ls, poses, cur)
    for path in (args.json, args.csv):
        if path:
            print(f"wrote {path}")
    return 0


def _write_csv(path, ls, poses: list, cur: dict | None) -> None:
    """One row per pose, then one per curve sample, with the full force and torque at each."""
    from simulator.commands._outputs import write_csv

    x, y, t = (np.array(v, float) for v in zip(*poses, strict=True))
    kind = ["pose"] * len(x)
    if cur is not None:
        n = len(cur["values"])
        cx, cy, ct = (np.full(n, float(c)) for c in poses[0])
        {"x": cx, "y": cy, "twist": ct}[cur["axis"]][:] = cur["values"]
        x, y, t = np.concatenate([x, cx]), np.concatenate([y, cy]), np.concatenate([t, ct])
        kind += ["curve"] * n
    e = ls.energy_at(x, y, t)
    fx, fy = ls.force_at(x, y, t)
    tq = ls.torque_at(x, y, t)
    cols = [
        "kind",
        "x_um",
        "y_um",
        "twist_deg",
        "overlap_um2",
        "energy_J",
        "force_x_N",
        "force_y_N",
        "torque_Nm",
    ]
    write_csv(path, cols, [kind, x, y, t, ls.overlap_um2(e), e, fx + 0.0, fy + 0.0, tq + 0.0])


def _sampled(cur: dict, most: int = 21):
    """At most ``most`` evenly spaced rows of a curve for the terminal (the JSON has all)."""
    n = len(cur["values"])
    idx = np.unique(np.linspace(0, n - 1, min(n, most)).round().astype(int))
    return zip(cur["values"][idx], cur["energy_J"][idx], cur["force"][idx], strict=True)
