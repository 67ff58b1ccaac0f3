# SPDX-License-Identifier: GPL-3.0-or-later
"""Reading LIGGGHTS output: the thermo table of a log file printed during ``run``, and the
frames of a ``dump custom`` text file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .errors import StageError

__all__ = ["Frame", "log_up_to_step", "read_dump", "run_loop_times", "thermo_rows", "total_wall_time"]


def total_wall_time(log: str) -> float:
    """Seconds of the last ``Total wall time: H:MM:SS`` line of a LIGGGHTS log (whole seconds; the
    wall time of a run started outside fiberform, e.g. by a batch script); 0 when there is none."""
    found = [line.split(":", 1)[1].strip() for line in log.splitlines() if line.startswith("Total wall time:")]
    if not found:
        return 0.0
    try:
        h, m, s = (int(x) for x in found[-1].split(":"))
    except ValueError:
        return 0.0
    return float(h * 3600 + m * 60 + s)


def _thermo_tables(log: str) -> list[tuple[list[list[float]], str | None]]:
    """Each thermo table of a LIGGGHTS log: its numeric rows (lines that are not all numbers are
    skipped) and the ``Loop time`` line that ended it (None: the run was cut off, or another
    header followed). A table starts after a header line beginning with ``Step``."""
    tables: list[tuple[list[list[float]], str | None]] = []
    rows: list[list[float]] | None = None
    for line in log.splitlines():
        words = line.split()
        if words[:1] == ["Step"]:
            if rows is not None:
                tables.append((rows, None))
            rows = []
            continue
        if rows is not None and line.startswith("Loop time"):
            tables.append((rows, line))
            rows = None
            continue
        if rows is not None and words:  # (blank lines: a resumed run's log after a killed part's)
            try:
                rows.append([float(w) for w in words])
            except ValueError:
                pass
    if rows is not None:
        tables.append((rows, None))
    return tables


def run_loop_times(log: str) -> list[tuple[int, float]]:
    """Each finished ``run`` of a LIGGGHTS log as (the step it ended at: the last row of its thermo
    table, which LIGGGHTS prints at a run's last step; its ``Loop time of T on ...`` in seconds). A
    run without a numeric thermo row, or a killed one (no Loop time line), is left out."""
    out: list[tuple[int, float]] = []
    for rows, loop in _thermo_tables(log):
        steps = [r[0] for r in rows if r]
        if loop is None or not steps:
            continue
        try:
            out.append((int(steps[-1]), float(loop.split()[3])))
        except (IndexError, ValueError):
            pass
    return out


def thermo_rows(log: str) -> list[list[float]]:
    """Numeric rows of every thermo table in a LIGGGHTS log, in order.

    A table starts after a header line beginning with ``Step`` (``Step Time ...`` for
    ``thermo_style custom step time ...``) and ends at ``Loop time``. Lines inside a table that
    are not all numbers (warnings, memory lines) are skipped. LIGGGHTS abbreviates long column
    names in the header, so callers name the columns themselves from their input script."""
    return [row for rows, _ in _thermo_tables(log) for row in rows]


def log_up_to_step(log: str, step: int) -> str:
    """The text of a LIGGGHTS log up to and including the last thermo row of a step <= ``step``
    (what a run resumed from the restart file of ``step`` keeps of a killed part: the lines after
    that row belong to steps it repeats); "" when there is no such row. Rows as thermo_rows reads
    them: the all-number lines after a ``Step`` header, before its ``Loop time``."""
    lines = log.splitlines(keepends=True)
    end, in_table = 0, False
    for k, line in enumerate(lines):
        words = line.split()
        if words[:1] == ["Step"]:
            in_table = True
            continue
        if line.startswith("Loop time"):
            in_table = False
            continue
        if not in_table or not words:
            continue
        try:
            row = [float(w) for w in words]
        except ValueError:
            continue
        if row[0] > step:
            break
        end = k + 1
    return "".join(lines[:end])


@dataclass(frozen=True)
class Frame:
    """One snapshot of a LAMMPS/LIGGGHTS text dump, rows sorted by atom id."""

    step: int
    ids: npt.NDArray[np.int64]
    columns: dict[str, npt.NDArray[np.float64]]


def _parse_frame(lines: list[str], i: int) -> tuple[Frame, int]:
    """The frame whose ``ITEM: TIMESTEP`` line is ``lines[i]``, and the index of the line after it.
    Raises IndexError or ValueError for a malformed or cut-off frame."""
    step = int(lines[i + 1])
    if not lines[i + 2].startswith("ITEM: NUMBER OF ATOMS"):
        raise ValueError("NUMBER OF ATOMS expected")
    n = int(lines[i + 3])
    j = i + 4
    while not lines[j].startswith("ITEM: ATOMS"):
        j += 1
    names = lines[j].split()[2:]
    rows = np.array([[float(x) for x in lines[j + 1 + k].split()] for k in range(n)])
    rows = rows.reshape(n, len(names))
    order = np.argsort(rows[:, names.index("id")], kind="stable")
    rows = rows[order]
    cols = {name: rows[:, c] for c, name in enumerate(names)}
    ids = cols.pop("id").astype(np.int64)
    return Frame(step, ids, cols), j + 1 + n


def read_dump(path: Path) -> list[Frame]:
    """Read every frame of a ``dump custom`` text file."""
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise StageError(f"cannot read dump {path}: {exc.strerror}") from None
    frames: list[Frame] = []
    i = 0
    try:
        while i < len(lines):
            if not lines[i].startswith("ITEM: TIMESTEP"):
                i += 1
                continue
            frame, i = _parse_frame(lines, i)
            frames.append(frame)
    except (IndexError, ValueError) as exc:
        raise StageError(f"malformed dump {path} near line {i + 1}: {exc}") from None
    if not frames:
        raise StageError(f"dump {path} holds no frame")
    return frames


def dump_frame(text: str, pos: int) -> Frame:
    """The frame whose ``ITEM: TIMESTEP`` header starts at character ``pos`` of a dump file's
    text (only that frame's lines are split)."""
    end = text.find("ITEM: TIMESTEP", pos + 1)
    lines = text[pos:end if end >= 0 else len(text)].splitlines()
    try:
        return _parse_frame(lines, 0)[0]
    except (IndexError, ValueError) as exc:
        raise StageError(f"malformed dump frame at character {pos}: {exc}") from None
