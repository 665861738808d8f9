# Quick start: `make mission` (the cube-mission comparison) and `make test` (all tests).
PY ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -e '.[dev]'
	touch $(STAMP)

.PHONY: venv mission test test-unit lint typecheck bench
venv: $(STAMP)

mission: $(STAMP)
	$(VENV)/bin/gcs mission compare scenarios/cube8.toml --out runs/compare

test: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	$(VENV)/bin/python -m pytest -q tests/unit
	$(VENV)/bin/python -m pytest -q tests/integration

test-unit: $(STAMP)
	$(VENV)/bin/python -m pytest -q tests/unit

lint: $(STAMP)
	$(VENV)/bin/ruff check .

typecheck: $(STAMP)
	$(VENV)/bin/mypy

bench: $(STAMP)
	$(VENV)/bin/python bench/bench_dynamics.py
	$(VENV)/bin/python bench/bench_mavlink.py
	$(VENV)/bin/python bench/bench_control.py
	$(VENV)/bin/python bench/bench_distributed.py
