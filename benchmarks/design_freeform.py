"""Time per gradient iteration of ``selfalign design`` in free-form mode, at 256 and 512 px.

The problem is the worked example's (``examples/design_freeform_rfid.toml``: the 400 um
RFID-like chip with its index mark, the wall-profile meniscus, the four contact pads kept,
the capture, orientation (90, 180, 270 degrees) and gap terms, two edge-perturbation
samples per iteration, float32) on a square design canvas of N px: the canvas stays
720 um and its pixels shrink (2.81 um at 256 px, 1.41 um at 512 px), the minimum feature,
the perturbations and the chip keeping their sizes in um. One iteration: the pattern from
the design variables (filter, two perturbations, projection), four twist planes per sample
by FFT correlation, the objective, its gradient by reverse mode, the Adam update, in one
jit-compiled step (:func:`simulator.design.freeform`, which reports the mean time of the
iterations after the first and the first's compilation apart).

The sizes alternate ``--repeat`` times (256, 512, 256, 512, ...: the machine may be shared)
and the best run of each is reported, with every run's time and the load average. Writes
``benchmarks/results/design_freeform.json``.

Usage: ``.venv/bin/python benchmarks/design_freeform.py [--sizes 256 512] [--iterations 20] [--repeat 2]``.
``--smoke OUT``: one 80 px canvas (9 um pixels, the smallest the minimum feature allows), one timed iteration, once; the JSON goes to OUT only.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from _smoke import add_smoke_arg, smoke_out  # noqa: E402

EXAMPLE = ROOT / "examples" / "design_freeform_rfid.toml"
CANVAS_UM = 720.0


def one_size(n: int, iterations: int) -> dict:
    from simulator.design import freeform, load_freeform, price_freeform
    from simulator.sweep import read_toml_file

    doc = read_toml_file(EXAMPLE, "design file")
    s = CANVAS_UM / n
    doc["freeform"]["um_per_px"] = s
    spec = load_freeform(doc, base=EXAMPLE.parent, source=f"{EXAMPLE.name} at {n} px")
    t0 = time.perf_counter()
    r = freeform(spec, iterations=iterations + 1, verify=False)
    return {
        "N": n,
        "um_per_px": s,
        "twists": len(spec.twists_deg()),
        "samples": spec.perturbation["samples"],
        "iterations": iterations,
        "seconds_per_iteration": r.seconds_per_iteration,
        "compile_s": r.compile_seconds,
        "total_s": time.perf_counter() - t0,
        "priced_MB": price_freeform(spec) / 2**20,
        "load_average": os.getloadavg()[0],
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[256, 512])
    ap.add_argument("--iterations", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "design_freeform.json"))
    add_smoke_arg(ap, "the JSON")
    a = ap.parse_args(argv)
    if smoke_out(ap, a.smoke):
        a.sizes, a.iterations, a.repeat, a.json = [80], 1, 1, str(a.smoke)
    import jax
    import numpy as np

    runs = []
    for _ in range(a.repeat):
        for n in a.sizes:
            r = one_size(n, a.iterations)
            print(
                f"N = {n} px ({r['um_per_px']:.3g} um/px, {r['twists']} twists x {r['samples']} samples): "
                f"{r['seconds_per_iteration'] * 1e3:.0f} ms per iteration (compile {r['compile_s']:.1f} s; "
                f"load {r['load_average']:.2f})",
                flush=True,
            )
            runs.append(r)
    rows = []
    for n in a.sizes:
        mine = [r for r in runs if r["N"] == n]
        best = min(mine, key=lambda r: r["seconds_per_iteration"])
        rows.append(
            best | {"seconds_per_iteration_all": [r["seconds_per_iteration"] for r in mine]}
        )
    doc = {
        "example": str(EXAMPLE.relative_to(ROOT)),
        "canvas_um": CANVAS_UM,
        "rows": rows,
        "machine": {
            "cpus": os.cpu_count(),
            "processor": platform.processor() or platform.machine(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "jax": jax.__version__,
            "backend": jax.default_backend(),
        },
    }
    Path(a.json).write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {a.json}")


if __name__ == "__main__":
    main()
