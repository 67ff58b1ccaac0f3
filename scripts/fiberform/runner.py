# SPDX-License-Identifier: GPL-3.0-or-later
"""The one place where fiberform starts external programs (fiberdem, OpenFOAM tools, mpirun).

* The command is a list of arguments; no shell is ever involved.
* ``ranks > 1`` prefixes ``mpirun -np N``; more ranks than cores is refused unless the caller
  passes ``oversubscribe=True`` (busy-waiting oversubscribed ranks double the run time).
* The environment gets ``OMPI_ALLOW_RUN_AS_ROOT=1`` and ``OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1`` (so
  mpirun works as root without ``--allow-run-as-root`` on the command line),
  ``WM_PROJECT_DIR=/usr/share/openfoam`` (every OpenFOAM binary needs it) and
  ``OMPI_MCA_mpi_yield_when_idle=1`` (:data:`MPI_ENVIRONMENT`), each unless already set.
* The program leads a new session (so that it and its ranks can be ended together) and gets our
  niceness for that session's scheduler autogroup (:func:`pass_on_niceness`).
* Standard output and error are streamed, merged, to the log file (``log.<tool>`` in the stage
  folder, as OpenFOAM's ``runApplication`` does).
* On a terminal, a rich progress bar shows the fraction reported by an optional ``progress``
  callback that reads log lines (see :func:`liggghts_progress`, :func:`openfoam_progress`).
  Elsewhere (a log file, a batch job, a sweep's variant log) the same fraction is written to
  standard error as a plain line every :data:`PROGRESS_EVERY_S` seconds (environment variable
  ``FIBERFORM_PROGRESS_EVERY_S``), with the time taken and the time left at the rate so far
  (:class:`ProgressLines`).
* A non-zero exit raises :class:`~fiberform.errors.RunError` with the command, the exit status and
  the last lines of the log.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rich.console import Console
from rich.progress import (
    BarColumn,
    Progress,
    SpinnerColumn,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from .errors import ConfigError, RunError

__all__ = [
    "MPIRUN_OPTIONS",
    "MPI_ENVIRONMENT",
    "OPENFOAM_PROJECT_DIR",
    "Program",
    "PROGRESS_EVERY_S",
    "ProgressLines",
    "ProgressParser",
    "RunResult",
    "build_command",
    "build_env",
    "mpmd_command",
    "capture",
    "liggghts_progress",
    "openfoam_progress",
    "pass_on_niceness",
    "run",
]

OPENFOAM_PROJECT_DIR = "/usr/share/openfoam"

#: Reads one log line; returns the fraction done (0..1) or None if the line says nothing about it.
ProgressParser = Callable[[str], float | None]


@dataclass(frozen=True)
class Program:
    """One external program line of a stage: ``argv`` run in ``cwd`` on ``ranks`` MPI ranks
    (``mpirun -np`` when > 1), standard output and error to ``log`` (absolute paths). :func:`run`
    starts it locally; a batch script carries it as a shell line (fiberform.executors)."""

    argv: tuple[str, ...]
    ranks: int
    cwd: Path
    log: Path
    #: progress from the log lines, for the local progress bar only
    progress: ProgressParser | None = field(default=None, compare=False)


@dataclass(frozen=True)
class RunResult:
    """What :func:`run` returns for a successful run."""

    cmd: tuple[str, ...]
    returncode: int
    log: Path
    elapsed_s: float


def _cores() -> int:
    return os.cpu_count() or 1


#: mpirun's options of every local run: no binding of ranks to cores. Open MPI binds rank i of
#: every mpirun to core i by default (with at most 2 ranks per job), so two jobs side by side
#: (sweep --jobs, campaign points at once) put both jobs' busy rank 0 on core 0. Measured on the
#: S3 sheet (one contact cluster: one busy rank per job, docs/bench/laydown.md "Two points side by
#: side"): two 2-rank probes at once each took 38 s against 18 s alone. Batch scripts
#: (fiberform.executors) keep the scheduler's binding within their allocation.
MPIRUN_OPTIONS = ("--bind-to", "none")


def build_command(cmd: Sequence[str], ranks: int = 1, oversubscribe: bool = False) -> list[str]:
    """The argument list actually started: ``cmd`` itself, or ``mpirun --bind-to none -np N`` +
    ``cmd`` (:data:`MPIRUN_OPTIONS`)."""
    if isinstance(cmd, (str, bytes)) or not cmd:
        raise ConfigError("a command is a non-empty list of arguments, not a string")
    if not all(isinstance(a, str) for a in cmd):
        raise ConfigError(f"every argument must be a str: {list(cmd)!r}")
    if isinstance(ranks, bool) or not isinstance(ranks, int) or ranks < 1:
        raise ConfigError(f"ranks must be an integer >= 1, got {ranks!r}")
    cores = _cores()
    if ranks > cores and not oversubscribe:
        raise ConfigError(
            f"{ranks} MPI ranks requested but this machine has {cores} cores; "
            "lower run.ranks or pass --oversubscribe"
        )
    if ranks == 1:
        return list(cmd)
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        raise ConfigError("mpirun not found on PATH (install openmpi-bin) but ranks > 1")
    prefix = [mpirun, *MPIRUN_OPTIONS, "-np", str(ranks)]
    if ranks > cores:
        prefix.append("--oversubscribe")
    return prefix + list(cmd)


def mpmd_command(parts: Sequence[tuple[Sequence[str], int]], oversubscribe: bool = False) -> list[str]:
    """One ``mpirun`` starting several programs (MPMD): ``mpirun -np A cmd1 : -np B cmd2``; the
    total ranks are checked against the cores as in :func:`build_command`. Run the result with
    ``ranks=1``."""
    total = 0
    out: list[str] = []
    for cmd, ranks in parts:
        build_command(cmd, 1)  # argument checks
        if isinstance(ranks, bool) or not isinstance(ranks, int) or ranks < 1:
            raise ConfigError(f"ranks must be an integer >= 1, got {ranks!r}")
        total += ranks
        out += ([":"] if out else []) + ["-np", str(ranks), *cmd]
    if total > _cores() and not oversubscribe:
        raise ConfigError(f"{total} MPI ranks requested in total but this machine has {_cores()} "
                          "cores; lower the ranks or pass --oversubscribe")
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        raise ConfigError("mpirun not found on PATH (install openmpi-bin)")
    return [mpirun, *MPIRUN_OPTIONS, *(["--oversubscribe"] if total > _cores() else []), *out]


#: Open MPI settings of every local run, unless the caller's environment sets them: a rank that
#: waits for a message yields its core (``sched_yield``) instead of polling flat out. Open MPI only
#: turns this on by itself when one ``mpirun`` has more ranks than cores; two 2-rank jobs side by
#: side on 2 cores (sweep --jobs, campaign --points-at-once) are not oversubscribed in its eyes,
#: and each job's waiting ranks then took the cores from the ranks they wait for. Measured on the
#: formed S3 sheet with the campaign's solver settings (docs/bench/laydown.md "Two points side by
#: side"): two 2-rank probes at once did 0.33 times the work of one alone polling, 1.71 times
#: yielding; one job alone the same within noise. Batch scripts (fiberform.executors) do not set
#: it: there the scheduler gives each job its own cores.
MPI_ENVIRONMENT = {"OMPI_MCA_mpi_yield_when_idle": "1"}


def build_env(env_extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment of a run: ours plus Open MPI's root permission, :data:`MPI_ENVIRONMENT`
    (unless set) and WM_PROJECT_DIR."""
    env = dict(os.environ)
    env["OMPI_ALLOW_RUN_AS_ROOT"] = "1"
    env["OMPI_ALLOW_RUN_AS_ROOT_CONFIRM"] = "1"
    env.setdefault("WM_PROJECT_DIR", OPENFOAM_PROJECT_DIR)
    for key, value in MPI_ENVIRONMENT.items():
        env.setdefault(key, value)
    for key, value in (env_extra or {}).items():
        if not isinstance(key, str) or not isinstance(value, str) or "=" in key or not key:
            raise ConfigError(f"bad environment entry {key!r}={value!r}")
        env[key] = value
    return env


#: seconds between two plain progress lines when standard error is not a terminal (default of
#: the environment variable ``FIBERFORM_PROGRESS_EVERY_S``)
PROGRESS_EVERY_S = 300.0


def _duration(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600} h {s % 3600 // 60:02d} min" if s >= 3600 else f"{s // 60} min {s % 60:02d} s"


class ProgressLines:
    """Plain progress lines for a log (standard error not a terminal): at most one per ``every_s``
    seconds, and only when the fraction has moved, e.g. ``fiberdem: 42.0 % after 12 min 05 s,
    about 16 min 40 s left``. The time left extrapolates the rate since the first fraction seen
    (a resumed run starts at its restart's fraction). ``clock``: for tests."""

    def __init__(self, name: str, write: Callable[[str], None], every_s: float | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if every_s is None:
            env = os.environ.get("FIBERFORM_PROGRESS_EVERY_S", "")
            try:
                every_s = float(env) if env else PROGRESS_EVERY_S
            except ValueError:
                write(f"FIBERFORM_PROGRESS_EVERY_S={env!r} is not a number of seconds: progress every "
                      f"{PROGRESS_EVERY_S:g} s")
                every_s = PROGRESS_EVERY_S
        self.name, self.write, self.every_s, self.clock = name, write, max(0.0, every_s), clock
        self.start = clock()
        self.first: tuple[float, float] | None = None  # (time, fraction) of the first fraction seen
        self.last_t, self.last_frac = self.start, -1.0

    def update(self, frac: float) -> None:
        now = self.clock()
        if self.first is None:
            self.first = (now, frac)
        if now - self.last_t < self.every_s or frac <= self.last_frac:
            return
        self.last_t, self.last_frac = now, frac
        line = f"{self.name}: {100.0 * frac:.1f} % after {_duration(now - self.start)}"
        t0, f0 = self.first
        if frac > f0 and now > t0:
            line += f", about {_duration((1.0 - frac) * (now - t0) / (frac - f0))} left"
        self.write(line)


def _progress_display(description: str, console: Console) -> Progress:
    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TaskProgressColumn(),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    )


def run(
    cmd: Sequence[str],
    log: Path,
    cwd: Path | None = None,
    env_extra: Mapping[str, str] | None = None,
    ranks: int = 1,
    progress: ProgressParser | None = None,
    *,
    oversubscribe: bool = False,
    description: str | None = None,
    tail_lines: int = 30,
    timeout_s: float | None = None,
    show_progress: bool | None = None,
) -> RunResult:
    """Run ``cmd`` (on ``ranks`` MPI ranks), stream its output into ``log``, raise on failure.

    ``log`` is relative to ``cwd`` if not absolute. ``show_progress`` defaults to "stderr is a
    terminal"; without it, a ``progress`` parser's fraction goes to standard error as plain lines
    (:class:`ProgressLines`). ``timeout_s`` ends the whole process group when exceeded.
    """
    full = build_command(cmd, ranks, oversubscribe)
    env = build_env(env_extra)
    workdir = Path(cwd) if cwd is not None else Path.cwd()
    log_path = log if log.is_absolute() else workdir / log
    if "/" not in full[0] and shutil.which(full[0], path=env.get("PATH")) is None:
        raise RunError(
            full, None, str(log_path), [], reason=f"program {full[0]!r} not found on PATH"
        )
    console = Console(stderr=True)
    if show_progress is None:
        show_progress = console.is_terminal
    tail: deque[str] = deque(maxlen=tail_lines)
    start = time.monotonic()
    log_path.parent.mkdir(parents=True, exist_ok=True)
    # line-buffered: the log follows a long run (progress, post-mortem of a killed one)
    with open(log_path, "w", encoding="utf-8", errors="replace", buffering=1) as logf:
        try:
            proc = subprocess.Popen(
                full,
                cwd=workdir,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
                errors="replace",
                bufsize=1,
                start_new_session=True,
            )
        except OSError as exc:
            raise RunError(full, None, str(log_path), [], reason=str(exc)) from None
        pass_on_niceness(proc.pid)
        name = description or Path(cmd[0]).name
        display = _progress_display(name, console)
        task = display.add_task(name, total=1.0 if progress else None)
        parser = progress
        done = 0.0
        lines = None if show_progress or progress is None else ProgressLines(
            name, lambda text: print(text, file=sys.stderr, flush=True))
        timed_out = threading.Event()

        def on_timeout() -> None:
            timed_out.set()
            _kill(proc)

        timer = threading.Timer(timeout_s, on_timeout) if timeout_s is not None else None
        try:
            if timer is not None:
                timer.daemon = True
                timer.start()
            if show_progress:
                display.start()
            assert proc.stdout is not None
            for line in proc.stdout:
                logf.write(line)
                text = line.rstrip("\n")
                tail.append(text)
                if parser is not None:
                    try:
                        frac = parser(text)
                    except Exception:  # a broken parser must not break the run
                        parser = None
                        frac = None
                    if frac is not None and frac > done:
                        done = min(1.0, frac)
                        display.update(task, completed=done)
                        if lines is not None:
                            lines.update(done)
            returncode = proc.wait()
        except BaseException:
            _kill(proc)
            proc.wait()
            raise
        finally:
            if timer is not None:
                timer.cancel()
            if show_progress:
                display.stop()
    elapsed = time.monotonic() - start
    if timed_out.is_set():
        raise RunError(
            full, returncode, str(log_path), list(tail), reason=f"timed out after {timeout_s:g} s"
        )
    if returncode != 0:
        raise RunError(full, returncode, str(log_path), list(tail))
    return RunResult(tuple(full), returncode, log_path, elapsed)


def pass_on_niceness(pid: int) -> None:
    """Give the session that ``pid`` leads our niceness. A program started in a new session gets its
    own scheduler autogroup on Linux (``kernel.sched_autogroup_enabled``), and autogroups share the
    cores by their own nice value, not their processes': without this, ``nice fiberform run ...``
    would not lower the programs' share against other sessions (measured in session 25: four
    simpleFoam runs, two of them started under ``nice -n 19``, each took half a core). Written to
    ``/proc/PID/autogroup`` right after the start (the session's later processes share it); nothing
    is done at niceness 0 or where autogroups do not exist."""
    nice = os.getpriority(os.PRIO_PROCESS, 0)
    if nice <= 0:
        return
    try:
        Path(f"/proc/{pid}/autogroup").write_text(f"{nice}\n")
    except OSError:
        pass  # no autogroups here (or the process has already ended): nice values apply as they are


def _kill(proc: subprocess.Popen[str]) -> None:
    """End the process and its children (mpirun ranks): it leads its own session."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def capture(cmd: Sequence[str], cwd: Path | None = None, timeout_s: float = 10.0) -> str | None:
    """Standard output of a short query (``git rev-parse``, ``dpkg-query``), or None if the
    program is missing, fails or times out. For runs with logs use :func:`run`."""
    if isinstance(cmd, (str, bytes)) or not cmd:
        raise ConfigError("a command is a non-empty list of arguments, not a string")
    try:
        done = subprocess.run(
            list(cmd),
            cwd=cwd,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            errors="replace",
            timeout=timeout_s,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout if done.returncode == 0 else None


def liggghts_progress(total_steps: int) -> ProgressParser:
    """Progress from LIGGGHTS thermo lines: rows of numbers whose first column is the step."""

    def parse(line: str) -> float | None:
        parts = line.split()
        if not parts or not parts[0].isdigit():
            return None
        try:
            [float(p) for p in parts[1:]]
        except ValueError:
            return None
        return int(parts[0]) / total_steps if total_steps > 0 else None

    return parse


_FOAM_TIME = re.compile(r"^Time = ([-+0-9.eE]+)\s*$")


def openfoam_progress(start_time: float, end_time: float) -> ProgressParser:
    """Progress from OpenFOAM solver logs (lines ``Time = <t>``)."""
    span = end_time - start_time

    def parse(line: str) -> float | None:
        m = _FOAM_TIME.match(line)
        if m is None or span <= 0:
            return None
        return (float(m.group(1)) - start_time) / span

    return parse
