# SPDX-License-Identifier: GPL-3.0-or-later
"""Shared pytest set-up: the ``system`` marker, the build directory and the venv's commands.

Slow tests that need built binaries (fiberdem, fiberPimpleFoam) carry ``@pytest.mark.system``;
``pytest -m "not system"`` runs the quick ones only.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "system: slow end-to-end test that runs built binaries (fiberdem, OpenFOAM)"
    )


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository root."""
    return ROOT


@pytest.fixture(scope="session")
def build_dir() -> Path:
    """``$FIBERFORM_BUILD`` or ``<root>/build`` (CONTRACTS.md)."""
    return Path(os.environ.get("FIBERFORM_BUILD", str(ROOT / "build"))).resolve()


@pytest.fixture(scope="session")
def venv_bin() -> Path:
    """``bin/`` of the venv made by scripts/setup/python-venv.sh."""
    return ROOT / ".venv" / "bin"


@pytest.fixture(scope="session")
def fiberform_cmd(venv_bin: Path) -> list[str]:
    """How to start the CLI: the venv's console script, else ``python -m fiberform``."""
    exe = venv_bin / "fiberform"
    if exe.is_file():
        return [str(exe)]
    return [sys.executable, "-m", "fiberform"]


@pytest.fixture(scope="session")
def fiberdem_build(build_dir: Path) -> Path:
    """The build directory, once fiberdem is built there (the test is skipped otherwise)."""
    if not (build_dir / "bin" / "fiberdem").is_file():
        pytest.skip("fiberdem not built")
    return build_dir
