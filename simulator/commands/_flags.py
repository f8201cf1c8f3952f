"""The flags shared by the commands that build a scene, and their value types: limits
(finite numbers, whole numbers), the scene's inputs, materials and pose grid
(:func:`add_scene_args`) and the dynamics' liquid and chip body (:func:`add_dynamics_args`),
each made from its scene parameter's one declaration (:data:`simulator.scene.SCENE_PARAMS`),
a chip size and a pose as typed."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING, Any

from foundation import InputError

if TYPE_CHECKING:  # the registry is read when a parser is built, not at import
    from simulator.scene import SceneParam


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
    """Pattern, chip, scale, materials and pose-grid options (a TOML scene may give them):
    one flag per scene parameter of :data:`simulator.scene.SCENE_PARAMS` in the groups of
    :data:`simulator.scene.FLAG_GROUPS` (the dynamics' flags aside: :func:`add_dynamics_args`)."""
    from simulator.scene import FLAG_GROUPS, SCENE_PARAMS

    p.add_argument(
        "scene", nargs="?", help="optional TOML scene file; flags given here override it"
    )
    groups = {title: p.add_argument_group(title) for title in FLAG_GROUPS}
    for param in SCENE_PARAMS:
        if param.flag is not None and param.group in groups:
            _add_flag(groups[param.group], param, param.help_text())


def add_dynamics_args(group: Any, helps: dict[str, str]) -> None:
    """The dynamics' liquid and chip-body flags of :data:`simulator.scene.SCENE_PARAMS`
    (``--viscosity``, ``--chip-thickness``, ...) in ``group``, each with the command's own
    help (``helps``: flag -> help text, one for each of those flags, in the order of ``--help``)."""
    from simulator.scene import FLAG_GROUPS, SCENE_PARAMS

    params = {q.flag: q for q in SCENE_PARAMS if q.flag is not None and q.group not in FLAG_GROUPS}
    assert sorted(helps) == sorted(params), sorted(helps)
    for flag, text in helps.items():
        _add_flag(group, params[flag], text)


def _add_flag(group: Any, param: SceneParam, help: str) -> None:
    """One scene parameter's flag (:class:`simulator.scene.SceneParam`) in ``group``."""
    flag = param.flag
    assert flag is not None, param
    kw: dict[str, Any] = {"help": help}
    if param.metavar is not None:
        kw["metavar"] = param.metavar
    if param.flag_type == "switch":
        kw["action"] = "store_true"
    elif param.choices is not None:
        kw["choices"] = param.choices
    elif param.flag_type == "float":
        kw["type"] = float
    elif param.flag_type == "limit":
        kw["type"] = finite_limit(flag, param.unit)
    elif param.flag_type == "count":
        kw["type"] = whole_limit(flag)
    group.add_argument(flag, **kw)


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
