"""A command's output files: the checks before any work (never over an input, never two
outputs in one file, an existing one only with ``--force``) and the atomic JSON and CSV
writers (every number finite)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from foundation import atomic_output, json_text
from simulator.commands._request import SceneRequest


def input_paths(request: SceneRequest) -> list[Path]:
    """The files this run reads (pattern, chip, scene and the scene's own pattern/chip):
    ``request``'s ``inputs``."""
    return list(request.inputs)


def check_outputs(request: SceneRequest) -> None:
    """Fail before any work when an output file of ``request``'s output plan cannot or must
    not be written.

    An output may not be an input, a link, a device or a directory, and two outputs may not
    name one file; one that exists is refused unless ``--force`` (:func:`add_force_arg`,
    ``request.force``).
    """
    from foundation import check_distinct, check_output_file, require_new_file

    inputs = list(request.inputs)
    named: dict[str, str | os.PathLike | None] = dict(request.outputs)
    for flag, path in named.items():
        if path:
            check_output_file(path, flag, inputs)
            require_new_file(path, flag, request.force)
    check_distinct(named)


def add_force_arg(p: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--force``: replace output files that exist (refused without it, before any work)."""
    p.add_argument(
        "--force",
        action="store_true",
        help="replace output files that already exist (without it an existing one is refused "
        "before any work; an input of the run is never replaced)",
    )


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write JSON atomically (no half-written file on failure); every number must be finite."""
    from foundation import require_finite

    require_finite(obj, f"output {path}")
    with atomic_output(path) as tmp:
        tmp.write_text(json_text(obj))


def write_csv(path: str | os.PathLike, columns: list[str], values: list) -> None:
    """Write a table as CSV atomically: ``columns`` (names carry their units, e.g. ``x_um``)
    and one array (or list of strings) per column, rows in order. Every number must be
    finite (:func:`simulator.core.require_finite`)."""
    import numpy as np

    from foundation import require_finite

    cols = [np.asarray(v) for v in values]
    require_finite(
        {c: v for c, v in zip(columns, cols, strict=True) if v.dtype.kind in "fiu"},
        f"output {path}",
    )
    n = len(cols[0]) if cols else 0

    def cell(v) -> str:
        return f"{v:.10g}" if isinstance(v, float | np.floating) else str(v)

    with atomic_output(path) as tmp, open(tmp, "w") as f:
        f.write(",".join(columns) + "\n")
        for i in range(0, n, 65536):
            rows = zip(*(c[i : i + 65536].tolist() for c in cols), strict=True)
            f.write("".join(",".join(cell(v) for v in row) + "\n" for row in rows))
