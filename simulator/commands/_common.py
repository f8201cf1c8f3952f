"""Options and parsing shared by the commands that build a scene."""

from __future__ import annotations

import argparse
import contextlib
import copy
import json
import math
import os
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from foundation import InputError, atomic_output
from simulator.scene import Scene


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


def scene_document(args: argparse.Namespace) -> dict[str, Any]:
    """The scene file's document (``args.scene``, read and validated by :func:`read_toml`),
    or {} without one. A command reads it once and passes it on (``doc=``) to
    :func:`scene_from_args`, :func:`liquid_checks` and :func:`check_outputs`."""
    return read_toml(args.scene) if args.scene else {}


def scene_from_args(
    args: argparse.Namespace,
    note_frame: bool = True,
    doc: dict[str, Any] | None = None,
    warn: bool = True,
) -> Scene:
    """Build the scene from an optional TOML file and the flags (flags win).

    Flags are merged into the TOML document under the TOML keys (see
    :mod:`simulator.scene`), so a file and the command line mean the same thing.
    ``doc``: the scene file's document when the command has read it
    (:func:`scene_document`; it is not changed), else it is read here.
    For a layout pattern, ``note_frame`` prints on stderr where the poses' origin is.
    ``warn=False`` leaves the accuracy warning (:func:`accuracy_check`) to the command, which
    prints it once its run is priced.
    """
    doc, base = scene_document_from_args(args, doc)
    try:
        scene = Scene.from_dict(
            doc, base=base
        )  # the accuracy preset applies here, as for Scene.from_toml
    except InputError as err:
        raise InputError(_cli_spelling(str(err), bool(args.scene))) from None
    if "volume_nl" in (
        doc.get("liquid") or {}
    ):  # a volume as typed: a film thicker than the chip is refused
        from simulator.liquid import check_scene_volume

        check_scene_volume(scene)
    if warn:
        accuracy_check(scene)
    if note_frame and "layout" in scene.pattern.params:
        from patterns.layout import frame_note

        print(frame_note(scene.pattern.params["layout"]), file=sys.stderr)
    return scene


def scene_document_from_args(
    args: argparse.Namespace, doc: dict[str, Any] | None = None
) -> tuple[dict[str, Any], Path]:
    """The scene document the flags and an optional TOML file make (flags win, under the
    TOML keys), and the directory its relative paths are read against: what
    :func:`scene_from_args` builds its scene from (``doc``: the scene file's document, not
    changed)."""
    doc = copy.deepcopy(scene_document(args) if doc is None else doc)
    base = Path(args.scene).parent if args.scene else Path(".")
    if args.pattern:
        doc["pattern"] = str(Path(args.pattern).resolve())
    chips = {
        "chip": str(Path(args.chip).resolve()) if args.chip else None,
        "chip_size_um": list(parse_chip_size(args.chip_size)) if args.chip_size else None,
        "chip_layer": getattr(args, "chip_layer", None),
    }
    given = {k: v for k, v in chips.items() if v is not None}
    if given:  # a chip on the command line replaces the scene file's (two on the command line: refused downstream)
        for k in chips:
            doc.pop(k, None)
        doc.update(given)
    if "pattern" not in doc:
        raise InputError(
            "no pattern given: pass --pattern P.png or a layout P.gds (or a TOML scene with pattern = ...)"
        )
    if not any(k in doc for k in chips):
        raise InputError(
            "no chip given: pass --chip C.png, --chip-size W[xH] (um) or, for a layout, --chip-layer L/D"
        )
    flags = {
        ("materials", "surface_tension_mN_m"): args.surface_tension,
        ("materials", "pad_angle_deg"): args.pad_angle,
        ("materials", "substrate_angle_deg"): args.substrate_angle,
        ("materials", "allow_repulsive"): True if args.allow_repulsive else None,
        ("twist", "step_deg"): args.twist_step,
        ("effects", "twist"): False if args.no_twist else None,
        ("effects", "meniscus"): True
        if (getattr(args, "meniscus", False) or getattr(args, "meniscus_height", None) is not None)
        else None,
        ("liquid", "meniscus_height_um"): getattr(args, "meniscus_height", None),
        ("liquid", "pinned"): True if getattr(args, "pinned", False) else None,
        ("liquid", "dispense"): getattr(args, "dispense", None),
        ("liquid", "dispense_at_um"): getattr(args, "dispense_at", None),
        ("effects", "hysteresis"): True if getattr(args, "hysteresis", None) else None,
        (None, "um_per_px"): args.um_per_px,
        (None, "pattern_um_per_px"): getattr(args, "pattern_um_per_px", None),
        (None, "chip_um_per_px"): getattr(args, "chip_um_per_px", None),
        (None, "override_scale"): True if getattr(args, "override_scale", False) else None,
        (None, "invert"): True if getattr(args, "invert", False) else None,
        (None, "invert_chip"): True if getattr(args, "invert_chip", False) else None,
        (None, "channel"): getattr(args, "channel", None),
        (None, "resolution_um"): args.resolution,
        (None, "window_um"): args.window,
        (None, "dtype"): args.dtype,
        (None, "memory_budget_mb"): args.memory_budget,
        (None, "max_image_mpx"): getattr(args, "max_image_mpx", None),
        (None, "layer"): getattr(args, "layer", None),
        (None, "cell"): getattr(args, "cell", None),
        (None, "dxf_units"): getattr(args, "dxf_units", None),
        (None, "max_polygons"): getattr(args, "max_polygons", None),
        ("liquid", "volume_nl"): getattr(args, "volume", None),
        ("topography", "edge_angle_deg"): getattr(args, "edge_angle", None),
        ("topography", "pad_advancing_deg"): getattr(args, "pad_advancing", None),
        ("topography", "chip_angle_deg"): getattr(args, "chip_angle", None),
        # Liquid and chip body: only commands with dynamics define these flags.
        ("liquid", "viscosity_mPa_s"): getattr(args, "viscosity", None),
        (None, "chip_thickness_um"): getattr(args, "chip_thickness", None),
        (None, "chip_density_kg_m3"): getattr(args, "chip_density", None),
        (None, "damping_calibration"): getattr(args, "damping_calibration", None),
        (None, "line_friction_Pa_s"): getattr(args, "line_friction", None),
    }
    if getattr(args, "hysteresis", None):
        from simulator.physics import parse_window

        r, a = parse_window(args.hysteresis)
        flags[("materials", "pad_receding_deg")], flags[("materials", "pad_advancing_deg")] = r, a
    for (table, key), value in flags.items():
        if value is not None:
            (doc.setdefault(table, {}) if table else doc)[key] = value
    if getattr(args, "accuracy", None):
        doc["accuracy"] = args.accuracy
    return doc, base


#: Python keyword spellings in the scene's messages: the command-line flag and the scene file's key.
_PY_TO_CLI = {
    "pass allow_repulsive=True": (
        "pass --allow-repulsive",
        "allow_repulsive = true under [materials]",
    )
}


def _cli_spelling(message: str, scene_file: bool) -> str:
    """``message`` with a Python keyword the fix names replaced by the command-line flag (and the
    scene file's key too when the scene comes from a file)."""
    for py, (flag, key) in _PY_TO_CLI.items():
        if py in message:
            message = message.replace(
                py, flag + (f" (or {key} in the scene file)" if scene_file else "")
            )
    return message


def accuracy_check(scene: Scene) -> None:
    """The scene's accuracy warning on stderr, when its pixel size leaves the pattern's
    smallest feature under 3 px (:meth:`Scene.accuracy_warning`). Measuring the feature
    outlines the whole pattern (0.3 s for a 16-megapixel image), so commands that price
    their run call this once the run is priced: a refusal does not wait for it. A chip much
    larger than the pattern's image (:meth:`Scene.scale_warning`) is warned of here too."""
    for warning in (*scene.input_warnings, scene.scale_warning(), scene.accuracy_warning()):
        if warning:
            print(f"warning: {warning}", file=sys.stderr)


def liquid_checks(
    args: argparse.Namespace,
    scene: Scene,
    method: str,
    biases_um: Any = None,
    placed: str = "the start",
    doc: dict[str, Any] | None = None,
) -> list[str]:
    """The droplet checks of :mod:`simulator.liquid` for a volume the user gave (``--volume``
    or ``[liquid] volume_nl``; :func:`scene_from_args` has refused a film thicker than the
    chip): a note when ``method`` does not use the volume, and the warnings of
    :func:`simulator.liquid.scene_warnings` (``biases_um``: per start, the larger of |x|, |y|),
    each printed as one line on stderr and returned for the JSON (``liquid_warnings``).
    ``doc``: the scene file's document (:func:`scene_document`; default: read here)."""
    from simulator.liquid import scene_warnings, volume_note

    given = getattr(args, "volume", None) is not None or (
        bool(args.scene)
        and "volume_nl" in ((scene_document(args) if doc is None else doc).get("liquid") or {})
    )
    used = method in ("overdamped", "inertial") or bool(getattr(scene.effects, "meniscus", False))
    if (
        not given
        and used
        and scene.liquid.volume_derived
        and getattr(scene.liquid, "height_um", None) is None
    ):
        # The volume derived from the chip (simulator.liquid.default_volume_nl), said and checked.
        print(f"note: {derived_volume_words(scene)}", file=sys.stderr)
        warns = scene_warnings(scene, biases_um, placed)
    elif not given:
        warns = []
        if scene.topography is not None:
            warns.append(
                "overflow check skipped: the scene declares a protruding pad (edge angle) but no droplet "
                "volume; give --volume NL to check the placement against the overflow bias"
            )
    else:
        note = volume_note(scene, method)
        if note:
            print(f"note: {note}", file=sys.stderr)
        warns = scene_warnings(scene, biases_um, placed)
    for w in warns:
        print(f"warning: {w}", file=sys.stderr)
    return warns


def derived_volume_words(scene: Scene) -> str:
    """'droplet volume 6.25 nl derived from the chip (...)': the volume a scene without
    ``--volume`` takes (:func:`simulator.liquid.default_volume_nl`), its film and the rule."""
    from simulator.liquid import DEFAULT_FILM_FRACTION

    v = scene.liquid.volume_nl
    h = scene.liquid_height_um
    return (
        f"droplet volume {v:.3g} nl derived from the chip (no --volume): a film h = V / A = {h:.3g} um, "
        f"{100 * DEFAULT_FILM_FRACTION:g} % of its smallest side {scene.chip_min_side_um:g} um "
        "(selfalign liquid window shows the usable range; give --volume NL to choose)"
    )


def read_toml(path: str | os.PathLike) -> dict[str, Any]:
    """Read and validate a TOML scene file (:func:`simulator.scene.read_scene_file`)."""
    from simulator.scene import read_scene_file

    return read_scene_file(path)


def input_paths(args: argparse.Namespace, doc: dict[str, Any] | None = None) -> list[Path]:
    """The files this run reads (pattern, chip, scene and the scene's own pattern/chip).
    ``doc``: the scene file's document (:func:`scene_document`; default: read here)."""
    paths = [getattr(args, k, None) for k in ("scene", "pattern", "chip", "image")]
    scene = getattr(args, "scene", None)
    if scene:
        if doc is None:
            try:
                doc = read_toml(scene)
            except InputError:
                doc = {}
        for key in ("pattern", "chip"):
            if isinstance(doc.get(key), str):
                paths.append(str(Path(scene).parent / doc[key]))
    return [Path(p) for p in paths if isinstance(p, str) and p]


def check_outputs(
    args: argparse.Namespace, flags: tuple[str, ...], doc: dict[str, Any] | None = None
) -> None:
    """Fail before any work when an output file cannot or must not be written.

    ``flags`` are attribute names (``json`` for ``--json``). An output may not be an
    input, a link, a device or a directory, and two outputs may not name one file; one that
    exists is refused unless ``args.force`` (:func:`add_force_arg`).
    ``doc``: the scene file's document (:func:`scene_document`; default: read here).
    """
    from foundation import check_distinct, check_output_file, require_new_file

    inputs = input_paths(args, doc)
    named = {f"--{f.replace('_', '-')}": getattr(args, f, None) for f in flags}
    for flag, path in named.items():
        if path:
            check_output_file(path, flag, inputs)
            require_new_file(path, flag, bool(getattr(args, "force", False)))
    check_distinct(named)


def add_force_arg(p: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--force``: replace output files that exist (refused without it, before any work)."""
    p.add_argument(
        "--force",
        action="store_true",
        help="replace output files that already exist (without it an existing one is refused "
        "before any work; an input of the run is never replaced)",
    )


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write JSON atomically (no half-written file on failure); every number must be finite."""
    from foundation import require_finite

    require_finite(obj, f"output {path}")
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2, allow_nan=False) + "\n")


def write_csv(path: str | os.PathLike, columns: list[str], values: list) -> None:
    """Write a table as CSV atomically: ``columns`` (names carry their units, e.g. ``x_um``)
    and one array (or list of strings) per column, rows in order. Every number must be
    finite (:func:`simulator.core.require_finite`)."""
    import numpy as np

    from foundation import require_finite

    cols = [np.asarray(v) for v in values]
    require_finite(
        {c: v for c, v in zip(columns, cols, strict=True) if v.dtype.kind in "fiu"},
        f"output {path}",
    )
    n = len(cols[0]) if cols else 0

    def cell(v) -> str:
        return f"{v:.10g}" if isinstance(v, float | np.floating) else str(v)

    with atomic_output(path) as tmp, open(tmp, "w") as f:
        f.write(",".join(columns) + "\n")
        for i in range(0, n, 65536):
            rows = zip(*(c[i : i + 65536].tolist() for c in cols), strict=True)
            f.write("".join(",".join(cell(v) for v in row) + "\n" for row in rows))


@contextlib.contextmanager
def sigterm_says_what_was_kept(out: str, command: str, noun: str, *kept: str) -> Iterator[None]:
    """While a resumable run (``sweep``, ``design``'s search) works into ``out``, SIGTERM ends it
    as the CLI's handler does (temporaries removed, at once), but says how many finished
    ``noun``s ``out`` keeps (a rerun resumes them), and leaves no semaphore of the Dask cluster
    behind (the resource tracker's warnings). ``kept``: the journal's name and its record's
    noun for :func:`simulator.sweep.kept_points`, when they are not the sweep's."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(signum, frame):
        from foundation import remove_pending
        from simulator.sweep import kept_points, release_semaphores

        remove_pending()
        n = kept_points(out, *kept) if os.path.isdir(out) else 0
        release_semaphores()
        said = (
            f"{n} finished {noun}{'s are' if n != 1 else ' is'} kept in {out} (rerun the same command to resume)"
            if n
            else f"no {noun} had finished, none was kept"
        )
        os.write(2, f"selfalign {command}: terminated; {said}\n".encode())
        os._exit(143)

    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
