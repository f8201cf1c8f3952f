"""The pattern library: the source's designs as PNGs at 1 um per px, with an index.

    python -m patterns.library [--out DIR]      # or: make library

writes ``patterns/library/*.png`` (16-bit grey, pHYs scale, parameters in a text chunk),
``index.json``, ``index.md`` and the contact sheet ``overview.png``. Find a file with
:func:`library_path`, e.g. ``read_mask(library_path("four_pad_730_50"))``.

Contents (docs/physics.md §6 and §10): four-pad 730/50, 730/100, 710/50, 710/100 um; a 200 um
square; defect types A, B, C (right edge) inward and outward; constant jaggedness with
amplitudes 1.7, 3.2, 5 and 15 um (centred teeth, pitch = 2 x amplitude, phase 'zero');
random jaggedness with sigma 2, 4 and 8 um (pitch = 4 x sigma, seed 1 for each).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from foundation import InputError, atomic_output
from patterns.geometry import DEFECT_TYPES, Mask, build, design_record

__all__ = ["LIBRARY", "LIBRARY_DIR", "MARGIN_UM", "UM_PER_PX", "build_library", "library_path"]

LIBRARY_DIR = Path(__file__).resolve().parent / "library"
UM_PER_PX = 1.0
MARGIN_UM = 10.0
RANDOM_SEED = 1


def _entries() -> list[tuple[str, str, dict[str, Any]]]:
    out: list[tuple[str, str, dict[str, Any]]] = [
        (f"four_pad_{size}_{gap}", "four-pad", {"size": size, "gap": gap})
        for size in (730, 710)
        for gap in (50, 100)
    ]
    out.append(("square_200", "square", {"size": 200}))
    for name, (position, h, w) in DEFECT_TYPES.items():
        for kind in ("inward", "outward"):
            out.append(
                (
                    f"defect_{name}_{kind}",
                    "defect",
                    {
                        "size": 200,
                        "kind": kind,
                        "position": position,
                        "edge": "right",
                        "height": h,
                        "width": w,
                    },
                )
            )
    for a in (1.7, 3.2, 5, 15):
        out.append(
            (
                f"constant_jagged_a{a:g}".replace(".", "p"),
                "constant-jagged",
                {"size": 200, "amplitude": a},
            )
        )
    for s in (2, 4, 8):
        out.append(
            (f"random_jagged_s{s}", "random-jagged", {"size": 200, "sigma": s, "seed": RANDOM_SEED})
        )
    return out


#: (file stem, design name, parameters in um) of every library pattern, in index order.
LIBRARY: tuple[tuple[str, str, dict[str, Any]], ...] = tuple(_entries())


def library_path(name: str) -> Path:
    """Path of the library PNG with file stem ``name`` (e.g. ``"defect_B_outward"``)."""
    names = [stem for stem, _, _ in LIBRARY]
    if name not in names:
        raise InputError(f"no library pattern {name!r}; choose one of {', '.join(names)}")
    path = LIBRARY_DIR / f"{name}.png"
    if not path.is_file():
        raise InputError(f"library pattern {path} is missing; rebuild it with `make library`")
    return path


def _title(stem: str, design: str, params: dict[str, Any]) -> str:
    if design == "four-pad":
        return f"four-pad L={params['size']:g}, g={params['gap']:g} um"
    if design == "defect":
        kind = stem.split("_")[1]
        return f"defect {kind} {params['kind']} ({params['position']}, h={params['height']:g}, w={params['width']:g})"
    if design == "constant-jagged":
        return f"constant jagged a={params['amplitude']:g} um"
    if design == "random-jagged":
        return f"random jagged sigma={params['sigma']:g} um (seed {params['seed']})"
    return f"{design} {params['size']:g} um"


def _write_overview(path: Path, items: list[tuple[str, str, dict[str, Any], Mask]]) -> None:
    """Contact sheet: one panel per pattern in the physical frame (um, y up); jagged ones with a corner zoom."""
    from matplotlib.figure import Figure  # lazy: plotting stays out of the geometry code

    cols = 6
    rows = -(-len(items) // cols)
    fig = Figure(figsize=(2.7 * cols, 2.9 * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat[len(items) :]:
        ax.set_axis_off()
    for ax, (stem, design, params, mask) in zip(axes.flat, items, strict=False):
        ax.imshow(
            mask.data,
            cmap="gray",
            vmin=0,
            vmax=1,
            extent=mask.extent_um,
            origin="upper",
            interpolation="nearest",
        )
        ax.set_title(_title(stem, design, params), fontsize=7.5)
        ax.tick_params(labelsize=6)
        ax.set_xlabel("x (um)", fontsize=6.5, labelpad=1)
        ax.set_ylabel("y (um)", fontsize=6.5, labelpad=1)
        ax.plot([0], [0], "+", color="tab:red", ms=6, mew=0.8)  # nominal centre = origin
        if design.endswith("jagged"):
            # Zoom on the top-right corner, drawn over the (plain white) middle of the pattern.
            zoom = ax.inset_axes((0.27, 0.27, 0.46, 0.46))
            zoom.imshow(
                mask.data,
                cmap="gray",
                vmin=0,
                vmax=1,
                extent=mask.extent_um,
                origin="upper",
                interpolation="nearest",
            )
            half = params["size"] / 2
            span = max(24.0, 5.0 * params.get("amplitude", 2 * params.get("sigma", 0)))
            zoom.set_xlim(half - 0.7 * span, half + 0.3 * span)
            zoom.set_ylim(half - 0.7 * span, half + 0.3 * span)
            zoom.set_title(f"{span:g} um corner zoom", fontsize=5.5, pad=1)
            zoom.set_xticks([])
            zoom.set_yticks([])
            for spine in zoom.spines.values():
                spine.set_edgecolor("tab:orange")
            ax.indicate_inset_zoom(zoom, edgecolor="tab:orange")
    fig.suptitle(
        f"selfalign pattern library ({UM_PER_PX:g} um/px; white = wettable; + = nominal centre)",
        fontsize=10,
    )
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png", dpi=80, metadata={"Software": None})


def build_library(out_dir: str | Path = LIBRARY_DIR, overview: bool = True) -> list[dict[str, Any]]:
    """Write every library PNG, ``index.json``, ``index.md`` and (optionally) ``overview.png``.

    Returns the index entries (file, design, parameters with units, scale, shape, areas).
    """
    from patterns._io import write_mask
    from patterns.geometry import mask_from_geometry

    out = Path(out_dir)
    if not out.is_dir():
        raise InputError(f"--out {out}: directory does not exist; create it first")
    index, items = [], []
    for stem, design, params in LIBRARY:
        geometry = build(design, **params)
        record = design_record(design, **params)
        record.update(margin_um=MARGIN_UM, area_um2=geometry.area)
        mask = mask_from_geometry(geometry, UM_PER_PX, margin_um=MARGIN_UM, params=record)
        write_mask(out / f"{stem}.png", mask)
        index.append(
            {
                "file": f"{stem}.png",
                "design": design,
                "parameters": record["parameters"],
                "um_per_px": UM_PER_PX,
                "margin_um": MARGIN_UM,
                "shape_px": list(mask.shape),
                "area_um2": geometry.area,
                "raster_area_um2": mask.area_um2,
            }
        )
        items.append((stem, design, params, mask))
    with atomic_output(out / "index.json") as tmp:
        tmp.write_text(json.dumps(index, indent=1) + "\n")
    with atomic_output(out / "index.md") as tmp:
        tmp.write_text(_index_markdown(index))
    if overview:
        _write_overview(out / "overview.png", items)
    return index


def _index_markdown(index: list[dict[str, Any]]) -> str:
    lines = [
        "# Pattern library",
        "",
        f"All files: 16-bit grey PNG, {UM_PER_PX:g} um/px (in the pHYs chunk), white = wettable, "
        f"{MARGIN_UM:g} um substrate margin, image centre = nominal pattern centre, y up.",
        "Rebuild with `make library` (`python -m patterns.library`). Contact sheet: `overview.png`.",
        "",
        "| file | design | parameters | image (px) | area (um^2) |",
        "|---|---|---|---|---|",
    ]
    for e in index:
        params = ", ".join(
            f"{k} {v['value']:g} {v['unit']}".rstrip()
            if isinstance(v["value"], int | float)
            else f"{k} {v['value']}"
            for k, v in e["parameters"].items()
        )
        h, w = e["shape_px"]
        lines.append(
            f"| `{e['file']}` | {e['design']} | {params} | {w} x {h} | {e['area_um2']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    assert __doc__ is not None  # for the type checker: the module has its docstring
    parser = argparse.ArgumentParser(
        prog="python -m patterns.library", description=__doc__.splitlines()[0]
    )
    parser.add_argument(
        "--out", default=str(LIBRARY_DIR), help=f"output directory (default {LIBRARY_DIR})"
    )
    parser.add_argument(
        "--no-overview", action="store_true", help="skip the matplotlib contact sheet"
    )
    args = parser.parse_args(argv)
    try:
        index = build_library(args.out, overview=not args.no_overview)
    except InputError as err:
        print(f"patterns.library: error: {err}", file=sys.stderr)
        return 2
    print(
        f"wrote {len(index)} patterns, index.json, index.md"
        + ("" if args.no_overview else ", overview.png")
        + f" to {args.out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
