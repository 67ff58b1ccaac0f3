# SPDX-License-Identifier: GPL-3.0-or-later
"""Validation of fix fiber/beam against closed forms (issue 4, thesis sec. 2.2 and 3.4).

Every expected number is computed here, independently of the C++ code: Euler-Bernoulli
deflection and frequency, St-Venant torsion, the elastica solved with scipy, energy conservation,
rest of a stress-free curved fiber, and 1-rank vs 2-rank identity with nodes migrating.
Run against ``$FIBERFORM_BUILD`` (default ``<root>/build``).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beam_cases import (  # noqa: E402
    E_WALL,
    G_WALL,
    RHO,
    Case,
    bent_state,
    critical_steps,
    eb_mode1,
    period_from_crossings,
    ellipse_section,
    run_case,
    straight_chain,
)

pytestmark = pytest.mark.system


@pytest.fixture(scope="module")
def fiberdem_build(build_dir: Path) -> Path:
    exe = build_dir / "bin" / "fiberdem"
    if not exe.is_file():
        pytest.skip(f"{exe} not built")
    return build_dir


def first_mode_omega(EI: float, rhoA: float, L: float) -> float:
    return 1.8751040687**2 / L**2 * math.sqrt(EI / rhoA)


# ------------------------------------------------------------------------------------------------
# statics


@pytest.mark.parametrize("direction", ["t2", "t1"])
def test_cantilever_small_tip_load(fiberdem_build: Path, tmp_path: Path, direction: str) -> None:
    """Collapsed ('rectangular', a1 = 0.8 w, a2 = 0.2 w) section, both principal axes:
    tip deflection = F L^3 / (3 E I) within 2%."""
    L, n, w = 1e-3, 17, 20e-6
    a1, a2 = 0.8 * w, 0.2 * w
    sec = ellipse_section(a1, a2)
    # a load along t2 bends about t1 (I1), along t1 about t2 (I2)
    inertia = sec["I1"] if direction == "t2" else sec["I2"]
    EI = E_WALL * inertia
    delta = 1e-3 * L  # small: 0.1% of the length
    F = 3 * EI * delta / L**3
    tau = 1 / (2 * first_mode_omega(EI, RHO * sec["A"], L))  # critically damped first mode
    force = (0.0, F, 0.0) if direction == "t2" else (F, 0.0, 0.0)
    case = Case(
        [straight_chain(n, L, [a1, a2, 0, 0])], [-5e-4, -5e-4, -1e-4], [5e-4, 5e-4, 1.2e-3],
        dt=1e-8, steps=int(30 * tau / 1e-8),
        fix_options=f"inertia_scale 100 drag {tau!r}",  # rotary inertia does not enter statics
        commands=["group clamp id 1", f"group tip id {n}",
                  "fix load tip addforce {!r} {!r} {!r}".format(*force), "fix clamp clamp freeze"],
        thermo_every=10000)
    r = run_case(fiberdem_build, tmp_path, case)
    tip = r.final[-1]
    got = tip[1] if direction == "t1" else tip[2]
    expected = F * L**3 / (3 * EI)
    assert got == pytest.approx(expected, rel=0.02), (got, expected)
    # still: kinetic energy negligible
    assert abs(r.thermo[-1, 2] - r.thermo[-1, 1]) < 1e-4 * r.thermo[-1, 1]


def test_torsion_twist_angle(fiberdem_build: Path, tmp_path: Path) -> None:
    """Hollow circular fiber, end torque T: twist = T L / (G J) within 2%, J = pi/2 (a^4 - b^4)."""
    L, n, a, b = 1e-3, 11, 15e-6, 8e-6
    J = math.pi / 2 * (a**4 - b**4)
    phi = 0.05  # rad
    T = phi * G_WALL * J / L
    # torsional first mode pi/(2L) sqrt(G J / (rho Ip)); Ip = J for a circle
    w_t = math.pi / (2 * L) * math.sqrt(G_WALL / RHO)
    tau = 1 / (2 * w_t)
    case = Case(
        [straight_chain(n, L, [a, a, b, b])], [-5e-4, -5e-4, -1e-4], [5e-4, 5e-4, 1.2e-3],
        dt=2e-9, steps=int(30 * tau / 2e-9),
        fix_options=f"drag {tau!r} torque tip 0 0 {T!r}",
        commands=["group clamp id 1", f"group tip id {n}", "fix clamp clamp freeze"],
        thermo_every=1000)
    # the fix's torque keyword names group 'tip', which must exist before the fix: define it first
    case.commands = ["fix clamp clamp freeze"]
    r = run_case(fiberdem_build, tmp_path, case, pre_fix=["group clamp id 1", f"group tip id {n}"])
    qw, qx, qy, qz = r.final[-1, 7:11]
    twist = 2 * math.atan2(qz, qw)
    assert abs(qx) < 1e-9 and abs(qy) < 1e-9
    assert twist == pytest.approx(T * L / (G_WALL * J), rel=0.02)
    # linear twist along the fiber
    twists = 2 * np.arctan2(r.final[:, 10], r.final[:, 7])
    s = r.final[:, 3]
    assert np.allclose(twists, T * s / (G_WALL * J), atol=0.02 * phi)


def elastica_tip(load: float, L: float) -> tuple[float, float]:
    """Inextensible elastica, clamped at s = 0 along +z, dead tip load F along +y, with
    load = F L^2 / (E I). Returns (y_tip, z_tip) / L, solved with scipy.integrate.solve_bvp."""
    from scipy.integrate import solve_bvp

    def rhs(s: np.ndarray, u: np.ndarray) -> np.ndarray:
        th, dth, _y, _z = u
        return np.vstack([dth, -load * np.cos(th), np.sin(th), np.cos(th)])

    def bc(ua: np.ndarray, ub: np.ndarray) -> np.ndarray:
        return np.array([ua[0], ub[1], ua[2], ua[3]])

    s = np.linspace(0, 1, 201)
    guess = np.vstack([0.3 * s, 0.3 * np.ones_like(s), 0.15 * s**2, s])
    sol = solve_bvp(rhs, bc, s, guess, tol=1e-10, max_nodes=100000)
    assert sol.success
    return float(sol.y[2, -1]) * L, float(sol.y[3, -1]) * L


def test_cantilever_large_tip_load_elastica(fiberdem_build: Path, tmp_path: Path) -> None:
    """F L^2 / (E I) = 3: tip position vs the elastica (scipy solve_bvp) within 3%."""
    L, n, w = 1e-3, 21, 10e-6
    sec = ellipse_section(w, w)
    EI = E_WALL * sec["I1"]
    load = 3.0
    F = load * EI / L**2
    tau = 1 / (2 * first_mode_omega(EI, RHO * sec["A"], L))
    case = Case(
        [straight_chain(n, L, [w, w, 0, 0])], [-5e-4, -2e-4, -1e-4], [5e-4, 1.2e-3, 1.2e-3],
        dt=1e-8, steps=int(40 * tau / 1e-8),
        fix_options=f"inertia_scale 100 drag {tau!r}",
        commands=["group clamp id 1", f"group tip id {n}", f"fix load tip addforce 0 {F!r} 0",
                  "fix clamp clamp freeze"],
        thermo_every=10000)
    r = run_case(fiberdem_build, tmp_path, case)
    y_ref, z_ref = elastica_tip(load, L)
    tip = r.final[-1]
    assert tip[2] == pytest.approx(y_ref, rel=0.03), (tip[2], y_ref)
    assert tip[3] == pytest.approx(z_ref, rel=0.03), (tip[3], z_ref)
    assert y_ref > 0.5 * L  # really large


# ------------------------------------------------------------------------------------------------
# dynamics


def test_first_bending_frequency(fiberdem_build: Path, tmp_path: Path) -> None:
    """Undamped cantilever started in the Euler-Bernoulli first mode shape: frequency vs
    (beta1 L)^2 / L^2 sqrt(E I / (rho A)), beta1 L = 1.8751, within 3%. Real rotary inertia."""
    L, n, w = 0.5e-3, 17, 10e-6
    sec = ellipse_section(w, w)
    om = first_mode_omega(E_WALL * sec["I1"], RHO * sec["A"], L)
    period = 2 * math.pi / om
    fib = straight_chain(n, L, [w, w, 0, 0])
    s = fib.x[:, 2]
    phi, dphi = eb_mode1(s, L)
    amp = 1e-3 * L / phi[-1]
    start = bent_state(fib, amp * phi, amp * dphi)
    dt = 4e-9
    case = Case([start], [-2e-4, -2e-4, -1e-4], [2e-4, 2e-4, 0.7e-3], dt=dt,
                steps=int(4.2 * period / dt),
                commands=["group clamp id 1", "fix clamp clamp freeze"],
                thermo_every=10000, track_atom=n, track_every=5)
    r = run_case(fiberdem_build, tmp_path, case)
    y = r.track[:, 1]
    t = np.arange(1, len(y) + 1) * 5 * dt
    measured_period, ncross = period_from_crossings(t, y)
    assert ncross >= 6
    assert 2 * math.pi / measured_period == pytest.approx(om, rel=0.03)


def test_energy_drift_free_vibration(fiberdem_build: Path, tmp_path: Path) -> None:
    """Free-free chain, large bent + twisted initial state, undamped, 1e5 steps:
    total (elastic + kinetic + rotational) energy drift < 0.5%."""
    L, n, w = 0.4e-3, 9, 10e-6
    fib = straight_chain(n, L, [0.8 * w, 0.6 * w, 0, 0])
    s = fib.x[:, 2] / L
    amp = 0.15 * L
    start = bent_state(fib, amp * s**2, 2 * amp * s / L, u_x=0.3 * amp * s**3,
                       du_x=0.9 * amp * s**2 / L, twist=0.3 * s)
    # timestep a quarter of the critical step printed by the fix (checked below)
    dt = 1e-9
    case = Case([start], [-4e-4, -4e-4, -3e-4], [4e-4, 4e-4, 7e-4], dt=dt, steps=100_000,
                thermo_every=1000)
    r = run_case(fiberdem_build, tmp_path, case)
    crit = min(critical_steps(r.log).values())
    assert dt <= 0.3 * crit
    e = r.thermo[:, 2]
    assert e[0] > 0 and r.thermo[0, 1] == pytest.approx(e[0])  # starts at rest, all elastic
    # the energy really moved between elastic and kinetic
    assert r.thermo[:, 1].min() < 0.7 * e[0]
    drift = np.max(np.abs(e - e[0])) / e[0]
    assert drift < 5e-3, drift


def test_curved_generated_fiber_stays_at_rest(fiberdem_build: Path, tmp_path: Path) -> None:
    """A curved, twisted fiber from the generator (thesis eq. 3.4-3.9) is its own stress-free
    reference: after 1e4 steps the largest node speed is < 1e-9 m/s."""
    from fiberform.stages.generate import FiberShape, fiber_shape

    rng = np.random.default_rng(7)
    shape = fiber_shape(FiberShape(length_m=1.0e-3, width_m=15e-6, alpha=np.full(21, 0.6),
                                   segments=20, cross_section="collapsed", wall_fraction=0.3,
                                   twist_max_rad=0.3, radius_jitter=0.02), rng)
    case = Case([shape], [-2e-3, -2e-3, -2e-3], [2e-3, 2e-3, 2e-3], dt=2e-9, steps=10_000,
                thermo_every=5000)
    r = run_case(fiberdem_build, tmp_path, case)
    speed = np.linalg.norm(r.final[:, 4:7], axis=1)
    assert speed.max() < 1e-9
    # the fiber is really curved (relative end-to-end distance well below 1)
    ee = np.linalg.norm(shape.x[-1] - shape.x[0]) / 1.0e-3
    assert ee < 0.98


def test_one_and_two_ranks_identical(fiberdem_build: Path, tmp_path: Path) -> None:
    """Chain translating through the rank boundary at z = 0 while vibrating: the final state on
    2 ranks equals the 1-rank state to 1e-10 (relative)."""
    L, n, w = 0.5e-3, 21, 10e-6
    fib = straight_chain(n, L, [w, 0.6 * w, 0.2 * w, 0.1 * w], origin=(0.0, 0.0, -0.45e-3))
    s = (fib.x[:, 2] - fib.x[0, 2]) / L
    start = bent_state(fib, 0.05 * L * np.sin(math.pi * s), 0.05 * math.pi * np.cos(math.pi * s),
                       twist=0.2 * s)
    case = Case([start], [-3e-4, -3e-4, -6e-4], [3e-4, 3e-4, 6e-4], dt=2e-9, steps=4000,
                fix_options="damping 1e-9", commands=["velocity all set 0 0 40"],
                thermo_every=1000, processors="1 1 *")
    one = run_case(fiberdem_build, tmp_path / "np1", case, ranks=1)
    two = run_case(fiberdem_build, tmp_path / "np2", case, ranks=2)
    assert one.final.shape == two.final.shape
    # nodes crossed z = 0 (migrated between the ranks)
    z0 = fib.x[:, 2]
    crossed = np.sum((z0 < 0) & (one.final[:, 3] > 0))
    assert crossed >= 5
    scale = np.abs(one.final[:, 1:]).max(axis=0)
    diff = np.abs(one.final[:, 1:] - two.final[:, 1:]).max(axis=0)
    assert np.all(diff <= 1e-10 * scale), diff / scale


def test_timestep_above_critical_is_an_error(fiberdem_build: Path, tmp_path: Path) -> None:
    L, n, w = 1e-3, 11, 10e-6
    case = Case([straight_chain(n, L, [w, w, 0, 0])], [-1e-4, -1e-4, -1e-4], [1e-4, 1e-4, 1.1e-3],
                dt=1e-6, steps=10)
    with pytest.raises(RuntimeError, match="exceeds the critical step"):
        run_case(fiberdem_build, tmp_path, case)
