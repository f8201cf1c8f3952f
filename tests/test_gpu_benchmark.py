"""Ready for the first GPU: the GPU benchmark's script runs its steps on small sizes on the
CPU (``--cpu-smoke``) and prints its one table, with the JAX backend agreeing with SciPy's.
No GPU has run it yet; this keeps the code it will run working."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_gpu_benchmark_smoke_run_prints_its_table(tmp_path):
    out = tmp_path / "gpu.json"
    env = os.environ | {"PYTHONWARNINGS": "ignore"}
    r = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "gpu.py"),
            "--cpu-smoke",
            "--repeats",
            "1",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("| step |"))
    assert lines[head] == "| step | backend | work | seconds | poses/s | check |"
    rows = [
        [c.strip() for c in line.strip("|").split("|")]
        for line in lines[head + 2 :]
        if line.startswith("| ")
    ]
    steps = [(row[0], row[1]) for row in rows]
    assert steps == [
        ("landscape (check)", "scipy"),
        ("landscape (check)", "jax"),
        ("cube 64 px", "jax"),
        ("cube 64 px", "scipy"),
        ("cube 128 px", "jax"),
        ("Monte Carlo greedy", "jax"),
    ]
    for row in rows:
        assert float(row[3]) > 0 and float(row[4].replace(",", "")) > 0, row
    assert "ok, limit 1e-06" in rows[1][5]
    assert any(line.startswith("JAX against SciPy: agree to ") for line in lines)
    doc = json.loads(out.read_text())
    assert doc["agree"] <= 1e-6 and doc["machine"]["jax_backend"] == "cpu" and len(doc["rows"]) == 6
    for row in rows[2:5]:  # the cubes against float64, in chip areas
        assert row[5].startswith("max error ") and float(row[5].split()[2]) < 1e-5, row


def test_gpu_benchmark_without_a_gpu_says_how_to_get_one():
    r = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "gpu.py")],
        capture_output=True,
        text=True,
        timeout=300,
        env=os.environ | {"JAX_PLATFORMS": "cpu", "PYTHONWARNINGS": "ignore"},
    )
    assert (
        r.returncode == 2
        and "no GPU visible to JAX" in r.stderr
        and "pip install -e '.[gpu]'" in r.stderr
    ), r.stderr


def test_gpu_extra_is_the_cuda_build_of_the_pinned_jax():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    jax = next(d for d in meta["dependencies"] if d.startswith("jax"))
    assert meta["optional-dependencies"]["gpu"] == [jax.replace("jax", "jax[cuda12]", 1)]
    assert os.access(ROOT / "benchmarks" / "gpu.sh", os.X_OK)
