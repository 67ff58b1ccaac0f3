#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Installs the Debian bookworm packages fiberform needs, pinned where the issue pins them.
# As root: installs what is missing. Not root and something missing: prints the apt command, exit 2.
# Idempotent: when everything is present at the right version it only runs dpkg-query (< 1 s).
set -euo pipefail

# package=version (empty version: any)
PINNED=(
  "liggghts=3.8.0+repack1-9+b2"
  "libliggghts-dev=3.8.0+repack1-9+b2"
  "openfoam=1912.200626-1+b1"
  "libopenfoam=1912.200626-1+b1"
  "libsundials-dev=6.4.1+dfsg1-3"
  # Eigen (header-only): the sparse LU of the contact clusters' capacitance matrix (implicit_rod.h)
  "libeigen3-dev=3.4.0-4"
  "libopenmpi-dev="
  "openmpi-bin="
  "cmake="
  "g++="
  "make="
  "python3="
  "python3-venv="
  "xz-utils="
  "patch="
  "bzip2="
  # Slurm for tests/test_submit.py (fiberform submit): its fixture starts slurmctld + slurmd on
  # localhost with a private slurm.conf; the packages start no daemon themselves (their services
  # need /etc/slurm/slurm.conf, which is not written).
  "slurmctld="
  "slurmd="
  "slurm-client="
)

missing=()
for spec in "${PINNED[@]}"; do
  pkg=${spec%%=*}
  want=${spec#*=}
  have=$(dpkg-query -W -f='${db:Status-Abbrev}|${Version}' "$pkg" 2>/dev/null || true)
  status=${have%%|*}
  version=${have#*|}
  if [[ "$status" != ii* ]]; then
    missing+=("$spec")
  elif [[ -n "$want" && "$version" != "$want" ]]; then
    echo "debian-packages: $pkg is at $version, fiberform needs $want" >&2
    missing+=("$spec")
  fi
done

# pkg=  (no version) is not valid apt syntax: drop the trailing '='.
apt_args=()
for spec in "${missing[@]}"; do apt_args+=("${spec%=}"); done

if [[ ${#missing[@]} -eq 0 ]]; then
  exit 0
fi

cmd="apt-get install -y --no-install-recommends ${apt_args[*]}"
if [[ $(id -u) -ne 0 ]]; then
  echo "debian-packages: missing packages. Run as root:" >&2
  echo "  apt-get update && $cmd" >&2
  exit 2
fi

echo "debian-packages: installing ${apt_args[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
# shellcheck disable=SC2086
apt-get install -y --no-install-recommends --allow-downgrades "${apt_args[@]}"
