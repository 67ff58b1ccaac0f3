# SPDX-License-Identifier: GPL-3.0-or-later
"""Two-way coupling of fiberdem and fiberPimpleFoam through the coupling layer (issue 13): real MPI
(one mpirun, MPMD), real LIGGGHTS, real OpenFOAM.

The fluid is plane Couette flow u = U0 z / H in a 1 mm box (openfoam-cases/couette: periodic in x
and y, walls at z = 0 and H, 4 x 4 x 8 cells); the fibers are one vertical fiber across four cells
layers, falling and sheared. Checks:
- momentum: per exchange interval, the momentum the fluid received (sum over cells of fiberSource
  x V x rho x fluid step, from the fields OpenFOAM wrote) equals minus the drag impulse on the
  fibers (sum over steps of fix fiber/drag's total over elements x dt) to round-off;
- one-way limit: with `reaction no` the coupled run equals a frozen-flow run on the same cell
  velocities (flow grid file written here) to 1e-10 relative (1 fiber rank + 1 fluid rank: the
  machine's 2 cores);
- a missing partner (fiberdem alone) and a partner that never answers end with a clear message and a
  non-zero status within the timeout.
"""

from __future__ import annotations

import os
import re
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from foamlib import FoamCase

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beam_cases import ENV as MPI_ENV  # noqa: E402
from beam_cases import RHO, Case, run_case, straight_chain  # noqa: E402

from fiberform.fiber_io import quat_from_frames

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[1]
RHO_F, MU = 998.2, 1.0e-3          # kg/m3, Pa s (nu in openfoam-cases/couette = MU / RHO_F)
U0, H = 0.01, 1e-3                 # lid speed (m/s), gap (m) of openfoam-cases/couette
DT, INTERVAL, EXCHANGES = 1e-7, 10, 12
ENV = {**MPI_ENV, "WM_PROJECT_DIR": os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam")}


@pytest.fixture(scope="module")
def binaries(build_dir: Path) -> tuple[Path, Path]:
    dem, foam = build_dir / "bin" / "fiberdem", build_dir / "bin" / "fiberPimpleFoam"
    for exe in (dem, foam):
        if not exe.is_file():
            pytest.fail(f"{exe} missing: build with cmake --build {build_dir}")
    return dem, foam


def foam_run(case: Path, *cmd: str) -> None:
    proc = subprocess.run(list(cmd), cwd=case, env=ENV, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"{cmd} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"


def couette_case(dest: Path, lid: float = U0) -> Path:
    """openfoam-cases/couette meshed, with the Couette profile of lid speed ``lid`` (m/s) in 0/U and
    the cell centres and volumes in 0/C and 0/V."""
    shutil.copytree(ROOT / "openfoam-cases" / "couette", dest)
    foam_run(dest, "blockMesh")
    foam_run(dest, "postProcess", "-func", "writeCellCentres", "-time", "0")
    foam_run(dest, "postProcess", "-func", "writeCellVolumes", "-time", "0")
    foam = FoamCase(dest)
    z = np.asarray(foam[0]["C"].internal_field)[:, 2]
    u = np.zeros((len(z), 3))
    u[:, 0] = lid * z / H
    foam[0]["U"].internal_field = u
    foam[0]["U"].boundary_field["top"].value = [lid, 0.0, 0.0]
    return dest


def fiber_case(commands: list[str], steps: int, horizontal: bool = False) -> Case:
    """One fiber (7 nodes over 0.3 mm, radius 10 um, 1500 kg/m3) in the middle of the box:
    vertical (across four cell layers) or horizontal along x at the centre of cell layer 4."""
    fib = straight_chain(7, 0.3e-3, [10e-6, 10e-6, 0.0, 0.0], origin=(0.45e-3, 0.55e-3, 0.35e-3))
    if horizontal:
        fib.x[:] = fib.x[:, [2, 1, 0]] + np.array([0.0, 0.0, 0.5625e-3 - 0.45e-3])
        n = fib.n
        fib.q[:] = quat_from_frames(np.tile([0.0, 0.0, -1.0], (n, 1)), np.tile([0.0, 1.0, 0.0], (n, 1)),
                                    np.tile([1.0, 0.0, 0.0], (n, 1)))
    drag = (f"fix drag all fiber/drag flow uniform 0 0 0 fluid_density {RHO_F!r} viscosity {MU!r} "
            "gravity 0 0 -9.81")
    lines = [drag, *commands, "velocity all set 0.0 0.0 -0.002",
             "variable dx equal f_drag[1]", "variable dy equal f_drag[2]", "variable dz equal f_drag[3]",
             'fix pr all print 1 "${dx} ${dy} ${dz}" file drag.txt screen no']
    return Case([fib], [-0.5e-3, -0.5e-3, -0.5e-3], [1.5e-3, 1.5e-3, 1.5e-3], dt=DT, steps=steps,
                fix_options="stiffness_scale 0.01 inertia_scale 1e4 dt_check warn",
                commands=lines, thermo_every=steps)


def coupled(reaction: str, kernel: str = "cell") -> list[str]:
    return [f"fix couple all fiber/coupling drag drag interval {INTERVAL} reaction {reaction} "
            f"kernel {kernel} timeout 60"]


@pytest.mark.parametrize("kernel", ["cell", "trilinear"])
def test_momentum_given_to_fluid_equals_minus_drag_impulse(binaries, tmp_path: Path, kernel: str) -> None:
    dem, foam_exe = binaries
    fluid = couette_case(tmp_path / "fluid")
    run_case(dem.parent.parent, tmp_path / "dem", fiber_case(coupled("yes", kernel), INTERVAL * EXCHANGES),
             partner=[foam_exe, "-coupled", "-case", fluid], timeout_s=300)
    drag = np.loadtxt(tmp_path / "dem" / "drag.txt", ndmin=2)[-INTERVAL * EXCHANGES:]  # steps 1..N
    impulse = drag.reshape(EXCHANGES, INTERVAL, 3).sum(axis=1) * DT   # N s per interval, on fibers

    foam = FoamCase(fluid)
    vol = np.asarray(foam[0]["V"].internal_field)
    times = [step.time for step in foam][1:]
    assert len(times) == EXCHANGES
    assert times[-1] == pytest.approx(EXCHANGES * INTERVAL * DT, rel=1e-9, abs=0)  # fluid step = N dt
    given = np.array([(np.asarray(foam[k]["fiberSource"].internal_field) * vol[:, None]).sum(axis=0)
                      * RHO_F * INTERVAL * DT for k in range(1, EXCHANGES + 1)])
    scale = np.abs(impulse).max()
    assert scale > 1e-15, "no drag: the comparison would be empty"
    # the fiber falls and is sheared: x and z impulses are both non-trivial
    assert np.abs(impulse[:, 0]).min() > 1e-3 * scale and np.abs(impulse[:, 2]).min() > 1e-3 * scale
    err = np.abs(given + impulse).max() / scale
    assert err < 1e-12, f"momentum to the fluid differs from minus the drag impulse by {err:.2e}"
    # the fibers' reaction spans several cell layers (the kernel spreads over the fiber's cells)
    src = np.asarray(foam[EXCHANGES]["fiberSource"].internal_field)
    assert np.count_nonzero(np.abs(src).sum(axis=1)) >= 3


def test_closed_box_pressure_carries_net_weight(binaries, tmp_path: Path) -> None:
    """A horizontal fiber settles in water at rest between walls at z = 0 and H (periodic in x, y:
    no side walls take load). Once the fiber is at terminal velocity its drag carries its weight
    minus buoyancy W - B = (rho_s - rho_f) pi r^2 L g; the reaction pushes the water down and, the
    water's mean vertical momentum being zero between the walls, the mean (dynamic) pressure on the
    bottom exceeds that on the top by (W - B) / A, A the wall area."""
    dem, foam_exe = binaries
    r, length, g, area = 10e-6, 0.3e-3, 9.81, 1e-3 * 1e-3
    net = (RHO - RHO_F) * np.pi * r * r * length * g  # N
    # approach time m / (d drag / d v), drag ~ v^1.22 at Re << 1: tau = v_t rho_s / (1.22 (rho_s - rho_f) g)
    # with v_t < 1 mm/s: tau < 2.5e-4 s; run 2 ms (> 8 tau). Measured 0.4 %; longer runs drift (0.9 %
    # at 3 ms) and other kernels/positions do worse (2.8 %): the cell-centred vertical momentum and
    # the walls' viscous stress take part of the load (docs/coupling/formulation.md, "Known errors";
    # bench/coupling/run_closed_box.py)
    interval, steps = 100, 20000
    fluid = couette_case(tmp_path / "fluid", lid=0.0)
    commands = [f"fix couple all fiber/coupling drag drag interval {interval} timeout 120"]
    case = fiber_case(commands, steps, horizontal=True)
    case.commands = [c for c in case.commands if not c.startswith("velocity")]
    run_case(dem.parent.parent, tmp_path / "dem", case, partner=[foam_exe, "-coupled", "-case", fluid],
             timeout_s=600)
    drag = np.loadtxt(tmp_path / "dem" / "drag.txt", ndmin=2)
    # terminal: the drag carries the net weight; it stays slightly below it because the water below
    # the fiber slowly picks up speed (two-way coupling) and the fiber with it
    assert drag[-1, 2] == pytest.approx(net, rel=5e-3, abs=0), "the fiber is not at terminal velocity"
    foam = FoamCase(fluid)
    layer = np.rint(np.asarray(foam[0]["C"].internal_field)[:, 2] / (H / 8) - 0.5).astype(int)
    p = np.asarray(foam[-1]["p"].internal_field) * RHO_F  # Pa
    assert foam[-1].time == pytest.approx(steps * DT, rel=1e-9, abs=0)
    # wall pressure = the wall cells' pressure (zeroGradient walls)
    dp = p[layer == 0].mean() - p[layer == 7].mean()
    assert dp == pytest.approx(net / area, rel=0.01, abs=0), (dp, net / area)


def write_cell_grid(path: Path, fluid: Path) -> None:
    """The fluid's 0/U as a flow.grid (physics/flow_grid.h format) with nodes at the cell centres."""
    foam = FoamCase(fluid)
    c = np.asarray(foam[0]["C"].internal_field)
    u = np.asarray(foam[0]["U"].internal_field)
    h = np.array([0.25e-3, 0.25e-3, 0.125e-3])
    n = np.array([4, 4, 8])
    idx = np.rint((c - h / 2) / h).astype(int)
    grid = np.zeros((*n, 3))
    grid[idx[:, 0], idx[:, 1], idx[:, 2]] = u
    with path.open("wb") as out:
        out.write(b"FFGRID1\n")
        out.write(struct.pack("<3q", *n))
        out.write(struct.pack("<6d", *(h / 2), *h))
        out.write(grid.astype("<f8").tobytes())


def test_one_way_limit_equals_frozen_flow(binaries, tmp_path: Path) -> None:
    dem, foam_exe = binaries
    steps = INTERVAL * 6
    fluid = couette_case(tmp_path / "fluid")
    write_cell_grid(tmp_path / "flow.grid", fluid)
    frozen = run_case(dem.parent.parent, tmp_path / "frozen",
                      fiber_case(["unfix drag", "fix drag all fiber/drag flow grid ../flow.grid "
                                  f"fluid_density {RHO_F!r} viscosity {MU!r} gravity 0 0 -9.81"], steps))
    both = run_case(dem.parent.parent, tmp_path / "coupled", fiber_case(coupled("no"), steps),
                    partner=[foam_exe, "-coupled", "-case", fluid], timeout_s=300)
    for cols in (slice(1, 4), slice(4, 7)):  # positions, velocities
        a, b = both.final[:, cols], frozen.final[:, cols]
        rel = np.abs(a - b).max() / np.abs(b).max()
        assert rel < 1e-10, f"coupled (reaction no) vs frozen: {rel:.2e}"
    # the fibers moved with the flow (the comparison is not of a state at rest)
    assert np.abs(frozen.final[:, 4]).min() > 1e-4
    # without reaction the fluid kept its Couette profile (an exact steady state of the scheme)
    foam = FoamCase(fluid)
    u_end = np.asarray(foam[-1]["U"].internal_field)
    assert foam[-1].time > 0
    assert np.abs(u_end - np.asarray(foam[0]["U"].internal_field)).max() < 1e-12 * U0


def test_missing_partner_fails_clearly(binaries, tmp_path: Path) -> None:
    dem, _ = binaries
    with pytest.raises(RuntimeError) as err:
        run_case(dem.parent.parent, tmp_path, fiber_case(coupled("yes"), 10), timeout_s=60)
    text = str(err.value)
    assert re.search(r"fiberdem failed \(([1-9]\d*)\)", text), text[-2000:]
    assert "no coupling partner" in text + (tmp_path / "log.case").read_text(errors="replace")


def test_silent_partner_times_out(binaries, tmp_path: Path) -> None:
    """The partner is a second fiberdem without the coupling fix: the handshake gets no answer and
    the coupled side ends the run after its timeout (2 s) with a message naming the wait."""
    dem, _ = binaries
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "in.plain").write_text("units si\nprint done\n")
    case = fiber_case([c.replace("timeout 60", "timeout 2") for c in coupled("yes")], 10)
    with pytest.raises(RuntimeError) as err:
        run_case(dem.parent.parent, tmp_path / "dem", case, timeout_s=60,
                 partner=[dem, "-in", plain / "in.plain", "-log", "none"])
    text = str(err.value)
    assert "no answer from fiberPimpleFoam within the coupling timeout of 2 s" in text, text[-3000:]
    assert re.search(r"fiberdem failed \(([1-9]\d*)\)", text)


def test_viscosity_mismatch_stops_both(binaries, tmp_path: Path) -> None:
    """The fibers' mu (2e-3 Pa s) differs from rho nu of the fluid (1e-3 Pa s): the fluid refuses in
    the handshake, tells fiberdem (Error message) and both end with a non-zero status."""
    dem, foam_exe = binaries
    fluid = couette_case(tmp_path / "fluid")
    case = fiber_case(coupled("yes"), 10)
    case.commands = [c.replace(f"viscosity {MU!r}", "viscosity 0.002") for c in case.commands]
    with pytest.raises(RuntimeError) as err:
        run_case(dem.parent.parent, tmp_path / "dem", case, timeout_s=60,
                 partner=[foam_exe, "-coupled", "-case", fluid])
    text = str(err.value)
    assert "viscosity mismatch: fix fiber/drag has mu = 0.002" in text, text[-3000:]
    assert re.search(r"fiberdem failed \(([1-9]\d*)\)", text)


def test_graded_fluid_mesh_is_refused(binaries, tmp_path: Path) -> None:
    """This version needs a uniform grid of cuboid cells: a graded blockMesh box is refused by the
    fibers in the handshake with the offending cell named, and both programs end non-zero."""
    dem, foam_exe = binaries
    fluid = tmp_path / "fluid"
    shutil.copytree(ROOT / "openfoam-cases" / "couette", fluid)
    mesh_dict = fluid / "system" / "blockMeshDict"
    mesh_dict.write_text(mesh_dict.read_text().replace("simpleGrading (1 1 1)", "simpleGrading (1 1 2)"))
    foam_run(fluid, "blockMesh")
    with pytest.raises(RuntimeError) as err:
        run_case(dem.parent.parent, tmp_path / "dem", fiber_case(coupled("yes"), 10), timeout_s=60,
                 partner=[foam_exe, "-coupled", "-case", fluid])
    text = str(err.value)
    assert "the fluid mesh must be a uniform axis-aligned grid" in text, text[-3000:]
    assert re.search(r"fiberdem failed \(([1-9]\d*)\)", text)
