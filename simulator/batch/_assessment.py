"""The assessment of one pattern, typed: frozen parts whose fields carry their units.

:func:`simulator.batch.assess` returns an :class:`Assessment`; its :meth:`~Assessment.to_dict`
is the summary (``summary.json``, a sweep point's summary), with the same keys in the same
order. A field's name is its key, the unit at the end as in the JSON (``x_um``, ``energy_J``,
``x_N_per_m``, ``planes_s``); where a key cannot be a name (``"+x"``, ``"yield"``,
``"from"``) the field's metadata names it (``key``). The metadata also says which scenes
produce a field (``when``: twist, a finite meniscus, free contact lines, dynamics, the
dispense protocols, a four-pad pattern, evaluate's own additions), which keys a table keyed
by name holds (``keys``: the outcomes, the protocols), which part is written flat into its
parent (``inline``: the meniscus's numbers, the protocols') and which key is left out, not
written null, when it has no value (``omit``). :func:`summary_shape` walks these fields: the
summary a scene of given effects has, numbers as placeholders, from which the sweep's
columns are derived (:func:`simulator.sweep.expected_columns`). Conventions as in
:mod:`simulator.batch` (positions in um of the chip centre from the pattern centre, twist
in degrees counter-clockwise, forces in N, energies in J).
"""

from __future__ import annotations

import dataclasses
import enum
import types
import typing
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Literal

from simulator.core import OUTCOMES
from simulator.physics import DISPENSE

__all__ = [
    "ABSENT",
    "EFFECTS",
    "Absent",
    "AssessedMinimum",
    "Assessment",
    "AssessmentSettings",
    "AxisErrors",
    "CaptureCentre",
    "CaptureGrid",
    "CaptureSummary",
    "CentreOffset",
    "ContactLineReach",
    "ErrorLimit",
    "ErrorStats",
    "FloatingRange",
    "MaxBias",
    "MeniscusSummary",
    "PlacementSigma",
    "Plateaus",
    "ProtocolSummary",
    "Protocols",
    "RestoringForce",
    "RestoringTorque",
    "Stiffness",
    "TimeStats",
    "TwistErrors",
    "YieldSummary",
    "summary_shape",
]

#: The conditions a field's ``when`` names: the scene's twist axis, a finite meniscus, free
#: contact lines (with a meniscus), a dynamic method, the dispense protocols, a four-pad
#: pattern (its critical volume), and what ``selfalign evaluate`` adds to its summary.
EFFECTS = ("twist", "meniscus", "free", "dynamics", "dispense", "four_pad", "evaluate")


class Absent(enum.Enum):
    """The value of a key the summary leaves out (where None would write null)."""

    ABSENT = "absent"


#: A key left out of the summary: a stepper's batch has no time to align (the key is absent),
#: a dynamic batch whose starts all failed has None (written null).
ABSENT = Absent.ABSENT


def _f(
    *,
    key: str | None = None,
    when: str | None = None,
    keys: tuple[str, ...] | None = None,
    inline: bool = False,
    omit: bool = False,
    default: Any = dataclasses.MISSING,
) -> Any:
    """A field with the metadata :meth:`_Part.to_dict` and :func:`summary_shape` read."""
    meta = {"key": key, "when": when, "keys": keys, "inline": inline, "omit": omit}
    return field(default=default, metadata={k: v for k, v in meta.items() if v})


def _plain(v: Any) -> Any:
    """A value as the summary writes it: a part as its dict, a tuple as a list."""
    if isinstance(v, _Part):
        return v.to_dict()
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, tuple | list):
        return [_plain(x) for x in v]
    return v


@dataclass(frozen=True, kw_only=True)
class _Part:
    """What every part shares: its summary dict, key by key in field order."""

    def to_dict(self) -> dict[str, Any]:
        """The part as the summary writes it (the keys of the JSON, in order)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if v is ABSENT or (v is None and f.metadata.get("omit")):
                continue
            if f.metadata.get("inline"):
                out |= _plain(v) if v is not None else {}
            else:
                out[f.metadata.get("key", f.name)] = _plain(v)
        return out


# ----------------------------------------------------------------------- the parts
@dataclass(frozen=True, kw_only=True)
class AssessedMinimum(_Part):
    """The global minimum of the energy: its pose, energy and overlap; ``refined`` when it
    lies below the grid (a finite meniscus whose well has no flat floor)."""

    x_um: float
    y_um: float
    twist_deg: float
    energy_J: float
    overlap_um2: float
    refined: bool


@dataclass(frozen=True, kw_only=True)
class Stiffness(_Part):
    """The curvature of the energy at the minimum (finite meniscus;
    :func:`simulator.landscape.stiffness`); zero where a floating chip's floor is flat."""

    x_N_per_m: float | None
    y_N_per_m: float | None
    #: None on a twist-free grid
    twist_Nm_per_rad: float | None = _f(when="twist")


@dataclass(frozen=True, kw_only=True)
class CentreOffset(_Part):
    """The minimum's offset from the pattern centre, to 0.1 um and 0.1 degree."""

    x_um: float
    y_um: float
    twist_deg: float
    distance_um: float


@dataclass(frozen=True, kw_only=True)
class FloatingRange(_Part):
    """The flat floor of the well the chip floats on (free contact lines): first and last
    pose of it along each axis (:meth:`simulator.landscape.Landscape.floor_range`)."""

    x_from_um: float
    x_to_um: float
    y_from_um: float
    y_to_um: float
    twist_from_deg: float
    twist_to_deg: float


@dataclass(frozen=True, kw_only=True)
class ContactLineReach(_Part):
    """How far (um) the free contact lines reach beyond the chip: on the substrate and on a pad."""

    substrate: float
    pad: float


@dataclass(frozen=True, kw_only=True)
class MeniscusSummary(_Part):
    """A finite meniscus's numbers (written flat into the summary): its height, the contact
    lines, the stiffness at the minimum, the minimum's offset, and the floor a chip floats on."""

    meniscus_height_um: float
    pinned: bool
    stiffness: Stiffness
    offset_from_centre: CentreOffset
    #: the regime's warning (:func:`simulator.physics.regime_warning`), None when there is none
    meniscus_warning: str | None
    #: "pinned" or "free"
    contact_lines: str
    #: None when the well has no flat floor
    floating_range: FloatingRange | None = _f(when="free")
    #: the free contact lines' reach (left out when they are pinned)
    contact_line_reach_um: ContactLineReach | None = _f(when="free", omit=True, default=None)


@dataclass(frozen=True, kw_only=True)
class ErrorLimit(_Part):
    """What limits the final poses' error (:func:`simulator.motion.error_limit`)."""

    #: "grid", "floor" or "refined"
    by: str
    um: float


@dataclass(frozen=True, kw_only=True)
class RestoringForce(_Part):
    """The force (N; [F_x, F_y]) on the chip displaced by ``bias_um`` from the minimum
    along +x, -x, +y and -y."""

    bias_um: float
    plus_x: tuple[float, float] = _f(key="+x")
    minus_x: tuple[float, float] = _f(key="-x")
    plus_y: tuple[float, float] = _f(key="+y")
    minus_y: tuple[float, float] = _f(key="-y")


@dataclass(frozen=True, kw_only=True)
class RestoringTorque(_Part):
    """The torque (N m) on the chip turned by +- ``twist_deg`` from the minimum."""

    twist_deg: float
    plus: float = _f(key="+")
    minus: float = _f(key="-")


@dataclass(frozen=True, kw_only=True)
class Plateaus(_Part):
    """The [start, end] stretches (um) of zero force along x and y through the minimum."""

    x: list[list[float]]
    y: list[list[float]]


@dataclass(frozen=True, kw_only=True)
class MaxBias(_Part):
    """The largest bias (um) along each half-axis from which the force points back to the
    minimum all the way (docs/physics.md §6.3)."""

    plus_x: float = _f(key="+x")
    minus_x: float = _f(key="-x")
    plus_y: float = _f(key="+y")
    minus_y: float = _f(key="-y")


@dataclass(frozen=True, kw_only=True)
class TimeStats(_Part):
    """The simulated time (s) to align of the aligned starts (:func:`simulator.batch.time_stats`)."""

    n: int
    median: float
    p90: float
    mean: float
    min: float
    max: float


@dataclass(frozen=True, kw_only=True)
class CaptureGrid(_Part):
    """The capture grid's extent about its centre (um), the same in x and y."""

    from_: float = _f(key="from")
    to: float
    step: float


@dataclass(frozen=True, kw_only=True)
class CaptureCentre(_Part):
    """The capture grid's centre (the global minimum on the grid)."""

    x_um: float
    y_um: float


#: The outcome counts of a batch, one per name of :data:`simulator.core.OUTCOMES`.
Outcomes = dict[str, int]


@dataclass(frozen=True, kw_only=True)
class CaptureSummary(_Part):
    """The capture fraction over a grid of starts around the global minimum, at its twist."""

    fraction: float
    n: int
    outcomes: Outcomes = _f(keys=OUTCOMES)
    grid_um: CaptureGrid
    center: CaptureCentre
    twist_deg: float
    #: dynamics only (absent for the steppers), None when no start aligned
    time_to_align_s: TimeStats | None | Literal[Absent.ABSENT] = _f(when="dynamics", default=ABSENT)


@dataclass(frozen=True, kw_only=True)
class PlacementSigma(_Part):
    """The placement noise's standard deviations."""

    x_um: float
    y_um: float
    twist_deg: float


@dataclass(frozen=True, kw_only=True)
class ErrorStats(_Part):
    """Mean, mean |error|, standard deviation and max |error| of the aligned starts' final poses."""

    mean: float
    mean_abs: float
    std: float
    max_abs: float


@dataclass(frozen=True, kw_only=True)
class AxisErrors(_Part):
    """The final-pose error (um) in x and y from the global minimum (None: no start aligned)."""

    x: ErrorStats | None
    y: ErrorStats | None


@dataclass(frozen=True, kw_only=True)
class TwistErrors(_Part):
    """The final twist's error (deg), modulo the chip's symmetry (None: no start aligned)."""

    twist: ErrorStats | None


@dataclass(frozen=True, kw_only=True)
class YieldSummary(_Part):
    """The yield under placement noise around the global minimum."""

    fraction: float
    n: int
    outcomes: Outcomes = _f(keys=OUTCOMES)
    placement_sigma: PlacementSigma
    seed: int
    error_um: AxisErrors
    error_deg: TwistErrors
    #: dynamics only (absent for the steppers), None when no start aligned
    time_to_align_s: TimeStats | None | Literal[Absent.ABSENT] = _f(when="dynamics", default=ABSENT)


@dataclass(frozen=True, kw_only=True)
class AssessmentSettings(_Part):
    """What the assessment ran with: the raster, the chip, the grid, the materials, the
    landscape's size and time; evaluate and a sweep point add the pixel size read and
    whether it was coarsened, a sweep point the droplet's volume."""

    um_per_px: float
    #: (rows, cols)
    pattern_px: tuple[int, int]
    #: (width, height) of the chip's wettable footprint
    chip_um: tuple[float, float]
    #: None on a twist-free grid
    twist_step_deg: float | None = _f(when="twist")
    twists: int
    dtype: str
    method: str
    surface_tension_N_m: float
    pad_angle_deg: float
    substrate_angle_deg: float
    delta_gamma_N_m: float
    landscape_MB: float
    landscape_s: float
    source_um_per_px: float | None = _f(omit=True, default=None)
    resolution_auto: bool | None = _f(omit=True, default=None)
    #: a sweep point's droplet volume (absent elsewhere; None writes null)
    volume_nl: float | None | Literal[Absent.ABSENT] = ABSENT


@dataclass(frozen=True, kw_only=True)
class ProtocolSummary(_Part):
    """One dispense protocol's numbers: the pads wet at release, the maximum bias, capture
    and yield, each start carrying its own footprint (docs/physics.md §3.5)."""

    why: str
    #: the pads (numbered from 1) wet when the chip is released
    wet_at_dispense: list[int]
    max_bias_um: MaxBias
    capture_fraction: float
    capture_outcomes: Outcomes = _f(keys=OUTCOMES)
    yield_fraction: float
    yield_outcomes: Outcomes = _f(keys=OUTCOMES)
    #: dynamics only (absent for the steppers), None when no start aligned
    time_to_align_s: TimeStats | None | Literal[Absent.ABSENT] = _f(when="dynamics", default=ABSENT)


@dataclass(frozen=True, kw_only=True)
class Protocols(_Part):
    """The two dispense protocols side by side (``--dispense``): the scene's own, the pads'
    reaches, the planes' build time, and each protocol's numbers by name (written flat)."""

    #: the scene's protocol
    dispense: str
    substrate_reach_um: float
    wet_reach_um: float
    receding_deg: float
    planes_s: float
    #: by name of :data:`simulator.physics.DISPENSE`
    by_protocol: dict[str, ProtocolSummary] = _f(keys=DISPENSE, inline=True)


@dataclass(frozen=True, kw_only=True)
class Assessment(_Part):
    """The numbers of :func:`simulator.batch.assess` (and of ``summary.json``): each part
    typed, each field with its unit; :meth:`to_dict` is the summary."""

    #: a finite meniscus's numbers (None: the overlap model)
    meniscus: MeniscusSummary | None = _f(when="meniscus", inline=True)
    global_minimum: AssessedMinimum
    #: what limits the yield's final-pose error
    error_limit: ErrorLimit | None
    restoring_force_N: RestoringForce
    #: None without twist
    restoring_torque_Nm: RestoringTorque | None = _f(when="twist")
    plateaus_um: Plateaus
    max_bias_um: MaxBias
    #: each dispense protocol's numbers (left out without ``--dispense``)
    protocols: Protocols | None = _f(when="dispense", omit=True, default=None)
    capture: CaptureSummary
    yield_: YieldSummary = _f(key="yield")
    settings: AssessmentSettings
    #: a four-pad pattern's critical volume (a sweep point's, docs/physics.md §8)
    critical_volume_nl: float | None = _f(when="four_pad", omit=True, default=None)
    #: a layout pattern's record (file, cell, layers, units, origin)
    layout: dict | None = _f(omit=True, default=None)
    #: evaluate's: the droplet's warnings (:func:`simulator.liquid.scene_warnings`)
    liquid_warnings: list[str] | None = _f(when="evaluate", omit=True, default=None)
    #: evaluate's: the droplet's volume window (:func:`simulator.liquid.volume_window`)
    volume_window: dict | None = _f(when="evaluate", omit=True, default=None)
    #: evaluate's: its wall-clock seconds
    seconds: float | None = _f(when="evaluate", omit=True, default=None)


# ----------------------------------------------------------------------- the shape
def _shape_of(tp: Any, effects: frozenset[str]) -> Any:
    """A placeholder value of type ``tp``: a part's shape, a fixed tuple's numbers, 1 for a
    number, True for a flag, "" for text, [] for a list of any length, None for an untyped
    record (what the summary gives no column)."""
    args = [a for a in typing.get_args(tp) if a not in (type(None), Literal[Absent.ABSENT])]
    if isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union:
        return _shape_of(args[0], effects) if len(args) == 1 else None
    if isinstance(tp, type) and issubclass(tp, _Part):
        return summary_shape(effects, tp)
    if typing.get_origin(tp) is tuple:
        return [_shape_of(a, effects) for a in typing.get_args(tp)]
    if typing.get_origin(tp) is list:
        return []
    return {bool: True, int: 1, float: 1.0, str: ""}.get(tp)


def summary_shape(effects: Iterable[str] = (), part: type[_Part] = Assessment) -> dict[str, Any]:
    """The summary (:meth:`Assessment.to_dict`) a scene with ``effects`` (names of
    :data:`EFFECTS`) may have, every number a placeholder: the keys of ``part``'s fields in
    order (a field whose ``when`` does not hold: null, or left out when the summary leaves it
    out), a table keyed by name with its ``keys``, the keys a caller adds (evaluate's, a
    sweep point's settings) included. What the sweep's columns are derived from
    (:func:`simulator.sweep.expected_columns`)."""
    effects = frozenset(effects)
    unknown = effects - set(EFFECTS)
    if unknown:
        raise ValueError(f"effects must be among {', '.join(EFFECTS)}, got {sorted(unknown)}")
    hints = typing.get_type_hints(part)
    out: dict[str, Any] = {}
    for f in dataclasses.fields(part):
        meta = f.metadata
        if meta.get("when") and meta["when"] not in effects:
            if not (meta.get("omit") or meta.get("inline") or f.default is ABSENT):
                out[meta.get("key", f.name)] = None  # the key is there, null
            continue
        tp = hints[f.name]
        if meta.get("keys"):
            (value_type,) = typing.get_args(tp)[1:]
            value = {k: _shape_of(value_type, effects) for k in meta["keys"]}
        else:
            value = _shape_of(tp, effects)
        if meta.get("inline"):
            out |= value or {}
        else:
            out[meta.get("key", f.name)] = value
    return out
