# Two entry points: `make demo` (install + the main job) and `make test` (install + lint + type check + tests).
VENV ?= .venv
PY := $(VENV)/bin/python
NSL := $(VENV)/bin/nsl
export MUJOCO_GL ?= egl
export NSL_HOME ?= $(CURDIR)/.nsl-demo

.PHONY: install lint demo test test-slow bench clean

$(VENV)/.installed: pyproject.toml
	@command -v python3 >/dev/null || { echo "python3 (>= 3.11) is required"; exit 1; }
	python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(PY) -m nsl.commands._doctor
	touch $@

install: $(VENV)/.installed

demo: install
	bash scripts/demo.sh

lint: install
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	PY=$(PY) bash scripts/typecheck.sh

test: lint
	$(PY) -m pytest -q

test-slow: install
	$(PY) -m pytest -q -m slow

bench: install
	$(NSL) bench env --json
	$(NSL) bench data --json
	$(NSL) bench learner --json
	$(NSL) bench eval --json
	$(NSL) bench cluster --json

clean:
	rm -rf $(VENV) .nsl-demo
