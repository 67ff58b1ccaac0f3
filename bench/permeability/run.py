#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Air permeability benchmarks (issue 12): resolution study, random 2D fiber mats against published
laws, wall time per mode on the demo sheet and a synthetic case-A sheet.

    .venv/bin/python bench/permeability/run.py [--part resolution mats timing] [--size small|full]

* ``resolution``: a two-layer grid of straight fibers (radius a = 10 um; fibers along x in the lower
  layer, along y in the upper one, spacing 2.5 d; through the symmetry sides this is an infinite
  grid) in resolved mode at 4, 8, 16 (``--size full``: also 32) cells across the fiber, air at
  Re << 1: Darcy k of the layer, iterations, wall time, peak memory of the largest OpenFOAM
  process, observed order of convergence from the three finest; sub-grid mode on the same grid
  (cells of 1.25 d, both laws) against the finest resolved k.
* ``mats``: random 2D mats (straight fibers lying in the plane, random position and direction,
  freely overlapping, in a 25 a x 25 a x 10 a box, 2 realizations (``full``: 30 a x 30 a x 12 a,
  4) at solid fractions 0.05-0.3), resolved at ``--mat-across`` cells across, flow across the mat
  at Re < 0.1; k / a^2 of the whole mat (mu u_s T / delta_p; also from the plane-mean pressures at
  1/4 and 3/4 of the mat, noisy with few fibers) against Tomadakis & Sotirchos (2D
  random, flow perpendicular to the fiber plane) and Jackson & James (random 3D).
* ``timing``: the demo sheet (scenes/demo.yaml lay-down, run into a temporary folder) and a
  synthetic case-A sheet (thesis Table 4.2: 35.7 ug of fibers on 3 x 3 mm; straight fibers of the
  demo's dimensions dropped flat on the fabric top at random) through ``fiberform permeability``
  at 125 Pa, per mode: wall time, cells, iterations, CFM.

Writes bench/permeability/results/<part>.json (and <part>.png) and prints the tables
(docs/bench/permeability.md); ``--replot`` redraws the PNGs from the JSON files.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt
import yaml

from fiberform.openfoam_case import BoxSetup, CaseResult, make_lattice, run_case
from fiberform.porous_media import (
    capsule_fraction, flow_rate_convergence, jackson_james, line_fraction, subgrid_resistance,
    tomadakis_sotirchos,
)  # fmt: skip
from fiberform.products import FABRIC_H5, FIBERS_H5, LAYDOWN_H5, read_fabric_image
from fiberform.provenance import machine_info
from fiberform.scene import read_scene_yaml

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
RHO, MU = 1.204, 1.81e-5  # air
A = 10e-6  # fiber radius of the resolution study and the mats [m]
FloatArray = npt.NDArray[np.float64]
Chains = list[tuple[FloatArray, float]]


def peak_child_rss_MiB() -> float:
    """Largest resident set of any finished child process so far (the OpenFOAM tools) [MiB]."""
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0


def solve(s: BoxSetup, chains: Chains, work: Path, mode: str, law: str = "jackson_james",
          window: int = 200) -> tuple[CaseResult, dict[str, Any]]:  # fmt: skip
    """One case as the permeability stage builds it: resolved (capsule sampling, volume-preserving
    removal) or subgrid (no removal, Darcy resistance from line_fraction and ``law``)."""
    t0 = time.monotonic()
    if mode == "resolved":
        res = run_case(s, lambda s_, lat: capsule_fraction(chains, s_, lat, 4), work,
                       record_flow_rate=True, preserve_volume=True, show_progress=False)  # fmt: skip
    else:
        res = run_case(
            s, lambda s_, lat: np.zeros((lat.nx, lat.ny, lat.n_fabric), np.float32), work,
            record_flow_rate=True, show_progress=False,
            resistance=lambda s_, lat: subgrid_resistance(line_fraction(chains, s_, lat), A, law),
        )  # fmt: skip
    wall = time.monotonic() - t0
    conv = flow_rate_convergence(res.history_q_bottom_m3_s, window, 1e-4)
    shutil.rmtree(work, ignore_errors=True)
    area = s.size_x_m * s.size_y_m
    u = res.q_bottom_m3_s / area
    return res, {
        "lattice_cells": res.lattice_cells, "fluid_cells": res.fluid_cells,
        "iterations": res.iterations, "residual_converged": res.converged,
        "flow_rate_window_relative_range": conv.relative_amplitude,
        "superficial_velocity_m_s": u, "imbalance": res.imbalance,
        "reynolds_superficial": RHO * u * 2 * A / MU,
        "reynolds_max_cell": RHO * float(np.max(np.linalg.norm(res.U, axis=-1))) * 2 * A / MU,
        "wall_time_s": wall, "peak_child_rss_MiB": peak_child_rss_MiB(),
    }  # fmt: skip


# ---- resolution study ------------------------------------------------------------------------


def grid_chains(period: float, z0: float, centred: bool) -> Chains:
    """The two-layer grid in a box of one period (centred: fibers through the box centre) or of
    half a period (fibers on the side planes x = 0, y = 0; the symmetry planes mirror them)."""
    c = 0.5 * period if centred else 0.0
    w = period if centred else 0.5 * period
    return [(np.array([[-A, c, z0 + A], [w + A, c, z0 + A]]), A),
            (np.array([[c, -A, z0 + 3 * A], [c, w + A, z0 + 3 * A]]), A)]  # fmt: skip


def grid_setup(width: float, h: float, z0: float, iterations: int, dp: float) -> BoxSetup:
    return BoxSetup(size_x_m=width, size_y_m=width, fabric_lo_z_m=z0, fabric_hi_z_m=z0 + 4 * A,
                    top_z_m=z0 + 4 * A + z0, cell_size_m=h, max_cell_height_m=8 * h, delta_p_Pa=dp,
                    density_kg_m3=RHO, viscosity_Pa_s=MU, max_iterations=iterations,
                    residual_tolerance=1e-9)  # fmt: skip


def part_resolution(size: str, tmp: Path) -> dict[str, Any]:
    period, z0, dp = 5 * A, 4 * A, 1.0
    across = [4, 8, 16] + ([32] if size == "full" else [])
    iterations = {4: 2000, 8: 4000, 16: 10000, 32: 30000}
    rows = []
    for n in across:
        h = 2 * A / n
        s = grid_setup(0.5 * period, h, z0, iterations[n], dp)
        res, row = solve(s, grid_chains(period, z0, centred=False), tmp / f"res{n}", "resolved")
        lat = make_lattice(s)
        row.update(cells_across_fiber=n, cell_size_m=h,
                   solid_fraction=float(res.solid_fraction.sum()) / (lat.nx * lat.ny * lat.n_fabric),
                   darcy_k_m2=MU * row["superficial_velocity_m_s"] * 4 * A / dp)  # fmt: skip
        rows.append(row)
        print(f"resolved {n:2d} across: k = {row['darcy_k_m2']:.5e} m^2, {row['fluid_cells']} cells, "
              f"{row['iterations']} it, {row['wall_time_s']:.1f} s, "
              f"{row['peak_child_rss_MiB']:.0f} MiB", flush=True)  # fmt: skip
    k = [r["darcy_k_m2"] for r in rows]
    order = None
    if len(k) >= 3:
        k1, k2, k3 = k[-3], k[-2], k[-1]  # h, h/2, h/4 ratio 2
        if (k2 - k1) * (k3 - k2) > 0:
            order = math.log(abs(k2 - k1) / abs(k3 - k2)) / math.log(2.0)
            richardson = k3 + (k3 - k2) / (2**order - 1)
        else:
            richardson = float("nan")
    else:
        richardson = float("nan")
    for r in rows:
        r["change_vs_finest"] = r["darcy_k_m2"] / k[-1] - 1
        r["error_vs_richardson"] = r["darcy_k_m2"] / richardson - 1 if order else float("nan")
    sub = []
    for law in ("jackson_james", "drummond_tahir"):
        s = grid_setup(period, 1.25 * 2 * A, z0, 2000, dp)
        _, row = solve(s, grid_chains(period, z0, centred=True), tmp / f"sub_{law}", "subgrid", law)
        row.update(law=law, cell_size_m=s.cell_size_m,
                   darcy_k_m2=MU * row["superficial_velocity_m_s"] * 4 * A / dp)  # fmt: skip
        row["vs_finest_resolved"] = row["darcy_k_m2"] / k[-1] - 1
        row["vs_richardson"] = row["darcy_k_m2"] / richardson - 1 if order else float("nan")
        sub.append(row)
        print(f"subgrid {law}: k = {row['darcy_k_m2']:.5e} m^2 ({row['vs_finest_resolved']:+.3f} vs "
              f"finest resolved), {row['wall_time_s']:.1f} s", flush=True)  # fmt: skip
    return {"geometry": "two-layer grid of straight fibers, a = 10 um, spacing 2.5 d = 50 um, layer "
                        "4 a thick; resolved: half-period box (25 um), subgrid: one period (50 um)",
            "pressure_drop_Pa": dp, "resolved": rows, "observed_order": order,
            "richardson_k_m2": richardson, "subgrid": sub}  # fmt: skip


# ---- random 2D mats --------------------------------------------------------------------------


def random_mat(rng: np.random.Generator, phi: float, width: float, z0: float,
               thickness: float) -> Chains:  # fmt: skip
    """Straight in-plane fibers through the box (random centre, direction and height, freely
    overlapping) until the nominal volume reaches -ln(1 - phi) of the box (the fraction of a
    Boolean model of overlapping fibers is 1 - exp(-nominal))."""
    target = -math.log(1.0 - phi) * width * width * thickness
    vol, chains = 0.0, []
    while vol < target:
        c = rng.uniform(0.0, width, 2)
        th = rng.uniform(0.0, math.pi)
        z = rng.uniform(z0 + A, z0 + thickness - A)
        d = np.array([math.cos(th), math.sin(th)])
        # chord of the box along d through c
        ts = []
        for k in range(2):
            if abs(d[k]) > 1e-12:
                ts += [(0.0 - c[k]) / d[k], (width - c[k]) / d[k]]
        lo = max(t for t in ts if t <= 0) if any(t <= 0 for t in ts) else 0.0
        hi = min(t for t in ts if t >= 0) if any(t >= 0 for t in ts) else 0.0
        p, q = c + lo * d, c + hi * d
        vol += math.pi * A * A * float(np.linalg.norm(q - p))
        chains.append((np.array([[p[0], p[1], z], [q[0], q[1], z]]), A))
    return chains


def part_mats(size: str, across: int, tmp: Path, seed: int) -> dict[str, Any]:
    width, thickness, realizations = (25 * A, 10 * A, 2) if size == "small" else (30 * A, 12 * A, 4)
    z0, dp = 4 * A, 0.05
    rows = []
    rng = np.random.default_rng(seed)
    for phi in (0.05, 0.1, 0.2, 0.3):
        for rep in range(realizations):
            chains = random_mat(rng, phi, width, z0, thickness)
            h = 2 * A / across
            s = BoxSetup(size_x_m=width, size_y_m=width, fabric_lo_z_m=z0,
                         fabric_hi_z_m=z0 + thickness, top_z_m=2 * z0 + thickness, cell_size_m=h,
                         max_cell_height_m=8 * h, delta_p_Pa=dp, density_kg_m3=RHO,
                         viscosity_Pa_s=MU, max_iterations=6000, residual_tolerance=1e-8)  # fmt: skip
            res, row = solve(s, chains, tmp / f"mat{phi:g}_{rep}", "resolved")
            lat = make_lattice(s)
            frac = res.solid_fraction[:, :, lat.n_below:lat.n_below + lat.n_fabric]
            phi_meas = float(frac.sum()) / frac.size
            q = lat.n_fabric // 4
            k_lo, k_hi = lat.n_below + q, lat.n_below + lat.n_fabric - 1 - q
            p_lo, p_hi = float(np.nanmean(res.p[:, :, k_lo])), float(np.nanmean(res.p[:, :, k_hi]))
            dz = float(res.lattice_z[k_hi] - res.lattice_z[k_lo])
            u = row["superficial_velocity_m_s"]
            k_in = MU * u * dz / (p_hi - p_lo)
            k_tot = MU * u * thickness / dp
            ts = float(tomadakis_sotirchos(np.array(phi_meas), A))
            jj = float(jackson_james(np.array(phi_meas), A))
            row.update(target_solid_fraction=phi, realization=rep, solid_fraction=phi_meas,
                       fibers=len(chains), cells_across_fiber=across, k_over_a2=k_tot / A**2,
                       k_over_a2_mid_planes=k_in / A**2, tomadakis_sotirchos_k_over_a2=ts / A**2,
                       jackson_james_k_over_a2=jj / A**2, vs_tomadakis_sotirchos=k_tot / ts - 1,
                       vs_jackson_james=k_tot / jj - 1)  # fmt: skip
            rows.append(row)
            print(f"mat phi {phi_meas:.3f} ({len(chains)} fibers): k/a^2 {k_tot / A**2:.4g} (mid "
                  f"planes {k_in / A**2:.4g}), T-S {ts / A**2:.4g} ({k_tot / ts - 1:+.2f}), J-J "
                  f"{jj / A**2:.4g} ({k_tot / jj - 1:+.2f}); {row['fluid_cells']} cells, "
                  f"{row['iterations']} it, {row['wall_time_s']:.0f} s, Re "
                  f"{row['reynolds_max_cell']:.1e}", flush=True)  # fmt: skip
    return {"box_m": [width, width, thickness], "seed": seed, "pressure_drop_Pa": dp,
            "realizations": realizations, "rows": rows}  # fmt: skip


# ---- timing on sheets ------------------------------------------------------------------------

MODES = {
    "subgrid 50 um": {"mode": "subgrid", "subgrid_cell_size_m": 50e-6},
    "subgrid 25 um": {"mode": "subgrid", "subgrid_cell_size_m": 25e-6},
}


def fiberform(args: list[str], cwd: Path) -> float:
    env = dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"))
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "fiberform", *args], cwd=cwd, env=env,
                       capture_output=True, text=True, errors="replace", check=False)  # fmt: skip
    if r.returncode != 0:
        raise RuntimeError(f"fiberform {' '.join(args)} failed:\n{r.stdout[-3000:]}{r.stderr[-3000:]}")
    return time.monotonic() - t0


def permeability_runs(scene: dict[str, Any], work: Path, modes: list[str]) -> list[dict[str, Any]]:
    rows = []
    for name in modes:
        sc = json.loads(json.dumps(scene))
        sc["permeability"] = {**sc.get("permeability", {}), **MODES[name]}
        (work / "s.yaml").write_text(yaml.safe_dump(sc, sort_keys=False))
        wall = fiberform(["permeability", "s.yaml", "--force"], work)
        out = work / sc["output_dir"] / "permeability-laydown" / "permeability.h5"
        with h5py.File(out) as f:
            r, sv = f["result"], f["solver"].attrs
            row = {"mode": name, "wall_time_s": wall, "lattice_cells": int(sv["lattice_cells"]),
                   "fluid_cells": int(sv["fluid_cells"]), "iterations": int(sv["iterations"]),
                   "simpleFoam_s": float(sv["wall_time_simpleFoam_s"]),
                   "cfm": float(r["cfm"][()]), "cfm_uncertainty": float(r["cfm_uncertainty"][()]),
                   "converged": bool(r.attrs["converged"]), "peak_child_rss_MiB": peak_child_rss_MiB()}  # fmt: skip
        rows.append(row)
        print(f"  {name}: {row['cfm']:.4g} +- {row['cfm_uncertainty']:.2g} CFM, "
              f"{row['lattice_cells']} cells, {row['iterations']} it, {wall:.0f} s", flush=True)
    return rows


def case_a_sheet(root: Path, rng: np.random.Generator, fibers: dict[str, Any], top: float,
                 size: float, mass_kg: float) -> int:  # fmt: skip
    """Synthetic case-A sheet: straight fibers of the scene's dimensions, random centre and
    in-plane direction, lying flat in a layer of 3 diameters on the fabric top (overlaps allowed),
    written as the lay-down and generate stages write their products. Returns the fiber count."""
    r, length, nodes = 0.5 * fibers["width_m"], fibers["length_m"], fibers["segments"] + 1
    m_fiber = fibers.get("density_kg_m3", 1500.0) * math.pi * r * r * length
    n = max(1, round(mass_kg / m_fiber))
    xs = []
    for _ in range(n):
        th = rng.uniform(0.0, math.pi)
        half = 0.5 * length * np.array([math.cos(th), math.sin(th)])
        c = rng.uniform(np.abs(half) + r, size - np.abs(half) - r)
        z = top + r + rng.uniform(0.0, 4 * r)
        t = np.linspace(-1.0, 1.0, nodes)[:, None]
        xy = c + t * half
        xs.append(np.column_stack([xy, np.full(nodes, z)]))
    (root / "laydown").mkdir(parents=True, exist_ok=True)
    (root / "fibers").mkdir(parents=True, exist_ok=True)
    with h5py.File(root / LAYDOWN_H5, "w") as f:
        f["sheet/x"] = np.concatenate(xs)
        f["sheet/offsets"] = np.arange(n + 1) * nodes
        f["sheet/fiber_id"] = np.arange(n)
    with h5py.File(root / FIBERS_H5, "w") as f:
        f["fibers/offsets"] = np.arange(n + 1) * nodes
        f["fibers/radii"] = np.tile([r, r, 0.0, 0.0], (n * nodes, 1))
    return n


def part_timing(tmp: Path, modes: list[str], seed: int) -> dict[str, Any]:
    demo = read_scene_yaml((ROOT / "scenes" / "demo.yaml").read_text())
    out: dict[str, Any] = {"modes": modes}
    # demo sheet: the demo's own lay-down
    work = tmp / "demo"
    work.mkdir()
    demo["output_dir"] = "runs/demo"
    (work / "s.yaml").write_text(yaml.safe_dump(demo, sort_keys=False))
    up = {st: fiberform([st, "s.yaml"], work) for st in ("generate", "fabric", "flow", "laydown")}
    print(f"demo sheet: upstream stages {up}", flush=True)
    out["demo"] = {"upstream_s": up, "rows": permeability_runs(demo, work, modes)}
    # synthetic case-A sheet on 3 x 3 mm
    work = tmp / "caseA"
    work.mkdir()
    sc = {k: demo[k] for k in ("format_version", "name", "seed", "run", "fibers", "permeability") if k in demo}
    sc.update(name="caseA", output_dir="runs/caseA", laydown={},
              fabric={"size_x_m": 3.0e-3, "size_y_m": 3.0e-3})  # fmt: skip
    sc["fibers"] = {k: v for k, v in sc["fibers"].items() if k != "target_mass_kg"}
    mass = 35.7e-9  # kg, Kettil 2016 Table 4.2, case A
    (work / "s.yaml").write_text(yaml.safe_dump(sc, sort_keys=False))
    t_fab = fiberform(["fabric", "s.yaml"], work)
    root = work / "runs" / "caseA"
    top = float(read_fabric_image(root / FABRIC_H5).upper[2])
    n = case_a_sheet(root, np.random.default_rng(seed), sc["fibers"], top, 3.0e-3, mass)
    sc["fibers"]["count"] = n
    print(f"case-A sheet: {n} fibers ({mass * 1e9:.1f} ug), fabric {t_fab:.0f} s", flush=True)
    out["case_a"] = {"fibers": n, "mass_kg": mass, "fabric_s": t_fab,
                     "rows": permeability_runs(sc, work, modes)}  # fmt: skip
    return out


def plot(part: str, res: dict[str, Any], path: Path) -> None:
    """resolution.png: k vs cells across; mats.png: k / a^2 vs solid fraction with the laws."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.5))
    if part == "resolution":
        rows = res["resolved"]
        ax.semilogx([r["cells_across_fiber"] for r in rows], [r["darcy_k_m2"] for r in rows], "ko-",
                    base=2, label="resolved")  # fmt: skip
        for r, m in zip(res["subgrid"], ("s", "^"), strict=True):
            ax.axhline(r["darcy_k_m2"], ls="--", color="0.5")
            ax.plot([], [], "--", color="0.5", marker=m, label=f"subgrid ({r['law']})")
            ax.annotate(r["law"], (4, r["darcy_k_m2"]))
        if res["observed_order"]:
            ax.axhline(res["richardson_k_m2"], color="r", lw=0.8, label="Richardson extrapolation")
        ax.set_xlabel("cells across the fiber")
        ax.set_ylabel("Darcy k of the layer [m^2]")
        ax.set_title("two-layer fiber grid, air, Re < 0.2")
    elif part == "mats":
        rows = res["rows"]
        phi = np.linspace(0.03, 0.35, 100)
        ax.semilogy(phi, tomadakis_sotirchos(phi, 1.0), "b-", label="Tomadakis-Sotirchos 2D, through-plane")
        ax.semilogy(phi, jackson_james(phi, 1.0), "g--", label="Jackson-James")
        ax.semilogy([r["solid_fraction"] for r in rows], [r["k_over_a2"] for r in rows], "ko",
                    label="resolved random mats")  # fmt: skip
        ax.set_xlabel("solid fraction")
        ax.set_ylabel("k / a^2")
        ax.set_title("random 2D fiber mats, flow across the mat")
    else:
        plt.close(fig)
        return
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", nargs="+", choices=["resolution", "mats", "timing"],
                    default=["resolution", "mats", "timing"])  # fmt: skip
    ap.add_argument("--size", choices=["small", "full"], default="small",
                    help="full: 32 cells across in the resolution study, larger mats")
    ap.add_argument("--mat-across", type=int, default=4, help="cells across a fiber in the mats")
    ap.add_argument("--modes", nargs="+", choices=list(MODES), default=list(MODES))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=HERE / "results")
    ap.add_argument("--replot", action="store_true", help="only redraw the PNGs from the JSON files")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.replot:
        for part in args.part:
            if (args.out / f"{part}.json").is_file():
                plot(part, json.loads((args.out / f"{part}.json").read_text()), args.out / f"{part}.png")
        return 0
    for part in args.part:
        print(f"== {part} ==", flush=True)
        t0, machine = time.monotonic(), machine_info()
        with tempfile.TemporaryDirectory(prefix=f"fiberform-bench-perm-{part}-") as tmp:
            if part == "resolution":
                res = part_resolution(args.size, Path(tmp))
            elif part == "mats":
                res = part_mats(args.size, args.mat_across, Path(tmp), args.seed)
            else:
                res = part_timing(Path(tmp), args.modes, args.seed)
        res.update(part=part, size=args.size, machine=machine,
                   total_wall_time_s=time.monotonic() - t0,
                   command=" ".join(["bench/permeability/run.py", *sys.argv[1:]]))  # fmt: skip
        path = args.out / f"{part}.json"
        path.write_text(json.dumps(res, indent=2) + "\n")
        plot(part, res, args.out / f"{part}.png")
        print(f"wrote {path} ({res['total_wall_time_s']:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
