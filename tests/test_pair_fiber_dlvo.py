# SPDX-License-Identifier: GPL-3.0-or-later
"""System tests of pair_style fiber/dlvo (thesis Kettil 2016, sections 2.4 and 4.1) through
fiberdem and liggghts-fiber-style/examples/in.fiber_collision.

Set-up (thesis 4.1): two straight fibers, L = 0.1 mm, D = 14 um, rho = 1500 kg/m3, parallel to y,
initial surface gap 12 um; fiber 2 moves at v0 towards fiber 1. ONE convention: each fiber is a
chain of 5 nodes (4 elements) driven by fix fiber/beam (rigid-equivalent settings), which gives the
contact style its topology. Test-size reduction (docs/models/contact.md section 7): the long runs
use L = 20 um instead of 0.1 mm; the points-per-element rule is applied unchanged (so 180 instead
of 897 points per fiber) and mass and force per unit length are the same, so the parallel-fiber
physics per unit length is unchanged. Assertions use independent numbers only: h_min = -D (thesis eq. 2.37), momentum
of the initial state, kinetic energy of the initial state, the attractive work bound
n_points * A R_eff / (6 h0) * 2 (eq. 2.25 integrated from h0, plus at most as much again from the
spline), and the 1-rank run for the 2-rank run."""
from __future__ import annotations

import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fiberform.liggghts_log import thermo_rows

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "liggghts-fiber-style" / "examples" / "in.fiber_collision"

pytestmark = pytest.mark.system

L, D, RHO = 1.0e-4, 1.4e-5, 1500.0
M_FIBER = RHO * math.pi * (D / 2) ** 2 * L
A_HAMAKER, H0 = 8.0e-21, 1.0e-9
R_EFF = (D / 2) / 2
COLUMNS = ["step", "time", "v_hsep", "v_px", "v_pz", "v_vx1", "v_vx3", "v_kin", "solves", "rhs_evals", "v_x1", "v_x3"]
L_SHORT = 2.0e-5


def write_nodes(path: Path, length: float) -> None:
    """fix fiber/beam nodes file of the two 5-node fibers along +y (t3 = y)."""
    s = math.sqrt(0.5)
    lines = []
    for f in range(2):
        for k in range(5):
            lines.append(f"{f * 5 + k + 1} {f + 1} {k} 5 {D / 2!r} {D / 2!r} 0 0 {f * 2 * D!r} "
                         f"{-length / 2 + k * length / 4!r} 0 {s!r} {-s!r} 0 0")
    path.write_text("\n".join(lines) + "\n")


def _points_per_fiber(length: float = L, h_match: float = 1e-9) -> int:
    # thesis 2.4.3: spacing so that sphere-sphere vdW sums to the parallel-cylinder force (4 elements)
    spacing = 4 * math.sqrt(2) / 3 * math.sqrt(R_EFF * h_match)
    return 4 * max(1, round(length / 4 / spacing))


def _fiberdem() -> Path:
    exe = (Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")) / "bin" / "fiberdem").resolve()
    if not exe.exists():
        pytest.fail(f"{exe} not built: run `make setup`")
    return exe


def _thermo(log: str, columns: list[str]) -> dict[str, np.ndarray]:
    """Thermo rows of a LIGGGHTS log (between a "Step Time ..." header and "Loop time"), as
    columns named by `columns` (LIGGGHTS abbreviates long header names, so the caller names them)."""
    rows = thermo_rows(log)
    assert rows, f"no thermo output:\n{log[-2000:]}"
    data = np.array(rows)
    return {c: data[:, i] for i, c in enumerate(columns)}


def _run(workdir: Path, ranks: int = 1, length: float = L, example: Path = EXAMPLE,
         **var: str) -> dict[str, np.ndarray]:
    workdir.mkdir(parents=True, exist_ok=True)
    write_nodes(workdir / "nodes", length)
    cmd = [str(_fiberdem()), "-in", str(example), "-log", "log.fiberdem", "-screen", "none",
           "-var", "nodes", "nodes", "-var", "L", repr(length)]
    var.setdefault("every", "1")
    for k, v in var.items():
        cmd += ["-var", k, str(v)]
    if ranks > 1:
        cmd = ["mpirun", "-np", str(ranks), "--oversubscribe"] + cmd
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    res = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, errors="replace", timeout=600)
    log = (workdir / "log.fiberdem").read_text() if (workdir / "log.fiberdem").exists() else ""
    assert res.returncode == 0, f"fiberdem failed:\n{res.stdout[-2000:]}\n{res.stderr[-2000:]}\n{log[-2000:]}"
    # LIGGGHTS abbreviates the header; the column order is fixed by in.fiber_collision
    out = _thermo(log, COLUMNS)
    out["dump"] = np.loadtxt(workdir / var.get("dump", "final.dump"), skiprows=9)
    return out


def _ke0(v0: float, length: float = L) -> float:
    return 0.5 * M_FIBER * length / L * v0**2


def _attractive_work_bound(length: float = L) -> float:
    return 2.0 * _points_per_fiber(length) * A_HAMAKER * R_EFF / (6 * H0)


def test_collision_4_1_1(tmp_path):
    """50 mm/s head-on: no pass-through, the moving fiber pushes the other, momentum conserved."""
    v0 = 0.05
    out = _run(tmp_path, v0=v0, tend=3.2e-4)
    assert np.all(out["v_hsep"] > -D), "fibers passed into each other (h <= h_min = -D)"
    assert out["v_hsep"].min() > -0.1 * D
    # the resting fiber has been pushed along -x by a sizeable fraction of v0
    assert out["v_vx1"][-1] < -0.3 * v0
    p0 = -M_FIBER * v0
    assert np.all(np.abs(out["v_px"] - p0) <= 1e-6 * abs(p0))
    assert out["solves"][-1] > 0, "no contact was sub-integrated"


def test_elastic_head_on_conserves_energy(tmp_path):
    """Steric only, damping terms off (S1 as a pure spring): kinetic energy within 1 %."""
    v0 = 0.05
    out = _run(tmp_path, v0=v0, tend=3.6e-4, terms="steric", extra="s1_damping no steric_terms s1")
    ke = out["v_kin"]
    assert abs(ke[-1] / _ke0(v0) - 1) < 0.01
    assert np.all(ke <= _ke0(v0) * 1.01)
    # the collision did happen: velocities exchanged (equal masses, elastic)
    assert out["v_vx1"][-1] < -0.99 * v0 and abs(out["v_vx3"][-1]) < 0.01 * v0


def test_one_vs_two_ranks(tmp_path):
    """Same final state on 1 and 2 ranks (relative 1e-10); the fibers sit on different ranks."""
    kw = dict(v0=0.05, gap=2e-8, tend=2e-5, every=1000)
    a = _run(tmp_path / "np1", 1, **kw)["dump"]
    b = _run(tmp_path / "np2", 2, **kw)["dump"]
    a, b = a[a[:, 0].argsort()], b[b[:, 0].argsort()]
    scale_x, scale_v = L, 0.05
    assert np.all(np.abs(a[:, 2:5] - b[:, 2:5]) <= 1e-10 * scale_x)
    assert np.all(np.abs(a[:, 5:8] - b[:, 5:8]) <= 1e-10 * scale_v)
    # and something happened: the contact changed the velocities
    assert abs(a[0, 5]) > 1e-4


def _separated_at_end(out) -> bool:
    """True if the fibers are apart by more than the force range and moving apart."""
    d = out["dump"]
    d = d[d[:, 0].argsort()]
    r = d[7, 2:5] - d[2, 2:5]
    v = d[7, 5:8] - d[2, 5:8]
    r[1] = 0.0
    return np.linalg.norm(r) - D > 1e-7 and float(v @ r) > 0


@pytest.mark.parametrize("v0,attached", [(0.01, True), (0.05, False)])
def test_adhesion_4_1_2(tmp_path, v0, attached):
    """Thesis 4.1.2: fiber 2 shifted 12 um in z; at 10 mm/s the fibers stay attached, at 50 mm/s they
    separate. Documented parameter set = the defaults of pair_style fiber/dlvo with terms vdw,steric
    (the thesis investigates the van der Waals adhesion). Momentum is conserved in this glancing
    contact too (one-sided point pairs are averaged)."""
    # contact starts after (D + gap - sqrt(D^2 - dz^2)) / v0; then 0.6 ms more
    tend = (D + 12e-6 - math.sqrt(D**2 - 12e-6**2)) / v0 + 6e-4
    out = _run(tmp_path, length=L_SHORT, v0=v0, dz=12e-6, tend=tend, every=20)
    assert out["solves"][-1] > 0
    assert bool(_separated_at_end(out)) == (not attached)
    if attached:
        assert out["v_hsep"][-1] < 5e-9
    p0 = -M_FIBER * L_SHORT / L * v0
    assert np.all(np.abs(out["v_px"] - p0) <= 1e-6 * abs(p0))


@pytest.mark.parametrize("v0", [1.0, 5.0])
def test_stability_fast_head_on(tmp_path, v0):
    out = _run(tmp_path, v0=v0, gap=2e-7, tend=2e-5)
    assert np.all(np.isfinite(out["v_kin"]))
    assert np.all(out["v_hsep"] > -D)
    assert np.all(out["v_kin"] <= _ke0(v0) + _attractive_work_bound())


def test_stability_start_in_overlap(tmp_path):
    """Start at 50 % overlap (h = -D/2), at rest: the steric force must separate them without
    injecting more kinetic energy than the attractive work bound (S4 caps the push-out speed).
    No NaN, no pass-through; the overlap is resolved."""
    out = _run(tmp_path, length=L_SHORT, v0=0.0, gap=-0.5 * D, tend=1.2e-3, every=20)
    assert np.all(np.isfinite(out["v_kin"]))
    assert np.all(out["v_hsep"] > -D)
    assert out["v_kin"].max() <= _attractive_work_bound(L_SHORT)
    assert out["v_hsep"][-1] > -1e-9


@pytest.mark.parametrize("dt", [1e-9, 1e-8, 1e-7, 1e-6])
def test_stability_time_steps(tmp_path, dt):
    v0 = 0.05
    out = _run(tmp_path, v0=v0, gap=2e-8, dt=dt, tend=max(300 * dt, 2e-6), every=10)
    assert np.all(np.isfinite(out["v_kin"]))
    assert np.all(out["v_hsep"] > -D)
    assert np.all(out["v_kin"] <= _ke0(v0) + _attractive_work_bound())


WALL = ROOT / "liggghts-fiber-style" / "examples" / "in.fiber_wall"


def _run_wall(workdir: Path, **var) -> dict[str, np.ndarray]:
    workdir.mkdir(parents=True, exist_ok=True)
    s = math.sqrt(0.5)
    (workdir / "nodes").write_text("".join(
        f"{k + 1} 1 {k} 5 {D / 2!r} {D / 2!r} 0 0 0 {-L_SHORT / 2 + k * L_SHORT / 4!r} 0 {s!r} {-s!r} 0 0\n"
        for k in range(5)))
    cmd = [str(_fiberdem()), "-in", str(WALL), "-log", "log", "-screen", "none", "-var", "nodes", "nodes",
           "-var", "L", repr(L_SHORT)]
    for k, v in var.items():
        cmd += ["-var", k, str(v)]
    res = subprocess.run(cmd, cwd=workdir, capture_output=True, text=True, errors="replace", timeout=600)
    log = (workdir / "log").read_text()
    assert res.returncode == 0, log[-2000:]
    return _thermo(log, ["step", "time", "zlo", "zhi", "vz", "kin", "solves", "psolves"])


def test_wall_bounce_steric_only(tmp_path):
    """fix wall/fiber/dlvo: a fiber hitting a plane wall at 5 cm/s (steric law only): it never
    passes through the wall (h > -r), its kinetic energy never exceeds the initial value (the
    steric terms are dissipative or a saturated spring, nothing attracts), and it comes back off
    the wall (rebound, or at least stopped: no sticking without attraction)."""
    v0 = 0.05
    out = _run_wall(tmp_path, vz0=v0, z0=D / 2 + 50e-9, tend=2e-4, vp=0.0, zp=1e-3)
    ke0 = 0.5 * M_FIBER * L_SHORT / L * v0**2
    assert out["solves"][-1] > 0
    assert np.all(out["zlo"] > 0.0), "fiber axis reached the wall plane (h <= -r)"
    assert np.all(out["kin"] <= ke0 * (1 + 1e-9))
    assert out["vz"][-1] >= 0.0


def test_moving_plate_pushes_at_plate_speed(tmp_path):
    """A plate (infinite mass) moving at -2 cm/s reaches a fiber at rest 100 nm below it and carries
    it (vdW + steric: the fiber adheres, oscillating in the well; with steric only it would bounce off at twice the plate
    speed): over the last 150 us it moves at the plate speed on average (within 2 %) and never above the plate."""
    vp = 0.02
    out = _run_wall(tmp_path, vz0=0.0, z0=20e-6, vp=vp, zp=20e-6 + D / 2 + 100e-9, tend=4e-4, every=2, terms="vdw,steric")
    assert out["psolves"][-1] > 0
    late = out["time"] > out["time"][-1] - 1.5e-4  # it oscillates in the well: average over the tail
    assert abs(out["vz"][late].mean() / -vp - 1) < 0.02
    assert np.all(out["zhi"] < 20e-6 + D / 2 + 100e-9 - vp * out["time"] + 1e-9)


def test_static_body_frozen_fiber(tmp_path):
    """A fiber held static through the `frozen` keyword (infinite mass, not integrated: a fabric
    yarn in lay-down) is hit at 50 mm/s: it does not move at all, the moving fiber never passes
    into it and comes back, and the kinetic energy stays within the initial value plus the
    attractive work bound."""
    text = EXAMPLE.read_text()
    text = text.replace("set          atom * diameter ${D}",
                        "group        static id 1:5\ngroup        moving id 6:10\n"
                        "set          atom * diameter ${D}")
    text = text.replace("fix          beam all fiber/beam", "fix          beam moving fiber/beam")
    text = text.replace("terms ${terms} ${extra}", "terms ${terms} frozen static ${extra}")
    assert text.count("frozen static") == 1 and "fix          beam moving" in text
    tmp_path.mkdir(exist_ok=True)
    example = tmp_path / "in.frozen"
    example.write_text(text)
    v0 = 0.05
    out = _run(tmp_path / "run", length=L_SHORT, example=example, tend="4e-4")
    assert np.all(out["v_x1"] == 0.0) and np.all(out["v_vx1"] == 0.0)  # static body never moves
    assert np.all(out["v_hsep"] > -D)                                    # no pass-through
    assert out["v_vx3"][-1] > 0.0                                        # came back (+x)
    assert out["v_hsep"][-1] > out["v_hsep"].min()                       # and is moving away
    assert np.all(out["v_kin"] <= _ke0(v0, L_SHORT) + _attractive_work_bound(L_SHORT))
