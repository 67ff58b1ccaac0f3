# SPDX-License-Identifier: GPL-3.0-or-later
"""System tests of the ``flow`` stage: OpenFOAM (blockMesh, topoSet, subsetMesh, simpleFoam) on a
coarse 1 x 1 mm piece of the default fabric (50 um cells, about 15,000 fluid cells).

* the stage runs end to end through the CLI and writes its products with provenance;
* mass is conserved: inflow through the top = outflow through the bottom within 0.5 %;
* the superficial velocity of the bare fabric grows monotonically with the pressure drop and, at
  low Reynolds number, linearly (Darcy);
* a 2-rank run (decomposePar + simpleFoam -parallel) gives the serial flow rate.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

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
