"""A command's scene: the scene file's document and the flags merged into it under the
TOML keys (flags win), the :class:`~simulator.scene.Scene` built from them, its refusals
spelled as flags, and its accuracy warning."""

from __future__ import annotations

import copy
import os
import sys
from pathlib import Path
from typing import Any

from foundation import InputError
from simulator.commands._request import SceneRequest
from simulator.scene import CHIP_KEYS, Scene, merge_values


def scene_from_args(request: SceneRequest, note_frame: bool = True, warn: bool = True) -> Scene:
    """Build the scene from an optional TOML file and the flags (flags win).

    Flags are merged into the TOML document under the TOML keys (see
    :mod:`simulator.scene`), so a file and the command line mean the same thing.
    ``request``: the command's :class:`SceneRequest` (its scene file read once, the flags).
    For a layout pattern, ``note_frame`` prints on stderr where the poses' origin is.
    ``warn=False`` leaves the accuracy warning (:func:`accuracy_check`) to the command, which
    prints it once its run is priced.
    """
    doc, base = scene_document_from_args(request)
    try:
        scene = Scene.from_dict(
            doc, base=base
        )  # the accuracy preset applies here, as for Scene.from_toml
    except InputError as err:
        raise InputError(_cli_spelling(str(err), bool(request.scene_file))) from None
    if "volume_nl" in (
        doc.get("liquid") or {}
    ):  # a volume as typed: a film thicker than the chip is refused
        from simulator.liquid import check_scene_volume

        check_scene_volume(scene)
    if scene.dispense == "pattern":
        # a drop that touches no pad is refused here, before any work or warning (the pads
        # are labelled again, cheaply, where the run takes its initial state)
        from patterns.geometry import pad_labels
        from simulator.liquid import dispensed_footprint

        dispensed_footprint(scene, *pad_labels(scene.pattern))
    if warn:
        accuracy_check(scene)
    if note_frame and "layout" in scene.pattern.params:
        from patterns.layout import frame_note

        print(frame_note(scene.pattern.params["layout"]), file=sys.stderr)
    return scene


def scene_document_from_args(request: SceneRequest) -> tuple[dict[str, Any], Path]:
    """The scene document the flags and an optional TOML file make (flags win, under the
    TOML keys), and the directory its relative paths are read against: what
    :func:`scene_from_args` builds its scene from (``request``: the command's
    :class:`SceneRequest`, whose document is not changed)."""
    doc = copy.deepcopy(request.document)
    base = request.base
    values = request.overrides  # (table, key) -> the flag's value, for the flags given
    chips = [(None, k) for k in CHIP_KEYS]
    if "pattern" not in doc and (None, "pattern") not in values:
        raise InputError(
            "no pattern given: pass --pattern P.png or a layout P.gds (or a TOML scene with pattern = ...)"
        )
    if not any(k in doc for k in CHIP_KEYS) and not any(place in values for place in chips):
        raise InputError(
            "no chip given: pass --chip C.png, --chip-size W[xH] (um) or, for a layout, --chip-layer L/D"
        )
    # a chip on the command line replaces the scene file's (two on the command line: refused downstream)
    merge_values(doc, values)
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
