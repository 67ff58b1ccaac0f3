# SPDX-License-Identifier: GPL-3.0-or-later
"""The fiberform command: help, version, exit statuses."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import fiberform
from fiberform._versions import build_revision, git_revision


def _cli(cmd: list[str], *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*cmd, *args], capture_output=True, text=True, errors="replace", cwd=cwd, timeout=60)


def test_help_lists_commands(fiberform_cmd: list[str]) -> None:
    proc = _cli(fiberform_cmd, "--help")
    assert proc.returncode == 0
    for command in ("version", "check", "schema", "demo-particles"):
        assert command in proc.stdout
    assert "exit status" in proc.stdout


def test_python_dash_m_works() -> None:
    proc = _cli([sys.executable, "-m", "fiberform"], "--help")
    assert proc.returncode == 0 and "demo-particles" in proc.stdout


def test_stage_help_has_force(fiberform_cmd: list[str]) -> None:
    proc = _cli(fiberform_cmd, "demo-particles", "--help")
    assert proc.returncode == 0
    assert "--force" in proc.stdout and "--oversubscribe" in proc.stdout


def test_version_prints_five_components(fiberform_cmd: list[str]) -> None:
    proc = _cli(fiberform_cmd, "version")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert len(lines) == 5, proc.stdout
    for line, name in zip(
        lines, ("LIGGGHTS", "OpenFOAM", "SUNDIALS", "Open MPI", "fiberform"), strict=True
    ):
        assert line.startswith(name + ":"), line
        assert len(line.split(":", 1)[1].strip()) > 0
    assert fiberform.__version__ in lines[4]
    assert "git " in lines[4]


def test_version_uses_debian_packages_when_present(fiberform_cmd: list[str]) -> None:
    proc = _cli(["dpkg-query", "-W", "-f=${Version}", "liggghts"])
    if proc.returncode != 0:
        pytest.skip("no Debian liggghts package")
    out = _cli(fiberform_cmd, "version").stdout
    assert proc.stdout.strip() in out.splitlines()[0]


def test_dash_dash_version(fiberform_cmd: list[str]) -> None:
    proc = _cli(fiberform_cmd, "--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"fiberform {fiberform.__version__}"


def test_git_revision_outside_git_and_dirty(tmp_path: Path) -> None:
    assert git_revision(tmp_path) == "unknown"
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@example.invalid"]
    subprocess.run([*git, "init", "-q"], check=True)
    (tmp_path / "f").write_text("a\n")
    subprocess.run([*git, "add", "f"], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "x"], check=True)
    clean = git_revision(tmp_path)
    assert clean != "unknown" and not clean.endswith("-dirty")
    (tmp_path / "f").write_text("b\n")
    assert git_revision(tmp_path) == clean + "-dirty"


def test_build_revision_reads_the_build_folders_file(tmp_path: Path) -> None:
    assert build_revision(tmp_path) == "unknown"  # no REVISION file
    (tmp_path / "REVISION").write_text("69802b8\n")
    assert build_revision(tmp_path) == "69802b8"
    (tmp_path / "REVISION").write_text("69802b8-dirty\nmore\n")
    assert build_revision(tmp_path) == "69802b8-dirty"
    for junk in ("not a commit; rm -rf /\n", "", "69802B8\n", "69802b8-clean\n"):
        (tmp_path / "REVISION").write_text(junk)
        assert build_revision(tmp_path) == "unknown", junk


def test_write_revision_cmake_script(tmp_path: Path) -> None:
    """cmake/WriteRevision.cmake (run at every build): REVISION holds the short commit, -dirty only
    when a tracked file under the compiled trees changed (not for docs), unknown outside git; it
    is not rewritten when its text stays the same."""
    script = Path(__file__).resolve().parents[1] / "cmake" / "WriteRevision.cmake"
    src, out = tmp_path / "src", tmp_path / "build" / "REVISION"
    out.parent.mkdir()
    src.mkdir()

    def write() -> str:
        subprocess.run(["cmake", f"-DSRC={src}", f"-DOUT={out}", "-P", str(script)], check=True)
        return out.read_text()

    assert write() == "unknown\n"
    git = ["git", "-C", str(src), "-c", "user.name=t", "-c", "user.email=t@example.invalid"]
    subprocess.run([*git, "init", "-q"], check=True)
    for rel in ("liggghts-fiber-style/a.cpp", "docs/a.md"):
        (src / rel).parent.mkdir(parents=True)
        (src / rel).write_text("a\n")
        subprocess.run([*git, "add", rel], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "x"], check=True)
    head = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    assert write() == f"{head}\n"
    stamp = out.stat().st_mtime_ns
    (src / "docs/a.md").write_text("b\n")  # not compiled: still clean, and not rewritten
    assert write() == f"{head}\n" and out.stat().st_mtime_ns == stamp
    (src / "liggghts-fiber-style/a.cpp").write_text("b\n")
    assert write() == f"{head}-dirty\n"
    assert build_revision(out.parent) == f"{head}-dirty"


def test_unknown_command_is_usage_error(fiberform_cmd: list[str]) -> None:
    proc = _cli(fiberform_cmd, "no-such-command")
    assert proc.returncode == 2
    assert "invalid choice" in proc.stderr


def test_no_command_is_usage_error(fiberform_cmd: list[str]) -> None:
    assert _cli(fiberform_cmd).returncode == 2


def test_schema_prints_the_field_table(fiberform_cmd: list[str]) -> None:
    proc = _cli(fiberform_cmd, "schema")
    assert proc.returncode == 0
    assert ("| `fibers.width_m` | Fiber width (the diameter for a circular cross-section) | m | required | "
            "0 < x <= 0.001 |") in proc.stdout
    assert ("| `fibers.length_m` | Fiber length (required unless fiber_generation.length_m samples it; not both) "
            "| m | absent | 0 < x <= 0.1 |") in proc.stdout
    proc = _cli(fiberform_cmd, "schema", "--json")
    assert proc.returncode == 0 and '"additionalProperties": false' in proc.stdout


def test_stage_without_fiberdem_fails_with_status_1(
    tmp_path: Path, repo_root: Path, fiberform_cmd: list[str]
) -> None:
    scene = tmp_path / "demo.yaml"
    scene.write_text((repo_root / "scenes" / "two-particles.yaml").read_text())
    proc = _cli(
        fiberform_cmd,
        "demo-particles",
        "demo.yaml",
        "--build-dir",
        str(tmp_path / "b"),
        cwd=tmp_path,
    )
    assert proc.returncode == 1
    assert "fiberdem not found" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.yaml"]


@pytest.mark.system
def test_run_executes_enabled_stages_and_writes_report(
    tmp_path: Path, build_dir: Path, fiberform_cmd: list[str], repo_root: Path
) -> None:
    """`fiberform run` (what `make demo` calls) runs every enabled stage and writes report.md;
    a second run finds everything up to date."""
    import shutil
    import subprocess

    shutil.copy(repo_root / "scenes" / "two-particles.yaml", tmp_path / "demo.yaml")
    cmd = [*fiberform_cmd, "run", "demo.yaml", "--build-dir", str(build_dir)]
    first = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, errors="replace", timeout=300)
    assert first.returncode == 0, first.stderr
    report = (tmp_path / "runs" / "two-particles" / "report.md").read_text()
    assert "| demo-particles | ran |" in report
    assert (tmp_path / "runs" / "two-particles" / "particles" / "particles.h5").is_file()
    second = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, errors="replace", timeout=300)
    assert second.returncode == 0 and "up to date" in second.stdout
