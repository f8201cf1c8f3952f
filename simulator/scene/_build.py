"""How a :class:`~simulator.scene.Scene` is built from what a user gives.

Owns the scene's builders, :meth:`~SceneBuilders.from_inputs` (a pattern and a chip as
masks, PNG or layout paths, or a chip size; scales, inversion, resampling to the
simulation resolution, every raster priced against the budget),
:meth:`~SceneBuilders.from_toml` and :meth:`~SceneBuilders.from_dict` (a scene file, keys
in the :mod:`simulator.scene` docstring, with its accuracy preset), as the classmethods of
:class:`SceneBuilders`, which :class:`~simulator.scene.Scene` inherits; the scene keys of
layout patterns and images (:data:`LAYOUT_KEYS`, :data:`IMAGE_KEYS`, declared with every
scene key in :mod:`simulator.scene._params`); and
:func:`resample_to_scale`, a mask at another pixel size. Every name is importable from
:mod:`simulator.scene` as before.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import numpy as np
from numpy.typing import ArrayLike
from shapely.geometry import box

from foundation import InputError, check_budget_mb, positive, price_raster, require
from patterns.geometry import Mask, footprint_um, mask_from_geometry
from simulator.liquid import Topography, check_surface_tension_mN_m
from simulator.physics import Liquid, Materials
from simulator.scene._params import IMAGE_KEYS, LAYOUT_KEYS, SCENE_FIELD_KEYS, known_keys
from simulator.scene._parts import Effects, TwistGrid
from simulator.scene._plausible import check_scales


class SceneBuilders:
    """The classmethods that build a :class:`~simulator.scene.Scene` (its base class): from
    inputs (:meth:`from_inputs`), a TOML file (:meth:`from_toml`) or its table (:meth:`from_dict`)."""

    if TYPE_CHECKING:  # for the type checker: what the builders call, defined by Scene

        def __init__(self, **fields: Any) -> None: ...

        def with_preset(
            self, name: str | None = None, explicit: dict | None = None, check_scale: bool = True
        ) -> Any: ...

    # ----------------------------------------------------------------- builders
    @classmethod
    def from_inputs(
        cls,
        pattern: Mask | str | os.PathLike,
        chip: Mask | str | os.PathLike | None = None,
        chip_size_um: ArrayLike | None = None,
        um_per_px: float | None = None,
        resolution_um: float | None = None,
        max_image_mpx: float | None = None,
        layout: Any = None,
        pattern_um_per_px: float | None = None,
        chip_um_per_px: float | None = None,
        override_scale: bool = False,
        invert: bool = False,
        invert_chip: bool = False,
        channel: str | None = None,
        check_scale: bool = True,
        **kwargs: Any,
    ) -> Self:
        """Scene from a pattern (Mask, PNG or layout path) and a chip (Mask, PNG/layout path, size or layout layer).

        ``um_per_px`` states the scale of PNGs that store none (their pHYs chunk wins);
        ``pattern_um_per_px`` and ``chip_um_per_px`` state it for one file each (and win over
        ``um_per_px``). A scale that contradicts a file's stored one is an InputError unless
        ``override_scale``, which makes the given scales replace the stored ones.
        ``invert`` / ``invert_chip`` read the pattern / chip image with black as wettable.
        ``channel`` picks what a colour image gives (:func:`patterns.read_mask`; red, green,
        blue or luminance): one whose channels differ is refused without it. A pattern image
        that looks inverted (:func:`patterns.polarity_warning`) is noted in the scene's
        ``input_warnings``. A chip and a pattern of implausible scales for each other (a size
        off by about 1000, a chip of fewer than 3 px) are refused before the chip's raster is
        made (:func:`simulator.scene._plausible.check_scales`); ``check_scale=False`` skips that
        for a stand-in chip (a probe that only reads the pattern).
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
        from patterns import read_mask
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
        from patterns import polarity_warning

        notes: list[str | None] = []  # warnings on the images as read (Scene.input_warnings)
        layout = layout if layout is not None else LayoutSelection()
        layout_chip = None
        p_scale, p_flag = (
            (pattern_um_per_px, "--pattern-um-per-px")
            if pattern_um_per_px is not None
            else (um_per_px, "--um-per-px")
        )
        c_scale, c_flag = (
            (chip_um_per_px, "--chip-um-per-px")
            if chip_um_per_px is not None
            else (um_per_px, "--um-per-px")
        )

        def image(path, scale, flag, hint, inv):
            if override_scale:
                return read_mask(
                    path,
                    um_per_px=scale,
                    invert=inv,
                    max_mpx=max_image_mpx,
                    budget_mb=budget,
                    channel=channel,
                )
            return read_mask(
                path,
                default_um_per_px=scale,
                scale_flag=flag,
                missing_hint=hint,
                invert=inv,
                max_mpx=max_image_mpx,
                budget_mb=budget,
                channel=channel,
            )

        if is_layout(pattern):
            require(
                not invert,
                f"--invert reads a pattern image with black as the pad; {pattern} is a layout (its polygons are the pads)",
            )
            pattern, layout_chip = layout_masks(
                pattern, layout, resolution_um or p_scale or DEFAULT_UM_PER_PX, budget
            )
            resolution_um = None  # rasterized at it already
        else:
            layout.require_unused(
                "the pattern" if isinstance(pattern, Mask) else f"the pattern {pattern}",
                units_ok=is_layout(chip),
            )
            if not isinstance(pattern, Mask):
                pattern = image(
                    pattern, p_scale, p_flag, "--um-per-px (or --pattern-um-per-px)", invert
                )
                notes.append(polarity_warning(pattern, invert))
            elif um_per_px is not None:
                pattern = Mask(pattern.data, um_per_px, pattern.geometry, pattern.params)
        if layout_chip is not None:
            require(
                chip is None and chip_size_um is None,
                "give one chip: a chip image (--chip), a chip size (--chip-size) or a chip layer (--chip-layer)",
            )
            chip = layout_chip
        require(
            (chip is None) != (chip_size_um is None),
            "give exactly one of a chip image (--chip), a chip size (--chip-size) or a chip layer (--chip-layer)",
        )
        if resolution_um is not None:
            pattern = resample_to_scale(
                pattern, positive("resolution", resolution_um, "um per px"), budget
            )
        s = pattern.um_per_px
        if chip_size_um is not None:
            w, h = _chip_size(chip_size_um)
            w, h = positive("chip width", w, "um"), positive("chip height", h, "um")
            if check_scale:  # before the chip's raster is made
                check_scales(pattern, (w, h), s, "size")
            chip = mask_from_geometry(
                box(-w / 2, -h / 2, w / 2, h / 2),
                s,
                params={"design": "rectangle", "width_um": w, "height_um": h},
                budget_mb=budget,
                what=f"the {w:g} x {h:g} um chip raster",
            )
        else:
            chip_from = "layout" if is_layout(chip) else "image"
            if is_layout(chip):
                chip = layout_chip_mask(chip, s, layout, budget)
            elif not isinstance(chip, Mask):
                chip = image(
                    chip, c_scale, c_flag, "--chip-um-per-px (or --um-per-px)", invert_chip
                )
            if layout_chip is not None:
                chip_from = "layout"
            if check_scale and np.any(chip.data > 0):  # an empty chip is refused as such (Scene)
                check_scales(pattern, footprint_um(chip), s, chip_from)
            chip = resample_to_scale(chip, s, budget)
        kwargs["input_warnings"] = tuple(n for n in notes if n)
        return cls(pattern=pattern, chip=chip, **kwargs)

    @classmethod
    def from_toml(cls, path: str | os.PathLike, **overrides: Any) -> Self:
        """Scene from a TOML file (keys in the :mod:`simulator.scene` docstring); paths are relative to it.

        The file means what it means on the command line: its ``accuracy`` preset (default
        "balanced") sets the pixel size, twist step and dtype the file does not set.
        """
        from simulator.scene._schema import read_scene_file

        return cls.from_dict(read_scene_file(path), base=Path(path).parent, **overrides)

    @classmethod
    def from_dict(
        cls, doc: dict, base: Path = Path("."), check_scale: bool = True, **overrides: Any
    ) -> Self:
        known = known_keys() - {"accuracy"}  # the preset is allowed, not listed (below)
        unknown = set(doc) - known - {"simulate", "montecarlo", "accuracy"}
        require(not unknown, f"unknown scene keys {sorted(unknown)}; allowed: {sorted(known)}")
        require("pattern" in doc, "scene needs a 'pattern' (PNG or layout path)")
        try:
            scene = cls._from_dict(doc, base, overrides | {"check_scale": check_scale})
        except TypeError as err:  # an unknown key inside a TOML table
            raise InputError(f"scene: {err}") from None
        explicit = {
            "um_per_px": doc.get("resolution_um"),
            "twist_step_deg": (doc.get("twist") or {}).get("step_deg"),
            "dtype": doc.get("dtype"),
        }
        return scene.with_preset(doc.get("accuracy"), explicit, check_scale=check_scale)

    @classmethod
    def _from_dict(cls, doc: dict, base: Path, overrides: dict) -> Self:
        def resolve(p: Any) -> Any:
            return p if isinstance(p, Mask) else base / p

        kw: dict[str, Any] = {}
        if "materials" in doc:
            m = dict(doc["materials"])
            if "surface_tension_mN_m" in m:
                where = "surface tension (--surface-tension, [materials] surface_tension_mN_m)"
                m["surface_tension_N_m"] = (
                    check_surface_tension_mN_m(m.pop("surface_tension_mN_m"), where) / 1000
                )
            kw["materials"] = Materials(**m)
        if "twist" in doc:
            kw["twist"] = TwistGrid(**doc["twist"])
        if "effects" in doc:
            kw["effects"] = Effects(**doc["effects"])
        # Without a volume the scene derives one from the chip (simulator.liquid.default_volume_nl).
        kw["liquid"] = Liquid(volume_nl=None)
        if "liquid" in doc:
            liq: dict[str, Any] = {"volume_nl": None} | dict(doc["liquid"])
            if "surface_tension_mN_m" in liq:
                where = "[liquid] surface_tension_mN_m"
                liq["surface_tension_N_m"] = (
                    check_surface_tension_mN_m(liq.pop("surface_tension_mN_m"), where) / 1000
                )
            if "viscosity_mPa_s" in liq:
                liq["viscosity_Pa_s"] = float(liq.pop("viscosity_mPa_s")) / 1000
            if "meniscus_height_um" in liq:
                liq["height_um"] = liq.pop("meniscus_height_um")
            if isinstance(liq.get("dispense_at_um"), str):  # "X,Y" as the flag takes it
                text = liq["dispense_at_um"]
                try:
                    liq["dispense_at_um"] = tuple(float(v) for v in text.split(","))
                except ValueError:
                    raise InputError(
                        f"dispense point (--dispense-at X,Y) must be two numbers of um separated by a comma, got {text!r}"
                    ) from None
            kw["liquid"] = Liquid(**liq)
        if "topography" in doc:
            require(
                "edge_angle_deg" in doc["topography"],
                "a protruding pad needs its edge angle: give --edge-angle DEG "
                "([topography] edge_angle_deg; 90 = vertical wall) with --pad-advancing / --chip-angle",
            )
            kw["topography"] = Topography(**doc["topography"])
        for key in SCENE_FIELD_KEYS:
            if key in doc:
                kw[key] = doc[key]
        kw.update({k: v for k, v in overrides.items() if v is not None})  # check_scale among them
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


def _padded_size(n: int, f: float, mask: Mask, um_per_px: float) -> int:
    """The size (px) a raster axis of ``n`` px is padded to, symmetrically, so that it maps to
    whole pixels at ``f`` new pixels per old pixel (:func:`resample_to_scale`)."""
    m = next(
        (
            m
            for m in range(n, n + 2001, 2)
            if abs(m * f - round(m * f)) < 1e-6 and round(m * f) >= 1
        ),
        None,
    )
    if m is None:
        raise InputError(
            f"cannot resample a {mask.um_per_px:g} um/px image to {um_per_px:g} um/px without moving its centre; "
            "choose a resolution that is a simple multiple or fraction of the image's"
        )
    return m


def resampled_extent(
    mask: Mask, um_per_px: float
) -> tuple[tuple[int, int], tuple[int, int, int, int]]:
    """(shape, nonzero box) of :func:`resample_to_scale` ``(mask, um_per_px)``, computed
    without making the raster: the box (row0, row1, col0, col1, end-exclusive) as
    :func:`patterns.geometry.nonzero_box` would give it.

    Exact geometry: the canvas of :func:`patterns.geometry.canvas_shape` and the pixels the
    geometry's bounds reach into (every pixel a polygon reaches into it covers with a positive
    area). A raster coarsened by a whole factor ``k``: the padded raster's blocks of k x k
    pixels, a block non-zero where one of its pixels is (area averaging). Any other
    resampling of a raster is made (and measured).
    """
    from patterns.geometry import canvas_shape, nonzero_box

    s = positive("resolution", um_per_px, "um per px")
    if math.isclose(mask.um_per_px, s, rel_tol=1e-9):
        return mask.shape, nonzero_box(mask.data > 0)
    if mask.geometry is not None:
        h, w = canvas_shape(mask.geometry, s)
        xmin, ymin, xmax, ymax = mask.geometry.bounds
        a = (
            1 / s
        )  # the pixel frame of patterns.geometry.to_pixel_frame: column = x / s + w / 2, row = h / 2 - y / s
        c0, c1 = math.floor(a * xmin + w / 2), math.ceil(a * xmax + w / 2)
        r0, r1 = math.floor(-a * ymax + h / 2), math.ceil(-a * ymin + h / 2)
        return (h, w), (max(r0, 0), min(r1, h), max(c0, 0), min(c1, w))
    k = s / mask.um_per_px
    if abs(k - round(k)) < 1e-9 and round(k) >= 1:
        k = round(k)
        (h, w), f = mask.shape, 1.0 / k
        ph, pw = _padded_size(h, f, mask, s), _padded_size(w, f, mask, s)
        r0, r1, c0, c1 = nonzero_box(mask.data > 0)
        oy, ox = (ph - h) // 2, (pw - w) // 2
        return (ph // k, pw // k), (
            (r0 + oy) // k,
            -(-(r1 + oy) // k),
            (c0 + ox) // k,
            -(-(c1 + ox) // k),
        )
    out = resample_to_scale(mask, s)
    return out.shape, nonzero_box(out.data > 0)


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
        return mask_from_geometry(
            mask.geometry,
            um_per_px,
            params=mask.params,
            budget_mb=budget_mb,
            what=f"the raster at {um_per_px:g} um/px",
        )
    import cv2

    f = mask.um_per_px / um_per_px  # new pixels per old pixel
    h, w = mask.shape
    price_raster(
        (h * f, w * f),
        um_per_px,
        f"the image resampled to {um_per_px:g} um/px",
        budget_mb,
    )
    (h, w), (ph, pw) = mask.shape, [_padded_size(n, f, mask, um_per_px) for n in mask.shape]
    data = np.pad(mask.data, (((ph - h) // 2,) * 2, ((pw - w) // 2,) * 2))
    out = cv2.resize(
        data,
        (round(pw * f), round(ph * f)),
        interpolation=cv2.INTER_AREA if f < 1 else cv2.INTER_NEAREST,
    )
    return Mask(np.clip(out, 0, 1), um_per_px, None, mask.params)


def _chip_size(size: Any) -> tuple[Any, Any]:
    """(width, height) of ``chip_size_um``: one number (a square) or two (a rectangle); InputError
    for anything else (each side is then checked by :func:`~foundation.positive`)."""
    if isinstance(size, bool | np.bool_):
        raise InputError(f"chip_size_um must be a size in um, not {size!r}")
    if np.isscalar(size):
        return size, size
    try:
        sides = list(size)
    except TypeError:
        sides = None
    if (
        sides is None
        or len(sides) != 2
        or any(not np.isscalar(v) or isinstance(v, bool) for v in sides)
    ):
        raise InputError(
            f"chip_size_um must be one number (a square chip) or two (width, height) in um, got {size!r}"
        )
    return sides[0], sides[1]
