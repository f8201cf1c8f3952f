"""Trajectory figures and costs for docs/guide/trajectories.md (not a test).

1. ``docs/methods.png``: one trajectory of each method (greedy, gradient, overdamped,
   inertial) on the 730/50 um four-pad, chip path over the pattern and energy curve.
2. The cost of one greedy run that builds only what it needs, against the full
   landscape (GitHub issue 4 item 6): 730 um four-pad, 1 um/px, start (300, 200, 10 deg).

3. A single run on a large image, both engines (GitHub issue 28): the 4000 um four-pad
   (gap 200 um) at 1 um/px under a 4000 um chip from (1200, -800, 10 deg), greedy and
   gradient, each in a fresh process (its own peak RSS): the FFT boxes against the
   path-cost engine (small boxes that follow the chip, pose by pose).

4. Meniscus runs against overlap runs of the same scene (GitHub issue 28 item 2): the
   730/50 um four-pad at 1 um/px (730 um chip, 20 nl, from (300, 200 um, 10 deg)) and the
   4000 um four-pad (gap 200 um) at 1 um/px (4000 um chip, 500 nl, from (1200, -800 um,
   10 deg)), greedy and gradient, engine "auto"; the overlap run and the meniscus run
   alternated, each in a fresh process (the simulate call's wall time, the whole process's,
   and its peak RSS), best of the repeats and every value; the ratio meniscus / overlap.
   Written to ``benchmarks/results/trajectories.json``.

Usage: ``python benchmarks/trajectories.py [--out docs] [--only-4k] [--engines fft,path]``;
``python benchmarks/trajectories.py --meniscus [--repeats 3] [--scenes 730,4k]
[--methods greedy,gradient]`` (item 4 alone: prints its table).

``--smoke OUT``: every item small and once: item 1 greedy at 20 um/px (the other methods'
code runs in tests/test_montecarlo.py and in the smoke run of
``benchmarks/dynamics_calibration.py``), item 2 at 20 um/px (item 1's scene: its compiled
stepper is reused), item 3 greedy on a 200 um four-pad (gap 20 um) by both engines, item 4
the 730 um scene at 20 um/px, greedy, once (11 s of CPU in all, 16 s before);
items 3 and 4 run their scripts in this process (not a fresh one each: their peak RSS is
then this process's). The tables go to OUT, the figure and the JSON beside it (OUT with
.png and .json), nothing into docs/ or benchmarks/results/.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _smoke import add_smoke_arg, smoke_out, tee_stdout  # noqa: E402

from patterns.library import library_path  # noqa: E402
from simulator import pyplot, save_figure  # noqa: E402
from simulator.landscape import build_landscape  # noqa: E402
from simulator.motion import simulate  # noqa: E402
from simulator.scene import Scene  # noqa: E402

METHODS = ("greedy", "gradient", "overdamped", "inertial")


def methods_figure(
    out: Path, start=(380.0, 120.0, 8.0), um_per_px: float = 2.0, methods=METHODS
) -> list[str]:
    scene = Scene.from_inputs(
        library_path("four_pad_730_50"), chip_size_um=730, resolution_um=um_per_px
    )
    ls = build_landscape(scene)
    plt = pyplot()
    fig, axes = plt.subplots(
        2,
        len(methods),
        figsize=(4 * len(methods), 7.4),
        gridspec_kw={"height_ratios": [1.25, 1]},
        squeeze=False,
    )
    lines = []
    for k, method in enumerate(methods):
        t0 = time.perf_counter()
        t = simulate(scene, start, method=method, landscape=ls)
        dt = time.perf_counter() - t0
        ax = axes[0, k]
        ax.imshow(scene.pattern.data, extent=scene.pattern.extent_um, cmap="gray", vmin=0, vmax=1.6)
        sc = ax.scatter(
            t.path[:, 0], t.path[:, 1], c=t.path[:, 2], cmap="coolwarm", s=4, vmin=-25, vmax=25
        )
        ax.plot(*t.path[0, :2], "o", color="C1", ms=6)
        ax.plot(*t.path[-1, :2], "s", color="C2", ms=6)
        ax.set(
            xlim=(-420, 420),
            ylim=(-420, 420),
            xlabel="x (um)",
            ylabel="y (um)",
            title=f"{method}: {t.outcome}",
        )
        fig.colorbar(sc, ax=ax, shrink=0.75, label="twist (deg)")
        ax2 = axes[1, k]
        if t.t_s is not None:
            ax2.plot(t.t_s * 1e3, t.energy_J * 1e9)
            ax2.set_xlabel("time (ms)")
        else:
            ax2.plot(np.arange(len(t.energy_J)), t.energy_J * 1e9)
            ax2.set_xlabel("step")
        ax2.set_ylabel("energy (nJ)")
        ax2.grid(alpha=0.3)
        f = [round(v, 1) + 0.0 for v in t.final]
        time_txt = f", {t.time_s * 1e3:.0f} ms of chip time" if t.time_s else ""
        lines.append(
            f"| {method} | {t.outcome} | ({f[0]:g}, {f[1]:g}, {f[2]:g}) | {t.steps}{time_txt} | {dt:.2f} |"
        )
    fig.suptitle(
        f"730 um chip on the 730/50 um four-pad, {um_per_px:g} um/px, from ({start[0]:g}, {start[1]:g} um, {start[2]:g} deg)"
    )
    fig.tight_layout()
    save_figure(fig, out, dpi=80)
    return lines


def cost_table(um_per_px: float | None = None) -> list[str]:
    scene = Scene.from_inputs(
        library_path("four_pad_730_50"), chip_size_um=730, resolution_um=um_per_px
    )
    simulate(scene, (30.0, 20.0, 1.0))  # compile once, outside the timing
    t0 = time.perf_counter()
    t = simulate(scene, (300.0, 200.0, 10.0))
    run_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    ls = build_landscape(scene)
    full_s = time.perf_counter() - t0
    c = t.cost
    return [
        "| | landscape poses | twist planes | landscape time (s) | peak landscape memory (MB) |",
        "|---|---:|---:|---:|---:|",
        f"| full landscape | {ls.energy.size:,} | {ls.energy.shape[0]} | {full_s:.2f} | {ls.energy.nbytes / 2**20:,.0f} |",
        f"| greedy run (300, 200, 10 deg), {t.outcome} in {t.steps} steps | {c.poses_computed:,} | {c.planes} | {c.landscape_s:.2f} | {c.poses_computed * 4 / 2**20:,.0f} |",
        f"| ratio | {c.poses_computed / ls.energy.size:.1%} | {c.planes / ls.energy.shape[0]:.0%} | {c.landscape_s / full_s:.0%} | |",
        "",
        f"(whole run including stepping: {run_s:.2f} s)",
    ]


LARGE_RUN = r"""
import json, sys, time
from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.motion import simulate
from simulator.scene import Scene
method, engine = sys.argv[1], sys.argv[2]
size, gap = (float(v) for v in sys.argv[3:5]) if len(sys.argv) > 3 else (4000.0, 200.0)
scene = Scene(pattern=mask_from_geometry(four_pad(size, gap), 1.0), chip=mask_from_geometry(square(size), 1.0))
t0 = time.perf_counter()
t = simulate(scene, (0.3 * size, -0.2 * size, 10.0), method=method, engine=engine)
wall = time.perf_counter() - t0
peak = [int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM:")][0] / 1024
print(json.dumps({"wall_s": wall, "peak_mb": peak, "outcome": t.outcome, "steps": t.steps, "final": t.final,
                  "poses": t.cost.poses_computed, "engine": t.cost.engine, "path": t.path.tolist()}))
"""


def _run_script(script: Path, args: list[str], in_process: bool) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``python script ARGS``: a fresh process, or, for a smoke
    run, this process (no second import and compilation of the engine; its peak RSS is then
    this process's)."""
    if not in_process:
        p = subprocess.run(
            [sys.executable, str(script), *args],
            capture_output=True,
            text=True,
            env=os.environ | {"PYTHONPATH": str(ROOT)},
        )
        return p.returncode, p.stdout, p.stderr
    import contextlib
    import io

    buf, argv = io.StringIO(), sys.argv
    sys.argv = [str(script), *args]
    try:
        with contextlib.redirect_stdout(buf):
            exec(compile(script.read_text(), str(script), "exec"), {"__name__": "__main__"})
    except Exception as err:  # noqa: BLE001 - reported as the fresh process's failure would be
        return 1, buf.getvalue(), f"{type(err).__name__}: {err}"
    finally:
        sys.argv = argv
    return 0, buf.getvalue(), ""


def large_run(
    engines=("fft", "path"),
    methods=("greedy", "gradient"),
    size_gap=(4000, 200),
    in_process: bool = False,
) -> list[str]:
    lines = [
        "| method | engine | outcome | steps | final (um, um, deg) | poses computed | wall (s) | peak RSS (MB) |",
        "|---|---|---|---:|---|---:|---:|---:|",
    ]
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "run.py"
        script.write_text(LARGE_RUN)
        for method in methods:
            for engine in engines:
                rc, stdout, stderr = _run_script(
                    script, [method, engine, *map(str, size_gap)], in_process
                )
                if rc:
                    lines.append(
                        f"| {method} | {engine} | failed: {stderr.strip().splitlines()[-1]} |"
                    )
                    continue
                r = json.loads(stdout.strip().splitlines()[-1])
                runs[method, engine] = r
                f = ", ".join(f"{v:.3g}" for v in r["final"])
                lines.append(
                    f"| {method} | {engine} | {r['outcome']} | {r['steps']} | ({f}) | {r['poses']:,} | {r['wall_s']:.1f} | {r['peak_mb']:,.0f} |"
                )
            if (method, "fft") in runs and (method, "path") in runs:
                a, b = (
                    np.asarray(runs[method, "fft"]["path"]),
                    np.asarray(runs[method, "path"]["path"]),
                )
                same = a.shape == b.shape and np.array_equal(a, b)
                gap = np.abs(a[-1] - b[-1]).max()
                lines.append(
                    f"| {method} | | same path: {same}; final poses {gap:.2g} apart | | | | | |"
                )
    return lines


MENISCUS_RUN = r"""
import json, sys, time
t_start = time.perf_counter()
from simulator.motion import simulate
from simulator.physics import Liquid
from simulator.scene import Effects, Scene
which, method, model = sys.argv[1], sys.argv[2], sys.argv[3]
res = float(sys.argv[4]) if len(sys.argv) > 4 else None
if which == "730":
    from patterns.library import library_path
    volume, start = 20.0, (300.0, 200.0, 10.0)
    kw = {"effects": Effects(meniscus=True), "liquid": Liquid(volume_nl=volume, dispense="none")} if model == "meniscus" else {}
    scene = Scene.from_inputs(library_path("four_pad_730_50"), chip_size_um=730, resolution_um=res, **kw)
else:
    from patterns.geometry import four_pad, mask_from_geometry, square
    volume, start = 500.0, (1200.0, -800.0, 10.0)
    kw = {"effects": Effects(meniscus=True), "liquid": Liquid(volume_nl=volume, dispense="none")} if model == "meniscus" else {}
    scene = Scene(pattern=mask_from_geometry(four_pad(4000, 200), 1.0),
                  chip=mask_from_geometry(square(4000), 1.0), **kw)
t0 = time.perf_counter()
t = simulate(scene, start, method=method)
wall = time.perf_counter() - t0
peak = [int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM:")][0] / 1024
c = t.cost
print(json.dumps({"simulate_s": wall, "process_s": time.perf_counter() - t_start, "peak_mb": peak,
                  "outcome": t.outcome, "steps": t.steps, "final": list(t.final), "engine": c.engine,
                  "poses": c.poses_computed, "planes": c.planes, "landscape_s": c.landscape_s,
                  "minimum_how": c.minimum_how, "minimum_s": c.minimum_s,
                  "meniscus_height_um": scene.meniscus_height_um}))
"""
MENISCUS_SCENES = {
    "730": "730/50 um four-pad, 1 um/px, 730 um chip, (300, 200 um, 10 deg), 20 nl",
    "4k": "4000 um four-pad (gap 200 um), 1 um/px, 4000 um chip, (1200, -800 um, 10 deg), 500 nl",
}


def meniscus_runs(
    scenes=("730", "4k"),
    methods=("greedy", "gradient"),
    repeats=3,
    um_per_px=None,
    in_process: bool = False,
) -> dict:
    """Overlap and meniscus runs of the same scene, alternated (A B A B ...), each in a fresh
    process: every value, the best of each, and the ratios meniscus / overlap."""
    out = {"scenes": {}, "repeats": repeats, "cpus": os.cpu_count()}
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "run.py"
        script.write_text(MENISCUS_RUN)
        for which in scenes:
            for method in methods:
                runs = {"overlap": [], "meniscus": []}
                for _ in range(repeats):
                    for model in ("overlap", "meniscus"):
                        res = [] if um_per_px is None else [str(um_per_px)]
                        rc, stdout, stderr = _run_script(
                            script, [which, method, model, *res], in_process
                        )
                        if rc:
                            raise RuntimeError(stderr.strip().splitlines()[-1])
                        r = json.loads(stdout.strip().splitlines()[-1])
                        runs[model].append(r)
                        print(
                            f"{which} {method} {model}: {r['simulate_s']:.1f} s "
                            f"(process {r['process_s']:.1f} s), {r['peak_mb']:,.0f} MB, "
                            f"{r['outcome']}, engine {r['engine']}",
                            file=sys.stderr,
                        )
                best = {
                    m: {
                        k: min(r[k] for r in v)
                        for k in ("simulate_s", "process_s", "peak_mb", "landscape_s")
                    }
                    for m, v in runs.items()
                }
                out["scenes"][f"{which} {method}"] = {
                    "scene": MENISCUS_SCENES[which],
                    "method": method,
                    "runs": runs,
                    "best": best,
                    "ratio_simulate": best["meniscus"]["simulate_s"]
                    / best["overlap"]["simulate_s"],
                    "ratio_process": best["meniscus"]["process_s"] / best["overlap"]["process_s"],
                    "ratio_peak": best["meniscus"]["peak_mb"] / best["overlap"]["peak_mb"],
                }
    return out


def meniscus_table(res: dict) -> list[str]:
    lines = [
        "| scene | method | model | engine | outcome | steps | simulate (s) | whole process (s) | peak RSS (MB) |",
        "|---|---|---|---|---|---:|---:|---:|---:|",
    ]
    for key, r in res["scenes"].items():
        which, method = key.split()
        for model in ("overlap", "meniscus"):
            last, b = r["runs"][model][-1], r["best"][model]
            allv = ", ".join(f"{x['simulate_s']:.1f}" for x in r["runs"][model])
            lines.append(
                f"| {which} | {method} | {model} | {last['engine']} | {last['outcome']} | "
                f"{last['steps']} | {b['simulate_s']:.1f} ({allv}) | {b['process_s']:.1f} | "
                f"{b['peak_mb']:,.0f} |"
            )
        lines.append(
            f"| {which} | {method} | **meniscus / overlap** | | | | "
            f"**{r['ratio_simulate']:.2f}** | **{r['ratio_process']:.2f}** | {r['ratio_peak']:.2f} |"
        )
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs")
    ap.add_argument("--only-4k", action="store_true", help="only the large single runs (item 3)")
    ap.add_argument("--engines", default="fft,path", help="engines of item 3, comma-separated")
    ap.add_argument("--meniscus", action="store_true", help="only the meniscus runs (item 4)")
    ap.add_argument("--repeats", type=int, default=3, help="alternated repeats of item 4")
    ap.add_argument("--scenes", default="730,4k", help="scenes of item 4, comma-separated")
    ap.add_argument("--methods", default="greedy,gradient", help="methods of item 4")
    add_smoke_arg(ap, "the tables (the figure and JSON beside them)")
    args = ap.parse_args(argv)
    smoke = smoke_out(ap, args.smoke)
    if smoke:
        with tee_stdout(smoke):
            print(
                "| method | outcome | final (um, um, deg) | steps | wall s |\n|---|---|---|---|---:|"
            )
            fig = smoke.with_suffix(".png")
            print("\n".join(methods_figure(fig, um_per_px=20.0, methods=("greedy",))))
            print()
            print("\n".join(cost_table(20.0)))
            print()
            print("\n".join(large_run(("fft", "path"), ("greedy",), (200, 20), in_process=True)))
            print()
            res = meniscus_runs(("730",), ("greedy",), 1, 20.0, in_process=True)
            smoke.with_suffix(".json").write_text(json.dumps(res, indent=1) + "\n")
            print("\n".join(meniscus_table(res)))
        print(
            f"wrote {smoke}, {smoke.with_suffix('.png')} and {smoke.with_suffix('.json')} (smoke run)"
        )
        return 0
    if args.meniscus:
        res = meniscus_runs(
            tuple(args.scenes.split(",")), tuple(args.methods.split(",")), args.repeats
        )
        dest = ROOT / "benchmarks" / "results" / "trajectories.json"
        dest.write_text(json.dumps(res, indent=1) + "\n")
        print("\n".join(meniscus_table(res)))
        return 0
    if args.only_4k:
        print("\n".join(large_run(tuple(args.engines.split(",")))))
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    print("| method | outcome | final (um, um, deg) | steps | wall s |\n|---|---|---|---|---:|")
    print("\n".join(methods_figure(args.out / "methods.png")))
    print()
    print("\n".join(cost_table()))
    print()
    print("\n".join(large_run(tuple(args.engines.split(",")))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
