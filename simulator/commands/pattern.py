"""``selfalign pattern``: draw a design as a 16-bit PNG that carries its scale, or as a mask layout.

    selfalign pattern DESIGN [design parameters] [--um-per-px R] [--margin M] -o OUT.png
    selfalign pattern DESIGN [design parameters] -o OUT.gds    (or .oas, .dxf)
    selfalign pattern --list

Design parameters are lengths in micrometres (see ``--list``). The image is centred on the
nominal pattern centre, y up, with an anti-aliased (area-coverage) edge; its pHYs chunk
records the scale and a ``selfalign`` text chunk the parameters. A layout holds the exact
polygon, vertices rounded to the 1 nm database unit, on layer 1/0 (DXF: layer PATTERN, in
micrometres), origin at the nominal pattern centre (:func:`patterns.layout.write_layout`);
``--um-per-px`` and ``--margin`` do not apply to it.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import NoReturn

from foundation import InputError, positive
from patterns.geometry import DESIGNS, Design
from simulator.cli import OneLineParser

DEFAULT_MARGIN_UM = 10.0


class _OneLineParser(OneLineParser):
    """Argument errors as one line (no usage block), exit code 2, like InputError; values
    with a leading minus sign after a space, as every command (``--points "-100,-100;..."``)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[no-untyped-def]
        namespace, extras = super().parse_known_args(args, namespace)
        if extras:  # reject here, before the top-level parser prints its usage block
            from simulator.cli import unknown_options_message

            self.error(unknown_options_message(self, extras))
        return namespace, extras


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "pattern",
        help="draw a pattern design as a PNG with its scale",
        description="Draw a pattern design (lengths in um) as a 16-bit grey PNG whose pHYs chunk "
        "records the scale. White = wettable. Use --list to see the designs and their parameters.",
    )
    parser.add_argument(
        "--list", action="store_true", help="describe every design and its parameters"
    )
    designs = parser.add_subparsers(dest="design", metavar="DESIGN", parser_class=_OneLineParser)
    for design in DESIGNS.values():
        sub = designs.add_parser(
            design.name,
            help=design.description,
            description=design.description,
            usage=_usage(design),
        )
        for p in design.params:
            sub.add_argument(
                p.flag,
                dest=f"p_{p.name}",
                metavar=p.unit.upper() or p.kind.upper(),
                help=p.describe().split(": ", 1)[1],
            )
        sub.add_argument(
            "--um-per-px", default="1", metavar="UM", help="pixel size in micrometres (default 1)"
        )
        sub.add_argument(
            "--margin",
            default=str(DEFAULT_MARGIN_UM),
            metavar="UM",
            help=f"substrate border around the design in um (default {DEFAULT_MARGIN_UM:g})",
        )
        sub.add_argument(
            "-o",
            "--output",
            metavar="OUT.png",
            help="output file (required): a PNG, or a layout .gds, .oas or .dxf "
            "(exact polygon, 1 nm database unit, layer 1/0; DXF layer PATTERN)",
        )
        sub.add_argument(
            "--force",
            action="store_true",
            help="replace the -o file if it exists (refused without it)",
        )
        sub.set_defaults(func=run)
    parser.set_defaults(func=run, design=None)


def _usage(design: Design) -> str:
    """The usage line of ``pattern DESIGN``: the required parameters and ``-o`` without the
    brackets argparse puts round every option (this command checks them itself, to name the
    parameter's meaning and unit when one is missing)."""
    params = " ".join(
        f"{p.flag} {p.unit.upper() or p.kind.upper()}"
        if p.required
        else f"[{p.flag} {p.unit.upper() or p.kind.upper()}]"
        for p in design.params
    )
    return f"%(prog)s [-h] {params} [--um-per-px UM] [--margin UM] -o OUT.png [--force]"


def describe_designs() -> str:
    """Text of ``--list``: each design, its description and its parameters with units."""
    lines = []
    for design in DESIGNS.values():
        lines.append(f"{design.name}: {design.description}")
        lines.extend(f"    {p.describe()}" for p in design.params)
    lines.append(
        "every design also takes: --um-per-px UM (default 1), "
        f"--margin UM (default {DEFAULT_MARGIN_UM:g}), -o OUT.png (required; or OUT.gds, OUT.oas, OUT.dxf for a layout)"
    )
    return "\n".join(lines)


def _design_values(design: Design, args: argparse.Namespace) -> dict:
    values = {}
    for p in design.params:
        text = getattr(args, f"p_{p.name}")
        if text is None:
            if p.required:
                raise InputError(
                    f"{design.name} needs {p.flag} ({p.help}{', ' + p.unit if p.unit else ''})"
                )
            continue
        values[p.name] = p.coerce(text, p.flag)
    return values


def run(args: argparse.Namespace) -> int:
    if args.list:
        print(describe_designs())
        return 0
    if args.design is None:
        raise InputError(f"name a design ({', '.join(DESIGNS)}) or use --list")
    # Lazy imports: the raster and PNG code are not needed for --list or --help.
    from patterns import write_mask
    from patterns.geometry import build, design_record, mask_from_geometry

    design = DESIGNS[args.design]
    values = _design_values(design, args)
    scale = positive("--um-per-px", args.um_per_px, "um per px")
    try:
        margin = float(args.margin)
    except ValueError:
        margin = float("nan")
    if not 0 <= margin < float("inf"):
        raise InputError(f"--margin must be a finite number >= 0 um, got {args.margin!r}")
    if args.output is None:
        raise InputError(
            "-o OUT.png is required (the PNG file to write; or OUT.gds, OUT.oas, OUT.dxf for a layout)"
        )
    if not Path(args.output).is_dir():  # a directory: write_mask and write_layout say so
        from foundation import check_output_file, require_new_file

        check_output_file(args.output, "-o")  # a link, a device: said as such, before "exists"
        require_new_file(args.output, "-o", args.force)
    geometry = build(design.name, **values)
    from patterns.layout import SUFFIXES

    suffix = Path(args.output).suffix.lower()
    if suffix in SUFFIXES:
        return _write_layout(args.output, design.name, geometry)
    if suffix != ".png" and not Path(args.output).is_dir():  # a directory: write_mask says so
        raise InputError(
            f"-o {args.output}: the file name must end in .png, or in .gds, .oas or .dxf for a layout"
        )
    record = design_record(design.name, **values)
    record.update(margin_um=margin, area_um2=geometry.area)
    mask = mask_from_geometry(geometry, scale, margin_um=margin, params=record)
    mask.require_nonempty(f"{design.name} at --um-per-px {scale:g}")
    path = write_mask(args.output, mask)
    h, w = mask.shape
    print(
        f"wrote {path}: {w} x {h} px at {scale:g} um/px ({w * scale:g} x {h * scale:g} um), "
        f"wettable area {mask.area_um2:.6g} um^2 (exact {geometry.area:.6g} um^2)"
    )
    return 0


def _write_layout(output: str, name: str, geometry) -> int:
    """Write the exact polygon as a layout and say what was written."""
    import shapely

    from patterns.layout import WRITE_DXF_LAYER, WRITE_LAYER, snap, write_layout

    path = write_layout(output, geometry, cell=name)
    layer = (
        WRITE_DXF_LAYER if path.suffix.lower() == ".dxf" else f"{WRITE_LAYER[0]}/{WRITE_LAYER[1]}"
    )
    n = len(shapely.get_parts(geometry))
    where = "model space" if path.suffix.lower() == ".dxf" else f"cell {name.replace('-', '_')}"
    print(
        f"wrote {path}: {where}, layer {layer}, {n} polygon{'' if n == 1 else 's'}, database unit 1 nm, "
        f"area {snap(geometry).area:.12g} um^2 (exact {geometry.area:.12g} um^2)"
    )
    return 0
