"""The droplet checks a command prints for its scene (:mod:`simulator.liquid`): the note
of a volume derived from the chip, and the warnings of a volume given."""

from __future__ import annotations

import sys
from typing import Any

from simulator.commands._request import SceneRequest
from simulator.core import DYNAMIC_METHODS
from simulator.scene import Scene


def liquid_checks(
    request: SceneRequest,
    scene: Scene,
    method: str,
    biases_um: Any = None,
    placed: str = "the start",
) -> list[str]:
    """The droplet checks of :mod:`simulator.liquid` for a volume the user gave (``--volume``
    or ``[liquid] volume_nl``; :func:`scene_from_args` has refused a film thicker than the
    chip): a note when ``method`` does not use the volume, and the warnings of
    :func:`simulator.liquid.scene_warnings` (``biases_um``: per start, the larger of |x|, |y|),
    each printed as one line on stderr and returned for the JSON (``liquid_warnings``).
    ``request``: the command's :class:`SceneRequest`."""
    from simulator.liquid import scene_warnings, volume_note

    given = request.volume_given()
    used = method in DYNAMIC_METHODS or bool(getattr(scene.effects, "meniscus", False))
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
