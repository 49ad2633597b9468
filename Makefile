# One-command entry points; each sets up .venv first (CPU torch before the package, never CUDA).
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: setup test demo quick selftest docs browser

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[dev]'
	touch $@

test: setup browser
	$(BIN)/ruff check aisdati tests benchmarks scripts
	$(BIN)/pytest -n 2 --dist loadfile

# Headless Chromium (Debian's package) for the offline-map test; where it cannot be installed
# (not root, no apt-get, no registry) that test skips with a message instead of failing.
browser:
	@command -v chromium >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null \
	  && { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; } \
	  >/dev/null 2>&1; } || echo "chromium could not be installed: the offline-map browser test will skip"

demo: setup
	bash scripts/demo.sh

quick: setup
	$(BIN)/aisdati selftest --quick --out runs/quick

selftest: setup
	$(BIN)/aisdati selftest --out runs/table1

# the documentation site (mkdocs.yml) into build/site, failing on any warning or broken link
docs: setup
	$(BIN)/mkdocs build --strict
