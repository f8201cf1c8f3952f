"""The flags shared by the commands that build a scene, and their value types: limits
(finite numbers, whole numbers), the scene's inputs, materials and pose grid
(:func:`add_scene_args`), a chip size and a pose as typed."""

from __future__ import annotations

import argparse
import math
from typing import Any

from foundation import InputError


def finite_limit(flag: str, unit: str) -> Any:
    """An argparse type for a limit flag: a finite number > 0 (``nan`` or ``inf`` would switch the guard off)."""

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"must be a finite number > 0 ({unit}), got {text!r}"
            ) from None
        if not (math.isfinite(v) and v > 0):
            off = (
                "; a limit cannot be switched off" if not (math.isfinite(v) or v < 0) else ""
            )  # nan, inf
            raise argparse.ArgumentTypeError(
                f"must be a finite number > 0 ({unit}), got {text!r}{off}"
            )
        return v

    parse.__name__ = flag  # argparse names the type in its messages
    return parse


def whole_limit(flag: str) -> Any:
    """An argparse type for a count limit: a whole number >= 1."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}") from None
        if v < 1:
            raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
        return v

    parse.__name__ = flag
    return parse


def add_scene_args(p: argparse.ArgumentParser) -> None:
    """Pattern, chip, scale, materials and pose-grid options (a TOML scene may give them)."""
    p.add_argument(
        "scene", nargs="?", help="optional TOML scene file; flags given here override it"
    )
    g = p.add_argument_group("inputs")
    g.add_argument(
        "--pattern", help="pattern PNG (white = wettable pad) or layout (.gds, .oas, .dxf)"
    )
    g.add_argument(
        "--chip",
        help="chip footprint PNG (white = wettable), or a layout holding only the chip outline",
    )
    g.add_argument("--chip-size", help="rectangular chip W[xH] in um, e.g. 730 or 730x500")
    g.add_argument(
        "--um-per-px",
        type=float,
        help="pixel size in um of the PNGs that store no scale (a file's own pHYs "
        "scale wins; one that contradicts it is refused, see --override-scale); for a layout, the raster's "
        "pixel size when --resolution is not given (default 1)",
    )
    g.add_argument(
        "--pattern-um-per-px",
        type=float,
        metavar="UM",
        help="the same for the pattern file alone (wins over --um-per-px)",
    )
    g.add_argument(
        "--chip-um-per-px",
        type=float,
        metavar="UM",
        help="the same for the chip file alone (wins over --um-per-px)",
    )
    g.add_argument(
        "--override-scale",
        action="store_true",
        help="let the scale flags replace the scales the files store",
    )
    g.add_argument(
        "--invert",
        action="store_true",
        help="the pattern image marks the pad in black: take 1 - value "
        "(transparent pixels stay non-wettable)",
    )
    g.add_argument("--invert-chip", action="store_true", help="the same for the chip image")
    from patterns import CHANNELS

    g.add_argument(
        "--channel",
        choices=CHANNELS,
        help="what to read from a colour pattern or chip image whose channels differ: one "
        "channel (its bright part is wettable) or the luminance (without it such an image is "
        "refused; a grey image stored as colour is read as it is)",
    )
    y = p.add_argument_group("layout patterns (.gds, .oas, .dxf)")
    y.add_argument(
        "--layer",
        metavar="L/D",
        help="the pattern's layer/datatype, e.g. 1/0 (DXF: the layer name; default: the only layer)",
    )
    y.add_argument(
        "--cell",
        metavar="NAME",
        help="the cell to read (default: the single top cell; DXF: the model space, or a block)",
    )
    y.add_argument(
        "--chip-layer",
        metavar="L/D",
        help="read the chip outline from this layer: its position in the layout is "
        "the aligned pose (default: no chip layer; the target is the pattern's bounding-box centre)",
    )
    y.add_argument(
        "--dxf-units",
        choices=("um", "mm", "nm"),
        help="units of a DXF file that states none ($INSUNITS)",
    )
    from patterns.layout import DEFAULT_MAX_POLYGONS

    y.add_argument(
        "--max-polygons",
        type=whole_limit("--max-polygons"),
        metavar="N",
        help="most polygons the layout cell may "
        f"hold once flattened (default {DEFAULT_MAX_POLYGONS}; about 20 s of work per 100000)",
    )
    g.add_argument(
        "--resolution",
        type=float,
        help="simulate at this pixel size in um (resamples the pattern; default: its own)",
    )
    m = p.add_argument_group("materials")
    m.add_argument(
        "--surface-tension", type=float, help="liquid surface tension in mN/m (default 72.8, water)"
    )
    m.add_argument(
        "--pad-angle", type=float, help="contact angle on the pads in degrees (default 30)"
    )
    m.add_argument(
        "--substrate-angle",
        type=float,
        help="contact angle on the substrate in degrees (default 60)",
    )
    m.add_argument(
        "--allow-repulsive",
        action="store_true",
        help="allow a pad that wets worse than the substrate",
    )
    n = p.add_argument_group("pose grid and numerics")
    n.add_argument("--accuracy", choices=("fast", "balanced", "precise"), help=_accuracy_help())
    n.add_argument("--twist-step", type=float, help="twist grid step in degrees (default 1)")
    n.add_argument(
        "--no-twist", action="store_true", help="keep the chip untwisted (computes one rotation)"
    )
    n.add_argument(
        "--window",
        type=float,
        help="translation half-width of the pose grid in um (default: full reach)",
    )
    n.add_argument(
        "--dtype", choices=("float32", "float64"), help="landscape precision (default float32)"
    )
    n.add_argument(
        "--memory-budget",
        type=finite_limit("--memory-budget", "MB"),
        help="memory budget in MB for the landscape and every other large array "
        "(default: half the available memory, at most 8192; never more than the machine has)",
    )
    g.add_argument(
        "--max-image-mpx",
        type=finite_limit("--max-image-mpx", "megapixels"),
        help="largest image to read, in megapixels (default 64)",
    )
    q = p.add_argument_group("liquid and meniscus")
    q.add_argument(
        "--volume",
        type=float,
        help="droplet volume in nl (default: derived from the chip, a film V / A of 5 %% of its "
        "smallest side; selfalign liquid window shows the usable range): the meniscus height V / A under the "
        "chip for --meniscus, and the film of the dynamic methods",
    )
    q.add_argument(
        "--meniscus",
        action="store_true",
        help="finite meniscus: round the overlap energy's cusps over the "
        "liquid height (default off: the thin-film overlap model)",
    )
    q.add_argument(
        "--meniscus-height",
        type=float,
        metavar="UM",
        help="the meniscus height in um (default: --volume "
        "over the chip's wetted area); implies --meniscus",
    )
    t = p.add_argument_group("protruding pads (the overflow check, docs/physics.md §9)")
    t.add_argument(
        "--edge-angle",
        type=float,
        metavar="DEG",
        help="the pads stand up from the substrate with this edge "
        "(solid wedge) angle in degrees, 90 = vertical wall: warn when the placement can overflow them",
    )
    t.add_argument(
        "--pad-advancing",
        type=float,
        metavar="DEG",
        help="advancing contact angle on the pads in degrees "
        "(default: the advancing angle of --hysteresis, else --pad-angle)",
    )
    t.add_argument(
        "--chip-angle",
        type=float,
        metavar="DEG",
        help="the chip's advancing contact angle in degrees "
        "(its receding angle for the stricter case; default: unknown)",
    )
    q.add_argument(
        "--hysteresis",
        metavar="RECEDING:ADVANCING",
        help="contact-angle hysteresis of the pads, in degrees "
        "(e.g. 31:50): runs stop where the restoring force falls below the contact lines' pinning force "
        "gamma (cos theta_r - cos theta_a) per unit length (default off)",
    )
    q.add_argument(
        "--dispense",
        choices=("pattern", "chip", "none"),
        help="where the process puts the liquid, which makes the wetted footprint a state of the "
        "run: 'pattern' (the droplet dispensed on the pattern before the chip is released "
        "onto it: every pad it covers starts wet) or 'chip' (the liquid comes in under the chip and "
        "wets what it reaches); pads then wet when the liquid's foot reaches them and dry beyond "
        "the reach of the chip's wall (docs/physics.md §3.5; needs --meniscus, free contact lines); "
        "'none': no state, every pad counted by its distance from the chip (default: 'pattern' "
        "with --meniscus and free contact lines, else none)",
    )
    q.add_argument(
        "--dispense-at",
        metavar="X,Y",
        help="where a --dispense pattern droplet is dispensed, in um (default: the pattern's centre)",
    )
    q.add_argument(
        "--pinned",
        action="store_true",
        help="contact lines held at the pad edges (liquid confined by a "
        "superhydrophobic substrate): the energy is the liquid-air area, Delta_gamma = -2 gamma",
    )


def _accuracy_help() -> str:
    from simulator.scene import DEFAULT_PRESET, PRESETS

    return (
        f"accuracy preset (default {DEFAULT_PRESET}) setting the pixel size, twist step and dtype "
        "that you do not set yourself (--resolution, --twist-step, --dtype win). "
        + " | ".join(p.describe() for p in PRESETS.values())
    ).replace("%", "%%")


def parse_chip_size(text: str) -> tuple[float, float]:
    try:
        parts = [float(v) for v in text.lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) not in (1, 2) or not all(math.isfinite(v) and v > 0 for v in parts):
        raise InputError(f"--chip-size must be W or WxH in um with positive numbers, got {text!r}")
    return (parts[0], parts[-1])


def parse_pose(text: str, flag: str) -> tuple[float, float, float]:
    """'X,Y,TWIST' (um, um, degrees) -> floats."""
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise InputError(f"{flag} must be X,Y,TWIST (um, um, degrees), got {text!r}")
    return vals[0], vals[1], vals[2]
