# SPDX-License-Identifier: GPL-3.0-or-later
"""The press plate (fix wall/fiber/dlvo ``servo``, ``stop``) on a real fiber in fiberdem.

A straight fiber (0.5 mm, radius 10 um, E 10 GPa, 1500 kg/m^3, 11 nodes, implicit integrator at
1 us) lies across two yarns (radius 50 um, 0.4 mm apart; fix wall/fiber/yarns, implicit_force newton,
friction 0.5) in water at rest (fix fiber/drag: zero flow, gravity, buoyancy). The plate comes down
from 2 um above the fiber, ramps to a target pressure p_t in 0.1 ms and holds it; plate area
A = 1 mm^2 (nominal). At rest, with the plate force F_p and the yarn reaction F_y (fix wall/fiber/yarns
vector 4-6), both forces on the fiber:

    F_p,z + F_y,z - W = 0,   W = (rho_f - rho) V g  (net weight; computed here from the geometry)

within 1 % of the plate force, and the measured pressure stays within 2 % of p_t over the hold.
Two targets: 4 Pa (weight 2e-4 of the plate force) and 8 mPa (weight ~10 % of the plate force: the
balance needs the weight right). Without the servo's stiffness bound the plain proportional law
cycles 0 <-> 15 Pa around 4 Pa on this contact (measured; docs/models/press.md).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beam_cases import Case, run_case  # noqa: E402

from fiberform.fiber_io import Fiber, quat_from_frames  # noqa: E402

pytestmark = pytest.mark.system

N, L, R, RHO, RHO_F, G = 11, 5e-4, 10e-6, 1500.0, 998.2, 9.81
AREA, DT, RAMP, HOLD = 1e-6, 1e-6, 1e-4, 1.5e-3
EVERY = 25


def _fiber() -> Fiber:
    x = np.zeros((N, 3))
    x[:, 0] = np.linspace(-L / 2, L / 2, N)
    x[:, 2] = R + 0.3e-9
    t1 = np.tile([0.0, 1.0, 0.0], (N, 1))
    t2 = np.tile([0.0, 0.0, 1.0], (N, 1))
    t3 = np.tile([1.0, 0.0, 0.0], (N, 1))
    return Fiber(x=x, q=quat_from_frames(t1, t2, t3), radii=np.tile([R, R, 0.0, 0.0], (N, 1)))


def _press(build: Path, work: Path, p_t: float) -> np.ndarray:
    work.mkdir(parents=True, exist_ok=True)
    yarns = work / "yarns.txt"
    yarns.write_text("0 -2e-4 -3e-4 -5e-5 5e-5\n0 -2e-4 3e-4 -5e-5 5e-5\n"
                     "1 2e-4 -3e-4 -5e-5 5e-5\n1 2e-4 3e-4 -5e-5 5e-5\n")
    z0 = 2 * R + 2e-6
    steps = round((RAMP + HOLD) / DT) + 300  # + the approach (about 2 um at 5 mm/s)
    names = ("fpz", "p", "pt", "tc", "fyz")
    refs = ("f_plate[9]", "f_plate[12]", "f_plate[13]", "f_plate[14]", "f_yarns[6]")
    cmds = [f"fix drag all fiber/drag flow uniform 0 0 0 fluid_density {RHO_F!r} gravity 0 0 {-G!r}",
            f"fix yarns all wall/fiber/yarns yarns {yarns.resolve()} implicit_force newton terms steric "
            "friction 0.5",
            f"fix plate all wall/fiber/dlvo plane 0 0 {z0!r} 0 0 -1 servo {AREA!r} 5e-3 "
            f"{0.1 * p_t!r} 3 0 0 {RAMP!r} {p_t!r} 1 {p_t!r} stop {z0 - 1e-6!r} terms steric "
            "implicit_force newton",
            *(f"variable {n} equal {r}" for n, r in zip(names, refs)),
            f'fix out all print {EVERY} "{" ".join("${" + n + "}" for n in names)}" file out.txt '
            "screen no"]
    case = Case(fibers=[_fiber()], box_lo=[-4e-4, -4e-4, -1e-4], box_hi=[4e-4, 4e-4, 1e-4], dt=DT,
                steps=steps, integrator="implicit", newton="on", commands=cmds, thermo_every=steps)
    run_case(build, work, case)
    return np.loadtxt(work / "out.txt", ndmin=2)


@pytest.mark.parametrize("p_t", [4.0, 8e-3])
def test_force_balance_and_pressure_hold(fiberdem_build: Path, tmp_path: Path, p_t: float) -> None:
    out = _press(fiberdem_build, tmp_path, p_t)
    fpz, p, pt, tc, fyz = out.T
    hold = tc > RAMP + 0.5e-3  # the hold, after 0.5 ms to settle
    assert hold.sum() >= 20, tc
    assert np.allclose(pt[hold], p_t, rtol=1e-12)
    # the pressure holds the target within 2 %
    dev = np.max(np.abs(p[hold] / p_t - 1.0))
    assert dev < 0.02, f"largest pressure deviation over the hold {dev:.3%}"
    # force balance at rest: plate + yarns (both on the fiber) = net weight
    volume = math.pi * R**2 * L
    weight = (RHO - RHO_F) * volume * G  # downward, N
    resid = fpz[hold] + fyz[hold] - weight
    f_plate = np.abs(fpz[hold])
    assert np.all(np.abs(resid) < 0.01 * f_plate), (
        f"balance residual {np.max(np.abs(resid / f_plate)):.3%} of the plate force "
        f"(plate {f_plate.mean():.4g} N, yarns {fyz[hold].mean():.4g} N, net weight {weight:.4g} N)")
    # the plate force is the target pressure times the area (the servo's own measure)
    assert np.allclose(-fpz[hold] / AREA, p[hold], rtol=1e-9)
