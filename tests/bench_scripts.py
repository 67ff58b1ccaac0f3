# SPDX-License-Identifier: GPL-3.0-or-later
"""Loading a benchmark script (bench/<area>/<script>.py, not a package) as a module for its tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def load_bench_script(relative: str, name: str) -> ModuleType:
    """The module of ``ROOT/relative`` under ``name`` (registered in sys.modules, so that its
    dataclasses and pickling work)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / relative)
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod
