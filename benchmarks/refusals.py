"""How fast large requests are refused or run in pieces (speed targets; not a test).

The test suite checks what happens (the error, the memory that stays untouched, the
final pose); the times are targets measured here, since timed assertions flake on a
shared machine:

1. An over-budget landscape (a 4096 x 4096 px pattern, a 4000 px chip, 64 MB budget)
   is refused in under 0.5 s (``tests/test_robustness.py::test_resources_over_budget_fails_before_allocating``).
2. One greedy trajectory on that pattern (a 4096 um four-pad, gap 96 um) builds boxes
   of the landscape only and finishes in under 60 s
   (``tests/test_robustness.py::test_resources_4096_px_pattern_single_trajectory``).

3. Hostile scene files and PNG notes are refused in under 1 s each: a TOML array nested
   5000 deep, a dotted key of 200,000 parts, a 50 MB scene file, a PNG note nested
   60,000 deep (``tests/test_schema.py``, which asserts the stage each is refused at:
   before parsing, before reading).

Usage: ``python benchmarks/refusals.py`` (best of 3 for items 1 and 3).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from patterns.errors import InputError  # noqa: E402
from patterns.geometry import four_pad, square  # noqa: E402
from patterns.mask import Mask  # noqa: E402
from patterns.raster import mask_from_geometry  # noqa: E402
from simulator import Scene, build_landscape, simulate  # noqa: E402

TARGETS_S = {
    "refuse over-budget landscape": 0.5,
    "4096 px greedy trajectory": 60.0,
    "refuse hostile scene files": 1.0,
}


def refuse_seconds() -> float:
    s = Scene(
        pattern=Mask(np.ones((4096, 4096)), 1.0),
        chip=mask_from_geometry(square(4000), 1.0),
        memory_budget_mb=64,
    )
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        try:
            build_landscape(s)
        except InputError:
            best = min(best, time.perf_counter() - t0)
    return best


def trajectory_seconds() -> float:
    t0 = time.perf_counter()
    s = Scene(
        pattern=mask_from_geometry(four_pad(4096, 96), 1.0),
        chip=mask_from_geometry(square(4000), 1.0),
    )
    simulate(s, (90, -70, 1), method="greedy", max_steps=100)
    return time.perf_counter() - t0


def hostile_files_seconds() -> float:
    """The slowest of the hostile scene-file and PNG-note refusals (best of 3 each)."""
    import tempfile

    from patterns.metadata import parse_png_params
    from simulator.scene import read_scene_file

    texts = {
        "deep.toml": "x = " + "[" * 5000 + "]" * 5000 + "\n",
        "dotted.toml": "x" + ".a" * 200_000 + " = 1\n",
        "big.toml": "x = [" + "0," * 25_000_000 + "]\n",
    }
    worst = 0.0
    with tempfile.TemporaryDirectory() as d:
        calls = []
        for name, text in texts.items():
            (Path(d) / name).write_text(text)
            calls.append(lambda p=Path(d) / name: read_scene_file(p))
        calls.append(lambda: parse_png_params("[" * 60_000, "note.png"))
        for call in calls:
            best = float("inf")
            for _ in range(3):
                t0 = time.perf_counter()
                try:
                    call()
                except InputError:
                    best = min(best, time.perf_counter() - t0)
            worst = max(worst, best)
    return worst


def main() -> int:
    results = {
        "refuse over-budget landscape": refuse_seconds(),
        "4096 px greedy trajectory": trajectory_seconds(),
        "refuse hostile scene files": hostile_files_seconds(),
    }
    ok = True
    for name, seconds in results.items():
        target = TARGETS_S[name]
        ok &= seconds < target
        print(
            f"{name}: {seconds:.3f} s (target < {target:g} s) {'ok' if seconds < target else 'MISSED'}"
        )
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
