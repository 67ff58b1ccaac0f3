# SPDX-License-Identifier: GPL-3.0-or-later
"""Batch executors: one Slurm or PBS job per stage, chained by afterok dependencies (issue 14).

``fiberform submit SCENE --scheduler slurm|pbs`` writes, for every selected stage that is not done,
``<output_dir>/jobs/<stage>.slurm`` (or ``.pbs``): a plain bash script whose directives ask for the
stage's MPI ranks as tasks and whose one command is ``fiberform <stage> SCENE --build-dir DIR``
(absolute paths); the stage launches its own programs (``mpirun -np N`` when its ``ranks`` > 1)
inside the allocation, exactly as ``fiberform run`` does on a workstation (the ``local`` executor).
The scripts are submitted in graph order, each with ``afterok`` on the jobs of the stages it needs
(Slurm ``--dependency=afterok:ID[:ID]``, PBS ``-W depend=afterok:ID[:ID]``); the job IDs go to
``<output_dir>/jobs/jobs.json`` and the submission itself to ``jobs/submit-<scheduler>.sh``, which
resubmits the same chain by hand. ``fiberform status`` reads the queue state of recorded jobs.

Safety: every value that reaches a script is a validated number, a validated identifier (scene,
stage, partition, account and qos names) or a path quoted with :func:`shlex.quote` (paths in
directive lines must also be free of blanks and quotes); anything else is refused with exit 2
naming the option and the allowed form, before anything is written.
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

__all__ = [
    "SCHEDULERS",
    "BatchOptions",
    "JobRecord",
    "JobSpec",
    "QueueState",
    "annotate_status",
    "batch_options",
    "parse_time",
    "plan_jobs",
    "queue_states",
    "read_records",
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


def _path(p: Path, what: str, directive: bool = False) -> str:
    s = str(p)
    if any(c in s for c in "\n\r\0"):
        raise ConfigError(f"{what} {s!r}: a path with a newline cannot go into a batch script")
    if directive and not _DIRECTIVE_PATH.fullmatch(s):
        raise ConfigError(f"{what} {s!r}: a batch directive cannot carry this path (allowed characters: "
                          "letters, digits and _ . / + @ , = : -; no blanks, quotes or %); choose an "
                          "output_dir / working folder without them")
    return s


def _hms(seconds: int) -> str:
    return f"{seconds // 3600:02d}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}"


def _slurm_time(seconds: int) -> str:
    days, rest = divmod(seconds, 86400)
    return f"{days}-{_hms(rest)}"


def _directives(opts: BatchOptions, job_name: str, ntasks: int, out: str) -> list[str]:
    if opts.scheduler == "slurm":
        lines = [f"--job-name={job_name}", f"--ntasks={ntasks}", f"--output={out}",
                 "--kill-on-invalid-dep=yes"]
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
    if opts.time_s is not None:
        lines.append(f"-l walltime={_hms(opts.time_s)}")
    if opts.partition is not None:
        lines.append(f"-q {opts.partition}")
    if opts.account is not None:
        lines.append(f"-A {opts.account}")
    return [f"#PBS {d}" for d in lines]


def render_script(opts: BatchOptions, *, stage: str, scene_name: str, scene_path: Path, workdir: Path,
                  build_dir: Path, jobs_dir: Path, ntasks: int, ranks: int, force: bool,
                  needs: Sequence[str], python: Path) -> str:
    """The batch script of one stage (text); ``needs``: its upstream stages. Paths must be absolute."""
    for p in (scene_path, workdir, build_dir, jobs_dir, python):
        if not p.is_absolute():
            raise ConfigError(f"internal: {p} is not absolute")
    if not re.fullmatch(r"[a-z][a-z0-9-]{0,63}", stage) or not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,63}", scene_name):
        raise ConfigError(f"internal: stage {stage!r} or scene name {scene_name!r} is not an identifier")
    jobs_s = _path(jobs_dir, "output folder", directive=True)
    if opts.scheduler == "slurm":
        job_name, out_s = f"ff-{scene_name}-{stage}", f"{jobs_s}/{stage}-%j.out"
    else:  # PBS: names of at most 15 characters starting with a letter are portable
        job_name, out_s = f"{stage}-{scene_name}"[:15], f"{jobs_s}/{stage}.pbs.out"
    sub = SUBMIT[opts.scheduler]
    dep = ("--dependency=afterok:" if opts.scheduler == "slurm" else "-W depend=afterok:")
    cmd = [_path(python, "python"), "-m", "fiberform", stage, _path(scene_path, "SCENE"),
           "--build-dir", _path(build_dir, "--build-dir")]
    if force:
        cmd.append("--force")
    script = jobs_dir / f"{stage}.{SUFFIX[opts.scheduler]}"
    lines = [
        "#!/bin/bash",
        *_directives(opts, job_name, ntasks, out_s),
        f"# Stage {stage} of scene '{scene_name}', written by `fiberform submit` (fiberform {__version__}).",
        f"# The stage runs its programs itself: on {ranks} MPI rank(s) "
        + (f"(mpirun -np {ranks} inside this allocation)." if ranks > 1 else "(no mpirun)."),
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
        "exec " + " ".join(shlex.quote(a) for a in cmd),
        "",
    ]
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
        return {stage: JobRecord(stage, str(r["scheduler"]), str(r["job_id"]), str(r["script"]),
                                 str(r["submitted_utc"]), tuple(str(a) for a in r.get("after", ())))
                for stage, r in data["jobs"].items()}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"{path}: unreadable job records ({exc}); delete it to forget the jobs") from None


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
    out, err = _query(["squeue", "-h", "-t", "all", "-j", ",".join(ids), "-o", "%i|%T|%r"])
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

def plan_jobs(graph: StageGraph, opts: BatchOptions, *, start: str | None, stop: str | None,
              forced: set[str], workdir: Path, python: Path,
              states: Mapping[str, QueueState]) -> list[JobSpec]:
    """The jobs to submit: each selected stage that is not done (or forced, or downstream of a
    stage submitted here), in graph order, with its dependencies. Raises ConfigError (nothing
    written) for a stage already queued or running, an upstream stage that is neither done,
    selected nor queued, and --ntasks below a stage's ranks."""
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
        if opts.ntasks is not None and opts.ntasks < ranks:
            raise ConfigError(f"--ntasks {opts.ntasks}: stage {name} runs on {ranks} MPI ranks (its scene "
                              "section's ranks); ask for at least that many")
        ntasks = opts.ntasks or ranks
        if opts.nodes is not None and opts.nodes > ntasks:
            raise ConfigError(f"--nodes {opts.nodes}: more nodes than the {ntasks} task(s) of stage {name}")
        text = render_script(opts, stage=name, scene_name=ctx.scene.name, scene_path=scene_path,
                             workdir=workdir, build_dir=build, jobs_dir=jdir, ntasks=ntasks, ranks=ranks,
                             force=name in forced, needs=ups, python=python)
        specs.append(JobSpec(name, jdir / f"{name}.{SUFFIX[opts.scheduler]}", text, ntasks,
                             tuple(after_stages), tuple(after_jobs)))
        chosen.add(name)
    return specs


def _var(stage: str) -> str:
    return "job_" + stage.replace("-", "_")


def submit_command(opts: BatchOptions, script: Path, after: Sequence[str]) -> list[str]:
    """The argument list that submits ``script`` after the jobs ``after`` (IDs)."""
    if opts.scheduler == "slurm":
        return ["sbatch", "--parsable", *([f"--dependency=afterok:{':'.join(after)}"] if after else []),
                str(script)]
    return ["qsub", *(["-W", f"depend=afterok:{':'.join(after)}"] if after else []), str(script)]


def replay_script(opts: BatchOptions, specs: Sequence[JobSpec], workdir: Path) -> str:
    """``jobs/submit-<scheduler>.sh``: the same submission as shell commands, IDs in variables."""
    lines = ["#!/bin/bash",
             (f"# Resubmits the jobs of the last `fiberform submit --scheduler {opts.scheduler}` "
              "in the same order, with the same dependencies."),
             "set -euo pipefail", f"cd {shlex.quote(str(workdir))}"]
    for s in specs:
        after = [f"${{{_var(u)}}}" for u in s.after_stages] + list(s.after_jobs)
        if opts.scheduler == "slurm":
            dep = f" --dependency=afterok:{':'.join(after)}" if after else ""
            lines += [f"{_var(s.stage)}=$(sbatch --parsable{dep} {shlex.quote(str(s.script))})",
                      f"{_var(s.stage)}=${{{_var(s.stage)}%%;*}}"]
        else:
            dep = f" -W depend=afterok:{':'.join(after)}" if after else ""
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
        cmd = submit_command(opts, s.script, after)
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
