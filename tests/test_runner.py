# SPDX-License-Identifier: GPL-3.0-or-later
"""fiberform.runner with real programs (/bin/sh, mpirun): logs, errors, environment, ranks."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest

from fiberform.errors import ConfigError, RunError
from fiberform.runner import (
    ProgressLines,
    build_command,
    build_env,
    capture,
    liggghts_progress,
    mpmd_command,
    openfoam_progress,
    run,
)

SH = "/bin/sh"
PACKAGE = Path(__file__).resolve().parents[1] / "scripts" / "fiberform"


def test_output_goes_to_the_log(tmp_path: Path) -> None:
    result = run([SH, "-c", "echo out; echo err >&2"], Path("log.sh"), cwd=tmp_path)
    assert result.returncode == 0
    assert result.log == tmp_path / "log.sh"
    assert (tmp_path / "log.sh").read_text().split() == ["out", "err"]


def test_failure_raises_with_command_status_and_tail(tmp_path: Path) -> None:
    with pytest.raises(RunError) as info:
        run([SH, "-c", "echo hi; exit 3"], Path("log.sh"), cwd=tmp_path)
    err = info.value
    assert err.returncode == 3
    assert err.tail == ["hi"]
    text = str(err)
    assert "/bin/sh -c echo hi; exit 3" in text
    assert "status 3" in text
    assert "| hi" in text
    assert str(tmp_path / "log.sh") in text
    assert (tmp_path / "log.sh").read_text() == "hi\n"


def test_tail_is_the_last_30_lines(tmp_path: Path) -> None:
    with pytest.raises(RunError) as info:
        run([SH, "-c", 'i=1; while [ $i -le 100 ]; do echo "line $i"; i=$((i+1)); done; exit 1'],
            Path("log.sh"), cwd=tmp_path)  # fmt: skip
    tail = info.value.tail
    assert len(tail) == 30
    assert tail[0] == "line 71" and tail[-1] == "line 100"
    assert "| line 70" not in str(info.value) and "| line 71" in str(info.value)
    assert len((tmp_path / "log.sh").read_text().splitlines()) == 100


def test_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("WM_PROJECT_DIR", raising=False)
    script = 'echo "$OMPI_ALLOW_RUN_AS_ROOT $OMPI_ALLOW_RUN_AS_ROOT_CONFIRM $WM_PROJECT_DIR $FOO"'
    run([SH, "-c", script],
        Path("log.env"), cwd=tmp_path, env_extra={"FOO": "bar"})  # fmt: skip
    assert (tmp_path / "log.env").read_text().strip() == "1 1 /usr/share/openfoam bar"
    monkeypatch.setenv("WM_PROJECT_DIR", "/elsewhere")
    assert build_env()["WM_PROJECT_DIR"] == "/elsewhere"
    with pytest.raises(ConfigError):
        build_env({"A=B": "x"})


def test_cwd_is_honoured(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    run([SH, "-c", "pwd"], Path("log.pwd"), cwd=tmp_path / "sub")
    assert (
        Path((tmp_path / "sub" / "log.pwd").read_text().strip()).resolve()
        == (tmp_path / "sub").resolve()
    )


def test_missing_program(tmp_path: Path) -> None:
    with pytest.raises(RunError) as info:
        run(["fiberform-no-such-program"], Path("log.x"), cwd=tmp_path)
    assert info.value.returncode is None
    assert "not found" in str(info.value)
    with pytest.raises(RunError):
        run([str(tmp_path / "nothing")], Path("log.x"), cwd=tmp_path)


def test_strings_are_not_commands(tmp_path: Path) -> None:
    with pytest.raises(ConfigError):
        run("echo hi; touch pwned", Path("log.x"), cwd=tmp_path)  # type: ignore[arg-type]
    with pytest.raises(ConfigError):
        run([], Path("log.x"), cwd=tmp_path)
    assert not (tmp_path / "pwned").exists()


def test_no_shell_anywhere_in_the_package() -> None:
    for src in PACKAGE.rglob("*.py"):
        text = src.read_text()
        assert "shell=True" not in text, src
        assert "os.system(" not in text and "os.popen(" not in text, src


def test_ranks_and_oversubscription(monkeypatch: pytest.MonkeyPatch) -> None:
    assert build_command(["a", "b"], 1) == ["a", "b"]
    cores = os.cpu_count() or 1
    with pytest.raises(ConfigError, match="cores"):
        build_command(["a"], cores + 1)
    with pytest.raises(ConfigError):
        build_command(["a"], 0)
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    cmd = build_command(["a"], cores + 1, oversubscribe=True)
    assert cmd[1:] == ["--bind-to", "none", "-np", str(cores + 1), "--oversubscribe", "a"]
    assert Path(cmd[0]).name == "mpirun"
    assert "--allow-run-as-root" not in cmd
    if cores >= 2:
        assert build_command(["a"], 2)[1:] == ["--bind-to", "none", "-np", "2", "a"]


def test_mpmd_command_counts_all_ranks() -> None:
    """One mpirun for two programs (the two-way lay-down): the ranks of both count against the
    cores; the programs are separated by ':'."""
    cores = os.cpu_count() or 1
    with pytest.raises(ConfigError, match="in total"):
        mpmd_command([(["a"], cores), (["b"], 1)])
    with pytest.raises(ConfigError):
        mpmd_command([(["a"], 1), (["b"], 0)])
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    cmd = mpmd_command([(["a", "x"], cores), (["b"], 1)], oversubscribe=True)
    assert cmd[1:] == ["--bind-to", "none", "--oversubscribe", "-np", str(cores), "a", "x", ":", "-np", "1", "b"]
    if cores >= 2:
        assert mpmd_command([(["a"], 1), (["b"], 1)])[1:] == ["--bind-to", "none", "-np", "1", "a", ":", "-np", "1",
                                                              "b"]


@pytest.mark.skipif(shutil.which("mpirun") is None or (os.cpu_count() or 1) < 2, reason="mpirun, 2 cores")
def test_local_mpi_ranks_are_not_bound_to_cores(tmp_path: Path) -> None:
    """Each rank of a local 2-rank run may use every core of the machine (Open MPI would otherwise
    pin rank i of every job to core i, so two jobs side by side share their busy rank's core):
    the ranks report their CPU affinity, each to its own file (mpirun forwards the ranks' output
    in chunks that need not end at a line: one run printed ``[0, 1][0, 1]``)."""
    import subprocess
    import sys

    show = [sys.executable, "-c", "import os; open('aff.' + os.environ['OMPI_COMM_WORLD_RANK'], 'w')"
                                  ".write(str(sorted(os.sched_getaffinity(0))))"]
    everything = sorted(os.sched_getaffinity(0))
    proc = subprocess.run(build_command(show, 2), env=build_env(), cwd=tmp_path, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert [(tmp_path / f"aff.{r}").read_text() for r in (0, 1)] == [str(everything)] * 2


@pytest.mark.skipif(shutil.which("mpirun") is None or shutil.which("ompi_info") is None
                    or (os.cpu_count() or 1) < 2, reason="mpirun, ompi_info, 2 cores")
def test_waiting_ranks_yield_their_core(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Every local run's ranks get Open MPI's yield-when-idle (two 2-rank jobs side by side on 2
    cores otherwise poll each other's cores away: 0.33x the work of one job, docs/bench/laydown.md
    "Two points side by side"). Open MPI itself, started through mpirun on 2 ranks, reports the
    parameter's value and that it came from the environment (a misspelt name would be ignored),
    each rank to its own file; a value the user set is kept."""
    import subprocess

    show = ["/bin/sh", "-c", "exec ompi_info --param mpi all --level 9 --parsable > info.$OMPI_COMM_WORLD_RANK"]

    def reported(env: dict[str, str]) -> list[list[str]]:
        proc = subprocess.run(build_command(show, 2), env=env, cwd=tmp_path, capture_output=True, text=True,
                              timeout=120)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return [[ln for ln in (tmp_path / f"info.{r}").read_text().splitlines()
                 if ln.startswith("mca:mpi:base:param:mpi_yield_when_idle:") and ln.split(":")[-2] in ("value", "source")]
                for r in (0, 1)]

    monkeypatch.delenv("OMPI_MCA_mpi_yield_when_idle", raising=False)
    assert reported(build_env()) == [["mca:mpi:base:param:mpi_yield_when_idle:value:true",
                                      "mca:mpi:base:param:mpi_yield_when_idle:source:environment"]] * 2
    monkeypatch.setenv("OMPI_MCA_mpi_yield_when_idle", "0")
    assert [r[0] for r in reported(build_env())] == ["mca:mpi:base:param:mpi_yield_when_idle:value:false"] * 2


@pytest.mark.skipif(not Path("/proc/self/autogroup").is_file(), reason="no scheduler autogroups")
def test_programs_keep_our_niceness(tmp_path: Path) -> None:
    """A program run through the runner leads its own session, hence its own scheduler autogroup,
    which would otherwise share the cores at nice 0 whatever ``nice`` the user started fiberform
    with: under ``nice -n 7`` the program's autogroup reports nice 7 (the program reads it after a
    second, the runner writes it right after the start); at niceness 0 nothing changes."""
    import subprocess
    import sys

    show = "from pathlib import Path; from fiberform.runner import run; " \
           "run(['/bin/sh', '-c', 'sleep 1; cat /proc/self/autogroup'], Path('log.n'))"
    for nice, expected in ((7, "nice 7"), (0, "nice 0")):
        proc = subprocess.run(["nice", "-n", str(nice), sys.executable, "-c", show], cwd=tmp_path,
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert (tmp_path / "log.n").read_text().split()[-2:] == expected.split()


@pytest.mark.skipif(
    shutil.which("mpirun") is None or (os.cpu_count() or 1) < 2, reason="mpirun, 2 cores"
)
def test_two_ranks_through_mpirun(tmp_path: Path) -> None:
    run(["/bin/echo", "hi"], Path("log.mpi"), cwd=tmp_path, ranks=2)
    # (both ranks' lines, whatever the chunks mpirun forwarded them in: "hihi\n\n" is possible)
    assert "".join((tmp_path / "log.mpi").read_text().split()) == "hihi"


def test_progress_callback_sees_every_line(tmp_path: Path) -> None:
    seen: list[str] = []

    def parser(line: str) -> float | None:
        seen.append(line)
        return None

    run(
        [SH, "-c", "echo a; echo b"],
        Path("log.p"),
        cwd=tmp_path,
        progress=parser,
        show_progress=True,
    )
    assert seen == ["a", "b"]

    def broken(line: str) -> float | None:
        raise ValueError("bug in a parser")

    run([SH, "-c", "echo a"], Path("log.q"), cwd=tmp_path, progress=broken)


def test_progress_lines_when_not_on_a_terminal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capfd: pytest.CaptureFixture[str]) -> None:
    """Without a terminal the parser's fraction goes to standard error as plain lines, at most one
    per FIBERFORM_PROGRESS_EVERY_S; none with the progress bar or without a parser."""
    monkeypatch.setenv("FIBERFORM_PROGRESS_EVERY_S", "0.2")
    thermo = "; ".join(f"echo '{step} 3146 0.5'; sleep 0.3" for step in (100, 200, 300, 400))
    run([SH, "-c", thermo], Path("log.l"), cwd=tmp_path, progress=liggghts_progress(400),
        description="press: fiberdem", show_progress=False)
    err = capfd.readouterr().err.splitlines()
    assert [ln.split(" %")[0] for ln in err] == [f"press: fiberdem: {p}" for p in ("50.0", "75.0", "100.0")], err
    assert "left" in err[0] and err[-1].endswith("0 min 00 s left"), err
    run([SH, "-c", thermo], Path("log.m"), cwd=tmp_path, progress=liggghts_progress(400), show_progress=True)
    run([SH, "-c", thermo], Path("log.n"), cwd=tmp_path, show_progress=False)
    assert "after" not in capfd.readouterr().err  # (the bar itself leaves an empty line)


def test_progress_lines_interval_and_time_left() -> None:
    """One line per interval, only when the fraction moved; the time left extrapolates the rate
    since the first fraction seen (a resumed run starting at 60 %: 10 % in 100 s, 30 % left)."""
    now = [0.0]
    out: list[str] = []
    p = ProgressLines("laydown: fiberdem", out.append, every_s=60.0, clock=lambda: now[0])
    for t, f in ((1.0, 0.6), (30.0, 0.62), (101.0, 0.7), (120.0, 0.7), (150.0, 0.71), (161.0, 0.7), (162.0, 0.75)):
        now[0] = t
        p.update(f)
    assert out == ["laydown: fiberdem: 70.0 % after 1 min 41 s, about 5 min 00 s left",
                   "laydown: fiberdem: 75.0 % after 2 min 42 s, about 4 min 28 s left"], out
    bad: list[str] = []
    os.environ["FIBERFORM_PROGRESS_EVERY_S"] = "soon"
    try:
        ProgressLines("x", bad.append)
    finally:
        del os.environ["FIBERFORM_PROGRESS_EVERY_S"]
    assert bad and "FIBERFORM_PROGRESS_EVERY_S" in bad[0]


def test_timeout_ends_the_run(tmp_path: Path) -> None:
    start = time.monotonic()
    with pytest.raises(RunError, match="timed out"):
        run([SH, "-c", "echo started; sleep 30"], Path("log.t"), cwd=tmp_path, timeout_s=0.5)
    assert time.monotonic() - start < 10


def test_liggghts_progress() -> None:
    p = liggghts_progress(1000)
    assert p("     500        2   6.2831853e-08 ") == 0.5
    assert p("    Step    Atoms         KinEng ") is None
    assert p("  1 by 1 by 1 MPI processor grid") is None
    assert p("Created 1 atoms") is None
    assert p("") is None


def test_openfoam_progress() -> None:
    p = openfoam_progress(0.0, 2.0)
    assert p("Time = 0.5") == 0.25
    assert p("ExecutionTime = 1 s") is None
    assert p("deltaT = 0.1") is None


def test_capture() -> None:
    assert capture([SH, "-c", "echo ok"]) == "ok\n"
    assert capture([SH, "-c", "exit 1"]) is None
    assert capture(["fiberform-no-such-program"]) is None
