# dualprobe: every target does its own set-up on a fresh Debian 12 machine (root or sudo for
# apt-get; python3, python3-venv, git, make, ca-certificates assumed: README).
SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
CMAKE := $(VENV)/bin/cmake
CTEST := $(VENV)/bin/ctest
# The Debian packages: tools/build-deps.txt, the one list (`make demo` installs the demo set,
# `make test` and the other targets the test set, which includes the demo set).
CHECK_DEPS := PYTHON=$(PYTHON) tools/check-build-deps
STAMP := build/.stamps

.PHONY: all demo test setup setup-demo deb deb-demo venv venv-demo venv-deps cpp-test \
	asan-test pytest lint stubs firmware soak bench paper clean

all: test

demo: setup-demo
	$(VENV)/bin/dualprobe demo --out out/demo

# One C++ build: the ASan/UBSan one (clang, CMakePresets.json), with every ctest test (the C API,
# the consumer project, the fuzz target, the firmware on QEMU). `make cpp-test` is the same
# tests in an optimised GCC build, for local use: not part of `make test`, whose time CI caps.
test: setup asan-test lint pytest
# ctest's firmware.host_vs_reference has just run tests/python/test_firmware.py on the sanitised
# host build; pytest alone would build its own host firmware (~4 min of CPU) for the same tests.
test: PYTEST_ARGS = --ignore=tests/python/test_firmware.py

# setup-demo: a C++ compiler, Eigen, Python headers and the package (no test extras);
# setup: everything the tests use (clang and its fuzzer runtime, the ARM toolchain, QEMU, ...).
# The Debian packages and the Python dependencies are installed in parallel (the virtual
# environment needs only what is assumed), then the extension is built, which needs both.
setup-demo:
	@$(MAKE) --no-print-directory -j2 deb-demo venv-deps
	@$(MAKE) --no-print-directory venv-demo
setup:
	@$(MAKE) --no-print-directory -j2 deb venv-deps
	@$(MAKE) --no-print-directory venv

# Install only what is missing (a prepared machine pays nothing), then check that every tool
# and runtime file is really there: a missing one stops here with one line naming its package.
define install-debs
	@missing=""; for p in $$(tools/check-build-deps --packages $(1)); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "apt-get install:$$missing"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -qq; \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	fi
	@$(CHECK_DEPS) $(1)
endef

deb-demo:
	$(call install-debs,demo)

deb:
	$(call install-debs,test)

# The virtual environment with the build tools and the package's dependencies (no compiler
# needed yet).
$(STAMP)/venv: pyproject.toml
	@$(CHECK_DEPS) base
	@mkdir -p $(STAMP)
	test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install -q ninja "cmake>=3.20" $$($(VPY) tools/pyproject-deps)
	touch $@

# The package, editable, with the C++ extension built in place; rebuilt whenever the core or
# the bindings change. Needs the Debian packages (setup-demo installs them first).
CORE_SOURCES := $(wildcard cpp/include/dualprobe/*.hpp cpp/include/dualprobe/*.h bindings/*.cpp \
	bindings/*.hpp)
$(STAMP)/extension: $(STAMP)/venv CMakeLists.txt $(CORE_SOURCES)
	$(VPY) -m pip install -q --no-build-isolation -e .
	touch $@

# The test extras (pytest, ruff, hypothesis), for `make test` only.
$(STAMP)/test-extras: $(STAMP)/extension pyproject.toml
	reqs=$$($(VPY) tools/pyproject-deps test); \
	if [ -n "$$reqs" ]; then $(VPY) -m pip install -q $$reqs; \
	else $(VPY) -m pip install -q --no-build-isolation -e ".[test]"; fi
	touch $@

venv-deps: $(STAMP)/venv
	@:
venv-demo: $(STAMP)/venv $(STAMP)/extension
	@:
venv: venv-demo $(STAMP)/test-extras
	@:

cpp-test: setup
	$(CMAKE) --preset dev -DCMAKE_MAKE_PROGRAM=$(abspath $(VENV)/bin/ninja) >/dev/null
	$(CMAKE) --build --preset dev
	$(CTEST) --preset dev

asan-test: setup
	$(CMAKE) --preset asan -DCMAKE_MAKE_PROGRAM=$(abspath $(VENV)/bin/ninja) >/dev/null
	$(CMAKE) --build --preset asan
	$(CTEST) --preset asan

# ruff; the import contracts of pyproject.toml (layers, the reference is a check, no cycles);
# the checked-in _core.pyi against the built extension.
lint: setup
	$(VENV)/bin/ruff check python tests/python scripts firmware_sim/tools
	$(VENV)/bin/lint-imports
	$(VPY) scripts/stubs.py --check

# Regenerate python/dualprobe/_core.pyi from the built extension (after changing bindings/).
stubs: setup
	$(VPY) scripts/stubs.py

# Two workers (the machine has 2 cores); whole files per worker so module fixtures run once.
# One BLAS thread per worker: two workers each starting OpenBLAS's two threads oversubscribe
# the cores (the suite took 13.2 min with one thread per worker, 15-19 min without).
# The 20 slowest tests are listed at the end: the suite sits near its 20 min aim, and CI's log
# then says where the time went.
pytest: setup
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(VPY) -m pytest -n 2 --dist loadfile --durations=20 \
		$(PYTEST_ARGS)

firmware: setup
	$(MAKE) -C firmware_sim report PYTHON=$(abspath $(VPY))

# The slow 10^8-tick float soak of the noise-robust estimator and reconstruction (issue 13);
# ctest runs the same binary on 10^6 ticks.
soak: setup
	$(CMAKE) --preset dev -DCMAKE_MAKE_PROGRAM=$(abspath $(VENV)/bin/ninja) >/dev/null
	$(CMAKE) --build --preset dev --target dualprobe_c_api_soak_robust
	build/cpp/firmware_sim/c_api_tests/dualprobe_c_api_soak_robust 100000000

bench: setup-demo
	$(VENV)/bin/dualprobe bench --json out/bench.json
	$(VENV)/bin/dualprobe bench --section pipeline --json out/bench_pipeline.json

paper: setup-demo
	$(VENV)/bin/dualprobe paper --out out/paper --json out/paper/paper.json

clean:
	rm -rf build out
