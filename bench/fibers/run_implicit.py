#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/fibers (implicit): the implicit integrator of fix fiber/beam against the explicit one at
real stiffness and inertia (no scaling). Pinned inputs below. Writes results/implicit.json and
results/implicit.png; docs/bench/fibers.md explains the numbers.

Measured:
* accuracy vs dt: first bending frequency of a cantilever (circular 10 um, 0.5 mm, 16 elements)
  against beta1 L = 1.8751, and the static tip deflection of the collapsed-section cantilever of
  run_bench.py, for the implicit integrator over dt = period/5 .. period/160 and the explicit one
  at 0.5 x its critical step;
* cost: wall time per simulated ms per node (the time LIGGGHTS reports for its run loop, "Loop
  time", which leaves out process start, input and set-up), and the CPU time of the process minus
  that of a run without steps (the same when the machine is idle, and less sensitive to other jobs
  when it is not); Newton iterations and tangent formations per fiber and step, wall time per
  Newton iteration per node;
* the step each integrator needs for 1 % frequency accuracy, and the speed-up at equal accuracy
  (explicit time / implicit time for the same simulated time, wall and CPU).

Usage: python bench/fibers/run_implicit.py [--build BUILD] [--repeat N] [--fix-extra "KEYWORDS"]
(--fix-extra: more fix fiber/beam keywords for the implicit runs, e.g. "tangent_steps 1" to form
the tangent anew in every step as before modified Newton across steps)
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import resource
import statistics
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "scripts"))
from beam_cases import (  # noqa: E402
    E_WALL, KSHEAR, G_WALL, RHO, Case, bent_state, critical_steps, eb_mode1, ellipse_section,
    period_from_crossings, run_case, straight_chain,
)

OUT = Path(__file__).resolve().parent / "results"
LF, NF, WF = 0.5e-3, 17, 10e-6          # frequency cantilever: length, nodes, radius (circular)
LS, NS, WS = 1e-3, 17, 20e-6            # static cantilever: collapsed a1 = 0.8 w, a2 = 0.2 w
PERIODS = 100.0                          # simulated periods of the frequency runs
DIVISIONS = [5, 10, 20, 40, 80, 160]     # implicit steps per period


def omega1(EI: float, rhoA: float, L: float) -> float:
    return 1.8751040687**2 / L**2 * math.sqrt(EI / rhoA)


def loop_time(log: str) -> float:
    """The wall time of the run loop that LIGGGHTS prints ("Loop time of T on P procs ...", s)."""
    m = re.findall(r"^Loop time of ([0-9.eE+-]+) on", log, flags=re.M)
    if not m:
        raise RuntimeError("no 'Loop time' in the LIGGGHTS log")
    return float(m[-1])


def child_cpu() -> float:
    """CPU time (user + system, s) of the finished child processes so far."""
    u = resource.getrusage(resource.RUSAGE_CHILDREN)
    return u.ru_utime + u.ru_stime


_STARTUP_CPU: list[float] = []


def startup_cpu(build: Path, work: Path) -> float:
    """Median CPU time of a run with no steps (process start, input, set-up), subtracted from the
    CPU time of every run."""
    if not _STARTUP_CPU:
        case = Case([straight_chain(NF, LF, [WF, WF, 0, 0])], [-1e-4] * 3, [1e-4, 1e-4, 1e-3], dt=1e-9,
                    steps=0, integrator="implicit")
        ts = []
        for _ in range(5):
            c0 = child_cpu()
            run_case(build, work, case)
            ts.append(child_cpu() - c0)
        _STARTUP_CPU.append(statistics.median(ts))
    return _STARTUP_CPU[0]


def timed(build: Path, work: Path, case: Case, repeat: int, **kw):
    """Median and spread of the loop time (wall) over `repeat` runs, and the median and spread of
    the CPU time minus that of a run without steps (less sensitive to other jobs on the machine)."""
    base = startup_cpu(build, work.parent / "startup")
    times, cpus, r = [], [], None
    for _ in range(repeat):
        c0 = child_cpu()
        r = run_case(build, work, case, **kw)
        cpus.append(max(child_cpu() - c0 - base, 1e-6))
        times.append(loop_time(r.log))
    return r, (statistics.median(times), max(times) - min(times), statistics.median(cpus), max(cpus) - min(cpus))


def frequency_run(build: Path, work: Path, integrator: str, dt: float, repeat: int, fix_extra: str = "") -> dict:
    sec = ellipse_section(WF, WF)
    om = omega1(E_WALL * sec["I1"], RHO * sec["A"], LF)
    period = 2 * math.pi / om
    fib = straight_chain(NF, LF, [WF, WF, 0, 0])
    phi, dphi = eb_mode1(fib.x[:, 2], LF)
    amp = 1e-3 * LF / phi[-1]
    steps = int(PERIODS * period / dt)
    # the tip is written about 20 times per period in every run (explicit and implicit alike)
    every = max(1, round(steps / (20 * PERIODS)))
    case = Case([bent_state(fib, amp * phi, amp * dphi)], [-2e-4, -2e-4, -1e-4], [2e-4, 2e-4, 0.7e-3],
                dt=dt, steps=steps, integrator=integrator, fix_options=f"clamp clamp {fix_extra}".strip(),
                # Newton iterations and tangent formations per step, averaged over the run by the fix
                # (f_beam[19], f_beam[20]) and printed once, at the end
                commands=["variable it equal f_beam[19]", "variable tg equal f_beam[20]",
                          f'fix itp all print {steps} "${{it}} ${{tg}}" file iters.txt screen no'],
                thermo_every=max(1, steps // 50), track_atom=NF, track_every=every)
    r, (wall, spread, cpu, cpu_spread) = timed(build, work, case, repeat, pre_fix=["group clamp id 1"])
    its = np.loadtxt(work / "iters.txt", ndmin=2)
    mean_it = float(np.mean(its[:, 0])) if integrator == "implicit" and its.size else math.nan
    mean_tg = float(np.mean(its[:, 1])) if integrator == "implicit" and its.size else math.nan
    y = r.track[:, 1]
    meas, _ = period_from_crossings(np.arange(1, len(y) + 1) * every * dt, y)
    sim_ms = steps * dt * 1e3
    return {"integrator": integrator, "dt_s": dt, "steps": steps, "steps_per_period": period / dt,
            "frequency_error": (2 * math.pi / meas) / om - 1 if meas == meas else math.nan,
            "wall_s_median": wall, "wall_s_spread": spread,
            "wall_s_per_sim_ms_per_node": wall / sim_ms / NF,
            "cpu_s_median": cpu, "cpu_s_spread": cpu_spread, "cpu_s_per_sim_ms_per_node": cpu / sim_ms / NF,
            "explicit_critical_s": min(critical_steps(r.log).values()),
            "newton_iterations_per_step": mean_it, "tangents_per_step": mean_tg,
            "wall_s_per_iteration_per_node": wall / (steps * mean_it * NF) if mean_it == mean_it else math.nan}


def static_run(build: Path, work: Path, integrator: str, dt: float, repeat: int, fix_extra: str = "") -> dict:
    a1, a2 = 0.8 * WS, 0.2 * WS
    sec = ellipse_section(a1, a2)
    EI = E_WALL * sec["I1"]
    F = 3 * EI * 1e-3 * LS / LS**3
    tau = 1 / (2 * omega1(EI, RHO * sec["A"], LS))
    steps = max(100, int(30 * tau / dt))
    case = Case([straight_chain(NS, LS, [a1, a2, 0, 0])], [-6e-4, -6e-4, -1e-4], [6e-4, 6e-4, 1.2e-3],
                dt=dt, steps=steps, integrator=integrator, fix_options=f"drag {tau!r} clamp clamp {fix_extra}".strip(),
                commands=[f"group tip id {NS}", f"fix load tip addforce 0 {F!r} 0"],
                thermo_every=max(1, steps // 10))
    r, (wall, spread, _, _) = timed(build, work, case, repeat, pre_fix=["group clamp id 1"])
    exact = F * LS**3 / (3 * EI) + F * LS / (KSHEAR * G_WALL * sec["A"])
    return {"integrator": integrator, "dt_s": dt, "steps": steps, "relative_error": r.final[-1, 2] / exact - 1,
            "wall_s_median": wall, "wall_s_spread": spread}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", type=Path, default=Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--fix-extra", default="", help="more fix fiber/beam keywords for the implicit runs")
    args = ap.parse_args()
    build = args.build.resolve()
    work = Path(os.environ.get("TMPDIR", "/tmp")) / "fiberform-bench-implicit"
    OUT.mkdir(parents=True, exist_ok=True)
    sec = ellipse_section(WF, WF)
    period = 2 * math.pi / omega1(E_WALL * sec["I1"], RHO * sec["A"], LF)
    res: dict = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
                 "inputs": {"frequency_cantilever": {"L_m": LF, "nodes": NF, "radius_m": WF},
                            "static_cantilever": {"L_m": LS, "nodes": NS, "w_m": WS},
                            "E_Pa": E_WALL, "G_Pa": G_WALL, "density_kg_m3": RHO, "rho_inf": 0.5,
                            "repeat": args.repeat, "period_s": period, "fix_extra": args.fix_extra},
                 "timing": "median and spread over the repeats of the LIGGGHTS loop time (wall) and of the CPU time minus a 0-step run"}
    # explicit reference at half its critical step
    probe = run_case(build, work / "probe", Case([straight_chain(NF, LF, [WF, WF, 0, 0])], [-1e-4] * 3,
                                                  [1e-4, 1e-4, 1e-3], dt=1e-15, steps=0))
    dt_ex = 0.5 * min(critical_steps(probe.log).values())
    res["frequency"] = [frequency_run(build, work / "fex", "explicit", dt_ex, args.repeat)]
    for div in DIVISIONS:
        res["frequency"].append(frequency_run(build, work / f"fim{div}", "implicit", period / div, args.repeat,
                                              args.fix_extra))
    res["static"] = [static_run(build, work / "sex", "explicit",
                                0.5 * min(critical_steps(run_case(build, work / "probe2", Case(
                                    [straight_chain(NS, LS, [0.8 * WS, 0.2 * WS, 0, 0])], [-1e-4] * 3,
                                    [1e-4, 1e-4, 1.1e-3], dt=1e-15, steps=0)).log).values()), 1)]
    for dt in (1e-7, 1e-6, 1e-5, 1e-4):
        res["static"].append(static_run(build, work / f"sim{dt:g}", "implicit", dt, args.repeat, args.fix_extra))
    # equal accuracy: the largest implicit step within 1 % of the frequency vs the explicit run
    ok = [r for r in res["frequency"][1:] if abs(r["frequency_error"]) <= 0.01]
    best = max(ok, key=lambda r: r["dt_s"]) if ok else None
    ex = res["frequency"][0]
    res["equal_accuracy"] = {
        "criterion": "first bending frequency within 1 %",
        "explicit": {"dt_s": ex["dt_s"], "frequency_error": ex["frequency_error"],
                     "wall_s_per_sim_ms_per_node": ex["wall_s_per_sim_ms_per_node"],
                     "cpu_s_per_sim_ms_per_node": ex["cpu_s_per_sim_ms_per_node"]},
        "implicit": None if best is None else {"dt_s": best["dt_s"], "frequency_error": best["frequency_error"],
                                               "wall_s_per_sim_ms_per_node": best["wall_s_per_sim_ms_per_node"],
                                               "cpu_s_per_sim_ms_per_node": best["cpu_s_per_sim_ms_per_node"]},
        "speedup": None if best is None else ex["wall_s_per_sim_ms_per_node"] / best["wall_s_per_sim_ms_per_node"],
        "speedup_cpu": None if best is None else ex["cpu_s_per_sim_ms_per_node"] / best["cpu_s_per_sim_ms_per_node"],
    }
    (OUT / "implicit.json").write_text(json.dumps(res, indent=2) + "\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        im = [r for r in res["frequency"] if r["integrator"] == "implicit"]
        ax[0].loglog([r["dt_s"] for r in im], [abs(r["frequency_error"]) + 1e-6 for r in im], "o-", label="implicit")
        ax[0].loglog([ex["dt_s"]], [abs(ex["frequency_error"]) + 1e-6], "s", label="explicit (0.5 critical)")
        ax[0].axhline(0.01, color="grey", lw=0.5)
        ax[0].set_xlabel("time step (s)")
        ax[0].set_ylabel("|first frequency error|")
        ax[0].legend()
        ax[1].loglog([r["dt_s"] for r in im], [r["wall_s_per_sim_ms_per_node"] for r in im], "o-", label="implicit")
        ax[1].loglog([ex["dt_s"]], [ex["wall_s_per_sim_ms_per_node"]], "s", label="explicit")
        ax[1].set_xlabel("time step (s)")
        ax[1].set_ylabel("wall s per simulated ms per node")
        ax[1].legend()
        fig.suptitle("fix fiber/beam: implicit vs explicit, real stiffness (bench/fibers/run_implicit.py)")
        fig.tight_layout()
        fig.savefig(OUT / "implicit.png", dpi=110)
        plt.close(fig)
    except ImportError:
        pass
    res["startup_cpu_s"] = _STARTUP_CPU[0] if _STARTUP_CPU else None
    (OUT / "implicit.json").write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps(res["equal_accuracy"], indent=2))
    for r in res["frequency"]:
        print(f"{r['integrator']:8s} dt {r['dt_s']:.3g} s ({r['steps_per_period']:.0f}/period): "
              f"frequency error {r['frequency_error']:+.4f}, {r['wall_s_per_sim_ms_per_node']:.3g} s/ms/node, "
              f"{r['newton_iterations_per_step']:.2f} it/step, {r['tangents_per_step']:.3f} tangents/step, "
              f"{r['wall_s_per_iteration_per_node']:.3g} s/it/node, loop {r['wall_s_median']:.3f} s "
              f"(spread {r['wall_s_spread']:.3f}), CPU {r['cpu_s_median']:.3f} s (spread {r['cpu_s_spread']:.3f})")
    for r in res["static"]:
        print(f"{r['integrator']:8s} dt {r['dt_s']:.3g} s: static error {r['relative_error']:+.5f}, wall {r['wall_s_median']:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
