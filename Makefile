# Set-up is part of every target: `make test`, `make lint` and `make demo` create .venv and install
# into it. Only cft_action is installed; demos, benchmarks, tests and what they share (harness/)
# are imported from this directory, which `python -m` and pytest put on sys.path.
#
# PYTHON picks the interpreter (3.11 or 3.12), e.g. `make test PYTHON=python3.12`. Each Python
# version has its own venv, so that switching needs no `make clean`: .venv for 3.11, the default,
# and .venv-3.12 for 3.12 (VENV=... chooses another directory).
PYTHON ?= $(shell command -v python3.11 || command -v python3)
# The interpreter itself. A PYTHON that does not run falls back to pyenv's copy of that version,
# the newest patch release ($(pyenv root)/versions/3.12.*/bin/python3.12 for python3.12; $PYENV_ROOT
# or ~/.pyenv when pyenv is not on PATH): where only pyenv has 3.12, `command -v python3.12` finds
# pyenv's shim, and the shim refuses to run a version that `pyenv global` did not select.
PYTHON_NAME := $(notdir $(PYTHON))
PYTHON_EXE := $(shell $(PYTHON) -c 'import sys; print(sys.executable)' 2>/dev/null || \
	ls -d "$$(pyenv root 2>/dev/null || echo $${PYENV_ROOT:-$$HOME/.pyenv})"/versions/$(patsubst python%,%,$(PYTHON_NAME)).*/bin/$(PYTHON_NAME) \
	2>/dev/null | sort -V | tail -n 1)
ifeq ($(PYTHON_EXE),)
$(error cannot run PYTHON=$(PYTHON), and pyenv has no $(PYTHON_NAME) either: install that Python or pass PYTHON=/path/to/python)
endif
PYTHON_VERSION := $(shell $(PYTHON_EXE) -c 'import sys; print("%d.%d" % sys.version_info[:2])')
VENV ?= $(if $(filter 3.11,$(PYTHON_VERSION)),.venv,.venv-$(PYTHON_VERSION))
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: test test-kilted kilted-tree lint demo bench clean compat compat-kilted

# [jazzy] is ROS 2 Jazzy from PyPI, so that a machine without ROS needs nothing else.
$(VENV)/bin/python:
	$(PYTHON_EXE) -m venv $(VENV)

$(STAMP): pyproject.toml setup.py $(shell find cft_action/native -name "*.[ch]" -o -name "*.cpp") | $(VENV)/bin/python
	$(PY) -m pip install --quiet --disable-pip-version-check -e '.[jazzy,test,bench,lint]'
	touch $(STAMP)

# TESTS narrows the run to some test files, e.g. `make test TESTS=tests/test_readme.py`.
TESTS ?=
test: $(STAMP)
	$(PY) -m pytest $(TESTS)

# ROS 2 Kilted's wheels (Fast DDS 3.2.2, Python 3.12), in a venv of their own, where the tests that
# apply to Fast DDS 3 run (docs/COMPATIBILITY.md). They run in a copy of this tree (KILTED_TREE):
# an in-place build for Python 3.12 here would replace the Jazzy 3.12 venv's libraries, which have
# the same file names. The copy is built with the wheels already in the venv, so that the build
# finds Fast DDS 3's headers there and builds no Fast DDS 2.14 layout, as `pip install .` does in a
# user's Kilted venv.
KILTED_VENV ?= .venv-kilted
KILTED_PYTHON ?= python3.12
KILTED_TREE := build/kilted-tree
KILTED_TESTS ?= tests/test_fastdds3.py tests/test_build_without_headers.py \
    tests/test_rclpy_contract.py tests/test_errors.py tests/test_sql.py tests/test_filters.py
# The wheels, by a first install (not in place; its build is replaced by the tree's below).
$(KILTED_VENV)/.installed: pyproject.toml
	$(MAKE) --no-print-directory $(KILTED_VENV)/bin/python PYTHON=$(KILTED_PYTHON) VENV=$(KILTED_VENV)
	$(KILTED_VENV)/bin/python -m pip install --quiet --disable-pip-version-check '.[kilted,test]'
	touch $@

kilted-tree: $(KILTED_VENV)/.installed
	rm -rf $(KILTED_TREE) && mkdir -p $(KILTED_TREE)
	git ls-files -z --cached --others --exclude-standard | xargs -0 cp --parents -t $(KILTED_TREE)
	cd $(KILTED_TREE) && $(CURDIR)/$(KILTED_VENV)/bin/python -m pip install --quiet \
	    --disable-pip-version-check --no-deps -e .

test-kilted: kilted-tree
	cd $(KILTED_TREE) && $(CURDIR)/$(KILTED_VENV)/bin/python -m pytest $(KILTED_TESTS)

# ruff and mypy take their settings from pyproject.toml. ruff checks all the code (the library,
# harness/, benchmarks/, tests/, demos/, compat/, setup.py; not the venvs, which it skips); mypy
# the library, harness/, demos/ and compat/.
lint: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy

demo: $(STAMP)
	$(PY) -m demos.load_demo

bench: $(STAMP)
	$(PY) -m benchmarks.sweep

# The test files below, on Fast DDS stacks other than the wheels' (docs/COMPATIBILITY.md): apt's
# (2.14.6, SECURITY=ON, with its own rmw_fastrtps) and the 2.14.x branch head. Not part of
# `make test`. Each stack is a prebuilt directory COMPAT_CACHE/<stack> (what it holds:
# docs/COMPATIBILITY.md, "The stacks"); a missing one fails the run. The tests take 3-4 minutes a
# stack. Results: COMPAT_CACHE/results/<stack>-<time>/.
# The cache of built stacks: $XDG_CACHE_HOME/cft-stack, else ~/.cache/cft-stack.
COMPAT_CACHE ?= $(or $(XDG_CACHE_HOME),$(HOME)/.cache)/cft-stack
COMPAT_STACKS ?= apt-2.14.6 head-2.14.x
COMPAT_TESTS ?= tests/test_guard.py tests/test_guard_filter.py tests/test_uuid_class.py \
    tests/test_node_class.py tests/test_action_client.py

compat: $(STAMP)
	compat/run.sh $(VENV) $(COMPAT_CACHE) "$(COMPAT_STACKS)" $(COMPAT_TESTS)

# The same on Fast DDS 3 stacks under Kilted's wheels (KILTED_VENV, the package in KILTED_TREE as
# for test-kilted): Lyrical's Fast DDS 3.6.2 with its rmw_fastrtps, `wheels` for Kilted's own 3.2.2.
KILTED_COMPAT_STACKS ?= lyrical-3.6.2
KILTED_COMPAT_TESTS ?= $(KILTED_TESTS)
compat-kilted: kilted-tree
	cd $(KILTED_TREE) && compat/run.sh $(CURDIR)/$(KILTED_VENV) $(COMPAT_CACHE) \
	    "$(KILTED_COMPAT_STACKS)" $(KILTED_COMPAT_TESTS)

clean:
	rm -rf .venv .venv-3.* .venv-kilted build *.egg-info cft_action/*.so .mypy_cache .ruff_cache
