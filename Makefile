# The README's commands. `make demo` and `make test` work on a fresh clone.
SHELL := /bin/bash
VENV := $(CURDIR)/.venv
PY := $(VENV)/bin/python
PYTHON ?= python3
export CARGO_TERM_COLOR ?= never
# Rust is built for this machine's CPU (AVX2 / AVX-512 where it has them):
# the helper DSP's sums vectorise wider (measured on the 2-core VM: one
# antenna's job 191 -> 153 us, the fusion's 124 -> 74 us, the runtime's p99
# latency about 0.95 -> 0.85 ms). Same results: Rust never fuses or
# reorders floating-point operations on its own. For a build that runs on
# any CPU of the architecture: make setup RUST_TARGET_CPU=generic (cargo
# rebuilds when the flags change). Every cargo call below shares the flags,
# so nothing is built twice.
RUST_TARGET_CPU ?= native
export RUSTFLAGS ?= -C target-cpu=$(RUST_TARGET_CPU)

.PHONY: setup demo demo-live test test-rust test-python bench results clean

# One shared set-up: a virtualenv with pinned dependencies, the Rust
# extension built in release mode and the package installed (editable), so
# that afterwards the CLI is .venv/bin/scattertrack.
setup: $(VENV)/.deps-installed web/dist/index.html
	@echo "setup: building the Rust extension (release) into .venv"
	VIRTUAL_ENV=$(VENV) PATH=$(VENV)/bin:$$PATH $(VENV)/bin/maturin develop --release -m python/Cargo.toml -q
	@test -x $(VENV)/bin/scattertrack

$(VENV)/.deps-installed: requirements-dev.txt
	@echo "setup: installing the pinned Python dependencies into .venv (minutes on a fresh clone)"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements-dev.txt
	touch $@

# The dashboard's front end (docs/dashboard.md): npm installs the locked
# packages, Vite builds web/dist, which `scattertrack dashboard` serves.
# Rebuilt only when its sources or the lockfile change; never committed.
WEB_SOURCES := web/index.html web/vite.config.js web/package.json $(wildcard web/src/*)
web/node_modules/.package-lock.json: web/package-lock.json
	cd web && npm ci --no-audit --no-fund --loglevel=error

web/dist/index.html: web/node_modules/.package-lock.json $(WEB_SOURCES)
	cd web && npm run --silent build

demo: setup
	$(VENV)/bin/scattertrack demo --out out/demo

# The live path (docs/live.md): the reader emulator on loopback serves a
# simulated session over LLRP, with a forced disconnect at 8 s; `live`
# journals and tracks it for 21 s; the journal is then tracked offline.
demo-live: setup
	mkdir -p out/live
	$(VENV)/bin/scattertrack simulate --scenario glac-3d-walls --out out/live/session
	rm -f out/live/reads.csv out/live/track.csv
	$(VENV)/bin/scattertrack emulate-reader --scenario glac-3d-walls --port 15084 --drop-after 8 --linger 5 > out/live/emulator.log 2>&1 & \
	  emulator=$$!; sleep 2; \
	  $(VENV)/bin/scattertrack live --scene out/live/session/scene.toml --llrp 127.0.0.1:15084 \
	    --out out/live/track.csv --journal out/live/reads.csv --duration 21 --no-progress; \
	  status=$$?; kill $$emulator 2>/dev/null; cat out/live/emulator.log; exit $$status
	$(VENV)/bin/scattertrack track --scene out/live/session/scene.toml --reads out/live/reads.csv --out out/live/offline.csv --no-progress

test: setup test-rust test-python

test-rust:
	@echo "test: Rust (scattertrack-core, -dsp, -runtime)"
	cargo test -p scattertrack-core -p scattertrack-dsp -p scattertrack-runtime --release -q

test-python:
	@echo "test: Python (python/tests and the examples in docs/)"
	$(PY) -m pytest -q python/tests docs

# The benchmarks (their list is bench/results.py's BENCHMARKS): each one's
# output is shown and kept in out/bench/; `bench` renders them into
# out/bench/results.md, `results` into docs/results.md (never edited by hand).
bench: setup
	$(PY) bench/results.py

results: setup
	$(PY) bench/results.py --write docs/results.md

clean:
	rm -rf target out $(VENV) python/scattertrack/*.so web/dist web/node_modules

# The layers and the no-cycle contracts (python/pyproject.toml,
# [tool.importlinter]; python/import_contracts.py): an import against the
# layers, or any import cycle, fails the build.
test: test-layers
test-layers: setup
	@echo "test: layers and import cycles (lint-imports)"
	cd python && $(VENV)/bin/lint-imports
