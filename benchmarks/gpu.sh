#!/usr/bin/env bash
# The GPU benchmark (docs/benchmarks.md, "On a GPU"): the JAX backend checked against SciPy,
# then the 512 px and 4096 px cubes and 10^6 greedy Monte Carlo starts timed, in one table.
# Needs JAX's CUDA build: pip install -e '.[gpu]'. Arguments go to benchmarks/gpu.py
# (--json OUT, --chips exact, --repeats N; --cpu-smoke runs it small on the CPU; --smoke PLAN
# writes the plan without a GPU, running nothing). Give output paths as absolute paths: the
# script runs from the repository root.
set -euo pipefail
cd "$(dirname "$0")/.."
py="${PYTHON:-}"
if [ -z "$py" ]; then
    if [ -x .venv/bin/python ]; then py=.venv/bin/python; else py=python3; fi
fi
"$py" -c "import jax; print(f'jax {jax.__version__}: backend {jax.default_backend()}, devices {jax.devices()}')"
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
exec "$py" benchmarks/gpu.py "$@"
