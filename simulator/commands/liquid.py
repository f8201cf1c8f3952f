"""``selfalign liquid``: choosing the droplet (meniscus height, overflow, critical volume).

    selfalign liquid height --volume NL (--chip-size W[xH] | --area UM2) [--bias UM] [--json [FILE]]
    selfalign liquid overflow --pad-advancing DEG --chip-angle DEG|LO:HI --edge-angle DEG
                              (--meniscus-height UM | --volume NL --chip-size W[xH]) [--bias UM] [--json [FILE]]
    selfalign liquid critical-volume --size L --gap G --pad-angle DEG --substrate-angle DEG [--json [FILE]]
    selfalign liquid window --pattern P --chip-size C [--volume NL] [--edge-angle DEG --bias UM] [--json [FILE]]

The calculators of :mod:`simulator.liquid`; no landscape, so the command starts and
answers fast (``window`` reads the pattern and chip as simulate does, and computes no
landscape either). ``--json`` alone prints the JSON
(units in every key) instead of the text; ``--json FILE`` writes it and prints the text.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import NoReturn

from foundation import InputError, json_text
from simulator.cli import OneLineParser, unknown_options_message


class _SubParser(OneLineParser):
    """One-line errors for the calculators, before the top-level parser prints its usage."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[no-untyped-def]
        namespace, extras = super().parse_known_args(args, namespace)
        if extras:  # with the nearest of this calculator's options (did you mean --pattern?)
            self.error(unknown_options_message(self, extras))
        return namespace, extras


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--surface-tension",
        type=float,
        default=72.8,
        metavar="MN_M",
        help="liquid surface tension in mN/m (default 72.8, water)",
    )
    p.add_argument(
        "--density",
        type=float,
        default=998.0,
        metavar="KG_M3",
        help="liquid density in kg/m^3 (default 998, water)",
    )
    p.add_argument(
        "--json",
        nargs="?",
        const="-",
        metavar="FILE",
        help="the answer as JSON: alone, on standard output instead of "
        "the text; with FILE, written there",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace the --json FILE if it exists (refused without it)",
    )


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "liquid",
        help="choose the droplet: meniscus height, overflow of protruding pads, critical volume, the volume window of a pattern",
        description="Calculators for the droplet, before any simulation: the meniscus height h = V / A and whether "
        "the thin-film picture holds (height), the no-overflow conditions of a protruding pad (overflow), and the "
        "smallest droplet that wets all four pads of a four-pad pattern (critical-volume), and all of them for a pattern "
        "and chip: the usable volume window (window). Units: um, nl, degrees, mN/m.",
    )
    calc = p.add_subparsers(dest="calculator", metavar="CALCULATOR", parser_class=_SubParser)
    calc.required = True
    h = calc.add_parser(
        "height",
        help="meniscus height h = V / A and the thin-film check",
        description="The flat-film meniscus height h = V / A under the chip, compared with the chip's "
        "smallest side and the capillary length; with --chip-size also the parallelepiped meniscus "
        "(stiffness 2 gamma L / h, force -2 gamma L x / sqrt(x^2 + h^2) at --bias).",
    )
    h.add_argument(
        "--volume",
        type=float,
        required=True,
        metavar="NL",
        help="droplet volume in nl (1 nl = 1e6 um^3)",
    )
    h.add_argument(
        "--chip-size",
        metavar="W[xH]",
        help="the chip in um, e.g. 200 or 730x500 (the wetted area is W H)",
    )
    h.add_argument(
        "--area", type=float, metavar="UM2", help="the wetted area in um^2 instead of a chip size"
    )
    h.add_argument(
        "--bias",
        type=float,
        metavar="UM",
        help="a shift along x in um: the parallelepiped force there",
    )
    _common(h)
    h.set_defaults(func=run_height)

    o = calc.add_parser(
        "overflow",
        help="do the no-overflow conditions (1)-(3) of a protruding pad hold?",
        description="The no-overflow conditions of a pad standing up from the substrate (docs/physics.md §9): "
        "(1) edge angle <= pad advancing angle; (2) edge angle < pad advancing angle + chip angle (the chip "
        "de-wets first); (3) the bias stays below the overflow bias h / tan(edge - pad advancing). The liquid "
        "overflows when none holds. Without --bias, a case where only (3) can hold 'depends on the bias'.",
    )
    o.add_argument(
        "--pad-advancing",
        type=float,
        required=True,
        metavar="DEG",
        help="advancing contact angle on the pad, degrees",
    )
    o.add_argument(
        "--chip-angle",
        required=True,
        metavar="DEG|LO:HI",
        help="the chip's advancing angle (placed with a bias) or "
        "receding angle (placed without and dragged: the stricter case), degrees; a range LO:HI reports the "
        "verdict over it",
    )
    o.add_argument(
        "--edge-angle",
        type=float,
        required=True,
        metavar="DEG",
        help="solid wedge angle of the pad edge, degrees (90 = vertical wall)",
    )
    o.add_argument(
        "--meniscus-height",
        type=float,
        metavar="UM",
        help="the liquid height h in um (or --volume with --chip-size)",
    )
    o.add_argument(
        "--volume",
        type=float,
        metavar="NL",
        help="droplet volume in nl: h = V / A with --chip-size",
    )
    o.add_argument("--chip-size", metavar="W[xH]", help="the chip (and pad) in um, for h = V / A")
    o.add_argument(
        "--bias",
        type=float,
        metavar="UM",
        help="the placement bias in um (its magnitude): decides condition (3)",
    )
    _common(o)
    o.set_defaults(func=run_overflow)

    c = calc.add_parser(
        "critical-volume",
        help="the smallest droplet that wets all four pads of a four-pad pattern",
        description="The critical volume of a four-pad pattern (docs/physics.md §8): the energy of one drop centred "
        "on the pattern against the best split onto single pads, as functions of volume, from a reduced "
        "spherical-cap model (method, assumptions and validity are printed with the answer). Gravity is "
        "neglected; the volume does not depend on the surface tension.",
    )
    c.add_argument(
        "--size",
        type=float,
        required=True,
        metavar="L",
        help="outer side of the pattern in um, gaps included",
    )
    c.add_argument(
        "--gap", type=float, required=True, metavar="G", help="width of the cross-shaped gap in um"
    )
    c.add_argument(
        "--pad-angle",
        type=float,
        required=True,
        metavar="DEG",
        help="contact angle on the pads, degrees",
    )
    c.add_argument(
        "--substrate-angle",
        type=float,
        required=True,
        metavar="DEG",
        help="contact angle on the substrate (gap), degrees",
    )
    _common(c)
    c.set_defaults(func=run_critical_volume)

    w = calc.add_parser(
        "window",
        help="the usable droplet volumes of a pattern and chip: critical volume, thin-film and overflow limits",
        description="The usable droplet volume window of a pattern (PNG or layout: .gds, .oas, .dxf) under a chip, "
        "with the reasoning: the critical volume of a four-pad pattern (recognised in the pattern; below it the drop "
        "may split onto single pads), the thin-film limit (the film h = V / A within 10 % of the chip's smallest "
        "side) and, for protruding pads (--edge-angle) placed with a --bias, the overflow limit. Prints the volume "
        "a run without --volume takes (a film of 5 % of the chip's smallest side) or checks --volume. Units: nl, um, deg.",
    )
    from simulator.commands._flags import add_scene_args

    add_scene_args(w)
    w.add_argument(
        "--bias",
        type=float,
        metavar="UM",
        help="the placement bias in um (its magnitude): with --edge-angle, the overflow limit",
    )
    w.add_argument(
        "--density",
        type=float,
        default=998.0,
        metavar="KG_M3",
        help="liquid density in kg/m^3 (default 998, water): the capillary length",
    )
    w.add_argument(
        "--json",
        nargs="?",
        const="-",
        metavar="FILE",
        help="the answer as JSON: alone, on standard output instead of the text; with FILE, written there",
    )
    w.add_argument(
        "--force",
        action="store_true",
        help="replace the --json FILE if it exists (refused without it)",
    )
    w.set_defaults(func=run_window)


# ----------------------------------------------------------------------- parsing
def _finite(flag: str, value: float | None, positive: bool = True) -> float | None:
    if value is None:
        return None
    if not math.isfinite(value) or (positive and value <= 0):
        raise InputError(
            f"{flag} must be a finite number{' > 0' if positive else ''}, got {value!r}"
        )
    return float(value)


def _given(flag: str, value: float, positive: bool = True) -> float:
    """:func:`_finite` of a flag that is given (required, defaulted or checked present)."""
    v = _finite(flag, value, positive)
    assert v is not None
    return v


def _chip_size(text: str) -> tuple[float, float]:
    from simulator.commands._flags import parse_chip_size

    return parse_chip_size(text)


def _chip_angle(text: str) -> float | tuple[float, float]:
    parts = text.split(":")
    try:
        vals = [float(v) for v in parts]
    except ValueError:
        vals = []
    if len(vals) not in (1, 2) or not all(math.isfinite(v) for v in vals):
        raise InputError(
            f"--chip-angle must be an angle in degrees or a range LO:HI, e.g. 10:30, got {text!r}"
        )
    return vals[0] if len(vals) == 1 else (vals[0], vals[1])


def _liquid(args: argparse.Namespace) -> tuple[float, float]:
    """(surface tension N/m, density kg/m^3) from the flags, checked."""
    from simulator.liquid import check_surface_tension_mN_m

    gamma = check_surface_tension_mN_m(args.surface_tension, "--surface-tension") / 1000
    rho = _given("--density", args.density)
    return gamma, rho


def _emit(args: argparse.Namespace, doc: dict, lines: list[str]) -> int:
    from foundation import require_finite

    require_finite(doc, "the answer")
    text = json_text(doc)
    if args.json == "-":
        sys.stdout.write(text)
        return 0
    if args.json:
        from foundation import atomic_output, check_output_file, require_new_file

        check_output_file(args.json, "--json", [])
        require_new_file(args.json, "--json", args.force)
        with atomic_output(args.json) as tmp:
            tmp.write_text(text)
    print("\n".join(lines))
    if args.json:
        print(f"wrote {args.json}")
    return 0


# ----------------------------------------------------------------------- height
def run_height(args: argparse.Namespace) -> int:
    from simulator.liquid import height_report

    gamma, rho = _liquid(args)
    v = _given("--volume", args.volume)
    if (args.chip_size is None) == (args.area is None):
        raise InputError("give the wetted area once: --chip-size W[xH] (um) or --area UM2")
    sides = _chip_size(args.chip_size) if args.chip_size else None
    area = sides[0] * sides[1] if sides else _given("--area", args.area)
    bias = _finite("--bias", args.bias, positive=False)
    if bias is not None and sides is None:
        raise InputError(
            "--bias needs --chip-size (the parallelepiped force needs the chip's edge length)"
        )
    from simulator.liquid import require_film

    # As simulate and evaluate: a film thicker than the chip is a typing slip (nl for pl), refused.
    w, ht = sides if sides else (math.sqrt(area), math.sqrt(area))
    require_film(v, w, ht, area, None if sides else f"{area:g} um^2 (a square of side {w:.4g} um)")
    r = height_report(v, area, sides, gamma, rho, bias)
    r["surface_tension_mN_m"], r["density_kg_m3"] = gamma * 1000, rho
    h = r["meniscus_height_um"]
    lines = [f"meniscus height h = V / A = {h:.4g} um ({v:g} nl over {area:.6g} um^2)"]
    against = [
        f"{100 * r['h_over_capillary_length']:.3g} % of the capillary length {r['capillary_length_um']:.4g} um"
    ]
    if sides:
        against.insert(
            0,
            f"{100 * r['h_over_smallest_side']:.3g} % of the chip's smallest side {r['smallest_side_um']:g} um",
        )
    lines.append(
        f"thin-film picture {'holds' if r['thin_film_holds'] else 'does not hold'} (h is {', '.join(against)})"
    )
    lines += [f"  {note}" for note in r["thin_film_notes"]]
    if sides:
        pp = r["parallelepiped"]
        line = (
            f"parallelepiped meniscus, shift along x (edge {pp['edge_length_um']:g} um): stiffness 2 gamma L / h = "
            f"{pp['stiffness_N_per_m']:.4g} N/m, large-shift force -2 gamma L = {pp['force_limit_N'] * 1e6:.4g} uN"
        )
        if bias is not None:
            line += f", force at {bias:g} um = {pp['force_N'] * 1e6:.4g} uN"
        lines.append(line)
    return _emit(args, r, lines)


# ----------------------------------------------------------------------- overflow
def run_overflow(args: argparse.Namespace) -> int:
    from simulator.liquid import overflow_report

    _liquid(args)
    chip = _chip_angle(args.chip_angle)
    if args.meniscus_height is not None:
        if args.volume is not None:
            raise InputError(
                "give the liquid height once: --meniscus-height UM, or --volume NL with --chip-size W[xH]"
            )
        h = _given("--meniscus-height", args.meniscus_height)
    else:
        if args.volume is None or args.chip_size is None:
            raise InputError(
                "give the liquid height: --meniscus-height UM, or --volume NL with --chip-size W[xH]"
            )
        from simulator.liquid import require_film

        w, ht = _chip_size(args.chip_size)
        # As `liquid height`, simulate and evaluate: h = V / A, a film thicker than the chip refused.
        h = require_film(_given("--volume", args.volume), w, ht)
    r = overflow_report(
        args.pad_advancing, chip, args.edge_angle, h, _finite("--bias", args.bias, positive=False)
    )
    xo = r["overflow_bias_um"]
    lines = [
        f"meniscus height {h:.4g} um; overflow angle (180 - edge) + pad advancing = {r['overflow_angle_deg']:g} deg; "
        f"overflow bias h / tan(edge - pad advancing) = {'never (condition 1)' if xo is None else f'{xo:.4g} um'}"
    ]

    def said(piece: dict) -> str:
        held = piece["conditions_holding"]
        names = ", ".join(f"({i})" for i in held)
        conds = (
            (f"conditions {names} hold" if len(held) > 1 else f"condition {names} holds")
            if held
            else "no condition holds"
        )
        v = piece["overflows"]
        return f"{conds}: {'overflows' if v is True else 'does not overflow' if v is False else v}"

    if isinstance(chip, tuple):
        for piece in r["over_chip_angle_range"]:
            lo = f"{piece['chip_angle_from_deg']:g}" + (
                " (excluded)" if piece.get("from_excluded") else ""
            )
            lines.append(f"chip angle {lo} to {piece['chip_angle_to_deg']:g} deg: {said(piece)}")
        if r["condition_2_switch_chip_angle_deg"] is not None:
            lines.append(
                f"condition (2) switches on above a chip angle of {r['condition_2_switch_chip_angle_deg']:g} deg (edge - pad advancing)"
            )
    else:
        lines.append(
            f"chip angle {chip:g} deg{'' if args.bias is None else f', bias {abs(args.bias):g} um'}: {said(r)}"
        )
    return _emit(args, r, lines)


# ----------------------------------------------------------------------- critical volume
def run_critical_volume(args: argparse.Namespace) -> int:
    from simulator.liquid import critical_volume

    gamma, rho = _liquid(args)
    size, gap = _given("--size", args.size), _given("--gap", args.gap)
    cv = critical_volume(
        size,
        gap,
        _given("--pad-angle", args.pad_angle),
        _given("--substrate-angle", args.substrate_angle),
    )
    doc = cv.to_json(gamma, rho)
    mid, split = doc["middle_drop"], doc["split_below_critical_volume"]
    lines = [
        f"critical volume {doc['critical_volume_nl']:.4g} nl (V_ND = V^(2/3) / A = {doc['dimensionless_volume_V_ND']:.4g}, "
        f"A = L^2 = {size**2:.6g} um^2, relative gap {100 * gap / size:.3g} %)",
        f"at it, one drop on the pattern centre has a footprint of {mid['footprint_side_um']:.4g} um and an apparent angle of "
        f"{mid['apparent_angle_deg']:.3g} deg; below it the liquid prefers {len(split)} drop{'s' if len(split) != 1 else ''} on single pads ("
        + ", ".join(f"{d['volume_nl']:.3g} nl at {d['apparent_angle_deg']:.3g} deg" for d in split)
        + ")",
        f"method: {doc['method']}",
        "assumptions: " + "; ".join(doc["assumptions"]),
        "validity: " + "; ".join(doc["validity"]),
    ]
    return _emit(args, doc, lines)


# ----------------------------------------------------------------------- volume window
def run_window(args: argparse.Namespace) -> int:
    from simulator.commands._request import SceneRequest
    from simulator.commands._scene import scene_from_args
    from simulator.liquid import volume_window, window_lines

    if args.json and args.json != "-":
        from foundation import check_output_file, require_new_file

        check_output_file(args.json, "--json", [])  # before any work
        require_new_file(args.json, "--json", args.force)
    bias = _finite("--bias", args.bias, positive=False)
    rho = _finite("--density", args.density)
    # the scene file read and validated and the flags over it, once
    request = SceneRequest.from_args(args)
    scene = scene_from_args(request, warn=False)
    if rho is not None and rho != scene.liquid.density_kg_m3:
        import dataclasses

        scene = scene.replace(liquid=dataclasses.replace(scene.liquid, density_kg_m3=rho))
    win = volume_window(scene, bias, "a placement")
    given = not scene.liquid.volume_derived
    win["volume_given"] = given
    return _emit(args, win, window_lines(win, given))
