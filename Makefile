# The two commands of the README: `make demo` (main job on a small default) and `make test`.
VENV ?= .venv
PY := $(VENV)/bin/python
export MUJOCO_GL ?= osmesa
export PYOPENGL_PLATFORM ?= osmesa

.PHONY: demo test lint

$(VENV)/.installed: setup.cfg pyproject.toml scripts/setup_env.sh
	VENV=$(VENV) bash scripts/setup_env.sh

demo: $(VENV)/.installed
	$(PY) -m sb3_pilot.experiments.demo

test: $(VENV)/.installed
	$(VENV)/bin/ruff check sb3_pilot tests
	$(VENV)/bin/ruff format --check sb3_pilot tests
	$(PY) -m pytest -n 2 -q tests

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check sb3_pilot tests
	$(VENV)/bin/ruff format --check sb3_pilot tests
