"""``selfalign design`` with a ``[freeform]`` table: a pattern optimised pixel by pixel by
gradients through the JAX landscape, checked by the evaluator against a baseline."""

from __future__ import annotations

import argparse
from pathlib import Path

from foundation import InputError


def run_freeform(args: argparse.Namespace, path: Path, doc: dict) -> int:
    """Run the free-form design of the file at ``path`` (parsed: ``doc``) into ``args.out``."""
    from foundation import quiet_waits
    from simulator.design import freeform, load_freeform

    for flag, value in (("--workers", args.workers), ("--scheduler", args.scheduler)):
        if value is not None:
            raise InputError(
                f"{flag} sets where the trials of a [search] run; a [freeform] design runs its gradient "
                f"iterations in this process: drop {flag}"
            )
    if args.memory_budget is not None:  # over the file's, as every command's --memory-budget
        doc = {**doc, "scene": {**doc.get("scene", {}), "memory_budget_mb": args.memory_budget}}
    spec = load_freeform(doc, base=path.resolve().parent, source=str(path))
    spec = spec.with_iterations(args.trials)
    with quiet_waits(args.quiet):
        result = freeform(spec, args.out, quiet=args.quiet)
    v = result.verification or {}
    b, a = v.get("baseline"), v.get("optimised")
    print(
        f"free-form design: {spec.iterations} iterations on {spec.shape[1]} x {spec.shape[0]} px "
        f"({result.seconds_per_iteration * 1e3:.3g} ms per iteration); objective "
        f"{result.before[0]:.4g} (baseline) -> {result.after[0]:.4g} (optimised)"
    )
    if b and a:
        print(
            f"capture fraction {100 * b['capture']['fraction']:.1f} % -> {100 * a['capture']['fraction']:.1f} %, "
            f"yield {100 * b['yield']['fraction']:.1f} % -> {100 * a['yield']['fraction']:.1f} % "
            f"({spec.verify['yield_starts']} placement-noise starts, {spec.verify['method']})"
        )
        if a.get("orientation"):
            print(
                f"orientation gap (lowest energy turned minus the target's) "
                f"{b['orientation']['min_gap_J']:.4g} J -> {a['orientation']['min_gap_J']:.4g} J"
            )
    lay = result.layout or {}
    if lay and not lay["ok"]:
        print(
            f"warning: the written polygons move by up to {lay['opening_moves_um']} um (opening) and "
            f"{lay['closing_moves_um']:.3g} um (closing) under the minimum feature's disk; see report.html"
        )
    print(
        f"wrote {Path(args.out) / 'report.html'} (and result.json, pattern.png, pattern_mask.png, pattern.gds, "
        "history.csv, history.png, capture_before_after.png)"
    )
    return 0
