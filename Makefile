# Set-up is part of every target: `make test`, `make lint` and `make demo` create .venv and install
# into it. Only cft_action is installed; demos, benchmarks, tests and what they share (harness/)
# are imported from this directory, which `python -m` and pytest put on sys.path.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: test lint demo bench clean

$(STAMP): pyproject.toml setup.py cft_action/_guard.c cft_action/_guard_filter.c cft_action/_guard.h \
		cft_action/_guard_writer_qos.c \
		cft_action/_reader_lock.c
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -e '.[test,bench,lint]'
	touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest

# ruff and mypy take their settings from pyproject.toml.
lint: $(STAMP)
	$(PY) -m ruff check cft_action
	$(PY) -m mypy

demo: $(STAMP)
	$(PY) -m demos.load_demo

bench: $(STAMP)
	$(PY) -m benchmarks.sweep

clean:
	rm -rf $(VENV) build *.egg-info cft_action/*.so .mypy_cache .ruff_cache
