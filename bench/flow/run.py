#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Mesh convergence of the bare-fabric flow: cells vs run time vs flow rate.

Pinned inputs: the default double-layer fabric (fiberform.fabric_geometry.WeaveParams defaults)
cut to a 1 x 1 mm piece, voxel image at 5 um, water (998.2 kg/m3, 1e-3 Pa s), delta_p = 100 Pa,
1 mm of fluid above the fabric, 2 mm below, residual 1e-6. For each CFD cell size the script runs
the flow stage's case (blockMesh + topoSet + subsetMesh + simpleFoam) ``--repeats`` times and
records the median and spread of the wall time, the cell counts, the SIMPLE iterations and the
superficial velocity Q/A; the flow-rate change relative to the finest mesh measures convergence.

    .venv/bin/python bench/flow/run.py [--cells 50e-6 35e-6 25e-6] [--repeats 1] [--ranks 1]

Writes bench/flow/results/flow_bench.json and flow_bench.png (see docs/bench/flow.md).
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from fiberform.openfoam_case import make_lattice
from fiberform.provenance import machine_info
from fiberform.scene import FabricSection, FlowSection, FluidSection
from fiberform.stages.fabric import make_fabric
from fiberform.stages.flow import FlowSetup, run_flow_case

HERE = Path(__file__).resolve().parent


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=float, nargs="+", default=[50e-6, 35e-6, 25e-6])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--delta-p", type=float, default=100.0)
    ap.add_argument("--out", type=Path, default=HERE / "results")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    t0 = time.monotonic()
    fab = make_fabric(FabricSection(size_x_m=1.0e-3, size_y_m=1.0e-3, voxel_size_m=5e-6))
    img = fab.image
    assert img is not None and fab.yarns is not None
    yarns = [(y.points, y.radius) for y in fab.yarns]
    t_fabric = time.monotonic() - t0
    rows = []
    with tempfile.TemporaryDirectory(prefix="fiberform-bench-flow-") as tmp:
        for h in args.cells:
            flow = FlowSection(cell_size_m=h, delta_p_Pa=args.delta_p, ranks=args.ranks)
            s = FlowSetup.from_scene(img, flow, FluidSection())
            lat = make_lattice(s)
            walls, solver_walls, res = [], [], None
            for r in range(args.repeats):
                t = time.monotonic()
                res = run_flow_case(s, img, Path(tmp) / f"h{h:g}_{r}", yarns=yarns,
                                    show_progress=False)  # fmt: skip
                walls.append(time.monotonic() - t)
                solver_walls.append(res.wall_times_s["simpleFoam"])
            assert res is not None
            row = {
                "cell_size_m": h,
                "lattice_cells": lat.cells,
                "fluid_cells": res.fluid_cells,
                "fabric_zone_cells_per_warp_diameter": 0.11e-3 / h,
                "iterations": res.iterations,
                "converged": res.converged,
                "wall_time_s_median": statistics.median(walls),
                "wall_time_s_spread": max(walls) - min(walls),
                "simpleFoam_time_s_median": statistics.median(solver_walls),
                "superficial_velocity_m_s": res.q_bottom_m3_s / (s.size_x_m * s.size_y_m),
                "flow_rate_top_m3_s": res.q_top_m3_s,
                "flow_rate_bottom_m3_s": res.q_bottom_m3_s,
                "imbalance": res.imbalance,
                "ranks": args.ranks,
                "repeats": args.repeats,
            }
            rows.append(row)
            print(
                f"h = {h * 1e6:5.1f} um: {res.fluid_cells:7d} fluid cells, {res.iterations:5d} it, "
                f"{row['wall_time_s_median']:7.1f} s, U_s = {row['superficial_velocity_m_s']:.5g} m/s, "
                f"imbalance {res.imbalance:.1e}",
                flush=True,
            )
    finest = min(rows, key=lambda r: r["cell_size_m"])
    for r in rows:
        r["flow_rate_change_vs_finest"] = (
            r["superficial_velocity_m_s"] / finest["superficial_velocity_m_s"] - 1.0
        )
    result = {
        "benchmark": "bare-fabric flow, mesh convergence",
        "inputs": {
            "fabric": "WeaveParams defaults, 1 x 1 mm piece, voxel 5 um",
            "delta_p_Pa": args.delta_p,
            "fluid": "water 998.2 kg/m3, 1e-3 Pa s",
            "height_above_fabric_m": 1e-3,
            "fabric_lower_side_m": 2e-3,
            "residual_tolerance": 1e-6,
        },
        "fabric_generation_s": t_fabric,
        "machine": machine_info(),
        "rows": rows,
    }
    (args.out / "flow_bench.json").write_text(json.dumps(result, indent=2) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = np.array([r["fluid_cells"] for r in rows])
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].loglog(cells, [r["wall_time_s_median"] for r in rows], "o-")
    ax[0].set_xlabel("fluid cells")
    ax[0].set_ylabel("wall time (mesh + solve) [s]")
    ax[0].set_title(f"run time, {args.ranks} rank(s)")
    ax[1].semilogx(cells, [r["superficial_velocity_m_s"] * 1e3 for r in rows], "o-")
    for r in rows:
        ax[1].annotate(f"{r['cell_size_m'] * 1e6:.0f} um", (r["fluid_cells"], r["superficial_velocity_m_s"] * 1e3))
    ax[1].set_xlabel("fluid cells")
    ax[1].set_ylabel("superficial velocity Q/A [mm/s]")
    ax[1].set_title(f"bare fabric at delta_p = {args.delta_p:g} Pa")
    fig.tight_layout()
    fig.savefig(args.out / "flow_bench.png", dpi=110)
    print(f"wrote {args.out / 'flow_bench.json'} and flow_bench.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
