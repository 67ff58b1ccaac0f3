# SPDX-License-Identifier: GPL-3.0-or-later
"""No stage module imports another stage module: a stage reads upstream results through the
typed readers and shared modules (fiberform.products, fiber_io, fiber_sheet, liggghts_log,
openfoam_case), never through another stage's code (issue 11, point 3)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

STAGES = Path(__file__).resolve().parents[1] / "scripts" / "fiberform" / "stages"
MODULES = sorted(p.stem for p in STAGES.glob("*.py") if p.stem not in ("__init__", "_stage"))


def _stage_imports(path: Path) -> set[str]:
    """The stage modules that ``path`` imports (relative ``.x``, ``..stages.x`` or absolute)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level == 1 and mod in MODULES:
                found.add(mod)
            elif node.level == 1 and not mod:  # from . import x
                found |= {a.name for a in node.names if a.name in MODULES}
            elif mod.startswith(("fiberform.stages.", "stages.")) or (node.level == 2 and mod.startswith("stages")):
                tail = mod.split(".")[-1]
                if tail in MODULES:
                    found.add(tail)
        elif isinstance(node, ast.Import):
            found |= {a.name.split(".")[-1] for a in node.names
                      if a.name.startswith("fiberform.stages.") and a.name.split(".")[-1] in MODULES}
    return found


@pytest.mark.parametrize("module", MODULES)
def test_stage_imports_no_other_stage(module: str) -> None:
    assert _stage_imports(STAGES / f"{module}.py") - {module} == set()


def test_the_check_finds_a_cross_stage_import(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("from .generate import fiber_shape\nfrom ..stages.laydown import X\n")
    assert _stage_imports(bad) == {"generate", "laydown"}
