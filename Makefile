# The two commands of the README: `make demo` (main job on a small default) and `make test`; `make docs` builds docs/.
VENV ?= .venv
PY := $(VENV)/bin/python
export MUJOCO_GL ?= osmesa
export PYOPENGL_PLATFORM ?= osmesa

.PHONY: demo test lint docs

SPHINXBUILD := $(VENV)/bin/sphinx-build -W --keep-going -q -b html docs docs/_build/html

$(VENV)/.installed: setup.cfg pyproject.toml scripts/setup_env.sh
	VENV=$(VENV) bash scripts/setup_env.sh

demo: $(VENV)/.installed
	$(PY) -m sb3_pilot.experiments.demo

test: $(VENV)/.installed
	$(VENV)/bin/ruff check sb3_pilot benchmarks tests
	$(VENV)/bin/ruff format --check sb3_pilot benchmarks tests
	$(PY) -m pytest -n 2 --dist worksteal -q tests
	$(SPHINXBUILD)

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check sb3_pilot benchmarks tests
	$(VENV)/bin/ruff format --check sb3_pilot benchmarks tests

# the docs (Sphinx, Read-the-Docs theme), warnings as errors; open docs/_build/html/index.html
docs: $(VENV)/.installed
	$(SPHINXBUILD)
