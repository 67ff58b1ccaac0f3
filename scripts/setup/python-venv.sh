#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
#
# Create /work/main/.venv (or $FIBERFORM_VENV) with the exact packages of
# scripts/requirements.lock and fiberform installed editable from scripts/.
#
# Idempotent: .venv/.fiberform-stamp holds a hash of requirements.lock, pyproject.toml and the
# interpreter version; when it matches, the script exits at once. Packages in the venv that the
# lock does not list are removed, so the venv is exactly the lock.
#
# Environment: PYTHON (interpreter, default python3, must be >= 3.11), FIBERFORM_VENV.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
venv="${FIBERFORM_VENV:-$root/.venv}"
lock="$root/scripts/requirements.lock"
pyproject="$root/scripts/pyproject.toml"
stamp="$venv/.fiberform-stamp"
python="${PYTHON:-python3}"

say() { echo "python-venv: $*"; }
die() { echo "python-venv: error: $*" >&2; exit 1; }

command -v "$python" >/dev/null 2>&1 || die "$python not found (install Python >= 3.11)"
pyver="$("$python" -c 'import sys; print("%d.%d.%d" % sys.version_info[:3])')"
"$python" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' \
  || die "$python is Python $pyver; fiberform needs >= 3.11 (set PYTHON=...)"

want="$( { cat "$lock" "$pyproject"; echo "python $pyver"; } | sha256sum | cut -d' ' -f1)"
if [[ -f "$stamp" && "$(<"$stamp")" == "$want" && -x "$venv/bin/python" && -x "$venv/bin/fiberform" ]]; then
  say "$venv is up to date"
  exit 0
fi

# A venv whose interpreter no longer runs (moved, Python upgraded) is rebuilt from scratch.
if [[ -e "$venv" ]] && ! "$venv/bin/python" -c 'pass' >/dev/null 2>&1; then
  [[ -f "$venv/pyvenv.cfg" ]] || die "$venv exists but is not a venv; move it away"
  say "removing broken venv $venv"
  rm -rf -- "$venv"
fi

if [[ ! -x "$venv/bin/python" ]]; then
  say "creating $venv with $python ($pyver)"
  if ! "$python" -m venv "$venv" 2>/tmp/fiberform-venv.err.$$; then
    cat /tmp/fiberform-venv.err.$$ >&2 || true
    rm -f /tmp/fiberform-venv.err.$$
    rm -rf -- "$venv"
    if [[ -f /etc/debian_version ]]; then
      pkg="python3-venv"
      minor="$("$python" -c 'import sys; print("python%d.%d-venv" % sys.version_info[:2])')"
      if [[ "$(id -u)" == 0 ]]; then
        say "installing $pkg (and $minor if it exists) with apt-get"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq "$pkg" || true
        apt-get install -y -qq "$minor" 2>/dev/null || true
        "$python" -m venv "$venv" || die "python3 -m venv still fails"
      else
        die "python3 -m venv failed; install the venv module: sudo apt-get install $pkg $minor"
      fi
    else
      die "python3 -m venv failed (install your distribution's venv module for $python)"
    fi
  fi
  rm -f /tmp/fiberform-venv.err.$$
fi

pip=("$venv/bin/python" -m pip --disable-pip-version-check --no-input)
say "installing the locked packages"
"${pip[@]}" install -q -r "$lock"

# Remove what the lock does not list (left over from an older lock).
extra="$("$venv/bin/python" - "$lock" <<'PY'
import re, subprocess, sys
def norm(n): return re.sub(r"[-_.]+", "-", n).lower()
locked = set()
for line in open(sys.argv[1]):
    line = line.split("#", 1)[0].strip()
    if "==" in line:
        locked.add(norm(line.split("==", 1)[0]))
out = subprocess.run([sys.executable, "-m", "pip", "freeze", "--exclude-editable"],
                     capture_output=True, text=True, check=True).stdout
keep = locked | {"pip", "fiberform"}
print(" ".join(n for n in (l.split("==", 1)[0] for l in out.splitlines() if "==" in l)
               if norm(n) not in keep))
PY
)"
if [[ -n "$extra" ]]; then
  say "removing packages not in the lock: $extra"
  # shellcheck disable=SC2086
  "${pip[@]}" uninstall -q -y $extra
fi

say "installing fiberform (editable) from scripts/"
"${pip[@]}" install -q --no-deps --no-build-isolation -e "$root/scripts"
"$venv/bin/fiberform" --version >/dev/null || die "the fiberform command does not run"

echo "$want" >"$stamp"
say "done: $venv ($("$venv/bin/fiberform" --version))"
