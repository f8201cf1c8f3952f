"""Write examples/calibrate_trials.csv: a bench table the model itself made.

Ten nominal starts on the scene examples/calibrate_fourpad.toml with the pads' receding
angle at 20 degrees (the scene file says 25), 100 trials each with placement noise of 20 um,
20 um and 2 degrees (seed 1), run with gradient steps: ``selfalign calibrate ... --method
gradient`` should find 20 degrees back (docs/guide/calibrate.md). The starts: the capture
edge on x, and where the pinning weighs against a force that varies with the placement (a
chip half off the pads' corner, a centred chip turned 36-44 degrees), so that the yields
change smoothly with the angle.

Usage: ``python examples/make_calibrate_trials.py [OUT.csv]``
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simulator.design import synthetic_trials, write_trials  # noqa: E402

STARTS = [(x, 0, 0) for x in (150, 300, 350)] + [
    (600, 300, 0),
    (650, 300, 0),
    (700, 350, 0),
    (0, 0, 36),
    (0, 0, 40),
    (0, 0, 44),
    (200, 200, 0),
]

if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "examples" / "calibrate_trials.csv"
    rows = synthetic_trials(
        ROOT / "examples" / "calibrate_fourpad.toml",
        STARTS,
        {"receding_angle_deg": 20.0},
        trials=100,
        spread=(20.0, 20.0, 2.0),
        seed=1,
        method="gradient",
    )
    write_trials(out, rows)
    print(f"wrote {out}")
