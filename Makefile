# SPDX-License-Identifier: GPL-3.0-or-later
# fiberform: the two commands a new user runs (as root on Debian bookworm) are
#   make demo   install what is missing, build, run the default scene, write results + report
#   make test   install what is missing, build, run all tests (ctest + pytest), one summary line
# Both are idempotent. `make setup` alone prepares the machine; a second run takes well under 10 s.

SHELL      := /bin/bash
BUILD      ?= build
JOBS       ?= $(shell nproc)
VENV       := .venv
FIBERFORM  := $(VENV)/bin/fiberform
SCENE      ?= scenes/demo.yaml
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
export WM_PROJECT_DIR := /usr/share/openfoam
export FIBERFORM_BUILD := $(abspath $(BUILD))

.PHONY: all setup packages openfoam-headers openfoam-pstream build venv demo test test-quick validate bench clean distclean help

all: setup

help:
	@echo "make demo      - install, build, run the default scene ($(SCENE)) into runs/"
	@echo "make test      - install, build, run all tests (ctest + pytest)"
	@echo "make setup     - install missing Debian packages, OpenFOAM headers, libPstream, build C++, Python venv"
	@echo "make validate  - the reduced thesis campaign (bench/thesis/run.py --reduced --points-at-once 2; hours on 2 cores)"
	@echo "make bench     - benchmarks (write JSON + PNG under bench/*/results)"

setup: packages openfoam-headers openfoam-pstream build venv

packages:
	@bash scripts/setup/debian-packages.sh

openfoam-headers: packages
	@bash scripts/setup/openfoam-headers.sh

# OpenFOAM's MPI layer rebuilt with the MPMD split (parallel coupled fluid; docs/coupling/launch.md),
# into $(FIBERFORM_PSTREAM_DIR) (default .deps/openfoam-pstream); a few seconds, then a no-op
openfoam-pstream: openfoam-headers
	@bash scripts/setup/openfoam-pstream.sh

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release

build: openfoam-headers $(BUILD)/CMakeCache.txt
	@set -o pipefail; cmake --build $(BUILD) -j $(JOBS) -- --no-print-directory | { grep -v -E '^\[ *[0-9]+%\] Built target' || true; }

venv: packages
	@bash scripts/setup/python-venv.sh

demo: setup
	$(FIBERFORM) run $(SCENE)

test: setup
	@bash scripts/setup/run-tests.sh $(BUILD)

validate: setup
	$(VENV)/bin/python bench/thesis/run.py --reduced --points-at-once 2

bench: setup
	@bash bench/run-all.sh $(BUILD)

clean:
	rm -rf $(BUILD)

distclean: clean
	rm -rf $(VENV) .deps runs
