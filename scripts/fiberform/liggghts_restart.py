# SPDX-License-Identifier: GPL-3.0-or-later
"""Restart files of a fiberdem (LIGGGHTS) stage run and continuing a killed run from them.

A stage run that writes restart files ``<stem>.<step>.restart`` (LIGGGHTS ``restart N
<stem>.*.restart``) in its working folder, a snapshot dump (``traj.dump``) and a log
(``log.fiberdem``) can be continued after a kill (``fiberform <stage> SCENE --resume``):

- :func:`start_fresh` records the input hashes of a fresh run (RESUME_STATE) beside its files;
- :func:`resume_point` finds the last restart file that is certainly complete (the run wrote a
  snapshot after it, or an earlier resume started from it) of a run of the same inputs;
- :func:`cut_back` cuts the snapshots back to that step, removes the later restart files, counts the
  killed part's fiberdem time up to the step (EARLIER_WALL) and returns the killed part's log;
- :func:`record_prepared` / :func:`prepared_step` record the step the run starts from (PREPARED_STEP,
  ``null``: a fresh run), which :func:`earlier_wall` and the stages' collect read.

Used by the stages laydown and press (docs/stages/laydown.md and press.md, "Resuming").
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from .errors import ConfigError, StageError
from .liggghts_log import run_loop_times
from .provenance import atomic_write_text

__all__ = [
    "EARLIER_LOG", "EARLIER_WALL", "PREPARED_STEP", "RESTART_EXT", "RESUME_STATE", "cut_back",
    "dump_snapshots", "dump_steps", "earlier_wall", "prepared_step", "read_text_if", "record_earlier_wall",
    "record_prepared", "recorded_inputs", "refuse_to_discard", "restart_interval_steps", "restart_name", "restart_steps",
    "resume_point", "run_log", "run_log_parts", "same_run", "start_fresh", "start_over",
]

RESTART_EXT = "restart"
#: the killed parts' log text a resumed run keeps (what each stage needs of it)
EARLIER_LOG = "log.earlier"
#: the input hashes of the run whose restart files the working folder holds
RESUME_STATE = "resume.json"
#: the fiberdem time of the parts before a resume, up to the restart step it continued from
EARLIER_WALL = "wall.earlier.json"
#: written by a stage's prepare: the step the run starts from (null: a fresh run)
PREPARED_STEP = "prepared-step.json"
_SNAPSHOT = re.compile(r"^ITEM: TIMESTEP\n(\d+)\n", re.M)


def read_text_if(path: Path) -> str:
    """The text of ``path`` ("" when it does not exist; undecodable bytes replaced)."""
    return path.read_text(errors="replace") if path.is_file() else ""


def run_log_parts(work: Path, log_name: str) -> tuple[str, str]:
    """A run's log along its path in two parts: that of the killed parts before the restart step it
    resumed from (EARLIER_LOG; "" for a run from step 0) and this part's (``log_name``)."""
    return read_text_if(work / EARLIER_LOG), read_text_if(work / log_name)


def run_log(work: Path, log_name: str) -> str:
    """A run's whole log along its path (:func:`run_log_parts` joined)."""
    return "".join(run_log_parts(work, log_name))


def restart_interval_steps(interval_s: float, output_interval_s: float, steps_per_output: int) -> int:
    """Steps between restart files: ``interval_s`` rounded to a whole number (at least one) of the
    output intervals of ``steps_per_output`` steps each, so that a resume starts at a snapshot and
    at a run chunk's end; 0 (no restart files) when ``interval_s`` <= 0."""
    if interval_s <= 0.0:
        return 0
    return steps_per_output * max(1, round(interval_s / output_interval_s))


def restart_name(stem: str, step: int) -> str:
    """The restart file of ``step``: ``<stem>.<step>.restart``."""
    return f"{stem}.{int(step)}.{RESTART_EXT}"


def restart_steps(work: Path, stem: str) -> list[int]:
    """Steps of the restart files ``<stem>.<step>.restart`` in the working folder, ascending."""
    pattern = re.compile(re.escape(stem) + r"\.(\d+)\." + RESTART_EXT)
    out = []
    for p in work.glob(f"{stem}.*.{RESTART_EXT}"):
        m = pattern.fullmatch(p.name)
        if m:
            out.append(int(m.group(1)))
    return sorted(out)


def dump_snapshots(text: str) -> list[tuple[int, int]]:
    """(step, offset of its header) of every snapshot in the text of a LIGGGHTS dump file, in file
    order; a header cut off by a kill (step line incomplete) is not a snapshot."""
    return [(int(m.group(1)), m.start()) for m in _SNAPSHOT.finditer(text)]


def dump_steps(path: Path) -> list[int]:
    """Steps of the snapshots in a LIGGGHTS dump file (in file order)."""
    if not path.is_file():
        return []
    return [step for step, _ in dump_snapshots(path.read_text(errors="replace"))]


def start_fresh(work: Path, hashes: Mapping[str, str]) -> None:
    """Record the input hashes of a fresh run in its working folder (RESUME_STATE)."""
    atomic_write_text(work / RESUME_STATE, json.dumps(dict(hashes), sort_keys=True))


def recorded_inputs(work: Path) -> Any:
    """The input hashes the working folder's run was started with (RESUME_STATE, a dict as
    :func:`start_fresh` writes it), None when there is no readable record."""
    try:
        return json.loads((work / RESUME_STATE).read_text())
    except (OSError, ValueError):
        return None


def same_run(work: Path, hashes: Mapping[str, str], legacy: Mapping[str, str] | None = None) -> bool:
    """The working folder's restart files belong to a run of these inputs: RESUME_STATE equals
    ``hashes`` (the stage's restart identity, :meth:`fiberform.stages.Stage.restart_identity`) or,
    for a folder written before that identity existed, ``legacy`` (the full input hashes)."""
    old = recorded_inputs(work)
    return old is not None and (old == dict(hashes) or (legacy is not None and old == dict(legacy)))


def refuse_to_discard(work: Path, stem: str, hashes: Mapping[str, str], command: str,
                      legacy: Mapping[str, str] | None = None) -> None:
    """Before a run that would start over (neither ``--resume`` nor ``--force``): ConfigError (exit
    status 2, nothing removed) when the working folder holds restart files of a killed run of the
    same inputs (:func:`same_run`): a plain rerun must not delete hours of work. Restart files of
    other inputs cannot be resumed and go as before. ``command``: how the stage is called
    (``fiberform laydown SCENE``), for the message."""
    steps = restart_steps(work, stem) if work.is_dir() else []
    if steps and same_run(work, hashes, legacy):
        raise ConfigError(f"{work} holds restart files to step {steps[-1]} of a killed run of these inputs: "
                          f"`{command} --resume` continues it, `{command} --force` starts over and removes them")


def start_over(work: Path, stem: str, hashes: Mapping[str, str], command: str, resume_asked: bool,
               why_not: str = "no snapshot after it, no resume from it") -> None:
    """A fresh working folder for a run from step 0 (RESUME_STATE records ``hashes``). Restart files
    of an earlier run in it are removed, saying so on standard error: ``--resume`` was asked but
    none of them is certainly complete and usable (``why_not``), ``--force`` was given, or they
    belong to other inputs (:func:`refuse_to_discard` refuses the case where they are of the same
    inputs and neither option was given)."""
    import shutil
    import sys

    earlier = restart_steps(work, stem) if work.is_dir() else []
    if earlier:
        if resume_asked:
            why = f"none of them is certainly complete ({why_not})"
        else:
            why = "--force starts over" if same_run(work, hashes) else "they are of other inputs"
        print(f"{command}: starting over: the restart files of an earlier run in {work} (steps "
              f"{earlier[0]}-{earlier[-1]}) are removed; {why}", file=sys.stderr)
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    start_fresh(work, hashes)


def record_prepared(work: Path, step: int | None) -> None:
    """PREPARED_STEP: the step the run starts from (None: a fresh run)."""
    atomic_write_text(work / PREPARED_STEP, json.dumps({"resume_step": step}) + "\n")


def prepared_step(work: Path) -> int | None:
    """The step the prepared run starts from (PREPARED_STEP; None: a fresh run or not recorded)."""
    try:
        step = json.loads((work / PREPARED_STEP).read_text())["resume_step"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return int(step) if isinstance(step, int) else None


def resume_point(work: Path, hashes: Mapping[str, str], stem: str, traj: str,
                 usable: Callable[[int], bool] = lambda step: True,
                 legacy: Mapping[str, str] | None = None) -> int | None:
    """The step to resume a killed run from: the last restart file ``<stem>.<step>.restart`` that
    is certainly complete and ``usable``, if the working folder belongs to the same inputs
    (:func:`same_run`); None: nothing to resume (start over). Complete: the run wrote a snapshot
    (dump ``traj``) after it, or an earlier resume started from it (PREPARED_STEP; a resumed run
    killed before its first new snapshot must not lose that restart file). Raises StageError when
    the folder holds another run's files."""
    if recorded_inputs(work) is None:
        return None
    if not same_run(work, hashes, legacy):
        raise StageError(f"{work}: the restart files belong to other inputs (scene, upstream "
                         "products or fiberdem changed); run without --resume to start over")
    done = max(dump_steps(work / traj), default=-1)
    resumed = prepared_step(work)
    complete = max(done - 1, resumed if resumed is not None else -1)
    good = [s for s in restart_steps(work, stem) if s <= complete and usable(s)]
    return good[-1] if good else None


def cut_back(work: Path, step: int, stem: str, traj: str, log_name: str, dump_text: str | None = None,
             log_text: str | None = None) -> str:
    """Cut the killed run back to the restart step ``step``: the snapshots of the dump ``traj`` from
    that step on go (the resumed run writes that step's again and everything after it), later
    restart files go, and the killed part's fiberdem time up to the step is counted (EARLIER_WALL).
    ``dump_text``, ``log_text``: the dump's and the log's text when the caller has read them already.
    Returns the killed part's log text (``log_name``)."""
    dump = work / traj
    if dump_text is None:
        dump_text = read_text_if(dump)
    current = read_text_if(work / log_name) if log_text is None else log_text
    keep = next((pos for s, pos in dump_snapshots(dump_text) if s >= step), len(dump_text))
    record_earlier_wall(work, step, current)
    atomic_write_text(dump, dump_text[:keep])
    for s in restart_steps(work, stem):
        if s > step:
            (work / restart_name(stem, s)).unlink()
    return current


def record_earlier_wall(work: Path, step: int, log: str) -> None:
    """EARLIER_WALL: the fiberdem time spent on the way to the restart step ``step`` a resume
    continues from: the Loop times of the killed part's runs (its log text ``log``) that ended at or
    before ``step`` (its work after the restart step is redone, so not counted) plus what
    EARLIER_WALL said of the parts before it. ``None`` when a resume goes back behind the step an
    earlier resume counted to (that count would include work now redone)."""
    path = work / EARLIER_WALL
    prev: dict[str, Any] = json.loads(path.read_text()) if path.is_file() else {"up_to_step": 0, "wall_s": 0.0}
    runs = run_loop_times(log)
    if prev["wall_s"] is None or int(prev["up_to_step"]) > step:
        wall = None
    else:
        wall = float(prev["wall_s"]) + sum(t for end, t in runs if int(prev["up_to_step"]) < end <= step)
    atomic_write_text(path, json.dumps({"up_to_step": step, "wall_s": wall}) + "\n")


def earlier_wall(work: Path) -> float | None:
    """The fiberdem time of the parts before this resumed run (EARLIER_WALL), 0 for a run from step
    0, ``None`` when unknown (:func:`record_earlier_wall`)."""
    resumed = prepared_step(work)
    if resumed is None:
        return 0.0
    path = work / EARLIER_WALL
    if not path.is_file():
        return None  # a run resumed before fiberform recorded it
    rec = json.loads(path.read_text())
    return None if rec["wall_s"] is None or int(rec["up_to_step"]) != int(resumed) else float(rec["wall_s"])
