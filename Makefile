# Two entry points: `make demo` and `make test`. Both create .venv on first use.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test lint library bench clean

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

clean:
	rm -rf $(VENV) out .pytest_cache
