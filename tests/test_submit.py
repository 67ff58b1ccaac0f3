# SPDX-License-Identifier: GPL-3.0-or-later
"""``fiberform submit`` (fiberform.executors; issue 14, deliverable 2): batch scripts per stage,
afterok chains, job records and queue states in ``fiberform status``.

* Quick tests: the PBS scripts of a two-stage scene against the expected files in
  ``tests/data/submit/``; option checks (injection through partition/account/qos names, bad times and
  counts, paths a directive cannot carry) exit 2 naming the option, with nothing written.
* System test: a real Slurm (Debian's slurmctld + slurmd, ``AuthType=auth/none``) started on this
  host by the fixture; a fabric -> flow pipeline submitted with an afterok dependency runs to
  completion, and a failing first stage gets the second cancelled. Needs root (slurmd runs jobs as
  root here); skipped only when not root.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from cli_helpers import parse_status
from fiberform import __version__
from fiberform.cli import build_parser, main
from fiberform.errors import ConfigError
from fiberform.executors import (
    JobRecord,
    QueueState,
    annotate_status,
    batch_options,
    parse_time,
    pbs_state,
)
from fiberform.pipeline import StageStatus

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "submit"

SCENE = """name: pipe
run: {timestep_s: 1.0e-6, duration_s: 1.0e-3}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3, voxel_size_m: 10.0e-6}
flow: {cell_size_m: 50.0e-6, delta_p_Pa: 100.0}
"""


def _ff(d: Path, monkeypatch: pytest.MonkeyPatch, *args: str) -> int:
    monkeypatch.chdir(d)
    try:
        return main([*args, "--build-dir", str(ROOT / "build")])
    except SystemExit as exc:  # argparse's own usage errors
        return int(exc.code or 0)


# ---- scripts and option checks (no scheduler needed) --------------------------------------------

def test_pbs_scripts_match_the_expected_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "s.yaml").write_text(SCENE.replace("delta_p_Pa: 100.0", "delta_p_Pa: 100.0, ranks: 2"))
    rc = _ff(tmp_path, monkeypatch, "submit", "s.yaml", "--scheduler", "pbs", "--dry-run",
             "--partition", "workq", "--account", "proj_1", "--time", "1-02:03:04")
    assert rc == 0, capsys.readouterr().err
    jobs = tmp_path / "runs/pipe/jobs"
    assert sorted(p.name for p in jobs.iterdir()) == ["fabric.pbs", "flow.pbs", "submit-pbs.sh"]
    subst = {"@WORKDIR@": str(tmp_path), "@PYTHON@": str(Path(sys.executable).absolute()),
             "@BUILD@": str((ROOT / "build").resolve()), "@VERSION@": __version__}
    for name in ("fabric.pbs", "flow.pbs", "submit-pbs.sh"):
        want = (DATA / name).read_text()
        for k, v in subst.items():
            want = want.replace(k, v)
        assert (jobs / name).read_text() == want, name
    assert os.access(jobs / "flow.pbs", os.X_OK)
    assert not (jobs / "jobs.json").exists()  # a dry run records no job


def test_slurm_script_asks_for_the_stage_ranks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "s.yaml").write_text(SCENE.replace("delta_p_Pa: 100.0", "delta_p_Pa: 100.0, ranks: 2"))
    rc = _ff(tmp_path, monkeypatch, "submit", "s.yaml", "--scheduler", "slurm", "--dry-run", "--time", "90",
             "--qos", "normal", "--nodes", "1")
    assert rc == 0, capsys.readouterr().err
    fabric = (tmp_path / "runs/pipe/jobs/fabric.slurm").read_text()
    flow = (tmp_path / "runs/pipe/jobs/flow.slurm").read_text()
    directives = lambda text: [ln for ln in text.splitlines() if ln.startswith("#SBATCH")]  # noqa: E731
    assert directives(flow) == ["#SBATCH --job-name=ff-pipe-flow", "#SBATCH --ntasks=2",
                                f"#SBATCH --output={tmp_path}/runs/pipe/jobs/flow-%j.out",
                                "#SBATCH --kill-on-invalid-dep=yes", "#SBATCH --nodes=1", "#SBATCH --qos=normal",
                                "#SBATCH --time=0-01:30:00"]
    assert "#SBATCH --ntasks=1" in fabric
    # flow is split: fiberform prepare, the solver line itself on the stage's 2 ranks, fiberform collect
    py, build = Path(sys.executable).absolute(), (ROOT / "build").resolve()
    assert f"{py} -m fiberform prepare flow {tmp_path}/s.yaml --build-dir {build} || status=$?" in flow
    assert (f"(cd {tmp_path}/runs/pipe/flow/case && mpirun -np 2 simpleFoam -parallel) > "
            f"{tmp_path}/runs/pipe/flow/log.simpleFoam 2>&1") in flow.splitlines()
    assert flow.splitlines()[-1] == f"exec {py} -m fiberform collect flow {tmp_path}/s.yaml --build-dir {build}"
    assert fabric.splitlines()[-1] == f"exec {py} -m fiberform fabric {tmp_path}/s.yaml --build-dir {build}"
    replay = (tmp_path / "runs/pipe/jobs/submit-slurm.sh").read_text()
    assert f"job_flow=$(sbatch --parsable --dependency=afterok:${{job_fabric}} {tmp_path}/runs/pipe/jobs/flow.slurm)" \
        in replay
    # the scripts are valid bash
    for p in ("fabric.slurm", "flow.slurm", "submit-slurm.sh"):
        subprocess.run(["bash", "-n", str(tmp_path / "runs/pipe/jobs" / p)], check=True)


BAD = [
    (["--partition", "debug\n#SBATCH --uid=0"], "--partition"),
    (["--partition", "debug;touch /tmp/x"], "--partition"),
    (["--partition", "$(id)"], "--partition"),
    (["--partition", "a b"], "--partition"),
    (["--partition=-x"], "--partition"),
    (["--partition", ""], "--partition"),
    (["--account", "acct'"], "--account"),
    (["--account", "`reboot`"], "--account"),
    (["--qos", "hi\nlo"], "--qos"),
    (["--time", "10:00"], "--time"),
    (["--time", "0"], "--time"),
    (["--time", "1-25:61:00"], "--time"),
    (["--time", "10\n#SBATCH --uid=0"], "--time"),
    (["--time", "1:00:00;id"], "--time"),
    (["--nodes", "0"], "--nodes"),
    (["--nodes", "-1"], "--nodes"),
    (["--nodes", "two"], "--nodes"),
    (["--ntasks", "1.5"], "--ntasks"),
    (["--ntasks", "0"], "--ntasks"),
    (["--nodes", "3", "--ntasks", "2"], "--nodes"),
    (["--ntasks", "1"], "--ntasks 1: stage flow runs on 2 MPI ranks"),  # flow.ranks is 2 below
    (["--from", "nosuch"], "--from 'nosuch'"),
    (["--to", "fabric", "--force", "flow"], "--force 'flow'"),
    (["--scheduler", "lsf"], "--scheduler"),
]


@pytest.mark.parametrize("scheduler", ["slurm", "pbs"])
@pytest.mark.parametrize(("args", "named"), BAD, ids=[f"{i}" for i in range(len(BAD))])
def test_bad_options_exit_2_naming_the_option_and_write_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        scheduler: str, args: list[str], named: str) -> None:
    _assert_refused(tmp_path, monkeypatch, capsys, SCENE.replace("delta_p_Pa: 100.0", "delta_p_Pa: 100.0, ranks: 2"),
                    ["submit", "s.yaml", "--scheduler", scheduler, "--dry-run", *args], named)


def _assert_refused(d: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], scene: str,
                    args: list[str], named: str) -> None:
    """`fiberform ARGS` on the scene text exits 2 naming ``named`` and writes nothing."""
    (d / "s.yaml").write_text(scene)
    rc = _ff(d, monkeypatch, *args)
    err = capsys.readouterr().err
    assert rc == 2 and named in err, err
    assert not (d / "runs").exists()


def test_qos_is_slurm_only_and_pbs_needs_qsub(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "s.yaml").write_text(SCENE)
    assert _ff(tmp_path, monkeypatch, "submit", "s.yaml", "--scheduler", "pbs", "--qos", "normal") == 2
    assert "--qos: Slurm only" in capsys.readouterr().err
    if shutil.which("qsub") is None:  # Debian has no PBS: without --dry-run, exit 2 and nothing written
        assert _ff(tmp_path, monkeypatch, "submit", "s.yaml", "--scheduler", "pbs") == 2
        assert "qsub not found" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def test_paths_a_directive_cannot_carry_are_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    for folder in ("with blank", "quote'd", "new\nline", "pct%u"):
        d = tmp_path / folder
        d.mkdir()
        (d / "s.yaml").write_text(SCENE)
        assert _ff(d, monkeypatch, "submit", "s.yaml", "--scheduler", "slurm", "--dry-run") == 2
        err = capsys.readouterr().err
        assert "output folder" in err and ("cannot carry" in err or "with a newline cannot" in err), err
        assert not (d / "runs").exists()
    # a scene file in a folder with a newline (the output folder itself is fine)
    (tmp_path / "a\nb").mkdir()
    (tmp_path / "a\nb" / "s.yaml").write_text(SCENE)
    assert _ff(tmp_path, monkeypatch, "submit", "a\nb/s.yaml", "--scheduler", "pbs", "--dry-run") == 2
    assert "SCENE" in (err := capsys.readouterr().err) and "newline" in err, err
    assert not (tmp_path / "runs").exists()


def test_from_a_stage_whose_upstream_is_neither_done_nor_queued(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "s.yaml").write_text(SCENE)
    assert _ff(tmp_path, monkeypatch, "submit", "s.yaml", "--scheduler", "slurm", "--dry-run", "--from", "flow") == 2
    assert "stage flow needs the products of fabric, which is missing" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


QSUB = """#!/bin/bash
# stand-in for PBS's qsub (Debian has no PBS server): logs its arguments, prints a PBS-style job ID
# (an array job's, NNN[].server, for a script with a -J directive)
n=$(( $(wc -l < "$0.log" 2>/dev/null || echo 0) + 1 ))
echo "$*" >> "$0.log"
if [[ -n "${QSUB_FAIL_AT:-}" && $n -ge $QSUB_FAIL_AT ]]; then echo "qsub: Unknown queue" >&2; exit 170; fi
if grep -q '^#PBS -J ' "${@: -1}"; then echo "$n[].pbs-test"; else echo "$n.pbs-test"; fi
"""
QSTAT = """#!/bin/bash
# stand-in for PBS's qstat -x -f ID
case "$3" in 1.pbs-test) printf 'Job Id: 1.pbs-test\n    job_state = F\n    Exit_status = 0\n';;
              2.pbs-test) printf 'Job Id: 2.pbs-test\n    job_state = H\n';; *) exit 153;; esac
"""


def test_pbs_submission_through_stand_in_qsub(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """The qsub command lines (``-W depend=afterok:<full PBS ID>``), the job records, a submission
    that fails half-way, and status from qstat, with small stand-ins for qsub/qstat (no PBS server
    in Debian; the real-scheduler test is the Slurm one below)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name, text in (("qsub", QSUB), ("qstat", QSTAT)):
        (bin_dir / name).write_text(text)
        (bin_dir / name).chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    (tmp_path / "s.yaml").write_text(SCENE)
    assert _ff(tmp_path, monkeypatch, "submit", "s.yaml", "--scheduler", "pbs", "--time", "30") == 0
    jobs = tmp_path / "runs/pipe/jobs"
    assert (bin_dir / "qsub.log").read_text().splitlines() == [
        f"{jobs}/fabric.pbs", f"-W depend=afterok:1.pbs-test {jobs}/flow.pbs"]
    rec = json.loads((jobs / "jobs.json").read_text())["jobs"]
    assert (rec["fabric"]["job_id"], rec["flow"]["job_id"], rec["flow"]["after"]) == ("1.pbs-test", "2.pbs-test",
                                                                                      ["1.pbs-test"])
    capsys.readouterr()
    assert _ff(tmp_path, monkeypatch, "status", "s.yaml") == 0
    out = capsys.readouterr().out
    assert "fabric  missing  (pbs 1.pbs-test, COMPLETED)" in out and "flow    queued   (pbs 2.pbs-test, HELD)" in out, out
    # a record whose job ID no scheduler prints (edited, or a string meant for a shell) is refused
    # before it reaches a scheduler command: exit 2, naming the file
    good = (jobs / "jobs.json").read_text()
    (jobs / "jobs.json").write_text(good.replace('"2.pbs-test"', '"2; rm -rf ~"', 1))
    assert _ff(tmp_path, monkeypatch, "status", "s.yaml") == 2
    assert "jobs.json: job record of stage 'flow'" in capsys.readouterr().err
    (jobs / "jobs.json").write_text(good)

    # qsub fails for the second job: exit 1, the first job stays recorded
    shutil.rmtree(jobs)
    (bin_dir / "qsub.log").unlink()
    monkeypatch.setenv("QSUB_FAIL_AT", "2")
    assert _ff(tmp_path, monkeypatch, "submit", "s.yaml", "--scheduler", "pbs") == 1
    err = capsys.readouterr().err
    assert "qsub did not return a job ID (jobs queued before: fabric 1.pbs-test)" in err and "Unknown queue" in err, err
    assert list(json.loads((jobs / "jobs.json").read_text())["jobs"]) == ["fabric"]


# ---- sweeps as job arrays -----------------------------------------------------------------------

SWEEP = ["sweep", "s.yaml", "--set", "flow.delta_p_Pa=50.0,100.0"]


def test_pbs_sweep_array_scripts_match_the_expected_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """`sweep --submit pbs`: one array script per stage (-J 0-1, PBS_ARRAY_INDEX picks the line of
    variants.txt), afterok on the whole upstream array; checked against tests/data/submit/sweep-*."""
    (tmp_path / "s.yaml").write_text(SCENE)
    rc = _ff(tmp_path, monkeypatch, *SWEEP, "--submit", "pbs", "--dry-run", "--partition", "workq",
             "--account", "proj_1", "--time", "1-02:03:04")
    assert rc == 0, capsys.readouterr().err
    jobs = tmp_path / "runs/pipe-sweep/jobs"
    assert sorted(p.name for p in jobs.iterdir()) == ["fabric.pbs", "flow.pbs", "submit-pbs.sh", "variants.txt"]
    subst = {"@WORKDIR@": str(tmp_path), "@PYTHON@": str(Path(sys.executable).absolute()),
             "@BUILD@": str((ROOT / "build").resolve()), "@VERSION@": __version__}
    for name in ("fabric.pbs", "flow.pbs", "submit-pbs.sh"):
        want = (DATA / f"sweep-{name}").read_text()
        for k, v in subst.items():
            want = want.replace(k, v)
        assert (jobs / name).read_text() == want, name
        subprocess.run(["bash", "-n", str(jobs / name)], check=True)
    assert (jobs / "variants.txt").read_text().splitlines() == [
        f"{tmp_path}/runs/pipe-sweep/scenes/pipe_000.yaml", f"{tmp_path}/runs/pipe-sweep/scenes/pipe_001.yaml"]
    assert not (jobs / "jobs.json").exists()


def test_sweep_array_through_stand_in_qsub(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """The qsub lines of a sweep (the flow array after the whole fabric array, by its NNN[] ID),
    the array IDs in the sweep's jobs.json and task k's ID in variant k's records."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "qsub").write_text(QSUB)
    (bin_dir / "qsub").chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    (tmp_path / "s.yaml").write_text(SCENE)
    assert _ff(tmp_path, monkeypatch, *SWEEP, "--submit", "pbs") == 0, capsys.readouterr().err
    jobs = tmp_path / "runs/pipe-sweep/jobs"
    assert (bin_dir / "qsub.log").read_text().splitlines() == [
        f"{jobs}/fabric.pbs", f"-W depend=afterok:1[].pbs-test {jobs}/flow.pbs"]
    rec = json.loads((jobs / "jobs.json").read_text())["jobs"]
    assert (rec["fabric"]["job_id"], rec["flow"]["job_id"]) == ("1[].pbs-test", "2[].pbs-test")
    for k in (0, 1):
        v = json.loads((tmp_path / f"runs/pipe-sweep/pipe_00{k}/jobs/jobs.json").read_text())["jobs"]
        assert (v["fabric"]["job_id"], v["flow"]["job_id"], v["flow"]["after"]) == (
            f"1[{k}].pbs-test", f"2[{k}].pbs-test", [f"1[{k}].pbs-test"])


def _resumed_stage_lines(texts: dict[bool, dict[str, str]], forced: str | None) -> list[list[str]]:
    """The scripts written with --resume (texts[True]) against those without (texts[False]): equal
    but for that word; every fiberform line one the command line accepts; --resume on each
    prepare/stage line and never on collect; --force only on the ``forced`` stage's line. Returns
    the resumed lines' command words (``[stage]`` or ``["prepare", stage]``) in script order."""
    parser = build_parser()
    resumed = []
    for name, text in texts[True].items():
        assert text.replace(" --resume", "") == texts[False][name], name
        for line in text.splitlines():
            if line.startswith("#") or " -m fiberform " not in line:
                continue
            argv = shlex.split(line.removeprefix("exec ").removesuffix(" || status=$?"))
            assert argv[1:3] == ["-m", "fiberform"], line
            args = parser.parse_args(argv[3:])  # SystemExit: a line the command line refuses
            if args.command == "collect":
                assert "--resume" not in argv, line
            else:
                assert args.resume is True, line
                assert bool(args.force) is (argv[3] == forced), line
                resumed.append(argv[3:5] if args.command == "prepare" else argv[3:4])
    return resumed


def test_sweep_resume_reaches_the_array_scripts(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """`sweep --submit slurm --resume` (the demo scene, 2 seeds, up to the lay-down): every array
    script runs its stage with --resume on its `fiberform prepare STAGE` (split stages: the
    lay-down's prepare is where a killed run continues from its restart files) or `fiberform STAGE`
    line, never on `fiberform collect` (no such option); each fiberform line is one the command
    line accepts, and the scripts equal those written without --resume but for that word."""
    texts: dict[bool, dict[str, str]] = {}
    for resume in (False, True):
        d = tmp_path / f"resume-{resume}"
        d.mkdir()
        shutil.copyfile(ROOT / "scenes" / "demo.yaml", d / "s.yaml")
        rc = _ff(d, monkeypatch, "sweep", "s.yaml", "--seeds", "2", "--to", "laydown", "--submit", "slurm",
                 "--dry-run", *(["--resume"] if resume else []))
        assert rc == 0, capsys.readouterr().err
        jobs = d / "runs/demo-sweep/jobs"
        texts[resume] = {p.name: p.read_text().replace(str(d), "@DIR@") for p in sorted(jobs.glob("*.slurm"))}
        for p in jobs.glob("*.slurm"):
            subprocess.run(["bash", "-n", str(p)], check=True)
    assert sorted(texts[True]) == ["fabric.slurm", "flow.slurm", "generate.slurm", "laydown.slurm"]
    resumed = _resumed_stage_lines(texts, None)
    assert resumed == [["fabric"], ["prepare", "flow"], ["generate"], ["prepare", "laydown"]]


@pytest.mark.parametrize("scheduler", ["slurm", "pbs"])
def test_submit_resume_reaches_the_scripts(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str], scheduler: str) -> None:
    """`submit SCENE --scheduler slurm|pbs --resume` (the demo scene up to the lay-down, generate
    forced so that one line carries --force and --resume): every script runs its stage with --resume
    on its `fiberform prepare STAGE` (the lay-down's prepare is where a resubmitted job continues
    from the restart files) or `fiberform STAGE` line, never on `fiberform collect` (no such
    option); each fiberform line is one the command line accepts, and the scripts and the replay
    script equal those written without --resume but for that word."""
    suffix = "slurm" if scheduler == "slurm" else "pbs"
    texts: dict[bool, dict[str, str]] = {}
    for resume in (False, True):
        d = tmp_path / f"resume-{resume}"
        d.mkdir()
        shutil.copyfile(ROOT / "scenes" / "demo.yaml", d / "s.yaml")
        rc = _ff(d, monkeypatch, "submit", "s.yaml", "--scheduler", scheduler, "--to", "laydown", "--dry-run",
                 "--force", "generate", *(["--resume"] if resume else []))
        assert rc == 0, capsys.readouterr().err
        jobs = d / "runs/demo/jobs"
        texts[resume] = {p.name: p.read_text().replace(str(d), "@DIR@") for p in sorted(jobs.iterdir())}
        for p in jobs.iterdir():
            subprocess.run(["bash", "-n", str(p)], check=True)
    assert sorted(texts[True]) == sorted([*(f"{s}.{suffix}" for s in ("fabric", "flow", "generate", "laydown")),
                                          f"submit-{scheduler}.sh"])
    assert texts[True][f"submit-{scheduler}.sh"] == texts[False][f"submit-{scheduler}.sh"]
    resumed = _resumed_stage_lines(texts, "generate")
    assert resumed == [["fabric"], ["prepare", "flow"], ["generate"], ["prepare", "laydown"]]


BAD_SWEEP = [
    (["--submit", "slurm", "--partition", "debug\n#SBATCH --uid=0"], "--partition"),
    (["--submit", "slurm", "--account", "$(id)"], "--account"),
    (["--submit", "pbs", "--qos", "normal"], "--qos: Slurm only"),
    (["--submit", "slurm", "--time", "10:00"], "--time"),
    (["--submit", "slurm", "--ntasks", "0"], "--ntasks"),
    (["--submit", "slurm", "--nodes", "2", "--ntasks", "1"], "--nodes"),
    (["--submit", "lsf"], "--submit"),
    (["--submit", "slurm", "--no-run"], "--no-run"),
    (["--partition", "debug"], "--partition: only with --submit"),
    (["--dry-run"], "--dry-run: only with --submit"),
    (["--submit", "slurm", "--to", "nosuch"], "--to 'nosuch'"),
]


@pytest.mark.parametrize(("args", "named"), BAD_SWEEP, ids=[f"{i}" for i in range(len(BAD_SWEEP))])
def test_bad_sweep_submit_options_exit_2_and_write_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        args: list[str], named: str) -> None:
    _assert_refused(tmp_path, monkeypatch, capsys, SCENE, [*SWEEP, "--dry-run", *args], named)


def test_pbs_array_needs_two_variants(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    _assert_refused(tmp_path, monkeypatch, capsys, SCENE, ["sweep", "s.yaml", "--submit", "pbs", "--dry-run"],
                    "at least 2 variants")


def test_time_forms() -> None:
    assert parse_time("90") == 5400
    assert parse_time("01:30:00") == 5400
    assert parse_time("2-00:00:01") == 2 * 86400 + 1
    with pytest.raises(ConfigError, match="--time '1:3:00'"):
        parse_time("1:3:00")
    assert batch_options("slurm", partition="gpu-a100.x", nodes="2", ntasks=4).nodes == 2


def test_status_merges_queue_states() -> None:
    rec = lambda stage: JobRecord(stage, "slurm", "7", f"/j/{stage}.slurm", "t", ())  # noqa: E731
    rows = [StageStatus("a", "missing", ""), StageStatus("b", "stale", "upstream not done: a"),
            StageStatus("c", "done", "2026"), StageStatus("d", "missing", ""), StageStatus("e", "running", "pid 3")]
    states = {"a": QueueState(rec("a"), "RUNNING"), "b": QueueState(rec("b"), "PENDING", "Dependency"),
              "c": QueueState(rec("c"), "COMPLETED", "None"), "d": QueueState(rec("d"), "CANCELLED", "x"),
              "e": QueueState(rec("e"), "TIMEOUT")}
    got = {r.stage: (r.state, r.detail) for r in annotate_status(rows, states)}
    assert got == {"a": ("running", "(slurm 7, RUNNING)"), "b": ("queued", "(slurm 7, PENDING (Dependency))"),
                   "c": ("done", "2026 (slurm 7, COMPLETED)"), "d": ("failed", "(slurm 7, CANCELLED (x))"),
                   "e": ("failed", "(slurm 7, TIMEOUT); the job ended before the stage finished")}


def test_pbs_qstat_states() -> None:
    assert pbs_state("Job Id: 12.srv\n    job_state = Q\n") == ("QUEUED", "")
    assert pbs_state("    job_state = F\n    Exit_status = 0\n") == ("COMPLETED", "")
    assert pbs_state("    job_state = F\n    Exit_status = 2\n") == ("FAILED", "exit status 2")
    assert pbs_state("nothing") is None


# ---- a real Slurm on this host -------------------------------------------------------------------

def _free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


SLURM_CONF = """# A one-node Slurm for tests/test_submit.py (written by the test fixture)
ClusterName=fftest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ctld_port}
SlurmdPort={d_port}
SlurmUser=root
SlurmdUser=root
AuthType=auth/none
CredType=cred/none
StateSaveLocation={d}/state
SlurmdSpoolDir={d}/spool
SlurmctldPidFile={d}/slurmctld.pid
SlurmdPidFile={d}/slurmd.pid
SlurmctldLogFile={d}/slurmctld.log
SlurmdLogFile={d}/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
MinJobAge=600
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} State=UNKNOWN
PartitionName=debug Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


def _stop(pid_file: Path) -> None:
    with contextlib.suppress(OSError, ValueError):
        pid = int(pid_file.read_text().split()[0])
        os.kill(pid, signal.SIGTERM)
        for _ in range(100):
            os.kill(pid, 0)  # raises once it is gone
            time.sleep(0.1)
        os.kill(pid, signal.SIGKILL)


@pytest.fixture(scope="module")
def slurm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, str]]:
    """slurmctld + slurmd on this host with a private configuration, state and ports; yields the
    environment for the client commands (SLURM_CONF). The daemons are stopped afterwards, also
    when the start fails."""
    if os.geteuid() != 0:
        pytest.skip("the Slurm test needs root: slurmd runs the jobs as root here (see docs/stages/cli.md)")
    missing = [t for t in ("slurmctld", "slurmd", "sbatch", "squeue", "scontrol", "sinfo") if shutil.which(t) is None]
    if missing:
        pytest.fail(f"{', '.join(missing)} not installed: `make setup` installs slurmctld, slurmd, slurm-client")
    d = tmp_path_factory.mktemp("slurm")
    (d / "state").mkdir()
    (d / "spool").mkdir()
    host = socket.gethostname().split(".")[0]
    ctld_port, d_port = _free_ports(2)
    conf = d / "slurm.conf"
    conf.write_text(SLURM_CONF.format(host=host, ctld_port=ctld_port, d_port=d_port, d=d, cpus=os.cpu_count() or 1))
    env = dict(os.environ, SLURM_CONF=str(conf), OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"))
    logs = lambda: "\n".join(f"--- {p.name}:\n" + "\n".join(p.read_text(errors="replace").splitlines()[-15:])  # noqa: E731
                             for p in sorted(d.glob("*.log")))
    try:
        subprocess.run(["slurmctld", "-c", "-f", str(conf)], env=env, check=True, timeout=30)
        subprocess.run(["slurmd", "-f", str(conf)], env=env, check=True, timeout=30)
        deadline = time.monotonic() + 30
        state = ""
        while time.monotonic() < deadline:
            r = subprocess.run(["sinfo", "-h", "-n", host, "-o", "%T"], env=env, capture_output=True, text=True,
                               timeout=10, check=False)
            state = r.stdout.strip()
            if state == "idle":
                break
            time.sleep(0.3)
        else:
            pytest.fail(f"the test Slurm node never became idle (sinfo: {state!r})\n{logs()}")
        yield env
    finally:
        _stop(d / "slurmd.pid")
        _stop(d / "slurmctld.pid")


def _run(env: dict[str, str], cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fiberform", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120, check=False)


def _scontrol(env: dict[str, str], *args: str) -> str:
    return subprocess.run(["scontrol", *args], env=env, capture_output=True, text=True, timeout=20,
                          check=True).stdout


def _job_state(env: dict[str, str], jid: str) -> tuple[str, str]:
    out = _scontrol(env, "-o", "show", "job", jid)
    state = re.search(r"\bJobState=(\S+)", out)
    reason = re.search(r"\bReason=(\S+)", out)
    assert state is not None and reason is not None, out
    return state[1], reason[1]


def _wait_ended(env: dict[str, str], ids: list[str], timeout: float = 150) -> dict[str, tuple[str, str]]:
    deadline = time.monotonic() + timeout
    while True:
        states = {j: _job_state(env, j) for j in ids}
        if all(s not in ("PENDING", "RUNNING", "CONFIGURING", "COMPLETING") for s, _ in states.values()):
            return states
        assert time.monotonic() < deadline, f"jobs did not end in {timeout} s: {states}"
        time.sleep(0.5)


def _status(env: dict[str, str], d: Path) -> dict[str, tuple[str, str]]:
    r = _run(env, d, "status", "s.yaml")
    assert r.returncode == 0, r.stderr
    return parse_status(r.stdout)


def _submit(env: dict[str, str], d: Path) -> tuple[str, str]:
    """Submit fabric -> flow while the partition is down (so the pending state and the dependency
    can be seen before anything runs); returns the two job IDs from jobs.json."""
    _scontrol(env, "update", "PartitionName=debug", "State=DOWN")
    r = _run(env, d, "submit", "s.yaml", "--scheduler", "slurm", "--partition", "debug", "--time", "5")
    assert r.returncode == 0, r.stderr
    jobs = json.loads((d / "runs/pipe/jobs/jobs.json").read_text())["jobs"]
    fabric, flow = jobs["fabric"]["job_id"], jobs["flow"]["job_id"]
    assert jobs["flow"]["after"] == [fabric] and jobs["fabric"]["after"] == []
    assert f"flow: slurm job {flow} after {fabric}" in r.stdout, r.stdout
    return fabric, flow


@pytest.mark.system
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")
def test_slurm_runs_the_chain_and_cancels_after_a_failure(slurm: dict[str, str], tmp_path: Path) -> None:
    env, d = slurm, tmp_path
    (d / "s.yaml").write_text(SCENE)

    fabric, flow = _submit(env, d)
    # the flow job waits for the fabric job in Slurm itself
    assert f"Dependency=afterok:{fabric}(unfulfilled)" in _scontrol(env, "-o", "show", "job", flow)
    st = _status(env, d)
    assert st["fabric"] == ("queued", f"(slurm {fabric}, PENDING (PartitionDown))"), st
    assert st["flow"][0] == "queued" and st["flow"][1].startswith(f"(slurm {flow}, PENDING"), st
    # a second submission while queued is refused, nothing new queued
    r = _run(env, d, "submit", "s.yaml", "--scheduler", "slurm")
    assert r.returncode == 2 and f"stage fabric is already submitted (slurm {fabric}, PENDING" in r.stderr, r.stderr

    _scontrol(env, "update", "PartitionName=debug", "State=UP")
    ended = _wait_ended(env, [fabric, flow])
    assert ended == {fabric: ("COMPLETED", "None"), flow: ("COMPLETED", "None")}, ended
    for p in ("fabric/fabric.h5", "flow/flow.h5", "flow/flow.grid"):
        assert (d / "runs/pipe" / p).is_file(), p
    out = (d / f"runs/pipe/jobs/flow-{flow}.out").read_text()
    assert "flow: prepared; run in" in out and "flow: collected in" in out, out  # prepare, solver, collect
    assert "SIMPLE solution converged" in (d / "runs/pipe/flow/log.simpleFoam").read_text()
    st = _status(env, d)
    assert st["fabric"][0] == "done" and st["fabric"][1].endswith(f"(slurm {fabric}, COMPLETED)"), st
    assert st["flow"][0] == "done" and st["flow"][1].endswith(f"(slurm {flow}, COMPLETED)"), st
    r = _run(env, d, "submit", "s.yaml", "--scheduler", "slurm")
    assert r.returncode == 0 and "nothing to do" in r.stdout, r.stdout + r.stderr

    # a failing first stage (its folder is a plain file) cancels the second: afterok never holds
    shutil.rmtree(d / "runs/pipe/fabric")
    (d / "runs/pipe/fabric").write_text("not a folder\n")
    fabric2, flow2 = _submit(env, d)
    assert (fabric2, flow2) != (fabric, flow)
    _scontrol(env, "update", "PartitionName=debug", "State=UP")
    ended = _wait_ended(env, [fabric2, flow2])
    assert ended == {fabric2: ("FAILED", "NonZeroExitCode"), flow2: ("CANCELLED", "DependencyNeverSatisfied")}, ended
    st = _status(env, d)
    assert st["fabric"] == ("failed", f"(slurm {fabric2}, FAILED (NonZeroExitCode))"), st
    assert st["flow"] == ("failed", f"(slurm {flow2}, CANCELLED (DependencyNeverSatisfied))"), st
    assert not (d / f"runs/pipe/jobs/flow-{flow2}.out").exists()  # never started


@pytest.mark.system
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM (simpleFoam) not installed")
def test_slurm_sweep_runs_as_job_arrays(slurm: dict[str, str], tmp_path: Path) -> None:
    """`sweep --submit slurm` of 2 variants (flow.delta_p_Pa 50, 100 Pa): a fabric array and a flow
    array with aftercorr on it run to completion; each variant's status names its array task;
    collect tabulates both, the larger pressure drop giving the larger superficial velocity."""
    env, d = slurm, tmp_path
    (d / "s.yaml").write_text(SCENE)
    _scontrol(env, "update", "PartitionName=debug", "State=DOWN")
    r = _run(env, d, *SWEEP, "--submit", "slurm", "--partition", "debug", "--time", "5")
    assert r.returncode == 0, r.stderr
    sweep = d / "runs/pipe-sweep"
    jobs = json.loads((sweep / "jobs/jobs.json").read_text())["jobs"]
    fabric, flow = jobs["fabric"]["job_id"], jobs["flow"]["job_id"]
    assert jobs["flow"]["after"] == [fabric]
    shown = _scontrol(env, "-o", "show", "job", flow)
    assert f"Dependency=aftercorr:{fabric}_*(unfulfilled)" in shown, shown
    st = _run(env, d, "status", "runs/pipe-sweep/scenes/pipe_001.yaml")
    assert st.returncode == 0, st.stderr
    rows = parse_status(st.stdout)
    assert rows["fabric"] == ("queued", f"(slurm {fabric}_1, PENDING (PartitionDown))"), rows
    _scontrol(env, "update", "PartitionName=debug", "State=UP")
    tasks = [f"{j}_{k}" for j in (fabric, flow) for k in (0, 1)]
    ended = _wait_ended(env, tasks, timeout=300)
    assert all(s == ("COMPLETED", "None") for s in ended.values()), ended
    for k in (0, 1):
        st = _run(env, d, "status", f"runs/pipe-sweep/scenes/pipe_00{k}.yaml")
        rows = parse_status(st.stdout)
        assert rows["flow"][0] == "done" and rows["flow"][1].endswith(f"(slurm {flow}_{k}, COMPLETED)"), rows
        assert (d / f"runs/pipe-sweep/jobs/flow-{flow}_{k}.out").is_file()
    r = _run(env, d, "collect", "runs/pipe-sweep")
    assert r.returncode == 0, r.stderr
    table = list(csv.DictReader((sweep / "collect.csv").open()))
    assert [float(row["flow.delta_p_Pa"]) for row in table] == [50.0, 100.0]
    u = [float(row["flow_superficial_velocity_m_s"]) for row in table]
    assert 0 < u[0] < u[1], u
