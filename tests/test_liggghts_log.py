# SPDX-License-Identifier: GPL-3.0-or-later
"""fiberform.liggghts_log: thermo tables and run times of a LIGGGHTS log."""
from __future__ import annotations

from fiberform.liggghts_log import run_loop_times, thermo_rows

LOG = """LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0)
Memory usage per processor = 6.5 Mbytes
    Step           Time           hsep
       0 0 1.2e-05
WARNING: something happened (src/x.cpp:1)
      10 1e-05 1.1e-05
Loop time of 0.01 on 1 procs for 10 steps with 10 atoms
Step Time hsep
      10 1e-05 1.1e-05
      20 2e-05 -3.5e-07
Loop time of 0.01 on 1 procs for 10 steps with 10 atoms
Total wall time: 0:00:00
"""


def test_rows_of_every_run_without_warnings_or_text() -> None:
    assert thermo_rows(LOG) == [
        [0.0, 0.0, 1.2e-05],
        [10.0, 1e-05, 1.1e-05],
        [10.0, 1e-05, 1.1e-05],
        [20.0, 2e-05, -3.5e-07],
    ]


def test_no_table() -> None:
    assert thermo_rows("LIGGGHTS (Version 3.8.0)\nERROR: bad input\n") == []


def test_loop_time_of_each_finished_run_at_its_last_step() -> None:
    """(last step, Loop time) per run; the warning inside the first table is skipped; a run
    killed before its Loop time line (the third) is not counted."""
    log = LOG.replace("Loop time of 0.01 on 1 procs for 10 steps", "Loop time of 2.5 on 1 procs for 10 steps", 1)
    log += "Step Time hsep\n      20 2e-05 0\n      25 2.5e-05 0\n"
    assert run_loop_times(log) == [(10, 2.5), (20, 0.01)]
    assert run_loop_times("LIGGGHTS (Version 3.8.0)\nERROR: bad input\n") == []
