# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/laydown/motion_report.py on a hand-made two-fiber dump: the mass shares and speed
measures against values worked out by hand."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_motion_report_table(tmp_path: Path) -> None:
    work = tmp_path / "laydown" / "work"
    work.mkdir(parents=True)
    # fiber 1: atoms 1-2 (mass 1 each), fiber 2: atoms 3-4 (mass 3 each)
    (work / "fibers.nodes").write_text(
        "# atom-ID fiber-ID node-index node-count ...\n"
        "1 1 0 2 1e-5 1e-5 0 0 0 0 0 1 0 0 0\n2 1 1 2 1e-5 1e-5 0 0 0 0 0 1 0 0 0\n"
        "3 2 0 2 1e-5 1e-5 0 0 0 0 0 1 0 0 0\n4 2 1 2 1e-5 1e-5 0 0 0 0 0 1 0 0 0\n")
    # fiber 1 slides sideways at 5 mm/s (one node 4, the other 6: centre 5); fiber 2 sinks at 1 mm/s
    rows = ["1 1 0 0 1e-3 0.004 0 0", "2 1 0 0 2e-3 0.006 0 0",
            "3 3 0 0 3e-3 0 0 -0.001", "4 3 0 0 4e-3 0 0 -0.001"]
    (work / "traj.dump").write_text(
        "ITEM: TIMESTEP\n2000\nITEM: NUMBER OF ATOMS\n4\nITEM: BOX BOUNDS ff ff ff\n0 1\n0 1\n0 1\n"
        "ITEM: ATOMS id mass x y z vx vy vz\n" + "\n".join(rows) + "\n")
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "laydown" / "motion_report.py"), "--run",
                          str(tmp_path), "--top", "1"], capture_output=True, text=True, check=True).stdout
    lines = [ln for ln in out.splitlines() if ln.startswith("| 2.0 ")]
    assert len(lines) == 1, out
    cells = [c.strip() for c in lines[0].strip("|").split("|")]
    # mass shares: fiber 1 carries 2/8 of the mass and moves 5 mm/s horizontally; fiber 2 1 mm/s
    assert cells[1] == "2" and cells[2] == "0.250 / 0.250 / 0.000", cells
    # 99 %-mass speeds: the fastest fiber's (5 mm/s) for |v|; fiber 2's 1 mm/s for |v_z|
    assert cells[3] == "5.00 / 1.00", cells
    # node heights 1..4 mm: percentiles 50 / 90 / 99 of (1, 2, 3, 4) mm
    assert cells[4] == "2500 / 3700 / 3970", cells
    assert "fiber 1 (2 nodes, centre 1500 um) | v = (5.00, 0.00, 0.00) mm/s" in out
