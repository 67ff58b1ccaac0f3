#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/coupling/run_closed_box: the closed-box balance of two-way coupling (docs/coupling/
formulation.md, "Known errors"). A horizontal fiber (0.3 mm, radius 10 um, 1500 kg/m3) settles in
water at rest between walls at z = 0 and 1 mm (periodic in x, y; openfoam-cases/couette with the lid
at rest, 4 x 4 x 8 cells), fiberdem + fiberPimpleFoam -coupled, interval 100 x 1e-7 s, 3 ms.
For both reaction kernels and two fiber heights (a cell-layer centre, a cell face) it records, at
1, 2 and 3 ms, relative to the net weight W - B = (rho_s - rho_f) pi r^2 L g:
  F      the reaction the fluid received (sum of fiberSource V rho),
  dpA    (mean p of the bottom cell layer - mean p of the top layer) x wall area,
  visc   the walls' discrete normal viscous force rho nu sum(w_wall cells) / (h/2) x face area,
  dmom   the rate of change of the cell-centred vertical momentum sum(rho w V) over the last step;
and, at 3 ms, the fiber's mean vertical velocity and the fluid's in the cells of its nodes (the
velocity the fiber induced where it samples the flow: no undisturbed-velocity correction).
Writes results/closed_box.json and prints a table. Usage: python bench/coupling/run_closed_box.py
(about 15 s; FIBERFORM_BUILD selects the build, default build/).
"""
from __future__ import annotations

import json
import os
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "scripts"))
import test_coupling as tc  # noqa: E402
from beam_cases import RHO, run_case  # noqa: E402
from foamlib import FoamCase  # noqa: E402

BUILD = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()
NU = 1.001803245842517e-06       # openfoam-cases/couette transportProperties (m2/s)
H_CELL, AREA = tc.H / 8, 1e-6   # m, m2
NET = (RHO - tc.RHO_F) * np.pi * 1e-10 * 0.3e-3 * 9.81  # N
CONFIGS = [("cell", 0.5625e-3), ("cell", 0.5e-3), ("trilinear", 0.5625e-3), ("trilinear", 0.5e-3)]


def run_one(work: Path, kernel: str, z: float) -> list[dict[str, float]]:
    fluid = tc.couette_case(work / "fluid", lid=0.0)
    case = tc.fiber_case([f"fix couple all fiber/coupling drag drag interval 100 timeout 120 "
                          f"kernel {kernel}"], 30000, horizontal=True)
    case.commands = [c for c in case.commands if not c.startswith("velocity")]
    case.fibers[0].x[:, 2] += z - 0.5625e-3
    res = run_case(BUILD, work / "dem", case, timeout_s=600,
                   partner=[BUILD / "bin" / "fiberPimpleFoam", "-coupled", "-case", fluid])
    foam = FoamCase(fluid)
    vol = np.asarray(foam[0]["V"].internal_field)
    layer = np.rint(np.asarray(foam[0]["C"].internal_field)[:, 2] / H_CELL - 0.5).astype(int)
    # the velocity the fiber induced in its own cells (no undisturbed-velocity correction) at 3 ms
    centres = np.asarray(foam[0]["C"].internal_field)
    w_end = np.asarray(foam[300]["U"].internal_field)[:, 2]
    own = [int(np.argmin(((centres - x) ** 2).sum(axis=1))) for x in res.final[:, 1:4]]
    induced = {"fiber_vz_m_s": float(res.final[:, 6].mean()), "fluid_w_own_cells_m_s": float(w_end[own].mean())}
    rows = []
    for k in (100, 200, 300):
        t, dt = foam[k].time, foam[k].time - foam[k - 1].time
        p = np.asarray(foam[k]["p"].internal_field) * tc.RHO_F
        w, w0 = (np.asarray(foam[j]["U"].internal_field)[:, 2] for j in (k, k - 1))
        src = np.asarray(foam[k]["fiberSource"].internal_field)[:, 2]
        rows.append({
            "time_s": t,
            "F": -(src * vol).sum() * tc.RHO_F / NET,
            "dpA": (p[layer == 0].mean() - p[layer == 7].mean()) * AREA / NET,
            "visc": tc.RHO_F * NU * (w[layer == 0].sum() + w[layer == 7].sum()) / (H_CELL / 2)
            * (AREA / 16) / NET,
            "dmom": tc.RHO_F * ((w - w0) * vol).sum() / dt / NET,
            **(induced if k == 300 else {}),
        })
    return rows


def main() -> None:
    out = Path(__file__).resolve().parent / "results"
    out.mkdir(exist_ok=True)
    results = []
    for kernel, z in CONFIGS:
        with tempfile.TemporaryDirectory(prefix="closed_box_") as tmp:
            rows = run_one(Path(tmp), kernel, z)
        for r in rows:
            results.append({"kernel": kernel, "fiber_z_m": z, **r})
            print(f"{kernel:9s} z={z * 1e3:.4f} mm t={r['time_s'] * 1e3:.0f} ms  F/net {r['F']:.4f}  "
                  f"dpA/net {r['dpA']:.4f}  visc/net {r['visc']:.4f}  dmom/net {r['dmom']:.4f}"
                  + (f"  fiber vz {r['fiber_vz_m_s']:.3e} m/s, fluid w in its cells "
                     f"{r['fluid_w_own_cells_m_s']:.3e} m/s" if "fiber_vz_m_s" in r else ""))
    (out / "closed_box.json").write_text(json.dumps(
        {"machine": platform.node(), "net_weight_N": NET, "rows": results}, indent=1) + "\n")


if __name__ == "__main__":
    main()
