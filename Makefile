# dualprobe: every target does its own set-up on a fresh Debian machine (root for apt-get).
SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
CMAKE := $(VENV)/bin/cmake
CTEST := $(VENV)/bin/ctest
DEB_PACKAGES := make g++ libeigen3-dev libgtest-dev clang gcc-arm-none-eabi \
	libstdc++-arm-none-eabi-newlib libnewlib-arm-none-eabi qemu-system-arm
STAMP := build/.stamps

.PHONY: all demo test setup deb venv cpp-test asan-test pytest lint stubs firmware bench paper clean soak

all: test

demo: setup
	$(VENV)/bin/dualprobe demo --out out/demo

test: setup cpp-test asan-test lint pytest

setup: deb venv

# Install only what is missing, so a prepared machine pays nothing.
deb:
	@missing=""; for p in $(DEB_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "apt-get install:$$missing"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -qq; \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	fi

$(STAMP)/venv: pyproject.toml CMakeLists.txt
	@mkdir -p $(STAMP)
	test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install -q --upgrade pip
	$(VPY) -m pip install -q "scikit-build-core>=0.10" "pybind11>=3" ninja "cmake>=3.20"
	$(VPY) -m pip install -q --no-build-isolation -e ".[test]"
	touch $@ $(STAMP)/extension

# The extension is rebuilt whenever the core or the bindings change.
CORE_SOURCES := $(wildcard cpp/include/dualprobe/*.hpp cpp/include/dualprobe/*.h bindings/*.cpp)
$(STAMP)/extension: $(STAMP)/venv $(CORE_SOURCES)
	$(VPY) -m pip install -q --no-build-isolation --no-deps -e .
	touch $@

venv: $(STAMP)/venv $(STAMP)/extension

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
	$(VENV)/bin/ruff check python tests/python scripts
	$(VENV)/bin/lint-imports
	$(VPY) scripts/stubs.py --check

# Regenerate python/dualprobe/_core.pyi from the built extension (after changing bindings/).
stubs: setup
	$(VPY) scripts/stubs.py

# Two workers (the machine has 2 cores); whole files per worker so module fixtures run once.
pytest: setup
	$(VPY) -m pytest -n 2 --dist loadfile

firmware: setup
	$(MAKE) -C firmware_sim report PYTHON=$(abspath $(VPY))

# The slow 10^8-tick float soak of the noise-robust estimator and reconstruction (issue 13);
# ctest runs the same binary on 10^6 ticks.
soak: setup
	$(CMAKE) --preset dev -DCMAKE_MAKE_PROGRAM=$(abspath $(VENV)/bin/ninja) >/dev/null
	$(CMAKE) --build --preset dev --target dualprobe_c_api_soak_robust
	build/cpp/firmware_sim/c_api_tests/dualprobe_c_api_soak_robust 100000000

bench: setup
	$(VENV)/bin/dualprobe bench --json out/bench.json

paper: setup
	$(VENV)/bin/dualprobe paper --out out/paper --json out/paper/paper.json

clean:
	rm -rf build out
