"""Every script in benchmarks/ runs: its ``--smoke OUT`` mode (smallest sizes, one repeat)
in a fresh process exits 0 and writes its table or JSON to OUT, and nothing else into the
repository (never benchmarks/results/ or the documentation's images).

``benchmarks/gpu.sh`` needs a GPU for its run: its ``--smoke`` writes the run's plan without
one (arguments, the hooks it imports, the sizes of every step); the steps themselves run on
the CPU, small, in tests/test_gpu_benchmark.py (``benchmarks/gpu.py --cpu-smoke``). The
helper modules ``_memory.py`` and ``_smoke.py`` are imported by the scripts, not run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"

#: script -> (the smoke run's file name, extra arguments, what its table must hold).
SMOKE = {
    "accuracy.py": ("accuracy.md", [], "| baseline | - |"),
    "calibrate.py": ("calibrate.md", [], "| receding_angle_deg | 20 |"),
    "design_freeform.py": ("design_freeform.json", [], '"seconds_per_iteration"'),
    "dynamics_calibration.py": ("dynamics.md", [], "| (500, 0, 0) | overdamped |"),
    "footprint.py": ("footprint.json", [], '"ratio"'),
    "landscape.py": ("landscape.md", [], "| 64 | exact | selfalign |"),
    "meniscus_tables.py": ("meniscus.md", [], "| square_200 |"),
    "montecarlo.py": ("montecarlo.md", [], "| greedy | 64 |"),
    "refusals.py": ("refusals.md", [], "refuse over-budget landscape:"),
    "sweep.py": ("sweep.json", [], '"workers_1"'),
    "trajectories.py": ("trajectories.md", [], "same path: True"),
    "yield_table.py": ("yield.md", [], "| (50, 0) |"),
}
#: Files beside OUT that a smoke run writes too (its figure, its JSON).
BESIDE = {
    "accuracy.py": (".json", ".png"),
    "dynamics_calibration.py": (".png",),
    "landscape.py": (".json",),
    "meniscus_tables.py": (".png",),
    "trajectories.py": (".png", ".json"),
}


def _tracked_state() -> str:
    """What git sees changed or new in the repository (a smoke run must add nothing)."""
    r = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=all", "--", "benchmarks", "docs"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    return r.stdout if r.returncode == 0 else ""


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = os.environ | {
        "PYTHONPATH": str(ROOT),
        "PYTHONWARNINGS": "ignore",
        "MPLBACKEND": "Agg",
        "PYTHON": sys.executable,
    }
    cache = os.environ.get("SELFALIGN_TEST_JAX_CACHE")
    if cache:  # the suite's JAX compilation cache (tests/conftest.py), shared by these runs too
        env |= {
            "JAX_COMPILATION_CACHE_DIR": cache,
            "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
            "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "-1",
        }
    return subprocess.run(args, capture_output=True, text=True, cwd=cwd, env=env, timeout=600)


def test_every_benchmark_script_has_a_smoke_run():
    scripts = {p.name for p in BENCH.iterdir() if p.suffix in (".py", ".sh")}
    helpers = {"_memory.py", "_smoke.py"}
    assert scripts - helpers == set(SMOKE) | {"gpu.py", "gpu.sh"}


@pytest.mark.parametrize("script", sorted(SMOKE))
def test_benchmark_smoke_run_writes_its_table(tmp_path, script):
    name, extra, needle = SMOKE[script]
    out = tmp_path / name
    before = _tracked_state()
    r = _run([sys.executable, str(BENCH / script), "--smoke", str(out), *extra], tmp_path)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    text = out.read_text()
    assert needle in text, text[:2000]
    if out.suffix == ".json":
        json.loads(text)
    for suffix in BESIDE.get(script, ()):
        assert out.with_suffix(suffix).stat().st_size > 0, suffix
    assert _tracked_state() == before  # nothing written into benchmarks/ or docs/


def test_gpu_script_smoke_run_writes_the_plan_without_a_gpu(tmp_path):
    out = tmp_path / "plan.json"
    before = _tracked_state()
    r = _run(["bash", str(BENCH / "gpu.sh"), "--smoke", str(out), "--repeats", "1"], tmp_path)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    doc = json.loads(out.read_text())
    assert [s["step"] for s in doc["steps"]] == [
        "landscape (check)",
        "cube 512 px",
        "cube 4096 px",
        "Monte Carlo greedy",
    ]
    big = doc["steps"][2]
    assert big["output_shape"] == [46, 8191, 8191] and big["output_MB"] > 10_000
    assert doc["steps"][3] == {
        "step": "Monte Carlo greedy",
        "backends": ["jax"],
        "starts": 1_000_000,
        "chunk": 65536,
    }
    assert doc["gpu_visible"] == (doc["machine"]["jax_backend"] == "gpu")
    assert "wrote the plan to" in r.stdout
    assert _tracked_state() == before


@pytest.mark.parametrize(
    "script",
    ["gpu.py", "sweep.py"],  # both check --smoke before importing the engine
)
def test_smoke_run_refuses_to_write_into_the_results(tmp_path, script):
    target = BENCH / "results" / "smoke.md"
    r = _run([sys.executable, str(BENCH / script), "--smoke", str(target)], tmp_path)
    assert r.returncode == 2 and "never writes into" in r.stderr, r.stderr
    assert not target.exists()
