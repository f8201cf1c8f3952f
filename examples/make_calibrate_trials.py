"""Write examples/calibrate_trials.csv: a bench table the model itself made.

Ten nominal starts on the scene examples/calibrate_fourpad.toml with the pads' receding
angle at 20 degrees (the scene file says 25), 100 trials each with placement noise of 20 um,
20 um and 2 degrees (seed 1): ``selfalign calibrate`` should find 20 degrees back
(docs/guide/calibrate.md).

Usage: ``python examples/make_calibrate_trials.py [OUT.csv]``
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simulator.design import synthetic_trials, write_trials  # noqa: E402

STARTS = [(x, 0, 0) for x in (150, 250, 300, 325, 350, 375, 400)] + [
    (200, 200, 0),
    (300, -300, 0),
    (250, 100, 0),
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
    )
    write_trials(out, rows)
    print(f"wrote {out}")
