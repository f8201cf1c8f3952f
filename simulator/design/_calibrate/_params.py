"""What ``selfalign calibrate`` can fit: the names, their units, their default bounds and
where each goes in a scene (its TOML key and its :class:`~simulator.scene.Scene` field)."""

from __future__ import annotations

import copy
import difflib
import math
from dataclasses import dataclass, replace

from foundation import InputError


@dataclass(frozen=True)
class Fittable:
    """One parameter a calibration can fit.

    ``table``, ``key``: where it goes in a scene file (``table`` None: the top level);
    ``lo``, ``hi``: the default bounds (None: relative to the scene's value, ``rel``);
    ``log``: searched on a log scale; ``what``: its meaning and physical range, said in
    the help and the guide.
    """

    name: str
    unit: str
    table: str | None
    key: str
    lo: float | None
    hi: float | None
    log: bool
    what: str
    rel: tuple[float, float] | None = None


#: The fittable parameters, in the order the help lists them.
FITTABLE: dict[str, Fittable] = {
    f.name: f
    for f in (
        Fittable(
            "receding_angle_deg",
            "deg",
            "materials",
            "pad_receding_deg",
            0.0,
            60.0,
            False,
            "the pads' receding contact angle (hysteresis); default bounds 0-60 deg, water on oxide",
        ),
        Fittable(
            "advancing_angle_deg",
            "deg",
            "materials",
            "pad_advancing_deg",
            10.0,
            90.0,
            False,
            "the pads' advancing contact angle (hysteresis); default bounds 10-90 deg",
        ),
        Fittable(
            "volume_nl",
            "nl",
            "liquid",
            "volume_nl",
            None,
            None,
            True,
            "the dispensed droplet volume; default bounds 0.25-4 times the scene's volume (nl), log scale",
            rel=(0.25, 4.0),
        ),
        Fittable(
            "damping",
            "x Couette",
            None,
            "damping_calibration",
            10.0,
            10_000.0,
            True,
            "the viscous override (--damping-calibration): the film's Couette drag times this factor; "
            "default bounds 10-10000, log scale (dynamics only: it sets the times)",
        ),
        Fittable(
            "pad_angle_deg",
            "deg",
            "materials",
            "pad_angle_deg",
            5.0,
            None,
            False,
            "the pads' (equilibrium) contact angle; default bounds 5 deg to 1 deg below the substrate's angle",
        ),
    )
}

#: The hysteresis angles: fitting one turns the scene's hysteresis on.
ANGLES = ("receding_angle_deg", "advancing_angle_deg")


def _near(name: str) -> str:
    near = difflib.get_close_matches(name, list(FITTABLE), n=1, cutoff=0.5)
    return f"did you mean {near[0]}? " if near else ""


def parse_fit(names: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """``NAME[,NAME...]`` (or a list) -> the names, checked (unknown: a did-you-mean)."""
    items = names.split(",") if isinstance(names, str) else list(names)
    items = [str(n).strip() for n in items if str(n).strip()]
    if not items:
        raise InputError(f"--fit needs at least one name: {', '.join(FITTABLE)}")
    for n in items:
        if n not in FITTABLE:
            raise InputError(
                f"--fit: unknown parameter {n!r}; {_near(n)}fittable: {', '.join(FITTABLE)}"
            )
    dup = [n for n in items if items.count(n) > 1]
    if dup:
        raise InputError(f"--fit: {dup[0]} is named twice")
    return tuple(items)


def parse_bounds(items) -> dict[str, tuple[float, float]]:
    """``NAME=LO:HI`` strings (or a dict NAME -> (LO, HI)) -> the bounds, checked."""
    out: dict[str, tuple[float, float]] = {}
    pairs = items.items() if isinstance(items, dict) else [(None, t) for t in items or ()]
    for name, text in pairs:
        if name is None:
            name, sep, rng = str(text).partition("=")
            if not sep:
                raise InputError(
                    f"--bounds must be NAME=LO:HI, e.g. receding_angle_deg=10:40, got {text!r}"
                )
            parts = rng.split(":")
        else:
            parts = list(text) if not isinstance(text, str) else text.split(":")
        name = name.strip()
        if name not in FITTABLE:
            raise InputError(
                f"--bounds: unknown parameter {name!r}; {_near(name)}fittable: {', '.join(FITTABLE)}"
            )
        try:
            lo, hi = (float(v) for v in parts)
        except (TypeError, ValueError):
            raise InputError(f"--bounds {name}: give LO:HI, two numbers, got {text!r}") from None
        f = FITTABLE[name]
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise InputError(f"--bounds {name}={lo:g}:{hi:g}: give finite LO < HI ({f.unit})")
        if f.log and lo <= 0:
            raise InputError(f"--bounds {name}: {f.unit} bounds must be > 0, got {lo:g}")
        if f.unit == "deg" and not (0 <= lo and hi <= 180):
            raise InputError(f"--bounds {name}: contact angles lie in 0-180 deg, got {lo:g}:{hi:g}")
        if name in out:
            raise InputError(f"--bounds: {name} is given twice")
        out[name] = (lo, hi)
    return out


def default_bounds(name: str, scene) -> tuple[float, float]:
    """A parameter's default bounds for ``scene`` (:data:`FITTABLE`)."""
    f = FITTABLE[name]
    if f.rel is not None:
        v = float(scene.liquid.volume_nl)
        return (f.rel[0] * v, f.rel[1] * v)
    assert f.lo is not None  # only the relative parameters (rel) lack a lower bound
    if name == "receding_angle_deg" and scene.materials.pad_advancing_deg is not None:
        assert f.hi is not None
        return (f.lo, min(f.hi, scene.materials.pad_advancing_deg))
    if name == "pad_angle_deg":
        hi = 175.0 if scene.materials.allow_repulsive else scene.materials.substrate_angle_deg - 1.0
        return (f.lo, max(hi, f.lo + 1.0))
    assert f.hi is not None  # pad_angle_deg's upper bound alone comes from the scene
    return (f.lo, f.hi)


def scene_value(name: str, scene) -> float | None:
    """The scene's own value of a parameter (None: not set, the hysteresis angles without it)."""
    m = scene.materials
    return {
        "receding_angle_deg": m.pad_receding_deg,
        "advancing_angle_deg": m.pad_advancing_deg,
        "volume_nl": scene.liquid.volume_nl,
        "damping": scene.damping_calibration,
        "pad_angle_deg": m.pad_angle_deg,
    }[name]


def prepared_document(doc: dict, fit: tuple[str, ...]) -> dict:
    """The scene document with what fitting ``fit`` needs: the hysteresis on when an angle
    is fitted, and both angles given (a scene without them starts from none: receding =
    advancing = the pad's angle)."""
    doc = copy.deepcopy(doc)
    if any(n in ANGLES for n in fit):
        mat = doc.setdefault("materials", {})
        pad = float(mat.get("pad_angle_deg", 30.0))
        mat.setdefault("pad_receding_deg", min(pad, float(mat.get("pad_advancing_deg", pad))))
        mat.setdefault("pad_advancing_deg", max(pad, float(mat["pad_receding_deg"])))
        doc.setdefault("effects", {})["hysteresis"] = True
    return doc


def with_values(doc: dict, values: dict[str, float]) -> dict:
    """The scene document with the fitted values written under their keys."""
    doc = copy.deepcopy(doc)
    for name, v in values.items():
        f = FITTABLE[name]
        (doc.setdefault(f.table, {}) if f.table else doc)[f.key] = float(v)
    if any(n in ANGLES for n in values):
        doc.setdefault("effects", {})["hysteresis"] = True
    return doc


def scene_with(scene, values: dict[str, float]):
    """``scene`` with the candidate ``values`` (validated again: a window with receding >
    advancing, a pad no more wettable than the substrate, are InputErrors)."""
    mat = {}
    for name, field in (
        ("receding_angle_deg", "pad_receding_deg"),
        ("advancing_angle_deg", "pad_advancing_deg"),
        ("pad_angle_deg", "pad_angle_deg"),
    ):
        if name in values:
            mat[field] = float(values[name])
    changes = {}
    if mat:
        changes["materials"] = replace(scene.materials, **mat)
    if "volume_nl" in values:
        changes["liquid"] = replace(
            scene.liquid, volume_nl=float(values["volume_nl"]), volume_derived=False
        )
    if values.get("damping") is not None:  # None: the scene's own damping (its terms)
        changes["damping_calibration"] = float(values["damping"])
    return scene.replace(**changes) if changes else scene
