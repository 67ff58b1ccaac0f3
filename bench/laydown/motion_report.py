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

With ``--paths T0`` (ms) a second table: for each fiber present from the first snapshot at or
after T0 to the last one, the path its centre of mass travelled between them (sum over the
snapshots) and its displacement (x, y, z); the ``--top`` fibers with the longest paths (10 without
``--top``), and the mass share of the fibers whose path exceeds ``--path-limit`` (um). A sheet
whose fibers still migrate (slide over each other, sink into the sheet) is still changing, even
when its height percentiles no longer move. ``--until T1`` (ms) leaves out the snapshots after T1
(the same tables from a run that has gone on since).

With ``--thickness`` a third table: per snapshot, the sheet's thickness above the fabric top as the
lay-down stage reports it (95th percentile of the fibers' upper surfaces minus the highest yarn
surface: fiberform.fiber_sheet.sheet_thickness_above_fabric), from the scene (``--scene``, default
``<run>/scene.yaml``) and its output folder's ``fibers/fibers.h5`` and ``fabric/fabric.h5``.

    .venv/bin/python bench/laydown/motion_report.py \\
        --run runs/bench-laydown/A-rectangular-loose-r2-s1 --every 4 --top 3
    .venv/bin/python bench/laydown/motion_report.py \\
        --run runs/thesis-campaign/S3-circular-sweep/campaign_S3_circular_000 --every 4 --paths 16 --until 38

Times are the dump steps times the run's time step (``--dt``, default 1e-6 s).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import numpy.typing as npt

from fiberform.fiber_io import NODES_NAME
from fiberform.fiber_sheet import (
    frame_fibers, frame_positions, mass_fraction_speed, sheet_thickness_above_fabric,
)
from fiberform.liggghts_log import Frame, read_dump
from fiberform.products import FABRIC_H5, read_yarns
from fiberform.scene import load_scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="lay-down run folder (scene.yaml, laydown/work)")
    ap.add_argument("--every", type=int, default=1, help="every k-th snapshot")
    ap.add_argument("--speed", type=float, default=2.062e-3, help="speed threshold (m/s)")
    ap.add_argument("--fraction", type=float, default=0.99, help="mass fraction of the speed measures")
    ap.add_argument("--top", type=int, default=0, help="list the K fastest fibers per snapshot")
    ap.add_argument("--dt", type=float, default=1e-6, help="time step (s)")
    ap.add_argument("--until", type=float, default=None, metavar="T1",
                    help="only the snapshots up to T1 (ms): a table of a run that has gone on since")
    ap.add_argument("--paths", type=float, default=None, metavar="T0",
                    help="also tabulate the fibers' centre-of-mass paths from T0 (ms) to the last snapshot")
    ap.add_argument("--path-limit", type=float, default=10.0, metavar="UM",
                    help="with --paths: the mass share of fibers whose path exceeds this (um)")
    ap.add_argument("--thickness", action="store_true",
                    help="also tabulate the sheet's thickness above the fabric top per snapshot")
    ap.add_argument("--scene", type=Path, default=None,
                    help="with --thickness: the run's scene file (default <run>/scene.yaml)")
    a = ap.parse_args()
    if a.paths is not None and (a.paths < 0.0 or a.path_limit <= 0.0):
        ap.error("--paths needs T0 >= 0 ms and --path-limit > 0 um")
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
    if a.until is not None:
        frames = [fr for fr in frames if fr.step <= round(a.until * 1e-3 / a.dt)]
    print(f"| t (ms) | fibers | mass share > {a.speed * 1e3:.3g} mm/s: all / horizontal / vertical | "
          f"{a.fraction:g}-mass speed |v| / |v_z| (mm/s) | node height 50 / 90 / 99 % (um) |")
    print("|---|---|---|---|---|")
    for fr in frames[::a.every]:
        c = fr.columns
        fid, fibers, m, v = fiber_means(fr, fiber_of, np.stack([c["vx"], c["vy"], c["vz"]], 1))
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
    if a.paths is not None:
        paths_table(frames, fiber_of, round(a.paths * 1e-3 / a.dt), a.top or 10, a.path_limit)
    if a.thickness:
        thickness_table(frames[::a.every], a.scene or a.run / "scene.yaml", a.dt)


def thickness_table(frames: list[Frame], scene_path: Path, dt: float) -> None:
    """Per snapshot: the thickness above the fabric top (um), the lay-down stage's measure."""
    scene = load_scene(scene_path)
    top = read_yarns(scene.output_path / FABRIC_H5).top
    print("\n| t (ms) | thickness above the fabric top (um) |\n|---|---|")
    for fr in frames:
        x, present, offsets = frame_fibers(fr.columns)
        above = sheet_thickness_above_fabric(scene, x, offsets, present, top)
        print(f"| {fr.step * dt * 1e3:.1f} | {above * 1e6:.1f} |")


def fiber_means(fr: Frame, fiber_of: dict[int, tuple[int, int]], values: npt.NDArray[np.float64]
                ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64],
                           npt.NDArray[np.float64]]:
    """Per fiber of a frame: the node's fiber IDs, the fibers present (ascending), their masses and
    the mass-weighted means of ``values`` (one row of 3 per node: velocities, positions)."""
    c = fr.columns
    fid = np.array([fiber_of[int(i)][0] for i in fr.ids])
    fibers, inv = np.unique(fid, return_inverse=True)
    m = np.bincount(inv, weights=c["mass"])
    means = np.stack([np.bincount(inv, weights=c["mass"] * values[:, k]) for k in range(3)], 1) / m[:, None]
    return fid, fibers, m, means


def paths_table(frames: list[Frame], fiber_of: dict[int, tuple[int, int]], from_step: int, top: int,
                limit_um: float) -> None:
    """The fibers' centre-of-mass paths and displacements from the first frame at or after
    ``from_step`` to the last frame (module docstring)."""
    span = [fr for fr in frames if fr.step >= from_step]
    if len(span) < 2:
        print(f"\n--paths: fewer than two snapshots from step {from_step} on")
        return
    centres: list[dict[int, npt.NDArray[np.float64]]] = []
    mass: dict[int, float] = {}
    for fr in span:
        _, fibers, m, com = fiber_means(fr, fiber_of, frame_positions(fr.columns))
        centres.append({int(f): com[k] for k, f in enumerate(fibers)})
        mass.update({int(f): float(m[k]) for k, f in enumerate(fibers)})
    kept = [f for f in centres[0] if all(f in cs for cs in centres)]
    rows = []
    for f in kept:
        track = np.array([cs[f] for cs in centres])
        rows.append((float(np.linalg.norm(np.diff(track, axis=0), axis=1).sum()), f, track[-1] - track[0]))
    rows.sort(key=lambda r: -r[0])
    total = sum(mass[f] for f in kept)
    moved = sum(mass[f] for p, f, _ in rows if p * 1e6 > limit_um)
    t0, t1 = span[0].step, span[-1].step
    print(f"\nCentre-of-mass paths from step {t0} to {t1}: {len(kept)} fibers present throughout; "
          f"mass share with a path > {limit_um:g} um: {moved / total:.3f}")
    print("| fiber | mass (ng) | path (um) | displacement x, y, z (um) |")
    print("|---|---|---|---|")
    for p, f, d in rows[:top]:
        print(f"| {f} | {mass[f] * 1e12:.2f} | {p * 1e6:.1f} | {d[0] * 1e6:.1f}, {d[1] * 1e6:.1f}, {d[2] * 1e6:.1f} |")


if __name__ == "__main__":
    main()
