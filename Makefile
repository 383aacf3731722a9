# Two entry points: `make demo` (install + the main job) and `make test` (install + lint + type check + tests).
VENV ?= .venv
PY := $(VENV)/bin/python
NSL := $(VENV)/bin/nsl
export MUJOCO_GL ?= egl
export NSL_HOME ?= $(CURDIR)/.nsl-demo

.PHONY: install lint demo test test-no-bf16 test-slow bench clean

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

# The default suite (under 10 minutes on 2 cores), its 15 slowest tests listed at the end.  Two pytest-xdist workers
# share it, each test module (or each study run's users, tests/conftest.py) on one of them.  On a CPU with bfloat16
# the tests whose behaviour depends on it (marker `precision`) run once more with it switched off (NSL_BF16=0), as
# on a CPU without it; on a CPU without it the first run was that run.
BF16 = $(PY) -c "from nsl.learners.precision import bf16_supported; raise SystemExit(not bf16_supported())"
test: lint
	$(PY) -m pytest -q -n 2 --dist loadgroup --no-loadscope-reorder --durations=15
	if $(BF16); then NSL_BF16=0 $(PY) -m pytest -q -m 'precision and not slow' -p no:cacheprovider; fi

# The whole default suite as on a CPU without bfloat16 (AVX-512 BF16 or AMX).
test-no-bf16: install
	NSL_BF16=0 $(PY) -m pytest -q -n 2 --dist loadgroup --no-loadscope-reorder --durations=15

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
