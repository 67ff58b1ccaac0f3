# SPDX-License-Identifier: GPL-3.0-or-later
"""Batch executors: one Slurm or PBS job per stage, chained by afterok dependencies (issue 14).

``fiberform submit SCENE --scheduler slurm|pbs`` writes, for every selected stage that is not done,
``<output_dir>/jobs/<stage>.slurm`` (or ``.pbs``): a plain bash script whose directives ask for the
stage's MPI ranks as tasks. A stage split into prepare / program lines / collect
(:attr:`fiberform.stages.Stage.splits`: the stages that run fiberdem or simpleFoam) runs
``fiberform prepare STAGE SCENE``, then its program lines themselves
(``(cd CASE && mpirun -np N simpleFoam -parallel) > LOG 2>&1``, readable and rerunnable by hand),
then ``fiberform collect STAGE SCENE``; generate and fabric (no external program) run
``fiberform <stage> SCENE --build-dir DIR``, as ``fiberform run`` does on a workstation (the
``local`` executor). All paths are absolute. The scripts are submitted in graph order, each with
``afterok`` on the jobs of the stages it needs (Slurm ``--dependency=afterok:ID[:ID]``, PBS
``-W depend=afterok:ID[:ID]``); the job IDs go to ``<output_dir>/jobs/jobs.json`` and the
submission itself to ``jobs/submit-<scheduler>.sh``, which resubmits the same chain by hand.
``fiberform status`` reads the queue state of recorded jobs.

Sweeps (``fiberform sweep ... --submit slurm|pbs``): one job array per stage, task k for variant k
(the scene on line k + 1 of ``<sweep dir>/jobs/variants.txt``, picked through SLURM_ARRAY_TASK_ID /
PBS_ARRAY_INDEX); between stages Slurm ``aftercorr`` (task k after task k of the upstream array),
PBS ``afterok`` on the whole upstream array (:data:`ARRAY_DEPENDENCY`). Task k's ID is recorded in
variant k's own ``jobs/jobs.json``. ``fiberform submit ... --resume`` and ``fiberform sweep
--submit ... --resume`` put ``--resume`` on each script's ``fiberform prepare`` (or ``fiberform
STAGE``) line, never on ``fiberform collect``.

Safety: every value that reaches a script is a validated number, a validated identifier (scene,
stage, partition, account and qos names), a fixed option (``--force``, ``--resume``) or a path
quoted with :func:`shlex.quote` (paths in directive lines must also be free of blanks and quotes);
anything else is refused with exit 2 naming the option and the allowed form, before anything is
written.
"""

from __future__ import annotations

import datetime as _dt
import json
import re
import shlex
import shutil
import subprocess
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from . import __version__
from .errors import ConfigError, RunError
from .pipeline import StageGraph, StageStatus
from .provenance import atomic_write_text
from .runner import Program

__all__ = [
    "SCHEDULERS",
    "BatchOptions",
    "JobRecord",
    "JobSpec",
    "QueueState",
    "annotate_status",
    "array_task_id",
    "batch_options",
    "parse_time",
    "plan_array_jobs",
    "plan_jobs",
    "queue_states",
    "read_records",
    "record_array_tasks",
    "submit_jobs",
]

SCHEDULERS = ("slurm", "pbs")
#: Script suffix and submit program of each scheduler.
SUFFIX = {"slurm": "slurm", "pbs": "pbs"}
SUBMIT = {"slurm": "sbatch", "pbs": "qsub"}
JOBS_FOLDER = "jobs"
RECORDS_NAME = "jobs.json"

#: Partition / queue, account and QOS names: a letter or digit, then letters, digits, _ . - (<= 64).
NAME_PATTERN = r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}"
_NAME = re.compile(NAME_PATTERN)
#: Wall time: minutes (an integer), or [D-]HH:MM:SS.
TIME_FORM = "minutes (e.g. 90) or [D-]HH:MM:SS (e.g. 1-12:00:00)"
_TIME = re.compile(r"(?:(?P<d>\d{1,3})-)?(?P<h>\d{1,3}):(?P<m>[0-5]\d):(?P<s>[0-5]\d)|(?P<min>\d{1,7})")
#: Characters a folder may hold in a directive line (``#SBATCH --output=DIR/flow-%j.out``); no ``%``,
#: which Slurm would expand.
_DIRECTIVE_PATH = re.compile(r"[A-Za-z0-9_./+@,=:-]+")
#: A job ID as sbatch / qsub print it (Slurm: digits; PBS: ``123.server``).
_JOB_ID = {"slurm": re.compile(r"\d+"), "pbs": re.compile(r"\d+(?:\[\d*\])?(?:\.[A-Za-z0-9_.-]+)?")}
#: the IDs a job record may hold: a job's, or an array task's (Slurm ``<array>_<k>``, PBS ``<n>[<k>]...``)
_RECORD_ID = {"slurm": re.compile(r"\d+(?:_\d+)?"), "pbs": _JOB_ID["pbs"]}
_MAX_INT = 100_000


@dataclass(frozen=True)
class BatchOptions:
    """Validated scheduler options (``fiberform submit``)."""

    scheduler: str
    partition: str | None = None
    account: str | None = None
    qos: str | None = None
    time_s: int | None = None
    nodes: int | None = None
    ntasks: int | None = None


def parse_time(text: str, option: str = "--time") -> int:
    """Seconds of a wall-time limit given as minutes or ``[D-]HH:MM:SS``; ConfigError otherwise."""
    m = _TIME.fullmatch(text) if isinstance(text, str) else None
    if m is None:
        raise ConfigError(f"{option} {text!r}: not a wall time; allowed: {TIME_FORM}")
    if m["min"] is not None:
        seconds = int(m["min"]) * 60
    else:
        seconds = ((int(m["d"] or 0) * 24 + int(m["h"])) * 60 + int(m["m"])) * 60 + int(m["s"])
    if seconds <= 0:
        raise ConfigError(f"{option} {text!r}: must be longer than zero; allowed: {TIME_FORM}")
    return seconds


def _name(value: str | None, option: str) -> str | None:
    if value is None:
        return None
    if not _NAME.fullmatch(value):
        raise ConfigError(f"{option} {value!r}: not a valid name; allowed: ^{NAME_PATTERN}$ (letters, digits, "
                          "_ . -; no blanks, quotes or newlines)")
    return value


def _count(value: int | str | None, option: str) -> int | None:
    if value is None:
        return None
    text = str(value)
    if not re.fullmatch(r"[0-9]{1,6}", text) or not 1 <= int(text) <= _MAX_INT:
        raise ConfigError(f"{option} {text!r}: allowed: a whole number from 1 to {_MAX_INT}")
    return int(text)


def batch_options(scheduler: str, *, partition: str | None = None, account: str | None = None,
                  qos: str | None = None, time: str | None = None, nodes: int | str | None = None,
                  ntasks: int | str | None = None) -> BatchOptions:
    """Check every option and return them validated; ConfigError (exit 2) names the bad one."""
    if scheduler not in SCHEDULERS:
        raise ConfigError(f"--scheduler {scheduler!r}: allowed: {', '.join(SCHEDULERS)}")
    opts = BatchOptions(
        scheduler=scheduler,
        partition=_name(partition, "--partition"),
        account=_name(account, "--account"),
        qos=_name(qos, "--qos"),
        time_s=None if time is None else parse_time(time),
        nodes=_count(nodes, "--nodes"),
        ntasks=_count(ntasks, "--ntasks"),
    )
    if scheduler == "pbs" and opts.qos is not None:
        raise ConfigError("--qos: Slurm only (PBS has no QOS; use --partition for the queue)")
    if opts.nodes is not None and opts.ntasks is not None and opts.nodes > opts.ntasks:
        raise ConfigError(f"--nodes {opts.nodes}: more nodes than --ntasks {opts.ntasks}")
    return opts


# ---- job scripts ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class JobSpec:
    """One stage's batch job: its script and what it waits for."""

    stage: str
    script: Path
    text: str
    ntasks: int
    #: stages of the same submission this job waits for (afterok)
    after_stages: tuple[str, ...]
    #: jobs queued earlier (recorded in jobs.json) this job waits for
    after_jobs: tuple[str, ...]
    #: tasks of a job array (a sweep: one per variant); 0 for a single job
    tasks: int = 0


def _path(p: Path, what: str, directive: bool = False) -> str:
    s = str(p)
    if any(c in s for c in "\n\r\0"):
        raise ConfigError(f"{what} {s!r}: a path with a newline cannot go into a batch script")
    if directive and not _DIRECTIVE_PATH.fullmatch(s):
        raise ConfigError(f"{what} {s!r}: a batch directive cannot carry this path (allowed characters: "
                          "letters, digits and _ . / + @ , = : -; no blanks, quotes or %); choose an "
                          "output_dir / working folder without them")
    return s


#: Exit status of ``fiberform prepare`` when the stage is up to date (fiberform.cli).
UP_TO_DATE_STATUS = 3


def _program_line(p: Program) -> str:
    """A program line as a shell command: in its folder, on its ranks, output to its log."""
    mpi = ["mpirun", "-np", str(int(p.ranks))] if p.ranks > 1 else []
    argv = " ".join(shlex.quote(a) for a in [*mpi, *p.argv])
    return (f"(cd {shlex.quote(_path(p.cwd, 'program folder'))} && {argv}) "
            f"> {shlex.quote(_path(p.log, 'program log'))} 2>&1")


def _hms(seconds: int) -> str:
    return f"{seconds // 3600:02d}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}"


def _slurm_time(seconds: int) -> str:
    days, rest = divmod(seconds, 86400)
    return f"{days}-{_hms(rest)}"


def _directives(opts: BatchOptions, job_name: str, ntasks: int, out: str, tasks: int = 0) -> list[str]:
    if opts.scheduler == "slurm":
        lines = [f"--job-name={job_name}", f"--ntasks={ntasks}", f"--output={out}",
                 "--kill-on-invalid-dep=yes"]
        if tasks:
            lines.append(f"--array=0-{tasks - 1}")
        if opts.nodes is not None:
            lines.append(f"--nodes={opts.nodes}")
        if opts.partition is not None:
            lines.append(f"--partition={opts.partition}")
        if opts.account is not None:
            lines.append(f"--account={opts.account}")
        if opts.qos is not None:
            lines.append(f"--qos={opts.qos}")
        if opts.time_s is not None:
            lines.append(f"--time={_slurm_time(opts.time_s)}")
        return [f"#SBATCH {d}" for d in lines]
    nodes = opts.nodes or 1
    per_node = -(-ntasks // nodes)
    lines = [f"-N {job_name}", f"-l select={nodes}:ncpus={per_node}:mpiprocs={per_node}", "-j oe",
             f"-o {out}", "-V"]
    if tasks:
        lines.append(f"-J 0-{tasks - 1}")
    if opts.time_s is not None:
        lines.append(f"-l walltime={_hms(opts.time_s)}")
    if opts.partition is not None:
        lines.append(f"-q {opts.partition}")
    if opts.account is not None:
        lines.append(f"-A {opts.account}")
    return [f"#PBS {d}" for d in lines]


#: The environment variable holding the array task index, by scheduler.
ARRAY_INDEX = {"slurm": "SLURM_ARRAY_TASK_ID", "pbs": "PBS_ARRAY_INDEX"}
#: The dependency of a job array on the array of an upstream stage: Slurm ``aftercorr`` (task k
#: waits for task k of the upstream array only: each variant's chain is independent, and a failed
#: variant cancels only its own downstream tasks); PBS has no per-task dependency: ``afterok`` on
#: the whole upstream array.
ARRAY_DEPENDENCY = {"slurm": "aftercorr", "pbs": "afterok"}


def _dependency(opts: BatchOptions, tasks: int) -> str:
    kind = ARRAY_DEPENDENCY[opts.scheduler] if tasks else "afterok"
    return f"--dependency={kind}:" if opts.scheduler == "slurm" else f"-W depend={kind}:"


def render_script(opts: BatchOptions, *, stage: str, scene_name: str, scene_path: Path, workdir: Path,
                  build_dir: Path, jobs_dir: Path, ntasks: int, ranks: int, force: bool,
                  needs: Sequence[str], python: Path, tasks: int = 0,
                  variants_file: Path | None = None, programs: Sequence[Sequence[Program]] = (),
                  resume: bool = False) -> str:
    """The batch script of one stage (text); ``needs``: its upstream stages. Paths must be absolute.
    ``tasks`` > 0: a job array of that many tasks (a sweep); task k runs the stage on the scene
    on line k + 1 of ``variants_file`` (``scene_path`` is then the sweep's base scene, named in
    the comments only). ``programs``: the program lines of a split stage (one list, or one per
    array task): the script runs ``fiberform prepare``, the lines, ``fiberform collect``; else
    ``fiberform STAGE`` alone. ``resume``: that ``fiberform prepare`` (or ``fiberform STAGE``) line
    carries ``--resume`` (a killed lay-down continues from its restart files; ``collect`` takes no
    such option)."""
    for p in (scene_path, workdir, build_dir, jobs_dir, python, *([variants_file] if variants_file else [])):
        if not p.is_absolute():
            raise ConfigError(f"internal: {p} is not absolute")
    if not re.fullmatch(r"[a-z][a-z0-9-]{0,63}", stage) or not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,63}", scene_name):
        raise ConfigError(f"internal: stage {stage!r} or scene name {scene_name!r} is not an identifier")
    if tasks and variants_file is None:
        raise ConfigError("internal: a job array needs its variants file")
    jobs_s = _path(jobs_dir, "output folder", directive=True)
    if opts.scheduler == "slurm":
        job_name = f"ff-{scene_name}-{stage}"
        out_s = f"{jobs_s}/{stage}-%A_%a.out" if tasks else f"{jobs_s}/{stage}-%j.out"
    else:  # PBS: names of at most 15 characters starting with a letter are portable
        job_name = f"{stage}-{scene_name}"[:15]
        out_s = f"{jobs_s}/{stage}.^array_index^.pbs.out" if tasks else f"{jobs_s}/{stage}.pbs.out"
    sub = SUBMIT[opts.scheduler]
    dep = _dependency(opts, tasks)
    scene_arg = '"$scene"' if tasks else shlex.quote(_path(scene_path, "SCENE"))
    py = shlex.quote(_path(python, "python"))
    tail = ["--build-dir", shlex.quote(_path(build_dir, "--build-dir")), *(["--force"] if force else []),
            *(["--resume"] if resume else [])]
    cmd = [py, "-m", "fiberform", stage, scene_arg, *tail]
    script = jobs_dir / f"{stage}.{SUFFIX[opts.scheduler]}"
    what = (f"Stage {stage} of the {tasks} variants of sweep '{scene_name}' (one array task each)" if tasks
            else f"Stage {stage} of scene '{scene_name}'")
    if programs:
        ranks_note = ("`fiberform prepare` writes the inputs, the program lines below run the stage's programs "
                      "(mpirun -np N on N > 1 ranks), `fiberform collect` writes the products.")
    else:
        ranks_note = (f"The stage runs its programs itself: on {ranks} MPI rank(s) "
                      + (f"(mpirun -np {ranks} inside this allocation)." if ranks > 1 else "(no mpirun)."))
    lines = [
        "#!/bin/bash",
        *_directives(opts, job_name, ntasks, out_s, tasks),
        f"# {what}, written by `fiberform {'sweep --submit' if tasks else 'submit'}` (fiberform {__version__}).",
        "# " + ranks_note,
    ]
    if needs:
        lines += [f"# Needs the products of: {', '.join(needs)}. Resubmit by hand after their jobs:",
                  f"#   {sub} {dep}JOBID[:JOBID] {shlex.quote(str(script))}"]
    else:
        lines += ["# Resubmit by hand:", f"#   {sub} {shlex.quote(str(script))}"]
    lines += [
        "set -eu",
        f"cd {shlex.quote(_path(workdir, 'working folder'))}",
        'export WM_PROJECT_DIR="${WM_PROJECT_DIR:-/usr/share/openfoam}"',
    ]
    if tasks:
        assert variants_file is not None
        index = ARRAY_INDEX[opts.scheduler]
        lines += [f"# Array task k runs the variant on line k + 1 of {variants_file.name} ({index}).",
                  f'scene=$(sed -n "$(( {index} + 1 ))p" {shlex.quote(_path(variants_file, "variants file"))})',
                  'test -n "$scene"']
    if programs:
        if len(programs) != (tasks or 1):
            raise ConfigError("internal: one list of program lines per array task expected")
        lines += [f"# 1. inputs (exit status {UP_TO_DATE_STATUS}: the products are up to date, nothing to run)",
                  "status=0",
                  " ".join([py, "-m", "fiberform", "prepare", stage, scene_arg, *tail]) + " || status=$?",
                  f'if [ "$status" -eq {UP_TO_DATE_STATUS} ]; then exit 0; fi',
                  'if [ "$status" -ne 0 ]; then exit "$status"; fi',
                  "# 2. the program line(s)"]
        if tasks:
            index = ARRAY_INDEX[opts.scheduler]
            lines.append(f'case "${index}" in')
            for k, progs in enumerate(programs):
                lines.append(f"  {k}) " + " && ".join(_program_line(p) for p in progs) + " ;;")
            lines += [f'  *) echo "no program lines for task ${index}" >&2; exit 1 ;;', "esac"]
        else:
            lines += [_program_line(p) for p in programs[0]]
        lines.append("# 3. outputs -> products")
        cmd = [py, "-m", "fiberform", "collect", stage, scene_arg, "--build-dir",
               shlex.quote(_path(build_dir, "--build-dir"))]
    lines += ["exec " + " ".join(cmd), ""]
    return "\n".join(lines)


# ---- job records -------------------------------------------------------------------------------

@dataclass(frozen=True)
class JobRecord:
    """A submitted job, as recorded in ``jobs/jobs.json``."""

    stage: str
    scheduler: str
    job_id: str
    script: str
    submitted_utc: str
    after: tuple[str, ...]


def jobs_dir(output_path: Path) -> Path:
    return output_path / JOBS_FOLDER


def read_records(output_path: Path) -> dict[str, JobRecord]:
    """The last recorded job of each stage (empty when nothing was submitted)."""
    path = jobs_dir(output_path) / RECORDS_NAME
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
        records = {stage: JobRecord(stage, str(r["scheduler"]), str(r["job_id"]), str(r["script"]),
                                    str(r["submitted_utc"]), tuple(str(a) for a in r.get("after", ())))
                   for stage, r in data["jobs"].items()}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"{path}: unreadable job records ({exc}); delete it to forget the jobs") from None
    # the IDs go into scheduler commands and scripts again (status, resubmission): only what the
    # scheduler could have printed is accepted, as at submission
    for r in records.values():
        pattern = _RECORD_ID.get(r.scheduler)
        if pattern is None or not all(pattern.fullmatch(j) for j in (r.job_id, *r.after)):
            raise ConfigError(f"{path}: job record of stage {r.stage!r} holds a scheduler or job ID that "
                              f"{r.scheduler} would not print ({r.scheduler!r}, {r.job_id!r}, {list(r.after)!r}); "
                              "delete the file to forget the jobs")
    return records


def _write_records(output_path: Path, records: Mapping[str, JobRecord]) -> None:
    data = {"format": 1, "jobs": {s: {"scheduler": r.scheduler, "job_id": r.job_id, "script": r.script,
                                      "submitted_utc": r.submitted_utc, "after": list(r.after)}
                                  for s, r in records.items()}}
    atomic_write_text(jobs_dir(output_path) / RECORDS_NAME, json.dumps(data, indent=2) + "\n")


# ---- queue states ------------------------------------------------------------------------------

#: Scheduler states (Slurm names; PBS letters are mapped to these words) by what they mean here.
QUEUED = {"PENDING", "CONFIGURING", "REQUEUED", "REQUEUE_HOLD", "REQUEUE_FED", "RESV_DEL_HOLD",
          "SUSPENDED", "STOPPED", "QUEUED", "HELD", "WAITING", "TRANSIT"}
ACTIVE = {"RUNNING", "COMPLETING", "STAGE_OUT", "SIGNALING", "RESIZING", "EXITING"}
ENDED_BAD = {"FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY", "PREEMPTED", "BOOT_FAIL",
             "DEADLINE", "REVOKED"}
_PBS_STATE = {"Q": "QUEUED", "H": "HELD", "W": "WAITING", "T": "TRANSIT", "S": "SUSPENDED", "U": "SUSPENDED",
              "R": "RUNNING", "E": "EXITING", "B": "RUNNING", "M": "TRANSIT", "X": "COMPLETED"}


@dataclass(frozen=True)
class QueueState:
    """What the scheduler says about a recorded job (``state`` is e.g. PENDING, COMPLETED, or
    UNKNOWN when no tool knows the job any more)."""

    record: JobRecord
    state: str
    reason: str = ""

    def label(self) -> str:
        why = f" ({self.reason})" if self.reason and self.reason not in ("None", "(null)") else ""
        return f"{self.record.scheduler} {self.record.job_id}, {self.state}{why}"


def _query(cmd: Sequence[str], timeout: float = 30) -> tuple[str | None, str]:
    """(stdout or None when the command is missing or failed, stderr or why it failed)."""
    if shutil.which(cmd[0]) is None:
        return None, f"{cmd[0]} not found"
    try:
        r = subprocess.run(list(cmd), capture_output=True, text=True, timeout=timeout, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return None, str(exc)
    return (r.stdout if r.returncode == 0 else None), r.stderr.strip()


def _slurm_states(ids: Sequence[str]) -> dict[str, tuple[str, str]]:
    found: dict[str, tuple[str, str]] = {}
    out, err = _query(["squeue", "-h", "-r", "-t", "all", "-j", ",".join(ids), "-o", "%i|%T|%r"])
    if out is None and ("contact slurm controller" in err or "not found" in err or "timed out" in err):
        return {j: ("UNKNOWN", f"squeue: {err.splitlines()[-1] if err else 'failed'}") for j in ids}
    for line in (out or "").splitlines():
        parts = line.strip().split("|")
        if len(parts) == 3:
            found[parts[0]] = (parts[1], parts[2])
    for jid in (j for j in ids if j not in found):  # aged out of squeue: accounting, then scontrol
        out, _ = _query(["sacct", "-n", "-X", "-P", "-j", jid, "-o", "State"])
        if out and out.split():
            found[jid] = (out.split()[0], "")
            continue
        out, _ = _query(["scontrol", "-o", "show", "job", jid])
        m = re.search(r"\bJobState=(\S+)", out or "")
        if m:
            reason = re.search(r"\bReason=(\S+)", out or "")
            found[jid] = (m[1], reason[1] if reason else "")
    return found


def pbs_state(qstat_f: str) -> tuple[str, str] | None:
    """(state, detail) from ``qstat -x -f ID`` output (PBS Pro and Torque print ``job_state = X``)."""
    m = re.search(r"^\s*job_state\s*=\s*(\w)", qstat_f, re.MULTILINE)
    if m is None:
        return None
    letter = m[1]
    if letter in ("F", "C"):
        code = re.search(r"^\s*[Ee]xit_status\s*=\s*(-?\d+)", qstat_f, re.MULTILINE)
        if code is None or code[1] == "0":
            return "COMPLETED", ""
        return "FAILED", f"exit status {code[1]}"
    return _PBS_STATE.get(letter, letter), ""


def queue_states(records: Mapping[str, JobRecord]) -> dict[str, QueueState]:
    """Ask the schedulers about every recorded job (squeue, then sacct, then scontrol; qstat)."""
    slurm = [r.job_id for r in records.values() if r.scheduler == "slurm"]
    found = _slurm_states(slurm) if slurm else {}
    out: dict[str, QueueState] = {}
    for stage, r in records.items():
        if r.scheduler == "slurm":
            state, reason = found.get(r.job_id, ("UNKNOWN", "not known to squeue/sacct/scontrol any more"))
        else:
            text, _ = _query(["qstat", "-x", "-f", r.job_id])
            got = pbs_state(text) if text is not None else None
            state, reason = got or ("UNKNOWN", "qstat missing or does not know the job")
        out[stage] = QueueState(r, state, reason)
    return out


def annotate_status(rows: Sequence[StageStatus], states: Mapping[str, QueueState]) -> list[StageStatus]:
    """Merge the queue state of each stage's recorded job into its file-based status: a pending
    job makes the stage ``queued``, a running one ``running``; a job that failed or was cancelled
    makes a stage without (current) products ``failed``; otherwise the job is only named."""
    out = []
    for row in rows:
        q = states.get(row.stage)
        if q is None:
            out.append(row)
            continue
        tag = f"({q.label()})"
        if q.state in QUEUED and row.state != "running":
            out.append(StageStatus(row.stage, "queued", tag))
        elif q.state in ACTIVE and row.state != "running":
            out.append(StageStatus(row.stage, "running", tag))
        elif q.state in ENDED_BAD and row.state in ("missing", "stale", "running"):
            note = "; the job ended before the stage finished" if row.state == "running" else ""
            out.append(StageStatus(row.stage, "failed", f"{tag}{note}"))
        else:
            out.append(StageStatus(row.stage, row.state, f"{row.detail} {tag}".strip()))
    return out


def live_jobs(states: Mapping[str, QueueState]) -> dict[str, QueueState]:
    """The recorded jobs still queued or running."""
    return {s: q for s, q in states.items() if q.state in QUEUED | ACTIVE}


# ---- planning and submitting -------------------------------------------------------------------

def _job_tasks(opts: BatchOptions, stage: str, ranks: int, why: str) -> int:
    """The tasks a stage's job asks for: --ntasks (never below the stage's ``ranks``) or the ranks;
    ConfigError for too few tasks or more nodes than tasks."""
    if opts.ntasks is not None and opts.ntasks < ranks:
        raise ConfigError(f"--ntasks {opts.ntasks}: stage {stage} runs on {ranks} MPI ranks ({why}); ask for "
                          "at least that many")
    ntasks = opts.ntasks or ranks
    if opts.nodes is not None and opts.nodes > ntasks:
        raise ConfigError(f"--nodes {opts.nodes}: more nodes than the {ntasks} task(s) of stage {stage}")
    return ntasks


def plan_jobs(graph: StageGraph, opts: BatchOptions, *, start: str | None, stop: str | None,
              forced: set[str], workdir: Path, python: Path,
              states: Mapping[str, QueueState], resume: bool = False) -> list[JobSpec]:
    """The jobs to submit: each selected stage that is not done (or forced, or downstream of a
    stage submitted here), in graph order, with its dependencies. Raises ConfigError (nothing
    written) for a stage already queued or running, an upstream stage that is neither done,
    selected nor queued, and --ntasks below a stage's ranks. ``resume``: every script runs its
    stage with ``--resume`` (as ``fiberform run --resume`` does: a killed lay-down continues from
    its restart files instead of starting over)."""
    ctx = graph.ctx
    selected = graph.select(start, stop)
    status = {r.stage: r for r in graph.status()}
    live = live_jobs(states)
    scene_path = ctx.scene_path.resolve()
    build = ctx.build_dir.resolve()
    out_dir = (workdir / ctx.scene.output_path).resolve()
    jdir = jobs_dir(out_dir)
    specs: list[JobSpec] = []
    chosen: set[str] = set()
    for st in selected:
        name = st.name
        ups = graph.upstream[name]
        if not (name in forced or status[name].state != "done" or any(u in chosen for u in ups)):
            continue
        if name in live:
            q = live[name]
            cancel = "scancel" if q.record.scheduler == "slurm" else "qdel"
            raise ConfigError(f"stage {name} is already submitted ({q.label()}): wait for it, or "
                              f"`{cancel} {q.record.job_id}` before submitting it again")
        if status[name].state == "running":
            raise ConfigError(f"stage {name} is running ({status[name].detail}): wait for it first")
        after_stages, after_jobs = [], []
        for u in ups:
            if u in chosen:
                after_stages.append(u)
            elif u in live:
                if live[u].record.scheduler != opts.scheduler:
                    raise ConfigError(f"stage {name} needs {u}, queued on {live[u].record.scheduler}, "
                                      f"not {opts.scheduler}")
                after_jobs.append(live[u].record.job_id)
            elif status[u].state != "done":
                raise ConfigError(f"stage {name} needs the products of {u}, which is {status[u].state} and "
                                  "neither selected nor queued: select it too (drop --from) or run it first")
        ranks = st.ranks(ctx)
        ntasks = _job_tasks(opts, name, ranks, "its scene section's ranks")
        progs = [_absolute(st.programs(ctx), workdir)] if st.splits else []
        text = render_script(opts, stage=name, scene_name=ctx.scene.name, scene_path=scene_path,
                             workdir=workdir, build_dir=build, jobs_dir=jdir, ntasks=ntasks, ranks=ranks,
                             force=name in forced, needs=ups, python=python, programs=progs, resume=resume)
        specs.append(JobSpec(name, jdir / f"{name}.{SUFFIX[opts.scheduler]}", text, ntasks,
                             tuple(after_stages), tuple(after_jobs)))
        chosen.add(name)
    return specs


VARIANTS_NAME = "variants.txt"


def array_task_id(scheduler: str, array_id: str, k: int) -> str:
    """The ID of task ``k`` of a job array: Slurm ``<id>_<k>``, PBS ``<n>[<k>].<server>``."""
    return f"{array_id}_{k}" if scheduler == "slurm" else array_id.replace("[]", f"[{k}]", 1)


def plan_array_jobs(graphs: Sequence[StageGraph], opts: BatchOptions, *, start: str | None, stop: str | None,
                    sweep_name: str, base_scene: Path, jobs_folder: Path, workdir: Path, python: Path,
                    states: Mapping[str, QueueState], resume: bool = False) -> tuple[list[JobSpec], str]:
    """One job array per selected stage for the sweep variants (``graphs``: one stage graph per
    variant, in variant order; task k = variant k), in graph order, each array after the arrays of
    the stages it needs (:data:`ARRAY_DEPENDENCY`); and the text of the variants file (one absolute
    scene path a line). Every selected stage is submitted: a task whose variant is already done
    finds its stage up to date and ends at once. ConfigError (nothing written) when the variants
    do not share their stages, a stage of the sweep is still queued or running (``states``), a
    PBS array would have fewer than 2 tasks, or --ntasks is below a stage's ranks. ``resume``:
    every script runs its stage with ``--resume`` (as ``fiberform run --resume`` does: a killed
    lay-down continues from its restart files instead of starting over)."""
    if not graphs:
        raise ConfigError("internal: a sweep without variants")
    if opts.scheduler == "pbs" and len(graphs) < 2:
        raise ConfigError("--submit pbs: a PBS job array needs at least 2 variants (use `fiberform submit` "
                          "for one scene)")
    first = [st.name for st in graphs[0].select(start, stop)]
    for g in graphs[1:]:
        names = [st.name for st in g.select(start, stop)]
        if names != first:
            raise ConfigError(f"--set: the variants enable different stages ({', '.join(first)} vs "
                              f"{', '.join(names)}); a sweep submits the same stages for every variant")
    live = live_jobs(states)
    if live:
        name, q = next(iter(live.items()))
        cancel = "scancel" if q.record.scheduler == "slurm" else "qdel"
        raise ConfigError(f"stage {name} of this sweep is already submitted ({q.label()}): wait for it, or "
                          f"`{cancel} {q.record.job_id}` before submitting the sweep again")
    variants_file = jobs_folder / VARIANTS_NAME
    scenes = [g.ctx.scene_path if g.ctx.scene_path.is_absolute() else (workdir / g.ctx.scene_path) for g in graphs]
    for s in scenes:
        _path(s, "variant scene")
    build = graphs[0].ctx.build_dir.resolve()
    specs: list[JobSpec] = []
    for name in first:
        ups = graphs[0].upstream[name]
        ranks = max(g.stages[name].ranks(g.ctx) for g in graphs)
        ntasks = _job_tasks(opts, name, ranks, "its scene section's ranks, largest over the variants")
        after = tuple(u for u in ups if u in first)
        split = graphs[0].stages[name].splits
        progs = [_absolute(g.stages[name].programs(g.ctx), workdir) for g in graphs] if split else []
        text = render_script(opts, stage=name, scene_name=sweep_name, scene_path=base_scene, workdir=workdir,
                             build_dir=build, jobs_dir=jobs_folder, ntasks=ntasks, ranks=ranks, force=False,
                             needs=after, python=python, tasks=len(graphs), variants_file=variants_file,
                             programs=progs, resume=resume)
        specs.append(JobSpec(name, jobs_folder / f"{name}.{SUFFIX[opts.scheduler]}", text, ntasks, after, (),
                             len(graphs)))
    return specs, "".join(f"{s}\n" for s in scenes)


def record_array_tasks(opts: BatchOptions, made: Sequence[JobRecord], variant_outputs: Sequence[Path]) -> None:
    """Record task k of every submitted array in the job records of variant k (its
    ``<output_dir>/jobs/jobs.json``), so that ``fiberform status VARIANT`` shows its queue state."""
    for k, out in enumerate(variant_outputs):
        records = read_records(out)
        for rec in made:
            records[rec.stage] = JobRecord(rec.stage, rec.scheduler, array_task_id(opts.scheduler, rec.job_id, k),
                                           rec.script, rec.submitted_utc,
                                           tuple(array_task_id(opts.scheduler, a, k) for a in rec.after))
        jobs_dir(out).mkdir(parents=True, exist_ok=True)
        _write_records(out, records)


def _absolute(programs: Sequence[Program], workdir: Path) -> list[Program]:
    """The program lines with absolute folders and logs (a stage folder relative to the working
    folder of the job)."""
    def a(p: Path) -> Path:
        return p if p.is_absolute() else workdir / p

    return [Program(p.argv, p.ranks, a(p.cwd), a(p.log)) for p in programs]


def _var(stage: str) -> str:
    return "job_" + stage.replace("-", "_")


def submit_command(opts: BatchOptions, script: Path, after: Sequence[str], tasks: int = 0) -> list[str]:
    """The argument list that submits ``script`` after the jobs ``after`` (IDs; for a job array
    (``tasks`` > 0) the upstream arrays, :data:`ARRAY_DEPENDENCY`)."""
    dep = _dependency(opts, tasks) + ":".join(after)
    if opts.scheduler == "slurm":
        return ["sbatch", "--parsable", *([dep] if after else []), str(script)]
    return ["qsub", *(dep.split(" ", 1) if after else []), str(script)]


def replay_script(opts: BatchOptions, specs: Sequence[JobSpec], workdir: Path) -> str:
    """``jobs/submit-<scheduler>.sh``: the same submission as shell commands, IDs in variables."""
    what = "sweep --submit" if specs and specs[0].tasks else "submit --scheduler"
    lines = ["#!/bin/bash",
             (f"# Resubmits the jobs of the last `fiberform {what} {opts.scheduler}` "
              "in the same order, with the same dependencies."),
             "set -euo pipefail", f"cd {shlex.quote(str(workdir))}"]
    for s in specs:
        after = [f"${{{_var(u)}}}" for u in s.after_stages] + list(s.after_jobs)
        dep = f" {_dependency(opts, s.tasks)}{':'.join(after)}" if after else ""
        if opts.scheduler == "slurm":
            lines += [f"{_var(s.stage)}=$(sbatch --parsable{dep} {shlex.quote(str(s.script))})",
                      f"{_var(s.stage)}=${{{_var(s.stage)}%%;*}}"]
        else:
            lines.append(f"{_var(s.stage)}=$(qsub{dep} {shlex.quote(str(s.script))})")
        lines.append(f'echo "{s.stage}: job ${{{_var(s.stage)}}}"')
    return "\n".join(lines) + "\n"


def write_scripts(opts: BatchOptions, specs: Sequence[JobSpec], workdir: Path) -> Path:
    """Write every job script and the replay script; returns the replay script's path."""
    if not specs:
        raise ConfigError("internal: no jobs")
    jdir = specs[0].script.parent
    jdir.mkdir(parents=True, exist_ok=True)
    for s in specs:
        atomic_write_text(s.script, s.text)
        s.script.chmod(0o755)
    replay = jdir / f"submit-{opts.scheduler}.sh"
    atomic_write_text(replay, replay_script(opts, specs, workdir))
    replay.chmod(0o755)
    return replay


def check_submit_program(opts: BatchOptions) -> str:
    """The submit program (sbatch / qsub); ConfigError (exit 2) when it is not on PATH."""
    program = SUBMIT[opts.scheduler]
    if shutil.which(program) is None:
        raise ConfigError(f"--scheduler {opts.scheduler}: {program} not found on PATH, so nothing was "
                          "written or submitted; --dry-run writes the scripts without submitting")
    return program


def submit_jobs(opts: BatchOptions, specs: Sequence[JobSpec], output_path: Path, workdir: Path) -> list[JobRecord]:
    """Submit the (written) scripts in order with afterok dependencies; record each job in
    ``jobs.json`` as soon as it is queued. RunError (exit 1) when the submit program fails; the
    jobs queued before stay queued and recorded."""
    program = check_submit_program(opts)
    records = read_records(output_path)
    ids: dict[str, str] = {}
    made: list[JobRecord] = []
    for s in specs:
        after = [ids[u] for u in s.after_stages] + list(s.after_jobs)
        cmd = submit_command(opts, s.script, after, s.tasks)
        try:
            r = subprocess.run(cmd, cwd=workdir, capture_output=True, text=True, timeout=120, check=False)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise RunError(cmd, None, "(none)", [str(exc)], f"{program} failed") from None
        jid = r.stdout.strip().split(";")[0] if r.returncode == 0 else ""
        if not _JOB_ID[opts.scheduler].fullmatch(jid):
            queued = ", ".join(f"{m.stage} {m.job_id}" for m in made) or "none"
            raise RunError(cmd, r.returncode, "(stdout/stderr below)",
                           (r.stdout + r.stderr).strip().splitlines()[-20:],
                           f"{program} did not return a job ID (jobs queued before: {queued})")
        ids[s.stage] = jid
        rec = JobRecord(s.stage, opts.scheduler, jid, str(s.script), _now(), tuple(after))
        records[s.stage] = rec
        made.append(rec)
        _write_records(output_path, records)
    return made


def default_python() -> Path:
    """The interpreter the jobs run fiberform with: this one (the venv's)."""
    return Path(sys.executable).absolute()


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
