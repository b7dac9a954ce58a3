# Two commands do all the set-up: `make demo` (main job) and `make test` (tests).
# Each creates .venv with Python 3.12 when it is missing.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
# Test processes (pytest-xdist): one per core; a file's tests stay in one process so its
# fixtures are built once. Files are handed out in collection order, which tests/conftest.py
# starts with the files of tests marked heavy (xdist's own order, most tests first, left the
# one-test end-to-end files for last, one worker running them alone).
# `make test TEST_WORKERS=0` runs them in this process.
TEST_WORKERS ?= auto
# python3.12 may be a pyenv shim that refuses to run; fall back to known install places.
PYTHON312 := $(shell for c in python3.12 $$HOME/.pyenv/versions/3.12*/bin/python3.12 /usr/local/bin/python3.12 /usr/bin/python3.12; do \
	$$c -c 'import sys; assert sys.version_info[:2] == (3, 12)' >/dev/null 2>&1 && { echo $$c; break; }; done)

.PHONY: demo test test-all lint format bench clean clean-cache

$(VENV)/.installed: pyproject.toml
	@test -n "$(PYTHON312)" || { echo "error: Python 3.12 not found (tried python3.12 and ~/.pyenv/versions/3.12*)"; exit 1; }
	@test -x $(PY) || $(PYTHON312) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	@touch $@

demo: $(VENV)/.installed
	$(PY) -m pm_joint.cli demo $(if $(OUT),--out $(OUT),)

test: $(VENV)/.installed
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=30

test-all: $(VENV)/.installed
	$(PY) -m pytest -q -m "slow or not slow"

lint: $(VENV)/.installed
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

format: $(VENV)/.installed
	$(PY) -m ruff format .
	$(PY) -m ruff check --fix .

bench: $(VENV)/.installed
	for f in bench/*.py; do $(PY) $$f || exit 1; done

clean: clean-cache
	rm -rf $(VENV) build dist *.egg-info .pytest_cache .ruff_cache

# numba's cache checks only a kernel's own file, not the kernels it inlines.
clean-cache:
	find . -path ./$(VENV) -prune -o \( -name '*.nbi' -o -name '*.nbc' \) -type f -exec rm -f {} +
