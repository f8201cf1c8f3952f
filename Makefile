# Two entry points: `make demo` and `make test`. Both create .venv on first use.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test lint library bench validate clean

$(BIN)/selfalign: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	@touch $@

demo: $(BIN)/selfalign
	$(BIN)/selfalign demo --out out --force

test: $(BIN)/selfalign
	$(BIN)/python -m pytest -q tests
	$(BIN)/python -m pytest -q --nbmake notebooks

lint: $(BIN)/selfalign
	$(BIN)/ruff check .

library: $(BIN)/selfalign
	$(BIN)/python -m patterns.library

bench: $(BIN)/selfalign
	$(BIN)/python benchmarks/landscape.py

# Surface Evolver reference numbers for the finite-meniscus model (~20 min on one core).
validate: $(BIN)/selfalign
	@command -v evolver >/dev/null 2>&1 || { echo "make validate: Surface Evolver ('evolver') is not on PATH; install it with: apt-get install -y evolver-nox"; exit 1; }
	$(BIN)/python validation/evolver.py --out validation/evolver_reference.csv

clean:
	rm -rf $(VENV) out .pytest_cache
