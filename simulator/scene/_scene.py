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
    volume_nl = 20                  # default: a film of 5 % of the chip's smallest side
    # chip_thickness_um = 50, chip_density_kg_m3 = 1200, damping_calibration (top level; none: the damping's terms, docs/physics.md §4), line_friction_Pa_s = 6 (fitted to the video; water on oxide 0.01-0.1)

    [topography]                    # a protruding pad: the overflow check (simulator.liquid.Topography)
    edge_angle_deg = 90             # solid wedge angle of the pad edge (90 = vertical wall)
    pad_advancing_deg = 50          # default: the pad angle
    chip_angle_deg = 60             # the chip's advancing angle (receding: the stricter case)

Modules: this one holds the :class:`Scene` (its fields, validation and derived
quantities); its builders (:meth:`Scene.from_inputs`, :meth:`Scene.from_toml`,
:meth:`Scene.from_dict`) and :func:`resample_to_scale` are
:mod:`simulator.scene`, :class:`TwistGrid` and :class:`Effects`
:mod:`simulator.scene`; every name is importable from here.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from foundation import InputError, check_budget_mb, default_budget_mb, positive, require
from patterns.geometry import Mask
from simulator.core import SU8_DENSITY_KG_M3
from simulator.liquid import Topography
from simulator.physics import LINE_FRICTION_PA_S, Liquid, Materials
from simulator.scene._build import SceneBuilders, resample_to_scale
from simulator.scene._parts import Effects, TwistGrid
from simulator.scene._schema_kinds import DTYPES
from simulator.scene._twist_axis import TwistAxis


def default_memory_budget_mb() -> float:
    """Half of the memory available when the process started, at most 8 GiB (MiB)."""
    return default_budget_mb()


def chip_radius_of_gyration_px(chip: Mask) -> float:
    """sqrt(polar moment / area) (px) of a chip's wettable footprint about its centre: the
    one formula of the radius of gyration (:attr:`Scene.chip_rg_px` caches it per scene).
    Each pixel counts its coverage at its centre (no ``1/6 px^2`` self-term: a full
    ``n x n`` px square gives ``sqrt((n^2 - 1) / 6)`` px, the exact ``n / sqrt(6)`` less a
    relative ``1 / (12 rg^2)``)."""
    d = chip.data
    h, w = d.shape
    # r^2 = x^2 + y^2 separates: the column and row sums of the footprint carry the moment
    # (no chip-sized array of r^2: a 4000 px chip's took a second and 0.5 GB).
    cols, rows = d.sum(axis=0, dtype=np.float64), d.sum(axis=1, dtype=np.float64)
    x2 = (np.arange(w) + 0.5 - w / 2) ** 2
    y2 = (np.arange(h) + 0.5 - h / 2) ** 2
    return float(math.sqrt((cols @ x2 + rows @ y2) / rows.sum()))


@dataclass(frozen=True, eq=False)
class Scene(SceneBuilders):
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
        damping_calibration: None (default): the damping is the sum of its documented terms
            (:func:`simulator.physics.dissipation_terms`, docs/physics.md §4); a number k:
            the film's Couette drag times k instead (the override; 600,
            :data:`simulator.physics.DAMPING_CALIBRATION`, was the fit to the source's video).
        line_friction_Pa_s: molecular-kinetic contact-line friction coefficient, Pa s
            (:data:`simulator.physics.LINE_FRICTION_PA_S`), one of the terms.
        topography: a protruding pad's edge angle (None: a flat pattern), for the
            overflow check of :func:`simulator.liquid.scene_warnings`.
        input_warnings: one-line warnings on the images as read (a pattern that looks
            inverted, :func:`patterns.polarity_warning`), printed by the commands.
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
    damping_calibration: float | None = None
    line_friction_Pa_s: float = LINE_FRICTION_PA_S
    topography: Topography | None = None
    input_warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        self.pattern.require_nonempty("pattern")
        self.chip.require_nonempty("chip", "--invert-chip")
        if self.liquid.volume_nl is None:  # no volume given: derived from the chip
            from simulator.liquid import default_volume_nl

            v = default_volume_nl(self.chip.area_um2, self.chip_min_side_um)
            object.__setattr__(
                self, "liquid", replace(self.liquid, volume_nl=v, volume_derived=True)
            )
        require(self.dtype in DTYPES, f"dtype must be one of {DTYPES}, got {self.dtype!r}")
        if self.window_um is not None:
            positive("window_um", self.window_um, "um")
        check_budget_mb(self.memory_budget_mb, "memory_budget_mb")
        positive("chip thickness", self.chip_thickness_um, "um")
        positive("chip density", self.chip_density_kg_m3, "kg/m^3")
        if self.damping_calibration is not None:
            positive("damping calibration", self.damping_calibration)
        positive("line friction", self.line_friction_Pa_s, "Pa s")
        ps, cs = self.pattern.um_per_px, self.chip.um_per_px
        require(
            math.isclose(ps, cs, rel_tol=1e-9),
            f"chip scale {cs} um/px differs from pattern scale {ps} um/px; "
            "give both at one scale (Scene.from_inputs resamples a chip PNG for you)",
        )
        if self.window_um is not None and self.window_um < ps:
            # Below a pixel the pose grid has no translation to step to (and 1e-300 rounds to none at all).
            raise InputError(
                f"window_um (--window) {self.window_um:g} um is below one pixel of the pose grid ({ps:g} um); "
                f"give at least {ps:g} um, or leave it out for the full reach"
            )
        if self.effects.meniscus:
            _ = self.meniscus_height_um  # validated here: positive, finite, not above the chip
        if self.liquid.dispense in ("pattern", "chip") and self.wall_profile is None:
            raise InputError(
                f"--dispense {self.liquid.dispense} makes the wetted footprint a state of the run, which needs the "
                "finite meniscus with free contact lines: give --meniscus (not --pinned)"
                + (
                    f", with a height of at least a pixel (a finer --resolution than {self.um_per_px:g} um)"
                    if self.effects.meniscus and not self.liquid.pinned
                    else ""
                )
                + ", or leave --dispense out"
            )
        if self.liquid.dispense_at_um is not None and self.dispense != "pattern":
            raise InputError(
                "--dispense-at places a droplet dispensed on the pattern, which makes the wetted footprint a "
                "state of the run and needs the finite meniscus with free contact lines: give --meniscus "
                "(not --pinned), or leave --dispense-at out"
            )
        if self.effects.hysteresis:
            require(
                self.materials.pad_receding_deg is not None,
                "contact-angle hysteresis needs the pad's receding and advancing angles: --hysteresis RECEDING:ADVANCING "
                "(or [materials] pad_receding_deg and pad_advancing_deg)",
            )

    @property
    def dispense(self) -> str | None:
        """The protocol the run's footprint state starts from (docs/physics.md §3.5):
        ``"pattern"`` or ``"chip"``, or None for the stateless footprint. The liquid's
        ``dispense`` when given (``"none"``: None); when not, ``"pattern"``
        (:data:`simulator.physics.DEFAULT_DISPENSE`) wherever the scene's meniscus has free
        contact lines and a height of a pixel or more (:attr:`wall_profile`), else None: the
        overlap model, pinned lines and sub-pixel heights have no footprint to keep."""
        given = self.liquid.dispense
        if given is not None:
            return None if given == "none" else given
        if self.wall_profile is None:
            return None
        from simulator.physics import DEFAULT_DISPENSE

        return DEFAULT_DISPENSE

    @property
    def delta_gamma_N_m(self) -> float:
        """The energy per unit area of overlap (N/m, negative): the materials' Young
        contrast, or ``-2 gamma_LA`` when the liquid is pinned at the pad edges."""
        if self.liquid.pinned:
            return -2.0 * self.materials.surface_tension_N_m
        return self.materials.delta_gamma_N_m

    @property
    def chip_min_side_um(self) -> float:
        """The smallest side (um) of the chip's wettable footprint (:func:`patterns.geometry.footprint_um`)."""
        from patterns.geometry import footprint_um

        return float(min(footprint_um(self.chip)))

    @functools.cached_property
    def liquid_height_um(self) -> float:
        """The liquid's height under the chip (um), derived once per scene: the given
        meniscus height (``liquid.height_um``, ``--meniscus-height``), else the droplet volume
        over the chip's wetted area (:meth:`simulator.physics.Liquid.meniscus_height_um`).
        The one height of the scene: the finite meniscus's energy
        (:attr:`meniscus_height_um`) and the dynamics' Couette damping
        (:meth:`simulator.motion.DynamicsParams.from_scene`) both take it."""
        if self.liquid.height_um is None:
            require(
                self.chip.area_um2 > 0,
                "the meniscus height needs a chip with a wetted area to divide the volume by; give --meniscus-height",
            )
        return self.liquid.meniscus_height_um(self.chip.area_um2)

    @functools.cached_property
    def meniscus_height_um(self) -> float | None:
        """The meniscus height (um) when the scene calls for the meniscus, else None:
        :attr:`liquid_height_um`, checked (positive, finite, not above the chip's smallest side)."""
        if not self.effects.meniscus:
            return None
        from simulator.physics import require_height

        flag = "--volume" if self.liquid.height_um is None else "--meniscus-height"
        return require_height(self.liquid_height_um, self.chip_min_side_um, flag)

    @property
    def meniscus_height_px(self) -> float:
        """The meniscus height in pixels (0 without the meniscus)."""
        return self.meniscus_height_px_at(self.um_per_px)

    def meniscus_height_px_at(self, um_per_px: float) -> float:
        """The meniscus height in pixels of ``um_per_px`` (0 without the meniscus)."""
        h = self.meniscus_height_um
        return 0.0 if h is None else h / um_per_px

    @functools.cached_property
    def wall_profile(self):
        """The free-contact-line footprint (:class:`simulator.physics.WallProfile`) when the
        scene's meniscus has free lines and a height of a pixel or more, else None (no
        meniscus, pinned lines, or a height below a pixel: the ``K_h`` blur)."""
        return self._wall_profile_at(self.um_per_px)

    def _wall_profile_at(self, um_per_px: float):
        from simulator.physics import CHIP_BLUR_MIN_PX, WallProfile

        h_px = self.meniscus_height_px_at(um_per_px)
        if self.liquid.pinned or h_px < CHIP_BLUR_MIN_PX:
            return None
        m = self.materials
        return WallProfile.from_angles(h_px, m.pad_angle_deg, m.substrate_angle_deg)

    @property
    def meniscus_margin_px(self) -> int:
        """Pixels beyond the chip that the meniscus's footprint reaches (0 without it)."""
        return self.meniscus_margin_px_at(self.um_per_px)

    def meniscus_margin_px_at(self, um_per_px: float) -> int:
        """:attr:`meniscus_margin_px` for pixels of ``um_per_px`` (the scene's height, not resampled)."""
        from simulator.physics import margin_px

        prof = (
            self.wall_profile if um_per_px == self.um_per_px else self._wall_profile_at(um_per_px)
        )
        return (
            prof.margin_px if prof is not None else margin_px(self.meniscus_height_px_at(um_per_px))
        )

    @property
    def um_per_px(self) -> float:
        return self.pattern.um_per_px

    @functools.cached_property
    def twist_axis(self):
        """The twist axis of the pose grid (:class:`simulator.landscape.TwistAxis`): the
        chip's symmetry is computed once per scene, however often the axis is asked for."""
        return TwistAxis.from_scene(self.chip, self.effects, self.twist)

    @functools.cached_property
    def chip_rg_px(self) -> float:
        """The chip's radius of gyration (px), derived once per scene: sqrt(polar moment /
        area) of its wettable footprint about its centre, each pixel's coverage at its centre
        (:func:`chip_radius_of_gyration_px`). The length one radian of twist moves the chip's
        edge: the pose grid's twist metric (the steppers) and, as ``A rg^2``, the polar moment
        of the dynamics' inertia and rotational damping."""
        return chip_radius_of_gyration_px(self.chip)

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
        return self.replace(
            pattern=resample_to_scale(self.pattern, s, b), chip=resample_to_scale(self.chip, s, b)
        )

    def with_preset(
        self, name: str | None = None, explicit: dict | None = None, check_scale: bool = True
    ) -> Scene:
        """The scene with the knobs of an accuracy preset (pixel size, twist step, dtype)
        that ``explicit`` does not set (:func:`simulator.scene.apply_preset`; None =
        the default preset). A pattern image is never refined past its own pixels, and its
        smallest feature (outlining the whole image) is measured only when it can change
        the pixel size (:func:`simulator.scene.feature_sets_pixel`). A coarser pixel must still
        give the chip 3 px (:func:`simulator.scene._plausible.check_scales`; ``check_scale=False``
        skips it for a stand-in chip)."""
        from simulator.scene._accuracy import apply_preset, feature_sets_pixel

        native = None if self.pattern.geometry is not None else self.pattern.um_per_px
        pixel_given = (explicit or {}).get("um_per_px") is not None
        feature = (
            self.smallest_feature_um()
            if not pixel_given and feature_sets_pixel(name, native)
            else None
        )
        knobs = apply_preset(name, explicit, feature_um=feature, native_um_per_px=native)
        # a coarser grid must still carry the chip
        if check_scale and knobs["um_per_px"] > self.um_per_px:
            from patterns.geometry import footprint_um
            from simulator.scene._plausible import check_scales

            check_scales(self.pattern, footprint_um(self.chip), knobs["um_per_px"], "size")
        scene = self.at_resolution(knobs["um_per_px"])
        if knobs["twist_step_deg"] != scene.twist.step_deg:
            scene = scene.replace(
                twist=TwistGrid(knobs["twist_step_deg"], scene.twist.min_deg, scene.twist.max_deg)
            )
        if knobs["dtype"] != scene.dtype:
            scene = scene.replace(dtype=knobs["dtype"])
        return scene

    def smallest_feature_um(self) -> float | None:
        """The pattern's smallest feature in um (:func:`simulator.scene.smallest_feature_um`), or None."""
        from simulator.scene._accuracy import smallest_feature_um

        try:
            return smallest_feature_um(self.pattern)
        except InputError:
            return None

    def scale_warning(self) -> str | None:
        """A one-line warning when the chip is much larger than the pattern's whole image
        (:func:`simulator.scene._plausible.scale_warning`), else None."""
        from simulator.scene._plausible import scale_warning

        return scale_warning(self.pattern, self.chip)

    def accuracy_warning(self, pattern: Mask | None = None) -> str | None:
        """A one-line warning when the pixel size leaves the smallest feature of ``pattern``
        (default: the scene's) under 3 pixels, else None."""
        from simulator.scene._accuracy import feature_warning

        pattern = self.pattern if pattern is None else pattern
        try:
            return feature_warning(pattern, self.um_per_px)
        except InputError:
            return None
