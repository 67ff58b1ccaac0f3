# SPDX-License-Identifier: GPL-3.0-or-later
"""Reading LIGGGHTS log files: the thermo table printed during ``run``."""

from __future__ import annotations

__all__ = ["thermo_rows"]


def thermo_rows(log: str) -> list[list[float]]:
    """Numeric rows of every thermo table in a LIGGGHTS log, in order.

    A table starts after a header line beginning with ``Step`` (``Step Time ...`` for
    ``thermo_style custom step time ...``) and ends at ``Loop time``. Lines inside a table that
    are not all numbers (warnings, memory lines) are skipped. LIGGGHTS abbreviates long column
    names in the header, so callers name the columns themselves from their input script."""
    rows: list[list[float]] = []
    inside = False
    for line in log.splitlines():
        words = line.split()
        if words[:1] == ["Step"]:
            inside = True
            continue
        if inside and line.startswith("Loop time"):
            inside = False
            continue
        if inside:
            try:
                rows.append([float(w) for w in words])
            except ValueError:
                pass
    return rows
