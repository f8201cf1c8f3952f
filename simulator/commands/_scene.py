"""A command's scene: the scene file's document and the flags merged into it under the
TOML keys (flags win), the :class:`~simulator.scene.Scene` built from them, its refusals
spelled as flags, and its accuracy warning."""

from __future__ import annotations

import argparse
import copy
import os
import sys
from pathlib import Path
from typing import Any

from foundation import InputError
from simulator.commands._flags import parse_chip_size
from simulator.scene import Scene


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


def read_toml(path: str | os.PathLike) -> dict[str, Any]:
    """Read and validate a TOML scene file (:func:`simulator.scene.read_scene_file`)."""
    from simulator.scene import read_scene_file

    return read_scene_file(path)
