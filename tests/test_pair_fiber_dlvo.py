# SPDX-License-Identifier: GPL-3.0-or-later
"""System tests of pair_style fiber/dlvo (thesis Kettil 2016, sections 2.4 and 4.1) through
fiberdem and liggghts-fiber-style/examples/in.fiber_collision.

Set-up (thesis 4.1): two straight fibers, L = 0.1 mm, D = 14 um, rho = 1500 kg/m3, parallel to y,
initial surface gap 12 um; fiber 2 moves at v0 towards fiber 1. Each fiber is one element between
two end nodes. Assertions use independent numbers only: h_min = -D (thesis eq. 2.37), momentum
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

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "liggghts-fiber-style" / "examples" / "in.fiber_collision"

pytestmark = pytest.mark.system

L, D, RHO = 1.0e-4, 1.4e-5, 1500.0
M_FIBER = RHO * math.pi * (D / 2) ** 2 * L
A_HAMAKER, H0 = 8.0e-21, 1.0e-9
R_EFF = (D / 2) / 2
COLUMNS = ["step", "time", "v_hsep", "v_px", "v_pz", "v_vx1", "v_vx3", "v_kin", "solves", "rhs_evals"]


def _points_per_element(h_match: float = 1e-9) -> int:
    # thesis 2.4.3: spacing so that sphere-sphere vdW sums to the parallel-cylinder force
    spacing = 4 * math.sqrt(2) / 3 * math.sqrt(R_EFF * h_match)
    return max(1, round(L / spacing))


def _fiberdem() -> Path:
    exe = (Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")) / "bin" / "fiberdem").resolve()
    if not exe.exists():
        pytest.fail(f"{exe} not built: run `make setup`")
    return exe


def _run(workdir: Path, ranks: int = 1, **var: str) -> dict[str, np.ndarray]:
    workdir.mkdir(parents=True, exist_ok=True)
    cmd = [str(_fiberdem()), "-in", str(EXAMPLE), "-log", "log.fiberdem", "-screen", "none"]
    var.setdefault("every", "1")
    for k, v in var.items():
        cmd += ["-var", k, str(v)]
    if ranks > 1:
        cmd = ["mpirun", "-np", str(ranks), "--oversubscribe"] + cmd
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    res = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=600)
    log = (workdir / "log.fiberdem").read_text() if (workdir / "log.fiberdem").exists() else ""
    assert res.returncode == 0, f"fiberdem failed:\n{res.stdout[-2000:]}\n{res.stderr[-2000:]}\n{log[-2000:]}"
    rows, cols, on = [], None, False
    for line in log.splitlines():
        if line.split()[:2] == ["Step", "Time"]:
            # LIGGGHTS abbreviates the header; the order is fixed by in.fiber_collision
            cols, on = COLUMNS, True
            continue
        if on and line.startswith("Loop time"):
            on = False
            continue
        if on:
            try:
                rows.append([float(w) for w in line.split()])
            except ValueError:
                pass
    assert cols and rows, f"no thermo output:\n{log[-2000:]}"
    data = np.array(rows)
    out = {c: data[:, i] for i, c in enumerate(cols)}
    out["dump"] = np.loadtxt(workdir / var.get("dump", "final.dump"), skiprows=9)
    return out


def _ke0(v0: float) -> float:
    return 0.5 * M_FIBER * v0**2


def _attractive_work_bound() -> float:
    return 2.0 * _points_per_element() * A_HAMAKER * R_EFF / (6 * H0)


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


@pytest.mark.parametrize("v0", [1.0, 5.0])
def test_stability_fast_head_on(tmp_path, v0):
    out = _run(tmp_path, v0=v0, gap=2e-7, tend=2e-5)
    assert np.all(np.isfinite(out["v_kin"]))
    assert np.all(out["v_hsep"] > -D)
    assert np.all(out["v_kin"] <= _ke0(v0) + _attractive_work_bound())


@pytest.mark.xfail(strict=True, reason="KNOWN WEAKNESS: the S1 servo (eq. 2.35) pushes a deep overlap apart "
                   "at ~(h_R - h)/t_R and S3 only caps that at ~sqrt(2 x |h_min|/1000)/t_R; measured peak KE "
                   "3.8e-12 J vs bound 8.4e-15 J (docs/models/contact.md)")
def test_stability_start_in_overlap(tmp_path):
    """Start at 50 % overlap (h = -D/2), at rest: the steric force must separate them without
    injecting more kinetic energy than the attractive work bound. No NaN, no pass-through hold."""
    out = _run(tmp_path, v0=0.0, gap=-0.5 * D, tend=5e-6)
    assert np.all(np.isfinite(out["v_kin"]))
    assert np.all(out["v_hsep"] > -D)
    assert out["v_kin"].max() <= _attractive_work_bound()


@pytest.mark.parametrize("dt", [1e-9, 1e-8, 1e-7, 1e-6])
def test_stability_time_steps(tmp_path, dt):
    v0 = 0.05
    out = _run(tmp_path, v0=v0, gap=2e-8, dt=dt, tend=max(300 * dt, 2e-6), every=10)
    assert np.all(np.isfinite(out["v_kin"]))
    assert np.all(out["v_hsep"] > -D)
    assert np.all(out["v_kin"] <= _ke0(v0) + _attractive_work_bound())
