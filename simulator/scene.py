"""What to simulate: chip, pattern, materials, pose grid and the effects called for.

A :class:`Scene` is frozen and validated at construction; everything downstream
(landscape, steppers, Monte Carlo) reads it and never changes it. Build one in
Python (:meth:`Scene.from_inputs`) or from a TOML file (:meth:`Scene.from_toml`).

TOML keys (all optional except ``pattern`` and one of ``chip`` / ``chip_size_um`` / ``chip_layer``)::

    pattern = "patterns/library/fourpad_730_50.png"   # PNG path (scale from pHYs), or .gds/.oas/.dxf
    layer = "1/0"                   # layout patterns: the pattern layer (DXF: its name); also
    # cell = "SITE", chip_layer = "2/0" (the chip from the layout), dxf_units = "um" | "mm" | "nm"
    um_per_px = 1.0                 # the scale of PNGs that store none (a file's own pHYs scale wins)
    pattern_um_per_px = 1.0         # the same for the pattern alone; chip_um_per_px for the chip alone
    override_scale = false          # true: um_per_px (and the two above) replace the files' stored scales
    invert = false                  # the pattern image marks the pad in black (invert_chip: the chip image)
    resolution_um = 2.0             # simulate at this pixel size (resamples the pattern)
    chip = "chip.png"               # chip footprint PNG, or:
    chip_size_um = [730, 730]       # rectangular chip, exact geometry
    dtype = "float32"               # or "float64"
    window_um = 800                 # translation half-width of the pose grid
    memory_budget_mb = 4096
    accuracy = "balanced"           # preset for the knobs not set here: fast | balanced | precise

    [materials]
    surface_tension_mN_m = 72.8
    pad_angle_deg = 30
    substrate_angle_deg = 60
    allow_repulsive = false

    [twist]
    step_deg = 1.0
    min_deg = -45                   # default: one symmetry period of the chip
    max_deg = 45

    [effects]
    twist = true

    [liquid]                        # for the dynamic methods
    viscosity_mPa_s = 1.0
    volume_nl = 20
    # chip_thickness_um = 50, chip_density_kg_m3 = 1200, damping_calibration = 1000 (top level; see materials.DAMPING_CALIBRATION)

    [topography]                    # a protruding pad: the overflow check (simulator.liquid.Topography)
    edge_angle_deg = 90             # solid wedge angle of the pad edge (90 = vertical wall)
    pad_advancing_deg = 50          # default: the pad angle
    chip_angle_deg = 60             # the chip's advancing angle (receding: the stricter case)
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from shapely.geometry import box

from patterns.errors import InputError, positive, require
from patterns.mask import Mask
from patterns.raster import mask_from_geometry
from patterns.resources import check_budget_mb, default_budget_mb, price_raster
from simulator.liquid import Topography, check_surface_tension_mN_m
from simulator.materials import DAMPING_CALIBRATION, SU8_DENSITY_KG_M3, Liquid, Materials

DTYPES = ("float32", "float64")
#: Scene keys that choose what to read from a layout pattern (:class:`patterns.layout.LayoutSelection`).
LAYOUT_KEYS = ("layer", "cell", "chip_layer", "dxf_units")
#: Scene keys on how the pattern and chip images are read (:meth:`Scene.from_inputs`).
IMAGE_KEYS = ("pattern_um_per_px", "chip_um_per_px", "override_scale", "invert", "invert_chip")


def default_memory_budget_mb() -> float:
    """Half of the memory available when the process started, at most 8 GiB (MiB)."""
    return default_budget_mb()


@dataclass(frozen=True)
class TwistGrid:
    """Twists on the pose grid, in degrees (CCW positive).

    ``min_deg``/``max_deg`` of None mean one full rotational-symmetry period of the
    chip, centred on zero (e.g. [-45, 45) for a square chip, [-90, 90) for a
    rectangle), which the steppers treat as periodic.
    """

    step_deg: float = 1.0
    min_deg: float | None = None
    max_deg: float | None = None

    def __post_init__(self) -> None:
        positive("twist step_deg", self.step_deg, "degrees")
        require(self.step_deg <= 90, f"twist step_deg must be <= 90 degrees, got {self.step_deg}")
        if (self.min_deg is None) != (self.max_deg is None):
            raise InputError("twist min_deg and max_deg must be given together (or neither)")
        if self.min_deg is not None:
            for name, v in (("min_deg", self.min_deg), ("max_deg", self.max_deg)):
                require(math.isfinite(v) and abs(v) <= 3600, f"twist {name} must be a finite angle within +-3600 degrees, got {v}")
            require(self.max_deg >= self.min_deg, f"twist max_deg ({self.max_deg}) must be >= min_deg ({self.min_deg})")


@dataclass(frozen=True)
class Effects:
    """The physics a scene calls for; the engine computes nothing else.

    twist: rotate the chip (False: one rotation, twist fixed at 0).
    hysteresis: contact-angle hysteresis of the pad (``materials.pad_receding_deg`` /
        ``pad_advancing_deg``): the steppers stop where the restoring force falls below
        the contact lines' pinning force (:mod:`simulator.hysteresis`).
    meniscus: a liquid of finite height (:mod:`simulator.meniscus`): every cusp of the
        overlap energy rounded over the meniscus height (False: the overlap model, h -> 0).
    """

    twist: bool = True
    meniscus: bool = False
    hysteresis: bool = False

    def __post_init__(self) -> None:
        for name in ("twist", "meniscus", "hysteresis"):
            if not isinstance(getattr(self, name), bool | np.bool_):
                raise InputError(f"effects {name} must be true or false, got {getattr(self, name)!r}")


@dataclass(frozen=True, eq=False)
class Scene:
    """One validated description of what to simulate.

    Attributes:
        pattern: the pattern's wettability mask (values in [0, 1], grey = graded).
        chip: the chip's wettable footprint at the pattern's scale; its ``geometry``
            is kept when known, so rotations are rasterized exactly.
        materials: surface tension and contact angles (Young weights).
        twist: the twist axis of the pose grid.
        effects: which terms are computed.
        window_um: translation half-width of the pose grid (um); None = every
            translation at which the chip can touch the pattern.
        dtype: "float32" (default) or "float64" for the landscape.
        memory_budget_mb: the landscape build refuses to exceed this.
        liquid: the droplet (viscosity, volume) for the dynamic methods.
        chip_thickness_um, chip_density_kg_m3: the chip body (mass, inertia) for dynamics.
        damping_calibration: multiplier on the Couette damping estimate
            (see :data:`simulator.materials.DAMPING_CALIBRATION`).
        topography: a protruding pad's edge angle (None: a flat pattern), for the
            overflow check of :func:`simulator.liquid.scene_warnings`.
    """

    pattern: Mask
    chip: Mask
    materials: Materials = field(default_factory=Materials)
    twist: TwistGrid = field(default_factory=TwistGrid)
    effects: Effects = field(default_factory=Effects)
    window_um: float | None = None
    dtype: str = "float32"
    memory_budget_mb: float = field(default_factory=default_memory_budget_mb)
    liquid: Liquid = field(default_factory=Liquid)
    chip_thickness_um: float = 50.0
    chip_density_kg_m3: float = SU8_DENSITY_KG_M3
    damping_calibration: float = DAMPING_CALIBRATION
    topography: Topography | None = None

    def __post_init__(self) -> None:
        self.pattern.require_nonempty("pattern")
        self.chip.require_nonempty("chip", "--invert-chip")
        require(self.dtype in DTYPES, f"dtype must be one of {DTYPES}, got {self.dtype!r}")
        if self.window_um is not None:
            positive("window_um", self.window_um, "um")
        check_budget_mb(self.memory_budget_mb, "memory_budget_mb")
        positive("chip thickness", self.chip_thickness_um, "um")
        positive("chip density", self.chip_density_kg_m3, "kg/m^3")
        positive("damping calibration", self.damping_calibration)
        ps, cs = self.pattern.um_per_px, self.chip.um_per_px
        require(
            math.isclose(ps, cs, rel_tol=1e-9),
            f"chip scale {cs} um/px differs from pattern scale {ps} um/px; "
            "give both at one scale (Scene.from_inputs resamples a chip PNG for you)",
        )
        if self.effects.meniscus:
            _ = self.meniscus_height_um  # validated here: positive, finite, not above the chip
        if self.effects.hysteresis:
            require(self.materials.pad_receding_deg is not None,
                    "contact-angle hysteresis needs the pad's receding and advancing angles: --hysteresis RECEDING:ADVANCING "
                    "(or [materials] pad_receding_deg and pad_advancing_deg)")

    @property
    def delta_gamma_N_m(self) -> float:
        """The energy per unit area of overlap (N/m, negative): the materials' Young
        contrast, or ``-2 gamma_LA`` when the liquid is pinned at the pad edges."""
        if self.liquid.pinned:
            return -2.0 * self.materials.surface_tension_N_m
        return self.materials.delta_gamma_N_m

    @property
    def chip_min_side_um(self) -> float:
        """The smallest side (um) of the chip's wettable footprint (:func:`patterns.mask.footprint_um`)."""
        from patterns.mask import footprint_um

        return float(min(footprint_um(self.chip)))

    @property
    def meniscus_height_um(self) -> float | None:
        """The meniscus height (um) when the scene calls for the meniscus, else None: the
        liquid's ``meniscus_height_um``, or its volume over the chip's wetted area."""
        if not self.effects.meniscus:
            return None
        from simulator.meniscus import require_height

        h, flag = self.liquid.height_um, "--meniscus-height"
        if h is None:
            area = self.chip.area_um2
            require(area > 0, "the meniscus height needs a chip with a wetted area to divide the volume by; give --meniscus-height")
            h, flag = self.liquid.meniscus_height_um(area), "--volume"
        return require_height(h, self.chip_min_side_um, flag)

    @property
    def meniscus_height_px(self) -> float:
        """The meniscus height in pixels (0 without the meniscus)."""
        h = self.meniscus_height_um
        return 0.0 if h is None else h / self.um_per_px

    @property
    def um_per_px(self) -> float:
        return self.pattern.um_per_px

    @functools.cached_property
    def twist_axis(self):
        """The twist axis of the pose grid (:class:`simulator.posegrid.TwistAxis`): the
        chip's symmetry is computed once per scene, however often the axis is asked for."""
        from simulator.posegrid import TwistAxis

        return TwistAxis.from_scene(self)

    def replace(self, **changes: Any) -> Scene:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def at_resolution(self, um_per_px: float) -> Scene:
        """The scene at another pixel size: pattern and chip resampled
        (:func:`resample_to_scale`: exact geometry rasterized anew), priced against the budget."""
        s = positive("resolution", um_per_px, "um per px")
        if math.isclose(s, self.um_per_px, rel_tol=1e-9):
            return self
        b = self.memory_budget_mb
        return self.replace(pattern=resample_to_scale(self.pattern, s, b), chip=resample_to_scale(self.chip, s, b))

    def with_preset(self, name: str | None = None, explicit: dict | None = None) -> Scene:
        """The scene with the knobs of an accuracy preset (pixel size, twist step, dtype)
        that ``explicit`` does not set (:func:`simulator.accuracy.apply_preset`; None =
        the default preset). A pattern image is never refined past its own pixels."""
        from simulator.accuracy import apply_preset

        native = None if self.pattern.geometry is not None else self.pattern.um_per_px
        knobs = apply_preset(name, explicit, feature_um=self.smallest_feature_um(), native_um_per_px=native)
        scene = self.at_resolution(knobs["um_per_px"])
        if knobs["twist_step_deg"] != scene.twist.step_deg:
            scene = scene.replace(twist=TwistGrid(knobs["twist_step_deg"], scene.twist.min_deg, scene.twist.max_deg))
        if knobs["dtype"] != scene.dtype:
            scene = scene.replace(dtype=knobs["dtype"])
        return scene

    def smallest_feature_um(self) -> float | None:
        """The pattern's smallest feature in um (:func:`simulator.accuracy.smallest_feature_um`), or None."""
        from simulator.accuracy import smallest_feature_um

        try:
            return smallest_feature_um(self.pattern)
        except InputError:
            return None

    def accuracy_warning(self, pattern: Mask | None = None) -> str | None:
        """A one-line warning when the pixel size leaves the smallest feature of ``pattern``
        (default: the scene's) under 3 pixels, else None."""
        from simulator.accuracy import feature_warning

        pattern = self.pattern if pattern is None else pattern
        try:
            return feature_warning(pattern, self.um_per_px)
        except InputError:
            return None

    # ----------------------------------------------------------------- builders
    @classmethod
    def from_inputs(
        cls,
        pattern: Mask | str | os.PathLike,
        chip: Mask | str | os.PathLike | None = None,
        chip_size_um: tuple[float, float] | float | None = None,
        um_per_px: float | None = None,
        resolution_um: float | None = None,
        max_image_mpx: float | None = None,
        layout: Any = None,
        pattern_um_per_px: float | None = None,
        chip_um_per_px: float | None = None,
        override_scale: bool = False,
        invert: bool = False,
        invert_chip: bool = False,
        **kwargs: Any,
    ) -> Scene:
        """Scene from a pattern (Mask, PNG or layout path) and a chip (Mask, PNG/layout path, size or layout layer).

        ``um_per_px`` states the scale of PNGs that store none (their pHYs chunk wins);
        ``pattern_um_per_px`` and ``chip_um_per_px`` state it for one file each (and win over
        ``um_per_px``). A scale that contradicts a file's stored one is an InputError unless
        ``override_scale``, which makes the given scales replace the stored ones.
        ``invert`` / ``invert_chip`` read the pattern / chip image with black as wettable.
        ``resolution_um`` is the pixel size to simulate at (default: the pattern's):
        the pattern is resampled to it (:func:`resample_to_scale`). A chip PNG at
        another scale is resampled to the simulation scale the same way.
        ``chip_size_um`` gives an exact rectangle (width, height) or a square (one number).
        ``max_image_mpx`` raises the limit on the size of the images read (megapixels).
        ``layout`` (a :class:`patterns.layout.LayoutSelection`) chooses the cell and layers of a
        ``.gds``/``.oas``/``.dxf`` pattern, rasterized at ``resolution_um`` (else ``um_per_px``,
        else :data:`patterns.layout.DEFAULT_UM_PER_PX`); its ``chip_layer`` gives the chip.
        Every raster is priced against ``memory_budget_mb`` before it is made.
        """
        from patterns.io import read_mask
        from patterns.layout import (
            DEFAULT_UM_PER_PX,
            LayoutSelection,
            is_layout,
            layout_chip_mask,
            layout_masks,
        )

        budget = kwargs.get("memory_budget_mb")
        if budget is not None:
            budget = check_budget_mb(budget, "memory_budget_mb")
        layout = layout if layout is not None else LayoutSelection()
        layout_chip = None
        p_scale, p_flag = (pattern_um_per_px, "--pattern-um-per-px") if pattern_um_per_px is not None else (um_per_px, "--um-per-px")
        c_scale, c_flag = (chip_um_per_px, "--chip-um-per-px") if chip_um_per_px is not None else (um_per_px, "--um-per-px")

        def image(path, scale, flag, hint, inv):
            if override_scale:
                return read_mask(path, um_per_px=scale, invert=inv, max_mpx=max_image_mpx, budget_mb=budget)
            return read_mask(path, default_um_per_px=scale, scale_flag=flag, missing_hint=hint, invert=inv, max_mpx=max_image_mpx, budget_mb=budget)

        if is_layout(pattern):
            require(not invert, f"--invert reads a pattern image with black as the pad; {pattern} is a layout (its polygons are the pads)")
            pattern, layout_chip = layout_masks(pattern, layout, resolution_um or p_scale or DEFAULT_UM_PER_PX, budget)
            resolution_um = None  # rasterized at it already
        else:
            layout.require_unused("the pattern" if isinstance(pattern, Mask) else f"the pattern {pattern}", units_ok=is_layout(chip))
            if not isinstance(pattern, Mask):
                pattern = image(pattern, p_scale, p_flag, "--um-per-px (or --pattern-um-per-px)", invert)
            elif um_per_px is not None:
                pattern = Mask(pattern.data, um_per_px, pattern.geometry, pattern.params)
        if layout_chip is not None:
            require(chip is None and chip_size_um is None, "give one chip: a chip image (--chip), a chip size (--chip-size) or a chip layer (--chip-layer)")
            chip = layout_chip
        require((chip is None) != (chip_size_um is None), "give exactly one of a chip image (--chip), a chip size (--chip-size) or a chip layer (--chip-layer)")
        if resolution_um is not None:
            pattern = resample_to_scale(pattern, positive("resolution", resolution_um, "um per px"), budget)
        s = pattern.um_per_px
        if chip_size_um is not None:
            w, h = (chip_size_um, chip_size_um) if np.isscalar(chip_size_um) else chip_size_um
            w, h = positive("chip width", w, "um"), positive("chip height", h, "um")
            chip = mask_from_geometry(
                box(-w / 2, -h / 2, w / 2, h / 2), s, params={"design": "rectangle", "width_um": w, "height_um": h}, budget_mb=budget, what=f"the {w:g} x {h:g} um chip raster"
            )
        else:
            if is_layout(chip):
                chip = layout_chip_mask(chip, s, layout, budget)
            elif not isinstance(chip, Mask):
                chip = image(chip, c_scale, c_flag, "--chip-um-per-px (or --um-per-px)", invert_chip)
            chip = resample_to_scale(chip, s, budget)
        return cls(pattern=pattern, chip=chip, **kwargs)

    @classmethod
    def from_toml(cls, path: str | os.PathLike, **overrides: Any) -> Scene:
        """Scene from a TOML file (keys in the module docstring); paths are relative to it.

        The file means what it means on the command line: its ``accuracy`` preset (default
        "balanced") sets the pixel size, twist step and dtype the file does not set.
        """
        from simulator.schema import read_scene_file

        return cls.from_dict(read_scene_file(path), base=Path(path).parent, **overrides)

    @classmethod
    def from_dict(cls, doc: dict, base: Path = Path("."), **overrides: Any) -> Scene:
        known = {
            "pattern", "chip", "chip_size_um", "um_per_px", "resolution_um", "dtype", "window_um", "memory_budget_mb", "materials", "twist",
            "effects", "liquid", "chip_thickness_um", "chip_density_kg_m3", "damping_calibration", "max_image_mpx",
            "topography", *LAYOUT_KEYS, *IMAGE_KEYS,
        }
        unknown = set(doc) - known - {"simulate", "montecarlo", "accuracy"}
        require(not unknown, f"unknown scene keys {sorted(unknown)}; allowed: {sorted(known)}")
        require("pattern" in doc, "scene needs a 'pattern' (PNG or layout path)")
        try:
            scene = cls._from_dict(doc, base, overrides)
        except TypeError as err:  # an unknown key inside a TOML table
            raise InputError(f"scene: {err}") from None
        explicit = {"um_per_px": doc.get("resolution_um"), "twist_step_deg": (doc.get("twist") or {}).get("step_deg"), "dtype": doc.get("dtype")}
        return scene.with_preset(doc.get("accuracy"), explicit)

    @classmethod
    def _from_dict(cls, doc: dict, base: Path, overrides: dict) -> Scene:
        def resolve(p: Any) -> Any:
            return p if isinstance(p, Mask) else base / p

        kw: dict[str, Any] = {}
        if "materials" in doc:
            m = dict(doc["materials"])
            if "surface_tension_mN_m" in m:
                where = "surface tension (--surface-tension, [materials] surface_tension_mN_m)"
                m["surface_tension_N_m"] = check_surface_tension_mN_m(m.pop("surface_tension_mN_m"), where) / 1000
            kw["materials"] = Materials(**m)
        if "twist" in doc:
            kw["twist"] = TwistGrid(**doc["twist"])
        if "effects" in doc:
            kw["effects"] = Effects(**doc["effects"])
        if "liquid" in doc:
            liq = dict(doc["liquid"])
            if "surface_tension_mN_m" in liq:
                where = "[liquid] surface_tension_mN_m"
                liq["surface_tension_N_m"] = check_surface_tension_mN_m(liq.pop("surface_tension_mN_m"), where) / 1000
            if "viscosity_mPa_s" in liq:
                liq["viscosity_Pa_s"] = float(liq.pop("viscosity_mPa_s")) / 1000
            if "meniscus_height_um" in liq:
                liq["height_um"] = liq.pop("meniscus_height_um")
            kw["liquid"] = Liquid(**liq)
        if "topography" in doc:
            require("edge_angle_deg" in doc["topography"], "a protruding pad needs its edge angle: give --edge-angle DEG "
                    "([topography] edge_angle_deg; 90 = vertical wall) with --pad-advancing / --chip-angle")
            kw["topography"] = Topography(**doc["topography"])
        for key in ("dtype", "window_um", "memory_budget_mb", "chip_thickness_um", "chip_density_kg_m3", "damping_calibration"):
            if key in doc:
                kw[key] = doc[key]
        kw.update({k: v for k, v in overrides.items() if v is not None})
        chip = doc.get("chip")
        from patterns.layout import LayoutSelection

        layout = LayoutSelection(**{k: doc[k] for k in LAYOUT_KEYS if k in doc})
        return cls.from_inputs(
            pattern=resolve(doc["pattern"]),
            chip=resolve(chip) if chip is not None else None,
            chip_size_um=doc.get("chip_size_um"),
            um_per_px=doc.get("um_per_px"),
            resolution_um=doc.get("resolution_um"),
            max_image_mpx=doc.get("max_image_mpx"),
            layout=layout,
            **{k: doc[k] for k in IMAGE_KEYS if k in doc},
            **kw,
        )


def resample_to_scale(mask: Mask, um_per_px: float, budget_mb: float | None = None) -> Mask:
    """``mask`` at another pixel size, its centre kept at the image centre.

    Exact geometry is rasterized anew. A raster is first padded symmetrically with
    substrate so that its size maps to whole pixels at the new scale, then resampled
    by area averaging (OpenCV INTER_AREA; sum x pixel area preserved) when coarsening,
    and by pixel replication when refining. The result is priced against ``budget_mb``
    (default: the default budget) before it is made.
    """
    if math.isclose(mask.um_per_px, um_per_px, rel_tol=1e-9):
        return mask
    if mask.geometry is not None:
        return mask_from_geometry(mask.geometry, um_per_px, params=mask.params, budget_mb=budget_mb, what=f"the raster at {um_per_px:g} um/px")
    import cv2

    f = mask.um_per_px / um_per_px  # new pixels per old pixel
    price_raster(tuple(n * f for n in mask.shape), um_per_px, f"the image resampled to {um_per_px:g} um/px", budget_mb)
    sizes = []
    for n in mask.shape:
        m = next((m for m in range(n, n + 2001, 2) if abs(m * f - round(m * f)) < 1e-6 and round(m * f) >= 1), None)
        if m is None:
            raise InputError(
                f"cannot resample a {mask.um_per_px:g} um/px image to {um_per_px:g} um/px without moving its centre; "
                "choose a resolution that is a simple multiple or fraction of the image's"
            )
        sizes.append(m)
    (h, w), (ph, pw) = mask.shape, sizes
    data = np.pad(mask.data, (((ph - h) // 2,) * 2, ((pw - w) // 2,) * 2))
    out = cv2.resize(data, (round(pw * f), round(ph * f)), interpolation=cv2.INTER_AREA if f < 1 else cv2.INTER_NEAREST)
    return Mask(np.clip(out, 0, 1), um_per_px, None, mask.params)
