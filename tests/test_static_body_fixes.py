# SPDX-License-Identifier: GPL-3.0-or-later
"""The lay-down's static-body fixes together in fiberdem (issue 10, deliver 1): fix wall/fiber/yarns
(two yarns), four side planes of fix wall/fiber/dlvo with friction, fix fiber/remove and fix
fiber/settle, on 1 and 2 MPI ranks and across a restart.

Ten fibers (0.8 mm, radius 10 um, 9 nodes, E 10 GPa, 1500 kg/m^3, implicit at 1 us) in a flow
pushing them down and towards the y-high side plane (fix fiber/drag, uniform flow 10 mm/s along y,
50 mm/s down, gravity): seven lie across the two yarns (radius 50 um at x = 0.35 and 0.85 mm) and
across x = 0.6 mm, where the 2-rank run splits the box (elements straddle the split), the last one
against the y-high side plane; three lie along y between the yarns and fall through the gap below
the removal height (z = -60 um) and are removed whole.

- 1 vs 2 ranks: the same sheet (every node within TOL_RANKS), the same fibers removed, the same
  removed mass, and that mass equals the hand sum of the removed fibers' masses (rho pi r^2 L
  each);
- a run stopped at a restart file and continued from it (read_restart, the fixes defined again)
  ends with the same sheet (TOL_RESUME), the same removal totals and the same settle count as the
  uninterrupted run; the count was already > 0 at the restart, so it was carried over;
- Coulomb friction of a side plane (fix wall/fiber/dlvo `friction`, the sub-integrated contact of
  physics/friction.h, and inside the Newton solve): a fiber sliding along the plane under its
  weight decelerates at mu g (closed form) until it stops."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fiberform.fiber_io import Fiber, quat_from_frames, write_fibers_liggghts, write_nodes_subset
from fiberform.fiber_sheet import element_clearance

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beam_cases import ENV, Case, run_case, run_fiberdem_thermo, straight_chain  # noqa: E402

pytestmark = pytest.mark.system

R, RHO, N, L = 10e-6, 1500.0, 9, 0.8e-3
LO, HI = [0.0, 0.0, -0.3e-3], [1.2e-3, 1.2e-3, 0.5e-3]
Z_REMOVE, V_SETTLE = -60e-6, 2e-3
STEPS, EVERY, SPLIT = 3000, 100, 1800  # steps, steps per check, restart step of the resume test
TOL_RANKS = 1e-9   # m (each fiber is solved whole on one rank)
TOL_RESUME = 1e-9  # m (restart files are exact)
# x0, y, z of the fibers across the yarns (the last one 0.5 um from the y-high side plane) and of
# those along y between the yarns
CROSS = ([(0.2e-3, 0.15e-3 + 0.15e-3 * j, 75e-6 + 3e-6 * j) for j in range(6)]
         + [(0.2e-3, HI[1] - R - 0.5e-6, 70e-6)])
ALONG = [(0.6e-3 + dx, 0.2e-3, -45e-6) for dx in (-0.1e-3, 0.0, 0.1e-3)]
NAMES = ["step", "atoms", "nrem", "mrem", "settled", "vset", "fyz"]


def _fiber(p0: tuple[float, float, float], axis: int) -> Fiber:
    x = np.tile(p0, (N, 1))
    x[:, axis] += np.linspace(0.0, L, N)
    t3 = [1.0, 0.0, 0.0] if axis == 0 else [0.0, 1.0, 0.0]
    t1 = [0.0, 1.0, 0.0] if axis == 0 else [-1.0, 0.0, 0.0]
    q = np.tile(quat_from_frames(t1, [0, 0, 1], t3)[0], (N, 1))
    return Fiber(x=x, q=q, radii=np.tile([R, R, 0.0, 0.0], (N, 1)))


def _fixes() -> list[str]:
    planes = ["0 0 0 1 0 0", f"{HI[0]!r} 0 0 -1 0 0", "0 0 0 0 1 0", f"0 {HI[1]!r} 0 0 -1 0"]
    return [
        "fix drag all fiber/drag flow uniform 0 1e-2 -5e-2 fluid_density 1000 viscosity 1e-3 "
        "gravity 0 0 -9.81",
        *(f"fix wall{k} all wall/fiber/dlvo plane {p} terms steric implicit_force newton friction 0.3"
          for k, p in enumerate(planes)),
        "fix yarns all wall/fiber/yarns yarns yarns.txt terms steric implicit_force newton friction 0.3",
        f"fix remove all fiber/remove below {Z_REMOVE!r} every {EVERY}",
        f"fix settle all fiber/settle {V_SETTLE!r} {EVERY} measure node",
        "timestep 1e-6",
        "thermo_style custom step atoms f_remove[1] f_remove[2] f_settle[1] f_settle[2] f_yarns[6]",
        "thermo_modify lost ignore format float %.17g", f"thermo {EVERY}",
    ]


def _run(work: Path, build: Path, ranks: int, stop: int | None = None,
         resume: str | None = None) -> tuple[dict[str, np.ndarray], str]:
    """The lay-down on ``ranks`` ranks to STEPS (``stop``: to that step, then a restart file;
    ``resume``: from that restart file to STEPS)."""
    work.mkdir(parents=True, exist_ok=True)
    fibers = [_fiber(c, 0) for c in CROSS] + [_fiber(c, 1) for c in ALONG]
    write_fibers_liggghts(work / "data.fib", work / "nodes.fib", fibers, LO, HI, density_kg_m3=RHO)
    if resume is not None:  # fix fiber/beam wants the fibers left in the restart file only
        write_nodes_subset(work / "nodes.fib", work / "nodes.fib", range(len(CROSS)))
    (work / "yarns.txt").write_text("".join(f"{k} {x!r} {y!r} 0.0 50e-6\n"
                                            for k, x in enumerate((0.35e-3, 0.85e-3)) for y in (-0.1e-3, 1.3e-3)))
    head = ["units si", f"processors {ranks} 1 1"]
    if resume is None:
        head += ["atom_style sphere", "atom_modify map array sort 0 0.0", "boundary f f f", "newton on",
                 "communicate single vel yes", "read_data data.fib"]
    else:
        head += ["atom_modify map array sort 0 0.0", f"read_restart {resume}", "communicate single vel yes"]
    head += [f"neighbor {0.1 * R!r} bin", "neigh_modify delay 0",
             f"fix beam all fiber/beam nodes nodes.fib E 10e9 G 4e9 density {RHO!r}"]
    tail: list[str] = []
    if stop is not None:
        tail += [f"run {stop}", "write_restart split.restart"]
    else:
        done = SPLIT if resume is not None else 0
        tail += [f"run {STEPS - done}", "write_dump all custom final.dump id x y z modify sort id"]
    out = run_fiberdem_thermo(work, build, [*head, *_fixes(), *tail], NAMES, ranks=ranks)
    return out, (work / "log.fiberdem").read_text(errors="replace")


def _dump(path: Path) -> np.ndarray:
    lines = path.read_text().splitlines()
    start = lines.index(next(ln for ln in lines if ln.startswith("ITEM: ATOMS"))) + 1
    return np.array([[float(v) for v in ln.split()] for ln in lines[start:]])


def _removed(log: str) -> list[int]:
    lines = re.finditer(r"fix fiber/remove: step \d+ removed fiber\(s\)((?: \d+)+)", log)
    return sorted(int(i) for m in lines for i in m.group(1).split())


@pytest.fixture(scope="module")
def one_rank(tmp_path_factory: pytest.TempPathFactory,
             fiberdem_build: Path) -> tuple[Path, dict[str, np.ndarray], str]:
    work = tmp_path_factory.mktemp("static1")
    out, log = _run(work, fiberdem_build, 1)
    return work, out, log


def test_fibers_removed_whole_with_exact_mass(one_rank: tuple[Path, dict[str, np.ndarray], str]) -> None:
    work, out, log = one_rank
    gone = _removed(log)
    # the three fibers between the yarns (fiber IDs 8-10 of the nodes file), none of those on them
    assert gone == [8, 9, 10], gone
    hand = len(gone) * RHO * math.pi * R**2 * L  # a fiber's mass: rho pi r^2 L (fix fiber/beam lumps it)
    assert out["nrem"][-1] == 3
    assert abs(out["mrem"][-1] - hand) <= 1e-13 * hand, (out["mrem"][-1], hand)
    ids = np.arange(1, 10 * N + 1)
    fiber_of = (ids - 1) // N + 1  # atoms 1..N: fiber 1, ... (the data file's order)
    assert out["atoms"][-1] == 7 * N
    final = _dump(work / "final.dump")
    assert set(np.rint(final[:, 0]).astype(int)) == set(ids[fiber_of <= 7].tolist())
    # the yarns carry the fibers (their force on the fibers points up): every node left is above
    # the removal height and outside the yarns (axes along y at z = 0, radius 50 um) and the side
    # plane y = HI (within 5 % of the fiber radius: the law's own overlaps are nanometres)
    y, z = final[:, 2], final[:, 3]
    assert z.min() > Z_REMOVE
    assert out["fyz"][-1] > 0.0
    yarn_pts = np.array([[xa, yy, 0.0] for xa in (0.35e-3, 0.85e-3) for yy in (-0.1e-3, 1.3e-3)])
    clear = element_clearance(final[:, 1:4], np.arange(0, 7 * N + 1, N), yarn_pts, np.array([0, 2, 4]),
                              np.array([50e-6, 50e-6]))
    assert clear > 0.95 * R, clear  # element centre line to yarn surface >= the fiber radius
    side = (HI[1] - y - R).min()
    assert -0.05 * R < side < 50e-9, side  # the last fiber rests against the side plane


def test_two_ranks_give_the_same_sheet_and_accounting(one_rank: tuple[Path, dict[str, np.ndarray], str],
                                                      fiberdem_build: Path, tmp_path: Path) -> None:
    work1, out1, log1 = one_rank
    out2, log2 = _run(tmp_path, fiberdem_build, 2)
    assert "2 by 1 by 1 MPI processor grid" in log2
    x1, x2 = _dump(work1 / "final.dump"), _dump(tmp_path / "final.dump")
    assert np.array_equal(x1[:, 0], x2[:, 0])
    # elements straddle the split at x = 0.6 mm in the final sheet
    xs = x2[:, 1].reshape(-1, N)
    assert np.any((xs.min(axis=1) < 0.6e-3) & (xs.max(axis=1) > 0.6e-3))
    assert np.abs(x1[:, 1:] - x2[:, 1:]).max() < TOL_RANKS, np.abs(x1[:, 1:] - x2[:, 1:]).max()
    assert _removed(log2) == _removed(log1)
    assert out2["nrem"][-1] == out1["nrem"][-1] and out2["mrem"][-1] == out1["mrem"][-1]
    assert out2["settled"][-1] == out1["settled"][-1]


def test_resumed_run_ends_as_the_uninterrupted_one(one_rank: tuple[Path, dict[str, np.ndarray], str],
                                                   fiberdem_build: Path, tmp_path: Path) -> None:
    work1, out1, _ = one_rank
    first, _ = _run(tmp_path, fiberdem_build, 1, stop=SPLIT)
    assert first["settled"][-1] > 0, "the settle count must be > 0 at the restart (else nothing to carry)"
    out, log = _run(tmp_path, fiberdem_build, 1, resume="split.restart")
    x1, x = _dump(work1 / "final.dump"), _dump(tmp_path / "final.dump")
    assert np.array_equal(x1[:, 0], x[:, 0])
    assert np.abs(x1[:, 1:] - x[:, 1:]).max() < TOL_RESUME, np.abs(x1[:, 1:] - x[:, 1:]).max()
    assert out["nrem"][-1] == out1["nrem"][-1] and out["mrem"][-1] == out1["mrem"][-1]
    assert out["settled"][-1] == out1["settled"][-1]
    assert out["settled"][-1] > (STEPS - SPLIT) // EVERY  # more checks than the resumed part had


@pytest.mark.parametrize("mode", ["position", "newton"])
def test_plane_friction_decelerates_a_sliding_fiber_at_mu_g(fiberdem_build: Path, tmp_path: Path,
                                                           mode: str) -> None:
    """A straight fiber (0.2 mm, 5 nodes) resting on the plane x = 0 under g = 9.81 m/s^2 along -x
    (fix fiber/drag: no flow, negligible fluid), sliding along its axis at 20 mm/s; mu = 0.5. Once
    sliding, its speed falls at mu g = 4.905 m/s^2 (Coulomb: the friction force is mu times the
    weight the plane carries), measured over 0.5-3 ms (it stops at about 4 ms)."""
    mu, g, v0, dt = 0.5, 9.81, 0.02, 1e-6
    fib = straight_chain(5, 0.2e-3, [R, R, 0.0, 0.0], origin=(R + 0.4839e-9, 0.0, 0.1e-3))
    cmds = [f"fix drag all fiber/drag flow uniform 0 0 0 fluid_density 1e-9 viscosity 1e-12 gravity {-g!r} 0 0",
            f"fix floor all wall/fiber/dlvo plane 0 0 0 1 0 0 terms steric implicit_force {mode} friction {mu!r} points 3",
            f"velocity all set 0 0 {v0!r} units box"]
    case = Case(fibers=[fib], box_lo=[-1e-4, -1e-4, -1e-4], box_hi=[1e-4, 1e-4, 1e-3], dt=dt, steps=3500,
                integrator="implicit", newton="on", commands=cmds, thermo_every=500, track_atom=3,
                track_every=100)
    track = run_case(fiberdem_build, tmp_path, case).track
    t = np.arange(len(track)) * 100 * dt
    v = np.diff(track[:, 2]) / (100 * dt)
    window = (t[1:] > 0.5e-3) & (t[1:] < 3e-3)
    decel = -np.polyfit(t[1:][window], v[window], 1)[0]
    assert abs(decel - mu * g) < 0.01 * mu * g, (decel, mu * g)
    assert np.all(np.abs(track[:, 0] - R) < 0.05 * R)  # it stays on the plane


def test_friction_stick_sets_the_creep_of_a_stuck_fiber(fiberdem_build: Path, tmp_path: Path) -> None:
    """The keyword friction_stick k reaches the friction inside the Newton solve: the fiber of the
    test above, at rest on the plane x = 0 under g along -x and a tangential load 0.3 g along -z
    (below mu g: it sticks) creeps at the speed v where the regularised friction
    mu N v / sqrt(v^2 + v_eps^2), v_eps = mu N / c_stick, c_stick = k m / dt (docs/models/contact.md
    section 8), balances F_t: v = (F_t / c_stick) / sqrt(1 - (F_t / mu N)^2) = 1.25 x 0.3 g dt / k,
    measured over 1-3 ms for k = 1 and 10 (within 5 %)."""
    mu, g, dt = 0.5, 9.81, 1e-6
    speeds = {}
    for k in (1.0, 10.0):
        fib = straight_chain(5, 0.2e-3, [R, R, 0.0, 0.0], origin=(R + 0.4839e-9, 0.0, 0.1e-3))
        cmds = ["fix drag all fiber/drag flow uniform 0 0 0 fluid_density 1e-9 viscosity 1e-12 "
                f"gravity {-g!r} 0 {-0.3 * g!r}",
                f"fix floor all wall/fiber/dlvo plane 0 0 0 1 0 0 terms steric implicit_force newton "
                f"friction {mu!r} friction_stick {k!r}"]
        case = Case(fibers=[fib], box_lo=[-1e-4, -1e-4, -1e-4], box_hi=[1e-4, 1e-4, 1e-3], dt=dt, steps=3000,
                    integrator="implicit", newton="on", commands=cmds, thermo_every=500, track_atom=3,
                    track_every=100)
        track = run_case(fiberdem_build, tmp_path / f"k{k:g}", case).track
        t = np.arange(len(track)) * 100 * dt
        window = (t > 1e-3) & (t <= 3e-3)
        speeds[k] = -np.polyfit(t[window], track[window, 2], 1)[0]
        want = 0.3 * g * dt / k / np.sqrt(1.0 - (0.3 / mu) ** 2)
        assert abs(speeds[k] / want - 1.0) < 0.05, (k, speeds[k], want)
    assert speeds[1.0] > 5.0 * speeds[10.0]


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("case", ["missing yarns file", "missing flow grid", "malformed yarns file"])
def test_an_unreadable_input_file_ends_every_rank_naming_it(fiberdem_build: Path, tmp_path: Path, ranks: int,
                                                             case: str) -> None:
    """The yarns file of fix wall/fiber/yarns and the flow grid of fix fiber/drag are read on rank 0
    and broadcast (style_args.h read_file_everywhere): a file that cannot be read, or a malformed
    one, ends the run on every rank with a message naming the style and the file, no rank left
    waiting in a collective call (the timeout), on 1 and 2 ranks."""
    write_fibers_liggghts(tmp_path / "data.fib", tmp_path / "nodes.fib", [_fiber(c, 0) for c in CROSS[:2]], LO, HI,
                          density_kg_m3=RHO)
    (tmp_path / "bad_yarns.txt").write_text("0 0.35e-3 -0.1e-3 0.0 50e-6\n0 0.35e-3 1.3e-3\n")
    drag, yarns, words = {
        "missing yarns file": ("flow uniform 0 0 -5e-2", "missing_yarns.txt",
                               "fix wall/fiber/yarns: yarns file: cannot read missing_yarns.txt"),
        "missing flow grid": ("flow grid missing.grid", "bad_yarns.txt",
                              "fix fiber/drag: flow grid: cannot read missing.grid"),
        "malformed yarns file": ("flow uniform 0 0 -5e-2", "bad_yarns.txt",
                                 "bad_yarns.txt:2: expected 'yarn-index x y z radius'"),
    }[case]
    lines = ["units si", f"processors {ranks} 1 1", "atom_style sphere", "atom_modify map array sort 0 0.0",
             "boundary f f f", "newton on", "communicate single vel yes", "read_data data.fib",
             f"neighbor {0.1 * R!r} bin", "neigh_modify delay 0",
             f"fix beam all fiber/beam nodes nodes.fib E 10e9 G 4e9 density {RHO!r}",
             f"fix drag all fiber/drag {drag} fluid_density 1000 viscosity 1e-3 gravity 0 0 -9.81",
             f"fix yarns all wall/fiber/yarns yarns {yarns} terms steric implicit_force newton",
             "timestep 1e-6", "run 10"]
    (tmp_path / "in.fiberdem").write_text("\n".join(lines) + "\n")
    mpi = ["mpirun", "--oversubscribe", "-np", str(ranks)] if ranks > 1 else []
    proc = subprocess.run([*mpi, str(fiberdem_build / "bin" / "fiberdem"), "-in", "in.fiberdem", "-log",
                           "log.fiberdem", "-screen", "none"], cwd=tmp_path, env=ENV, capture_output=True,
                          text=True, errors="replace", timeout=120)
    log = (tmp_path / "log.fiberdem").read_text(errors="replace")
    assert proc.returncode != 0
    assert words in log, log[-2000:] + proc.stderr[-2000:]
