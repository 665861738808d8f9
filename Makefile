# Quick start: `make mission` (the cube-mission comparison) and `make test` (all tests).
# `make check` is the quick tier (lint, types, unit tests, one distributed smoke run).
PY ?= python3
VENV := .venv
STAMP := $(VENV)/.installed
PYTEST := $(VENV)/bin/python -m pytest -q
# test processes, one per core: the suite is CPU-bound (its integration tests start
# simulators and daemons), and more workers than cores starve lockstep runs into timeouts
# on a loaded machine (docs/testing.md)
TEST_JOBS ?= 2
UNIT_JOBS ?= $(TEST_JOBS)
INTEGRATION_JOBS ?= $(TEST_JOBS)
SMOKE_DIR := $(VENV)/smoke
# a standard client the tests drive unmodified; --no-deps: its map and camera modules'
# vtk and opencv (200 MB) are never loaded by mavproxy.py on a UDP link (its other
# dependencies are in the dev extra)
CLIENT_TOOLS := 'mavproxy>=1.8.70'

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -e '.[dev]'
	$(VENV)/bin/pip install --quiet --no-deps $(CLIENT_TOOLS)
	touch $(STAMP)

.PHONY: venv mission test check static smoke test-all test-unit test-unit-quick test-integration lint typecheck warm bench bytecode
venv: $(STAMP)

# every module's bytecode written once (only what changed since): where the environment
# sets PYTHONDONTWRITEBYTECODE, as CI machines often do, each of the hundreds of Python
# processes a test run starts would otherwise compile the project from source again
# (about 0.2 s of CPU each); an existing .pyc is still read, and a stale one is ignored
bytecode: $(STAMP)
	$(VENV)/bin/python -m compileall -q -j 0 swarm_common vehicle_sim offboard gcs tests bench > /dev/null

# PORT_OFFSET=N forces the port offset (a busy port: exit 2 before anything starts);
# without it the first offset 0, 1000, ... whose ports are all free is chosen
PORT_OFFSET ?=
mission: $(STAMP)
	$(VENV)/bin/gcs mission compare scenarios/cube8.toml --out runs/compare \
	  $(if $(PORT_OFFSET),--port-offset $(PORT_OFFSET))

test: bytecode static test-all

# the quick tier: unit tests marked `full` (a few seconds each) run in `make test` only
check: bytecode static test-unit-quick smoke

# lint, then the type check beside the kernels' first compilation (gcs.mission.warmup):
# each uses one core, so side by side they take the longer one's time, not the sum
static: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/python -c 'from gcs.mission.warmup import compile_kernels; compile_kernels()' & \
	  warm=$$!; $(VENV)/bin/mypy; types=$$?; wait $$warm; kernels=$$?; \
	  test $$types -eq 0 && test $$kernels -eq 0

# unit and integration tests in one pytest session: one start of the workers, and the
# unit tests fill the gaps the long integration tests leave at the end (slow ones first:
# tests/conftest.py)
test-all: $(STAMP)
	$(PYTEST) -n $(TEST_JOBS) tests

test-unit: $(STAMP)
	$(PYTEST) -n $(UNIT_JOBS) tests/unit

test-unit-quick: $(STAMP)
	$(PYTEST) -n $(UNIT_JOBS) -m 'not full' tests/unit

test-integration: $(STAMP)
	$(PYTEST) -n $(INTEGRATION_JOBS) tests/integration

# one distributed run: vehicle-sim, a Zenoh router and eight daemons as processes
smoke: $(STAMP)
	rm -rf $(SMOKE_DIR)
	$(VENV)/bin/gcs mission run scenarios/cube8.toml --method dcbf --duration 2 --out $(SMOKE_DIR)

lint: $(STAMP)
	$(VENV)/bin/ruff check .

typecheck: $(STAMP)
	$(VENV)/bin/mypy

warm: $(STAMP)
	$(VENV)/bin/python -c 'from gcs.mission.warmup import compile_kernels; compile_kernels()'

bench: $(STAMP)
	$(VENV)/bin/python bench/bench_dynamics.py
	$(VENV)/bin/python bench/bench_mavlink.py
	$(VENV)/bin/python bench/bench_control.py
	$(VENV)/bin/python bench/bench_distributed.py
