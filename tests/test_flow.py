# SPDX-License-Identifier: GPL-3.0-or-later
"""System tests of the ``flow`` stage: OpenFOAM (blockMesh, topoSet, subsetMesh, simpleFoam) on a
coarse 1 x 1 mm piece of the default fabric (50 um cells, about 15,000 fluid cells).

* the stage runs end to end through the CLI and writes its products with provenance;
* mass is conserved: inflow through the top = outflow through the bottom within 0.5 %;
* the superficial velocity of the bare fabric grows monotonically with the pressure drop and, at
  low Reynolds number, linearly (Darcy);
* a 2-rank run (decomposePar + simpleFoam -parallel) gives the serial flow rate;
* a solve killed with SIGTERM resumes from its latest complete time directory (1 and 2 ranks) to
  the uninterrupted result; a changed input starts over.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_helpers import processes_under, terminate_when

from fiberform.scene import FabricSection, FlowSection, FluidSection
from fiberform.stages.fabric import make_fabric
from fiberform.stages.flow import FlowSetup, read_flow_grid, run_flow_case

pytestmark = [
    pytest.mark.system,
    pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed"),
]

CELL = 50e-6
SCENE = f"""name: flowtest
run: {{timestep_s: 1.0e-6, duration_s: 1.0e-3}}
fabric: {{size_x_m: 1.0e-3, size_y_m: 1.0e-3, voxel_size_m: 10.0e-6}}
flow: {{cell_size_m: {CELL!r}, delta_p_Pa: 100.0}}
"""


@pytest.fixture(scope="module")
def stage_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("flowstage")
    (d / "s.yaml").write_text(SCENE)
    env = dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"))
    for stage in ("fabric", "flow"):
        r = subprocess.run(
            [sys.executable, "-m", "fiberform", stage, "s.yaml"], cwd=d, env=env,
            capture_output=True, text=True, errors="replace", timeout=600, check=False,
        )  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
    return d / "runs" / "flowtest"


@pytest.fixture(scope="module")
def fabric_piece():  # type: ignore[no-untyped-def]
    """The 1 x 1 mm default fabric: (voxel image, yarns as (centre line, radius))."""
    sec = FabricSection(size_x_m=1.0e-3, size_y_m=1.0e-3, voxel_size_m=10.0e-6)
    res = make_fabric(sec)
    assert res.image is not None and res.yarns is not None
    return res.image, [(y.points, y.radius) for y in res.yarns]


def _setup(fabric, delta_p: float, ranks: int = 1) -> FlowSetup:  # type: ignore[no-untyped-def]
    return FlowSetup.from_scene(
        fabric[0], FlowSection(cell_size_m=CELL, delta_p_Pa=delta_p, ranks=ranks), FluidSection()
    )


def test_stage_products_and_mass_conservation(stage_run: Path) -> None:
    d = stage_run / "flow"
    for name in ("flow.h5", "flow.grid", "flow.png", "log.simpleFoam", "log.subsetMesh"):
        assert (d / name).is_file(), name
    with h5py.File(d / "flow.h5") as f:
        assert f.attrs["stage"] == "flow"
        assert "fabric_h5" in f.attrs["input_hashes"]
        q_top = float(f["flow_rate/top"][()])
        q_bot = float(f["flow_rate/bottom"][()])
        assert f["flow_rate/top"].attrs["units"] == "m^3/s"
        assert q_bot > 0
        assert abs(q_top - q_bot) / q_bot < 0.005
        assert bool(f["solver"].attrs["converged"])
        U = f["grid/U"][...]
        assert f["grid/U"].attrs["units"] == "m/s"
        origin, spacing = f["grid/origin"][...], f["grid/spacing"][...]
        shape = tuple(int(n) for n in f["grid/shape"][...])
        # Far below the fabric the flow is uniform: the plane mean of -U_z is the superficial
        # velocity Q / A.
        k = 2
        assert -U[:, :, k, 2].mean() == pytest.approx(q_bot / 1e-6, rel=0.02)
        # No flow inside yarns: lattice cells removed from the mesh carry U = 0.
        fluid = f["lattice/fluid"][...].astype(bool)
        assert np.all(f["lattice/U"][...][~fluid] == 0.0)
        assert (~fluid).sum() > 0
    grid, Ubin = read_flow_grid(d / "flow.grid")
    assert grid.shape == shape
    assert np.array_equal(grid.origin, origin) and np.array_equal(grid.spacing, spacing)
    assert np.array_equal(Ubin, U)


def test_superficial_velocity_vs_pressure_drop(fabric_piece, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    drops = [0.25, 0.5, 1.0]
    rows = []
    for dp in drops:
        res = run_flow_case(_setup(fabric_piece, dp), fabric_piece[0], tmp_path / f"dp{dp:g}",
                            yarns=fabric_piece[1])  # fmt: skip
        assert res.converged
        assert res.imbalance < 0.005
        rows.append((dp, res.q_bottom_m3_s / 1e-6, res.iterations))
    print("\nbare fabric, 1 x 1 mm, 50 um cells: delta_p [Pa], superficial velocity [m/s], iterations")
    for dp, u, it in rows:
        print(f"  {dp:6g}  {u:.6e}  {it}")
    u = np.array([r[1] for r in rows])
    assert np.all(np.diff(u) > 0), "superficial velocity must grow with the pressure drop"
    # Re (warp diameter, superficial velocity) stays below 0.5: Darcy's law, u / delta_p constant.
    assert u[-1] * 0.11e-3 / 1e-6 < 0.5
    perm = u / np.array(drops)
    assert perm.max() / perm.min() - 1 < 0.02, perm


def test_two_ranks_match_serial(fabric_piece, stage_run: Path, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    if (os.cpu_count() or 1) < 2:
        pytest.skip("needs 2 cores")
    res = run_flow_case(_setup(fabric_piece, 100.0, ranks=2), fabric_piece[0], tmp_path / "par",
                        yarns=fabric_piece[1])  # fmt: skip
    assert (tmp_path / "par" / "log.decomposePar").is_file()
    with h5py.File(stage_run / "flow" / "flow.h5") as f:
        q_serial = float(f["flow_rate/bottom"][()])
    assert res.imbalance < 0.005
    assert res.q_bottom_m3_s == pytest.approx(q_serial, rel=1e-3)


# --------------------------------------------------------------------------------------------
# Resume of a killed solve (issue 14): simpleFoam writes a time directory every
# WRITE_EVERY_ITERATIONS; a rerun of the same inputs continues from the latest complete one.

#: Relative difference allowed between a resumed and an uninterrupted solve (flow rate, velocity):
#: the restart state is written with 12 significant digits, and both runs stop at the same
#: residual tolerance (1e-6), so they agree far below it (measured 1.6e-12 on the flow rate).
TOL_RESUME = 1e-6


def _first_time(log: Path) -> int:
    for line in log.read_text(errors="replace").splitlines():
        if line.startswith("Time = "):
            return int(line.split()[2])
    raise AssertionError(f"no 'Time =' line in {log}")


def _kill_flow_mid_run(d: Path, scene: str, marker: str) -> None:
    """`fiberform flow --force`, sent SIGTERM once ``marker`` (a time directory) exists."""
    case = d / "runs" / "flowtest" / "flow" / "case"
    rc = terminate_when([sys.executable, "-m", "fiberform", "flow", scene, "--force"], d, case / marker)
    assert rc == 143, rc
    assert not (d / "runs" / "flowtest" / "flow" / "flow.h5").exists()
    assert not processes_under(d), processes_under(d)


@pytest.mark.parametrize("ranks", [1, 2])
def test_killed_flow_resumes_to_the_same_result(stage_run: Path, tmp_path: Path, ranks: int) -> None:
    """SIGTERM to `fiberform flow` after the time directory 200 appeared (it may be half
    written); the rerun (no --force) continues from iteration 100 or 200 and reaches the
    uninterrupted result (the stage_run fixture, 1 rank) within TOL_RESUME."""
    if ranks > (os.cpu_count() or 1):
        pytest.skip("needs 2 cores")
    scene = SCENE.replace("delta_p_Pa: 100.0}", f"delta_p_Pa: 100.0, ranks: {ranks}}}")
    (tmp_path / "s.yaml").write_text(scene)
    r = subprocess.run([sys.executable, "-m", "fiberform", "fabric", "s.yaml"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0, r.stderr
    _kill_flow_mid_run(tmp_path, "s.yaml", "processor0/200" if ranks > 1 else "200")
    d = tmp_path / "runs" / "flowtest" / "flow"
    assert '"failed"' in (d / "stage-state.json").read_text()
    r = subprocess.run([sys.executable, "-m", "fiberform", "flow", "s.yaml"], cwd=tmp_path,
                       capture_output=True, text=True, errors="replace", timeout=600, check=False)
    assert r.returncode == 0, r.stdout + r.stderr
    start = _first_time(d / "log.simpleFoam") - 1
    assert start in (100, 200), start  # a complete time directory, never 0
    assert (d / "log.simpleFoam.earlier").is_file()
    with h5py.File(d / "flow.h5") as f, h5py.File(stage_run / "flow" / "flow.h5") as ref:
        assert int(f["solver"].attrs["resumed_from_iteration"]) == start
        assert int(ref["solver"].attrs["resumed_from_iteration"]) == 0
        assert bool(f["solver"].attrs["converged"])
        if ranks == 1:  # the same iterations as the uninterrupted run (2 ranks converge differently)
            assert abs(int(f["solver"].attrs["iterations"]) - int(ref["solver"].attrs["iterations"])) <= 1
        q, q_ref = float(f["flow_rate/bottom"][()]), float(ref["flow_rate/bottom"][()])
        U, U_ref = f["grid/U"][...], ref["grid/U"][...]
    tol = TOL_RESUME if ranks == 1 else 1e-3  # 2 ranks: the serial-vs-parallel tolerance above
    assert abs(q - q_ref) / q_ref < tol, (q, q_ref)
    assert np.abs(U - U_ref).max() < tol * np.abs(U_ref).max()


def test_changed_input_starts_over(fabric_piece, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """A killed solve is not resumed when an input changed (here flow.delta_p_Pa 100 -> 50 Pa):
    the rerun meshes and solves from iteration 1 and gives the flow rate of a fresh solve at
    50 Pa (run_flow_case in a folder of its own)."""
    (tmp_path / "s.yaml").write_text(SCENE)
    r = subprocess.run([sys.executable, "-m", "fiberform", "fabric", "s.yaml"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0, r.stderr
    _kill_flow_mid_run(tmp_path, "s.yaml", "200")
    (tmp_path / "s.yaml").write_text(SCENE.replace("delta_p_Pa: 100.0", "delta_p_Pa: 50.0"))
    r = subprocess.run([sys.executable, "-m", "fiberform", "flow", "s.yaml"], cwd=tmp_path,
                       capture_output=True, text=True, errors="replace", timeout=600, check=False)
    assert r.returncode == 0, r.stdout + r.stderr
    d = tmp_path / "runs" / "flowtest" / "flow"
    assert _first_time(d / "log.simpleFoam") == 1
    assert not (d / "log.simpleFoam.earlier").exists()
    with h5py.File(d / "flow.h5") as f:
        assert int(f["solver"].attrs["resumed_from_iteration"]) == 0
        q = float(f["flow_rate/bottom"][()])
    fresh = run_flow_case(_setup(fabric_piece, 50.0), fabric_piece[0], tmp_path / "fresh",
                          yarns=fabric_piece[1])  # fmt: skip
    assert q == pytest.approx(fresh.q_bottom_m3_s, rel=TOL_RESUME)


def test_prepare_program_collect_equals_the_one_step_stage(stage_run: Path, tmp_path: Path) -> None:
    """The batch split (issue 14): `fiberform prepare flow`, the solver line run by hand as the
    batch script does, `fiberform collect flow` give the one-step stage's flow rate (same case, same
    solver: equal within TOL_RESUME); prepare of a done stage exits 3; collect refuses a folder
    prepared from other inputs, or not prepared; a stage without a program line cannot be split."""
    (tmp_path / "s.yaml").write_text(SCENE)

    def ff(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "fiberform", *args], cwd=tmp_path, capture_output=True,
                              text=True, errors="replace", timeout=600, check=False)

    assert ff("fabric", "s.yaml").returncode == 0
    r = ff("prepare", "fabric", "s.yaml")
    assert r.returncode == 2 and "runs in one step" in r.stderr, r.stderr
    r = ff("collect", "flow", "s.yaml")
    assert r.returncode == 1 and "prepared.json: missing" in r.stderr, r.stderr
    r = ff("prepare", "flow", "s.yaml")
    assert r.returncode == 0, r.stderr
    d = tmp_path / "runs" / "flowtest" / "flow"
    assert f"run in {d / 'case'}: simpleFoam > {d / 'log.simpleFoam'} 2>&1" in r.stdout, r.stdout
    with open(d / "log.simpleFoam", "w") as log:
        subprocess.run(["simpleFoam"], cwd=d / "case", stdout=log, stderr=subprocess.STDOUT, check=True,
                       env=dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam")))
    r = ff("collect", "flow", "s.yaml")
    assert r.returncode == 0, r.stderr
    with h5py.File(d / "flow.h5") as f, h5py.File(stage_run / "flow" / "flow.h5") as ref:
        q, q_ref = float(f["flow_rate/bottom"][()]), float(ref["flow_rate/bottom"][()])
        assert int(f["solver"].attrs["iterations"]) == int(ref["solver"].attrs["iterations"])
    assert abs(q - q_ref) / q_ref < TOL_RESUME, (q, q_ref)
    assert not (d / "stage-state.json").exists() and not (d / "prepared.json").exists()
    assert ff("prepare", "flow", "s.yaml").returncode == 3  # up to date: the batch job ends here
    assert ff("prepare", "flow", "s.yaml", "--force").returncode == 0
    # the product records the options the run was prepared with (collect has none of its own)
    assert json.loads((d / "prepared.json").read_text())["options"]["force"] is True
    (tmp_path / "s.yaml").write_text(SCENE.replace("delta_p_Pa: 100.0", "delta_p_Pa: 50.0"))
    r = ff("collect", "flow", "s.yaml")
    assert r.returncode == 1 and "prepared from other inputs" in r.stderr, r.stderr
