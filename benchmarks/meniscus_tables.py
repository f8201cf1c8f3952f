"""Figures and tables of the finite meniscus for the README (a few minutes on 2 cores).

* the 730/50 um four-pad x-curve at 20 nl (h = 37.5 um) against the overlap model:
  ``docs/images/meniscus_fourpad_x.png``;
* the defect library's offsets: each 200 um pattern of ``patterns/library`` under a
  200 um chip with 0.9 nl of water (h = 22.5 um), pinned contact lines, at 1 um/px and
  0.25 degree twists within +-3 degrees: the refined global minimum (a markdown table
  on stdout).

Usage: ``python benchmarks/meniscus_tables.py [--skip-figure]``
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simulator import render  # noqa: E402
from simulator.landscape import build_landscape  # noqa: E402
from simulator.materials import Liquid  # noqa: E402
from simulator.refine import refine_minimum, stiffness  # noqa: E402
from simulator.scene import Effects, Scene, TwistGrid  # noqa: E402

LIB = ROOT / "patterns" / "library"
DEFECTS = ["square_200", "defect_A_inward", "defect_A_outward", "defect_B_inward", "defect_B_outward", "defect_C_inward",
           "defect_C_outward", "constant_jagged_a5", "random_jagged_s2", "random_jagged_s4", "random_jagged_s8"]


def figure(out: Path) -> None:
    base = Scene.from_inputs(LIB / "four_pad_730_50.png", chip_size_um=730, resolution_um=2.0, effects=Effects(twist=False),
                             liquid=Liquid(volume_nl=20.0))
    men = base.replace(effects=replace(base.effects, meniscus=True))
    a, b = build_landscape(base), build_landscape(men)
    render.plot_forces(b, out, through=(0.0, 0.0, 0.0), compare=a)
    k = stiffness(b, 0.0, 0.0, 0.0)
    print(f"four_pad_730_50, 730 um chip, 20 nl: h = {men.meniscus_height_um:.2f} um, stiffness x {k['x_N_per_m']:.3g} N/m; wrote {out}")


def table() -> None:
    print("| pattern | global minimum x (um) | y (um) | twist (deg) | stiffness x (N/m) | y (N/m) | twist (N m/rad) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name in DEFECTS:
        t0 = time.perf_counter()
        sc = Scene.from_inputs(LIB / f"{name}.png", chip_size_um=200, effects=Effects(meniscus=True),
                               liquid=Liquid(volume_nl=0.9, pinned=True), twist=TwistGrid(0.25, -3, 3), window_um=30, dtype="float64")
        ls = build_landscape(sc)
        r = refine_minimum(ls, *ls.global_minimum()[:3])
        k = stiffness(ls, r["x_um"], r["y_um"], r["twist_deg"])
        print(f"| {name} | {r['x_um']:+.1f} | {r['y_um']:+.1f} | {r['twist_deg']:+.2f} | {k['x_N_per_m']:.3g} | {k['y_N_per_m']:.3g} | "
              f"{k['twist_Nm_per_rad']:.3g} |", flush=True)
        print(f"  ({time.perf_counter() - t0:.1f} s)", file=sys.stderr)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--skip-figure", action="store_true")
    args = ap.parse_args(argv)
    if not args.skip_figure:
        figure(ROOT / "docs" / "images" / "meniscus_fourpad_x.png")
    table()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
