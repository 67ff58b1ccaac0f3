#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/coupling/run_sheet_effect: a thesis campaign point laid down one-way (the reference) and
as controlled variants (issue 13, benchmark "Effect on the sheet"; issue 15, the open questions
(a) stiffness, (b) fines, (c) coupling at a high mass), compared at common times.

The scene is the validation campaign's point (``bench/thesis/run.py``'s derivation,
:func:`fiberform.campaign.point_scene`: ``--campaign``, default scenes/thesis/campaign.yaml, on the
case-A scene of the section; default point C circular, seed 1) with the lay-down on ``--ranks`` fiber ranks (default
1: the pile's contact cluster is solved on one rank, docs/bench/laydown.md) and restart files every
``--restart`` s (``--max-time``: a shorter lay-down). The reference ``one_way`` has no
``coupling`` section (the flow stage's frozen flow); each ``--variants`` entry changes one thing:

- ``two_way``: ``coupling: {mode: two_way, interval: N, fluid_ranks: 1}`` (the same fibers);
- ``soft``: ``fibers.youngs_modulus_Pa`` and ``fibers.shear_modulus_Pa`` at 1/3 (the same fibers:
  generation does not depend on them);
- ``no_fines``: ``fiber_generation.fines_fraction`` 0 at the same injected mass (other fibers: the
  per-fiber distance is not computed).

The fabric and flow stages run once (the reference's) and are copied to the variants' runs; each
lay-down generates its fibers itself (where the fibers should be the same, the comparison checks
that they are). The lay-downs run at the same time (one-way: ranks processes; two-way: ranks + 1),
each logging to ``<runs>/<name>.log``; with ``--resume`` they continue from their restart files.
``--reference-json`` takes the reference from an earlier results JSON of this script (the same
point and section, laid down from the same point scene: the JSON's ``point_scene_sha256`` against
:func:`point_key` of ``--campaign``, so a campaign file whose presses changed still fits; JSONs
without it: the same campaign file) instead of laying it down again: its rows give the reference's
columns at the common times, the products its metrics; the differences of maps, profiles and
fiber positions need both runs' snapshots and are left out. The same-fibers check still runs, on
the reference scene's fibers generated here with its fabric and flow.

``--to permeability`` runs the permeability stage on the finished sheets as well (air, the
campaign scene's settings); ``--max-time`` with ``--resume`` ends the lay-downs at a common time
from their restart files (the restart identity leaves the end time out: docs/stages/laydown.md,
"Resuming"), so that all have products (a lay-down that did not settle has none until it ends).

``--compare`` reads the lay-downs' snapshots (``laydown/work/traj.dump``; a finished,
still running or killed run) at the common times every ``--every`` s up to the last snapshot
both have, and tabulates for each: fibers present and the mass, and the fines, still in the
domain (fibers that pass through the fabric are removed), the settled grammage (fibers slower than
the lay-down's settle speed), the thickness above the fabric top (the lay-down's measure, over all
fibers present), node heights, the difference of the grammage maps (node mass on a ``--bins`` grid
over the piece: RMS and largest difference over the mean) and of the mass profiles through the
thickness (10 um slabs: largest difference over the largest slab), how far the same fibers lie
apart (centre of mass: median and 90 %), and the drainage (superficial velocity through fabric +
sheet: the two-way fluid's bottom flow rate at that time; otherwise the flow stage's bare fabric).
Where the runs have finished products, their lay-down metrics (thickness above the fabric,
grammage, simulated time) and, with ``--to permeability``, their air permeabilities (CFM) are
added. Written to ``bench/coupling/results/sheet_effect_<point>_<section>.json`` for ``two_way``,
``..._<variant>.json`` for the others and for every variant with ``--reference-json`` (``--out``:
one variant only; never the reference JSON itself).

    .venv/bin/python bench/coupling/run_sheet_effect.py                 # both lay-downs (hours)
    .venv/bin/python bench/coupling/run_sheet_effect.py --resume        # continue killed ones
    .venv/bin/python bench/coupling/run_sheet_effect.py --compare       # the table, any time
    .venv/bin/python bench/coupling/run_sheet_effect.py --variants soft no_fines --to permeability \
        --reference-json bench/coupling/results/sheet_effect_C_circular.json
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import shutil
import subprocess
import sys
from functools import cache
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
from fiberform.provenance import atomic_write_text, file_hash, machine_info, text_hash
from fiberform.scene import Scene, load_scene
from fiberform.stages import STAGES, StageContext
from fiberform.stages.laydown import FLUID_CASE, settle_speed

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
PROFILE_DZ = 10e-6  # m: the slabs of the mass profile
REFERENCE = "one_way"
VARIANTS = ("two_way", "soft", "no_fines")
SAME_FIBERS = {"two_way": True, "soft": True, "no_fines": False}


def variant_data(base: dict[str, Any], name: str, interval: int) -> dict[str, Any]:
    """The scene data of ``name`` (the reference or one of :data:`VARIANTS`) from the reference's."""
    data = copy.deepcopy(base)
    if name == "two_way":
        data["coupling"] = {"mode": "two_way", "interval": interval, "fluid_ranks": 1}
    elif name == "soft":
        for key in ("youngs_modulus_Pa", "shear_modulus_Pa"):
            if key not in data["fibers"]:
                raise SystemExit(f"--variants soft: the campaign scene states no fibers.{key} to divide by 3")
            data["fibers"][key] = float(data["fibers"][key]) / 3.0
    elif name == "no_fines":
        data["fiber_generation"]["fines_fraction"] = 0.0
    elif name != REFERENCE:
        raise SystemExit(f"variant {name!r}: allowed {', '.join(VARIANTS)}")
    return data


def point_base(campaign: Path, point: str, section: str, runs: Path) -> dict[str, Any]:
    """The campaign point's scene data without its press (this script lays down and computes the
    permeability only), output folder under ``runs``."""
    c = cp.load_campaign(campaign)
    folder = campaign.resolve().parent
    pts = {p.name: p for p in cp.points(c, cp.read_experiments(folder / "experiments.csv"))}
    if point not in pts:
        raise SystemExit(f"--point {point}: allowed {', '.join(pts)}")
    base = cp.point_scene(c, pts[point], section, folder, runs)  # type: ignore[arg-type]
    base.pop("press", None)
    return base


def point_key(campaign: Path, point: str, section: str) -> str:
    """sha256 of the point's scene as :func:`point_base` has it, without name and output folder:
    what a reference laid down from another version of the campaign file must share with this
    one (a change of the campaign's presses leaves it as it is)."""
    base = point_base(campaign, point, section, Path("runs"))
    for key in ("name", "output_dir"):
        base.pop(key, None)
    return text_hash(json.dumps(base, sort_keys=True))


def scenes(campaign: Path, point: str, section: str, ranks: int, restart: float, interval: int,
           max_time: float | None, runs: Path, variants: list[str]) -> dict[str, Path]:
    """Write the reference's and the variants' scenes of the campaign point under ``runs``
    (relative to the working directory, as their output folders)."""
    base = point_base(campaign, point, section, runs)
    base["laydown"].update({"ranks": ranks, "restart_interval_s": restart})
    if max_time is not None:
        base["laydown"]["max_time_s"] = max_time
    out: dict[str, Path] = {}
    for name in (REFERENCE, *variants):
        data = {**variant_data(base, name, interval), "name": f"sheet_effect_{point}_{section}_{name}",
                "output_dir": str(runs / name)}
        path = runs / f"{name}.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, f"# {name} lay-down of campaign point {point} {section}: written by "
                          "bench/coupling/run_sheet_effect.py\n" + yaml.safe_dump(data, sort_keys=False))
        load_scene(path)  # validated
        out[name] = path
    return out


def build_dir() -> Path:
    return Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()


def run(paths: dict[str, Path], resume: bool, to: str, with_reference: bool) -> None:
    """The reference's fabric and flow, copied to the variants; then the lay-downs (and the
    permeability with ``to``) side by side, the reference's only if ``with_reference``."""
    cmd = [sys.executable, "-m", "fiberform", "run", "--build-dir", str(build_dir())]
    if subprocess.run([*cmd, str(paths[REFERENCE]), "--to", "flow"]).returncode != 0:
        raise SystemExit("the reference scene's fabric and flow stages failed")
    src = load_scene(paths[REFERENCE]).output_path
    names = [n for n in paths if n != REFERENCE or with_reference]
    for name in names:
        dst = load_scene(paths[name]).output_path
        for stage in ("fabric", "flow"):
            if dst != src and not (dst / stage).exists():
                shutil.copytree(src / stage, dst / stage, symlinks=True)
    procs = []
    for name in names:
        log = (paths[name].parent / f"{name}.log").open("a")
        procs.append(subprocess.Popen([*cmd, str(paths[name]), "--to", to, *(["--resume"] if resume else [])],
                                      stdout=log, stderr=subprocess.STDOUT))
    codes = [p.wait() for p in procs]
    if any(codes):
        raise SystemExit(f"lay-downs {names} ended with {codes} (logs beside the scenes)")


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


@cache
def dump_frames(dump: Path) -> dict[int, Frame]:
    """The snapshots of a lay-down's ``traj.dump`` by step, read once per run even when several
    variants are compared with the same reference."""
    return {fr.step: fr for fr in read_dump(dump)}


MEASURES = ("fibers", "mass_fraction", "fines_fraction", "settled_grammage_kg_m2",
            "thickness_above_fabric_m", "node_height_50_90_99_m")


def compare(paths: dict[str, Path], variant: str, every: float, bins: int, dt: float,
            reference: dict[str, Any] | None = None) -> dict[str, Any]:
    """The table of the module docstring for ``variant`` against the reference, one row per common
    time; ``reference``: an earlier results JSON standing for the reference's run."""
    names = (REFERENCE, variant)
    sc = {n: load_scene(paths[n]) for n in names}
    out = {n: sc[n].output_path for n in names}
    with h5py.File(out[variant] / FIBERS_H5, "r") as b:
        mass = {variant: b["fibers/mass"][...]}
        fine = {variant: b["fibers/is_fine"][...].astype(bool)}
        # with a reference JSON: checked against the reference scene's fibers where they are here
        # (run() generates them with the reference's fabric and flow)
        if reference is None or (out[REFERENCE] / FIBERS_H5).exists():
            with h5py.File(out[REFERENCE] / FIBERS_H5, "r") as a:
                same = np.array_equal(a["fibers/x"][...], b["fibers/x"][...])
                if SAME_FIBERS[variant] and not same:
                    raise SystemExit(f"{REFERENCE} and {variant} generated different fibers: not a controlled comparison")
                if reference is None:
                    mass[REFERENCE], fine[REFERENCE] = a["fibers/mass"][...], a["fibers/is_fine"][...].astype(bool)
    top = read_yarns(out[REFERENCE] / FABRIC_H5).top
    u_s = read_superficial_velocity(out[REFERENCE] / "flow" / "flow.h5")
    v_settle = settle_speed(sc[REFERENCE], u_s)
    runs = names if reference is None else (variant,)
    frames = {n: dump_frames(out[n] / "laydown" / "work" / "traj.dump") for n in runs}
    if reference is None:
        ref_rows: dict[int, dict[str, Any]] = {}
        common = sorted(set(frames[REFERENCE]) & set(frames[variant]))
    else:
        ref_rows = {round(r["time_s"] / dt): r for r in reference["rows"]}
        common = sorted(set(ref_rows) & set(frames[variant]))
    stride = max(1, round(every / dt))
    steps = [s for s in common if s % stride == 0 and s > 0]
    if common and common[-1] not in steps:
        steps.append(common[-1])
    if variant == "two_way":
        t_q, q = read_patch_history(out[variant] / "laydown" / "work" / FLUID_CASE, DRAINAGE_FO["bottom"])
    fab = sc[REFERENCE].fabric
    assert fab is not None
    area = fab.size_x_m * fab.size_y_m
    rows = []
    for s in steps:
        b = frame_measures(sc[variant], frames[variant][s], mass[variant], fine[variant], top, bins, v_settle)
        row: dict[str, Any] = {"time_s": s * dt}
        if reference is None:
            a = frame_measures(sc[REFERENCE], frames[REFERENCE][s], mass[REFERENCE], fine[REFERENCE], top, bins,
                               v_settle)
            row.update({f"{REFERENCE}_{key}": a[key] for key in MEASURES})
        else:
            row.update({f"{REFERENCE}_{key}": ref_rows[s][f"{REFERENCE}_{key}"] for key in MEASURES})
        row.update({f"{variant}_{key}": b[key] for key in MEASURES})
        diff: dict[str, Any] = dict.fromkeys(("grammage_map_rms_diff_rel", "grammage_map_max_diff_rel",
                                              "profile_max_diff_rel", "com_apart_median_m", "com_apart_90_m"))
        if reference is None:
            mean = float(np.mean(a["map"]))
            dmap = b["map"] - a["map"]
            zmax = max(a["z"].max(), b["z"].max())
            edges = np.arange(top - 10 * PROFILE_DZ, zmax + 2 * PROFILE_DZ, PROFILE_DZ)
            pa, pb = (np.histogram(m["z"], bins=edges, weights=m["m_node"])[0] for m in (a, b))
            diff.update({"grammage_map_rms_diff_rel": float(np.sqrt(np.mean(dmap ** 2))) / mean,
                         "grammage_map_max_diff_rel": float(np.max(np.abs(dmap))) / mean,
                         "profile_max_diff_rel": float(np.max(np.abs(pb - pa)) / max(pa.max(), pb.max()))})
            both, ia, ib = np.intersect1d(a["present"], b["present"], return_indices=True)
            if SAME_FIBERS[variant] and len(both):
                apart = np.linalg.norm(a["com"][ia] - b["com"][ib], axis=1)
                diff.update({"com_apart_median_m": float(np.median(apart)),
                             "com_apart_90_m": float(np.percentile(apart, 90))})
            cv_ref = float(np.std(a["map"]) / np.mean(a["map"]))
        else:
            cv_ref = ref_rows[s]["grammage_map_cv"][0]
        row.update(diff)
        row["grammage_map_cv"] = [cv_ref, float(np.std(b["map"]) / np.mean(b["map"]))]
        row[f"drainage_{REFERENCE}_m_s"] = u_s
        if variant == "two_way":
            k = int(np.searchsorted(t_q, s * dt * (1 + 1e-9), side="right")) - 1
            row[f"drainage_{variant}_m_s"] = float(q[k] / area) if k >= 0 else float("nan")
        else:
            row[f"drainage_{variant}_m_s"] = u_s
        rows.append(row)
    last = {n: max(frames[n]) * dt if frames[n] else 0.0 for n in runs}
    prods = {n: products(paths[n], sc[n]) for n in runs}
    if reference is not None:
        last[REFERENCE] = reference["last_snapshot_s"][REFERENCE]
        prods[REFERENCE] = reference["products"][REFERENCE]
    return {"names": list(names), "settle_speed_m_s": v_settle, "fabric_top_m": top, "bins": bins, "rows": rows,
            "last_snapshot_s": last, "products": prods,
            "reference_from": None if reference is None else reference.get("results_file")}


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


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{value * 100:.1f} %"


def _um(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e6:.1f}"


def print_table(res: dict[str, Any]) -> None:
    r0, v = res["names"]
    print(f"reference {r0}, variant {v} (ref / var)")
    print("| t (ms) | fibers | fines kept | settled g/m^2 | thickness above fabric (um) | grammage map RMS / "
          "max diff | profile max diff | same fiber apart, median / 90 % (um) | drainage (mm/s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in res["rows"]:
        print(f"| {r['time_s'] * 1e3:.1f} | {r[f'{r0}_fibers']} / {r[f'{v}_fibers']} | "
              f"{_share(r[f'{r0}_fines_fraction'])} / {_share(r[f'{v}_fines_fraction'])} | "
              f"{r[f'{r0}_settled_grammage_kg_m2'] * 1e3:.2f} / {r[f'{v}_settled_grammage_kg_m2'] * 1e3:.2f} | "
              f"{r[f'{r0}_thickness_above_fabric_m'] * 1e6:.1f} / {r[f'{v}_thickness_above_fabric_m'] * 1e6:.1f} | "
              f"{_pct(r['grammage_map_rms_diff_rel'])} / {_pct(r['grammage_map_max_diff_rel'])} | "
              f"{_pct(r['profile_max_diff_rel'])} | {_um(r['com_apart_median_m'])} / "
              f"{_um(r['com_apart_90_m'])} | {r[f'drainage_{r0}_m_s'] * 1e3:.2f} / "
              f"{r[f'drainage_{v}_m_s'] * 1e3:.2f} |")


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
    ap.add_argument("--variants", nargs="+", choices=VARIANTS, default=["two_way"],
                    help="what is compared with the one-way reference (default two_way)")
    ap.add_argument("--reference-json", type=Path, default=None,
                    help="take the reference from this earlier results JSON instead of laying it down")
    ap.add_argument("--compare", action="store_true", help="run nothing: compare what the runs have")
    ap.add_argument("--every", type=float, default=2e-3, help="--compare: time between rows, s (default 2e-3)")
    ap.add_argument("--bins", type=int, default=6, help="--compare: grammage map cells per side (default 6)")
    ap.add_argument("--out", type=Path, default=None, help="--compare: results JSON")
    a = ap.parse_args()
    if not 1 <= a.ranks <= 64 or not 1 <= a.interval <= 100000 or not 0 < a.restart <= 1.0:
        ap.error("--ranks 1..64, --interval 1..100000, --restart in (0, 1] s")
    if not 0 < a.every <= 1.0 or not 1 <= a.bins <= 100 or (a.max_time is not None and not 0 < a.max_time <= 10.0):
        ap.error("--every in (0, 1] s, --bins 1..100, --max-time in (0, 10] s")
    if len(set(a.variants)) != len(a.variants) or (a.out is not None and len(a.variants) != 1):
        ap.error("--variants: each once; --out needs a single variant")
    runs = a.runs or Path("runs") / f"sheet-effect-{a.point}-{a.section}"
    if runs.is_absolute():
        ap.error("--runs: give a folder relative to the working directory")
    # the campaign as it was when the scenes were written (it may change while the lay-downs run)
    campaign_sha, point_sha = file_hash(a.campaign), point_key(a.campaign, a.point, a.section)
    ref_json = None
    if a.reference_json is not None:
        ref_json = json.loads(a.reference_json.read_text())
        ref_json["results_file"] = str(a.reference_json)
        if (ref_json.get("point"), ref_json.get("section")) != (a.point, a.section):
            ap.error(f"--reference-json: its point {ref_json.get('point')} {ref_json.get('section')} is not "
                     f"{a.point} {a.section}")
        code = ref_json.get("code", {})
        if "point_scene_sha256" in code:  # since session 33: the point's scene, presses left out
            if code["point_scene_sha256"] != point_sha:
                ap.error(f"--reference-json: its point {a.point} {a.section} was laid down from another scene "
                         "than --campaign gives it")
        elif code.get("campaign_sha256") != campaign_sha:
            ap.error("--reference-json: it was made from another campaign file than --campaign")
    outs: dict[str, Path] = {}
    for variant in a.variants:
        # two_way against a laid-down reference keeps its session-31 name; never overwrite the reference JSON
        suffix = "" if variant == "two_way" and ref_json is None else f"_{variant}"
        outs[variant] = a.out or HERE / "results" / f"sheet_effect_{a.point}_{a.section}{suffix}.json"
        if a.reference_json is not None and outs[variant].resolve() == a.reference_json.resolve():
            ap.error(f"--out {outs[variant]}: that is the --reference-json file, which this run reads")
    paths = scenes(a.campaign, a.point, a.section, a.ranks, a.restart, a.interval, a.max_time, runs, a.variants)
    if not a.compare:
        run(paths, a.resume, a.to, with_reference=ref_json is None)
    dt = load_scene(paths[REFERENCE]).laydown.timestep_s  # type: ignore[union-attr]
    for variant in a.variants:
        res = compare(paths, variant, a.every, a.bins, dt, ref_json)
        res.update({"point": a.point, "section": a.section, "ranks": a.ranks, "interval": a.interval,
                    "command": " ".join(sys.argv[1:]), "scenes": {n: str(paths[n]) for n in res["names"]},
                    "code": {"fiberform": package_version(), "git_revision": git_revision(),
                             "build_revision": build_revision(build_dir()), "campaign_sha256": campaign_sha,
                             "point_scene_sha256": point_sha},
                    "machine": machine_info()})
        print_table(res)
        for name, got in res["products"].items():
            if got:
                print(f"{name}: " + ", ".join(f"{k} {v:.6g}" for k, v in got.items()))
        out = outs[variant]
        atomic_write_text(out, json.dumps(res, indent=1) + "\n")
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
