"""``selfalign design`` in search mode: a file with a ``[search]`` table (:func:`simulator.design.search`)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from simulator.commands._signals import sigterm_says_what_was_kept

#: The memory advice of the checks shared with other commands, and a search's own: its
#: trials' budget is the file's (part of the search), not a flag.
_BUDGET_ADVICE = (
    ("(or raise --memory-budget)", "(or raise [scene] memory_budget_mb)"),
    ("raise memory_budget_mb (--memory-budget)", "raise [scene] memory_budget_mb"),
    ("or raise --memory-budget", "or raise [scene] memory_budget_mb"),
    ("MB (--memory-budget)", "MB ([scene] memory_budget_mb)"),
)


def run_search(args: argparse.Namespace, path: Path, doc: dict) -> int:
    """Run the search of the design file ``path`` (already read into ``doc``); print what it
    found. A refusal's memory advice names the file's budget, the one a search has."""
    from foundation import InputError

    try:
        return _run_search(args, path, doc)
    except InputError as err:
        text = str(err)
        for theirs, ours in _BUDGET_ADVICE:
            text = text.replace(theirs, ours)
        raise InputError(text) from None


def _run_search(args: argparse.Namespace, path: Path, doc: dict) -> int:
    from simulator.design import load_search, search

    if getattr(args, "memory_budget", None) is not None:
        from foundation import InputError

        raise InputError(
            "--memory-budget sets the budget of a [freeform] design; the trials of a [search] take theirs "
            "from the file's [scene] memory_budget_mb (part of the search, so a rerun resumes it): set it there "
            "and drop --memory-budget"
        )
    spec = load_search(doc, path.resolve().parent, source=str(path))
    try:
        with sigterm_says_what_was_kept(args.out, "design", "trial", "trials.jsonl", "trial"):
            table = search(
                spec,
                args.out,
                workers=args.workers,
                scheduler=args.scheduler,
                trials=args.trials,
                quiet=args.quiet,
            )
    except KeyboardInterrupt:
        from simulator.sweep import kept_points

        n = kept_points(args.out, "trials.jsonl", "trial") if os.path.isdir(args.out) else 0
        print(
            f"selfalign design: interrupted; {n} finished trial{'s are' if n != 1 else ' is'} kept in {args.out} "
            "(rerun the same command to resume)",
            file=sys.stderr,
        )
        return 130
    st = table.attrs["search"]
    where = f"{st['workers']} Dask workers" if st["workers"] else "this process"
    now = (
        f"{st['evaluated_now']} evaluated now in {st['run_s']:.1f} s on {where}"
        + (f", {st['reused_now']} reused a design already tried" if st["reused_now"] else "")
        if st["evaluated_now"] or st["reused_now"]
        else "none run now"
    )
    space = f"; all {st['space_size']} designs of the space tried" if st["exhausted"] else ""
    print(
        f"search {st['hash'][:12]}: {st['done']} of {st['trials']} trials ({spec.sampler}) over "
        f"{', '.join(a.name for a in spec.searched)}; {now}; {st['failed']} failed{space}"
    )
    _print_best(spec, table, st["best"])
    out = Path(args.out)
    extra = [f for f in ("history.png", "pareto.png", "best.png", "best.gds") if (out / f).exists()]
    print(
        f"wrote {out / 'trials.parquet'} (and trials.csv, report.html, best.json, {', '.join(extra)})"
    )
    return 0


def _print_best(spec, table, best: list[int]) -> None:
    def fmt(v) -> str:
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    def settings(row) -> str:
        return ", ".join(
            f"{a.column} = {fmt(row[a.column])}" for a in spec.searched if a.column in row
        )

    base = table[table["trial"] == 0]
    if not best:
        print("best: none (no feasible trial finished)")
    elif len(spec.objectives) == 1:
        row = table[table["trial"] == best[0]].iloc[0]
        o = spec.objectives[0]
        line = f"best: trial {best[0]} ({settings(row)}): {o.direction} {o.expression.text} = {fmt(row['objective_1'])}"
        if len(base) and base.iloc[0]["state"] == "complete":
            line += f" (baseline {fmt(base.iloc[0]['objective_1'])})"
        print(line)
    else:
        print(
            f"Pareto front: {len(best)} trial{'s' if len(best) != 1 else ''} ({', '.join(map(str, best))})"
        )
