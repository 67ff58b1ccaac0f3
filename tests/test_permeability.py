# SPDX-License-Identifier: GPL-3.0-or-later
"""Tests of the ``permeability`` stage (issue 12).

Quick (no OpenFOAM): the solid fraction of a cylinder sampled on the lattice against pi a^2, the
flow-rate convergence criterion against a sinusoid, the Tomadakis-Sotirchos law against a value
evaluated by hand, the product paths of the readers against the producing stages, bad
``permeability`` sections (exit status 2 naming the field, nothing written).

System (stock simpleFoam): a square array of cylinders in transverse Stokes flow through the same
box case, capsule rasterisation and cell removal as the stage; the permeability k / a^2 measured
between two planes one period apart inside the array against the closed form of Drummond & Tahir
(1984) at solid fractions 0.05 and 0.1, with mass conservation; the stage end to end on a
coarse bare fabric through the CLI; Darcy consistency: the bare fabric's k from water through the
flow stage equals k from air through this stage (one solid, low Re) within 1 %.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from fiberform.openfoam_case import BoxSetup, make_lattice, run_case
from fiberform.porous_media import (
    CFM_M_S, capsule_fraction, flow_rate_convergence, line_fraction, subgrid_resistance,
    tomadakis_sotirchos,
)  # fmt: skip
from fiberform.products import FABRIC_H5, FIBERS_H5, LAYDOWN_H5

needs_openfoam = pytest.mark.skipif(shutil.which("simpleFoam") is None,
                                    reason="OpenFOAM (simpleFoam) not installed")  # fmt: skip

BARE = """name: permtest
run: {timestep_s: 1.0e-6, duration_s: 1.0e-3}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3, voxel_size_m: 10.0e-6}
permeability: {cells_across_fiber: 2, max_iterations: 2000, convergence_window: 100, pressure_drop_Pa: 10.0}
"""


def drummond_tahir(phi: float) -> float:
    """k / a^2 of a square array of cylinders (radius a, solid fraction phi) in transverse Stokes
    flow: Drummond & Tahir (1984), Int. J. Multiphase Flow 10, 515-540, eq. for the square array,
    k / a^2 = (-ln phi - 1.476 + 2 phi - 1.774 phi^2 + 4.078 phi^3) / (8 phi)."""
    return (-math.log(phi) - 1.476 + 2 * phi - 1.774 * phi**2 + 4.078 * phi**3) / (8 * phi)


# ---- quick ---------------------------------------------------------------------------------


def test_capsule_fraction_of_a_cylinder_is_pi_a2() -> None:
    a, L = 10e-6, 60e-6
    s = BoxSetup(L, 2e-6, 1e-4, 1e-4 + L, 3e-4, 2e-6, 8e-6, 1.0, 1.2, 1.8e-5)
    lat = make_lattice(s)
    chain = (np.array([[L / 2, -a, 1e-4 + L / 2], [L / 2, 2e-6 + a, 1e-4 + L / 2]]), a)
    frac = capsule_fraction([chain], s, lat, subsamples=4)
    assert frac.shape == (lat.nx, lat.ny, lat.n_fabric)
    assert frac.mean() == pytest.approx(math.pi * a**2 / L**2, rel=0.01)
    assert frac.max() == 1.0 and frac.min() == 0.0


def test_convergence_criterion_on_a_sinusoid() -> None:
    it = np.arange(2000.0)
    q = 2.0 + 0.01 * np.sin(2 * math.pi * it / 40.0)  # amplitude 0.01, peaks on iterations
    c = flow_rate_convergence(q, window=480, tolerance=0.02)  # 12 periods
    assert c.window == 480
    assert c.mean_m3_s == pytest.approx(2.0, abs=1e-4)
    assert c.amplitude_m3_s == pytest.approx(0.01, rel=1e-3)
    assert c.relative_amplitude == pytest.approx(0.01, rel=1e-3)
    assert c.converged
    assert not flow_rate_convergence(q, window=500, tolerance=0.005).converged
    # fewer iterations than the window: the second half of the history is used
    assert flow_rate_convergence(q[:300], window=500, tolerance=0.1).window == 150


def test_tomadakis_sotirchos_2d_through_plane() -> None:
    """Tomadakis & Sotirchos (1993) for 2D random fiber structures, flow perpendicular to the
    fiber planes (percolation porosity 0.11, exponent 0.785), evaluated by hand at porosity 0.8:
    0.8 * 0.69^2.785 / (8 (ln 0.8)^2 0.89^0.785 (1.785 * 0.8 - 0.11)^2) = 2.00831 * 0.355776 /
    (0.912578 * 1.737124) = 0.45074; no flow at and below the percolation threshold."""
    a = 10e-6
    assert float(tomadakis_sotirchos(np.array(0.2), a)) == pytest.approx(0.45074 * a**2, rel=1e-4)
    assert float(tomadakis_sotirchos(np.array(0.89), a)) == 0.0
    assert float(tomadakis_sotirchos(np.array(0.95), a)) == 0.0
    k = tomadakis_sotirchos(np.array([0.05, 0.1, 0.2, 0.3]), a)
    assert np.all(np.diff(k) < 0)


def test_reader_paths_match_the_stages() -> None:
    from fiberform.stages import STAGES

    for path, stage in ((FABRIC_H5, "fabric"), (FIBERS_H5, "generate"), (LAYDOWN_H5, "laydown")):
        st = STAGES[stage]
        assert path == Path(st.folder) / st.products[0], stage
    assert "permeability" in STAGES
    assert CFM_M_S == pytest.approx(5.08e-3, rel=1e-12)


@pytest.mark.parametrize("bad,field", [
    ("pressure_drop_Pa: -125.0", "permeability.pressure_drop_Pa"),
    ("mode: voxel", "permeability.mode"),
    ("mode: subgrid, subgrid_law: kozeny", "permeability.subgrid_law"),
    ("subgrid_cell_size_m: 50.0e-6", "permeability.subgrid_cell_size_m"),
    ("mode: subgrid, cells_across_fiber: 4", "permeability.cells_across_fiber"),
    ("density_kg_m3: '1.2'", "permeability.density_kg_m3"),
    ("cells_across_fiber: 0", "permeability.cells_across_fiber"),
    ("cells_across_fiber: 64", "permeability.cells_across_fiber"),
    ("convergence_window: 5000", "permeability.convergence_window"),
    ("ranks: 1.5", "permeability.ranks"),
    ("codeStream: 1", "permeability.codeStream"),
])  # fmt: skip
def test_bad_permeability_section_exits_2(tmp_path: Path, bad: str, field: str) -> None:
    (tmp_path / "s.yaml").write_text(
        "name: bad\nrun: {timestep_s: 1.0e-6, duration_s: 1.0e-3}\n"
        "fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3}\n"
        f"permeability: {{{bad}}}\n"
    )
    r = subprocess.run([sys.executable, "-m", "fiberform", "permeability", "s.yaml"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=60, check=False)  # fmt: skip
    assert r.returncode == 2, r.stdout + r.stderr
    assert field in r.stderr, r.stderr
    assert not (tmp_path / "runs").exists()


# ---- system: square array of cylinders -------------------------------------------------------


def square_array_k(phi: float, cells_across: int, iterations: int, work: Path) -> tuple[float, float, float]:
    """k / a^2, in/out imbalance and Reynolds number of a square array of cylinders (radius a =
    10 um, axis along y, solid fraction phi) in transverse flow along -z: one period L wide
    (symmetry planes through the cylinder centres' mid-lines), one cell deep, three rows; k from
    the plane-mean pressures one period apart inside the array."""
    a = 10e-6
    L = a * math.sqrt(math.pi / phi)
    n = round(cells_across * L / (2 * a))  # cells per period
    h = L / n
    z0, rows = L, 3
    s = BoxSetup(size_x_m=L, size_y_m=h, fabric_lo_z_m=z0, fabric_hi_z_m=z0 + rows * L,
                 top_z_m=z0 + (rows + 1) * L, cell_size_m=h, max_cell_height_m=4 * h,
                 delta_p_Pa=0.02, density_kg_m3=1.204, viscosity_Pa_s=1.81e-5,
                 max_iterations=iterations, residual_tolerance=1e-7)  # fmt: skip
    chains = [(np.array([[L / 2, -a, z0 + (i + 0.5) * L], [L / 2, h + a, z0 + (i + 0.5) * L]]), a)
              for i in range(rows)]  # fmt: skip
    res = run_case(s, lambda s_, lat: capsule_fraction(chains, s_, lat, 4), work,
                   record_flow_rate=True, preserve_volume=True)  # fmt: skip
    conv = flow_rate_convergence(res.history_q_bottom_m3_s, 200, 1e-4)
    assert conv.converged, conv
    lat = make_lattice(s)
    k1 = lat.n_below + n  # first cell layer of the second period (between rows 1 and 2)
    p1, p2 = np.nanmean(res.p[:, :, k1]), np.nanmean(res.p[:, :, k1 + n])
    u_s = res.q_bottom_m3_s / (L * h)
    k = s.viscosity_Pa_s * u_s * L / (p2 - p1)  # flow along -z: p grows with z
    return k / a**2, res.imbalance, s.density_kg_m3 * u_s * 2 * a / s.viscosity_Pa_s


@pytest.mark.system
@needs_openfoam
@pytest.mark.parametrize("phi,across,iterations", [(0.05, 6, 3500), (0.1, 8, 2500)])
def test_square_array_matches_drummond_tahir(phi: float, across: int, iterations: int,
                                             tmp_path: Path) -> None:
    # SIMPLE needs about (gap between cylinders in cells)^2 iterations per e-fold of the flow-rate error
    # at low Re (measured: 210 at phi 0.1 with 8 cells across, 660 at phi 0.05 with 8 across,
    # about 340 with 6): the limits below bring it under 1e-4 (checked by the window criterion
    # inside square_array_k). 6 cells across at phi 0.05 keep the test file under 3 minutes.
    k, imbalance, re = square_array_k(phi, across, iterations, tmp_path)
    ref = drummond_tahir(phi)
    print(f"\nsquare array phi {phi}: k/a^2 {k:.5f}, Drummond-Tahir {ref:.5f}, error "
          f"{k / ref - 1:+.4f}, imbalance {imbalance:.2e}, Re {re:.2e}")
    assert re < 0.05
    assert imbalance < 0.005
    assert k == pytest.approx(ref, rel=0.03)


@pytest.mark.system
@needs_openfoam
@pytest.mark.parametrize("phi", [0.05, 0.1])
def test_subgrid_square_array_matches_drummond_tahir(phi: float, tmp_path: Path) -> None:
    """Sub-grid mode on the same array: no cell removed, one cell per period (2.8 to 4 cylinder
    diameters wide), the cylinders as a Darcy resistance from the Drummond-Tahir law at each
    cell's sampled solid fraction (line_fraction); k from the pressures of rows 2 and 5."""
    a, rows = 10e-6, 6
    L = a * math.sqrt(math.pi / phi)
    s = BoxSetup(size_x_m=L, size_y_m=L, fabric_lo_z_m=L, fabric_hi_z_m=(rows + 1) * L,
                 top_z_m=(rows + 2) * L, cell_size_m=L, max_cell_height_m=4 * L, delta_p_Pa=0.02,
                 density_kg_m3=1.204, viscosity_Pa_s=1.81e-5, max_iterations=1000,
                 residual_tolerance=1e-9)  # fmt: skip
    chains = [(np.array([[L / 2, -a, (i + 1.5) * L], [L / 2, L + a, (i + 1.5) * L]]), a)
              for i in range(rows)]  # fmt: skip
    res = run_case(
        s, lambda s_, lat: np.zeros((lat.nx, lat.ny, lat.n_fabric), np.float32), tmp_path,
        record_flow_rate=True,
        resistance=lambda s_, lat: subgrid_resistance(line_fraction(chains, s_, lat), a,
                                                      "drummond_tahir"),
    )  # fmt: skip
    assert flow_rate_convergence(res.history_q_bottom_m3_s, 100, 1e-4).converged
    u_s = res.q_bottom_m3_s / (L * L)
    lat = make_lattice(s)
    k1 = lat.n_below + 1  # second and fifth row: away from the ends of the porous zone
    p1, p2 = float(res.p[0, 0, k1]), float(res.p[0, 0, k1 + 3])
    k = s.viscosity_Pa_s * u_s * 3 * L / (p2 - p1) / a**2
    k_total = s.viscosity_Pa_s * u_s * rows * L / s.delta_p_Pa / a**2
    print(f"\nsub-grid square array phi {phi}: k/a^2 from the whole drop {k_total:.5f}")
    print(f"\nsub-grid square array phi {phi}: k/a^2 {k:.5f}, Drummond-Tahir "
          f"{drummond_tahir(phi):.5f}, error {k / drummond_tahir(phi) - 1:+.4f}")
    assert res.imbalance < 0.005
    assert k == pytest.approx(drummond_tahir(phi), rel=0.03)


# ---- system: the stage through the CLI -------------------------------------------------------


@pytest.mark.system
@needs_openfoam
def test_stage_on_bare_fabric(tmp_path: Path) -> None:
    (tmp_path / "s.yaml").write_text(BARE)
    env = dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"))
    for stage in ("fabric", "permeability"):
        r = subprocess.run([sys.executable, "-m", "fiberform", stage, "s.yaml"], cwd=tmp_path,
                           env=env, capture_output=True, text=True, errors="replace", timeout=600,
                           check=False)  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
    d = tmp_path / "runs" / "permtest" / "permeability-fabric"
    for name in ("permeability.h5", "report.md", "permeability.png", "log.simpleFoam"):
        assert (d / name).is_file(), name
    with h5py.File(d / "permeability.h5") as f:
        assert f.attrs["stage"] == "permeability"
        assert "fabric_h5" in f.attrs["input_hashes"]
        r_ = f["result"]
        assert bool(r_.attrs["converged"])
        u = float(r_["superficial_velocity"][()])
        assert r_["superficial_velocity"].attrs["units"] == "m/s"
        assert float(r_["cfm"][()]) == pytest.approx(u / 5.08e-3, rel=1e-12)
        q_top, q_bot = float(r_["q_top"][()]), float(r_["q_bottom"][()])
        assert abs(q_top - q_bot) / q_bot < 0.005  # mass conservation
        assert u == pytest.approx(q_bot / 1e-6, rel=1e-3)  # converged: window mean = final
        L = float(r_["layer_thickness"][()])
        assert float(r_["darcy_k"][()]) == pytest.approx(1.81e-5 * u * L / 10.0, rel=1e-12)
        assert len(f["history/q_bottom"]) == int(f["solver"].attrs["iterations"])
    assert "CFM" in (d / "report.md").read_text()


@pytest.mark.system
@needs_openfoam
def test_stage_on_one_and_two_ranks(tmp_path: Path) -> None:
    """permeability.ranks 2 (decomposePar, simpleFoam -parallel) gives the superficial velocity of
    the serial run within 1e-4 (measured: 3.4e-6 on the bare fabric at 10 Pa; domain decomposition
    changes SIMPLE's path, not its fixed point)."""
    env = dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"),
               OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    u = {}
    for ranks in (1, 2):
        (tmp_path / "s.yaml").write_text(BARE.replace("pressure_drop_Pa: 10.0}",
                                                      f"pressure_drop_Pa: 10.0, ranks: {ranks}}}"))
        for stage in ("fabric", "permeability"):
            r = subprocess.run([sys.executable, "-m", "fiberform", stage, "s.yaml"], cwd=tmp_path,
                               env=env, capture_output=True, text=True, errors="replace",
                               timeout=600, check=False)  # fmt: skip
            assert r.returncode == 0, r.stdout + r.stderr
        with h5py.File(tmp_path / "runs" / "permtest" / "permeability-fabric" / "permeability.h5") as f:
            assert bool(f["result"].attrs["converged"])
            assert int(f["solver"].attrs["ranks"]) == ranks
            u[ranks] = float(f["result/superficial_velocity"][()])
    print(f"superficial velocity: 1 rank {u[1]!r} m/s, 2 ranks {u[2]!r} m/s")
    assert u[2] == pytest.approx(u[1], rel=1e-4), u


SHEET = """name: sheettest
run: {timestep_s: 1.0e-6, duration_s: 1.0e-3}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3, voxel_size_m: 10.0e-6}
fibers: {count: 8, length_m: 0.9e-3, width_m: 40.0e-6, segments: 3,
         youngs_modulus_Pa: 1.0e+10, shear_modulus_Pa: 4.0e+9}
laydown: {}
permeability: {MODE, max_iterations: 1500, convergence_window: 100, pressure_drop_Pa: 2.0}
"""


def _write_sheet(root: Path, n: int, top: float) -> None:
    """A laid-down sheet of the first n of 8 straight fibers (radius 20 um) lying on the fabric
    top along x, written as the lay-down and generate stages write it (synthetic products)."""
    r, nodes = 20e-6, 4
    xs = []
    for i in range(n):
        y = (i + 0.5) * 1e-3 / 8
        z = top + r * (1 + 2 * (i % 2))  # alternate fibers one diameter higher
        xs.append(np.stack([np.linspace(0.05e-3, 0.95e-3, nodes), np.full(nodes, y),
                            np.full(nodes, z)], axis=1))  # fmt: skip
    (root / "laydown").mkdir(parents=True, exist_ok=True)
    (root / "fibers").mkdir(parents=True, exist_ok=True)
    with h5py.File(root / LAYDOWN_H5, "w") as f:
        f["sheet/x"] = np.concatenate(xs) if xs else np.zeros((0, 3))
        f["sheet/offsets"] = np.arange(n + 1) * nodes
        f["sheet/fiber_id"] = np.arange(n)
    with h5py.File(root / FIBERS_H5, "w") as f:
        f["fibers/offsets"] = np.arange(9) * nodes
        f["fibers/radii"] = np.tile([r, r, 0.0, 0.0], (8 * nodes, 1))


@pytest.mark.system
@needs_openfoam
@pytest.mark.parametrize("mode", ["cells_across_fiber: 1", "mode: subgrid, subgrid_cell_size_m: 50.0e-6"])
def test_sheet_permeability_decreases_as_fibers_are_added(tmp_path: Path, mode: str) -> None:
    from fiberform.products import read_fabric_image

    (tmp_path / "s.yaml").write_text(SHEET.replace("MODE", mode))
    env = dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"))
    run = [sys.executable, "-m", "fiberform"]
    r = subprocess.run([*run, "fabric", "s.yaml"], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=120, check=False)  # fmt: skip
    assert r.returncode == 0, r.stderr
    root = tmp_path / "runs" / "sheettest"
    top = float(read_fabric_image(root / FABRIC_H5).upper[2])
    speeds = []
    for n in (0, 4, 8):  # nested fiber sets on the same fabric
        _write_sheet(root, n, top)
        r = subprocess.run([*run, "permeability", "s.yaml"], cwd=tmp_path, env=env,
                           capture_output=True, text=True, timeout=600, check=False)  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
        with h5py.File(root / "permeability-laydown" / "permeability.h5") as f:
            assert bool(f["result"].attrs["converged"])
            assert int(f["solver"].attrs["fibers"]) == n
            assert float(f["result/imbalance"][()]) < 0.005
            speeds.append(float(f["result/superficial_velocity"][()]))
    print(f"\nsuperficial velocity with 0, 4, 8 fibers: {speeds} m/s")
    assert speeds[0] > speeds[1] > speeds[2] > 0


# ---- system: Darcy consistency of the two stages ---------------------------------------------

DARCY = """name: darcytest
run: {timestep_s: 1.0e-6, duration_s: 1.0e-3}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3, voxel_size_m: 10.0e-6}
fluid: {density_kg_m3: 998.2, viscosity_Pa_s: 1.0e-3}
flow: {cell_size_m: 5.5e-5, delta_p_Pa: 0.05, height_above_fabric_m: 0.5e-3,
       max_cell_height_m: 0.22e-3, max_iterations: 2000, residual_tolerance: 1.0e-8}
permeability: {cells_across_fiber: 2, pressure_drop_Pa: 0.02, height_above_m: 0.5e-3,
               max_cell_height_m: 0.22e-3, max_iterations: 2000, residual_tolerance: 1.0e-8,
               convergence_window: 200, convergence_tolerance: 1.0e-4}
"""


@pytest.mark.system
@needs_openfoam
def test_darcy_water_flow_stage_vs_air_permeability_stage(tmp_path: Path) -> None:
    """The bare fabric's Darcy permeability k = mu u_s L / delta_p is a property of its geometry:
    water through the flow stage (998.2 kg/m^3, 1e-3 Pa s, 0.05 Pa) and air through the
    permeability stage (1.204 kg/m^3, 1.81e-5 Pa s, 0.02 Pa), both at pore Reynolds numbers far
    below 1, give one k within 1 %; both stages build one solid (the same cells removed: 55 um
    cells, two across the 110 um warp) and conserve mass within 0.5 %."""
    (tmp_path / "s.yaml").write_text(DARCY)
    env = dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"))
    for stage in ("fabric", "flow", "permeability"):
        r = subprocess.run([sys.executable, "-m", "fiberform", stage, "s.yaml"], cwd=tmp_path,
                           env=env, capture_output=True, text=True, errors="replace", timeout=900,
                           check=False)  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
    root = tmp_path / "runs" / "darcytest"
    d_warp = 0.11e-3  # the thinnest yarn (fabric.md_diameter_m default)
    with h5py.File(root / "flow" / "flow.h5") as f:
        sv = f["solver"].attrs
        assert bool(sv["converged"])
        L_w = float(sv["setup_fabric_hi_z_m"]) - float(sv["setup_fabric_lo_z_m"])
        u_w = float(f["flow_rate/bottom"][()]) / 1e-6
        imb_w = abs(float(f["flow_rate/top"][()]) / float(f["flow_rate/bottom"][()]) - 1)
        fluid_w = f["lattice/fluid"][...]
        umax_w = float(np.max(np.linalg.norm(f["lattice/U"][...], axis=-1)))
    with h5py.File(root / "permeability-fabric" / "permeability.h5") as f:
        r_ = f["result"]
        assert bool(r_.attrs["converged"])
        assert float(r_["window_relative_range"][()]) <= 1e-4
        L_a = float(r_["layer_thickness"][()])
        u_a = float(r_["superficial_velocity"][()])
        imb_a = abs(float(r_["q_top"][()]) / float(r_["q_bottom"][()]) - 1)
        k_stage = float(r_["darcy_k"][()])
        fluid_a = f["lattice/fluid"][...]
        umax_a = float(np.max(np.linalg.norm(f["lattice/U"][...].astype(np.float64), axis=-1)))
    # one geometry: the same lattice, the same cells removed, the same layer
    assert fluid_w.shape == fluid_a.shape
    assert np.array_equal(fluid_w, fluid_a), f"{int(np.sum(fluid_w != fluid_a))} cells differ"
    assert L_w == pytest.approx(L_a, rel=1e-12)
    # low Reynolds number: superficial and largest cell velocity over the warp diameter
    re_w, re_a = 998.2 * u_w * d_warp / 1e-3, 1.204 * u_a * d_warp / 1.81e-5
    re_pore_w, re_pore_a = 998.2 * umax_w * d_warp / 1e-3, 1.204 * umax_a * d_warp / 1.81e-5
    k_w = 1e-3 * u_w * L_w / 0.05
    k_a = 1.81e-5 * u_a * L_a / 0.02
    print(f"\nDarcy k of the bare fabric: water (flow stage) {k_w:.6e} m^2, air (permeability "
          f"stage) {k_a:.6e} m^2, ratio - 1 {k_w / k_a - 1:+.2e}; Re superficial {re_w:.2e}, "
          f"{re_a:.2e}, largest cell velocity {re_pore_w:.2e}, {re_pore_a:.2e}; imbalance "
          f"{imb_w:.1e}, {imb_a:.1e}; {int(fluid_w.sum())} fluid cells")
    assert max(re_pore_w, re_pore_a) < 0.1
    assert imb_w < 0.005 and imb_a < 0.005
    assert k_stage == pytest.approx(k_a, rel=1e-12)
    assert k_w == pytest.approx(k_a, rel=0.01)
