# One-command entry points; each sets up .venv first (CPU torch before the package, never CUDA).
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: setup test demo quick selftest

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[dev]'
	touch $@

test: setup
	$(BIN)/ruff check aisdati tests benchmarks
	$(BIN)/pytest

demo: setup
	bash scripts/demo.sh

quick: setup
	$(BIN)/aisdati selftest --quick --out runs/quick

selftest: setup
	$(BIN)/aisdati selftest --out runs/table1
