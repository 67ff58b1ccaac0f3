# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage demo-particles: input generation, closed form, dump reading, and the stage mechanism
(products, provenance, skip when up to date, --force, atomic output, failures).

The end-to-end tests run the real build/bin/fiberdem (pair_style test/harmonic) and compare with
the closed form of an elastic collision; only the failure-path test uses a program that always
fails."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from fiberform.scene import parse_scene
from fiberform.stages.particles import (
    TwoSphereCollision,
    build_input,
    check_collision,
    read_dump,
)

DEMO = {
    "name": "demo",
    "seed": 0,
    "output_dir": "out",
    "run": {"timestep_s": 1.0e-6, "duration_s": 1.0e-2, "ranks": 1, "output_interval_s": 1.0e-3},
    "demo_particles": {
        "radius_m": 1.0e-3,
        "density_kg_m3": 1500.0,
        "speed_m_s": 0.1,
        "gap_m": 1.0e-3,
        "stiffness_N_m": 1000.0,
    },
}

ALLOWED_COMMANDS = {
    "units", "atom_style", "atom_modify", "boundary", "newton", "communicate", "processors",
    "region", "create_box", "neighbor", "neigh_modify", "pair_style", "pair_coeff",
    "create_atoms", "set", "fix", "timestep", "thermo_style", "thermo", "dump", "dump_modify",
    "run",
}  # fmt: skip


def test_input_has_the_required_commands() -> None:
    text = build_input(parse_scene(DEMO))
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    assert {ln.split()[0] for ln in lines} <= ALLOWED_COMMANDS
    for expected in (
        "units si",
        "atom_style sphere",
        "atom_modify map array",
        "boundary f f f",
        "pair_style test/harmonic",
        "pair_coeff * * 1000.0",
        "create_atoms 1 single -0.0015 0.0 0.0 units box",
        "create_atoms 1 single 0.0015 0.0 0.0 units box",
        "set atom 1 diameter 0.002 density 1500.0 vx 0.1",
        "set atom 2 diameter 0.002 density 1500.0 vx -0.1",
        "fix integrate all nve/sphere",
        "timestep 1e-06",
        "dump final all custom 10000 final.dump id x y z vx vy vz",
        'dump_modify final sort id format "%d %.17g %.17g %.17g %.17g %.17g %.17g"',
        "run 10000",
    ):
        assert expected in lines, expected
    assert any(ln.startswith("communicate single") and ln.endswith("vel yes") for ln in lines)
    assert lines[-1] == "run 10000"
    assert build_input(parse_scene(DEMO)) == text  # deterministic


def test_numbers_are_written_with_full_precision() -> None:
    data = json.loads(json.dumps(DEMO))
    data["demo_particles"]["stiffness_N_m"] = 1234.5678901234567
    text = build_input(parse_scene(data))
    assert "pair_coeff * * 1234.5678901234567" in text


def test_closed_form() -> None:
    c = TwoSphereCollision(1e-3, 1500.0, 0.1, 1e-3, 1000.0)
    m = 1500.0 * 4 / 3 * math.pi * 1e-9
    assert c.mass_kg == pytest.approx(m)
    assert c.contact_duration_s == pytest.approx(math.pi * math.sqrt(m / 2 / 1000.0))
    assert c.contact_start_s == pytest.approx(5e-3)
    assert c.max_overlap_m == pytest.approx(0.2 * math.sqrt(m / 2 / 1000.0))
    t = 1e-2
    x = c.positions_m(t)
    assert x[0, 0] == pytest.approx(-1e-3 - 0.1 * (t - c.contact_end_s))
    assert x[1, 0] == -x[0, 0]
    np.testing.assert_array_equal(c.velocities_m_s(t), [[-0.1, 0, 0], [0.1, 0, 0]])
    np.testing.assert_array_equal(c.velocities_m_s(0.0), [[0.1, 0, 0], [-0.1, 0, 0]])


def test_stage_checks_name_fields() -> None:
    assert check_collision(parse_scene(DEMO)) == []
    data = json.loads(json.dumps(DEMO))
    data["run"]["timestep_s"] = 1e-4
    data["run"]["duration_s"] = 4e-3
    data["run"]["output_interval_s"] = None
    data["demo_particles"]["stiffness_N_m"] = 1e-6
    problems = check_collision(parse_scene(data))
    assert any(p.startswith("run.duration_s") for p in problems)
    assert any(p.startswith("demo_particles.stiffness_N_m") for p in problems)
    data["demo_particles"]["stiffness_N_m"] = 1e3
    assert any(p.startswith("run.timestep_s") for p in check_collision(parse_scene(data)))


def test_read_dump(tmp_path: Path) -> None:
    frame = (
        "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS ff ff ff\n"
        "-1 1\n-1 1\n-1 1\nITEM: ATOMS id x y z vx vy vz \n"
        "2 0.5 0 0 -0.1 0 0 \n1 -0.5 0 0 0.10000000000000001 0 0 \n"
    )
    p = tmp_path / "d.dump"
    p.write_text(frame.format(step=0) + frame.format(step=10))
    frames = read_dump(p)
    assert [f.step for f in frames] == [0, 10]
    assert list(frames[1].ids) == [1, 2]
    assert frames[1].columns["x"][0] == -0.5 and frames[1].columns["vx"][0] == 0.1


# ---- end to end with the real fiberdem -----------------------------------------------------------

FAILING = """\
import sys
print("ERROR: this program always fails")
sys.exit(4)
"""


@pytest.fixture
def real_build(build_dir: Path) -> Path:
    """The real build (fiberdem with pair_style test/harmonic registered)."""
    if not (build_dir / "bin" / "fiberdem").is_file():
        pytest.fail(f"{build_dir}/bin/fiberdem not built: run `make setup`")
    return build_dir


@pytest.fixture
def failing_build(tmp_path: Path) -> Path:
    """A build folder whose `fiberdem` always fails: tests the stage's failure path only."""
    build = tmp_path / "failbuild"
    (build / "bin").mkdir(parents=True)
    exe = build / "bin" / "fiberdem"
    exe.write_text(f"#!{sys.executable}\n" + FAILING)
    exe.chmod(0o755)
    return build


def _stage(
    fiberform_cmd: list[str],
    work: Path,
    build: Path,
    *extra: str,
    env: dict[str, str] | None = None,
) -> subprocess.CompletedProcess[str]:
    import os

    return subprocess.run(
        [*fiberform_cmd, "demo-particles", "scene.yaml", "--build-dir", str(build), *extra],
        cwd=work,
        capture_output=True,
        text=True, errors="replace",
        timeout=120,
        env={**os.environ, **(env or {})},
    )


def _write_scene(work: Path, **run: object) -> None:
    import yaml

    data = json.loads(json.dumps(DEMO))
    data["run"].update(run)
    (work / "scene.yaml").write_text(yaml.safe_dump(data))


def test_stage_end_to_end(tmp_path: Path, real_build: Path, fiberform_cmd: list[str]) -> None:
    work = tmp_path / "work"
    work.mkdir()
    _write_scene(work)
    proc = _stage(fiberform_cmd, work, real_build)
    assert proc.returncode == 0, proc.stderr
    assert "done" in proc.stdout
    stage = work / "out" / "particles"
    assert (stage / "report.md").is_file()
    assert (stage / "log.fiberdem").read_text().startswith("LIGGGHTS (Version")
    assert not list(stage.glob("*.in_progress"))
    with h5py.File(stage / "particles.h5", "r") as f:
        assert f.attrs["stage"] == "demo-particles"
        assert json.loads(f.attrs["scene_json"])["demo_particles"]["speed_m_s"] == 0.1
        assert int(f.attrs["seed"]) == 0
        hashes = json.loads(f.attrs["input_hashes"])
        assert set(hashes) == {"scene", "stage_code", "in.particles", "fiberdem"}
        for key in ("fiberform", "git_revision", "created_utc", "options"):
            assert key in f.attrs
        assert f["final/velocities"].attrs["units"] == "m/s"
        assert f["final/positions"].attrs["units"] == "m"
        v = f["final/velocities"][()]
        v_exp = f["expected/velocities"][()]
        assert v.shape == (2, 3)
        np.testing.assert_allclose(v, v_exp, atol=1e-4)  # elastic: reversed
        np.testing.assert_allclose(f["initial/velocities"][()], -v_exp)
        assert f["trajectory/positions"].shape == (11, 2, 3)
        for name, ds in f.items():
            if isinstance(ds, h5py.Group):
                for sub in ds.values():
                    assert "units" in sub.attrs, f"{name}/{sub.name} lacks units"
    report = (stage / "report.md").read_text()
    assert "velocity error" in report and "fiberdem" in report

    # second run: up to date, nothing rerun
    mtime = (stage / "log.fiberdem").stat().st_mtime_ns
    proc = _stage(fiberform_cmd, work, real_build)
    assert proc.returncode == 0 and "up to date" in proc.stdout
    assert (stage / "log.fiberdem").stat().st_mtime_ns == mtime

    # --force reruns
    proc = _stage(fiberform_cmd, work, real_build, "--force")
    assert proc.returncode == 0 and "done" in proc.stdout
    assert (stage / "log.fiberdem").stat().st_mtime_ns != mtime

    # a changed input reruns
    _write_scene(work, duration_s=1.2e-2)
    proc = _stage(fiberform_cmd, work, real_build)
    assert proc.returncode == 0 and "done" in proc.stdout, proc.stdout


def test_stage_on_two_ranks(tmp_path: Path, real_build: Path, fiberform_cmd: list[str]) -> None:
    import os

    if shutil.which("mpirun") is None or (os.cpu_count() or 1) < 2:
        pytest.skip("needs mpirun and 2 cores")
    work = tmp_path / "work"
    work.mkdir()
    _write_scene(work, ranks=2)
    proc = _stage(fiberform_cmd, work, real_build)
    assert proc.returncode == 0, proc.stderr
    report = (work / "out" / "particles" / "report.md").read_text()
    assert "mpirun --bind-to none -np 2" in report


def test_failed_run_leaves_no_products(
    tmp_path: Path, failing_build: Path, fiberform_cmd: list[str]
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    _write_scene(work)
    proc = _stage(fiberform_cmd, work, failing_build)
    assert proc.returncode == 1
    assert "exited with status 4" in proc.stderr
    assert "ERROR: this program always fails" in proc.stderr
    stage = work / "out" / "particles"
    assert not (stage / "particles.h5").exists() and not (stage / "report.md").exists()
    assert not list(stage.glob("*.in_progress"))
