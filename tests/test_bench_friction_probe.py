# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/laydown/probe_friction.py writes the lay-down stage's own resumed input with the probe's
friction setting (laydown.friction_coefficient, laydown.friction_stick) and the solver counters,
and fiberform.provenance.append_result_rows keeps earlier rows. No binaries needed."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from bench_scripts import load_bench_script
from fiberform.provenance import append_result_rows

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def probe() -> Any:
    return load_bench_script("bench/laydown/probe_friction.py", "probe_friction")


@pytest.fixture()
def run(tmp_path: Path) -> Path:
    """A run folder holding the shipped case-A scene as a lay-down run would (2 ranks, newton)."""
    data = yaml.safe_load((ROOT / "scenes" / "thesis" / "case-A-circular.yaml").read_text())
    data["laydown"]["fiber_contact"] = "newton"
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(data))
    return tmp_path


def fix_lines(text: str, style: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("fix ") and f" {style} " in line]


def test_stick_setting_reaches_every_static_body(probe: Any, run: Path) -> None:
    text = probe.probe_input(run, 4000, 300, 50, 0.5, 10.0)
    bodies = fix_lines(text, "wall/fiber/yarns") + fix_lines(text, "wall/fiber/dlvo")
    assert len(bodies) == 5  # yarns and four side planes
    for line in bodies:
        assert line.endswith("friction 0.5 friction_stick 10.0"), line
    assert "read_restart laydown.4000.restart" in text.splitlines()
    # 300 steps in runs of 50 after step 4000, the solver counters in the thermo output
    assert sum(1 for line in text.splitlines() if line.startswith("run 50")) == 6
    thermo = [line for line in text.splitlines() if line.startswith("thermo_style")]
    assert thermo == ["thermo_style custom step atoms f_beam[14] f_beam[15] f_beam[18] f_beam[19] f_beam[20] f_beam[21]"]
    assert fix_lines(text, "fiber/beam")  # the fibers are defined before any contact


def test_frictionless_setting_has_no_stick(probe: Any, run: Path) -> None:
    text = probe.probe_input(run, 4000, 300, 50, 0.0, 100.0)
    for line in fix_lines(text, "wall/fiber/yarns") + fix_lines(text, "wall/fiber/dlvo"):
        assert line.endswith("friction 0.0"), line


def test_anderson_reaches_the_beam_fix(probe: Any, run: Path) -> None:
    """--anderson M puts `anderson M` on fix fiber/beam; without it the keyword is absent."""
    beam = fix_lines(probe.probe_input(run, 4000, 300, 50, 0.5, 100.0, probe.probe_fields(anderson=3)), "fiber/beam")
    assert len(beam) == 1 and " anderson 3" in beam[0], beam
    plain = fix_lines(probe.probe_input(run, 4000, 300, 50, 0.5, 100.0), "fiber/beam")
    assert " anderson " not in plain[0], plain


def test_landing_reaches_the_beam_fix(probe: Any, run: Path) -> None:
    """--landing predict puts `landing predict` on fix fiber/beam; limit (the default) writes nothing."""
    beam = fix_lines(probe.probe_input(run, 4000, 300, 50, 0.5, 100.0, probe.probe_fields(landing="predict")),
                     "fiber/beam")
    assert len(beam) == 1 and " landing predict" in beam[0], beam
    plain = fix_lines(probe.probe_input(run, 4000, 300, 50, 0.5, 100.0, probe.probe_fields(landing="limit")),
                      "fiber/beam")
    assert " landing " not in plain[0], plain


def test_tolerance_and_timestep_reach_the_input(probe: Any, run: Path) -> None:
    """--tolerance T and --timestep DT reach fix fiber/beam's newton_tol and the timestep command."""
    fields = probe.probe_fields(tolerance=1e-5, timestep=2e-6)
    assert fields == {"laydown.newton_tolerance": 1e-5, "laydown.timestep_s": 2e-6}
    text = probe.probe_input(run, 4000, 300, 50, 0.5, 200.0, fields)
    beam = fix_lines(text, "fiber/beam")
    assert " newton_tol 1e-05 " in beam[0] + " ", beam
    assert any(line.split() == ["timestep", "2e-06"] for line in text.splitlines()), text
    plain = probe.probe_input(run, 4000, 300, 50, 0.5, 200.0)
    assert " newton_tol 1e-05 " not in fix_lines(plain, "fiber/beam")[0] + " "
    assert not any(line.split() == ["timestep", "2e-06"] for line in plain.splitlines())


def test_probe_must_fit_the_chunks(probe: Any, run: Path) -> None:
    with pytest.raises(SystemExit, match="multiples"):
        probe.probe_input(run, 4000, 310, 50, 0.5, 10.0)
    with pytest.raises(SystemExit, match="FRICTION:STICK"):
        probe.parse_setting("half")


def test_append_result_rows_keeps_earlier_rows(tmp_path: Path) -> None:
    out = tmp_path / "results" / "probe.json"
    append_result_rows(out, [{"a": 1}])
    append_result_rows(out, [{"a": 2}, {"a": 3}])
    assert json.loads(out.read_text()) == {"rows": [{"a": 1}, {"a": 2}, {"a": 3}]}
    assert not list(out.parent.glob("*.in_progress"))
