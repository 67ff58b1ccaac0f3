# SPDX-License-Identifier: GPL-3.0-or-later
"""Two-way coupling on several ranks (issue 13, "Ranks"): fiberdem on A ranks and fiberPimpleFoam
-coupled on B ranks (B > 1: -parallel with the rebuilt libPstream, scripts/setup/openfoam-pstream.sh)
under one mpirun, real MPI, LIGGGHTS and OpenFOAM.

The case of tests/test_coupling.py's momentum test: plane Couette flow (openfoam-cases/couette,
4 x 4 x 8 cells, lid 0.01 m/s) and one vertical fiber falling and sheared across four cell layers,
12 exchanges of 10 fiber steps. B = 2 decomposes the fluid into two slabs in z (decomposePar, simple
1 1 2): the slab boundary (z = 0.5 mm) crosses the fiber, so both fluid ranks receive reaction.
Runs on 1+1, 1+2, 2+1 and 2+2 ranks (up to 4 processes on the 2-core machine: --oversubscribe).

Checks:
- the fibers' final node positions and the fluid's U and p after the last exchange agree with the
  1+1 run within the tolerance derived from the linear-solver tolerance (see ``field_tolerance``);
- momentum on 2 fluid ranks: per exchange, the momentum the fluid received (sum over the cells of all
  ranks) equals minus the drag impulse on the fibers to round-off (1e-12 relative, as on one rank);
- a failing partner with B = 2 ends every process with a non-zero status (no hang).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest
from foamlib import FoamCase, FoamFile

from fiberform._versions import pstream_dir

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beam_cases import run_case  # noqa: E402
from test_coupling import (DT, EXCHANGES, INTERVAL, RHO_F, binaries, coupled,  # noqa: E402, F401
                           couette_case, fiber_case, foam_run)

pytestmark = pytest.mark.system

# linear-solver tolerance of the test case (OpenFOAM's normalised residual), p and U, relTol 0
SOLVER_TOL = 1e-13
RANKS = [(1, 1), (1, 2), (2, 1), (2, 2)]


def field_tolerance() -> float:
    """Relative tolerance (max norm) between runs on different rank counts, from the solver tolerance.

    Each run solves every linear system to a normalised residual r <= SOLVER_TOL (OpenFOAM's
    residual: sum |b - A x| over the 1-norm of the right-hand side, about). The runs differ only in
    how far each solve stops from the exact discrete solution: the decomposed preconditioners and the
    order of parallel sums change the iterates, not the converged system. A residual of relative size
    r moves the solution by at most cond_2(A) r in the 2-norm; turning the 1-norm residual and the
    max-norm error into 2-norms costs at most a factor n (cells). The pressure equation is the worst
    conditioned: the 7-point Laplacian on 4 x 4 x 8 cells of 0.25 x 0.25 x 0.125 mm, periodic in x
    and y and closed in z, has eigenvalues (4/h^2) sin^2(pi k / (2 n)) per direction: lambda_max =
    4 (2/hx^2 + 1/hz^2), the lowest non-zero one (4/hz^2) sin^2(pi/16) (the pressure level is fixed
    at a point), cond_2 about 39. The scheme is stable (an error carried into the next step does
    not grow), so errors of successive solves add at most: one momentum and two pressure solves per
    exchange. Result: 39 x 128 x 36 x 1e-13 = 1.8e-8. Measured (1 + 2 vs 1 + 1): U 1.5e-15,
    p 7e-11 (the final residuals reach about 4e-15, below SOLVER_TOL)."""
    hx, hz, cells = 0.25e-3, 0.125e-3, 4 * 4 * 8
    lam_max = 4.0 * (2.0 / hx**2 + 1.0 / hz**2)
    lam_min = 4.0 / hz**2 * np.sin(np.pi / 16.0) ** 2
    solves = 3 * EXCHANGES
    return float(lam_max / lam_min * cells * solves * SOLVER_TOL)


@pytest.fixture(scope="module")
def pstream() -> Path:
    lib = pstream_dir() / "libPstream.so"
    if not lib.is_file():
        pytest.fail(f"{lib} missing: run `make setup` (scripts/setup/openfoam-pstream.sh)")
    return pstream_dir()


def fluid_case(dest: Path, ranks: int) -> Path:
    """openfoam-cases/couette with the Couette profile, solvers to SOLVER_TOL (relTol 0), the
    pressure level fixed at a point (the same cell however the mesh is decomposed), and decomposed
    into ``ranks`` slabs in z when ranks > 1."""
    fluid = couette_case(dest)
    with FoamFile(fluid / "system" / "fvSolution") as f:
        for name in ("p", "pFinal", '"U|UFinal"'):
            f["solvers"][name]["tolerance"] = SOLVER_TOL
            f["solvers"][name]["relTol"] = 0
        del f["PIMPLE"]["pRefCell"]
        f["PIMPLE"]["pRefPoint"] = [1.25e-4, 1.25e-4, 6.25e-5]  # the centre of cell 0
    if ranks > 1:
        (fluid / "system" / "decomposeParDict").write_text(
            "FoamFile { version 2.0; format ascii; class dictionary; object decomposeParDict; }\n"
            f"numberOfSubdomains {ranks};\nmethod simple;\n"
            f"coeffs {{ n (1 1 {ranks}); delta 0.001; }}\n")
        foam_run(fluid, "decomposePar", "-force")
    return fluid


def run_coupled(binaries, work: Path, fibers: int, fluid_ranks: int, pstream: Path,
                commands: list[str] | None = None, steps: int = INTERVAL * EXCHANGES,
                timeout_s: float = 240):
    dem, foam_exe = binaries
    fluid = fluid_case(work / "fluid", fluid_ranks)
    partner = [foam_exe, "-coupled", "-case", fluid] + (["-parallel"] if fluid_ranks > 1 else [])
    env = {"LD_LIBRARY_PATH": str(pstream)} if fluid_ranks > 1 else {}
    result = run_case(dem.parent.parent, work / "dem", fiber_case(commands or coupled("yes"), steps),
                      ranks=fibers, partner=partner, partner_ranks=fluid_ranks, env=env,
                      timeout_s=timeout_s)
    if fluid_ranks > 1:
        foam_run(fluid, "reconstructPar", "-fields", "(U p fiberSource)")
    return result, fluid


@pytest.fixture(scope="module")
def runs(binaries, pstream, tmp_path_factory) -> dict:
    out = {}
    for a, b in RANKS:
        work = tmp_path_factory.mktemp(f"ranks{a}_{b}")
        result, fluid = run_coupled(binaries, work, a, b, pstream)
        out[(a, b)] = (result, fluid, work)
    return out


def last_fields(fluid: Path) -> tuple[float, np.ndarray, np.ndarray]:
    step = FoamCase(fluid)[-1]
    return step.time, np.asarray(step["U"].internal_field), np.asarray(step["p"].internal_field)


@pytest.mark.parametrize("ranks", RANKS[1:], ids=lambda r: f"{r[0]}+{r[1]}")
def test_ranks_agree_with_one_plus_one(runs, ranks) -> None:
    tol = field_tolerance()
    ref, ref_fluid, _ = runs[(1, 1)]
    got, fluid, _ = runs[ranks]
    # fluid: the last time written, U and p over all cells (reconstructed in global order)
    t_ref, u_ref, p_ref = last_fields(ref_fluid)
    t_got, u_got, p_got = last_fields(fluid)
    run_time = DT * INTERVAL * EXCHANGES
    assert t_got == pytest.approx(t_ref, rel=1e-12) and t_ref == pytest.approx(run_time, rel=1e-9)
    assert np.abs(p_ref).max() > 0, "no pressure: the comparison would be empty"
    du = np.abs(u_got - u_ref).max() / np.abs(u_ref).max()
    dp = np.abs(p_got - p_ref).max() / np.abs(p_ref).max()
    assert du <= tol and dp <= tol, f"{ranks}: U differs by {du:.2e}, p by {dp:.2e} (tolerance {tol:.2e})"
    # fibers: their drag follows the fluid velocity without gain, so their velocities differ by at
    # most tol x the fluid's velocity scale, their positions by that x the run time
    u_scale = np.abs(u_ref).max()
    dv = np.abs(got.final[:, 4:7] - ref.final[:, 4:7]).max()
    dx = np.abs(got.final[:, 1:4] - ref.final[:, 1:4]).max()
    assert np.abs(ref.final[:, 4:7]).max() > 1e-4, "the fibers did not move: the comparison would be empty"
    assert dv <= tol * u_scale, f"{ranks}: fiber velocities differ by {dv:.3e} m/s"
    assert dx <= tol * u_scale * run_time, f"{ranks}: fiber positions differ by {dx:.3e} m"


def test_momentum_on_two_fluid_ranks(runs) -> None:
    """Per exchange, the momentum the fluid received on its two ranks (fiberSource x V x rho x fluid
    step, summed over the cells of both ranks after reconstructPar) equals minus the drag impulse on
    the fibers to round-off: each exchange cell's force reaches exactly one cell of one rank."""
    _, fluid, work = runs[(1, 2)]
    assert (fluid / "processor1").is_dir()
    drag = np.loadtxt(work / "dem" / "drag.txt", ndmin=2)[-INTERVAL * EXCHANGES:]
    impulse = drag.reshape(EXCHANGES, INTERVAL, 3).sum(axis=1) * DT
    foam = FoamCase(fluid)
    vol = np.asarray(foam[0]["V"].internal_field)
    assert len(foam) == EXCHANGES + 1
    given = np.array([(np.asarray(foam[k]["fiberSource"].internal_field) * vol[:, None]).sum(axis=0)
                      * RHO_F * INTERVAL * DT for k in range(1, EXCHANGES + 1)])
    scale = np.abs(impulse).max()
    assert scale > 1e-15 and np.abs(impulse[:, 2]).min() > 1e-3 * scale
    err = np.abs(given + impulse).max() / scale
    assert err < 1e-12, f"momentum to the fluid on 2 ranks differs from minus the drag impulse by {err:.2e}"
    # the reaction reached cells of both ranks (the fiber crosses the slab boundary z = 0.5 mm)
    for proc in ("processor0", "processor1"):
        src = np.asarray(FoamCase(fluid / proc)[-1]["fiberSource"].internal_field)
        assert np.count_nonzero(np.abs(src).sum(axis=1)) >= 1, proc


def test_fibers_failing_ends_two_fluid_ranks(binaries, pstream, tmp_path: Path) -> None:
    """fiberdem stops with an input error after 3 of 12 exchanges (LIGGGHTS' Error::all, which
    ends with MPI_Finalize): in a coupled run fiberdem turns that into an abort of the whole job
    (status 4), and mpirun ends all four processes (2 fiber + 2 fluid ranks) instead of leaving the
    fluid to its timeout (-couplingTimeout 3 s; before, mpirun was once seen to hang in that state)."""
    dem, foam_exe = binaries
    fluid = fluid_case(tmp_path / "fluid", 2)
    # a variable that fails when fix print evaluates it at step 3 x INTERVAL + 1
    commands = [*coupled("yes"), "variable bad equal v_undefined_name",
                f'fix fail all print {3 * INTERVAL + 1} "${{bad}}" screen no']
    case = fiber_case(commands, INTERVAL * EXCHANGES)
    partner = [foam_exe, "-coupled", "-parallel", "-couplingTimeout", "3", "-case", fluid]
    with pytest.raises(RuntimeError) as err:
        run_case(dem.parent.parent, tmp_path / "dem", case, ranks=2, partner=partner, partner_ranks=2,
                 env={"LD_LIBRARY_PATH": str(pstream)}, timeout_s=120)
    text = str(err.value)
    assert "fiberdem failed (4)" in text, text[-3000:]
    assert "ERROR: Invalid variable name" in text, text[-3000:]
    assert "the fibers' side of the coupled run ended with an error" in text, text[-3000:]


def test_viscosity_mismatch_stops_two_fluid_ranks(binaries, pstream, tmp_path: Path) -> None:
    """The handshake check of the fluid leader with B = 2: both programs end, status non-zero."""
    dem, foam_exe = binaries
    fluid = fluid_case(tmp_path / "fluid", 2)
    case = fiber_case(coupled("yes"), 10)
    case.commands = [c.replace("viscosity 0.001", "viscosity 0.002") for c in case.commands]
    partner = [foam_exe, "-coupled", "-parallel", "-case", fluid]
    with pytest.raises(RuntimeError) as err:
        run_case(dem.parent.parent, tmp_path / "dem", case, partner=partner, partner_ranks=2,
                 env={"LD_LIBRARY_PATH": str(pstream)}, timeout_s=120)
    text = str(err.value)
    assert "viscosity mismatch: fix fiber/drag has mu = 0.002" in text, text[-3000:]
    assert re.search(r"fiberdem failed \(([1-9]\d*)\)", text)


def test_parallel_fluid_refuses_stock_pstream(binaries, tmp_path: Path) -> None:
    """Without the rebuilt libPstream, -coupled -parallel stops before MPI starts (status 2 ends the
    mpirun) instead of taking the fibers' ranks for fluid ranks and hanging."""
    dem, foam_exe = binaries
    fluid = fluid_case(tmp_path / "fluid", 2)
    with pytest.raises(RuntimeError) as err:
        run_case(dem.parent.parent, tmp_path / "dem", fiber_case(coupled("yes"), 10),
                 partner=[foam_exe, "-coupled", "-parallel", "-case", fluid], partner_ranks=2,
                 env={"LD_LIBRARY_PATH": ""}, timeout_s=120)
    assert "-coupled -parallel needs OpenFOAM's libPstream rebuilt" in str(err.value)
