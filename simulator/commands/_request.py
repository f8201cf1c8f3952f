"""A command's request: what the command line asks for, read once and frozen.

The commands that read a scene (``selfalign simulate``, ``energy``, ``montecarlo``,
``evaluate``, ``calibrate`` and ``liquid window``) turn argparse's namespace into one
:class:`SceneRequest` at the start of their ``run`` and hand that, not the namespace, to the
shared helpers, which take a request only (the scene, :mod:`~simulator.commands._scene`; the
outputs' checks, :mod:`~simulator.commands._outputs`; the droplet checks,
:mod:`~simulator.commands._liquid`).
The namespace stops at the command layer: no helper fishes for an optional attribute.
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from simulator.commands._flags import parse_chip_size


@dataclass(frozen=True)
class SceneRequest:
    """The scene file's document (read and validated once), the flags' values over it, the
    files the run reads and the ones it will write.

    Equal for the same flags and file; not hashable (it holds the documents). Build it with
    :meth:`from_args`.
    """

    #: the TOML scene file as given on the command line (None without one)
    scene_file: str | None
    #: its document (:func:`simulator.scene.read_scene_file`), {} without a file; not changed
    document: dict[str, Any]
    #: the flags given, by the scene document's (table, key) (None: the top level), with
    #: their values as the document holds them (:func:`flag_values`)
    overrides: dict[tuple[str | None, str], Any]
    #: the files the run reads: the scene file, pattern, chip, image and the scene file's own
    #: pattern and chip (an output may name none of them)
    inputs: tuple[Path, ...]
    #: the output plan: each output flag ("--json") with the path it names (None: not asked)
    outputs: tuple[tuple[str, str | None], ...]
    #: ``--force``: an output that exists may be replaced
    force: bool

    @classmethod
    def from_args(
        cls,
        args: argparse.Namespace,
        outputs: tuple[str, ...] = (),
        doc: dict[str, Any] | None = None,
    ) -> SceneRequest:
        """The request of ``args``: its scene file read (unless ``doc``, that file's document,
        is given), its scene flags' values, its inputs, and the outputs named by ``outputs``
        (attribute names: ``json`` for ``--json``)."""
        scene_file = getattr(args, "scene", None) or None
        if doc is None:
            from simulator.scene import read_scene_file

            doc = read_scene_file(scene_file) if scene_file else {}
        return cls(
            scene_file=scene_file,
            document=doc,
            overrides=flag_values(args),
            inputs=tuple(_input_paths(args, scene_file, doc)),
            outputs=tuple((f"--{f.replace('_', '-')}", getattr(args, f, None)) for f in outputs),
            force=bool(getattr(args, "force", False)),
        )

    @property
    def base(self) -> Path:
        """The directory the scene file's relative paths are read against."""
        return Path(self.scene_file).parent if self.scene_file else Path(".")

    def output(self, flag: str) -> str | None:
        """The path the output ``flag`` ("--json") names, or None."""
        return dict(self.outputs).get(flag)

    def with_chip_size(self, size: str) -> SceneRequest:
        """This request with the chip ``size`` (W[xH] um) as ``--chip-size`` gives it: the
        chip ``evaluate`` takes from the pattern's bounding box when none is given."""
        overrides = {**self.overrides, (None, "chip_size_um"): list(parse_chip_size(size))}
        return dataclasses.replace(self, overrides=overrides)

    def volume_given(self) -> bool:
        """A droplet volume the user gave: ``--volume`` or ``[liquid] volume_nl``."""
        return ("liquid", "volume_nl") in self.overrides or "volume_nl" in (
            self.document.get("liquid") or {}
        )


def flag_values(args: argparse.Namespace) -> dict[tuple[str | None, str], Any]:
    """The scene document's values the flags give, by (table, key) (None: the top level):
    each scene parameter of :data:`simulator.scene.SCENE_PARAMS` whose flag is on ``args``
    and given (a command without the dynamics leaves their flags off its namespace)."""
    from simulator.scene import SCENE_PARAMS

    out: dict[tuple[str | None, str], Any] = {}
    for p in SCENE_PARAMS:
        given: Any = getattr(args, p.dest, None) if p.flag else None
        if p.merge == "meniscus" and getattr(args, "meniscus_height", None) is not None:
            given = True  # --meniscus-height implies --meniscus
        if given is None or given is False:  # not given (a switch left off is False)
            continue
        if given == "" and p.merge in ("path", "chip_size", "hysteresis"):
            continue  # an empty path, size or window reads as not given
        if p.merge == "hysteresis":  # R:A -> the pads' receding and advancing angles
            from simulator.physics import parse_window

            r, a = parse_window(given)
            out[("materials", "pad_receding_deg")], out[("materials", "pad_advancing_deg")] = r, a
            given = True
        elif p.merge == "path":
            given = str(Path(given).resolve())
        elif p.merge == "chip_size":
            given = list(parse_chip_size(given))
        elif p.flag_type == "switch":
            given = p.switch_value
        out[(p.table, p.key)] = given
    return out


def _input_paths(args: argparse.Namespace, scene_file: str | None, doc: dict) -> list[Path]:
    """The files ``args`` reads (pattern, chip, scene and the scene's own pattern/chip)."""
    paths = [getattr(args, k, None) for k in ("scene", "pattern", "chip", "image")]
    if scene_file:
        for key in ("pattern", "chip"):
            if isinstance(doc.get(key), str):
                paths.append(str(Path(scene_file).parent / doc[key]))
    return [Path(p) for p in paths if isinstance(p, str) and p]
