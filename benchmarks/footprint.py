"""What the footprint state costs: a ``--dispense pattern`` run against the same run without
the state (speed and memory targets; not a test).

Target (the footprint-state issue): a pattern-dispensed run within 2x of today's meniscus
run. Each run is a whole ``selfalign simulate`` process, the two alternated, each timed
with its own peak memory (``ru_maxrss``, printed by the process as it exits):

* the source's bench case: 730/100 four-pad, 730 um chip, 20 nl, 2 um/px, 90 twists,
  inertial from (500, 5, 1), pads 10:35 deg hysteresis (the far pads stay wet);
* ``--small``: the same at 5 um/px (90 twists: the same work, 6x fewer poses, a minute);
* ``--batch``: ``montecarlo``, 2,000 greedy placements around (300, 0, 0) um with sigma
  100 um, 100 um and 3 deg on the same scene at 5 um/px (target: a batch carrying one
  footprint state per start within 2x of today's batch);
* ``--path``: greedy runs on the path engine (the footprint state at the poses the run
  visits, ``--engine path``): the bench case greedy from (500, 5, 1) at 2 um/px, stateless
  (path engine) against ``--dispense pattern`` on the path engine and on the FFT planes; and
  the 4000 um four-pad (gap 200 um, made at 2 um/px) under a 4000 um chip, 500 nl, pads 10:35
  deg, greedy from (1200, -800, 10), stateless against ``--dispense pattern``, both on the
  path engine (the FFT planes of that scene are refused: tens of GB);
* ``--smoke OUT``: the same at 10 um/px without twist, greedy, one repeat, its JSON to
  OUT only (a check that the script runs: tests/test_benchmarks_smoke.py); with ``--path``,
  the bench case at 10 um/px without twist, the three runs once.

Each row has the wall and CPU seconds (user + system) of the process, its peak memory, and
the machine's load average before it started (what else was running: CPU seconds are the
fairer figure on a loaded machine).

Usage: ``python benchmarks/footprint.py [--small | --batch | --path] [--repeats N] [--json PATH] [--smoke OUT]``
(default ``--json benchmarks/results/footprint.json``, ``footprint_small.json`` with ``--small``,
``footprint_batch.json`` with ``--batch``, ``footprint_path.json`` with ``--path``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _smoke import add_smoke_arg, smoke_out  # noqa: E402  (benchmarks/ is on sys.path)

sys.path.insert(0, str(ROOT))

PATTERN = ROOT / "patterns" / "library" / "four_pad_730_100.png"


def case(smoke: bool, small: bool = False, batch: bool = False) -> list[str]:
    if batch:
        # 2,000 placements around (300, 0, 0) with sigma 100 um, 100 um, 3 deg, greedy
        args = ["montecarlo", "--pattern", str(PATTERN), "--chip-size", "730", "--meniscus"]
        args += ["--volume", "20", "--hysteresis", "10:35", "--quiet", "--resolution", "5"]
        args += ["--random", "2000", "--around", "300,0,0", "--spread", "100,100,3", "--seed", "1"]
        return args + ["--method", "greedy"]
    args = ["simulate", "--pattern", str(PATTERN), "--chip-size", "730", "--meniscus"]
    args += ["--volume", "20", "--hysteresis", "10:35", "--quiet"]
    if smoke:
        return args + ["--resolution", "10", "--no-twist", "--method", "greedy", "--start=500,5,0"]
    if small:
        return args + ["--resolution", "5", "--method", "inertial", "--start=500,5,1"]
    # priced 8,032 MB with the state: near the default budget of 8 GiB (half the free memory
    # where less than 16 GiB is free), so raised for both
    return (
        args
        + ["--resolution", "2", "--method", "inertial", "--start=500,5,1"]
        + [
            "--memory-budget",
            "9000",
        ]
    )


#: ``python -m simulator.cli`` that prints its own peak memory (kB) on stderr as it exits.
PEAK = (
    "import atexit, resource, runpy, sys; atexit.register(lambda: (lambda u: print('PEAK_KB', "
    "u.ru_maxrss, u.ru_utime + u.ru_stime, file=sys.stderr))(resource.getrusage(resource.RUSAGE_SELF))); "
    "sys.argv = ['selfalign'] + sys.argv[1:]; runpy.run_module('simulator.cli', run_name='__main__')"
)


def run(args: list[str]) -> dict:
    """One whole process: wall and CPU seconds, its peak memory (MB), the load average
    before it and its first output line."""
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    p = subprocess.run(
        [sys.executable, "-c", PEAK, *args], capture_output=True, text=True, cwd=ROOT, check=False
    )
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"benchmarks/footprint.py: {' '.join(args)} failed: {p.stderr.strip()}")
    kb = [line.split()[1:] for line in p.stderr.splitlines() if line.startswith("PEAK_KB")]
    return {
        "wall_s": wall,
        "cpu_s": float(kb[-1][1]) if kb else float("nan"),
        "peak_mb": int(kb[-1][0]) / 1024 if kb else float("nan"),
        "load_before": load,
        "result": p.stdout.splitlines()[0] if p.stdout else "",
    }


def path_cases(smoke: bool, tmp: Path) -> list[tuple[str, str, list[str]]]:
    """(case, run, args) of ``--path``: each case's stateless run first (module docstring)."""
    bench = ["simulate", "--pattern", str(PATTERN), "--chip-size", "730", "--meniscus"]
    bench += ["--volume", "20", "--hysteresis", "10:35", "--quiet", "--method", "greedy"]
    if smoke:
        bench += ["--resolution", "10", "--no-twist", "--start=500,5,0"]
    else:
        bench += ["--resolution", "2", "--start=500,5,1"]
    out = [
        ("bench", "stateless path", bench + ["--dispense", "none", "--engine", "path"]),
        ("bench", "dispense pattern path", bench + ["--dispense", "pattern", "--engine", "path"]),
    ]
    # the FFT planes of the bench case are priced over the default budget (11.2 GB when measured)
    fft = ("bench", "dispense pattern fft", bench + ["--dispense", "pattern", "--engine", "fft"])
    if smoke:
        return [*out, fft]
    fft[2].extend(["--memory-budget", "11500"])
    big = tmp / "four_pad_4000_200.png"
    if not big.exists():
        make = ["pattern", "four-pad", "--size", "4000", "--gap", "200", "--um-per-px", "2"]
        subprocess.run(
            [sys.executable, "-m", "simulator.cli", *make, "-o", str(big)],
            check=True,
            capture_output=True,
            cwd=ROOT,
        )
    k4 = ["simulate", "--pattern", str(big), "--chip-size", "4000", "--meniscus"]
    k4 += ["--volume", "500", "--hysteresis", "10:35", "--quiet", "--method", "greedy"]
    k4 += ["--start=1200,-800,10", "--engine", "path"]
    out += [
        ("4000 um", "stateless path", k4 + ["--dispense", "none"]),
        ("4000 um", "dispense pattern path", k4 + ["--dispense", "pattern"]),
        fft,  # last: the largest
    ]
    return out


def main_path(repeats: int, smoke: Path | None, out: Path) -> int:
    """``--path`` (module docstring): every run ``repeats`` times, alternated; the ratios of
    the best wall and CPU seconds to the case's stateless run."""
    import tempfile

    rows = []
    with tempfile.TemporaryDirectory() as d:
        cases = path_cases(smoke is not None, Path(d))
        for i in range(repeats):
            for case_name, name, args in cases:
                r = run(args) | {"case": case_name, "run": name, "repeat": i, "args": args}
                rows.append(r)
                print(
                    f"{case_name:8s} {name:22s} {r['wall_s']:8.1f} s wall {r['cpu_s']:8.1f} s CPU "
                    f"{r['peak_mb']:8.0f} MB  (load {r['load_before']:.1f})  {r['result']}"
                )
    summary = {}
    for case_name in dict.fromkeys(c for c, _, _ in cases):
        mine = [r for r in rows if r["case"] == case_name]
        best = {
            n: min(r["wall_s"] for r in mine if r["run"] == n) for n in {r["run"] for r in mine}
        }
        cpu = {n: min(r["cpu_s"] for r in mine if r["run"] == n) for n in best}
        peak = {n: max(r["peak_mb"] for r in mine if r["run"] == n) for n in best}
        base = "stateless path"
        summary[case_name] = {
            "best_s": best,
            "best_cpu_s": cpu,
            "peak_mb": peak,
            "ratio_wall": {n: best[n] / best[base] for n in best},
            "ratio_cpu": {n: cpu[n] / cpu[base] for n in best},
        }
        for n in sorted(best):
            print(
                f"{case_name}: {n}: best {best[n]:.1f} s wall ({best[n] / best[base]:.2f}x), "
                f"{cpu[n]:.1f} s CPU ({cpu[n] / cpu[base]:.2f}x), peak {peak[n]:.0f} MB (target 2x)"
            )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"rows": rows, "summary": summary}, indent=1) + "\n")
    print(f"wrote {out}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--small", action="store_true", help="the bench case at 5 um/px (a minute)")
    ap.add_argument(
        "--batch",
        action="store_true",
        help="montecarlo: 2,000 greedy placements on the bench's scene at 5 um/px, with and without the state",
    )
    ap.add_argument(
        "--path",
        action="store_true",
        help="greedy runs on the path engine: the bench case and a 4000 um chip, with and without the state",
    )
    ap.add_argument("--json", type=Path, default=None)
    add_smoke_arg(ap, "its JSON")
    a = ap.parse_args(argv)
    smoke = smoke_out(ap, a.smoke)
    name = (
        "footprint_path.json"
        if a.path
        else "footprint_batch.json"
        if a.batch
        else "footprint_small.json"
        if a.small
        else "footprint.json"
    )
    out = (a.json or ROOT / "benchmarks" / "results" / name) if smoke is None else smoke
    repeats = 1 if smoke is not None else a.repeats
    if a.path:
        return main_path(repeats, smoke, out)
    base = case(smoke is not None, a.small, a.batch and smoke is None)
    rows = []
    for i in range(repeats):
        for name, extra in (
            ("stateless", ["--dispense", "none"]),
            ("dispense pattern", ["--dispense", "pattern"]),
        ):
            r = run(base + extra) | {"run": name, "repeat": i}
            rows.append(r)
            print(
                f"{name:18s} {r['wall_s']:8.1f} s wall {r['cpu_s']:8.1f} s CPU {r['peak_mb']:8.0f} MB"
                f"  (load {r['load_before']:.1f})  {r['result']}"
            )
    best = {
        n: min(r["wall_s"] for r in rows if r["run"] == n)
        for n in ("stateless", "dispense pattern")
    }
    ratio = best["dispense pattern"] / best["stateless"]
    cpu = {
        n: min(r["cpu_s"] for r in rows if r["run"] == n) for n in ("stateless", "dispense pattern")
    }
    cpu_ratio = cpu["dispense pattern"] / cpu["stateless"]
    print(f"best of {repeats}: ratio {ratio:.2f}x wall, {cpu_ratio:.2f}x CPU (target 2x)")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "case": base,
                "rows": rows,
                "best_s": best,
                "ratio": ratio,
                "best_cpu_s": cpu,
                "cpu_ratio": cpu_ratio,
            },
            indent=1,
        )
        + "\n"
    )
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
