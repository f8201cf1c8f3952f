# Two entry points: `make demo` and `make test`. Both create .venv on first use: the demo
# installs selfalign and its own dependencies only; the tests add the `test` extra (pytest,
# hypothesis, ruff, the notebook runner and the `docs` extra's mkdocs tool chain), `make docs`
# the `docs` extra alone.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test docs serve lint library bench validate validate-pinned validate-defects validate-fourpad clean

$(BIN)/selfalign: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e .
	@touch $@

# Stamps of the extras installed on top (re-installed when pyproject.toml changes).
$(VENV)/.extra-test: $(BIN)/selfalign
	$(BIN)/pip install --quiet -e '.[test]'
	@touch $@

$(VENV)/.extra-docs: $(BIN)/selfalign
	$(BIN)/pip install --quiet -e '.[docs]'
	@touch $@

demo: $(BIN)/selfalign
	$(BIN)/selfalign demo --out out --force

# The manual as a site (mkdocs-material, API reference by mkdocstrings): `make docs` writes
# site/; `make test` builds it too, in strict mode, so a broken link or a citation the pages
# cannot resolve fails the tests (no --quiet: it would hide the warnings strict mode counts).
MKDOCS = NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

# The tests run in parallel (pytest-xdist, from the `test` extra): PYTEST_WORKERS processes
# (2, CI's cores; `make test PYTEST_WORKERS=auto` takes one per core, `=0` runs serially),
# the 25 slowest tests listed at the end. `--dist loadgroup`: tests marked with one
# `xdist_group` run on one worker, in order (tests/conftest.py). Hypothesis draws the `ci` profile's examples
# (tests/conftest.py; HYPOTHESIS_PROFILE=dev for random ones).
# Then the numerical landscape and energy tests (marked `fft`) once more under each FFT
# backend, forced by SELFALIGN_FFT_BACKEND (the first pass takes the machine's default:
# OpenCV for float32 where it runs in Intel's IPP, else SciPy): a bound tuned to one
# backend's round-off fails here, not on the next machine. The pytest stages share one JAX
# compilation cache (SELFALIGN_TEST_JAX_CACHE, tests/conftest.py: a fresh temporary folder,
# removed when they end), so a rerun does not compile again what the first stage compiled.
# The suite compiles far more than it computes (small landscapes; each stepper, grid and
# method compiled once): XLA's CPU backend at optimisation level 0 compiles the diffrax
# steppers about a fifth faster (tests/test_montecarlo_dynamics.py: 97 -> 77 s of CPU) and
# runs them a little slower; without LLVM's expensive passes (as JAX's own
# jax_disable_most_optimizations sets) they compile another 13-15 % faster (the batch-equals-
# single tests of test_friction.py and test_montecarlo_dynamics.py: 46.5 -> 39.5 and 59.2 ->
# 51.6 s of CPU). The bounds come from the dtype's round-off and the quantity's
# scale, which holds for any instruction selection (as on another CPU). The tests marked
# `xla_exact` compare two compiled programs (a vmapped batch and single runs) bit for bit,
# which holds for the same optimisation only: they run in a stage of their own as XLA
# compiles for users. `make test TEST_XLA_FLAGS=` runs every stage that way.
TEST_XLA_FLAGS ?= --xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true
PYTEST_WORKERS ?= 2
HYPOTHESIS_PROFILE ?= ci
FFT_BACKENDS ?= scipy opencv jax

test: $(VENV)/.extra-test
	cache="$$(mktemp -d)"; trap 'rm -rf "$$cache"' EXIT; export SELFALIGN_TEST_JAX_CACHE="$$cache"; \
	XLA_FLAGS="$(TEST_XLA_FLAGS) $$XLA_FLAGS" SELFALIGN_HYPOTHESIS_PROFILE=$(HYPOTHESIS_PROFILE) $(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist loadgroup --durations=25 -m "not xla_exact" tests || exit 1; \
	echo "as XLA compiles for users:"; \
	SELFALIGN_HYPOTHESIS_PROFILE=$(HYPOTHESIS_PROFILE) $(BIN)/python -m pytest -q -p no:xdist -m xla_exact tests || exit 1; \
	for b in $(FFT_BACKENDS); do \
		echo "FFT backend $$b:"; \
		XLA_FLAGS="$(TEST_XLA_FLAGS) $$XLA_FLAGS" SELFALIGN_FFT_BACKEND=$$b SELFALIGN_HYPOTHESIS_PROFILE=$(HYPOTHESIS_PROFILE) $(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist loadgroup -m "fft and not xla_exact" tests || exit 1; \
	done
	$(BIN)/python -m pytest -q --nbmake notebooks
	d="$$(mktemp -d)" && $(MKDOCS) --site-dir "$$d" && rm -rf "$$d"

docs: $(VENV)/.extra-docs
	$(MKDOCS) --site-dir site

# The manual served live at http://127.0.0.1:8000 (rebuilt on every change); a built site/ is
# read served too (python3 -m http.server -d site 8000): opened from disk its links lead to folders.
serve: $(VENV)/.extra-docs
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs serve

# The lint tools (the `dev` extra: pyright, the SciPy stubs, pre-commit) on top of the test environment.
$(BIN)/pyright: $(VENV)/.extra-test
	$(BIN)/pip install --quiet -e '.[dev]'
	@touch $@

lint: $(BIN)/pyright
	$(BIN)/ruff check .
	$(BIN)/pyright --pythonpath $(BIN)/python
	$(BIN)/ruff format --check .

library: $(BIN)/selfalign
	$(BIN)/python -m patterns.library

bench: $(BIN)/selfalign
	$(BIN)/python benchmarks/landscape.py --json benchmarks/results/landscape.json
	$(BIN)/python benchmarks/design_freeform.py --repeat 3 --json benchmarks/results/design_freeform.json

# Surface Evolver reference numbers (validation/README.md; hours on one core: pinned single pad
# ~20 min, pinned defects ~20 min, four-pad paths with free contact lines ~2 h).
EVOLVER_CHECK = @command -v evolver >/dev/null 2>&1 || { echo "make validate: Surface Evolver ('evolver') is not on PATH; install it with: apt-get install -y evolver-nox"; exit 1; }

validate: validate-pinned validate-defects validate-fourpad

validate-pinned: $(BIN)/selfalign
	$(EVOLVER_CHECK)
	$(BIN)/python validation/evolver.py --out validation/evolver_reference.csv

validate-defects: $(BIN)/selfalign
	$(EVOLVER_CHECK)
	$(BIN)/python validation/evolver_defects.py --out validation/evolver_defects.csv

validate-fourpad: $(BIN)/selfalign
	$(EVOLVER_CHECK)
	$(BIN)/python validation/evolver_fourpad.py --out validation/evolver_fourpad.csv

clean:
	rm -rf $(VENV) out site .pytest_cache
