# SPDX-License-Identifier: GPL-3.0-or-later
"""fiberform.liggghts_log: thermo tables and run times of a LIGGGHTS log."""
from __future__ import annotations

from fiberform.liggghts_log import log_up_to_step, run_loop_times, thermo_rows

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


def test_log_up_to_a_restart_step_keeps_the_rows_to_it() -> None:
    """What a resumed run keeps of a killed part's log: every line up to the last thermo row of a
    step at or before the restart step; rows after it (and a row cut off by the kill) go."""
    killed = LOG.replace("Total wall time: 0:00:00\n", "Step Time hsep\n      20 2e-05 -3.5e-07\n      30 3e-05 -4e-07\n   4")
    kept = log_up_to_step(killed, 20)
    assert [r[0] for r in thermo_rows(kept)] == [0.0, 10.0, 10.0, 20.0, 20.0]
    assert kept.endswith("      20 2e-05 -3.5e-07\n")
    assert log_up_to_step(killed, 5) == LOG[:LOG.index("WARNING")]  # the rows of step 0 only
    assert log_up_to_step("no table\n", 10) == ""
    # the resumed run's own log follows the kept text: its rows are read after those kept, the
    # blank lines between (inside the killed part's open table) are no rows
    resumed = "LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0)\n\nStep Time hsep\n      20 2e-05 -3.5e-07\n      40 4e-05 -5e-07\nLoop time of 0.01 on 1 procs for 20 steps with 10 atoms\n"
    assert [r[0] for r in thermo_rows(kept + resumed)] == [0.0, 10.0, 10.0, 20.0, 20.0, 20.0, 40.0]
