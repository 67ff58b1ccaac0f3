#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Which fibers still move in a lay-down, and how (issue 10, settling): a table over the dump
snapshots of a lay-down run folder (``laydown/work/traj.dump`` and ``fibers.nodes``).

Per snapshot, from each fiber's centre-of-mass velocity (the quantity of fix fiber/settle
``measure fiber``):

* the mass share of the fibers faster than ``--speed`` (m/s): in all, horizontally, vertically;
* the speed below which ``--fraction`` of the mass moves, of |v| (the settle measure) and of
  |v_z| alone;
* node heights (50, 90, 99 % percentiles, um) of the sheet;
* with ``--top K``: the K fastest fibers (id, node count, centre height, velocity).

    .venv/bin/python bench/laydown/motion_report.py \\
        --run runs/bench-laydown/A-rectangular-loose-r2-s1 --every 4 --top 3

Times are the dump steps times the run's time step (``--dt``, default 1e-6 s).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from fiberform.fiber_io import NODES_NAME
from fiberform.fiber_sheet import frame_positions, mass_fraction_speed
from fiberform.liggghts_log import read_dump


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="lay-down run folder (scene.yaml, laydown/work)")
    ap.add_argument("--every", type=int, default=1, help="every k-th snapshot")
    ap.add_argument("--speed", type=float, default=2.062e-3, help="speed threshold (m/s)")
    ap.add_argument("--fraction", type=float, default=0.99, help="mass fraction of the speed measures")
    ap.add_argument("--top", type=int, default=0, help="list the K fastest fibers per snapshot")
    ap.add_argument("--dt", type=float, default=1e-6, help="time step (s)")
    a = ap.parse_args()
    work = a.run / "laydown" / "work"
    fiber_of: dict[int, tuple[int, int]] = {}
    # the generated fibers' nodes file (the working folder's copy of a resumed run lists only the
    # fibers left at its restart step, the dump's earlier snapshots hold the removed ones too)
    generated = a.run / "fibers" / NODES_NAME
    for line in (generated if generated.is_file() else work / NODES_NAME).read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        p = line.split()
        fiber_of[int(p[0])] = (int(p[1]), int(p[3]))
    frames = read_dump(work / "traj.dump")
    print(f"| t (ms) | fibers | mass share > {a.speed * 1e3:.3g} mm/s: all / horizontal / vertical | "
          f"{a.fraction:g}-mass speed |v| / |v_z| (mm/s) | node height 50 / 90 / 99 % (um) |")
    print("|---|---|---|---|---|")
    for fr in frames[::a.every]:
        c = fr.columns
        fid = np.array([fiber_of[int(i)][0] for i in fr.ids])
        fibers, inv = np.unique(fid, return_inverse=True)
        m = np.bincount(inv, weights=c["mass"])
        v = np.stack([np.bincount(inv, weights=c["mass"] * c[k]) for k in ("vx", "vy", "vz")], 1) / m[:, None]
        w = m / m.sum()
        speed, horiz, vert = np.linalg.norm(v, axis=1), np.linalg.norm(v[:, :2], axis=1), np.abs(v[:, 2])
        height = frame_positions(c)[:, 2]  # z, or zu (laydown.walls periodic: unwrapped dump)
        z = np.percentile(height, [50, 90, 99]) * 1e6
        print(f"| {fr.step * a.dt * 1e3:.1f} | {len(fibers)} | {w[speed > a.speed].sum():.3f} / "
              f"{w[horiz > a.speed].sum():.3f} / {w[vert > a.speed].sum():.3f} | "
              f"{mass_fraction_speed(m, speed, a.fraction) * 1e3:.2f} / "
              f"{mass_fraction_speed(m, vert, a.fraction) * 1e3:.2f} | {z[0]:.0f} / {z[1]:.0f} / {z[2]:.0f} |")
        for k in np.argsort(speed)[::-1][:a.top]:
            sel = fid == fibers[k]
            zc = float(np.mean(height[sel])) * 1e6
            print(f"|  | fiber {fibers[k]} ({int(sel.sum())} nodes, centre {zc:.0f} um) | v = "
                  f"({v[k, 0] * 1e3:.2f}, {v[k, 1] * 1e3:.2f}, {v[k, 2] * 1e3:.2f}) mm/s | | |")


if __name__ == "__main__":
    main()
