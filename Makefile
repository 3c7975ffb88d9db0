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

.PHONY: test test-kilted kilted-tree test-asan lint demo bench clean compat compat-kilted fuzz \
    fuzz-toolchain

# [jazzy] is ROS 2 Jazzy from PyPI, so that a machine without ROS needs nothing else.
$(VENV)/bin/python:
	$(PYTHON_EXE) -m venv $(VENV)

$(STAMP): pyproject.toml setup.py $(shell find cft_action/native -name "*.[ch]" -o -name "*.[ch]pp") | $(VENV)/bin/python
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
KILTED_TESTS ?= tests/test_fastdds3.py tests/test_fastdds3_replies.py tests/test_fastdds3_feedback.py \
    tests/test_fastdds3_status.py tests/test_fastdds3_programs.py tests/test_sros2.py \
    tests/test_build_without_headers.py tests/test_rclpy_contract.py tests/test_errors.py \
    tests/test_sql.py tests/test_filters.py
# The wheels, by a first install (not in place; its build is replaced by the tree's below).
$(KILTED_VENV)/.installed: pyproject.toml
	$(MAKE) --no-print-directory $(KILTED_VENV)/bin/python PYTHON=$(KILTED_PYTHON) VENV=$(KILTED_VENV)
	$(KILTED_VENV)/bin/python -m pip install --quiet --disable-pip-version-check '.[kilted,test]'
	touch $@

# A copy of this tree's files (tracked, and untracked but not ignored) in $(1), for a build of the
# C libraries that must not replace this tree's own.
define copy-tree
	rm -rf $(1) && mkdir -p $(1)
	git ls-files -z --cached --others --exclude-standard | xargs -0 cp --parents -t $(1)
endef

# $(1): a copy of this tree, the package built in it for KILTED_VENV against the Fast DDS headers
# in $(2) (CFT_FASTDDS_INCLUDE; empty: those setup.py finds, the wheels').
define kilted-build
	$(call copy-tree,$(1))
	cd $(1) && CFT_FASTDDS_INCLUDE=$(2) $(CURDIR)/$(KILTED_VENV)/bin/python -m pip install \
	    --quiet --disable-pip-version-check --no-deps -e .
endef

kilted-tree: $(KILTED_VENV)/.installed
	$(call kilted-build,$(KILTED_TREE),)

test-kilted: kilted-tree
	cd $(KILTED_TREE) && $(CURDIR)/$(KILTED_VENV)/bin/python -m pytest $(KILTED_TESTS)

# The guard's and the client's C libraries built with AddressSanitizer and UBSan (in a copy of the
# tree, ASAN_TREE), under the test files that run them: every process the tests start has the
# sanitizers' runtimes preloaded (the guard's preload comes after them, hence
# verify_asan_link_order=0; PYTHONPATH: the `cft-action` command imports the copy too), and the
# first finding ends that process with its report, written to
# $(ASAN_TREE)/sanitizer.<pid>: any such file fails the target, whatever the tests said. Leaks are
# not checked (the Python interpreter's own would drown them).
ASAN_TREE := build/asan-tree
ASAN_TESTS ?= tests/test_guard.py tests/test_guard_filter.py tests/test_uuid_class.py \
    tests/test_node_class.py tests/test_reader_lock.py tests/test_rate_limit.py \
    tests/test_goal_status.py tests/test_status_wire.py tests/test_replies.py \
    tests/test_own_responses.py tests/test_heartbeats.py tests/test_signatures.py \
    tests/test_reader_filter_limit.py tests/test_parameter_events.py tests/test_hostile.py
SANITIZE := -fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer
# A SIGSEGV is reported by ASan too (allow_user_segv_handler=0: Python's faulthandler would take it).
SANITIZER_LOG := allow_user_segv_handler=0:log_path=$(CURDIR)/$(ASAN_TREE)/sanitizer
test-asan: $(STAMP)
	$(call copy-tree,$(ASAN_TREE))
	cd $(ASAN_TREE) && CFLAGS='$(SANITIZE)' LDFLAGS='$(SANITIZE)' $(CURDIR)/$(PY) setup.py -q \
	    build_ext --inplace
	cd $(ASAN_TREE) && \
	    LD_PRELOAD="$$(cc -print-file-name=libasan.so) $$(cc -print-file-name=libubsan.so)" \
	    ASAN_OPTIONS=detect_leaks=0:verify_asan_link_order=0:halt_on_error=1:$(SANITIZER_LOG) \
	    UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1:$(SANITIZER_LOG) \
	    PYTHONPATH=$(CURDIR)/$(ASAN_TREE) $(CURDIR)/$(PY) -m pytest $(ASAN_TESTS)
	@! ls $(ASAN_TREE)/sanitizer.* 2>/dev/null || { cat $(ASAN_TREE)/sanitizer.*; exit 1; }

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
    tests/test_node_class.py tests/test_action_client.py tests/test_sros2.py

compat: $(STAMP)
	compat/run.sh $(VENV) $(COMPAT_CACHE) "$(COMPAT_STACKS)" $(COMPAT_TESTS)

# The same on Fast DDS 3 stacks under Kilted's wheels (KILTED_VENV): Lyrical's Fast DDS 3.6.2 with its rmw_fastrtps, `wheels` for Kilted's own 3.2.2.
# The package is built in a copy of its own (KILTED_COMPAT_TREE) against the first stack's Fast DDS
# headers, as a user of that stack builds it (Lyrical's 3.6.2: the guard's Fast DDS 3 layer,
# native/guard/fastdds3/, is built and linked against it); the wheels' 3.2.2 where it has none.
KILTED_COMPAT_STACKS ?= lyrical-3.6.2
KILTED_COMPAT_TESTS ?= $(KILTED_TESTS)
KILTED_COMPAT_TREE := build/kilted-compat-tree
KILTED_COMPAT_HEADERS ?= $(wildcard $(COMPAT_CACHE)/$(firstword $(KILTED_COMPAT_STACKS))/install/include)
compat-kilted: $(KILTED_VENV)/.installed
	$(call kilted-build,$(KILTED_COMPAT_TREE),$(KILTED_COMPAT_HEADERS))
	cd $(KILTED_COMPAT_TREE) && compat/run.sh $(CURDIR)/$(KILTED_VENV) $(COMPAT_CACHE) \
	    "$(KILTED_COMPAT_STACKS)" $(KILTED_COMPAT_TESTS)

# libFuzzer over every C entry point that parses another participant's bytes (fuzz/README.md):
# each harness of fuzz/ built into build/fuzz/ with ASan and UBSan, then run for FUZZ_SECONDS on a
# copy of its corpus (fuzz/corpus/<target>/, regressions included, so the repository's is never
# written). Any crash, sanitizer report, leak or 10 s hang fails the run; the input is left in
# build/fuzz/artifacts/. CI runs `make fuzz FUZZ_SECONDS=10`. The harnesses read Fast DDS objects at
# the offsets of the headers the venv has: _fastdds_layout.h, generated as setup.py generates it.
FUZZ_SECONDS ?= 60
FUZZ_TARGETS := uuid node rate filter_class status_trim guard_status guard_filter guard_programs \
    writer_marks
FUZZ_DIR := build/fuzz
FUZZ_CC := clang-14
FUZZ_CFLAGS := -g -O1 -Wall -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
    -I$(FUZZ_DIR) -Icft_action/native -Icft_action/native/reader -Icft_action/native/guard
NATIVE := cft_action/native
# The library's files each harness links (a harness that includes one, for its statics, has it not).
FUZZ_SOURCES_uuid := $(NATIVE)/_uuid_program.c
FUZZ_SOURCES_node := $(NATIVE)/_node_program.c
FUZZ_SOURCES_rate := $(NATIVE)/_rate_program.c
FUZZ_CLASSES := $(NATIVE)/_filter_class.c $(NATIVE)/_uuid_program.c $(NATIVE)/_node_program.c \
    $(NATIVE)/_rate_program.c
FUZZ_SOURCES_filter_class := $(NATIVE)/reader/_status_trim.c $(FUZZ_CLASSES)
FUZZ_SOURCES_guard_status := $(NATIVE)/guard/_guard_goals.c $(NATIVE)/guard/_guard_log.c \
    $(NATIVE)/_endpoint_times.c fuzz/guard_stubs.c
FUZZ_SOURCES_guard_filter := $(NATIVE)/guard/_guard_status.c $(FUZZ_SOURCES_guard_status) \
    $(FUZZ_CLASSES)
FUZZ_SOURCES_guard_programs := $(NATIVE)/guard/_guard_programs.c $(NATIVE)/guard/_guard_feedback.c \
    $(NATIVE)/guard/_guard_status.c $(FUZZ_SOURCES_guard_status) $(FUZZ_CLASSES)
FUZZ_SOURCES_writer_marks := $(NATIVE)/reader/_patch.c
# clang reads the cleanup variable of _guard_status.c's cft_rtps_is_relevant as unused.
FUZZ_FLAGS_guard_status := -Wno-unused-variable
FUZZ_FLAGS_guard_filter := -Wno-unused-variable
FUZZ_FLAGS_guard_programs := -Wno-unused-variable

fuzz-toolchain:
	@command -v $(FUZZ_CC) >/dev/null && dpkg -s libfuzzer-14-dev >/dev/null 2>&1 || \
	    { apt-get update && apt-get install -y clang-14 libfuzzer-14-dev llvm-14; }

$(FUZZ_DIR)/_fastdds_layout.h: setup.py $(NATIVE)/_fastdds_layout.cpp $(STAMP)
	$(PY) -c "import pathlib, runpy, setuptools; setuptools.setup = lambda **kw: None; \
	    runpy.run_path('setup.py')['layout_header'](pathlib.Path('$(FUZZ_DIR)'))"

$(FUZZ_DIR)/fuzz_%: fuzz/fuzz_%.c fuzz/fuzz_common.h fuzz/guard_stubs.c $(FUZZ_DIR)/_fastdds_layout.h \
    $(shell find cft_action/native -name "*.[ch]") | fuzz-toolchain
	$(FUZZ_CC) $(FUZZ_CFLAGS) $(FUZZ_FLAGS_$*) -o $@ $< $(FUZZ_SOURCES_$*) -ldl -lpthread

fuzz: $(addprefix $(FUZZ_DIR)/fuzz_,$(FUZZ_TARGETS))
	@failed=; for t in $(FUZZ_TARGETS); do \
	    rm -rf $(FUZZ_DIR)/corpus/$$t && mkdir -p $(FUZZ_DIR)/corpus/$$t $(FUZZ_DIR)/artifacts && \
	    cp fuzz/corpus/$$t/* $(FUZZ_DIR)/corpus/$$t/ && \
	    if nice -n 10 $(FUZZ_DIR)/fuzz_$$t -max_total_time=$(FUZZ_SECONDS) -timeout=10 \
	        -print_final_stats=1 -artifact_prefix=$(FUZZ_DIR)/artifacts/$$t- \
	        $(FUZZ_DIR)/corpus/$$t > $(FUZZ_DIR)/$$t.log 2>&1; then \
	      echo "fuzz_$$t: $$(grep -o 'Done [0-9]* runs in [0-9]* second' $(FUZZ_DIR)/$$t.log)," \
	          "$$(grep -o 'cov: [0-9]* ft: [0-9]*' $(FUZZ_DIR)/$$t.log | tail -n 1)"; \
	    else failed="$$failed $$t"; tail -n 60 $(FUZZ_DIR)/$$t.log; fi; \
	done; test -z "$$failed" || { echo "fuzz: findings in$$failed (their inputs: $(FUZZ_DIR)/artifacts/)"; exit 1; }

clean:
	rm -rf .venv .venv-3.* .venv-kilted build *.egg-info cft_action/*.so .mypy_cache .ruff_cache
