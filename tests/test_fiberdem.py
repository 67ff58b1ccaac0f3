# SPDX-License-Identifier: GPL-3.0-or-later
"""System tests of the fiberdem driver: style registration, a two-sphere collision through the
registered test style against its closed form, and 1-rank vs 2-rank equality.

Closed form (elastic head-on collision of two equal spheres with a linear spring K):
reduced mass m_eff = m/2, contact duration t_c = pi*sqrt(m_eff/K), maximum overlap
delta_max = v_rel*sqrt(m_eff/K), and after the contact each velocity is reversed."""
from __future__ import annotations

import math
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "liggghts-fiber-style" / "examples" / "in.two_spheres"
STYLE_REGISTRY = ROOT / "liggghts-fiber-style" / "src" / "style_registry.cpp"

pytestmark = pytest.mark.system

# Parameters of in.two_spheres (SI).
RADIUS = 1.0e-5
DENSITY = 1500.0
V0 = 0.05
DT = 1.0e-7


def _fiberdem() -> Path:
    exe = (Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")) / "bin" / "fiberdem").resolve()
    if not exe.exists():
        pytest.fail(f"{exe} not built: run `make setup`")
    return exe


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def _run(workdir: Path, ranks: int, *var: str) -> None:
    workdir.mkdir(parents=True, exist_ok=True)
    cmd = [str(_fiberdem()), "-in", str(EXAMPLE), "-log", "log.fiberdem", "-screen", "none"]
    for i in range(0, len(var), 2):
        cmd += ["-var", var[i], var[i + 1]]
    if ranks > 1:
        cmd = ["mpirun", "-np", str(ranks)] + cmd
    proc = subprocess.run(cmd, cwd=workdir, env=_env(), capture_output=True, text=True, errors="replace", timeout=120)
    log = workdir / "log.fiberdem"
    tail = log.read_text()[-3000:] if log.exists() else ""
    assert proc.returncode == 0, f"{cmd} failed ({proc.returncode}):\n{proc.stderr}\n{tail}"


def _final_state(workdir: Path) -> np.ndarray:
    """Rows (id, x, y, z, vx, vy, vz) sorted by id, from the full-precision final dump."""
    lines = (workdir / "final.dump").read_text().splitlines()
    start = lines.index(next(l for l in lines if l.startswith("ITEM: ATOMS"))) + 1
    data = np.array([[float(t) for t in l.split()] for l in lines[start:] if l.strip()])
    return data[np.argsort(data[:, 0])]


def test_help_lists_every_registered_style() -> None:
    out = subprocess.run([str(_fiberdem()), "-h"], env=_env(), capture_output=True, text=True, errors="replace",
                         timeout=60, check=True).stdout
    # Every style row of the registrar (the one file listing them) appears in `fiberdem -h`.
    import re
    names = re.findall(r'StyleKind::\w+,\s*"([^"]+)"', STYLE_REGISTRY.read_text())
    assert "test/harmonic" in names
    for name in names:
        assert name in out, f"{name} missing from fiberdem -h"


def test_version_names_liggghts() -> None:
    out = subprocess.run([str(_fiberdem()), "--version"], env=_env(), capture_output=True,
                         text=True, errors="replace", timeout=60, check=True).stdout
    assert "LIGGGHTS" in out and "3.8" in out


def test_two_sphere_collision_matches_closed_form(tmp_path: Path) -> None:
    K = 1.0e-3
    m = DENSITY * 4.0 / 3.0 * math.pi * RADIUS**3
    m_eff = m / 2.0
    t_c = math.pi * math.sqrt(m_eff / K)
    # Contact starts when the gap (4e-5 m between surfaces) closes at 2*V0.
    t_start = (6.0e-5 - 2 * RADIUS) / (2 * V0)
    nsteps = int(round((t_start + t_c) / DT)) + 2000
    _run(tmp_path, 1, "K", repr(K), "nsteps", str(nsteps))
    state = _final_state(tmp_path)
    vx = state[:, 4]
    # Elastic: velocities reversed (velocity Verlet energy error is O((dt/t_c)^2) ~ 1e-6 here).
    assert vx[0] == pytest.approx(-V0, rel=1e-5)
    assert vx[1] == pytest.approx(+V0, rel=1e-5)
    # Positions after the collision: separating at V0 each since t_start + t_c.
    t_end = nsteps * DT
    x_expected = 2 * RADIUS / 2 + V0 * (t_end - t_start - t_c)  # each centre: touching at +-R, then out
    assert state[1, 1] == pytest.approx(x_expected, rel=2e-3)
    assert state[0, 1] == pytest.approx(-x_expected, rel=2e-3)


def test_one_and_two_ranks_give_the_same_final_state(tmp_path: Path) -> None:
    _run(tmp_path / "np1", 1)
    _run(tmp_path / "np2", 2)
    s1, s2 = _final_state(tmp_path / "np1"), _final_state(tmp_path / "np2")
    assert s1.shape == s2.shape == (2, 7)
    scale = np.maximum(np.abs(s1), 1e-300)
    assert np.all(np.abs(s1 - s2) <= 1e-12 * scale + 1e-300), f"1 rank:\n{s1}\n2 ranks:\n{s2}"
    # On 2 ranks the sub-domain boundary is x = 0 (processors * 1 1): each sphere stays on its
    # own rank and the contact force comes entirely through ghost atoms.
    assert s1[0, 1] < 0 < s1[1, 1]


def test_bad_input_fails_with_liggghts_error(tmp_path: Path) -> None:
    bad = tmp_path / "in.bad"
    bad.write_text("units si\natom_style sphere\nregion b block 0 1 0 1 0 1\ncreate_box 1 b\n"
                   "pair_style test/harmonic\npair_coeff * * -1\n")
    proc = subprocess.run([str(_fiberdem()), "-in", str(bad), "-log", "none"], cwd=tmp_path,
                          env=_env(), capture_output=True, text=True, errors="replace", timeout=60)
    assert proc.returncode != 0
    assert "K (N/m) must be a finite number > 0" in proc.stdout + proc.stderr


BOX = "units si\natom_style sphere\nregion b block 0 1 0 1 0 1\ncreate_box 1 b\n"


@pytest.mark.parametrize("command, words", [
    ("pair_style fiber/dlvo steric_terms S1,s2", "steric_terms: 'S1,s2' is not a comma list of distinct terms"),
    ("pair_style fiber/dlvo steric_terms s1,s1", "steric_terms: 's1,s1' is not a comma list of distinct terms"),
    ("pair_style fiber/dlvo integrator substep 2.5", "integrator substep: '2.5' is not a whole number in [1, 1000000]"),
    ("pair_style fiber/dlvo points 0", "points: '0' is not a whole number in [1, 100000]"),
    ("fix s all fiber/settle 1.0e-3 2.5", "M: '2.5' is not a whole number in [1, 2000000000]"),
    ("fix r all fiber/remove below 0.0 every 10.5", "every: '10.5' is not a whole number in [1, 2000000000]"),
], ids=["unknown steric term", "repeated steric term", "fractional substeps", "zero points", "fractional M",
        "fractional every"])
def test_bad_style_arguments_are_refused_not_truncated(tmp_path: Path, command: str, words: str) -> None:
    """A count given as a fraction (was truncated) and an unknown or repeated steric term (an
    unknown one used to switch the others off silently) end the run with a message naming the
    keyword."""
    bad = tmp_path / "in.bad"
    bad.write_text(BOX + command + "\n")
    proc = subprocess.run([str(_fiberdem()), "-in", str(bad), "-log", "none"], cwd=tmp_path,
                          env=_env(), capture_output=True, text=True, errors="replace", timeout=60)
    assert proc.returncode != 0
    assert words in proc.stdout + proc.stderr, proc.stdout[-1500:] + proc.stderr[-1500:]


def test_stock_liggghts_with_preload_shim_matches_fiberdem(tmp_path: Path) -> None:
    """The LD_PRELOAD shim makes Debian's stock `liggghts` binary accept our styles; without it the
    stock binary does not know them."""
    shim = _fiberdem().parent.parent / "lib" / "libfiberform_preload.so"
    liggghts = shutil.which("liggghts")
    assert liggghts is not None and shim.exists()
    cmd = [liggghts, "-in", str(EXAMPLE), "-log", "none", "-screen", "none"]

    plain = tmp_path / "plain"
    plain.mkdir()
    proc = subprocess.run(cmd, cwd=plain, env=_env(), capture_output=True, text=True, errors="replace", timeout=60)
    assert proc.returncode != 0 and not (plain / "final.dump").exists()

    shimmed = tmp_path / "shim"
    shimmed.mkdir()
    subprocess.run(cmd, cwd=shimmed, env={**_env(), "LD_PRELOAD": str(shim)}, check=True,
                   capture_output=True, text=True, errors="replace", timeout=60)
    _run(tmp_path / "fiberdem", 1)
    assert np.array_equal(_final_state(shimmed), _final_state(tmp_path / "fiberdem"))
