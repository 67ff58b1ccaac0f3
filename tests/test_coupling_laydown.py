# SPDX-License-Identifier: GPL-3.0-or-later
"""The two-way coupled lay-down stage (issue 13): `coupling: {mode: two_way}` runs fiberdem and
fiberPimpleFoam -coupled under ONE mpirun (1 fiber rank + 1 fluid rank, the machine's 2 cores; and
`coupling.fluid_ranks: 2`, 1 + 2 processes with --oversubscribe) on the flow stage's real mesh (graded
in z, yarn cells removed) through the exchange map.

- frozen-flow equivalence: with `reaction: off` and one exchange per settle check, the fibers see
  the fluid's initial state (the flow stage's solution) sampled on flow.grid's grid over the first
  check: nodes and velocities equal the one-way lay-down's (reading flow.grid) to 1e-10 relative.
  Later the fluid evolves on its own (the transient solver's drift from the steady solution), so
  the end state differs by a stated tolerance;
- momentum: every exchange's total force sent by the fibers equals the source the fluid received
  (sum over its cells of rho V fiberSource) to 1e-12 relative;
- drainage: laydown.h5 /drainage holds the flow rate through the bottom after every fluid step and
  the report prints it next to the sheet's growth;
- restart (both sides): the two-way run resumed (`--resume`) from its restart file and fluid state at
  the first check repeats the rest: the same sheet to 1e-9 m (the restart files are exact: binary
  fluid state, LIGGGHTS restart) and the same drainage curve to 1e-12 relative."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from fiberform.liggghts_log import read_dump

pytestmark = pytest.mark.system

BASE = """
seed: 3
domain: {lo_m: [0.0, 0.0, 0.0], hi_m: [1.0e-3, 1.0e-3, 3.437e-3]}
fibers: {count: 3, length_m: 0.6e-3, width_m: 20.0e-6, segments: 8,
         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}
fiber_generation: {placement_lo_m: [0.0, 0.0, 2.66e-3], placement_hi_m: [1.0e-3, 1.0e-3, 3.43e-3]}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3}
flow: {delta_p_Pa: 100.0, cell_size_m: 50.0e-6, height_above_fabric_m: 0.8e-3,
       sample_spacing_m: 100.0e-6}
laydown: {terms: [steric], max_time_s: 1.0e-3, check_interval_s: 5.0e-4, settle_speed_m_s: 2.0e-3, settle_checks: 3,
          timestep_s: 1.0e-6, restart_interval_s: 0.0}
"""
SCENES = {
    "one_way": None,
    "off": {"mode": "two_way", "interval": 500, "reaction": "off", "timeout_s": 120.0},
    "on": {"mode": "two_way", "interval": 50, "timeout_s": 120.0},
    # the same on 2 fluid ranks (1 + 2 processes on 2 cores: --oversubscribe)
    "on2": {"mode": "two_way", "interval": 50, "timeout_s": 120.0, "fluid_ranks": 2},
}
RESTART_EVERY_CHECK = {"on", "on2"}  # restart files (fibers) and fluid states at every check


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory, build_dir: Path,
         fiberform_cmd: list[str]) -> dict[str, Path]:
    for b in ("fiberdem", "fiberPimpleFoam"):
        if not (build_dir / "bin" / b).is_file():
            pytest.skip(f"{b} not built")
    work = tmp_path_factory.mktemp("coupled_laydown")
    out = {}
    for name, coupling in SCENES.items():
        data = yaml.safe_load(BASE)
        data["name"] = f"cpl_{name}"
        if coupling is not None:
            data["coupling"] = coupling
        if name in RESTART_EVERY_CHECK:
            data["laydown"]["restart_interval_s"] = data["laydown"]["check_interval_s"]
        (work / f"{name}.yaml").write_text(yaml.safe_dump(data))
        proc = subprocess.run([*fiberform_cmd, "run", f"{name}.yaml", "--build-dir", str(build_dir),
                               *oversubscribe(name)],
                              cwd=work, capture_output=True, text=True, errors="replace", timeout=600)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
        out[name] = work / "runs" / f"cpl_{name}" / "laydown"
    return out


def frame(run: Path, step: int) -> tuple[np.ndarray, np.ndarray]:
    fr = {f.step: f for f in read_dump(run / "work" / "traj.dump")}[step]
    order = np.argsort(fr.ids)
    x = np.stack([fr.columns[c][order] for c in ("x", "y", "z")], 1)
    v = np.stack([fr.columns[c][order] for c in ("vx", "vy", "vz")], 1)
    return x, v


def test_reaction_off_sees_the_frozen_flow(runs: dict[str, Path]) -> None:
    x0, _ = frame(runs["one_way"], 0)
    x1, v1 = frame(runs["one_way"], 500)
    x2, v2 = frame(runs["off"], 500)
    assert np.max(np.abs(v1)) > 1e-3  # the fibers move in the flow
    assert np.max(np.abs(v2 - v1)) <= 1e-10 * np.max(np.abs(v1))
    assert np.max(np.abs(x2 - x1)) <= 1e-10 * np.max(np.abs(x1 - x0))
    # after the first exchange the fluid evolves on its own (the transient solver drifts from the
    # steady solution: the flow rate changes by 0.03 % in 1 ms here): the end state differs by less
    # than 1 % of the fibers' speed
    _, e1 = frame(runs["one_way"], 1000)
    _, e2 = frame(runs["off"], 1000)
    assert np.max(np.abs(e2 - e1)) <= 1e-2 * np.max(np.abs(e1))


def oversubscribe(name: str) -> list[str]:
    coupling = SCENES[name]
    return ["--oversubscribe"] if coupling and coupling.get("fluid_ranks", 1) > 1 else []


@pytest.mark.parametrize("name", ["on", "on2"])
def test_momentum_sent_equals_momentum_received(runs: dict[str, Path], name: str) -> None:
    """Per exchange, the force the fibers sent equals the source the fluid received, summed over its
    cells (on 2 fluid ranks: over the cells of both ranks, each exchange cell's force handed to the
    one rank owning its receiving cell)."""
    log = (runs[name] / "work" / "log.fiberPimpleFoam").read_text()
    vec = r"\(([^)]*)\)"
    pairs = re.findall(rf"Coupling reaction \(N\): sent {vec} received {vec}", log)
    assert len(pairs) == 1000 // 50
    for sent, got in pairs:
        s, r = np.array(sent.split(), float), np.array(got.split(), float)
        assert np.max(np.abs(s)) > 0.0
        assert np.max(np.abs(r - s)) <= 1e-12 * np.max(np.abs(s))


def test_drainage_curve_written(runs: dict[str, Path]) -> None:
    with h5py.File(runs["on"] / "laydown.h5", "r") as h:
        t = h["drainage/time"][...]
        u = h["drainage/superficial_velocity"][...]
        u_s = h["run"].attrs["superficial_velocity_m_s"]
        growth = h["snapshots/settled_grammage"][...]
    np.testing.assert_allclose(t, 50e-6 * np.arange(1, 21), rtol=1e-9)
    # the drainage starts at the flow stage's rate (its solution is the fluid's initial state)
    assert abs(u[0] - u_s) <= 0.01 * u_s
    assert np.all(u > 0.9 * u_s) and np.all(u < 1.1 * u_s)
    assert len(growth) == 3
    report = (runs["on"] / "report.md").read_text()
    assert "Drainage" in report and "settled grammage" in report
    with h5py.File(runs["one_way"] / "laydown.h5", "r") as h:
        assert "drainage" not in h


@pytest.mark.parametrize("name", ["on", "on2"])
def test_coupled_laydown_resumes_to_the_same_sheet(runs: dict[str, Path], tmp_path: Path, name: str,
                                                   build_dir: Path, fiberform_cmd: list[str]) -> None:
    """on2: the fluid's state is cut back in every processor folder (2 fluid ranks)."""
    ref = runs[name]
    work = tmp_path / "resume"
    shutil.copytree(ref.parents[2], work, symlinks=True)  # scenes and runs/ of the fixture
    # the fixture's run is complete: --resume continues from the last restart file before the
    # last snapshot (step 500), with the fluid cut back to its state of that step
    proc = subprocess.run([*fiberform_cmd, "laydown", f"{name}.yaml", "--resume", "--force",
                           "--build-dir", str(build_dir), *oversubscribe(name)],
                          cwd=work, capture_output=True, text=True, errors="replace", timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    again = work / "runs" / f"cpl_{name}" / "laydown"
    with h5py.File(again / "laydown.h5", "r") as h, h5py.File(ref / "laydown.h5", "r") as r:
        assert h["run"].attrs["resumed_from_step"] == 500
        assert np.abs(h["sheet/x"][...] - r["sheet/x"][...]).max() < 1e-9
        np.testing.assert_allclose(h["drainage/time"][...], r["drainage/time"][...], rtol=1e-9)
        q, q_ref = h["drainage/flow_rate"][...], r["drainage/flow_rate"][...]
        assert np.abs(q - q_ref).max() <= 1e-12 * np.abs(q_ref).max()
    log = (again / "work" / "log.fiberPimpleFoam").read_text()
    assert "Starting time loop" in log or "Coupled with fiberdem" in log
    assert len(re.findall(r"Coupling reaction", log)) == 500 // 50



def test_two_fluid_ranks_run_the_laydown(runs: dict[str, Path]) -> None:
    """coupling.fluid_ranks 2: the fluid case was decomposed and fiberPimpleFoam ran on 2 ranks over
    the whole lay-down. Its result is not compared with 1 fluid rank to a tight tolerance here: the
    flow stage's pressure solver (GAMG, relTol 0.01 in the first corrector) stops at points that
    depend on the decomposition (measured: drainage 2e-6, fiber positions 3e-7 relative);
    tests/test_coupling_ranks.py compares rank counts with the solvers converged."""
    fluid = runs["on2"] / "work" / "fluid"
    assert sorted(p.name for p in fluid.glob("processor*")) == ["processor0", "processor1"]
    log = (runs["on2"] / "work" / "log.fiberPimpleFoam").read_text()
    assert "2 fluid rank(s)" in log and "Coupled run ended by fiberdem after 20 exchanges" in log
    with h5py.File(runs["on2"] / "laydown.h5", "r") as h, h5py.File(runs["on"] / "laydown.h5", "r") as r:
        np.testing.assert_allclose(h["drainage/time"][...], r["drainage/time"][...], rtol=1e-9)
        q2, q1 = h["drainage/flow_rate"][...], r["drainage/flow_rate"][...]
        assert np.all(q2 > 0) and len(q2) == len(q1) == 20
