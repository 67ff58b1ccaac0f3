# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/laydown/motion_report.py on a hand-made two-fiber dump: the mass shares and speed
measures against values worked out by hand."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REPORT = ROOT / "bench" / "laydown" / "motion_report.py"


def _frame(step: int, rows: list[str], columns: str = "id mass x y z vx vy vz") -> str:
    """One LIGGGHTS dump frame of the given atom rows."""
    return (f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{len(rows)}\nITEM: BOX BOUNDS ff ff ff\n"
            f"0 1\n0 1\n0 1\nITEM: ATOMS {columns}\n" + "\n".join(rows) + "\n")


def _nodes(atoms: tuple[tuple[int, int, int], ...]) -> str:
    """fibers.nodes lines of two-node fibers: (atom ID, fiber ID, node index)."""
    return "".join(f"{a} {f} {k} 2 1e-5 1e-5 0 0 0 0 0 1 0 0 0\n" for a, f, k in atoms)


def test_motion_report_table(tmp_path: Path) -> None:
    work = tmp_path / "laydown" / "work"
    work.mkdir(parents=True)
    # fiber 1: atoms 1-2 (mass 1 each), fiber 2: atoms 3-4 (mass 3 each)
    (work / "fibers.nodes").write_text("# atom-ID fiber-ID node-index node-count ...\n"
                                       + _nodes(((1, 1, 0), (2, 1, 1), (3, 2, 0), (4, 2, 1))))
    # fiber 1 slides sideways at 5 mm/s (one node 4, the other 6: centre 5); fiber 2 sinks at 1 mm/s
    rows = ["1 1 0 0 1e-3 0.004 0 0", "2 1 0 0 2e-3 0.006 0 0",
            "3 3 0 0 3e-3 0 0 -0.001", "4 3 0 0 4e-3 0 0 -0.001"]
    (work / "traj.dump").write_text(_frame(2000, rows))
    out = subprocess.run([sys.executable, str(REPORT), "--run", str(tmp_path), "--top", "1"],
                         capture_output=True, text=True, check=True).stdout
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


def test_motion_report_paths(tmp_path: Path) -> None:
    """--paths: fiber 1 (mass 2) moves +10 um in x, then -4 um: path 14 um, displacement +6 um;
    fiber 2 (mass 6) sinks 3 um: path 3 um; fiber 3 is gone in the last frame (removed), so it is
    not listed. With --path-limit 5 the mass share above the limit is 2 / 8."""
    work = tmp_path / "laydown" / "work"
    work.mkdir(parents=True)
    (work / "fibers.nodes").write_text(_nodes(((1, 1, 0), (2, 1, 1), (3, 2, 0), (4, 2, 1), (5, 3, 0), (6, 3, 1))))

    def frame(step: int, dx1: float, dz2: float, with3: bool) -> str:
        rows = [f"1 1 {dx1} 0 1e-3 0 0 0", f"2 1 {1e-4 + dx1} 0 1e-3 0 0 0",
                f"3 3 0 0 {2e-3 + dz2} 0 0 0", f"4 3 1e-4 0 {2e-3 + dz2} 0 0 0"]
        rows += ["5 1 0 0 3e-3 0 0 0", "6 1 1e-4 0 3e-3 0 0 0"] if with3 else []
        return _frame(step, rows)

    (work / "traj.dump").write_text(frame(1000, 0.0, 0.0, True) + frame(2000, 0.0, 0.0, True)
                                    + frame(3000, 10e-6, -1e-6, True) + frame(4000, 6e-6, -3e-6, False))
    out = subprocess.run([sys.executable, str(REPORT), "--run",
                          str(tmp_path), "--paths", "2", "--path-limit", "5"],
                         capture_output=True, text=True, check=True).stdout
    assert "from step 2000 to 4000: 2 fibers present throughout; mass share with a path > 5 um: 0.250" in out, out
    rows = [ln for ln in out.splitlines() if ln.startswith("| 1 |") or ln.startswith("| 2 |")]
    assert rows == ["| 1 | 2000000000000.00 | 14.0 | 6.0, 0.0, 0.0 |",
                    "| 2 | 6000000000000.00 | 3.0 | 0.0, 0.0, -3.0 |"], out
    # --until 3: the frames up to 3 ms; fiber 3 is there throughout, fiber 1's path is 10 um
    out = subprocess.run([sys.executable, str(REPORT), "--run",
                          str(tmp_path), "--paths", "2", "--until", "3"],
                         capture_output=True, text=True, check=True).stdout
    assert "from step 2000 to 3000: 3 fibers present throughout" in out and "| 4.0 |" not in out, out
    assert "| 1 | 2000000000000.00 | 10.0 | 10.0, 0.0, 0.0 |" in out, out
    bad = subprocess.run([sys.executable, str(REPORT), "--run",
                          str(tmp_path), "--paths", "-1"], capture_output=True, text=True)
    assert bad.returncode == 2 and "--paths" in bad.stderr


def test_motion_report_thickness(tmp_path: Path) -> None:
    """--thickness: the stage's thickness above the fabric top (95th percentile of the fibers'
    upper surfaces minus the highest yarn surface). One yarn of radius 50 um along x at z = 0 (top
    50 um); fiber 1 (radius 10 um) at z = 100 um, fiber 2 at 200 um: upper surfaces 110, 110, 210,
    210 um, whose 95th percentile (linear) is 210 um: 160.0 um above the fabric."""
    import h5py
    import numpy as np

    out_dir = tmp_path / "out"
    (out_dir / "fibers").mkdir(parents=True)
    (out_dir / "fabric").mkdir(parents=True)
    with h5py.File(out_dir / "fibers" / "fibers.h5", "w") as f:
        f["fibers/offsets"] = np.array([0, 2, 4])
        f["fibers/radii"] = np.full((4, 4), 10e-6)
    with h5py.File(out_dir / "fabric" / "fabric.h5", "w") as f:
        f["yarns/points"] = np.array([[0.0, 0.0, 0.0], [1e-3, 0.0, 0.0]])
        f["yarns/offsets"] = np.array([0, 2])
        f["yarns/radius"] = np.array([50e-6])
    (tmp_path / "scene.yaml").write_text(
        "name: t\noutput_dir: out\nrun:\n  timestep_s: 1.0e-6\n  duration_s: 1.0e-3\n"
        "fibers:\n  count: 2\n  length_m: 1.0e-4\n  width_m: 2.0e-5\n  segments: 1\n"
        "  youngs_modulus_Pa: 1.0e10\n  shear_modulus_Pa: 4.0e9\n")
    work = tmp_path / "laydown" / "work"
    work.mkdir(parents=True)
    (work / "fibers.nodes").write_text(_nodes(((1, 1, 0), (2, 1, 1), (3, 2, 0), (4, 2, 1))))
    rows = ["1 1 0 0 1e-4 0 0 0 1 0", "2 1 1e-4 0 1e-4 0 0 0 1 1",
            "3 1 0 1e-4 2e-4 0 0 0 2 0", "4 1 1e-4 1e-4 2e-4 0 0 0 2 1"]
    (work / "traj.dump").write_text(_frame(1000, rows, "id mass x y z vx vy vz f_beam[1] f_beam[2]"))
    # (the scene's output_dir is relative to the working directory)
    out = subprocess.run([sys.executable, str(REPORT), "--run", str(tmp_path), "--thickness"],
                         capture_output=True, text=True, check=True, cwd=tmp_path).stdout
    assert "| 1.0 | 160.0 |" in out, out
