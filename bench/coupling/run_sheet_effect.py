#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/coupling/run_sheet_effect: one-way against two-way coupling on a thesis campaign point
(issue 13, benchmark "Effect on the sheet"; issue 15, open question (c)), compared at common times.

The scene is the validation campaign's point (``bench/thesis/run.py``'s derivation,
:func:`fiberform.campaign.point_scene`: ``--campaign``, default scenes/thesis/campaign.yaml, on the
case-A scene of the section; default point C circular, seed 1) with the lay-down on ``--ranks`` fiber ranks (default
1: the pile's contact cluster is solved on one rank, docs/bench/laydown.md) and restart files every
``--restart`` s (``--max-time``: a shorter lay-down). Two copies differ only in ``coupling``: absent (one-way, the flow stage's frozen
flow) and ``{mode: two_way, interval: N, fluid_ranks: 1}``. The fabric and flow stages run once
(the one-way copy's) and are copied to the two-way run; each lay-down generates its fibers itself
(the same seed: the comparison checks they are identical). The two lay-downs run at the same time
(one-way: ranks processes; two-way: ranks + 1), each logging to ``<runs>/<name>.log``; with
``--resume`` they continue from their restart files.

``--to permeability`` runs the permeability stage on both finished sheets as well (air, the
campaign scene's settings); ``--max-time`` with ``--resume`` ends both lay-downs at a common time
from their restart files (the restart identity leaves the end time out: docs/stages/laydown.md,
"Resuming"), so that both have products (a lay-down that did not settle has none until it ends).

``--compare`` reads the two lay-downs' snapshots (``laydown/work/traj.dump``; a finished,
still running or killed run) at the common times every ``--every`` s up to the last snapshot
both have, and tabulates for each: fibers present and the mass, and the fines, still in the
domain (fibers that pass through the fabric are removed), the settled grammage (fibers slower than
the lay-down's settle speed), the thickness above the fabric top (the lay-down's measure, over all
fibers present), node heights, the difference of the grammage maps (node mass on a ``--bins`` grid
over the piece: RMS and largest difference over the mean) and of the mass profiles through the
thickness (10 um slabs: largest difference over the largest slab), how far the same fibers lie
apart (centre of mass: median and 90 %), and the drainage (superficial velocity through fabric +
sheet: the two-way fluid's bottom flow rate at that time; one-way: the flow stage's bare fabric).
Where the runs have finished products, their lay-down metrics (thickness above the fabric,
grammage, simulated time) and, with ``--to permeability``, their air permeabilities (CFM) are
added. Written to ``bench/coupling/results/sheet_effect_<point>_<section>.json`` (``--out``).

    .venv/bin/python bench/coupling/run_sheet_effect.py                 # both lay-downs (hours)
    .venv/bin/python bench/coupling/run_sheet_effect.py --resume        # continue killed ones
    .venv/bin/python bench/coupling/run_sheet_effect.py --compare       # the table, any time
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import yaml

from fiberform import campaign as cp
from fiberform._versions import build_revision, git_revision, package_version
from fiberform.fiber_sheet import fiber_com_speeds, frame_fibers, sheet_thickness_above_fabric
from fiberform.liggghts_log import Frame, read_dump
from fiberform.openfoam_case import DRAINAGE_FO, read_patch_history
from fiberform.products import FABRIC_H5, FIBERS_H5, read_superficial_velocity, read_yarns
from fiberform.provenance import atomic_write_text, file_hash, machine_info
from fiberform.scene import Scene, load_scene
from fiberform.stages import STAGES, StageContext
from fiberform.stages.laydown import FLUID_CASE, settle_speed

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
PROFILE_DZ = 10e-6  # m: the slabs of the mass profile
NAMES = ("one_way", "two_way")


def scenes(campaign: Path, point: str, section: str, ranks: int, restart: float, interval: int,
           max_time: float | None, runs: Path) -> dict[str, Path]:
    """Write the two scenes (one-way, two-way) of the campaign point under ``runs`` (relative to
    the working directory, as their output folders)."""
    c = cp.load_campaign(campaign)
    folder = campaign.resolve().parent
    pts = {p.name: p for p in cp.points(c, cp.read_experiments(folder / "experiments.csv"))}
    if point not in pts:
        raise SystemExit(f"--point {point}: allowed {', '.join(pts)}")
    base = cp.point_scene(c, pts[point], section, folder, runs)  # type: ignore[arg-type]
    base.pop("press", None)
    base["laydown"].update({"ranks": ranks, "restart_interval_s": restart})
    if max_time is not None:
        base["laydown"]["max_time_s"] = max_time
    out: dict[str, Path] = {}
    for name in NAMES:
        data = {**base, "name": f"sheet_effect_{point}_{section}_{name}", "output_dir": str(runs / name)}
        if name == "two_way":
            data["coupling"] = {"mode": "two_way", "interval": interval, "fluid_ranks": 1}
        path = runs / f"{name}.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, f"# {name} lay-down of campaign point {point} {section}: written by "
                          "bench/coupling/run_sheet_effect.py\n" + yaml.safe_dump(data, sort_keys=False))
        load_scene(path)  # validated
        out[name] = path
    return out


def build_dir() -> Path:
    return Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()


def run(paths: dict[str, Path], resume: bool, to: str) -> None:
    cmd = [sys.executable, "-m", "fiberform", "run", "--build-dir", str(build_dir())]
    if subprocess.run([*cmd, str(paths["one_way"]), "--to", "flow"]).returncode != 0:
        raise SystemExit("the one-way scene's fabric and flow stages failed")
    src, dst = (load_scene(paths[n]).output_path for n in NAMES)
    for stage in ("fabric", "flow"):
        if not (dst / stage).exists():
            shutil.copytree(src / stage, dst / stage, symlinks=True)
    procs = []
    for name in NAMES:
        log = (paths[name].parent / f"{name}.log").open("a")
        procs.append(subprocess.Popen([*cmd, str(paths[name]), "--to", to, *(["--resume"] if resume else [])],
                                      stdout=log, stderr=subprocess.STDOUT))
    codes = [p.wait() for p in procs]
    if any(codes):
        raise SystemExit(f"lay-downs ended with {codes} (logs beside the scenes)")


def frame_measures(scene: Scene, fr: Frame, mass: np.ndarray, fine: np.ndarray, top: float, bins: int,
                   v_settle: float) -> dict[str, Any]:
    """What :func:`compare` tabulates of one snapshot (arrays kept for the differences); ``mass``,
    ``fine``: the generated fibers' masses (kg) and fines flags (fibers.h5)."""
    fab = scene.fabric
    assert fab is not None
    sx, sy = fab.size_x_m, fab.size_y_m
    x, present, offsets = frame_fibers(fr.columns)
    counts = np.diff(offsets)
    m_node = np.repeat(mass[present] / counts, counts)
    gmap, _, _ = np.histogram2d(x[:, 0], x[:, 1], weights=m_node,
                                bins=[np.linspace(0.0, sx, bins + 1), np.linspace(0.0, sy, bins + 1)])
    m_f, v_f = fiber_com_speeds(fr.columns)  # ascending fiber ID = ``present``
    starts = offsets[:-1]
    com = (np.stack([np.add.reduceat(x[:, k] * m_node, starts) for k in range(3)], 1)
           / np.add.reduceat(m_node, starts)[:, None])
    return {
        "fibers": int(len(present)), "mass_fraction": float(mass[present].sum() / mass.sum()),
        "fines_fraction": float(fine[present].sum() / fine.sum()) if fine.any() else None,  # None: no fines
        "settled_grammage_kg_m2": float(m_f[v_f < v_settle].sum() / (sx * sy)),
        "thickness_above_fabric_m": sheet_thickness_above_fabric(scene, x, offsets, present, top),
        "node_height_50_90_99_m": [float(h) - top for h in np.percentile(x[:, 2], [50, 90, 99])],
        "map": gmap / (sx * sy / bins ** 2), "z": x[:, 2], "m_node": m_node,
        "present": present, "com": com,
    }


def compare(paths: dict[str, Path], every: float, bins: int, dt: float) -> dict[str, Any]:
    """The table of the module docstring, one row per common time."""
    sc = {n: load_scene(paths[n]) for n in NAMES}
    out = {n: sc[n].output_path for n in NAMES}
    with h5py.File(out["one_way"] / FIBERS_H5, "r") as a, h5py.File(out["two_way"] / FIBERS_H5, "r") as b:
        if not np.array_equal(a["fibers/x"][...], b["fibers/x"][...]):
            raise SystemExit("the two runs generated different fibers: not a controlled comparison")
        mass, fine = a["fibers/mass"][...], a["fibers/is_fine"][...].astype(bool)  # the same in both
    top = read_yarns(out["one_way"] / FABRIC_H5).top
    u_s = read_superficial_velocity(out["one_way"] / "flow" / "flow.h5")
    v_settle = settle_speed(sc["one_way"], u_s)
    frames = {n: {fr.step: fr for fr in read_dump(out[n] / "laydown" / "work" / "traj.dump")} for n in NAMES}
    common = sorted(set(frames["one_way"]) & set(frames["two_way"]))
    stride = max(1, round(every / dt))
    steps = [s for s in common if s % stride == 0 and s > 0]
    if common and common[-1] not in steps:
        steps.append(common[-1])
    t_q, q = read_patch_history(out["two_way"] / "laydown" / "work" / FLUID_CASE, DRAINAGE_FO["bottom"])
    fab = sc["one_way"].fabric
    assert fab is not None
    area = fab.size_x_m * fab.size_y_m
    rows = []
    for s in steps:
        a, b = (frame_measures(sc[n], frames[n][s], mass, fine, top, bins, v_settle) for n in NAMES)
        mean = float(np.mean(a["map"]))
        dmap = b["map"] - a["map"]
        zmax = max(a["z"].max(), b["z"].max())
        edges = np.arange(top - 10 * PROFILE_DZ, zmax + 2 * PROFILE_DZ, PROFILE_DZ)
        pa, pb = (np.histogram(m["z"], bins=edges, weights=m["m_node"])[0] for m in (a, b))
        both, ia, ib = np.intersect1d(a["present"], b["present"], return_indices=True)
        apart = np.linalg.norm(a["com"][ia] - b["com"][ib], axis=1)
        k = int(np.searchsorted(t_q, s * dt * (1 + 1e-9), side="right")) - 1
        rows.append({
            "time_s": s * dt,
            **{f"{n}_{key}": m[key] for n, m in zip(NAMES, (a, b)) for key in
               ("fibers", "mass_fraction", "fines_fraction", "settled_grammage_kg_m2",
                "thickness_above_fabric_m", "node_height_50_90_99_m")},
            "grammage_map_rms_diff_rel": float(np.sqrt(np.mean(dmap ** 2))) / mean,
            "grammage_map_max_diff_rel": float(np.max(np.abs(dmap))) / mean,
            "grammage_map_cv": [float(np.std(m["map"]) / np.mean(m["map"])) for m in (a, b)],
            "profile_max_diff_rel": float(np.max(np.abs(pb - pa)) / max(pa.max(), pb.max())),
            "com_apart_median_m": float(np.median(apart)) if len(both) else float("nan"),
            "com_apart_90_m": float(np.percentile(apart, 90)) if len(both) else float("nan"),
            "drainage_one_way_m_s": u_s,
            "drainage_two_way_m_s": float(q[k] / area) if k >= 0 else float("nan"),
        })
    return {"settle_speed_m_s": v_settle, "fabric_top_m": top, "bins": bins, "rows": rows,
            "last_snapshot_s": {n: max(frames[n]) * dt if frames[n] else 0.0 for n in NAMES},
            "products": {n: products(paths[n], sc[n]) for n in NAMES}}


def products(scene_path: Path, scene: Scene) -> dict[str, float]:
    """The metrics of the finished lay-down and permeability products of a run (empty without)."""
    ctx = StageContext(scene=scene, scene_path=scene_path, build_dir=build_dir())
    out: dict[str, float] = {}
    for name in ("laydown", "permeability"):
        st = STAGES[name]
        if all(p.is_file() for p in st.product_paths(ctx)):
            out.update(st.metrics(ctx))
    return out


def _share(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def print_table(res: dict[str, Any]) -> None:
    print("| t (ms) | fibers 1w / 2w | fines kept 1w / 2w | settled g/m^2 1w / 2w | thickness above fabric "
          "1w / 2w (um) | grammage map RMS / max diff | profile max diff | same fiber apart, median / 90 % "
          "(um) | drainage 1w / 2w (mm/s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in res["rows"]:
        print(f"| {r['time_s'] * 1e3:.1f} | {r['one_way_fibers']} / {r['two_way_fibers']} | "
              f"{_share(r['one_way_fines_fraction'])} / {_share(r['two_way_fines_fraction'])} | "
              f"{r['one_way_settled_grammage_kg_m2'] * 1e3:.2f} / {r['two_way_settled_grammage_kg_m2'] * 1e3:.2f} | "
              f"{r['one_way_thickness_above_fabric_m'] * 1e6:.1f} / {r['two_way_thickness_above_fabric_m'] * 1e6:.1f} | "
              f"{r['grammage_map_rms_diff_rel'] * 100:.1f} % / {r['grammage_map_max_diff_rel'] * 100:.1f} % | "
              f"{r['profile_max_diff_rel'] * 100:.1f} % | {r['com_apart_median_m'] * 1e6:.1f} / "
              f"{r['com_apart_90_m'] * 1e6:.1f} | {r['drainage_one_way_m_s'] * 1e3:.2f} / "
              f"{r['drainage_two_way_m_s'] * 1e3:.2f} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--campaign", type=Path, default=ROOT / "scenes" / "thesis" / "campaign.yaml",
                    help="campaign definition (default scenes/thesis/campaign.yaml)")
    ap.add_argument("--point", default="C", help="campaign point, default C")
    ap.add_argument("--section", choices=("circular", "rectangular"), default="circular")
    ap.add_argument("--ranks", type=int, default=1, help="fiber ranks of each lay-down (default 1)")
    ap.add_argument("--interval", type=int, default=100, help="two-way exchange interval, fiber steps (default 100)")
    ap.add_argument("--restart", type=float, default=1e-3, help="restart file interval, s (default 1e-3)")
    ap.add_argument("--max-time", type=float, default=None,
                    help="lay-down end time, s (default: the campaign scene's max_time_s)")
    ap.add_argument("--runs", type=Path, default=None,
                    help="run folder relative to the working directory (default runs/sheet-effect-POINT-SECTION)")
    ap.add_argument("--resume", action="store_true", help="continue killed lay-downs from their restart files")
    ap.add_argument("--to", choices=("laydown", "permeability"), default="laydown",
                    help="the last stage to run (default laydown)")
    ap.add_argument("--compare", action="store_true", help="run nothing: compare what the runs have")
    ap.add_argument("--every", type=float, default=2e-3, help="--compare: time between rows, s (default 2e-3)")
    ap.add_argument("--bins", type=int, default=6, help="--compare: grammage map cells per side (default 6)")
    ap.add_argument("--out", type=Path, default=None, help="--compare: results JSON")
    a = ap.parse_args()
    if not 1 <= a.ranks <= 64 or not 1 <= a.interval <= 100000 or not 0 < a.restart <= 1.0:
        ap.error("--ranks 1..64, --interval 1..100000, --restart in (0, 1] s")
    if not 0 < a.every <= 1.0 or not 1 <= a.bins <= 100 or (a.max_time is not None and not 0 < a.max_time <= 10.0):
        ap.error("--every in (0, 1] s, --bins 1..100, --max-time in (0, 10] s")
    runs = a.runs or Path("runs") / f"sheet-effect-{a.point}-{a.section}"
    if runs.is_absolute():
        ap.error("--runs: give a folder relative to the working directory")
    paths = scenes(a.campaign, a.point, a.section, a.ranks, a.restart, a.interval, a.max_time, runs)
    if not a.compare:
        run(paths, a.resume, a.to)
    dt = load_scene(paths["one_way"]).laydown.timestep_s  # type: ignore[union-attr]
    res = compare(paths, a.every, a.bins, dt)
    res.update({"point": a.point, "section": a.section, "ranks": a.ranks, "interval": a.interval,
                "command": " ".join(sys.argv[1:]), "scenes": {n: str(p) for n, p in paths.items()},
                "code": {"fiberform": package_version(), "git_revision": git_revision(),
                         "build_revision": build_revision(build_dir()), "campaign_sha256": file_hash(a.campaign)},
                "machine": machine_info()})
    print_table(res)
    for name, got in res["products"].items():
        if got:
            print(f"{name}: " + ", ".join(f"{k} {v:.6g}" for k, v in got.items()))
    out = a.out or HERE / "results" / f"sheet_effect_{a.point}_{a.section}.json"
    atomic_write_text(out, json.dumps(res, indent=1) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
