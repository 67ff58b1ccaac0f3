#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Lay-down cost on 1 and 2 MPI ranks: wall time per simulated ms, node-steps per second, the
2-rank speed-up, and the contact state of the sheet (yarn clearance and fiber-fiber gap).

Pinned inputs: scenes/demo.yaml (20 fibers of 0.8 mm on 1 x 1 mm, implicit real fibers at 1 us)
run for a fixed simulated time (``--time``, settle check disabled so every run covers the same
steps); with ``--case-a`` also the demo scaled to the thesis' case A piece (3 x 3 mm fabric,
35.7 ug of 1.6 mm fibers, 32 elements each). Every variant runs the whole pipeline (generate,
fabric, flow, laydown) in a temporary folder; the lay-down numbers come from laydown.h5.

    .venv/bin/python bench/laydown/run.py [--time 5e-3] [--ranks 1 2] [--case-a]

Writes bench/laydown/results/laydown_bench.json (see docs/bench/laydown.md). Measure on an idle
machine: the 2-rank runs use both cores.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import h5py
import yaml

from fiberform.provenance import machine_info

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def variant(name: str, t_end: float, ranks: int) -> dict[str, Any]:
    scene = yaml.safe_load((ROOT / "scenes" / "demo.yaml").read_text())
    scene["name"] = f"bench_{name}_{ranks}"
    scene["output_dir"] = "runs/bench"
    ld = scene["laydown"]
    ld.update({"max_time_s": t_end, "settle_checks": 10000, "ranks": ranks,
               "restart_interval_s": 0.0})
    if name == "case_a":
        scene["domain"]["hi_m"][:2] = [3.0e-3, 3.0e-3]
        scene["fabric"].update({"size_x_m": 3.0e-3, "size_y_m": 3.0e-3})
        scene["fiber_generation"]["placement_hi_m"][:2] = [3.0e-3, 3.0e-3]
        f = scene["fibers"]
        f.pop("count", None)
        f.update({"target_mass_kg": 35.7e-9, "length_m": 1.6e-3, "segments": 32})
    return scene


def run_one(name: str, t_end: float, ranks: int, build: Path) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="fiberform-bench-laydown-") as tmp:
        work = Path(tmp)
        (work / "scene.yaml").write_text(yaml.safe_dump(variant(name, t_end, ranks)))
        t0 = time.monotonic()
        proc = subprocess.run([str(ROOT / ".venv" / "bin" / "fiberform"), "run", "scene.yaml",
                               "--build-dir", str(build)], cwd=work, capture_output=True, text=True)
        total = time.monotonic() - t0
        if proc.returncode != 0:
            raise RuntimeError(f"{name} on {ranks} rank(s) failed:\n{proc.stdout[-1500:]}{proc.stderr[-1500:]}")
        with h5py.File(work / "runs" / "bench" / "laydown" / "laydown.h5", "r") as h:
            a = dict(h["run"].attrs)
            nodes = int(h["sheet/x"].shape[0])
            fibers = int(h["sheet/fiber_id"].shape[0])
            ff = float(h["snapshots/min_fiber_fiber_gap"][...].min())
    steps = int(a["steps"])
    wall = float(a["wall_time_s"])
    return {
        "variant": name, "ranks": ranks, "fibers": fibers, "nodes": nodes, "steps": steps,
        "simulated_ms": steps * 1e-6 * 1e3, "pipeline_wall_s": total, "laydown_wall_s": wall,
        "wall_s_per_simulated_ms": wall / (steps * 1e-3), "node_steps_per_s": nodes * steps / wall,
        "min_element_yarn_clearance_m": float(a["min_element_clearance_m"]),
        "min_fiber_fiber_gap_m": ff,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--time", type=float, default=5e-3, help="simulated time per run (s)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--case-a", action="store_true", help="also the 3 x 3 mm case-A probe")
    ap.add_argument("--out", type=Path, default=HERE / "results")
    args = ap.parse_args()
    build = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()
    rows = []
    for name in ["demo"] + (["case_a"] if args.case_a else []):
        for ranks in args.ranks:
            row = run_one(name, args.time, ranks, build)
            rows.append(row)
            print(f"{name:7s} {ranks} rank(s): {row['nodes']} nodes, {row['simulated_ms']:.1f} ms in "
                  f"{row['laydown_wall_s']:.1f} s ({row['wall_s_per_simulated_ms']:.1f} s/ms, "
                  f"{row['node_steps_per_s']:.3g} node-steps/s); yarn clearance "
                  f"{row['min_element_yarn_clearance_m'] * 1e6:.2f} um, fiber-fiber "
                  f"{row['min_fiber_fiber_gap_m'] * 1e9:.1f} nm", flush=True)
    for name in {r["variant"] for r in rows}:
        by = {r["ranks"]: r for r in rows if r["variant"] == name}
        if 1 in by and 2 in by:
            print(f"{name}: 2-rank speed-up {by[1]['laydown_wall_s'] / by[2]['laydown_wall_s']:.2f}")
    args.out.mkdir(parents=True, exist_ok=True)
    out = args.out / "laydown_bench.json"
    out.write_text(json.dumps({"machine": machine_info(), "time_s": args.time, "rows": rows}, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
