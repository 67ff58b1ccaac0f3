# SPDX-License-Identifier: GPL-3.0-or-later
"""fiberform.liggghts_log: thermo tables of a LIGGGHTS log."""
from __future__ import annotations

from fiberform.liggghts_log import thermo_rows

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
