"""Monte Carlo benchmark: batched starts against a Python loop over single runs.

The job: run N starts to their end on one precomputed landscape and classify them.

* Scene: the 730 um four-pad pattern (gap 50 um, 10 um substrate margin) with a 730 um
  square chip, at 2 um/px; twist step 1.5 degrees over the chip's 90 degree symmetry
  period (-45 .. 43.5 degrees: 60 twist planes, periodic, i.e. 61 twists counting +45
  which the period maps onto -45). The landscape is built once (time reported, not
  counted in the runs).
* Starts: uniform in x, y in [-400, 400] um and twist in [-30, 30] degrees, from
  ``numpy.random.default_rng(0)`` (:func:`simulator.batch.random_starts`).
* ``batch``: :func:`simulator.batch.run_batch` (jit(vmap(stepper)), chunks of
  ``--chunk`` starts, one thread per core, progress bar off), best of ``--repeats``
  calls after a first call that compiles (its time is reported in the notes).
* ``loop``: the same stepper jit'ed for one start (``record=False``) called in a
  Python loop, one start at a time, each result pulled to the host, the outcome
  classified as in the batch. Timed on ``--loop-starts`` starts (after a warm-up, best
  of ``--repeats``) and extrapolated to N (marked "extrap.").
* trajectory-steps per second counts the moves (greedy) or accepted steps (gradient)
  of every start.

Usage::

    python benchmarks/montecarlo.py [--n 1000 10000 100000] [--methods greedy gradient]
        [--chunk 2048] [--loop-starts 300] [--page docs/benchmarks.md] [--no-page]
        [--smoke OUT]

``--smoke OUT``: the scene at 20 um/px and 15 degree twists, 64 starts (greedy unless
``--methods`` says otherwise), the loop timed on 4, one timing each; the text goes to OUT
only (never into the page).

The markdown table is printed and written between the markers
``<!-- bench:montecarlo -->`` and ``<!-- /bench:montecarlo -->`` of the benchmarks page.
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import platform
import re
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _smoke import add_smoke_arg, smoke_out  # noqa: E402  (benchmarks/ is on sys.path)

import simulator  # noqa: F401  (x64 on)
from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.batch import random_starts, run_batch
from simulator.batch._montecarlo import _one
from simulator.core import DEFAULT_CHUNK, DEFAULT_MAX_STEPS, METHODS
from simulator.landscape import build_landscape
from simulator.motion import field_and_grid, radius_of_gyration_px
from simulator.scene import Scene, TwistGrid

ROOT = Path(__file__).resolve().parents[1]
MARK_OPEN, MARK_CLOSE = "<!-- bench:montecarlo -->", "<!-- /bench:montecarlo -->"


def make_scene(s: float = 2.0, twist_step_deg: float = 1.5) -> Scene:
    """The benchmark's scene at ``s`` um/px (2 by default; coarser for a quick run)."""
    return Scene(
        pattern=mask_from_geometry(four_pad(730, 50), s, margin_um=10),
        chip=mask_from_geometry(square(730), s),
        twist=TwistGrid(step_deg=twist_step_deg),
    )


@functools.partial(jax.jit, static_argnames=("grid", "method", "max_steps"))
def _single(field, start, grid, method, max_steps):
    """One start, jit'ed alone: the loop baseline (same code as one vmap lane: no dynamics
    parameters, the explicit stepper)."""
    return _one(field, grid, None, start, method, max_steps, False)


def time_loop(fld, grid, q0: np.ndarray, method: str, n: int, repeats: int) -> tuple[float, int]:
    """Best-of-``repeats`` seconds and total steps for a Python loop over the first n starts."""
    conv = (lambda v: jnp.asarray(v, jnp.int32)) if method == "greedy" else jnp.asarray
    out = _single(
        fld, conv(q0[0]), grid=grid, method=method, max_steps=DEFAULT_MAX_STEPS
    )  # compile
    jax.block_until_ready(out)
    best = math.inf
    for _ in range(repeats):
        steps = 0
        t = time.perf_counter()
        for i in range(n):
            q, st, status, o, e, _time_s = _single(
                fld, conv(q0[i]), grid=grid, method=method, max_steps=DEFAULT_MAX_STEPS
            )
            steps += int(st)  # pulls the result to the host, as a user's loop would
            int(o)
        best = min(best, time.perf_counter() - t)
    return best, steps


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--n", type=int, nargs="+", default=[1000, 10000, 100000], help="numbers of starts"
    )
    ap.add_argument("--methods", nargs="+", default=None, choices=METHODS)
    ap.add_argument("--chunk", type=int, default=DEFAULT_CHUNK)
    ap.add_argument(
        "--loop-starts", type=int, default=300, help="starts the Python loop is timed on"
    )
    ap.add_argument(
        "--repeats", type=int, default=3, help="timings per figure; the best is reported"
    )
    ap.add_argument(
        "--page", "--readme", dest="readme", type=Path, default=ROOT / "docs" / "benchmarks.md"
    )
    ap.add_argument("--no-page", "--no-readme", dest="no_readme", action="store_true")
    add_smoke_arg(ap, "the table and notes")
    args = ap.parse_args(argv)
    smoke = smoke_out(ap, args.smoke)
    if smoke:
        args.n, args.loop_starts, args.repeats, args.chunk = [64], 4, 1, 64
    args.methods = args.methods or (["greedy"] if smoke else ["greedy", "gradient"])

    load = os.getloadavg()[0]
    scene = make_scene(20.0, 15.0) if smoke else make_scene()
    t = time.perf_counter()
    ls = build_landscape(scene)
    t_land = time.perf_counter() - t
    fld, grid = field_and_grid(ls, radius_of_gyration_px(scene))
    starts = random_starts(max(args.n), (400, 400, 30), seed=0, distribution="uniform")
    rows, notes = [], [f"landscape {ls.energy.shape} float32 built once in {t_land:.2f} s"]
    for method in args.methods:
        q0 = grid.to_index(starts)
        q0 = np.round(q0).astype(np.int32) if method == "greedy" else q0
        loop_s, loop_steps = time_loop(fld, grid, q0, method, args.loop_starts, args.repeats)
        loop_rate = args.loop_starts / loop_s
        first = True
        for n in args.n:
            t = time.perf_counter()
            run_batch(scene, starts[:n], method, landscape=ls, chunk=args.chunk, progress=False)
            warm = time.perf_counter() - t
            runs = [
                run_batch(scene, starts[:n], method, landscape=ls, chunk=args.chunk, progress=False)
                for _ in range(args.repeats)
            ]
            r = min(runs, key=lambda b: b.stats["run_s"])
            s = r.stats["run_s"]
            if first:
                notes.append(
                    f"{method}: first call (compile + run) of {n:,} starts {warm:.2f} s, second {s:.2f} s"
                )
                first = False
            loop_n = n / loop_rate
            rows.append(
                {
                    "method": method,
                    "n": n,
                    "batch_s": s,
                    "starts_per_s": n / s,
                    "steps_per_s": float(r.steps.sum()) / s,
                    "mean_steps": float(r.steps.mean()),
                    "yield": float(np.mean(r.outcome == 0)),
                    "loop_s": loop_n,
                    "loop_extrapolated": n > args.loop_starts,
                    "loop_steps_per_s": loop_steps / loop_s,
                    "speedup": loop_n / s,
                }
            )
    table = markdown(rows, args)
    info = (
        f"Machine: {os.cpu_count()} CPUs ({platform.processor() or platform.machine()}), "
        f"jax {jax.__version__} on {jax.default_backend()}, chunk {args.chunk}, "
        f"loop timed on {args.loop_starts} starts; best of {args.repeats} timings; "
        f"load average {load:.2f} at the start, {os.getloadavg()[0]:.2f} at the end (the machine is shared)."
    )
    text = "\n".join([table, "", info, ""] + [f"* {n}" for n in notes])
    print(text)
    if smoke:
        smoke.write_text(text)
        print(f"\nwrote {smoke} (smoke run)")
    elif not args.no_readme:
        write_readme(args.readme, text)
        print(f"\nwrote the table into {args.readme}")
    return 0


def markdown(rows: list[dict], args) -> str:
    head = (
        "| method | starts | batch (s) | starts/s | trajectory-steps/s | mean steps | yield | "
        "Python loop (s) | loop steps/s | speed-up |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    lines = [head]
    for r in rows:
        loop = f"{r['loop_s']:,.1f}" + (" extrap." if r["loop_extrapolated"] else "")
        lines.append(
            f"| {r['method']} | {r['n']:,} | {r['batch_s']:.2f} | {r['starts_per_s']:,.0f} | {r['steps_per_s']:,.0f} | "
            f"{r['mean_steps']:.0f} | {r['yield']:.3f} | {loop} | {r['loop_steps_per_s']:,.0f} | {r['speedup']:.0f}x |"
        )
    return "\n".join(lines)


def write_readme(path: Path, text: str) -> None:
    block = f"{MARK_OPEN}\n{text}\n{MARK_CLOSE}"
    old = path.read_text() if path.exists() else ""
    pat = re.compile(re.escape(MARK_OPEN) + r".*?" + re.escape(MARK_CLOSE), re.S)
    new = (
        pat.sub(lambda _: block, old)
        if pat.search(old)
        else old.rstrip("\n") + ("\n\n" if old else "") + block + "\n"
    )
    path.write_text(new)


if __name__ == "__main__":
    raise SystemExit(main())
