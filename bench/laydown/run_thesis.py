#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Thesis-scale lay-down benchmark (issue 10): the shipped thesis case scenes laid down with the
thesis' physics and with speed options, on 1 or 2 MPI ranks.

Each run is ``fiberform run SCENE --to laydown`` of a case scene (scenes/thesis/case-X-Y.yaml)
with the variant's fields set, in its own folder ``runs/bench-laydown/<case>-<variant>-r<ranks>-s<seed>/``
(kept: a second call resumes or skips finished stages; the generate, fabric and flow stages are
taken over from an earlier run of the same case and seed when their inputs are identical:
fiberform.reuse.adopt_stages). The numbers come from laydown.h5, the fiberdem log and the process
accounting:

* simulated time, settled or not, wall time of the lay-down program, node-steps per second;
* the sheet: thickness (5-95 % span and above the fabric top), grammage, fibers and fines on it,
  smallest fiber-fiber gap and element-yarn clearance (the lay-down's own checks of every
  snapshot);
* the largest resident memory of one process (getrusage of the children).

Variants (``--variants``):
  thesis   the scene as shipped: fiber-fiber contact averaged + CVODE, vdw + es + steric (thesis sec. 2.4)
  newton   fiber-fiber contact inside each fiber's Newton solve (laydown.fiber_contact newton), same terms
  steric   newton, steric term only (a speed option: no colloidal terms)
  loose    newton with laydown.newton_tolerance 1e-6 instead of 1e-8 (a speed option: fewer Newton
           iterations; corrections below 1e-6 x the section radius, ~15 pm, end the iteration)
  loose_soft
           loose with the fibers' Young's and shear moduli at 1/3 of the case scenes' 10 and 4 GPa
           (issue 15, open question (a): "fibers too stiff", thesis sec. 5.2)
  loose_nofines
           loose with fiber_generation.fines_fraction 0 (the same injected mass, all of it in
           fibers; issue 15, open question (b))
  loose_frictionless
           loose with laydown.friction_coefficient 0: no Coulomb friction on yarns and side planes,
           as the thesis' law (sec. 2.4, normal forces only); the case scenes add 0.5
  loose_steric
           loose with the steric term only against fibers, yarns and planes (a speed option: no
           colloidal terms)
  loose_stick10, loose_stick1, loose_stick1000
           loose with laydown.friction_stick 10 / 1 / 1000 instead of 100: the regularised yarn
           friction's stick damping c_stick = k m_eff / dt softer (a speed option: fewer Newton
           iterations; a stuck point creeps 100 / k times faster) or stiffer (the convergence of
           the sheet in k)
  loose_dt2, loose_dt5
           loose with the fiber time step laydown.timestep_s 2 / 5 us instead of 1 us, and
           laydown.friction_stick 200 / 500 so that the stick damping c_stick = k m_eff / dt stays
           that of the case scenes (a speed option if the sheet does not change: fewer steps, each
           needing more Newton iterations)
  loose_aa3
           loose with laydown.anderson_depth 3: Anderson mixing of the implicit Newton corrections
           (the same tolerance; fewer iterations in piled-up clusters)
  loose_repeat, loose_periodic
           loose on the piece of whole weave repeats nearest the case's (8/3000 x 16/5000 m = 2.667 x
           3.2 mm for the thesis fabric; injected mass and placement scaled by area), with the four
           side planes (the thesis' lay-down, sec. 3.1) or periodic in x and y (laydown.walls
           periodic; issue 15, open question (d): compare with --reference loose_repeat)
  two_way, loose_two_way
           newton / loose with coupling.mode two_way (issue 13): fiberPimpleFoam on one more process
           next to the --ranks fiber ranks, the drag reaction exchanged every coupling.interval
           steps; the row adds the drainage (superficial velocity through fabric + sheet) at the
           start and the end (compare with --reference newton / loose)

Every row of a variant other than the reference (``--reference``, default newton) is compared with
the reference row of the same case and seed that exists (either rank count; 1 and 2 ranks give the
same sheet): sheet thickness, grammage, the grammage map on a 6 x 6 grid of the 3 x 3 mm piece
(largest and RMS difference, relative to the mean) and the mass profile through the thickness in
10 um slabs (largest difference, relative to the reference's largest slab).

    .venv/bin/python bench/laydown/run_thesis.py --cases A-circular --variants thesis newton --ranks 2
    .venv/bin/python bench/laydown/run_thesis.py --cases A-circular --max-time 2e-3   # a short probe
    .venv/bin/python bench/laydown/run_thesis.py --cases A-circular --variants loose --ranks 2
    .venv/bin/python bench/laydown/run_thesis.py --cases C-circular --variants loose --ranks 2 --resume  # after a kill

Writes bench/laydown/results/thesis_laydown.json (rows appended per run; see docs/bench/laydown.md).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import yaml

from fiberform.campaign import use_fiber_contact
from fiberform.fiber_sheet import product_thickness_above_fabric
from fiberform.products import read_sheet
from fiberform.provenance import append_result_rows, atomic_write_text, machine_info
from fiberform.reuse import adopt_stages
from fiberform.scene.fabric import FabricSection
from fiberform.scene import load_scene
from fiberform.stages import StageContext
from fiberform.sweep import set_field

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
THESIS = ROOT / "scenes" / "thesis"
#: the loose variant's fields (the thesis' terms inside the Newton solve at tolerance 1e-6), which
#: the variants built on it extend
LOOSE: dict[str, Any] = {"laydown.fiber_contact": "newton", "laydown.newton_tolerance": 1.0e-6}
VARIANTS: dict[str, dict[str, Any]] = {
    "thesis": {},
    "newton": {"laydown.fiber_contact": "newton"},
    "steric": {"laydown.fiber_contact": "newton", "laydown.terms": ["steric"], "contact.terms": ["steric"]},
    "loose": LOOSE,
    "two_way": {"laydown.fiber_contact": "newton", "coupling.mode": "two_way"},
    "loose_two_way": {**LOOSE, "coupling.mode": "two_way"},
    # issue 15's open questions (a) and (b), each against ``loose`` (the thesis' sec. 5.2)
    "loose_soft": {**LOOSE, "fibers.youngs_modulus_Pa": 10.0e9 / 3.0, "fibers.shear_modulus_Pa": 4.0e9 / 3.0},
    "loose_nofines": {**LOOSE, "fiber_generation.fines_fraction": 0.0},
    # the thesis' contact law has no tangential force (sec. 2.4): the case scenes' Coulomb friction
    # on yarns and side planes (0.5) switched off
    "loose_frictionless": {**LOOSE, "laydown.friction_coefficient": 0.0},
    # speed option: a softer stick of the regularised yarn friction (laydown.friction_stick, default 100)
    "loose_stick10": {**LOOSE, "laydown.friction_stick": 10.0},
    "loose_stick1": {**LOOSE, "laydown.friction_stick": 1.0},
    "loose_stick1000": {**LOOSE, "laydown.friction_stick": 1000.0},
    # speed option: the steric term only (no van der Waals, no electrostatics), fibers and yarns
    "loose_steric": {**LOOSE, "laydown.terms": ["steric"], "contact.terms": ["steric"]},
    # the fiber time step 2 / 5 us instead of 1 us, the friction's stick damping c_stick = k m_eff / dt
    # kept (k scaled with dt): is 1 us set by accuracy, or can the implicit fibers take longer steps?
    "loose_dt2": {**LOOSE, "laydown.timestep_s": 2.0e-6, "laydown.friction_stick": 200.0},
    "loose_dt5": {**LOOSE, "laydown.timestep_s": 5.0e-6, "laydown.friction_stick": 500.0},
    # solver option: Anderson mixing of the Newton corrections over the last 3 (laydown.anderson_depth)
    "loose_aa3": {**LOOSE, "laydown.anderson_depth": 3},
    # solver option: a 10x looser Newton tolerance (1e-5 of the section radius, 150 pm for a 15 um
    # radius; the contact law's smallest length is 0.5 nm) with the mixing
    "loose_tol1e5_aa3": {**LOOSE, "laydown.newton_tolerance": 1.0e-5, "laydown.anderson_depth": 3},
    # solver option: the same with the landing predictor (laydown.newton_landing predict: several
    # contacts land in one Newton iteration; docs/bench/laydown.md "Landing predictor")
    "loose_tol1e5_aa3_land": {**LOOSE, "laydown.newton_tolerance": 1.0e-5, "laydown.anderson_depth": 3,
                              "laydown.newton_landing": "predict"},
    # issue 15's open question (d): side planes against periodic x/y, both on a piece of whole
    # weave repeats (repeat_piece: the 3 x 3 mm piece is not one), the injected mass scaled by area
    "loose_repeat": {**LOOSE},
    "loose_periodic": {**LOOSE, "laydown.walls": "periodic"},
}
#: variants laid down on the whole-repeat piece of the case's fabric (repeat_piece)
REPEAT_VARIANTS = ("loose_repeat", "loose_periodic")
MAP_BINS = 6           # grammage map: bins per side of the fabric piece
PROFILE_DZ = 10.0e-6   # mass profile through the thickness: slab thickness (m)
SHARED_STAGES = ("generate", "fabric", "flow")  # stages a variant can take over
THESIS_PROBE_S = 4.0e-3  # simulated time of the thesis variant unless --max-time is given


def repeat_piece(data: dict[str, Any]) -> None:
    """Put a case scene on the piece of whole weave repeats nearest its own (periodic x/y needs
    one; the thesis' 3 x 3 mm piece of the eight-shed fabric is 9 weft columns x 15 warps, not a
    whole number of 8-column repeats): sizes shed / cd_count_per_m and shed / md_count_per_m times
    the nearest whole numbers, the injected mass and the placement box scaled with the area, so
    the grammage injected stays the case's."""
    fab = data.setdefault("fabric", {})
    defaults = FabricSection()
    sizes = []
    for key, count_key in (("size_x_m", "cd_count_per_m"), ("size_y_m", "md_count_per_m")):
        size = float(fab.get(key, getattr(defaults, key)))
        repeat = float(fab.get("shed", defaults.shed)) / float(fab.get(count_key, getattr(defaults, count_key)))
        sizes.append((size, repeat * max(1, round(size / repeat))))
    f = data["fibers"]
    f["target_mass_kg"] = float(f["target_mass_kg"]) * (sizes[0][1] * sizes[1][1]) / (sizes[0][0] * sizes[1][0])
    fab["size_x_m"], fab["size_y_m"] = sizes[0][1], sizes[1][1]
    gen = data.get("fiber_generation", {})
    if "placement_hi_m" in gen:
        gen["placement_hi_m"] = [sizes[0][1], sizes[1][1], gen["placement_hi_m"][2]]


def scene_for(case: str, variant: str, ranks: int, seed: int, max_time: float | None, runs: Path) -> tuple[str, dict[str, Any]]:
    data = yaml.safe_load((THESIS / f"case-{case}.yaml").read_text())
    if variant in REPEAT_VARIANTS:
        repeat_piece(data)
    for path, value in VARIANTS[variant].items():
        if path == "laydown.fiber_contact":
            use_fiber_contact(data, value)
        else:
            set_field(data, path, value)
    name = f"{case}-{variant}-r{ranks}-s{seed}"
    data.update(name=f"bench_{name.replace('-', '_')}", seed=seed, output_dir=str(runs / name))
    data["laydown"]["ranks"] = ranks
    if max_time is not None:
        data["laydown"]["max_time_s"] = max_time
    elif variant == "thesis":
        # the averaged contact lets the fibers of a thesis case pass through each other and its
        # cost grows with the overlaps (docs/models/contact.md section 6): a probe of THESIS_PROBE_S
        data["laydown"]["max_time_s"] = THESIS_PROBE_S
    return name, data


def donor_stages(runs: Path, case: str, seed: int, target: Path, build: Path) -> None:
    """Take over the generate, fabric and flow folders of an earlier run of the same case and seed
    (fiberform.reuse.adopt_stages: copied only where the target's stages then find them up to
    date, i.e. made from the same inputs; otherwise they run as usual). ``target`` holds the
    run's scene.yaml."""
    scene = load_scene(target / "scene.yaml")
    # its output_dir is relative to ROOT (the runs' working directory), this process's may differ
    scene = scene.model_copy(update={"output_dir": str(target.resolve())})
    ctx = StageContext(scene=scene, scene_path=target / "scene.yaml", build_dir=build)
    for other in sorted(runs.glob(f"{case}-*-s{seed}")):
        if other != target:
            adopt_stages(ctx, other, SHARED_STAGES)


def run_one(case: str, variant: str, ranks: int, seed: int, max_time: float | None, runs: Path,
            build: Path, resume: bool = False) -> dict[str, Any]:
    name, data = scene_for(case, variant, ranks, seed, max_time, runs)
    out = ROOT / runs / name
    out.mkdir(parents=True, exist_ok=True)
    scene = out / "scene.yaml"
    atomic_write_text(scene, yaml.safe_dump(data, sort_keys=False))
    donor_stages(ROOT / runs, case, seed, out, build)
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "fiberform", "run", str(scene), "--to", "laydown",
                           "--build-dir", str(build), *(["--resume"] if resume else [])],
                          cwd=ROOT, capture_output=True, text=True)
    total = time.monotonic() - t0
    rss_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    row: dict[str, Any] = {"case": case, "variant": variant, "ranks": ranks, "seed": seed,
                           "pipeline_wall_s": total, "max_rss_MiB_any_child_so_far": rss_kb / 1024.0,
                           "exit": proc.returncode}
    h5 = out / "laydown" / "laydown.h5"
    if proc.returncode != 0 or not h5.is_file():
        row["error"] = (proc.stdout[-800:] + proc.stderr[-800:]).strip()
        return row
    with h5py.File(out / "fibers" / "fibers.h5", "r") as f:
        is_fine = f["fibers/is_fine"][...].astype(bool)
    with h5py.File(h5, "r") as h:
        a = dict(h["run"].attrs)
        nodes = int(h["sheet/x"].shape[0])
        kept = np.unique(h["sheet/fiber_id"][...])
        row.update({"fibers_generated": int(is_fine.size), "fines_generated": int(is_fine.sum()),
                    "fibers_on_sheet": int(kept.size), "fines_on_sheet": int(is_fine[kept].sum())})
        ff = h["snapshots/min_fiber_fiber_gap"][...]
        if "drainage" in h:
            u = h["drainage/superficial_velocity"][...]
            row.update({"drainage_start_m_s": float(u[0]), "drainage_end_m_s": float(u[-1])})
    steps, wall = int(a["steps"]), float(a["wall_time_s"])
    row.update({
        "nodes": nodes, "steps": steps, "settled": bool(a["settled"]),
        "simulated_ms": float(a["simulated_time_s"]) * 1e3, "laydown_wall_s": wall,
        "wall_s_per_simulated_ms": wall / max(float(a["simulated_time_s"]) * 1e3, 1e-12),
        "node_steps_per_s": nodes * steps / wall if wall > 0 else float("nan"),
        "sheet_thickness_m": float(a["sheet_thickness_m"]), "grammage_kg_m2": float(a["grammage_kg_m2"]),
        "sheet_thickness_above_fabric_m": above_fabric(out, float(a["fabric_top_m"])),
        "min_fiber_fiber_gap_m": float(np.min(ff)) if ff.size else float("nan"),
        "final_fiber_fiber_gap_m": float(ff[-1]) if ff.size else float("nan"),
        "min_element_yarn_clearance_m": float(a["min_element_clearance_m"]),
        "fiber_contact": str(a.get("fiber_contact", "")),
    })
    row["edge_interior_grammage"] = edge_interior_grammage(out)
    row["run_dir"] = str(out.relative_to(ROOT))
    return row


def above_fabric(run_dir: Path, fabric_top: float) -> float:
    """The lay-down's thickness above the fabric top (m; fiberform.fiber_sheet.thickness_above_fabric,
    the lay-down stage's metric sheet_thickness_above_fabric_m) from the run's products."""
    scene = load_scene(run_dir / "scene.yaml")
    scene = scene.model_copy(update={"output_dir": str(run_dir.resolve())})
    return product_thickness_above_fabric(scene, run_dir / "laydown" / "laydown.h5", fabric_top)


def sheet_nodes(run_dir: Path) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """A lay-down's final sheet as nodes: positions (m; a periodic sheet's wrapped into the piece
    in x and y), masses (kg: each fiber's mass, fibers.h5, shared equally by its nodes), the fabric
    piece's size x, y and the fabric top (m)."""
    scene = yaml.safe_load((run_dir / "scene.yaml").read_text())
    sx, sy = float(scene["fabric"]["size_x_m"]), float(scene["fabric"]["size_y_m"])
    with h5py.File(run_dir / "fibers" / "fibers.h5", "r") as f:
        fiber_mass = f["fibers/mass"][...]
    sheet = read_sheet(run_dir / "laydown" / "laydown.h5")
    with h5py.File(run_dir / "laydown" / "laydown.h5", "r") as h:
        top = float(h["run"].attrs["fabric_top_m"])
    x = sheet.x.copy()
    if scene.get("laydown", {}).get("walls") == "periodic":  # unwrapped chains: their images in the piece
        x[:, 0], x[:, 1] = np.mod(x[:, 0], sx), np.mod(x[:, 1], sy)
    counts = np.diff(sheet.offsets)
    m = np.repeat(fiber_mass[sheet.fiber_id] / counts, counts)
    return x, m, sx, sy, top


def sheet_measures(run_dir: Path) -> dict[str, Any]:
    """Grammage map (kg/m^2, MAP_BINS x MAP_BINS over the fabric piece) and mass profile over z
    (kg/m^2 per slab of PROFILE_DZ, from 10 slabs below the fabric top) of a lay-down's final sheet
    (:func:`sheet_nodes`)."""
    x, m, sx, sy, top = sheet_nodes(run_dir)
    gmap, _, _ = np.histogram2d(x[:, 0], x[:, 1], bins=[np.linspace(0.0, sx, MAP_BINS + 1),
                                                      np.linspace(0.0, sy, MAP_BINS + 1)], weights=m)
    zedges = np.arange(top - 10 * PROFILE_DZ, x[:, 2].max() + 2 * PROFILE_DZ, PROFILE_DZ)
    prof, _ = np.histogram(x[:, 2], bins=zedges, weights=m)
    return {"map": gmap / (sx * sy / MAP_BINS ** 2), "profile": prof / (sx * sy)}


EDGE_BAND_M = 0.2e-3  # the band along the piece's four sides of edge_interior_grammage


def edge_interior_grammage(run_dir: Path, band_m: float = EDGE_BAND_M) -> float:
    """Grammage in the band ``band_m`` wide along the four sides of the fabric piece over the
    grammage inside it (1: no side effect), from the final sheet's nodes (:func:`sheet_nodes`):
    the thin margin of fibers placed inside the box (docs/validation/table41.md, open question (d))."""
    x, m, sx, sy, _ = sheet_nodes(run_dir)
    inner = ((x[:, 0] >= band_m) & (x[:, 0] <= sx - band_m) & (x[:, 1] >= band_m) & (x[:, 1] <= sy - band_m))
    inner_area = (sx - 2 * band_m) * (sy - 2 * band_m)
    g_in = m[inner].sum() / inner_area
    g_edge = m[~inner].sum() / (sx * sy - inner_area)
    return float(g_edge / g_in) if g_in > 0 else float("nan")


def compare(row: dict[str, Any], ref: dict[str, Any]) -> dict[str, Any]:
    """The sheet of ``row`` against the reference row's (same case and seed)."""
    a, b = sheet_measures(ROOT / row["run_dir"]), sheet_measures(ROOT / ref["run_dir"])
    mean = float(np.mean(b["map"]))
    dmap = a["map"] - b["map"]
    size = max(len(a["profile"]), len(b["profile"]))
    pa, pb = (np.pad(p, (0, size - len(p))) for p in (a["profile"], b["profile"]))
    return {
        "reference": f"{ref['variant']} r{ref['ranks']}",
        "thickness_change_m": row["sheet_thickness_m"] - ref["sheet_thickness_m"],
        "thickness_change_rel": row["sheet_thickness_m"] / ref["sheet_thickness_m"] - 1.0,
        "grammage_change_rel": row["grammage_kg_m2"] / ref["grammage_kg_m2"] - 1.0,
        "grammage_map_max_diff_rel": float(np.max(np.abs(dmap))) / mean,
        "grammage_map_rms_diff_rel": float(np.sqrt(np.mean(dmap ** 2))) / mean,
        "grammage_map_cv": float(np.std(a["map"]) / np.mean(a["map"])),
        "grammage_map_cv_reference": float(np.std(b["map"]) / mean),
        "profile_max_diff_rel": float(np.max(np.abs(pa - pb)) / np.max(pb)),
        "wall_ratio": row["laydown_wall_s"] / ref["laydown_wall_s"],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=["A-circular"], help="case scenes, e.g. A-circular C-rectangular")
    ap.add_argument("--variants", nargs="+", default=["thesis", "newton"], choices=sorted(VARIANTS))
    ap.add_argument("--ranks", type=int, nargs="+", default=[2])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--max-time", type=float, help="laydown.max_time_s (s) of every run (default: the scene's; "
                    f"the thesis variant {THESIS_PROBE_S:g} s)")
    ap.add_argument("--runs", type=Path, default=Path("runs") / "bench-laydown")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "thesis_laydown.json")
    ap.add_argument("--reference", default="newton", choices=sorted(VARIANTS),
                    help="variant the others' sheets are compared with (default: newton)")
    ap.add_argument("--resume", action="store_true",
                    help="continue each run's interrupted lay-down from its last restart file (fiberform run "
                         "--resume); without it an interrupted lay-down starts over")
    args = ap.parse_args()
    for case in args.cases:
        if not (THESIS / f"case-{case}.yaml").is_file():
            print(f"--cases: no scene scenes/thesis/case-{case}.yaml", file=sys.stderr)
            return 2
    build = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()
    old: list[dict[str, Any]] = []
    if args.out.is_file():
        old = json.loads(args.out.read_text()).get("rows", [])
    rows = []
    for case in args.cases:
        for seed in args.seeds:
            for variant in args.variants:
                for ranks in args.ranks:
                    row = run_one(case, variant, ranks, seed, args.max_time, args.runs, build, args.resume)
                    row["machine"] = machine_info()
                    refs = [r for r in old + rows if r.get("case") == case and r.get("seed") == seed
                            and r.get("variant") == args.reference and r.get("exit") == 0 and r.get("settled")
                            and "run_dir" in r]
                    if variant != args.reference and row.get("exit") == 0 and refs:
                        row["versus_reference"] = compare(row, refs[-1])
                    rows.append(row)
                    print(json.dumps({k: v for k, v in row.items() if k != "machine"}), flush=True)
    append_result_rows(args.out, rows)
    print(f"wrote {args.out}")
    return 0 if all(r.get("exit") == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
