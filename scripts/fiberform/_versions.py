# SPDX-License-Identifier: GPL-3.0-or-later
"""Where things are (repository root, build directory) and which versions are installed."""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from .runner import capture

__all__ = [
    "ComponentVersion",
    "build_dir",
    "build_revision",
    "component_versions",
    "fiberform_version",
    "git_revision",
    "package_version",
    "pstream_dir",
    "repo_root",
]


def repo_root() -> Path:
    """The repository root: the package lives in ``<root>/scripts/fiberform``."""
    return Path(__file__).resolve().parents[2]


def build_dir() -> Path:
    """``$FIBERFORM_BUILD`` if set, else ``<root>/build`` (see CONTRACTS.md)."""
    env = os.environ.get("FIBERFORM_BUILD")
    return Path(env) if env else repo_root() / "build"


def pstream_dir() -> Path:
    """Directory of OpenFOAM's libPstream rebuilt with the MPMD split (a coupled fluid on several
    ranks; scripts/setup/openfoam-pstream.sh): ``$FIBERFORM_PSTREAM_DIR`` if set, else
    ``<root>/.deps/openfoam-pstream`` (see CONTRACTS.md)."""
    env = os.environ.get("FIBERFORM_PSTREAM_DIR")
    return Path(env) if env else repo_root() / ".deps" / "openfoam-pstream"


def package_version() -> str:
    try:
        return metadata.version("fiberform")
    except metadata.PackageNotFoundError:
        return "0+unknown"


def git_revision(root: Path | None = None) -> str:
    """Short commit of the repository, ``-dirty`` if tracked files are modified, ``unknown``
    outside a git work tree (or without git)."""
    where = root or repo_root()
    rev = capture(["git", "-C", str(where), "rev-parse", "--short", "HEAD"])
    if rev is None or not rev.strip():
        return "unknown"
    status = capture(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"])
    dirty = status is None or bool(status.strip())
    return rev.strip() + ("-dirty" if dirty else "")


#: what build/REVISION may hold (cmake/WriteRevision.cmake): a short commit, maybe ``-dirty``
_BUILD_REVISION = re.compile(r"[0-9a-f]{7,40}(-dirty)?")


def build_revision(build: Path) -> str:
    """The commit a build folder's binaries were compiled from: the first line of its
    ``REVISION`` file, written at every build by cmake/WriteRevision.cmake (a short commit,
    ``-dirty`` when the compiled trees had changes); ``unknown`` without that file or with other
    text. It can differ from :func:`git_revision` (the Python code's): a frozen build folder keeps
    running the binaries of its commit."""
    try:
        first = (build / "REVISION").read_text().splitlines()[0].strip()
    except (OSError, IndexError, UnicodeDecodeError):
        return "unknown"
    return first if _BUILD_REVISION.fullmatch(first) else "unknown"


def fiberform_version() -> str:
    """``<package version>+git.<revision>``-like text for provenance: ``0.1.0 (git abc1234)``."""
    return f"{package_version()} (git {git_revision()})"


@dataclass(frozen=True)
class ComponentVersion:
    name: str
    version: str
    source: str

    def line(self) -> str:
        return f"{self.name + ':':<11}{self.version} ({self.source})"


def _dpkg(package: str) -> str | None:
    out = capture(["dpkg-query", "-W", "-f=${db:Status-Status} ${Version}", package])
    if out is None:
        return None
    parts = out.split()
    if len(parts) == 2 and parts[0] == "installed":
        return parts[1]
    return None


def _fiberdem_liggghts(build: Path) -> str | None:
    exe = build / "bin" / "fiberdem"
    if not exe.is_file():
        return None
    out = capture([str(exe), "--version"])
    for line in (out or "").splitlines():
        if line.startswith("LIGGGHTS "):
            return line.split(None, 1)[1].strip()
    return None


def _openfoam_bashrc() -> str | None:
    try:
        text = Path("/usr/share/openfoam/etc/bashrc").read_text(errors="replace")
    except OSError:
        return None
    m = re.search(r"^\s*export\s+WM_PROJECT_VERSION=(\S+)", text, re.MULTILINE)
    return m.group(1) if m else None


def _sundials_header() -> str | None:
    for inc in (Path("/usr/include/sundials/sundials_config.h"),):
        try:
            text = inc.read_text(errors="replace")
        except OSError:
            continue
        m = re.search(r'#define\s+SUNDIALS_VERSION\s+"([^"]+)"', text)
        if m:
            return m.group(1)
    return None


def _mpirun() -> str | None:
    out = capture(["mpirun", "--version"])
    m = re.search(r"\(Open MPI\)\s+(\S+)", out or "")
    return m.group(1) if m else None


def component_versions(build: Path | None = None) -> list[ComponentVersion]:
    """Versions of LIGGGHTS, OpenFOAM, SUNDIALS, Open MPI and fiberform, always five entries;
    ``not found`` where no source knows."""
    bdir = build or build_dir()
    found: list[ComponentVersion] = []

    def first(name: str, *probes: tuple[str, Callable[[], str | None]]) -> None:
        for source, probe in probes:
            version = probe()
            if version:
                found.append(ComponentVersion(name, version, source))
                return
        found.append(ComponentVersion(name, "not found", "no dpkg entry or fallback"))

    first(
        "LIGGGHTS",
        ("Debian package liggghts", lambda: _dpkg("liggghts")),
        (f"{bdir / 'bin' / 'fiberdem'} --version", lambda: _fiberdem_liggghts(bdir)),
    )
    first(
        "OpenFOAM",
        ("Debian package openfoam", lambda: _dpkg("openfoam")),
        ("/usr/share/openfoam/etc/bashrc", lambda: _openfoam_bashrc()),
    )
    first(
        "SUNDIALS",
        ("Debian package libsundials-dev", lambda: _dpkg("libsundials-dev")),
        ("sundials_config.h", lambda: _sundials_header()),
    )
    first(
        "Open MPI",
        ("Debian package openmpi-bin", lambda: _dpkg("openmpi-bin")),
        ("mpirun --version", lambda: _mpirun()),
    )
    found.append(ComponentVersion("fiberform", package_version(), f"git {git_revision()}"))
    return found
