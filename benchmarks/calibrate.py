"""How long ``selfalign calibrate`` takes with its defaults: a 10-row bench table, two parameters.

The bench is examples/calibrate_trials.csv (made by the model itself,
examples/make_calibrate_trials.py: receding angle 20 deg, pad angle 30 deg, gradient steps),
fitted on examples/calibrate_fourpad.toml (730/100 um four-pad, 20 um/px, 5 degree twists,
overlap model with hysteresis) for ``receding_angle_deg`` and ``pad_angle_deg`` with the
defaults (40 trials, 32 draws per row, 6 profile points per parameter) and gradient steps, as
the example's command gives them, in this process (the JAX import and compilation included). The table: wall time, seconds per evaluated point, the fitted values
and their ranges against the truth. On this table the two angles trade along a valley (the
yields depend on the pinning against the drive, not on the two apart): both ranges hold the
truth and the pad angle's is flagged not identified (docs/guide/calibrate.md).

Usage: ``python benchmarks/calibrate.py [--smoke OUT]``

``--smoke OUT``: the first three rows, 3 trials, 8 draws; the table goes to OUT.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _smoke import add_smoke_arg, smoke_out, tee_stdout  # noqa: E402

TRUTH = {"receding_angle_deg": 20.0, "pad_angle_deg": 30.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_smoke_arg(ap)
    args = ap.parse_args()
    smoke = smoke_out(ap, args.smoke)
    t0 = time.perf_counter()
    from simulator.design import calibrate, read_trials

    table = ROOT / "examples" / "calibrate_trials.csv"
    scene = ROOT / "examples" / "calibrate_fourpad.toml"
    with tempfile.TemporaryDirectory() as d:
        if smoke:
            lines = table.read_text().splitlines()
            table = Path(d) / "bench.csv"
            table.write_text("\n".join(lines[:4]) + "\n")
        kw = dict(trials=3, draws=8) if smoke else {}
        fit = calibrate(
            read_trials(table), scene, list(TRUTH), Path(d) / "fit", method="gradient", **kw
        )
    wall = time.perf_counter() - t0
    with tee_stdout(smoke):
        print(
            f"calibrate: {len(fit['rows'])} rows, {fit['trials']} trials, {fit['draws']} draws per row, "
            f"{fit['method']}, fitting {', '.join(fit['fit'])}"
        )
        print()
        points = fit["trials"] + 1 + fit["profiled"]
        print("| wall time (s) | fit (s) | points (trials, profile) | s per point |")
        print("|---:|---:|---:|---:|")
        print(
            f"| {wall:.1f} | {fit['run_s']:.1f} | {points} ({fit['trials'] + 1}, {fit['profiled']}) "
            f"| {fit['run_s'] / points:.2f} |"
        )
        print()
        print("| parameter | truth | best | range (Delta log L <= 0.5, outer) | identified |")
        print("|---|---:|---:|---|---|")
        for k, v in fit["best"].items():
            r = fit["range"][k]
            print(
                f"| {k} | {TRUTH[k]:g} | {v:.3g} | {r['lo']:.3g} .. {r['hi']:.3g} "
                f"| {'yes' if r['identified'] else 'no'} |"
            )


if __name__ == "__main__":
    main()
