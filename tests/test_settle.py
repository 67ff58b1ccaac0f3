# SPDX-License-Identifier: GPL-3.0-or-later
"""The lay-down's settle criterion at scale (issue 10, deliver 5): fix fiber/settle ``V M
measure fiber mass_fraction q`` counts consecutive checks at which the fibers carrying
the fraction q of the mass move slower than V (physics/settle.h; unit test test_settle.cpp).

Ten fibers of 0.4 mm at rest (no gravity, no flow, nothing touching) and one fine of 0.1 mm
(2.4 % of the mass) flying at 50 mm/s, or the whole set sinking together at 3 mm/s; threshold
V = 1 mm/s, a check every 10 steps of 1e-6 s, 200 steps (20 checks):

- q = 1 (every fiber, the former criterion): the fine keeps the counter at 0;
- q = 0.95: the fine is ignored, the counter reaches 20, the number of checks;
- q = 0.95 with the whole set sinking: still 0 (a sinking sheet is not settled);
- the same on 2 MPI ranks (the per-fiber sums are reduced over ranks: five fibers span both sub-domains, x = 0.6 mm).
Expected values are the counts above, from the set-up (not from a run)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from fiberform.fiber_io import Fiber, quat_from_frames, write_fibers_liggghts

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beam_cases import run_fiberdem_thermo  # noqa: E402

pytestmark = pytest.mark.system

R, RHO = 10e-6, 1500.0
STEPS, EVERY, V_SETTLE = 200, 10, 1e-3


def _fiber(x0: float, y0: float, n: int, length: float) -> Fiber:
    x = np.tile([x0, y0, 1e-3], (n, 1))
    x[:, 0] += np.linspace(0.0, length, n)
    q = np.tile(quat_from_frames([0, 1, 0], [0, 0, 1], [1, 0, 0])[0], (n, 1))
    return Fiber(x=x, q=q, radii=np.tile([R, R, 0.0, 0.0], (n, 1)))


def _settled(work: Path, build_dir: Path, fraction: float, sinking: bool, ranks: int = 1) -> float:
    fibers = [_fiber(0.1e-3 + 0.35e-3 * (j % 2), 0.1e-3 + 0.1e-3 * j, 5, 0.4e-3) for j in range(10)]
    fibers.append(_fiber(0.5e-3, 1.2e-3, 3, 0.1e-3))  # the fine: atoms 51-53
    work.mkdir(parents=True, exist_ok=True)
    write_fibers_liggghts(work / "data.fib", work / "nodes.fib", fibers, [0, 0, 0], [1.2e-3, 1.4e-3, 2e-3],
                          density_kg_m3=RHO)
    motion = (["velocity all set 0 0 -3e-3 units box"] if sinking else
              ["group fine id 51:53", "velocity fine set 5e-2 0 0 units box"])
    lines = ["units si", "atom_style sphere", "atom_modify map array sort 0 0.0", "boundary f f f",
             "newton on", "communicate single vel yes", f"processors {ranks} 1 1", "read_data data.fib",
             f"neighbor {0.1 * R!r} bin", "neigh_modify delay 0",
             f"fix beam all fiber/beam nodes nodes.fib E 10e9 G 4e9 density {RHO!r}",
             f"fix settle all fiber/settle {V_SETTLE!r} {EVERY} measure fiber mass_fraction {fraction!r}",
             *motion, "timestep 1e-6", "thermo_style custom step f_settle[1]", f"thermo {STEPS}",
             f"run {STEPS}"]
    out = run_fiberdem_thermo(work, build_dir, lines, ["step", "settled"], ranks=ranks)
    return float(out["settled"][-1])


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_fluttering_fine_does_not_keep_the_sheet_running(fiberdem_build: Path, tmp_path: Path, ranks: int) -> None:
    assert _settled(tmp_path / "all", fiberdem_build, 1.0, False, ranks) == 0.0
    assert _settled(tmp_path / "q95", fiberdem_build, 0.95, False, ranks) == STEPS / EVERY


def test_a_sinking_sheet_is_not_settled(fiberdem_build: Path, tmp_path: Path) -> None:
    assert _settled(tmp_path / "sink", fiberdem_build, 0.95, True) == 0.0


def _frame(speeds: list[float], masses: list[float]) -> dict[str, np.ndarray]:
    """A dump frame of one-node-per-fiber 'fibers' moving along x (the report's measure reads the
    columns fix fiber/beam's dump gives: f_beam[1] fiber ID, mass, velocities)."""
    n = len(speeds)
    return {"f_beam[1]": np.arange(1.0, n + 1), "mass": np.asarray(masses, float),
            "vx": np.asarray(speeds, float), "vy": np.zeros(n), "vz": np.zeros(n)}


def test_the_report_measures_what_the_fix_counts() -> None:
    """fiber_sheet.fiber_com_speeds + mass_fraction_speed (the lay-down report's measure) on the
    hand values of test_settle.cpp: the fine is ignored at 0.99, not at 0.999 or 1."""
    from fiberform.fiber_sheet import fiber_com_speeds, mass_fraction_speed

    def speed(frame: dict[str, np.ndarray], q: float = 1.0) -> float:
        return mass_fraction_speed(*fiber_com_speeds(frame), q)

    fr = _frame([1e-4] * 99 + [5e-2], [1e-9] * 99 + [0.2e-9])
    assert speed(fr) == 5e-2
    assert speed(fr, 0.99) == 1e-4
    assert speed(fr, 0.999) == 5e-2
    edge = _frame([3.0, 1.0, 2.0], [1.0, 1.0, 2.0])
    assert [speed(edge, q) for q in (0.25, 0.5, 0.75, 0.76)] == [1.0, 2.0, 2.0, 3.0]
