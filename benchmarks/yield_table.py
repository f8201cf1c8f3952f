"""The yield table of docs/guide/montecarlo.md: yield against the nominal placement bias, one column per model.

The 730/50 and 730/100 um four-pads under a 730 um chip, 20 nl of water (h = 37.5 um),
4 um/px and 2 degree twist steps; at each nominal bias, ``--starts`` placements with
normal noise of 10 um in x and y and 2 degrees in twist (seed 0, the same draws for every
column). Columns: the overlap model with greedy steps, the finite meniscus (free contact
lines, stateless: ``--dispense none``) with gradient steps, and the same with overdamped
dynamics, without and with the pad's contact-angle hysteresis (receding 25, advancing 35 degrees around the 30
degree pad); then the footprint as each start's state (``--dispense``, docs/physics.md
§3.5): the liquid coming in under the chip (``chip``), the droplet dispensed on the pattern
first (``pattern``), and ``pattern`` with the hysteresis. Each column's landscape (or the
pads' planes) is built once and every bias runs on it; the time
of a column is its landscape plus its batches (compilation included, once per column).

Usage: ``python benchmarks/yield_table.py [--starts N] [--resolution UM] [--smoke OUT]``

``--smoke OUT``: the 730/50 um four-pad only, at 20 um/px and 15 degree twists, 8
placements at the first two biases, and two columns: the overlap model with greedy steps
and the meniscus with gradient steps (each further column compiles its method again: an
overdamped column nearly doubles the smoke run's CPU time; overdamped batches run in
tests/test_montecarlo_dynamics.py). The table goes to OUT.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _smoke import add_smoke_arg, smoke_out, tee_stdout  # noqa: E402

from simulator.batch import (  # noqa: E402
    random_starts,
    run_batch,
    summarize,
)
from simulator.landscape import build_footprint_planes, build_landscape  # noqa: E402
from simulator.physics import Liquid, Materials  # noqa: E402
from simulator.scene import Effects, Scene, TwistGrid  # noqa: E402

BIASES = [
    (50, 0),
    (100, 0),
    (300, 0),
    (400, 0),
    (500, 0),
    (600, 0),
    (50, 50),
    (100, 100),
    (200, -200),
    (300, -300),
]
COLUMNS = [
    ("overlap, greedy", dict(meniscus=False, hysteresis=False), "greedy"),
    ("meniscus, gradient", dict(meniscus=True, hysteresis=False), "gradient"),
    ("meniscus, overdamped", dict(meniscus=True, hysteresis=False), "overdamped"),
    ("meniscus, overdamped, hysteresis 25/35", dict(meniscus=True, hysteresis=True), "overdamped"),
    # the footprint as each start's state (docs/physics.md §3.5): where the liquid was
    (
        "dispense chip, overdamped",
        dict(meniscus=True, hysteresis=False, dispense="chip"),
        "overdamped",
    ),
    (
        "dispense pattern, overdamped",
        dict(meniscus=True, hysteresis=False, dispense="pattern"),
        "overdamped",
    ),
    (
        "dispense pattern, overdamped, hysteresis 25/35",
        dict(meniscus=True, hysteresis=True, dispense="pattern"),
        "overdamped",
    ),
]


def scene(
    gap: int,
    meniscus: bool,
    hysteresis: bool,
    resolution: float,
    twist_step_deg: float = 2.0,
    dispense: str = "none",
) -> Scene:
    mat = Materials(pad_receding_deg=25.0, pad_advancing_deg=35.0) if hysteresis else Materials()
    return Scene.from_inputs(
        ROOT / "patterns" / "library" / f"four_pad_730_{gap}.png",
        chip_size_um=730,
        resolution_um=resolution,
        effects=Effects(meniscus=meniscus, hysteresis=hysteresis),
        liquid=Liquid(volume_nl=20.0, dispense=dispense),
        materials=mat,
        twist=TwistGrid(twist_step_deg, -45.0, 45.0),
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--starts", type=int, default=200, help="placements per bias (default 200)")
    ap.add_argument("--resolution", type=float, default=4.0, help="um per pixel (default 4)")
    add_smoke_arg(ap)
    args = ap.parse_args(argv)
    smoke = smoke_out(ap, args.smoke)
    with tee_stdout(smoke):
        _main(args, bool(smoke))
    return 0


def _main(args: argparse.Namespace, smoke: bool) -> None:
    gaps, biases, columns, step = (50, 100), BIASES, COLUMNS, 2.0
    if smoke:
        gaps, biases, columns, step = (50,), BIASES[:2], COLUMNS[:2], 15.0
        args.starts, args.resolution = 8, 20.0
    for gap in gaps:
        yields: dict[str, list[float]] = {}
        seconds: dict[str, float] = {}
        for name, eff, method in columns:
            t0 = time.perf_counter()
            sc = scene(
                gap,
                eff["meniscus"],
                eff["hysteresis"],
                args.resolution,
                step,
                eff.get("dispense", "none"),
            )
            # the stateless landscape, or the pads' planes of the footprint state (built once)
            built = (
                {"planes": build_footprint_planes(sc)}
                if eff.get("dispense")
                else {"landscape": build_landscape(sc)}
            )
            ys = []
            for bx, by in biases:
                starts = random_starts(
                    args.starts, (10.0, 10.0, 2.0), seed=0, around=(float(bx), float(by), 0.0)
                )
                res = run_batch(sc, starts, method, progress=False, **built)
                ys.append(summarize(res)["yield"])
            seconds[name] = time.perf_counter() - t0
            yields[name] = ys
            print(f"  730/{gap} {name}: {seconds[name]:.1f} s", file=sys.stderr, flush=True)
        print(
            f"\n730/{gap} um four-pad, 20 nl, {args.starts} placements per bias (sigma 10 um, 10 um, 2 deg), {args.resolution:g} um/px, {step:g} deg twists\n"
        )
        print("| nominal bias (um) | " + " | ".join(n for n, _, _ in columns) + " |")
        print("|---|" + "---:|" * len(columns))
        for i, (bx, by) in enumerate(biases):
            print(
                f"| ({bx}, {by}) | "
                + " | ".join(f"{100 * yields[n][i]:.1f} %" for n, _, _ in columns)
                + " |"
            )
        print(
            "| time (s) | " + " | ".join(f"{seconds[n]:.0f}" for n, _, _ in columns) + " |",
            flush=True,
        )


if __name__ == "__main__":
    raise SystemExit(main())
