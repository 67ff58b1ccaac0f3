#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/coupling/run_interval: the exchange-interval sweep of two-way coupling (issue 13).

Pinned inputs: scenes/demo-two-way.yaml (20 fibers of 0.8 mm on 1 x 1 mm, implicit real fibers at
1 us, fluid on the flow stage's mesh, 1 fiber rank + 1 fluid rank) with laydown.max_time_s
shortened (``--time``, default 2 ms: the fibers, placed 0.02-0.22 mm above the fabric, reach it and
pile up; the sheet has not settled yet) and coupling.interval swept over 1, 5, 20, 100 fiber steps
(fluid step = interval x 1 us). The generate, fabric and flow stages run once; the lay-down once per
interval (``--repeats`` times, for the spread of the wall times).

Per interval, against interval 1 (the finest coupling):
  - sheet thickness: 5-95 % range of the sheet's node heights + one fiber width (fiber_sheet),
  - grammage map: fiber length per column of a 4 x 4 grid over the 1 x 1 mm piece (uniform fibers:
    mass per area up to a constant), rms difference / mean,
  - drainage: superficial velocity through fabric + sheet at the fluid times of the interval (every
    interval x 1 us), largest difference relative to interval 1 at the same times,
  - wall time of the lay-down (laydown.h5 run/wall_time_s: fiberdem's loop), median and spread,
  - the one-way lay-down of the same scene (coupling.mode one_way, frozen flow) as the baseline of
    the wall time (same simulated time, same repeats),
  - exchange share: the coupling's part of the coupled run's wall time, from the timers of
    fix fiber/coupling and fiberPimpleFoam -coupled (rank 0 / master):
        exchange = fibers' coupling work + fibers' waiting for the fluid - the fluid's steps
    (the fluid's steps: PIMPLE, writing, function objects; so the exchange is everything the fibers
    spent on coupling that was not the fluid's own computation: spreading, sums over ranks, the
    fluid's gather/sample/scatter, the messages), share = exchange / lay-down wall time.

    .venv/bin/python bench/coupling/run_interval.py [--time 2e-3] [--intervals 1 5 20 100] [--repeats 2]

Writes bench/coupling/results/interval_sweep.json (docs/bench/coupling.md). The machine's load
average at the start is recorded: on a shared machine the wall times are not idle numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import yaml

from fiberform.fiber_sheet import sheet_thickness
from fiberform.provenance import machine_info

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
FIBER_WIDTH = 20e-6  # m, scenes/demo-two-way.yaml fibers.width_m
GRID = 4             # grammage map columns per side


def grammage_map(x: np.ndarray, offsets: np.ndarray, size: float) -> np.ndarray:
    """Fiber length (m) per column of a GRID x GRID grid over [0, size]^2, from element midpoints."""
    out = np.zeros((GRID, GRID))
    for lo, hi in zip(offsets[:-1], offsets[1:]):
        a, b = x[lo:hi - 1], x[lo + 1:hi]
        mid = 0.5 * (a + b)
        ij = np.clip((mid[:, :2] / size * GRID).astype(int), 0, GRID - 1)
        np.add.at(out, (ij[:, 0], ij[:, 1]), np.linalg.norm(b - a, axis=1))
    return out


def run_laydown(work: Path, interval: int | None, t_end: float, build: Path) -> dict[str, Any]:
    """The lay-down with coupling.interval ``interval``, or one-way (frozen flow) for None."""
    scene = yaml.safe_load((ROOT / "scenes" / "demo-two-way.yaml").read_text())
    scene["output_dir"] = "runs/bench"
    scene["laydown"]["max_time_s"] = t_end
    if interval is None:
        scene["coupling"] = {"mode": "one_way"}
    else:
        scene["coupling"]["interval"] = interval
    (work / "scene.yaml").write_text(yaml.safe_dump(scene))
    proc = subprocess.run([str(ROOT / ".venv" / "bin" / "fiberform"), "run", "scene.yaml", "--to", "laydown",
                           "--build-dir", str(build)], cwd=work, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"interval {interval} failed:\n{proc.stdout[-1500:]}{proc.stderr[-1500:]}")
    stage = work / "runs" / "bench" / "laydown"
    with h5py.File(stage / "laydown.h5", "r") as h:
        a = dict(h["run"].attrs)
        x, offsets = h["sheet/x"][...], h["sheet/offsets"][...]
        if interval is None:
            return {"interval": None, "steps": int(a["steps"]), "wall_s": float(a["wall_time_s"]),
                    "thickness_m": sheet_thickness(x[:, 2], FIBER_WIDTH),
                    "grammage_map": grammage_map(x, offsets, 1e-3).tolist()}
        t_q, u_q = h["drainage/time"][...], h["drainage/superficial_velocity"][...]
    fibers_log = (stage / "work" / "log.fiberdem").read_text(errors="replace")
    fluid_log = (stage / "work" / "log.fiberPimpleFoam").read_text(errors="replace")
    m = re.findall(r"coupling work ([0-9.eE+-]+), waiting for the fluid ([0-9.eE+-]+)", fibers_log)
    f = re.findall(r"fluid steps ([0-9.eE+-]+), waiting for the fibers ([0-9.eE+-]+), coupling work "
                   r"([0-9.eE+-]+)", fluid_log)
    if not m or not f:
        raise RuntimeError(f"interval {interval}: coupling timers missing in the logs")
    work_s, wait_s = (float(v) for v in m[-1])
    fluid_steps_s, fluid_wait_s, fluid_work_s = (float(v) for v in f[-1])
    wall = float(a["wall_time_s"])
    exchange = work_s + wait_s - fluid_steps_s
    return {"interval": interval, "steps": int(a["steps"]), "wall_s": wall,
            "fibers_coupling_work_s": work_s, "fibers_wait_s": wait_s, "fluid_steps_s": fluid_steps_s,
            "fluid_wait_s": fluid_wait_s, "fluid_coupling_work_s": fluid_work_s,
            "exchange_s": exchange, "exchange_share": exchange / wall,
            "thickness_m": sheet_thickness(x[:, 2], FIBER_WIDTH),
            "grammage_map": grammage_map(x, offsets, 1e-3).tolist(),
            "drainage_time_s": t_q.tolist(), "drainage_u_m_s": u_q.tolist()}


def compare_sheet(row: dict[str, Any], ref: dict[str, Any]) -> dict[str, float]:
    g, g_ref = np.asarray(row["grammage_map"]), np.asarray(ref["grammage_map"])
    return {"thickness_rel_diff": row["thickness_m"] / ref["thickness_m"] - 1.0,
            "grammage_rms_rel_diff": float(np.sqrt(np.mean((g - g_ref) ** 2)) / g_ref.mean())}


def compare(row: dict[str, Any], ref: dict[str, Any]) -> dict[str, float]:
    t_ref, u_ref = np.asarray(ref["drainage_time_s"]), np.asarray(ref["drainage_u_m_s"])
    t, u = np.asarray(row["drainage_time_s"]), np.asarray(row["drainage_u_m_s"])
    idx = np.searchsorted(t_ref, t - 1e-12)
    ok = (idx < len(t_ref)) & (np.abs(t_ref[np.minimum(idx, len(t_ref) - 1)] - t) < 1e-9)
    du = np.abs(u[ok] - u_ref[idx[ok]]).max() / np.abs(u_ref).max() if ok.any() else float("nan")
    return {**compare_sheet(row, ref), "drainage_max_rel_diff": float(du),
            "drainage_compared_points": int(ok.sum())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--time", type=float, default=2e-3, help="simulated lay-down time (s)")
    ap.add_argument("--intervals", type=int, nargs="+", default=[1, 5, 20, 100])
    ap.add_argument("--repeats", type=int, default=2, help="lay-down runs per interval (wall-time spread)")
    ap.add_argument("--out", type=Path, default=HERE / "results")
    args = ap.parse_args()
    build = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()
    machine = machine_info()
    rows: dict[int, list[dict[str, Any]]] = {}
    one_way: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="coupling_interval_") as tmp:
        work = Path(tmp)
        for rep in range(args.repeats):
            one_way.append(run_laydown(work, None, args.time, build))
            print(f"one-way       (run {rep + 1}): lay-down {one_way[-1]['wall_s']:.1f} s, thickness "
                  f"{one_way[-1]['thickness_m'] * 1e6:.1f} um", flush=True)
            for interval in args.intervals:
                row = run_laydown(work, interval, args.time, build)
                rows.setdefault(interval, []).append(row)
                print(f"interval {interval:4d} (run {rep + 1}): lay-down {row['wall_s']:.1f} s, exchange "
                      f"{row['exchange_share'] * 100:.2f} %, thickness {row['thickness_m'] * 1e6:.1f} um",
                      flush=True)
    ref = rows[min(args.intervals)][0]
    one_way_wall = statistics.median(r["wall_s"] for r in one_way)
    summary = []
    for interval in args.intervals:
        runs = rows[interval]
        walls = [r["wall_s"] for r in runs]
        shares = [r["exchange_share"] for r in runs]
        entry = {"interval": interval, "fluid_step_s": interval * 1e-6,
                 "wall_s_median": statistics.median(walls), "wall_s_min": min(walls), "wall_s_max": max(walls),
                 "wall_vs_one_way": statistics.median(walls) / one_way_wall,
                 "exchange_share_median": statistics.median(shares), "exchange_share_min": min(shares),
                 "exchange_share_max": max(shares), "thickness_m": runs[0]["thickness_m"],
                 **compare(runs[0], ref),
                 "repeat_identical": all(r["thickness_m"] == runs[0]["thickness_m"] for r in runs)}
        summary.append(entry)
        print(f"interval {interval:4d}: wall {entry['wall_s_median']:.1f} s "
              f"[{entry['wall_s_min']:.1f}, {entry['wall_s_max']:.1f}] ({entry['wall_vs_one_way']:.2f} x one-way), "
              f"exchange share "
              f"{entry['exchange_share_median'] * 100:.2f} % [{entry['exchange_share_min'] * 100:.2f}, "
              f"{entry['exchange_share_max'] * 100:.2f}], thickness {entry['thickness_m'] * 1e6:.2f} um "
              f"({entry['thickness_rel_diff'] * 100:+.2f} %), grammage rms {entry['grammage_rms_rel_diff'] * 100:.2f} %, "
              f"drainage {entry['drainage_max_rel_diff'] * 100:.3f} %")
    args.out.mkdir(parents=True, exist_ok=True)
    out = args.out / "interval_sweep.json"
    tmp_out = out.with_suffix(".json.in_progress")
    tmp_out.write_text(json.dumps({"machine": machine, "load_average_at_end": os.getloadavg(),
                                   "scene": "scenes/demo-two-way.yaml", "time_s": args.time,
                                   "command": " ".join(["bench/coupling/run_interval.py", *sys.argv[1:]]),
                                   "one_way": {"wall_s_median": one_way_wall,
                                               "wall_s": [r["wall_s"] for r in one_way],
                                               "thickness_m": one_way[0]["thickness_m"],
                                               **compare_sheet(one_way[0], ref)},
                                   "summary": summary, "runs": {str(k): v for k, v in rows.items()}},
                                  indent=1) + "\n")
    tmp_out.replace(out)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
