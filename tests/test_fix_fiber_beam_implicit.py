# SPDX-License-Identifier: GPL-3.0-or-later
"""Validation of the implicit integrator of fix fiber/beam (issue 9; thesis sec. 2.2: each fiber
solved implicitly every step, generalized-alpha on SO(3), docs/models/beam.md).

Every expected number is computed here, independently of the C++ code: Euler-Bernoulli and
Timoshenko deflection, St-Venant torsion, the elastica (scipy), the first bending frequency,
energy conservation without numerical dissipation, the explicit integrator at a small step for a
large-rotation motion, and the 1-rank run for the 2-rank run. All runs use the real stiffness and
inertia of a wet pulp fiber wall (E 10 GPa, G 4 GPa, 1500 kg/m3): no stiffness_scale or
inertia_scale. Run against ``$FIBERFORM_BUILD`` (default ``<root>/build``).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beam_cases import (  # noqa: E402
    ENV,
    E_WALL,
    G_WALL,
    KSHEAR,
    RHO,
    Case,
    bent_state,
    critical_steps,
    eb_mode1,
    ellipse_section,
    period_from_crossings,
    run_case,
    _read_final,
    straight_chain,
)
from test_fix_fiber_beam import elastica_tip, first_mode_omega  # noqa: E402

pytestmark = pytest.mark.system


@pytest.fixture(scope="module")
def fiberdem_build(build_dir: Path) -> Path:
    exe = build_dir / "bin" / "fiberdem"
    if not exe.is_file():
        pytest.fail(f"{exe} not built: run `make setup`")
    return build_dir


def implicit_case(*args: object, **kw: object) -> Case:
    return Case(*args, integrator="implicit", **kw)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------------
# statics at dt >= 1e-5 s (the explicit critical step of these fibers is 1e-8 s or less)


@pytest.mark.parametrize("direction", ["t2", "t1"])
def test_cantilever_small_tip_load(fiberdem_build: Path, tmp_path: Path, direction: str) -> None:
    """Collapsed section (a1 = 0.8 w, a2 = 0.2 w), both principal axes, dt = 1e-5 s:
    tip deflection = F L^3 / (3 E I) + F L / (k G A) within 1 %."""
    L, n, w = 1e-3, 17, 20e-6
    a1, a2 = 0.8 * w, 0.2 * w
    sec = ellipse_section(a1, a2)
    inertia = sec["I1"] if direction == "t2" else sec["I2"]
    EI = E_WALL * inertia
    F = 3 * EI * 1e-3 * L / L**3
    tau = 1 / (2 * first_mode_omega(EI, RHO * sec["A"], L))
    dt = 1e-5
    force = (0.0, F, 0.0) if direction == "t2" else (F, 0.0, 0.0)
    case = implicit_case(
        [straight_chain(n, L, [a1, a2, 0, 0])], [-5e-4, -5e-4, -1e-4], [5e-4, 5e-4, 1.2e-3],
        dt=dt, steps=max(200, int(30 * tau / dt)), fix_options=f"drag {tau!r} clamp clamp",
        commands=[f"group tip id {n}", "fix load tip addforce {!r} {!r} {!r}".format(*force)],
        thermo_every=100)
    r = run_case(fiberdem_build, tmp_path, case, pre_fix=["group clamp id 1"])
    assert min(critical_steps(r.log).values()) < 1e-3 * dt  # really far beyond the explicit limit
    tip = r.final[-1]
    got = tip[1] if direction == "t1" else tip[2]
    expected = F * L**3 / (3 * EI) + F * L / (KSHEAR * G_WALL * sec["A"])
    assert got == pytest.approx(expected, rel=0.01), (got, expected)


def test_torsion_twist_angle(fiberdem_build: Path, tmp_path: Path) -> None:
    """Hollow circular fiber, end torque T, dt = 1e-5 s: twist = T L / (G J) within 1 %."""
    L, n, a, b = 1e-3, 11, 15e-6, 8e-6
    J = math.pi / 2 * (a**4 - b**4)
    phi = 0.05
    T = phi * G_WALL * J / L
    w_t = math.pi / (2 * L) * math.sqrt(G_WALL / RHO)
    tau = 1 / (2 * w_t)
    dt = 1e-5
    case = implicit_case(
        [straight_chain(n, L, [a, a, b, b])], [-5e-4, -5e-4, -1e-4], [5e-4, 5e-4, 1.2e-3],
        dt=dt, steps=200, fix_options=f"drag {tau!r} torque tip 0 0 {T!r} clamp clamp",
        thermo_every=100)
    r = run_case(fiberdem_build, tmp_path, case, pre_fix=["group clamp id 1", f"group tip id {n}"])
    qw, qx, qy, qz = r.final[-1, 7:11]
    twist = 2 * math.atan2(qz, qw)
    assert abs(qx) < 1e-9 and abs(qy) < 1e-9
    assert twist == pytest.approx(T * L / (G_WALL * J), rel=0.01)


@pytest.mark.parametrize("anderson", [0, 3])
def test_cantilever_large_tip_load_elastica(fiberdem_build: Path, tmp_path: Path, anderson: int) -> None:
    """F L^2 / (E I) = 3, dt = 1e-5 s: tip position vs the elastica (scipy) within 3 %; also with
    Anderson mixing of the Newton corrections (keyword anderson)."""
    L, n, w = 1e-3, 21, 10e-6
    sec = ellipse_section(w, w)
    EI = E_WALL * sec["I1"]
    load = 3.0
    F = load * EI / L**2
    tau = 1 / (2 * first_mode_omega(EI, RHO * sec["A"], L))
    dt = 1e-5
    case = implicit_case(
        [straight_chain(n, L, [w, w, 0, 0])], [-5e-4, -2e-4, -1e-4], [5e-4, 1.2e-3, 1.2e-3],
        dt=dt, steps=max(300, int(40 * tau / dt)), fix_options=f"drag {tau!r} clamp clamp anderson {anderson}",
        commands=[f"group tip id {n}", f"fix load tip addforce 0 {F!r} 0"], thermo_every=100)
    r = run_case(fiberdem_build, tmp_path, case, pre_fix=["group clamp id 1"])
    y_ref, z_ref = elastica_tip(load, L)
    tip = r.final[-1]
    assert tip[2] == pytest.approx(y_ref, rel=0.03), (tip[2], y_ref)
    assert tip[3] == pytest.approx(z_ref, rel=0.03), (tip[3], z_ref)
    assert y_ref > 0.5 * L


# ------------------------------------------------------------------------------------------------
# dynamics


def test_first_bending_frequency(fiberdem_build: Path, tmp_path: Path) -> None:
    """Cantilever started in the first mode shape, default rho_inf, step = period / 20:
    frequency vs (beta1 L)^2 / L^2 sqrt(E I / (rho A)) within 3 %."""
    L, n, w = 0.5e-3, 17, 10e-6
    sec = ellipse_section(w, w)
    om = first_mode_omega(E_WALL * sec["I1"], RHO * sec["A"], L)
    period = 2 * math.pi / om
    fib = straight_chain(n, L, [w, w, 0, 0])
    phi, dphi = eb_mode1(fib.x[:, 2], L)
    amp = 1e-3 * L / phi[-1]
    dt = period / 20
    case = implicit_case([bent_state(fib, amp * phi, amp * dphi)], [-2e-4, -2e-4, -1e-4],
                         [2e-4, 2e-4, 0.7e-3], dt=dt, steps=int(6.2 * period / dt),
                         fix_options="clamp clamp", thermo_every=10, track_atom=n, track_every=1)
    r = run_case(fiberdem_build, tmp_path, case, pre_fix=["group clamp id 1"])
    assert dt > 100 * min(critical_steps(r.log).values())
    y = r.track[:, 1]
    measured_period, ncross = period_from_crossings(np.arange(1, len(y) + 1) * dt, y)
    assert ncross >= 10
    assert 2 * math.pi / measured_period == pytest.approx(om, rel=0.03)


def _bent_twisted_chain() -> tuple[object, float]:
    L, n, w = 0.4e-3, 9, 10e-6
    fib = straight_chain(n, L, [0.8 * w, 0.6 * w, 0, 0])
    s = fib.x[:, 2] / L
    amp = 0.15 * L
    return bent_state(fib, amp * s**2, 2 * amp * s / L, u_x=0.3 * amp * s**3,
                      du_x=0.9 * amp * s**2 / L, twist=0.3 * s), L


def test_energy_drift_without_dissipation(fiberdem_build: Path, tmp_path: Path) -> None:
    """Free-free chain, large bent + twisted initial state, rho_inf = 1 (no numerical
    dissipation), 1e4 steps: total energy drift < 0.5 %. The step is 3/4 of the explicit critical
    step of the stiffest (shear) mode and 1/6 of the bending one: without numerical dissipation the
    nonlinear coupling to unresolved modes makes the energy wander by 1-2 % at 2.5-5x that step and
    grow at 12x (measured, docs/bench/fibers.md); use rho_inf < 1 for large steps."""
    start, _ = _bent_twisted_chain()
    dt = 3e-9
    case = implicit_case([start], [-4e-4, -4e-4, -3e-4], [4e-4, 4e-4, 7e-4], dt=dt, steps=10_000,
                         fix_options="rho_inf 1 newton_tol 1e-10", thermo_every=100)
    r = run_case(fiberdem_build, tmp_path, case)
    e = r.thermo[:, 2]
    assert e[0] > 0 and r.thermo[0, 1] == pytest.approx(e[0])
    assert r.thermo[:, 1].min() < 0.7 * e[0]  # the energy really moved to kinetic
    drift = np.max(np.abs(e - e[0])) / e[0]
    assert drift < 5e-3, drift


@pytest.mark.parametrize("dt", [1e-7, 1e-5])
def test_numerical_dissipation_is_stable(fiberdem_build: Path, tmp_path: Path, dt: float) -> None:
    """The same release at 25x and 2500x the explicit critical step with the default rho_inf:
    the total energy never exceeds its initial value (the scheme only dissipates), and at the
    large step, where no vibration mode is resolved, the elastic energy is damped out."""
    start, _ = _bent_twisted_chain()
    case = implicit_case([start], [-4e-4, -4e-4, -3e-4], [4e-4, 4e-4, 7e-4], dt=dt, steps=2000,
                         thermo_every=100)
    r = run_case(fiberdem_build, tmp_path, case)
    e = r.thermo[:, 2]
    assert np.all(np.isfinite(r.thermo))
    assert np.all(e <= e[0] * (1 + 1e-9)), e.max() / e[0]
    if dt >= 1e-5:  # every vibration mode unresolved (omega h >= 10): damped out
        assert r.thermo[-1, 1] < 1e-3 * e[0]
def test_large_rotation_matches_explicit(fiberdem_build: Path, tmp_path: Path) -> None:
    """A bent, twisted fiber spinning and flopping (rotations of several radians): the implicit
    trajectory at 10x the explicit step (2.5x its critical step) follows the explicit one at a quarter of its critical step
    to within 1 % of the fiber length at every node."""
    L, n, w = 0.4e-3, 9, 10e-6
    fib = straight_chain(n, L, [0.8 * w, 0.6 * w, 0, 0])
    s = fib.x[:, 2] / L
    amp = 0.1 * L
    start = bent_state(fib, amp * s**2, 2 * amp * s / L, twist=0.2 * s)
    # spin at 2e4 rad/s about y through the centre (tip speed 4 m/s; the node frames start without
    # spin and are dragged along by the elements), plus the bend
    commands = ["variable vx atom 2.0e4*(z-2e-4)", "velocity all set v_vx NULL NULL units box"]
    dt_ex = 1e-9
    steps_ex = 200_000  # 0.2 ms: 4 rad at 2e4 rad/s
    ex = run_case(fiberdem_build, tmp_path / "explicit",
                  Case([start], [-1e-3, -1e-3, -1e-3], [1e-3, 1e-3, 1e-3], dt=dt_ex, steps=steps_ex,
                       commands=commands, thermo_every=steps_ex // 10))
    assert dt_ex <= 0.3 * min(critical_steps(ex.log).values())
    im = run_case(fiberdem_build, tmp_path / "implicit",
                  implicit_case([start], [-1e-3, -1e-3, -1e-3], [1e-3, 1e-3, 1e-3], dt=10 * dt_ex,
                                steps=steps_ex // 10, commands=commands, thermo_every=steps_ex // 200,
                                fix_options="newton_tol 1e-10"))
    turned = np.linalg.norm(ex.final[:, 1:4] - start.x_init, axis=1).max()
    assert turned > 0.5 * L  # really a large motion
    diff = np.linalg.norm(ex.final[:, 1:4] - im.final[:, 1:4], axis=1).max()
    assert diff < 0.01 * L, diff / L


def test_one_and_two_ranks_identical(fiberdem_build: Path, tmp_path: Path) -> None:
    """One fiber with nodes on both ranks, translating through the boundary at z = 0 while
    vibrating, implicit at dt = 1e-7: the 2-rank final state equals the 1-rank one to 1e-10."""
    L, n, w = 0.5e-3, 21, 10e-6
    fib = straight_chain(n, L, [w, 0.6 * w, 0.2 * w, 0.1 * w], origin=(0.0, 0.0, -0.45e-3))
    s = (fib.x[:, 2] - fib.x[0, 2]) / L
    start = bent_state(fib, 0.05 * L * np.sin(math.pi * s), 0.05 * math.pi * np.cos(math.pi * s),
                       twist=0.2 * s)
    case = implicit_case([start], [-3e-4, -3e-4, -6e-4], [3e-4, 3e-4, 6e-4], dt=1e-7, steps=800,
                         fix_options="damping 1e-9", commands=["velocity all set 0 0 4"],
                         thermo_every=100, processors="1 1 *")
    one = run_case(fiberdem_build, tmp_path / "np1", case, ranks=1)
    two = run_case(fiberdem_build, tmp_path / "np2", case, ranks=2)
    assert one.final.shape == two.final.shape
    z0 = fib.x[:, 2]
    assert np.sum((z0 < 0) & (one.final[:, 3] > 0)) >= 5  # nodes migrated between the ranks
    assert np.sum(one.final[:, 3] < 0) >= 3                # and the fiber spans both ranks
    scale = np.abs(one.final[:, 1:]).max(axis=0)
    diff = np.abs(one.final[:, 1:] - two.final[:, 1:]).max(axis=0)
    assert np.all(diff <= 1e-10 * scale), diff / scale


def test_tangent_steps_range(fiberdem_build: Path, tmp_path: Path) -> None:
    """tangent_steps (modified Newton across steps) takes an integer in [1, 100000]; the error
    names the keyword and the range."""
    for value in ("0", "100001"):
        case = implicit_case([straight_chain(5, 1e-4, [1e-5, 1e-5, 0, 0])], [-1e-4] * 3, [2e-4] * 3,
                             dt=1e-6, steps=1, fix_options=f"tangent_steps {value}")
        with pytest.raises(RuntimeError, match=r"tangent_steps' must be an integer in \[1, 100000\]"):
            run_case(fiberdem_build, tmp_path / f"ts{value}", case)


def test_landing_choices(fiberdem_build: Path, tmp_path: Path) -> None:
    """landing takes predict or limit."""
    case = implicit_case([straight_chain(5, 1e-4, [1e-5, 1e-5, 0, 0])], [-1e-4] * 3, [2e-4] * 3,
                         dt=1e-6, steps=1, fix_options="landing guess")
    with pytest.raises(RuntimeError, match=r"'landing' takes 'predict' or 'limit'"):
        run_case(fiberdem_build, tmp_path, case)


def test_anderson_range(fiberdem_build: Path, tmp_path: Path) -> None:
    """anderson (mixing depth of the Newton corrections) takes an integer in [0, 8]."""
    for value in ("-1", "9"):
        case = implicit_case([straight_chain(5, 1e-4, [1e-5, 1e-5, 0, 0])], [-1e-4] * 3, [2e-4] * 3,
                             dt=1e-6, steps=1, fix_options=f"anderson {value}")
        with pytest.raises(RuntimeError, match=r"anderson' must be an integer in \[0, 8\]"):
            run_case(fiberdem_build, tmp_path / f"aa{value}", case)


def test_bad_keywords_are_errors(fiberdem_build: Path, tmp_path: Path) -> None:
    for opts, msg in [("rho_inf 1.5", "rho_inf"), ("newton_max 0", "newton_max"),
                      ("integrator verlet", "integrator"), ("max_split 50", "max_split")]:
        case = implicit_case([straight_chain(5, 1e-4, [1e-5, 1e-5, 0, 0])], [-1e-4] * 3, [2e-4] * 3,
                             dt=1e-6, steps=1, fix_options=opts)
        with pytest.raises(RuntimeError, match=msg):
            run_case(fiberdem_build, tmp_path / msg, case)
    # contact keywords: fiber pairs in newton mode without self-contact; the press plate's servo/stop
    for cmds, msg in [(["newton on off", "pair_style fiber/dlvo implicit_force newton self yes", "pair_coeff * *"],
                       "no self_contact .keyword self."),
                      # the fiber pairs' candidate margin needs the drag in the node forces
                      (["newton on off", "pair_style fiber/dlvo implicit_force newton", "pair_coeff * *",
                        "fix drag all fiber/drag flow uniform 0 0 0"], "define fix fiber/drag before pair_style"),
                      (["fix w all wall/fiber/dlvo plane 0 0 -2e-5 0 0 1 servo 1e-6 5e-3 0 1 0 1 "
                        "implicit_force newton"], "p_ref > 0"),
                      (["fix w all wall/fiber/dlvo plane 0 0 -2e-5 0 0 1 servo 1e-6 5e-3 1 2 1e-3 1 0 2 "
                        "implicit_force newton"], "ascend"),
                      (["fix w all wall/fiber/dlvo plane 0 0 -2e-5 0 0 1 velocity 0 0 1e-3 "
                        "servo 1e-6 5e-3 1 1 0 1 implicit_force newton"], "exclude each other"),
                      (["fix w all wall/fiber/dlvo plane 0 0 -2e-5 0 0 1 stop -1e-6"], "stop needs"),
                      # the friction's stick factor: its range, newton mode only, with friction only
                      (["fix w all wall/fiber/dlvo plane 0 0 -2e-5 0 0 1 friction 0.5 friction_stick 0.5 "
                        "implicit_force newton"], "friction_stick must be in"),
                      (["fix w all wall/fiber/dlvo plane 0 0 -2e-5 0 0 1 friction 0.5 friction_stick 10 "
                        "implicit_force impulse"], "friction_stick acts inside the Newton solve only"),
                      (["pair_style fiber/dlvo implicit_force newton friction_stick 10", "pair_coeff * *"],
                       "friction_stick acts with friction > 0 only"),
                      (["pair_style fiber/dlvo integrator cvode friction 0.5", "pair_coeff * *"],
                       "friction between fibers needs implicit_force newton")]:
        case = implicit_case([straight_chain(5, 1e-4, [1e-5, 1e-5, 0, 0])], [-1e-4] * 3, [2e-4] * 3,
                             dt=1e-6, steps=1, commands=cmds)
        with pytest.raises(RuntimeError, match=msg):
            run_case(fiberdem_build, tmp_path / msg.replace(" ", "_").replace(">", "gt"), case)
    # and with explicit fibers, newton is refused
    case = Case([straight_chain(5, 1e-4, [1e-5, 1e-5, 0, 0])], [-1e-4] * 3, [2e-4] * 3, dt=1e-9, steps=1, newton="on",
                commands=["pair_style fiber/dlvo implicit_force newton", "pair_coeff * *"])
    with pytest.raises(RuntimeError, match="needs fix fiber/beam integrator implicit"):
        run_case(fiberdem_build, tmp_path / "explicit_newton", case)


# ------------------------------------------------------------------------------------------------
# thesis 4.1 with implicit fibers at full size (L = 0.1 mm, D = 14 um), real stiffness and inertia,
# fiber step 1 us: more than 100x the explicit critical step of these fibers (checked)

def _implicit_collision_input(tmp_path: Path) -> Path:
    import test_pair_fiber_dlvo as pf

    lines = pf.EXAMPLE.read_text().splitlines()
    out = []
    for ln in lines:
        if ln.startswith("fix          beam all fiber/beam"):
            ln = "fix          beam all fiber/beam nodes ${nodes} E 10e9 G 4e9 density 1500 integrator implicit"
        out.append(ln)
    assert sum("integrator implicit" in ln for ln in out) == 1
    tmp_path.mkdir(parents=True, exist_ok=True)
    path = tmp_path / "in.implicit"
    path.write_text("\n".join(out) + "\n")
    return path


def _explicit_critical_step(log: str) -> float:
    return min(critical_steps(log).values())


def test_collision_4_1_1_implicit(tmp_path: Path) -> None:
    """50 mm/s head-on at dt = 1 us: no pass-through, the moving fiber pushes the other, momentum
    conserved to 1e-6, kinetic energy never above the initial value plus the attractive work
    bound of the explicit tests, and below the initial value at the end (the steric terms
    dissipate)."""
    import test_pair_fiber_dlvo as pf

    v0 = 0.05
    example = _implicit_collision_input(tmp_path)
    out = pf._run(tmp_path / "run", example=example, v0=v0, tend=3.2e-4)
    log = (tmp_path / "run" / "log.fiberdem").read_text()
    assert 1e-6 >= 100 * _explicit_critical_step(log)
    assert np.all(out["v_hsep"] > -0.1 * pf.D)
    assert out["v_vx1"][-1] < -0.3 * v0
    p0 = -pf.M_FIBER * v0
    assert np.all(np.abs(out["v_px"] - p0) <= 1e-6 * abs(p0))
    assert np.all(out["v_kin"] <= pf._ke0(v0) + pf._attractive_work_bound())
    assert out["v_kin"][-1] <= pf._ke0(v0)
    assert out["solves"][-1] > 0


@pytest.mark.parametrize("v0,attached", [(0.01, True), (0.05, False)])
def test_adhesion_4_1_2_implicit(tmp_path: Path, v0: float, attached: bool) -> None:
    """Thesis 4.1.2 with implicit fibers at dt = 1 us: attached at 10 mm/s, separated at 50 mm/s
    (same parameter set and fiber length reduction as the explicit test), momentum conserved."""
    import test_pair_fiber_dlvo as pf

    example = _implicit_collision_input(tmp_path)
    tend = (pf.D + 12e-6 - math.sqrt(pf.D**2 - 12e-6**2)) / v0 + 6e-4
    out = pf._run(tmp_path / "run", example=example, length=pf.L_SHORT, v0=v0, dz=12e-6, tend=tend,
                  every=20)
    assert out["solves"][-1] > 0
    assert bool(pf._separated_at_end(out)) == (not attached)
    if attached:
        assert out["v_hsep"][-1] < 5e-9
    p0 = -pf.M_FIBER * pf.L_SHORT / pf.L * v0
    assert np.all(np.abs(out["v_px"] - p0) <= 1e-6 * abs(p0))
    assert np.all(out["v_kin"] <= pf._ke0(v0, pf.L_SHORT) + pf._attractive_work_bound(pf.L_SHORT))


# ------------------------------------------------------------------------------------------------
# stability: dt from 1e-7 to 1e-4 s, thin and thick fibers, short and long elements, falling in
# drag onto a plane (fix wall/fiber/dlvo) and onto a crossing fiber (pair_style fiber/dlvo)

def _crossing_pair(width: float, element: float, thickness: float | None = None) -> list:
    """Two straight 10-element fibers crossing at right angles above the plane z = 0: the lower
    along x at a surface gap of 0.5 um from the plane, the upper along y 0.5 um above it. With a
    ``thickness``: collapsed sections 2 a1 x 2 a2 = width x thickness lying flat (t2 vertical)."""
    from fiberform.fiber_io import quat_from_frames

    r = width / 2
    t = r if thickness is None else thickness / 2  # the half-thickness along t2 (vertical)
    n = 11
    L = 10 * element
    fibs = []
    for k, (axis, z) in enumerate([(0, t + 0.5e-6), (1, 3 * t + 1.0e-6)]):
        fib = straight_chain(n, L, [r, t, 0, 0])
        x = np.zeros((n, 3))
        x[:, axis] = np.linspace(-L / 2, L / 2, n)
        x[:, 2] = z
        t3 = np.zeros((n, 3))
        t3[:, axis] = 1.0
        t1 = np.zeros((n, 3))
        t1[:, 1 - axis] = 1.0
        t2 = np.cross(t3, t1)
        fib.x = x
        fib.q = quat_from_frames(t1, t2, t3)
        fibs.append(fib)
    return fibs


def _pair_on_plane(width: float, element: float, dt: float, steps: int, newton: bool,
                   thickness: float | None = None, fix_options: str = "") -> Case:
    """The _crossing_pair on the plane z = 0 (fix wall/fiber/dlvo, steric term), pressed onto it
    by a uniform 20 mm/s downward flow; fiber contact pair fiber/dlvo, inside the Newton solve
    (``newton``) or sub-integrated by CVODE."""
    L, r = 10 * element, width / 2
    t = r if thickness is None else thickness / 2
    mode = "implicit_force newton" if newton else "integrator cvode"
    return implicit_case(
        _crossing_pair(width, element, thickness), [-0.6 * L, -0.6 * L, -t], [0.6 * L, 0.6 * L, 6 * r + 5e-6],
        dt=dt, steps=steps, newton="on", fix_options=fix_options,
        commands=[f"fix drag all fiber/drag flow uniform 0 0 {-PAIR_FLOW_M_S!r}",
                  "fix floor all wall/fiber/dlvo plane 0 0 0 0 0 1 terms steric"
                  + (" implicit_force newton" if newton else ""),
                  f"pair_style fiber/dlvo {mode} terms steric", "pair_coeff * *"],
        thermo_every=steps // 3)


#: the downward flow of _pair_on_plane (m/s)
PAIR_FLOW_M_S = 0.02


@pytest.mark.parametrize("dt", [1e-7, 1e-6, 1e-5, 1e-4])
@pytest.mark.parametrize("width,element", [(10e-6, 20e-6), (100e-6, 200e-6)])
@pytest.mark.parametrize("drag", ["yes", "no"])
def test_stability_free_fall_and_drag(fiberdem_build: Path, tmp_path: Path, dt: float, width: float,
                                      element: float, drag: str) -> None:
    """A bent fiber (5 % of its length) released in quiescent water with drag (linearly implicit)
    or falling freely, 300 steps: no NaN, no blow-up: the fiber's energy (elastic + kinetic) never
    exceeds its initial value plus the work gravity (minus buoyancy) can have done on the
    centre-of-mass drop; free fall: the centre of mass falls at g_eff t within 1 %."""
    L = 10 * element
    fib = straight_chain(11, L, [width / 2, width / 2, 0, 0], origin=(0.0, 0.0, -L / 2))
    s = np.linspace(0, 1, 11)
    start = bent_state(fib, 0.05 * L * np.sin(math.pi * s), 0.05 * math.pi * np.cos(math.pi * s))
    steps = 300
    case = implicit_case([start], [-L, -L, -1.0], [L, L, 1.0], dt=dt, steps=steps,
                         commands=[f"fix drag all fiber/drag flow uniform 0 0 0 drag {drag}"],
                         thermo_every=steps // 3)
    res = run_case(fiberdem_build, tmp_path, case)
    fin = res.final
    assert np.all(np.isfinite(fin[:, 1:7])) and np.all(np.isfinite(res.thermo))
    g_eff = 9.81 * (1500.0 - 998.2) / 1500.0
    w = np.ones(11)
    w[0] = w[-1] = 0.5                       # end nodes carry half an element's mass
    mass = 1500.0 * math.pi * (width / 2) ** 2 * L
    drop = float(np.sum(w * (start.x_init[:, 2] - fin[:, 3])) / np.sum(w))
    e0, e_end = res.thermo[0, 2], res.thermo[-1, 2]
    assert e_end <= e0 * (1 + 1e-6) + mass * g_eff * max(drop, 0.0) * (1 + 1e-3) + 1e-30, (e0, e_end)
    if drag == "no":
        vcom = float(np.sum(w * fin[:, 6]) / np.sum(w))
        assert vcom == pytest.approx(-g_eff * dt * steps, rel=0.01)


@pytest.mark.parametrize("dt,width,element", [
    (1e-7, 10e-6, 20e-6), (1e-6, 10e-6, 20e-6),
    (1e-7, 100e-6, 200e-6), (1e-6, 100e-6, 200e-6), (1e-5, 100e-6, 200e-6),
])
def test_stability_drag_plane_and_fiber_contact(fiberdem_build: Path, tmp_path: Path, dt: float,
                                                width: float, element: float) -> None:
    """No NaN, no blow-up (every node slower than 3x the flow speed), no pass-through of the
    plane (every node centre above it) or of the other fiber (the upper fiber stays above the
    lower one where they cross), after the fibers have reached each other and the plane.
    Not covered (measured, docs/models/beam.md): the 10 um fiber at 1e-5 s (the upper fiber passed
    through the lower one) and both at 1e-4 s (the thin one passed through; the thick case took
    9 minutes of CVODE work)."""
    r = width / 2
    u_flow = PAIR_FLOW_M_S
    steps = 300
    case = _pair_on_plane(width, element, dt, steps, newton=False)
    res = run_case(fiberdem_build, tmp_path, case)
    fin = res.final
    assert np.all(np.isfinite(fin[:, 1:7]))
    speed = np.linalg.norm(fin[:, 4:7], axis=1)
    assert speed.max() < 3 * u_flow, speed.max()
    assert fin[:, 3].min() > 0.0, fin[:, 3].min()  # node centres above the plane
    lower, upper = fin[:11], fin[11:]
    # where they cross (the middle nodes), the upper fiber's centre is above the lower one's
    assert upper[5, 3] > lower[5, 3] + r, (upper[5, 3], lower[5, 3])
    # they did fall onto each other and onto the plane (each started 0.5 um apart): at least half
    # of both gaps closed. (Until session 26 this read "the upper fiber's centre at most 0.1 um
    # above its start", which also held for fibers that never touched, and which the averaged
    # contact's chatter at 1e-5 s (about +-1 um, docs/stages/laydown.md) broke with another
    # build's round-off: the pair, in contact, 0.25 um above the start after 3 ms; the two builds'
    # trajectories part from 1e-20 m at 25 steps to 0.6 um at 150 steps, as a bouncing contact does.)
    if dt * steps >= 1e-4:
        assert upper[5, 3] - lower[5, 3] - 2 * r < 0.25e-6, (upper[5, 3], lower[5, 3])
        assert lower[:, 3].min() - r < 0.25e-6, lower[:, 3].min()


@pytest.mark.parametrize("dt", [1e-5, 1e-4])
def test_thin_fiber_in_fast_flow_with_implicit_drag(fiberdem_build: Path, tmp_path: Path,
                                                     dt: float) -> None:
    """A straight 10 um fiber in a 0.1 m/s downward flow: its drag relaxation time m/(dF/dv) is
    about 2e-5 s, so a lagged (explicit) drag is unstable at 1e-4 s (measured: `implicit no` lost
    every node out of the box); with the Jacobian from fix fiber/drag every node ends at the flow
    speed plus the small terminal slip of its weight (< 1 mm/s)."""
    L = 0.2e-3
    fib = straight_chain(11, L, [5e-6, 5e-6, 0, 0], origin=(0.0, 0.0, -L / 2))
    case = implicit_case([fib], [-L, -L, -1.0], [L, L, 1.0], dt=dt, steps=300,
                         commands=["fix drag all fiber/drag flow uniform 0 0 -0.1 implicit yes"],
                         thermo_every=100)
    fin = run_case(fiberdem_build, tmp_path, case).final
    assert fin.ndim == 2 and fin.shape[0] == 11  # no node lost
    vz = fin[:, 6]
    assert np.all(np.isfinite(vz))
    assert np.all(np.abs(vz + 0.1) < 1e-3), vz


@pytest.mark.parametrize("dt,width,element", [
    (1e-5, 10e-6, 20e-6), (1e-4, 10e-6, 20e-6), (1e-6, 100e-6, 200e-6), (1e-4, 100e-6, 200e-6),
])
def test_plane_inside_the_newton_solve(fiberdem_build: Path, tmp_path: Path, dt: float, width: float,
                                       element: float) -> None:
    """fix wall/fiber/dlvo `implicit_force newton` (the plane inside each fiber's Newton solve,
    docs/models/contact.md section 8): a fiber pressed onto the plane by a 20 mm/s downward flow at
    steps up to 1e-4 s (the averaged force of the other modes is not covered there). No NaN; after
    30 ms the fiber lies within 1 % of its radius of the surface (no pass-through), at rest.
    Not covered (measured): the 100 um fiber at 1e-5 s lands but then rocks off the plane with
    growing energy (10 mm/s, 250 nm above it after 30 ms); docs/models/contact.md section 8. The
    100 um fiber at 1e-4 s is only checked for no pass-through and no blow-up: since the Newton
    backtracking at contact kinks (physics/implicit_rod.h) it still rocks after 30 ms (part of it
    3.2 um above the plane, measured)."""
    fib = _crossing_pair(width, element)[0]
    L = 10 * element
    r = width / 2
    u_flow = 0.02
    steps = round(0.03 / dt)  # 30 ms
    case = implicit_case(
        [fib], [-0.6 * L, -0.6 * L, -r], [0.6 * L, 0.6 * L, 6 * r + 5e-6], dt=dt, steps=steps,
        newton="on",
        commands=[f"fix drag all fiber/drag flow uniform 0 0 {-u_flow!r}",
                  "fix floor all wall/fiber/dlvo plane 0 0 0 0 0 1 terms steric implicit_force newton"],
        thermo_every=steps // 3)
    fin = run_case(fiberdem_build, tmp_path, case).final
    assert fin.shape[0] == 11 and np.all(np.isfinite(fin[:, 1:7]))
    gap = fin[:, 3] - r
    assert gap.min() > -0.01 * r, gap.min()          # on the surface, not through it
    if dt >= 1e-4 and width >= 100e-6:               # see the docstring: no rest asserted
        assert np.linalg.norm(fin[:, 4:7], axis=1).max() < u_flow
        return
    assert gap.max() < 0.05 * r, gap.max()           # and it did land (started 0.5 um above)
    assert np.linalg.norm(fin[:, 4:7], axis=1).max() < 1e-3 * u_flow


@pytest.mark.parametrize("plane", [True, False])
def test_limited_iterations_are_counted(fiberdem_build: Path, tmp_path: Path, plane: bool) -> None:
    """f_beam[21], the mean Newton iterations per fiber and step whose correction a contact
    model's limiter shortened (landings, docs/models/contact.md section 8): a fiber released 0.5 um
    above a plane (in the Newton solve) and pressed onto it by a 20 mm/s flow lands, so some of its
    iterations were shortened, never more than it made (f_beam[19]); without the plane none were."""
    fib = _crossing_pair(10e-6, 20e-6)[0]
    L, r, dt = 200e-6, 5e-6, 1e-5
    steps = 1000  # 10 ms: landed (0.5 um at 20 mm/s: 25 us)
    floor = ["fix floor all wall/fiber/dlvo plane 0 0 0 0 0 1 terms steric implicit_force newton"] if plane else []
    case = implicit_case(
        [fib], [-0.6 * L, -0.6 * L, -r], [0.6 * L, 0.6 * L, 6 * r + 5e-6], dt=dt, steps=steps, newton="on",
        commands=["fix drag all fiber/drag flow uniform 0 0 -0.02", *floor,
                  "variable it equal f_beam[19]", "variable lim equal f_beam[21]",
                  f'fix counters all print {steps} "${{it}} ${{lim}}" file counters.txt screen no'],
        thermo_every=steps)
    run_case(fiberdem_build, tmp_path, case)
    rows = [line.split() for line in (tmp_path / "counters.txt").read_text().splitlines()
            if line and not line.startswith("#")]
    iterations, limited = (float(v) for v in rows[-1])
    print(f"plane {plane}: {iterations:.3f} Newton iterations per step, {limited:.4f} shortened")
    assert iterations >= 1.0
    if plane:
        assert 0.0 < limited <= iterations
    else:
        assert limited == 0.0


@pytest.mark.parametrize("ranks", [1, 2])
def test_ribbon_pair_inside_the_newton_solve(fiberdem_build: Path, tmp_path: Path, ranks: int) -> None:
    """Collapsed fibers (2 a1 x 2 a2 = 20 x 5 um, lying flat) in the Newton-solve contacts: they
    touch as the thesis' rectangles (docs/models/contact.md section 9, "Sections"), not as circles
    of a1. The pair of test_fiber_pair_inside_the_newton_solve pressed by the 20 mm/s flow at
    1e-5 s, 1 and 2 ranks: after 10 ms the lower ribbon rests on the plane at its half-thickness a2
    and the upper one on it at 3 a2 where they cross (closed form), within 5 % of a2 (circles of
    a1 would put them at a1 = 4 a2 and 3 a1); the two runs agree to 1e-9 m."""
    width, thickness, element, dt = 20e-6, 5e-6, 20e-6, 1e-5
    t = thickness / 2
    case = _pair_on_plane(width, element, dt, round(0.01 / dt), newton=True, thickness=thickness)
    fin = run_case(fiberdem_build, tmp_path, case, ranks=ranks).final
    assert fin.shape[0] == 22 and np.all(np.isfinite(fin[:, 1:7]))
    lower, upper = fin[:11], fin[11:]
    assert abs(lower[:, 3] - t).max() < 0.05 * t, lower[:, 3] - t        # the lower ribbon on the plane
    assert abs(upper[5, 3] - 3 * t) < 0.05 * t, upper[5, 3] - 3 * t      # the upper one on the lower one
    if ranks == 2:
        ref = run_case(fiberdem_build, tmp_path / "r1", case, ranks=1).final
        assert np.abs(fin[:, 1:4] - ref[:, 1:4]).max() < 1e-9


@pytest.mark.parametrize("dt,width,element,anderson,landing", [
    (1e-6, 10e-6, 20e-6, 0, "limit"), (1e-5, 10e-6, 20e-6, 0, "limit"), (1e-4, 10e-6, 20e-6, 0, "limit"),
    (1e-6, 100e-6, 200e-6, 0, "limit"), (1e-5, 100e-6, 200e-6, 0, "limit"), (1e-4, 100e-6, 200e-6, 0, "limit"),
    (1e-5, 10e-6, 20e-6, 3, "limit"), (1e-4, 100e-6, 200e-6, 3, "limit"),
    (1e-5, 10e-6, 20e-6, 3, "predict"), (1e-4, 100e-6, 200e-6, 0, "predict"),
])
def test_fiber_pair_inside_the_newton_solve(fiberdem_build: Path, tmp_path: Path, dt: float, width: float,
                                            element: float, anderson: int, landing: str) -> None:
    """pair_style fiber/dlvo and fix wall/fiber/dlvo `implicit_force newton` (the two crossing fibers
    solved together in one Newton solve with their contact, docs/models/contact.md section 9): the
    upper fiber pressed by a 20 mm/s downward flow onto the lower one, which lies on the plane, at
    steps from 1e-6 to 1e-4 s, including the cases the averaged contact does not cover (10 um at
    1e-5 and 1e-4 s, 100 um at 1e-4 s). After 30 ms: no NaN, no blow-up (every node slower than
    10 % of the flow), the lower fiber on the plane and the upper one on the lower one where they
    cross, both within 1 % of the radius of touching (closed form: centres r and 3 r above the
    plane); also with Anderson mixing of the Newton corrections (anderson 3) at two of the steps,
    and with the landing predictor (landing predict) at two.
    Not asserted: rest. Measured after 30 ms: below 2e-5 m/s at 1e-6 s; the upper fiber's
    free ends still move at 3e-5 m/s (10 um, 1e-5 s), 8e-5 m/s (100 um, 1e-5 s) and 1.7e-3 m/s
    (100 um, 1e-4 s) while they sag under the flow."""
    r = width / 2
    u_flow = PAIR_FLOW_M_S
    case = _pair_on_plane(width, element, dt, round(0.03 / dt), newton=True,  # 30 ms
                          fix_options=f"anderson {anderson} landing {landing}")
    fin = run_case(fiberdem_build, tmp_path, case).final
    assert fin.shape[0] == 22 and np.all(np.isfinite(fin[:, 1:7]))
    lower, upper = fin[:11], fin[11:]
    assert abs(lower[:, 3] - r).max() < 0.01 * r, lower[:, 3] - r       # the lower fiber on the plane
    assert abs(upper[5, 3] - 3 * r) < 0.01 * r, upper[5, 3] - 3 * r     # the upper one on the lower one
    assert np.linalg.norm(fin[:, 4:7], axis=1).max() < 0.1 * u_flow


def _pair_in_cross_flow(fiber_friction: float, steps: int, dt: float) -> Case:
    """The _crossing_pair (10 um fibers, 20 um elements) on the plane z = 0 in a uniform flow
    (4, 0, -20) mm/s: the lower fiber (along x) held by the plane's friction 2, the upper one
    (along y) pressed onto it and dragged sideways along the lower one's axis; pair_style
    fiber/dlvo inside the Newton solve with Coulomb friction ``fiber_friction`` between them (stick
    factor 1000: a stuck contact creeps at F_t / c_stick, c_stick = k m_eff / dt)."""
    width, element = 10e-6, 20e-6
    L, r = 10 * element, width / 2
    pair = "pair_style fiber/dlvo implicit_force newton terms steric"
    if fiber_friction > 0.0:
        pair += f" friction {fiber_friction!r} friction_stick 1000"
    return implicit_case(
        _crossing_pair(width, element), [-0.6 * L, -0.6 * L, -r], [0.6 * L, 0.6 * L, 6 * r + 5e-6],
        dt=dt, steps=steps, newton="on",
        commands=[f"fix drag all fiber/drag flow uniform {0.2 * PAIR_FLOW_M_S!r} 0 {-PAIR_FLOW_M_S!r}",
                  "fix floor all wall/fiber/dlvo plane 0 0 0 0 0 1 terms steric implicit_force newton "
                  "friction 2.0",
                  pair, "pair_coeff * *"],
        thermo_every=steps)


def test_fiber_friction_holds_a_fiber_on_another(fiberdem_build: Path, tmp_path: Path) -> None:
    """pair_style fiber/dlvo `friction` (fiber-fiber Coulomb friction inside the Newton solve,
    docs/models/contact.md section 9): the upper fiber of _pair_in_cross_flow is pushed sideways
    with 0.2 of the force that presses it on the lower one. Frictionless (the thesis' law) it slides
    along the lower fiber with the flow (more than half of 4 mm/s x 10 ms = 40 um); with
    friction 0.5 > 0.2 it stays stuck: relative to the lower fiber it moves by less than 2 % of
    that (measured 0.29 um: the landing and the regularisation's creep; 1.4 um with the default
    stick factor 100). The lower fiber stays on its plane in both (less than 1 um; it creeps there
    by 0.36 um under the plane's friction). (The keyword is refused outside implicit_force newton:
    test_bad_keywords_are_errors.)"""
    dt, steps = 1e-5, 1000
    x0 = np.vstack([f.x for f in _crossing_pair(10e-6, 20e-6)])
    free = run_case(fiberdem_build, tmp_path / "free", _pair_in_cross_flow(0.0, steps, dt)).final
    held = run_case(fiberdem_build, tmp_path / "held", _pair_in_cross_flow(0.5, steps, dt)).final
    ux_t = 0.2 * PAIR_FLOW_M_S * dt * steps
    # the upper fiber's mean motion along x relative to the lower one's (which creeps on its plane)
    slid = float(np.mean(free[11:, 1] - x0[11:, 0]) - np.mean(free[:11, 1] - x0[:11, 0]))
    crept = float(np.mean(held[11:, 1] - x0[11:, 0]) - np.mean(held[:11, 1] - x0[:11, 0]))
    assert slid > 0.5 * ux_t, (slid, ux_t)
    assert abs(crept) < 0.02 * slid, (crept, slid)
    for fin in (free, held):
        assert np.abs(fin[:11, 1:4] - x0[:11]).max() < 1e-6
        assert np.all(np.isfinite(fin[:, 1:7]))


def _split_memory_case(steps: int, restart_every: int = 0) -> Case:
    """The pair of test_fiber_pair_inside_the_newton_solve at 1e-5 s with at most 4 Newton iterations
    per attempt (so that the landing steps are split) and `split_memory 5`; a new tangent in every
    step (tangent_steps 1: the held tangent is not in restart files); the per-step sub-step splits
    and split-memory start depth (f_beam[16], f_beam[22]) printed to split.txt."""
    case = _pair_on_plane(10e-6, 20e-6, 1e-5, steps, newton=True,
                          fix_options="newton_max 4 tangent_steps 1 split_memory 5")
    case.commands += ["variable sp equal f_beam[16]", "variable sd equal f_beam[22]",
                      'fix splitlog all print 1 "${sp} ${sd}" file split.txt screen no']
    if restart_every:
        case.commands.append(f"restart {restart_every} r.*.restart")
    return case


def test_split_memory_on_two_ranks_and_across_a_restart(fiberdem_build: Path, tmp_path: Path) -> None:
    """fix fiber/beam `split_memory` (physics/implicit_rod.h remember_split; the memory is per-node
    state that migrates with the atoms and is written to restart files): on _split_memory_case over
    10 ms some steps start already split (start depth > 0) and the memory has relaxed to whole
    steps at the end (the pair at rest); the pair lands as without it, on the closed form (lower
    fiber's centres r above the plane, upper one 3 r where they cross, within 1 % of r); the same
    run on 2 ranks (the pair across the rank boundary) ends within 1e-9 m, and a run resumed from
    its restart file at step 20, while the memory holds split starts, ends identical to the bit to
    the uninterrupted one (the memory read back with the atoms; zeroed, it ends elsewhere)."""
    steps, r, k = 1000, 5e-6, 20
    one = run_case(fiberdem_build, tmp_path / "np1", _split_memory_case(steps, restart_every=k))
    log = np.loadtxt(tmp_path / "np1" / "split.txt", ndmin=2)  # rows: steps 1, 2, ...
    assert log[:, 1].max() >= 1, "no step started split: the memory did not act"
    assert log[k, 1] >= 1, log[:k + 2, 1]  # the step after the restart starts split: memory in the file
    assert log[-1, 1] == 0, log[-20:, 1]
    lower, upper = one.final[:11], one.final[11:]
    assert abs(lower[:, 3] - r).max() < 0.01 * r, lower[:, 3] - r
    assert abs(upper[5, 3] - 3 * r) < 0.01 * r, upper[5, 3] - 3 * r
    two = run_case(fiberdem_build, tmp_path / "np2", _split_memory_case(steps), ranks=2)
    assert np.abs(two.final[:, 1:4] - one.final[:, 1:4]).max() < 1e-9
    # resumed at step k from the uninterrupted run's restart file: its input with the atoms read
    # from that file (units, atom style, boundary and newton come with it) and the rest of the run
    res = tmp_path / "resumed"
    res.mkdir()
    for name in ("nodes.fib", f"r.{k}.restart"):
        (res / name).symlink_to(tmp_path / "np1" / name)
    text = []
    for line in (tmp_path / "np1" / "in.case").read_text().splitlines():
        word = line.split(" ", 1)[0]
        if word in ("atom_style", "boundary", "newton", "restart"):
            continue
        if word == "read_data":
            line = f"read_restart r.{k}.restart"
        if word == "run":
            line = f"run {steps - k}"
        text.append(line)
    (res / "in.case").write_text("\n".join(text) + "\n")
    proc = subprocess.run([str(fiberdem_build / "bin" / "fiberdem"), "-in", "in.case", "-log", "log.case",
                           "-screen", "none"], cwd=res, env=ENV, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, (res / "log.case").read_text()[-3000:] if (res / "log.case").exists() else proc.stdout
    resumed = _read_final(res / "final.dump")
    assert np.array_equal(resumed[:, 1:7], one.final[:, 1:7]), np.abs(resumed[:, 1:7] - one.final[:, 1:7]).max()
