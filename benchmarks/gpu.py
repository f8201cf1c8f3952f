"""GPU benchmark: the JAX backend checked against SciPy, then timed, in one table.

Run on a machine whose JAX sees a GPU (``pip install -e '.[gpu]'``; ``benchmarks/gpu.sh``
prints the backend first). Four steps, meant to take under 5 minutes together:

1. **Check.** One landscape of the Monte Carlo benchmark's scene (the 730 um four-pad,
   gap 50 um, a 730 um chip at 2 um/px, twist step 1.5 degrees over the 90 degree period:
   ``benchmarks/montecarlo.py``'s ``make_scene``) built by ``build_landscape`` with the
   SciPy backend and with the JAX backend: the two must agree to ``1e-6`` of the chip's
   area (the largest |E_jax - E_scipy| over every pose, in units of the energy of a whole
   chip's overlap). The script exits with code 1 when they do not.
2. **The 512 px cube**: the full linear correlation of the landscape benchmark
   (``benchmarks/landscape.py``: a 512 x 512 px four-pad pattern, a square chip of side
   0.7 N) at 181 twists (-90..90 degrees, 1 degree apart), by ``correlate_stack`` on JAX
   and, for comparison, on SciPy.
3. **The 4096 px cube** at 4 degree steps (46 twists), JAX only; its error is measured
   against the float64 SciPy reference on 3 of its twists.
4. **10^6 greedy Monte Carlo starts** on the check's landscape (``run_batch``; uniform in
   x, y within 400 um and twist within 30 degrees, seed 0), in chunks of ``--chunk``.

The chips are ``cv2.warpAffine`` rasters by default (``--chips opencv``: no two alike, so
every twist is transformed and the rate is the transforms' own; ``--chips exact`` gives
the landscape benchmark's rasters, whose symmetries the engine uses to skip transforms).
Each timing is the best of ``--repeats`` calls after one that compiles.

The table's ``poses/s``: output pixels of all correlations per second (landscape poses for
the check, the cubes' (T, H + h - 1, W + w - 1) pixels), and for Monte Carlo the
trajectory steps of all starts per second (each step reads a pose's 26 neighbours).

``--cpu-smoke`` runs the same code on small sizes on the CPU in a few seconds (the test
suite runs it): a 10 um/px check scene, a 64 px cube at 19 twists, a 128 px cube at 10
twists and 2000 starts.

``--smoke OUT`` needs no GPU and runs nothing: it checks the arguments, imports the
hooks the steps use (``benchmarks/landscape.py``, ``benchmarks/montecarlo.py``), builds
the check's scene and writes the plan of the GPU run to OUT as JSON: each step with its
sizes and the bytes of its output, what JAX sees, and whether the run would start here
(``gpu_visible``). ``benchmarks/gpu.sh --smoke OUT`` does the same through the wrapper
(which runs from the repository root: give OUT, as ``--json OUT``, as an absolute path).

Usage::

    benchmarks/gpu.sh [--json OUT]
    python benchmarks/gpu.py [--cpu-smoke] [--chips opencv|exact] [--repeats 2] [--json OUT]
    python benchmarks/gpu.py --smoke PLAN.json    (no GPU needed: the plan only)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for p in (str(ROOT), str(HERE)):
    if p not in sys.path:
        sys.path.insert(0, p)

# The landscape and Monte Carlo benchmarks' inputs and hooks (benchmarks/landscape.py,
# benchmarks/montecarlo.py) are imported where used: --cpu-smoke picks JAX's platform first.

#: The check's limit: |E_jax - E_scipy| at most this fraction of a whole chip's overlap energy.
AGREE = 1e-6

#: Sizes: the check scene's pixel size (um), the cubes (N px, twists), Monte Carlo starts
#: and their chunk.
SIZES = {
    "gpu": {
        "um_per_px": 2.0,
        "cube": (512, 181),
        "large": (4096, 46),
        "starts": 1_000_000,
        "chunk": 65536,
    },
    "smoke": {
        "um_per_px": 10.0,
        "cube": (64, 19),
        "large": (128, 10),
        "starts": 2000,
        "chunk": 512,
    },
}

COLUMNS = ("step", "backend", "work", "seconds", "poses/s", "check")


def best_of(fn, repeats: int) -> tuple[float, object]:
    """(best seconds of ``repeats`` calls after a first, untimed one, last result)."""
    out = fn()
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def check_rows(um_per_px: float, repeats: int) -> tuple[list[dict], float, object]:
    """The landscape by SciPy and by JAX: a row each, the largest difference in chip areas."""
    from montecarlo import make_scene

    from simulator.core import UM2
    from simulator.landscape import build_landscape

    scene = make_scene(um_per_px)
    rows, built = [], {}
    for backend in ("scipy", "jax"):
        s, ls = best_of(lambda b=backend: build_landscape(scene, backend=b), repeats)
        built[backend] = ls
        t, ny, nx = ls.energy.shape
        rows.append(
            {
                "step": "landscape (check)",
                "backend": backend,
                "work": f"{t} twists x {ny} x {nx} poses",
                "seconds": s,
                "poses_per_s": ls.energy.size / s,
            }
        )
    whole_chip = (
        abs(scene.delta_gamma_N_m) * scene.chip.area_um2 * UM2
    )  # J of a whole chip's overlap
    diff = np.abs(
        built["jax"].energy.astype(np.float64) - built["scipy"].energy.astype(np.float64)
    ).max()
    err = float(diff / whole_chip)
    rows[-1]["check"] = (
        f"JAX - SciPy: {err:.2e} of the chip area at most ({'ok' if err <= AGREE else 'FAILED'}, limit {AGREE:g})"
    )
    return rows, err, (scene, built["jax"])


def cube_row(
    n: int, twists: int, backend: str, chips_kind: str, repeats: int, err_twists: int = 3
) -> dict:
    """The full linear correlation of the landscape benchmark's N px pattern with ``twists`` chips."""
    from landscape import make_chips, make_pattern, scipy_rfft2_f64, selfalign_method

    tw = np.linspace(-90.0, 90.0, twists)
    pattern = make_pattern(n)
    chips = make_chips(n, tw, chips_kind)
    s, out = best_of(lambda: selfalign_method(pattern, chips, backend=backend), repeats)
    idx = np.unique(np.linspace(0, twists - 1, min(err_twists, twists)).round().astype(int))
    ref = scipy_rfft2_f64(pattern, chips[idx])
    err = float(np.abs(out[idx].astype(np.float64) - ref).max() / chips[0].sum(dtype=np.float64))
    t, h, w = out.shape
    step = 180.0 / (twists - 1) if twists > 1 else 0.0
    return {
        "step": f"cube {n} px",
        "backend": backend,
        "work": f"{t} twists ({step:g} deg) x {h} x {w} poses",
        "seconds": s,
        "poses_per_s": out.size / s,
        "check": f"max error {err:.1e} of the chip area ({len(idx)} twists vs float64)",
    }


def montecarlo_row(scene, ls, n: int, chunk: int, repeats: int) -> dict:
    """``n`` greedy starts on the check's landscape: trajectory steps per second."""
    from simulator.batch import random_starts, run_batch

    starts = random_starts(n, (400, 400, 30), seed=0, distribution="uniform")
    chunk = min(chunk, n)
    run_batch(
        scene, starts[:chunk], "greedy", landscape=ls, chunk=chunk, progress=False
    )  # compiles
    s, r = best_of(
        lambda: run_batch(scene, starts, "greedy", landscape=ls, chunk=chunk, progress=False),
        max(0, repeats - 1),
    )
    run_s = r.stats["run_s"]
    return {
        "step": "Monte Carlo greedy",
        "backend": "jax",
        "work": f"{n:,} starts, {int(r.steps.sum()):,} steps (chunk {chunk:,})",
        "seconds": run_s,
        "poses_per_s": float(r.steps.sum()) / run_s,
        "check": f"{n / run_s:,.0f} starts/s, yield {float(np.mean(r.outcome == 0)):.3f}",
    }


def table(rows: list[dict]) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|---|---|---|---:|---:|---|"]
    for r in rows:
        lines.append(
            f"| {r['step']} | {r['backend']} | {r['work']} | {r['seconds']:.3g} | {r['poses_per_s']:,.0f} | {r.get('check', '')} |"
        )
    return "\n".join(lines)


def machine() -> dict:
    import jax

    return {
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jax_backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        "cpus": os.cpu_count(),
    }


def plan(size: dict, chunk: int, args: argparse.Namespace) -> dict:
    """The GPU run's steps and sizes, without running them: the check's scene is built (its
    landscape's shape and bytes from the pose grid's size), the cubes' and the batch's outputs
    counted (float32 cubes, as correlate_stack returns them)."""
    from landscape import make_pattern  # the hooks the steps import, checked here
    from montecarlo import make_scene

    scene = make_scene(size["um_per_px"])
    t, (ny, nx) = scene.twist_axis.count, scene.pattern.shape
    steps = [
        {
            "step": "landscape (check)",
            "backends": ["scipy", "jax"],
            "scene_px": [nx, ny],
            "twists": t,
            "um_per_px": size["um_per_px"],
        }
    ]
    for key, backends in (("cube", ["jax", "scipy"]), ("large", ["jax"])):
        n, twists = size[key]
        h, w = make_pattern(8).shape  # the pattern hook runs (its N x N image)
        assert (h, w) == (8, 8)
        out = (twists, 2 * n - 1, 2 * n - 1)
        steps.append(
            {
                "step": f"cube {n} px",
                "backends": backends,
                "output_shape": list(out),
                "output_MB": math.prod(out) * 4 / 2**20,
            }
        )
    steps.append(
        {
            "step": "Monte Carlo greedy",
            "backends": ["jax"],
            "starts": size["starts"],
            "chunk": min(chunk, size["starts"]),
        }
    )
    return {"steps": steps, "chips": args.chips, "repeats": args.repeats}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--cpu-smoke",
        action="store_true",
        help="the same steps on small sizes, on the CPU (a few seconds)",
    )
    ap.add_argument(
        "--chips",
        choices=("opencv", "exact"),
        default="opencv",
        help="chip rasters: warpAffine, no two alike (default), or exact, whose symmetries skip transforms",
    )
    ap.add_argument(
        "--repeats",
        type=int,
        default=2,
        help="timed calls per step after a compiling one; the best is reported",
    )
    ap.add_argument(
        "--chunk",
        type=int,
        default=None,
        help="Monte Carlo starts per compiled batch (default 65536; smoke 512)",
    )
    ap.add_argument(
        "--json", type=Path, default=None, metavar="OUT", help="also write the rows as JSON"
    )
    ap.add_argument(
        "--smoke",
        type=Path,
        default=None,
        metavar="OUT",
        help="no GPU needed, nothing run: check the arguments and the hooks, write the plan of the GPU run to OUT (JSON)",
    )
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error("--repeats must be >= 1")
    if args.smoke is not None:
        from _smoke import smoke_out

        smoke_out(ap, args.smoke)
        if args.cpu_smoke:
            ap.error("--smoke writes the plan only; --cpu-smoke runs the steps: give one")
        import jax

        import simulator  # noqa: F401

        doc = {"machine": machine(), "gpu_visible": jax.default_backend() == "gpu"}
        doc |= plan(SIZES["gpu"], args.chunk or SIZES["gpu"]["chunk"], args)
        args.smoke.write_text(json.dumps(doc, indent=2) + "\n")
        for st in doc["steps"]:
            print(f"{st['step']}: {', '.join(st['backends'])}")
        print(
            f"wrote the plan to {args.smoke}; JAX backend {doc['machine']['jax_backend']}"
            f"{'' if doc['gpu_visible'] else ' (no GPU visible: the run itself would refuse here)'}"
        )
        return 0
    if args.cpu_smoke:
        os.environ["JAX_PLATFORMS"] = "cpu"
    import jax

    import simulator  # noqa: F401  (JAX's x64 mode, as the engine runs)

    info = machine()
    if not args.cpu_smoke and jax.default_backend() != "gpu":
        print(
            f"no GPU visible to JAX (jax {jax.__version__}, backend {jax.default_backend()}): install the CUDA build "
            "with pip install -e '.[gpu]', or run --cpu-smoke",
            file=sys.stderr,
        )
        return 2
    size = SIZES["smoke" if args.cpu_smoke else "gpu"]
    chunk = args.chunk or size["chunk"]
    t_all = time.perf_counter()

    def say(text: str) -> None:
        print(f"[{time.perf_counter() - t_all:6.1f} s] {text}", file=sys.stderr, flush=True)

    say("check: the landscape by SciPy and by JAX")
    rows, err, (scene, ls) = check_rows(size["um_per_px"], args.repeats)
    n, t = size["cube"]
    for backend in ("jax", "scipy"):
        say(f"cube {n} px x {t} twists, {backend}")
        rows.append(cube_row(n, t, backend, args.chips, args.repeats))
    n, t = size["large"]
    say(f"cube {n} px x {t} twists, jax")
    rows.append(cube_row(n, t, "jax", args.chips, args.repeats))
    say(f"Monte Carlo: {size['starts']:,} greedy starts")
    rows.append(montecarlo_row(scene, ls, size["starts"], chunk, args.repeats))
    total = time.perf_counter() - t_all

    devices = ", ".join(info["devices"])
    print(
        f"GPU benchmark{' (CPU smoke run)' if args.cpu_smoke else ''}: jax {info['jax']} on {info['jax_backend']} ({devices}), "
        f"{info['cpus']} CPUs, {args.chips} chip rasters, best of {args.repeats}\n"
    )
    print(table(rows))
    ok = err <= AGREE
    print(
        f"\nJAX against SciPy: {'agree' if ok else 'DISAGREE'} to {err:.2e} of the chip area (limit {AGREE:g}); "
        f"total {total:.0f} s{'' if args.cpu_smoke else ' (target < 300 s)'}"
    )
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "machine": info,
                    "args": {k: str(v) for k, v in vars(args).items()},
                    "rows": rows,
                    "agree": err,
                    "total_s": total,
                },
                indent=2,
            )
            + "\n"
        )
        print(f"wrote {args.json}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
