# SPDX-License-Identifier: GPL-3.0-or-later
"""Builders and runners of small fix fiber/beam cases (used by tests/test_fix_fiber_beam.py and
bench/fibers/). Geometry helpers only: the physics answers live in the tests (closed forms)."""

from __future__ import annotations

import math
import os
import re
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fiberform.fiber_io import Fiber, quat_from_frames, write_fibers_liggghts
from fiberform.runner import build_env

# the stages' environment (Open MPI's root permission, ranks that yield when idle, WM_PROJECT_DIR):
# busy-waiting ranks slow 2-rank runs on a loaded 2-core machine by minutes
ENV = build_env()

# wet pulp fiber wall, order of magnitude (docs/styles/fix_fiber_beam.md)
E_WALL = 10e9
G_WALL = 4e9
RHO = 1500.0
KSHEAR = 5.0 / 6.0


def straight_chain(n_nodes: int, length: float, radii: Sequence[float],
                   origin: Sequence[float] = (0.0, 0.0, 0.0)) -> Fiber:
    """Nodes along +z from ``origin``, frame t1 = x, t2 = y, t3 = z."""
    z = np.linspace(0.0, length, n_nodes)
    x = np.zeros((n_nodes, 3)) + np.asarray(origin, dtype=float)
    x[:, 2] += z
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n_nodes, 1))
    r = np.tile(np.asarray(radii, dtype=float), (n_nodes, 1))
    return Fiber(x=x, q=q, radii=r)


def bent_state(fib: Fiber, u_y: np.ndarray, du_y: np.ndarray, u_x: np.ndarray | None = None,
               du_x: np.ndarray | None = None, twist: np.ndarray | None = None) -> Fiber:
    """An initial state of a straight +z reference displaced by u (small or large) with frames
    rotated so that t3 follows the deflected tangent (and twisted by ``twist`` about it)."""
    n = fib.n
    u_x = np.zeros(n) if u_x is None else u_x
    du_x = np.zeros(n) if du_x is None else du_x
    twist = np.zeros(n) if twist is None else twist
    xi = fib.x.copy()
    xi[:, 0] += u_x
    xi[:, 1] += u_y
    t3 = np.stack([du_x, du_y, np.ones(n)], axis=1)
    t3 /= np.linalg.norm(t3, axis=1)[:, None]
    t1 = np.array([1.0, 0.0, 0.0]) - t3 * t3[:, :1]
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(t3, t1)
    c, s = np.cos(twist)[:, None], np.sin(twist)[:, None]
    t1, t2 = c * t1 + s * t2, -s * t1 + c * t2
    return Fiber(x=fib.x, q=fib.q, radii=fib.radii, x_init=xi, q_init=quat_from_frames(t1, t2, t3))


@dataclass
class Case:
    fibers: list[Fiber]
    box_lo: Sequence[float]
    box_hi: Sequence[float]
    dt: float
    steps: int
    fix_options: str = ""
    commands: list[str] = field(default_factory=list)  # after the fix, before run
    thermo_every: int = 1000
    track_atom: int | None = None  # write x y z of this atom every `track_every` steps
    track_every: int = 10
    processors: str = "* 1 1"
    boundary: str = "f f f"
    E: float = E_WALL
    G: float = G_WALL
    rho: float = RHO
    integrator: str = "explicit"  # fix fiber/beam integrator: "explicit" or "implicit"
    newton: str = "off"           # LIGGGHTS newton setting ("on" for pair_style fiber/dlvo)


@dataclass
class Result:
    final: np.ndarray  # columns id x y z vx vy vz qw qx qy qz, sorted by id
    thermo: np.ndarray  # step, elastic energy, total energy
    track: np.ndarray | None
    log: str


def run_case(build_dir: Path, work: Path, case: Case, ranks: int = 1,
             pre_fix: Sequence[str] = (), partner: Sequence[str] = (),
             timeout_s: float = 900, partner_ranks: int = 1,
             env: dict[str, str] | None = None) -> Result:
    """Write and run the case; ``partner``: a second program started under the same mpirun (MPMD,
    ``partner_ranks`` ranks), e.g. ``[fiberPimpleFoam, "-coupled", "-case", dir]`` for a coupled
    run. More ranks than cores are run with ``--oversubscribe``; ``env``: extra environment."""
    if case.integrator not in ("explicit", "implicit"):
        raise ValueError(f"Case.integrator must be 'explicit' or 'implicit', not {case.integrator!r}")
    work.mkdir(parents=True, exist_ok=True)
    write_fibers_liggghts(work / "data.fib", work / "nodes.fib", case.fibers, case.box_lo,
                          case.box_hi, density_kg_m3=case.rho)
    skin = float(0.1 * max(np.max(f.radii[:, :2]) for f in case.fibers))
    lines = [
        "units si", "atom_style sphere", "atom_modify map array sort 0 0.0", f"boundary {case.boundary}",
        f"newton {'on' if case.newton == 'on' else 'off'}", "communicate single vel yes", f"processors {case.processors}",
        "read_data data.fib", f"neighbor {skin!r} bin", "neigh_modify delay 0", *pre_fix,
        f"fix beam all fiber/beam nodes nodes.fib E {case.E!r} G {case.G!r} density {case.rho!r} "
        f"shear_factor {KSHEAR!r} integrator {case.integrator} {case.fix_options}",
        *case.commands,
        f"timestep {case.dt!r}",
        "thermo_style custom step f_beam[1] f_beam[4]",
        "thermo_modify format float %.15g",
        f"thermo {case.thermo_every}",
    ]
    if case.track_atom is not None:
        a = case.track_atom
        lines += [f"variable tx equal x[{a}]", f"variable ty equal y[{a}]", f"variable tz equal z[{a}]",
                  f'fix track all print {case.track_every} "${{tx}} ${{ty}} ${{tz}}" file track.txt '
                  "screen no"]
    fmt = " ".join(["%d"] + ["%.17g"] * 10)
    lines += [f"run {case.steps}",
              "write_dump all custom final.dump id x y z vx vy vz f_beam[4] f_beam[5] f_beam[6] "
              f'f_beam[7] modify sort id format "{fmt}"']
    (work / "in.case").write_text("\n".join(lines) + "\n")
    exe = str(build_dir / "bin" / "fiberdem")
    cmd = [exe, "-in", "in.case", "-log", "log.case", "-screen", "none"]
    if ranks > 1 or partner:
        total = ranks + (partner_ranks if partner else 0)
        over = ["--oversubscribe"] if total > (os.cpu_count() or 1) else []
        cmd = ["mpirun", *over, "-np", str(ranks), *cmd]
    if partner:
        cmd += [":", "-np", str(partner_ranks), *map(str, partner)]
    proc = subprocess.run(cmd, cwd=work, env={**ENV, **(env or {})}, capture_output=True, text=True,
                          timeout=timeout_s, errors="replace")
    log = ((work / "log.case").read_text(errors="replace") if (work / "log.case").exists()
           else "")
    if proc.returncode != 0:
        raise RuntimeError(f"fiberdem failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n"
                           f"{proc.stderr[-3000:]}\n{log[-3000:]}")
    final = _read_final(work / "final.dump")
    thermo = _read_thermo(log)
    track = np.loadtxt(work / "track.txt", ndmin=2) if case.track_atom is not None else None
    return Result(final=final, thermo=thermo, track=track, log=log)


def _read_final(path: Path) -> np.ndarray:
    lines = path.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("ITEM: ATOMS"))
    return np.array([[float(v) for v in ln.split()] for ln in lines[i + 1:] if ln.strip()])


def _read_thermo(log: str) -> np.ndarray:
    rows = []
    on = False
    for ln in log.splitlines():
        if ln.strip().startswith("Step"):
            on = True
            continue
        if on:
            parts = ln.split()
            if len(parts) == 3 and re.fullmatch(r"\d+", parts[0]):
                rows.append([float(p) for p in parts])
            else:
                on = False
    return np.array(rows)


def eb_mode1(s: np.ndarray, L: float) -> tuple[np.ndarray, np.ndarray]:
    """First mode shape (and slope) of an Euler-Bernoulli cantilever clamped at s = 0, beta1 L =
    1.8751: the textbook closed form (e.g. Meirovitch, Fundamentals of Vibrations, sec. 8.7)."""
    bl = 1.8751040687
    b = bl / L
    sig = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
    phi = np.cosh(b * s) - np.cos(b * s) - sig * (np.sinh(b * s) - np.sin(b * s))
    dphi = b * (np.sinh(b * s) + np.sin(b * s) - sig * (np.cosh(b * s) - np.cos(b * s)))
    return phi, dphi


def period_from_crossings(t: np.ndarray, y: np.ndarray) -> tuple[float, int]:
    """Mean period of an oscillating signal from its linearly interpolated zero crossings; returns
    (period, number of crossings); nan if fewer than 3 crossings."""
    idx = np.nonzero(np.sign(y[:-1]) != np.sign(y[1:]))[0]
    cr = t[idx] - y[idx] * (t[idx + 1] - t[idx]) / (y[idx + 1] - y[idx])
    if len(cr) < 3:
        return math.nan, len(cr)
    return 2 * (cr[-1] - cr[0]) / (len(cr) - 1), len(cr)


def critical_steps(log: str) -> dict[str, float]:
    m = re.search(r"axial ([0-9.eE+-]+) s, shear ([0-9.eE+-]+) s, bending ([0-9.eE+-]+) s, "
                  r"torsion ([0-9.eE+-]+) s", log)
    if not m:
        return {}
    return dict(zip(("axial", "shear", "bending", "torsion"), (float(g) for g in m.groups())))


def ellipse_section(a1: float, a2: float, b1: float = 0.0, b2: float = 0.0) -> dict[str, float]:
    """Closed forms of a hollow ellipse (the test's own, independent of beam.h)."""
    def jt(a: float, b: float) -> float:
        return 0.0 if a <= 0 or b <= 0 else math.pi * a**3 * b**3 / (a * a + b * b)
    return {
        "A": math.pi * (a1 * a2 - b1 * b2),
        "I1": math.pi / 4 * (a1 * a2**3 - b1 * b2**3),
        "I2": math.pi / 4 * (a1**3 * a2 - b1**3 * b2),
        "J": jt(a1, a2) - jt(b1, b2),
    }


def run_fiberdem_thermo(work: Path, build_dir: Path, lines: list[str], names: list[str],
                        ranks: int = 1) -> dict[str, np.ndarray]:
    """Run the input ``lines`` with fiberdem on ``ranks`` MPI ranks in ``work``; the thermo rows as
    columns ``names``."""
    (work / "in.fiberdem").write_text("\n".join(lines) + "\n")
    mpi = ["mpirun", "-np", str(ranks)] if ranks > 1 else []
    proc = subprocess.run([*mpi, str(build_dir / "bin" / "fiberdem"), "-in", "in.fiberdem", "-log", "log.fiberdem",
                           "-screen", "none"], cwd=work, env=ENV, capture_output=True, text=True,
                          errors="replace", timeout=1800)
    log = (work / "log.fiberdem").read_text(errors="replace") if (work / "log.fiberdem").exists() else ""
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:] + log[-3000:]
    number = r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
    rows = [ln.split() for ln in log.splitlines()
            if re.fullmatch(rf"\s*\d+(\s+{number}){{{len(names) - 1}}}\s*", ln)]
    data = np.array([[float(v) for v in r] for r in rows])
    return {k: data[:, i] for i, k in enumerate(names)}
