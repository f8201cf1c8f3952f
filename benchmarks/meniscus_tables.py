"""Figures and tables of the finite meniscus for docs/guide/meniscus.md (a few minutes on 2 cores).

* the 730/50 um four-pad x-curve at 20 nl (h = 37.5 um) against the overlap model:
  ``docs/images/meniscus_fourpad_x.png``;
* the 730/50 and 730/100 um four-pads at 20 nl against Surface Evolver with free contact
  lines (outward from alignment: ``validation/evolver_fourpad_levels.csv``, levels 2 and 3;
  inward from x = 500 um: ``validation/evolver_fourpad_inward.csv``, level 1): force along x
  of the overlap model, the meniscus model and the Evolver points,
  ``docs/images/meniscus_fourpad_evolver.png``;
  the table of the three on stdout;
* the defect library's offsets: each 200 um pattern of ``patterns/library`` under a
  200 um chip with 0.9 nl of water (h = 22.5 um), pinned contact lines, at 1 um/px and
  0.25 degree twists within +-3 degrees: the refined global minimum (a markdown table
  on stdout).

Usage: ``python benchmarks/meniscus_tables.py [--skip-figure] [--evolver-only] [--smoke OUT]``

``--smoke OUT``: the Evolver comparison at 10 um/px every 50 um, the first two defect
patterns at 5 um/px and 1 degree twists, no x-curve figure; the tables go to OUT and the
figure beside it (OUT with .png), nothing into docs/images.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from _smoke import add_smoke_arg, smoke_out, tee_stdout  # noqa: E402

from simulator.landscape import (  # noqa: E402
    build_footprint_planes,
    build_landscape,
    refine_minimum,
    stiffness,
)
from simulator.physics import Liquid  # noqa: E402
from simulator.render import (
    CHIP_COLOUR,
    PATH_COLOUR,
    PLATEAU_COLOUR,
    plot_forces,
    pyplot,
    save_figure,
)
from simulator.scene import Effects, Scene, TwistGrid  # noqa: E402

LIB = ROOT / "patterns" / "library"
DEFECTS = [
    "square_200",
    "defect_A_inward",
    "defect_A_outward",
    "defect_B_inward",
    "defect_B_outward",
    "defect_C_inward",
    "defect_C_outward",
    "constant_jagged_a5",
    "random_jagged_s2",
    "random_jagged_s4",
    "random_jagged_s8",
]


def figure(out: Path) -> None:
    base = Scene.from_inputs(
        LIB / "four_pad_730_50.png",
        chip_size_um=730,
        resolution_um=2.0,
        effects=Effects(twist=False),
        liquid=Liquid(volume_nl=20.0),
    )
    men = base.replace(effects=replace(base.effects, meniscus=True))
    a, b = build_landscape(base), build_landscape(men)
    plot_forces(b, out, through=(0.0, 0.0, 0.0), compare=a)
    k = stiffness(b, 0.0, 0.0, 0.0)
    print(
        f"four_pad_730_50, 730 um chip, 20 nl: h = {men.meniscus_height_um:.2f} um, stiffness x {k['x_N_per_m']:.3g} N/m; wrote {out}"
    )


def evolver_paths(level: str = "2") -> dict[int, list[dict]]:
    """The stored Surface Evolver x paths of the 730 um four-pads at one refinement level, by gap (um)."""
    import csv

    rows: dict[int, list[dict]] = {}
    with open(ROOT / "validation" / "evolver_fourpad_levels.csv", newline="") as f:
        for r in csv.DictReader(f):
            if (
                r["path"] in ("x_730_50", "x_730_100")
                and r["level"] == level
                and float(r["y_um"]) == 0.0
            ):
                rows.setdefault(int(float(r["g_um"])), []).append(r)
    return rows


def evolver_inward(level: str = "1") -> dict[int, list[dict]]:
    """The stored Surface Evolver inward continuations (x = 500 -> 0 um) by gap (um)."""
    import csv

    rows: dict[int, list[dict]] = {}
    with open(ROOT / "validation" / "evolver_fourpad_inward.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["path"] in ("x_730_50_inward", "x_730_100_inward") and r["level"] == level:
                rows.setdefault(int(float(r["g_um"])), []).append(r)
    return rows


def evolver_figure(out: Path, um_per_px: float = 2.0, x_step_um: float = 2.0) -> None:
    """Force along x on the 730/50 and 730/100 four-pads with 20 nl: overlap model,
    meniscus model (h = V / A) and Surface Evolver (free contact lines, 30/60 degrees)."""
    import numpy as np

    plt = pyplot()
    paths, finer, inward = evolver_paths("2"), evolver_paths("3"), evolver_inward("1")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), layout="constrained", sharey=True)
    print(
        "| gap (um) | x (um) | Surface Evolver inward, level 1 (uN) | Surface Evolver outward, level 2 (uN) | meniscus model (uN) "
        "| `chip`, inward (uN) | `pattern`, outward (uN) | overlap model (uN) |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for ax, gap in zip(axes, (50, 100), strict=True):
        base = Scene.from_inputs(
            LIB / f"four_pad_730_{gap}.png",
            chip_size_um=730,
            resolution_um=um_per_px,
            effects=Effects(twist=False),
            liquid=Liquid(volume_nl=20.0),
            window_um=520,
            dtype="float64",
        )
        men = base.replace(effects=replace(base.effects, meniscus=True))
        over, mls = build_landscape(base), build_landscape(men)
        xs = np.arange(0.0, 510.0, x_step_um)
        f_over = np.array([float(over.force_at(x, 0.0, 0.0)[0]) for x in xs]) * 1e6
        f_men = np.array([float(mls.force_at(x, 0.0, 0.0)[0]) for x in xs]) * 1e6
        # the footprint state (docs/physics.md §3.5), carried pose by pose along each path:
        # `pattern` outward from alignment (every pad wet), `chip` inward from 500 um (none)
        fp = build_footprint_planes(men.replace(liquid=replace(men.liquid, dispense="chip")))
        branch = {}
        for name, order, wet in (
            ("pattern", xs, np.ones(fp.n_pads, bool)),
            ("chip", xs[::-1], np.zeros(fp.n_pads, bool)),
        ):
            f = {}
            for x in order:
                wet = fp.next_state(wet, (x, 0.0, 0.0))
                f[float(x)] = -float(fp.landscape(wet).force_at(x, 0.0, 0.0)[0]) * 1e6
            branch[name] = f
        ax.plot(
            xs,
            [branch["pattern"][float(x)] for x in xs],
            color="tab:green",
            lw=1.2,
            label="footprint state, dispense pattern, outward",
        )
        ax.plot(
            xs,
            [branch["chip"][float(x)] for x in xs],
            ":",
            color="black",
            lw=1.4,
            label="footprint state, dispense chip, inward",
        )
        se = sorted(paths.get(gap, []), key=lambda r: float(r["x_um"]))
        sx = np.array([float(r["x_um"]) for r in se])
        sf = np.array([float(r["force_x_N"]) for r in se]) * 1e6
        ax.plot(xs, -f_over, "--", color="0.45", label="overlap model")
        ax.plot(
            xs,
            -f_men,
            color=PATH_COLOUR,
            label=f"meniscus model (h = {men.meniscus_height_um:.1f} um)",
        )
        ax.plot(
            sx,
            -sf,
            "o",
            ms=4,
            color=CHIP_COLOUR,
            label="Surface Evolver, outward from alignment (level 2)",
        )
        f3 = sorted(finer.get(gap, []), key=lambda r: float(r["x_um"]))
        ax.plot(
            [float(r["x_um"]) for r in f3],
            [-float(r["force_x_fd_N"]) * 1e6 for r in f3],
            "o",
            ms=7,
            mfc="none",
            color=CHIP_COLOUR,
            label="Surface Evolver, outward (level 3)",
        )
        inw = {
            float(r["x_um"]): -float(r["force_x_N"]) * 1e6
            for r in inward.get(gap, [])
            if float(r["x_um"]) > 1
        }
        ax.plot(
            list(inw),
            list(inw.values()),
            "^",
            ms=5,
            color="black",
            label="Surface Evolver, inward from x = 500 um (level 1; x = 0 not relaxed, left out)",
        )
        p = (730 - gap) / 2
        ax.axvspan(
            p, p + gap, color=PLATEAU_COLOUR, alpha=0.25, lw=0, label="overlap model's flat part"
        )
        ax.set_title(
            f"four-pad 730/{gap} um, 730 um chip, 20 nl, pads 30 deg, substrate 60 deg", fontsize=9
        )
        ax.set_xlabel("x (um)")
        ax.grid(alpha=0.3)
        out_f = {float(r["x_um"]): -float(r["force_x_N"]) * 1e6 for r in se}
        for x in sorted(set(out_f) | set(inw)):
            i, o = (f"{d[x]:.2f}" if x in d else "" for d in (inw, out_f))
            ci, po = (f"{branch[k][x]:.2f}" if x in branch[k] else "" for k in ("chip", "pattern"))
            print(
                f"| {gap} | {x:g} | {i} | {o} | {-float(mls.force_at(x, 0.0, 0.0)[0]) * 1e6:.2f} | "
                f"{ci} | {po} | {-float(over.force_at(x, 0.0, 0.0)[0]) * 1e6:.2f} |"
            )
    axes[0].set_ylabel("restoring force -F_x (uN)")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncol=3, fontsize=8)
    save_figure(fig, out)
    print(f"wrote {out}", file=sys.stderr)


def evolver_defects(volume_nl: float = 0.9) -> dict[str, tuple[float, float, float]]:
    """Surface Evolver's equilibrium pose (x um, y um, twist deg) per library defect pattern."""
    import csv

    out = {}
    with open(ROOT / "validation" / "evolver_defects.csv", newline="") as f:
        for r in csv.DictReader(f):
            if float(r["volume_nl"]) == volume_nl:
                name = (
                    "square_200" if r["defect"] == "none" else f"defect_{r['defect']}_{r['kind']}"
                )
                out[name] = (float(r["x_um"]), float(r["y_um"]), float(r["twist_deg"]))
    return out


def table(
    names: list[str] = DEFECTS, um_per_px: float | None = None, step_deg: float = 0.25
) -> None:
    se = evolver_defects(0.9)
    print(
        "| pattern | global minimum x (um) | y (um) | twist (deg) | Surface Evolver x, y (um), twist (deg) | stiffness x (N/m) | y (N/m) | twist (N m/rad) |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in names:
        t0 = time.perf_counter()
        sc = Scene.from_inputs(
            LIB / f"{name}.png",
            chip_size_um=200,
            effects=Effects(meniscus=True),
            liquid=Liquid(volume_nl=0.9, pinned=True),
            twist=TwistGrid(step_deg, -3, 3),
            window_um=30,
            resolution_um=um_per_px,
            dtype="float64",
        )
        ls = build_landscape(sc)
        r = refine_minimum(ls, *ls.global_minimum()[:3])
        k = stiffness(ls, r["x_um"], r["y_um"], r["twist_deg"])
        ref = ", ".join(f"{v:+.2f}" for v in se[name]) if name in se else "—"
        print(
            f"| {name} | {r['x_um']:+.2f} | {r['y_um']:+.2f} | {r['twist_deg']:+.2f} | {ref} | {k['x_N_per_m']:.3g} | {k['y_N_per_m']:.3g} | "
            f"{k['twist_Nm_per_rad']:.3g} |",
            flush=True,
        )
        print(f"  ({time.perf_counter() - t0:.1f} s)", file=sys.stderr)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--skip-figure", action="store_true")
    ap.add_argument(
        "--evolver-only",
        action="store_true",
        help="only the four-pad figure and table against Surface Evolver",
    )
    add_smoke_arg(ap, "the tables (and the Evolver figure beside them)")
    args = ap.parse_args(argv)
    smoke = smoke_out(ap, args.smoke)
    if smoke:
        with tee_stdout(smoke):
            evolver_figure(smoke.with_suffix(".png"), um_per_px=10.0, x_step_um=50.0)
            table(DEFECTS[:2], um_per_px=5.0, step_deg=1.0)
        print(f"wrote {smoke} and {smoke.with_suffix('.png')} (smoke run)")
        return 0
    evolver_figure(ROOT / "docs" / "images" / "meniscus_fourpad_evolver.png")
    if args.evolver_only:
        return 0
    if not args.skip_figure:
        figure(ROOT / "docs" / "images" / "meniscus_fourpad_x.png")
    table()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
