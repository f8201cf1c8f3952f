"""``selfalign design``: which pattern to make, by a search over a design's parameters
(``[search]``) or by gradients over a free-form pattern (``[freeform]``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from simulator.commands._flags import finite_limit
from simulator.sweep import CONNECT_TIMEOUT_S


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "design",
        help="design search: the pattern that does best, by Optuna trials on Dask or by gradients",
        description=(
            "Find the alignment pattern that does best. A design file with a [search] table is a sweep "
            "file whose axes are ranges to search, with an objective and constraints over the columns of "
            "`selfalign evaluate`: Optuna trials (TPE or CMA-ES; several objectives give a Pareto front) run "
            "on Dask as sweep points are, resumable from --out. A design file with a [freeform] table "
            "optimises a pattern pixel by pixel by gradients through the JAX landscape, keeping the "
            "keep-in areas wettable and the keep-out areas dry. Both check the result with the evaluator "
            "against a baseline and write the table, pictures, the best pattern as PNG and GDSII, and report.html."
        ),
    )
    p.add_argument(
        "design_file", metavar="SPEC.toml", help="the design file (see docs/guide/design.md)"
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="results directory: new, empty, or holding this same design run (resumed)",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="local Dask worker processes for the trials (default: one per core); 0 runs them in this process",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=f"run the trials on the Dask cluster of this scheduler (tcp://HOST:PORT); refused after "
        f"{CONNECT_TIMEOUT_S:g} s if unreachable",
    )
    p.add_argument(
        "--trials",
        type=int,
        metavar="N",
        help="trials of a search, or iterations of a free-form optimisation (default: the file's)",
    )
    p.add_argument(
        "--memory-budget",
        type=finite_limit("--memory-budget", "MB"),
        help="memory budget in MB of a [freeform] run, over the file's [scene] memory_budget_mb "
        "(default: half the available memory, at most 8192; never more than the machine has)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from foundation import InputError

    try:
        return _run(args)
    except InputError as err:
        raise InputError(without_force(str(err))) from None


#: What the output checks shared with other commands advise, and what design has instead of
#: their --force: a rerun resumes a search or replaces a previous free-form output itself.
_FORCE_ADVICE = (
    (
        "choose a new directory, or pass --force to replace a previous selfalign output",
        "choose a new directory (a rerun of the same design resumes its search, or replaces its "
        "previous free-form output)",
    ),
    (
        "holds files selfalign did not write; not replaced even with --force (choose another directory)",
        "holds files selfalign did not write; choose another directory",
    ),
)


def without_force(message: str) -> str:
    """A refusal's advice with the flags design has: it has no --force."""
    for theirs, ours in _FORCE_ADVICE:
        message = message.replace(theirs, ours)
    return message


def _run(args: argparse.Namespace) -> int:
    from simulator.design import design_mode
    from simulator.sweep import read_toml_file

    path = Path(args.design_file)
    doc = read_toml_file(path, "design file")
    mode = design_mode(doc, path)
    if mode == "search":
        from simulator.commands._design_search import run_search

        return run_search(args, path, doc)
    from simulator.commands._design_freeform import run_freeform

    return run_freeform(args, path, doc)
