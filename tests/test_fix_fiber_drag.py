# SPDX-License-Identifier: GPL-3.0-or-later
"""fix fiber/drag (issue 5): a stiff fiber in uniform flow reaches the velocity at which the drag of
Kettil 2016 eq. 2.14-2.16 balances gravity and buoyancy.

The expected slip speed is computed here with scipy's brentq on the thesis formulas, independently
of physics/drag.h.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beam_cases import RHO, Case, run_case, straight_chain  # noqa: E402

pytestmark = pytest.mark.system

RHO_F, MU, G = 998.2, 1.0e-3, 9.81


def cd_thesis(re: float) -> float:
    """Eq. 2.15 as printed (clamped above Re = 400, docs/models/drag.md)."""
    re = min(re, 400.0)
    base = 9.689 * re**-0.78
    if re < 5:
        return base * (1 + 0.147 * re**0.82)
    if re < 40:
        return base * (1 + 0.227 * re**0.5)
    return base * (1 + 0.0838 * re**0.82)


def slip_speed(d: float, area: float) -> float:
    load = (RHO - RHO_F) * area * G  # N/m
    def residual(v: float) -> float:
        re = RHO_F * v * d / MU  # eq. 2.16
        return 0.5 * RHO_F * cd_thesis(re) * d * v * v - load  # eq. 2.14
    return float(brentq(residual, 1e-9, 10.0, xtol=1e-14, rtol=1e-12))


@pytest.mark.parametrize("radius", [10e-6, 40e-6])
def test_stiff_fiber_reaches_balance_velocity(fiberdem_build: Path, tmp_path: Path,
                                              radius: float) -> None:
    """A straight horizontal fiber (6 nodes, 250 um) in uniform flow u = (0.01, 0, -0.02) m/s ends
    moving with u_x and with u_z - v_slip, v_slip from eq. 2.14 = (rho_s - rho_f) A g, within 1%."""
    u = (0.01, 0.0, -0.02)
    fib = straight_chain(6, 250e-6, [radius, radius, 0.0, 0.0])
    fib.x[:] = fib.x[:, [2, 1, 0]]  # along x
    fib.x[:, 2] += 1e-3
    from fiberform.fiber_io import quat_from_frames
    n = fib.n
    fib.q[:] = quat_from_frames(np.tile([0.0, 0.0, -1.0], (n, 1)), np.tile([0.0, 1.0, 0.0], (n, 1)),
                                np.tile([1.0, 0.0, 0.0], (n, 1)))
    d, area = 2 * radius, math.pi * radius**2
    v_slip = slip_speed(d, area)
    # time constant of the approach: m / (d drag / d v) per unit length (drag ~ v^1.22 at low Re)
    tau = RHO * area / (1.22 * (RHO - RHO_F) * area * G / v_slip)
    dt = 1e-7
    steps = int(12 * tau / dt) + 1000
    case = Case([fib], [-1e-3, -1e-3, -0.5], [1e-3, 1e-3, 2e-3], dt=dt, steps=steps,
                fix_options="stiffness_scale 0.01 inertia_scale 1e4 dt_check warn",
                commands=[f"fix drag all fiber/drag flow uniform {u[0]!r} {u[1]!r} {u[2]!r} "
                          f"fluid_density {RHO_F!r} viscosity {MU!r} gravity 0 0 {-G!r}"],
                thermo_every=max(1, steps // 10))
    r = run_case(fiberdem_build, tmp_path, case)
    v = r.final[:, 4:7]
    assert np.allclose(v[:, 0], u[0], rtol=1e-3), v[:, 0]
    assert np.allclose(v[:, 1], 0.0, atol=1e-9)
    slip = u[2] - v[:, 2]
    assert np.allclose(slip, v_slip, rtol=0.01), (slip, v_slip)
