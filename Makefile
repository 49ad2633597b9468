# One-command entry points; each sets up .venv first (CPU torch before the package, never CUDA).
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: setup test demo quick selftest docs browser postgres bench

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[dev]'
	touch $@

test: setup browser postgres
	$(BIN)/ruff check aisdati tests benchmarks scripts
	$(BIN)/pytest -n 2 --dist loadfile

# Headless Chromium (Debian's package) for the offline-map test, installed system-wide (as root,
# with apt-get) and said so first; where it cannot be installed (not root, no apt-get, no
# registry) that test skips with a message instead of failing.
browser:
	@command -v chromium >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null \
	  && echo "installing Debian's chromium system-wide (apt-get install chromium) for the offline-map browser test" \
	  && { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; } \
	  >/dev/null 2>&1; } || echo "chromium could not be installed: the offline-map browser test will skip"

# A PostgreSQL server (Debian's package) for the watch's database test, which starts a throwaway
# cluster of its own; installed system-wide and said so first, as chromium is; where it cannot be
# installed that test skips with a message.
postgres:
	@ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 || command -v initdb >/dev/null 2>&1 || { \
	  [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null \
	  && echo "installing Debian's postgresql system-wide (apt-get install postgresql) for the watch's database test" \
	  && { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq postgresql; } \
	  >/dev/null 2>&1; } || echo "postgresql could not be installed: the watch's PostgreSQL test will skip"

demo: setup
	bash scripts/demo.sh

quick: setup
	$(BIN)/aisdati selftest --quick --out runs/quick

selftest: setup
	$(BIN)/aisdati selftest --out runs/table1

# the documentation site (mkdocs.yml) into build/site, failing on any warning or broken link
docs: setup
	$(BIN)/mkdocs build --strict

# the lasting speed and memory benchmarks at small sizes (a few minutes on 2 cores): each prints
# its table, and its rows go as JSON to $(BENCH_JSON)/<script>.json (benchmarks/README.md). The
# full sizes are each script without the size options (JSON in benchmarks/results/); the
# detection-quality grids train models for hours and are not run here, e.g.
#   $(BIN)/python benchmarks/detection_quality.py --seeds 0,1,2
#   $(BIN)/python benchmarks/detection_quality.py --forward --data kitimat --train-seeds 0,1,2
#   $(BIN)/python benchmarks/pooled_grid.py runs/quality/<area>/forward-s1 [more grids]
#   $(BIN)/python benchmarks/coastal_areas.py
BENCH_JSON ?= benchmarks/results/quick
bench: setup
	$(BIN)/python benchmarks/dtw_speed.py --json $(BENCH_JSON)/dtw_speed.json
	$(BIN)/python benchmarks/ashore_speed.py --sizes 100000,1000000 \
	  --json $(BENCH_JSON)/ashore_speed.json
	$(BIN)/python benchmarks/ais_speed.py --train-steps 30 --tracks 20 --rollouts 2 \
	  --json $(BENCH_JSON)/ais_speed.json
	$(BIN)/python benchmarks/detection_speed.py --tracks 100 --points 200 --draws 4 --before 5 \
	  --json $(BENCH_JSON)/detection_speed.json
	$(BIN)/python benchmarks/routes_speed.py --tracks 10000,100000 \
	  --json $(BENCH_JSON)/routes_speed.json
	$(BIN)/python benchmarks/selftest_speed.py --steps 5 --repeats 1 \
	  --json $(BENCH_JSON)/selftest_speed.json
	$(BIN)/python benchmarks/ingest_speed.py --rows 1000000 --work-dir data/raw/bench-quick \
	  --json $(BENCH_JSON)/ingest_speed.json
	$(BIN)/python benchmarks/ingest_memory.py --bomb-mb 20 --members 300 \
	  --work-dir data/raw/bench-hostile-quick --json $(BENCH_JSON)/ingest_memory.json
	$(BIN)/python benchmarks/scale.py --rows 1200000 --stages ingest \
	  --work-dir data/raw/scale-quick --json $(BENCH_JSON)/scale.json
