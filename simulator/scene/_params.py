"""The scene's parameters, each declared once: :data:`SCENE_PARAMS`.

One :class:`SceneParam` per key a scene file may hold outside ``[simulate]`` and
``[montecarlo]``: its TOML table and key, its command-line flag (with the flag's group,
help text, metavar and value type), its value kind (range and unit, or choices, from
:mod:`simulator.scene._schema_kinds`, which takes them from :mod:`simulator.core` where they
live there), and whether a design sweep may vary it. Generated from it:

- the scene sections of :data:`simulator.scene.SCHEMA` (:func:`scene_tables`);
- the scene keys :meth:`Scene.from_dict` knows (:func:`known_keys`), the layout and image
  keys it passes on (:data:`LAYOUT_KEYS`, :data:`IMAGE_KEYS`) and the top-level keys that
  are the scene's own fields (:data:`SCENE_FIELD_KEYS`);
- the scene's flags of the commands and their merge into the scene document
  (:mod:`simulator.commands`: ``add_scene_args``, ``scene_document_from_args``);
- the sweep's scene axes and where a point puts their values (:func:`sweep_places`), which
  the design search reads its baseline from;
- the merge of values by place into a scene document (:func:`merge_values`: a chip given
  replaces the document's, :data:`CHIP_KEYS`), the commands' flags' and a sweep point's.

The order of :data:`SCENE_PARAMS` is the order of the flags in each group of ``--help``
and of the keys in each table of the schema. Nothing heavy is imported here: the commands
read it for ``--help``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from patterns import CHANNELS
from simulator.physics import DISPENSE_CHOICES
from simulator.scene._schema_kinds import (
    ACCURACY_PRESETS,
    BOOL,
    CONTACT_ANGLE_DEG,
    DTYPES,
    DXF_UNITS,
    LENGTH_UM,
    MAX_UM,
    POSITION_UM,
    SURFACE_TENSION_MN_M,
    TWIST_DEG,
    Choice,
    FilePath,
    Kind,
    Number,
    Pose,
    Size,
    Text,
    integer,
    number,
)

__all__ = [
    "CHIP_KEYS",
    "FLAG_GROUPS",
    "IMAGE_KEYS",
    "LAYOUT_KEYS",
    "SCENE_FIELD_KEYS",
    "SCENE_PARAMS",
    "SceneParam",
    "known_keys",
    "merge_values",
    "scene_tables",
    "sweep_places",
]

#: The argparse groups of the scene's flags, in the order ``--help`` shows them.
FLAG_GROUPS = (
    "inputs",
    "layout patterns (.gds, .oas, .dxf)",
    "materials",
    "pose grid and numerics",
    "liquid and meniscus",
    "protruding pads (the overflow check, docs/physics.md §9)",
)
_IN, _LAYOUT, _MAT, _GRID, _LIQ, _TOPO = FLAG_GROUPS
#: The flags of the dynamics' liquid and chip body: each dynamic command adds them to a group
#: of its own, with its own help (``selfalign simulate``, ``selfalign calibrate``).
DYNAMICS = "dynamics"


@dataclass(frozen=True)
class SceneParam:
    """One scene parameter: where a scene file keeps it, its flag and what it may be.

    Attributes:
        table: the TOML table (``"materials"``, ...), None for the top level.
        key: the key in that table.
        kind: what the value must be (range and unit, or choices): the schema's check.
        flag: the command-line flag, None when only a scene file gives it.
        help: the flag's help text (a callable for one built when the parser is).
        group: the flag's group in ``--help`` (:data:`FLAG_GROUPS`), or :data:`DYNAMICS`
            for the flags the dynamic commands add themselves.
        metavar: the flag's metavar (None: argparse's default).
        flag_type: how the flag's text becomes its value: ``"float"``, ``"text"``,
            ``"limit"`` (a finite number > 0), ``"count"`` (a whole number >= 1), or
            ``"switch"`` (no value: the flag puts ``switch_value`` in the document).
        switch_value: the document's value when a ``"switch"`` flag is given.
        merge: how the flag's value goes into the document: ``"value"`` (as parsed),
            ``"path"`` (resolved against the working directory), ``"chip_size"``
            (``W[xH]`` parsed), ``"hysteresis"`` (``R:A``: this key true and the pad's two
            angles set), ``"meniscus"`` (true also when ``--meniscus-height`` is given).
        sweep: the help of the sweep axis that varies it ("" when no sweep may vary it).
        name: the parameter's name: the sweep's axis and column (default: ``key``).
        role: what :meth:`Scene.from_dict` does with a top-level key: ``"field"`` (a field
            of the scene), ``"layout"`` (:class:`patterns.layout.LayoutSelection`),
            ``"image"`` (how the images are read), ``"input"`` (the pattern and chip
            inputs), ``"preset"`` (the accuracy preset); ``"table"`` for a key of a table.
    """

    table: str | None
    key: str
    kind: Kind
    flag: str | None = None
    help: str | Callable[[], str] = ""
    group: str = ""
    metavar: str | None = None
    flag_type: Literal["float", "text", "limit", "count", "switch"] = "float"
    switch_value: bool = True
    merge: Literal["value", "path", "chip_size", "hysteresis", "meniscus"] = "value"
    sweep: str = ""
    name: str = ""
    role: Literal["field", "layout", "image", "input", "preset", "table"] = "table"

    @property
    def axis(self) -> str:
        """The parameter's name: its sweep axis and column."""
        return self.name or self.key

    @property
    def dest(self) -> str:
        """The flag's attribute on argparse's namespace ("" without a flag)."""
        return self.flag.removeprefix("--").replace("-", "_") if self.flag else ""

    @property
    def unit(self) -> str:
        """The value's unit ("" for a choice, a switch or text)."""
        kind = self.kind.side if isinstance(self.kind, Size) else self.kind
        return kind.unit if isinstance(kind, Number) else ""

    @property
    def choices(self) -> tuple[str, ...] | None:
        """The allowed values of a choice, else None."""
        return self.kind.choices if isinstance(self.kind, Choice) else None

    @property
    def sweepable(self) -> bool:
        return bool(self.sweep)

    def help_text(self) -> str:
        return self.help() if callable(self.help) else self.help


def _accuracy_help() -> str:
    from simulator.scene._accuracy import DEFAULT_PRESET, PRESETS

    return (
        f"accuracy preset (default {DEFAULT_PRESET}) setting the pixel size, twist step and dtype "
        "that you do not set yourself (--resolution, --twist-step, --dtype win). "
        + " | ".join(p.describe() for p in PRESETS.values())
    ).replace("%", "%%")


def _max_polygons_help() -> str:
    from patterns.layout import DEFAULT_MAX_POLYGONS

    return (
        "most polygons the layout cell may "
        f"hold once flattened (default {DEFAULT_MAX_POLYGONS}; about 20 s of work per 100000)"
    )


_P = SceneParam
_UM_PER_PX = number(f"(0, {MAX_UM:g}]", "um per px")  # as write_mask's pHYs range

#: Every scene parameter, once. The order is that of the flags in each ``--help`` group and
#: of the keys in each table of the schema.
SCENE_PARAMS: tuple[SceneParam, ...] = (
    # ------------------------------------------------------------------ inputs
    _P(
        None,
        "pattern",
        FilePath("the pattern image (PNG) or layout (.gds, .oas, .dxf)"),
        flag="--pattern",
        help="pattern PNG (white = wettable pad) or layout (.gds, .oas, .dxf)",
        group=_IN,
        flag_type="text",
        merge="path",
        role="input",
        sweep="pattern files (PNG or layout), relative to the sweep file",
    ),
    _P(
        None,
        "chip",
        FilePath("the chip footprint image (PNG) or layout"),
        flag="--chip",
        help="chip footprint PNG (white = wettable), or a layout holding only the chip outline",
        group=_IN,
        flag_type="text",
        merge="path",
        role="input",
    ),
    _P(
        None,
        "chip_size_um",
        Size(LENGTH_UM),
        flag="--chip-size",
        help="rectangular chip W[xH] in um, e.g. 730 or 730x500",
        group=_IN,
        flag_type="text",
        merge="chip_size",
        role="input",
        sweep="side of a square chip (um)",
    ),
    _P(
        None,
        "um_per_px",
        _UM_PER_PX,
        flag="--um-per-px",
        help="pixel size in um of the PNGs that store no scale (a file's own pHYs "
        "scale wins; one that contradicts it is refused, see --override-scale); for a layout, the raster's "
        "pixel size when --resolution is not given (default 1)",
        group=_IN,
        role="input",
    ),
    _P(
        None,
        "pattern_um_per_px",
        _UM_PER_PX,
        flag="--pattern-um-per-px",
        help="the same for the pattern file alone (wins over --um-per-px)",
        group=_IN,
        metavar="UM",
        role="image",
    ),
    _P(
        None,
        "chip_um_per_px",
        _UM_PER_PX,
        flag="--chip-um-per-px",
        help="the same for the chip file alone (wins over --um-per-px)",
        group=_IN,
        metavar="UM",
        role="image",
    ),
    _P(
        None,
        "override_scale",
        BOOL,
        flag="--override-scale",
        help="let the scale flags replace the scales the files store",
        group=_IN,
        flag_type="switch",
        role="image",
    ),
    _P(
        None,
        "invert",
        BOOL,
        flag="--invert",
        help="the pattern image marks the pad in black: take 1 - value "
        "(transparent pixels stay non-wettable)",
        group=_IN,
        flag_type="switch",
        role="image",
    ),
    _P(
        None,
        "invert_chip",
        BOOL,
        flag="--invert-chip",
        help="the same for the chip image",
        group=_IN,
        flag_type="switch",
        role="image",
    ),
    _P(
        None,
        "channel",
        Choice(CHANNELS),
        flag="--channel",
        help="what to read from a colour pattern or chip image whose channels differ: one "
        "channel (its bright part is wettable) or the luminance (without it such an image is "
        "refused; a grey image stored as colour is read as it is)",
        group=_IN,
        flag_type="text",
        role="image",
    ),
    # ------------------------------------------------------------------ layout patterns
    _P(
        None,
        "layer",
        Text(200),
        flag="--layer",
        help="the pattern's layer/datatype, e.g. 1/0 (DXF: the layer name; default: the only layer)",
        group=_LAYOUT,
        metavar="L/D",
        flag_type="text",
        role="layout",
    ),
    _P(
        None,
        "cell",
        Text(200),
        flag="--cell",
        help="the cell to read (default: the single top cell; DXF: the model space, or a block)",
        group=_LAYOUT,
        metavar="NAME",
        flag_type="text",
        role="layout",
    ),
    _P(
        None,
        "chip_layer",
        Text(200),
        flag="--chip-layer",
        help="read the chip outline from this layer: its position in the layout is "
        "the aligned pose (default: no chip layer; the target is the pattern's bounding-box centre)",
        group=_LAYOUT,
        metavar="L/D",
        flag_type="text",
        role="layout",
    ),
    _P(
        None,
        "dxf_units",
        Choice(DXF_UNITS),
        flag="--dxf-units",
        help="units of a DXF file that states none ($INSUNITS)",
        group=_LAYOUT,
        flag_type="text",
        role="layout",
    ),
    _P(
        None,
        "max_polygons",
        integer("[1, 1e9]", "polygons"),
        flag="--max-polygons",
        help=_max_polygons_help,
        group=_LAYOUT,
        metavar="N",
        flag_type="count",
        role="layout",
    ),
    # ------------------------------------------------------------------ inputs (continued)
    _P(
        None,
        "resolution_um",
        _UM_PER_PX,
        flag="--resolution",
        help="simulate at this pixel size in um (resamples the pattern; default: its own)",
        group=_IN,
        role="input",
        sweep="pixel size simulated at (um)",
    ),
    # ------------------------------------------------------------------ materials
    _P(
        "materials",
        "surface_tension_mN_m",
        SURFACE_TENSION_MN_M,
        flag="--surface-tension",
        help="liquid surface tension in mN/m (default 72.8, water)",
        group=_MAT,
        sweep="surface tension (mN/m)",
    ),
    _P(
        "materials",
        "pad_angle_deg",
        CONTACT_ANGLE_DEG,
        flag="--pad-angle",
        help="contact angle on the pads in degrees (default 30)",
        group=_MAT,
        sweep="contact angle on the pads (deg)",
    ),
    _P(
        "materials",
        "substrate_angle_deg",
        CONTACT_ANGLE_DEG,
        flag="--substrate-angle",
        help="contact angle on the substrate in degrees (default 60)",
        group=_MAT,
        sweep="contact angle on the substrate (deg)",
    ),
    _P(
        "materials",
        "allow_repulsive",
        BOOL,
        flag="--allow-repulsive",
        help="allow a pad that wets worse than the substrate",
        group=_MAT,
        flag_type="switch",
    ),
    _P("materials", "pad_receding_deg", CONTACT_ANGLE_DEG),  # from --hysteresis
    _P("materials", "pad_advancing_deg", CONTACT_ANGLE_DEG),  # from --hysteresis
    # ------------------------------------------------------------------ pose grid and numerics
    _P(
        None,
        "accuracy",
        Choice(ACCURACY_PRESETS),
        flag="--accuracy",
        help=_accuracy_help,
        group=_GRID,
        flag_type="text",
        role="preset",
    ),
    _P(
        "twist",
        "step_deg",
        number("(0, 90]", "deg"),
        flag="--twist-step",
        help="twist grid step in degrees (default 1)",
        group=_GRID,
        name="twist_step_deg",
        sweep="twist grid step (deg)",
    ),
    _P("twist", "min_deg", TWIST_DEG),
    _P("twist", "max_deg", TWIST_DEG),
    _P(
        "effects",
        "twist",
        BOOL,
        flag="--no-twist",
        help="keep the chip untwisted (computes one rotation)",
        group=_GRID,
        flag_type="switch",
        switch_value=False,
    ),
    _P(
        None,
        "window_um",
        LENGTH_UM,
        flag="--window",
        help="translation half-width of the pose grid in um (default: full reach)",
        group=_GRID,
        role="field",
    ),
    _P(
        None,
        "dtype",
        Choice(DTYPES),
        flag="--dtype",
        help="landscape precision (default float32)",
        group=_GRID,
        flag_type="text",
        role="field",
    ),
    _P(
        None,
        "memory_budget_mb",
        number("(0, 1e9]", "MB"),
        flag="--memory-budget",  # capped downstream at the machine's memory
        help="memory budget in MB for the landscape and every other large array "
        "(default: half the available memory, at most 8192; never more than the machine has)",
        group=_GRID,
        flag_type="limit",
        role="field",
    ),
    _P(
        None,
        "max_image_mpx",
        number("(0, 1e6]", "megapixels"),
        flag="--max-image-mpx",
        help="largest image to read, in megapixels (default 64)",
        group=_IN,
        flag_type="limit",
        role="input",
    ),
    # ------------------------------------------------------------------ the chip body (dynamics)
    _P(None, "chip_thickness_um", LENGTH_UM, flag="--chip-thickness", group=DYNAMICS, role="field"),
    _P(
        None,
        "chip_density_kg_m3",
        number("(0, 1e6]", "kg/m^3"),
        flag="--chip-density",  # osmium 22590
        group=DYNAMICS,
        role="field",
    ),
    _P(
        None,
        "damping_calibration",
        number("(0, 1e9]"),
        flag="--damping-calibration",  # default: none
        group=DYNAMICS,
        role="field",
    ),
    _P(
        None,
        "line_friction_Pa_s",
        number("(0, 100]", "Pa s"),
        flag="--line-friction",  # default 6
        group=DYNAMICS,
        metavar="PA_S",
        role="field",
    ),
    # ------------------------------------------------------------------ liquid and meniscus
    _P("liquid", "name", Text(200)),
    _P("liquid", "surface_tension_mN_m", SURFACE_TENSION_MN_M, name="liquid_surface_tension_mN_m"),
    _P(
        "liquid",
        "viscosity_mPa_s",
        number("(0, 1e9]", "mPa s"),
        flag="--viscosity",  # water 1, glycerol 1400
        group=DYNAMICS,
    ),
    _P("liquid", "density_kg_m3", number("(0, 1e6]", "kg/m^3")),
    _P(
        "liquid",
        "volume_nl",
        number("(0, 1e9]", "nl"),
        flag="--volume",  # 1e9 nl = 1 litre
        help="droplet volume in nl (default: derived from the chip, a film V / A of 5 %% of its "
        "smallest side; selfalign liquid window shows the usable range): the meniscus height V / A under the "
        "chip for --meniscus, and the film of the dynamic methods",
        group=_LIQ,
        sweep="droplet volume (nl)",
    ),
    _P(
        "effects",
        "meniscus",
        BOOL,
        flag="--meniscus",
        help="finite meniscus: round the overlap energy's cusps over the "
        "liquid height (default off: the thin-film overlap model)",
        group=_LIQ,
        flag_type="switch",
        merge="meniscus",
    ),
    _P(
        "liquid",
        "meniscus_height_um",
        LENGTH_UM,
        flag="--meniscus-height",
        help="the meniscus height in um (default: --volume "
        "over the chip's wetted area); implies --meniscus",
        group=_LIQ,
        metavar="UM",
    ),
    # ------------------------------------------------------------------ protruding pads
    _P(
        "topography",
        "edge_angle_deg",
        number("(0, 180]", "deg"),
        flag="--edge-angle",  # a solid wedge: 0 is no solid
        help="the pads stand up from the substrate with this edge "
        "(solid wedge) angle in degrees, 90 = vertical wall: warn when the placement can overflow them",
        group=_TOPO,
        metavar="DEG",
    ),
    _P(
        "topography",
        "pad_advancing_deg",
        CONTACT_ANGLE_DEG,
        flag="--pad-advancing",
        help="advancing contact angle on the pads in degrees "
        "(default: the advancing angle of --hysteresis, else --pad-angle)",
        group=_TOPO,
        metavar="DEG",
        name="topography_pad_advancing_deg",
    ),
    _P(
        "topography",
        "chip_angle_deg",
        CONTACT_ANGLE_DEG,
        flag="--chip-angle",
        help="the chip's advancing contact angle in degrees "
        "(its receding angle for the stricter case; default: unknown)",
        group=_TOPO,
        metavar="DEG",
    ),
    # ------------------------------------------------------------------ liquid (continued)
    _P(
        "effects",
        "hysteresis",
        BOOL,
        flag="--hysteresis",
        help="contact-angle hysteresis of the pads, in degrees "
        "(e.g. 31:50): runs stop where the restoring force falls below the contact lines' pinning force "
        "gamma (cos theta_r - cos theta_a) per unit length (default off)",
        group=_LIQ,
        metavar="RECEDING:ADVANCING",
        flag_type="text",
        merge="hysteresis",
    ),
    _P(
        "liquid",
        "dispense",
        Choice(DISPENSE_CHOICES),
        flag="--dispense",
        help="where the process puts the liquid, which makes the wetted footprint a state of the "
        "run: 'pattern' (the droplet dispensed on the pattern before the chip is released "
        "onto it: every pad it covers starts wet) or 'chip' (the liquid comes in under the chip and "
        "wets what it reaches); pads then wet when the liquid's foot reaches them and dry beyond "
        "the reach of the chip's wall (docs/physics.md §3.5; needs --meniscus, free contact lines); "
        "'none': no state, every pad counted by its distance from the chip (default: 'pattern' "
        "with --meniscus and free contact lines, else none)",
        group=_LIQ,
        flag_type="text",
    ),
    _P(
        "liquid",
        "dispense_at_um",
        Pose((("x", POSITION_UM), ("y", POSITION_UM)), text_ok=True),
        flag="--dispense-at",
        help="where a --dispense pattern droplet is dispensed, in um (default: the pattern's centre)",
        group=_LIQ,
        metavar="X,Y",
        flag_type="text",
    ),
    _P(
        "liquid",
        "pinned",
        BOOL,
        flag="--pinned",
        help="contact lines held at the pad edges (liquid confined by a "
        "superhydrophobic substrate): the energy is the liquid-air area, Delta_gamma = -2 gamma",
        group=_LIQ,
        flag_type="switch",
    ),
)


def scene_tables() -> dict[str | None, dict[str, Kind]]:
    """The scene's sections of the schema (None: the top level), each key's kind, in the
    registry's order."""
    out: dict[str | None, dict[str, Kind]] = {None: {}}
    for p in SCENE_PARAMS:
        out.setdefault(p.table, {})[p.key] = p.kind
    return out


def _top_keys(role: str) -> tuple[str, ...]:
    return tuple(p.key for p in SCENE_PARAMS if p.table is None and p.role == role)


#: Scene keys that choose what to read from a layout pattern (:class:`patterns.layout.LayoutSelection`).
LAYOUT_KEYS = _top_keys("layout")
#: Scene keys on how the pattern and chip images are read (:meth:`Scene.from_inputs`).
IMAGE_KEYS = _top_keys("image")
#: Top-level scene keys that are fields of the :class:`~simulator.scene.Scene` itself.
SCENE_FIELD_KEYS = _top_keys("field")


def known_keys() -> set[str]:
    """The keys a scene document may hold (its top-level keys and its tables), ``[simulate]``
    and ``[montecarlo]`` aside."""
    return {p.key if p.table is None else p.table for p in SCENE_PARAMS}


def sweep_places() -> dict[str, tuple[str | None, str]]:
    """Where a sweep point puts each scene axis's value: axis name -> (table, key), None for
    the top level; in the registry's order."""
    return {p.axis: (p.table, p.key) for p in SCENE_PARAMS if p.sweepable}


#: The top-level keys that give the chip (a file, a size, a layout's layer): one of them
#: given over a document replaces the document's (:func:`merge_values`).
CHIP_KEYS = ("chip", "chip_size_um", "chip_layer")


def merge_values(doc: dict[str, Any], values: Mapping[tuple[str | None, str], Any]) -> None:
    """Put ``values`` (by place: (table, key), None for the top level) into the scene
    document ``doc``, in place: a chip among them (a key of :data:`CHIP_KEYS`) replaces the
    document's chip, whichever key gave it; each value goes to its place, a table made when
    missing. The one merge of the commands' flags (flags win over the scene file) and of a
    sweep point's axes (the point's values over the base scene); docs/guide/scenes.md."""
    if any((None, k) in values for k in CHIP_KEYS):
        for k in CHIP_KEYS:
            doc.pop(k, None)
    for (table, key), value in values.items():
        (doc.setdefault(table, {}) if table else doc)[key] = value
