#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The validation campaign of issue 15: thesis Table 4.1 reproduced end to end.

For every point (thesis cases A-F, G, and the seven experimental sheets' masses; see
scenes/thesis/campaign.yaml) and cross-section, a scene is derived from the shipped case scenes
(fiberform.campaign.point_scene) into ``runs/thesis-campaign/scenes/`` and run through
``fiberform sweep SCENE --seeds N`` (generate, fabric, flow, lay-down, permeability, press to the
experimental thickness, permeability of the pressed sheet). With ``pressure_press`` in the
campaign, each laid-down sheet is then pressed a second time, to that pressure
(fiberform.campaign.pressure_scene, run_pressure_sweep: the scene ``<point>-<section>-pressure.yaml``
differs from the point's only in ``press``; its sweep takes over each seed's finished generate,
fabric, flow, lay-down and permeability folders, so nothing is laid down twice, and runs the press
and the pressed permeability). Finished stages are skipped, so the same command resumes the
campaign; a lay-down that was killed (a time limit, Ctrl-C, a crash) continues from its last
LIGGGHTS restart file only with ``--resume`` (passed to every ``fiberform sweep``, the pressure
presses' included); without it that lay-down starts over and its restart files are removed.
``--jobs N`` runs up to N seeds of a point at once on this machine (``fiberform sweep
--jobs``). ``--points-at-once N`` runs up to N point-section groups at once, each its own
``fiberform sweep`` (and pressure presses), its output in ``RUNS/logs/<group>.log``: once a sheet
has formed, a lay-down's contact cluster is solved by one rank (docs/models/contact.md section 9),
so on a small machine two points side by side use the cores that one point leaves idle
(docs/bench/laydown.md, "Two points side by side"). The number of lay-downs at once is the
product of the two. ``--submit slurm|pbs`` submits each sweep as job arrays instead; the pressure presses of
a point can only be submitted once its sweep has finished the lay-downs and permeabilities (they
are copied, not awaited by a job dependency): run the same command again then (and without
--submit, or with --collect-only, once everything is done).

    .venv/bin/python bench/thesis/run.py --reduced            # make validate: A and C, seed 1
    .venv/bin/python bench/thesis/run.py                      # the full campaign (cluster scale)
    .venv/bin/python bench/thesis/run.py --points A --sections circular --seeds 1
    .venv/bin/python bench/thesis/run.py --collect-only       # tables from what has finished
    .venv/bin/python bench/thesis/run.py --reduced --resume   # again after a kill: lay-downs go on
                                                              # from their restart files
    .venv/bin/python bench/thesis/run.py --points S3 --sections circular --seeds 1 --keep
                                                              # add S3, keep the file's other points
    .venv/bin/python bench/thesis/run.py --points S4,S5 --sections circular --seeds 1 --keep \
        --points-at-once 2                                    # S4 and S5 side by side

Writes bench/thesis/results/campaign[-reduced].json: the machine, per variant (point, section,
seed) the collected metrics and stage wall times with the ranks each stage ran on, per point the
mean and sd over seeds, and per experimental sheet simulated / measured permeability in both mass
conventions, unpressed, pressed to thickness and pressed to pressure (docs/validation/table41.md).
Each point row carries its ``sem_mass_kg`` (mass x ``sem_factor``, also in the file): in the SEM
convention every point, case or sheet, is a support point at that mass; the per-sheet SEM values
name the points they come from (``support``).
A variant that failed is listed with its error; a pressure press that waits for its lay-down is
listed under ``pending``.
Next to it (fiberform.campaign_report): campaign[-reduced]-fig412-thickness.png and
campaign[-reduced]-fig413-permeability.png (thesis Figs. 4.12/4.13 redrawn) and campaign[-reduced].md
(per-sheet tables); --collect-only redraws them from what has finished. ``--collect-only --keep``
keeps the file's groups whose run folders are not here (it replaces only the groups it found a
sweep of), so it redraws a results file on another machine:

    .venv/bin/python bench/thesis/run.py --collect-only --keep
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import yaml

from fiberform import campaign as cp
from fiberform import campaign_report, executors
from fiberform.errors import ConfigError, FiberformError
from fiberform._versions import build_revision, git_revision, package_version
from fiberform.provenance import atomic_write_text, file_hash, machine_info
from fiberform.scene import load_scene

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
THESIS = ROOT / "scenes" / "thesis"


def _csv_list(text: str) -> list[str]:
    return [t for t in (s.strip() for s in text.split(",")) if t]


def _write_scene(path: Path, header: str, data: dict[str, Any]) -> None:
    text = header + yaml.safe_dump(data, sort_keys=False)
    if not path.is_file() or path.read_text() != text:
        atomic_write_text(path, text)


def _read_collect(sweep_dir: Path, fiberform: list[str], build: Path, label: str) -> list[dict[str, str]]:
    """``fiberform collect SWEEP_DIR`` and its collect.csv rows (none before the sweep exists)."""
    if not (sweep_dir / "sweep.json").is_file():
        return []
    col = subprocess.run([*fiberform, "collect", str(sweep_dir), "--build-dir", str(build)],
                         capture_output=True, text=True)
    if col.returncode != 0:
        print(f"== {label}: fiberform collect failed: {col.stderr.strip()[-500:]}", file=sys.stderr)
    table = sweep_dir / "collect.csv"
    return list(csv.DictReader(table.read_text().splitlines())) if table.is_file() else []


def _kept_file(out: Path, current: dict[str, Any] | None, sem_factor: float) -> dict[str, Any] | None:
    """--keep: the results JSON ``out`` (None if there is none yet); ConfigError (exit 2) if it was
    written with another pressure_press than the campaign's ``current`` or with another SEM factor
    than the campaign's ``sem_factor`` (its rows not comparable: a case point's press target is
    the thickness at its SEM-mapped mass). A file written before the SEM factor was recorded
    (sessions 9-22) is taken as of the campaign's."""
    if not out.is_file():
        return None
    previous: dict[str, Any] = json.loads(out.read_text())
    if previous.get("pressure_press") != current:
        raise ConfigError(f"--keep: {out} was written with pressure_press {previous.get('pressure_press')}, the "
                          f"campaign now has {current}: its rows are not comparable; run their points again or give "
                          "another --out")
    old = previous.get("sem_factor")
    if old is not None and abs(old - sem_factor) > 1e-9 * sem_factor:
        raise ConfigError(f"--keep: {out} was written with SEM factor {old:.6g}, the campaign's sem_mapping now "
                          f"gives {sem_factor:.6g}: its rows are not comparable; run their points again or give "
                          "another --out")
    return previous


@dataclass
class GroupJob:
    """One point-section group: its sweep's command line, its scene, the sweep's folder and its
    pressure scene (None without the campaign's pressure_press)."""
    group: str
    cmd: list[str]
    scene: Path
    sweep_dir: Path
    pressure_scene: Path | None


@dataclass
class GroupOutcome:
    failures: dict[str, str] = field(default_factory=dict)
    pending: dict[str, dict[str, str]] = field(default_factory=dict)


def print_line(line: str) -> None:
    print(line, flush=True)


def _run_group(job: GroupJob, seeds: int, build: Path, opts: Any, args: argparse.Namespace,
               emit: Callable[[str], None], log: IO[str] | None) -> GroupOutcome:
    """The group's ``fiberform sweep`` (its output to ``log``, or inherited with None), then its
    pressure presses; the group's failures and waiting pressure presses."""
    out = GroupOutcome()
    group = job.group
    emit(f"== {group}: fiberform {' '.join(job.cmd[3:])}")
    t0 = time.monotonic()
    proc = subprocess.run(job.cmd, stdout=log, stderr=subprocess.STDOUT if log else None)
    emit(f"== {group}: exit {proc.returncode} after {time.monotonic() - t0:.0f} s")
    if proc.returncode != 0:
        out.failures[group] = (f"fiberform sweep exit {proc.returncode} "
                               f"({'see its output above' if log is None else 'see ' + log.name})")
    if job.pressure_scene is None:
        return out
    emit(f"== {group}-pressure: the second press ({job.pressure_scene}), lay-downs taken over from "
         f"{job.sweep_dir}")
    try:
        pr = cp.run_pressure_sweep(job.scene, job.pressure_scene, seeds, build, emit, opts, jobs=args.jobs,
                                   resume=args.resume)
    except FiberformError as exc:
        out.failures[f"{group}-pressure"] = str(exc)
        return out
    if pr.waiting:
        out.pending[f"{group}-pressure"] = pr.waiting
        emit(f"== {group}-pressure: {len(pr.waiting)} seed(s) wait for their lay-down and permeability in "
             f"{job.sweep_dir} (not laid down again)"
             + (": run this command again once they are done" if args.submit else ""))
    if pr.failed:
        out.failures[f"{group}-pressure"] = (f"failed: {', '.join(pr.failed)} "
                                             f"({'see the output above' if log is None else 'see ' + log.name})")
    return out


def _run_groups_at_once(jobs: list[GroupJob], at_once: int, logs: Path, seeds: int, build: Path, opts: Any,
                        args: argparse.Namespace) -> list[GroupOutcome]:
    """--points-at-once: up to ``at_once`` groups run side by side, each writing its output to
    ``logs/<group>.log`` (appended: a resumed campaign keeps the earlier output); this process
    prints when each starts and ends. The outcomes in the order of ``jobs``."""
    lock = threading.Lock()

    def one(job: GroupJob) -> GroupOutcome:
        path = logs / f"{job.group}.log"
        with lock:
            print(f"== {job.group}: started, output in {path}", flush=True)
        t0 = time.monotonic()
        with path.open("a") as log:
            def emit(line: str) -> None:
                log.write(line + "\n")
                log.flush()

            try:
                outcome = _run_group(job, seeds, build, opts, args, emit, log)
            except Exception as exc:  # noqa: BLE001 - reported as the group's failure, the others go on
                emit(f"== {job.group}: {type(exc).__name__}: {exc}")
                outcome = GroupOutcome(failures={job.group: f"{type(exc).__name__}: {exc} (see {path})"})
        with lock:
            state = "failed: " + "; ".join(outcome.failures.values()) if outcome.failures else "done"
            print(f"== {job.group}: {state} after {time.monotonic() - t0:.0f} s (output in {path})", flush=True)
        return outcome

    with ThreadPoolExecutor(max_workers=at_once) as pool:
        return list(pool.map(one, jobs))


def main() -> int:
    try:
        return _main()
    except FiberformError as exc:
        print(f"run.py: error: {exc}", file=sys.stderr)
        return exc.exit_status


def _main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--campaign", type=Path, default=THESIS / "campaign.yaml",
                    help="campaign definition; its folder holds the base scenes and experiments.csv")
    ap.add_argument("--runs", type=Path, default=Path("runs") / "thesis-campaign",
                    help="output folder of the runs, relative to the current directory "
                    "(default runs/thesis-campaign)")
    ap.add_argument("--reduced", action="store_true", help="the campaign's reduced set (make validate)")
    ap.add_argument("--points", type=_csv_list, help="comma list of points (A..G, S1..S7); default all")
    ap.add_argument("--sections", type=_csv_list, help="comma list: circular, rectangular; default both")
    ap.add_argument("--seeds", type=int, help="seeds per point (default: the campaign's)")
    ap.add_argument("--submit", choices=("slurm", "pbs"), help="submit job arrays instead of running here")
    ap.add_argument("--jobs", type=int, default=1, metavar="N",
                    help="seeds of a point run at once on this machine (fiberform sweep --jobs; not with --submit)")
    ap.add_argument("--points-at-once", type=int, default=1, metavar="N",
                    help="point-section groups run at once on this machine, each its own fiberform sweep, output "
                         "in RUNS/logs/GROUP.log (not with --submit)")
    ap.add_argument("--collect-only", action="store_true", help="run nothing; tabulate what has finished")
    ap.add_argument("--resume", action="store_true",
                    help="a killed lay-down continues from its last restart file (fiberform sweep --resume, "
                         "passed to every sweep); without it, it starts over")
    ap.add_argument("--out", type=Path, help="results JSON (default bench/thesis/results/campaign[-reduced].json)")
    ap.add_argument("--keep", action="store_true",
                    help="keep the points of the existing results JSON that this call does not run (their rows "
                         "unchanged; listed under kept_from), instead of writing only this call's points")
    args = ap.parse_args()

    c = cp.load_campaign(args.campaign)
    thesis = args.campaign.resolve().parent
    sheets = cp.read_experiments(thesis / "experiments.csv")
    pts = cp.points(c, sheets)
    f_sem = cp.sem_factor(c, sheets)
    names = args.points or (c.reduced.points if args.reduced else [p.name for p in pts])
    unknown = sorted(set(names) - {p.name for p in pts})
    if unknown:
        print(f"--points: unknown point(s) {', '.join(unknown)} (known: {', '.join(p.name for p in pts)})",
              file=sys.stderr)
        return 2
    sections = args.sections or list(c.sections)
    if bad := sorted(set(sections) - {"circular", "rectangular"}):
        print(f"--sections: {', '.join(bad)}: allowed circular, rectangular", file=sys.stderr)
        return 2
    seeds = args.seeds or (c.reduced.seeds if args.reduced else c.seeds)
    if not 1 <= seeds <= 100:
        print(f"--seeds {seeds}: allowed 1..100", file=sys.stderr)
        return 2
    if not 1 <= args.jobs <= 64 or (args.jobs > 1 and args.submit):
        print(f"--jobs {args.jobs}: allowed 1..64, and only without --submit", file=sys.stderr)
        return 2
    if not 1 <= args.points_at_once <= 64 or (args.points_at_once > 1 and args.submit):
        print(f"--points-at-once {args.points_at_once}: allowed 1..64, and only without --submit", file=sys.stderr)
        return 2
    out = args.out or HERE / "results" / ("campaign-reduced.json" if args.reduced else "campaign.json")
    current = None if c.pressure_press is None else c.pressure_press.model_dump()
    if args.keep:  # checked before anything runs (and read again at the end)
        _kept_file(out, current, f_sem)
    fiberform = [sys.executable, "-m", "fiberform"]
    build = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()
    if args.runs.is_absolute():
        print("--runs: give a folder relative to the current directory", file=sys.stderr)
        return 2
    scenes_dir = args.runs / "scenes"
    scenes_dir.mkdir(parents=True, exist_ok=True)

    chosen = [p for p in pts if p.name in names]
    groups: dict[str, Path] = {}  # "A-circular" -> sweep dir
    pressure_groups: dict[str, Path] = {}  # "A-circular" -> the pressure presses' sweep dir
    failures: dict[str, str] = {}
    pending: dict[str, dict[str, str]] = {}  # "A-circular-pressure" -> {variant: why it waits}
    opts = executors.batch_options(args.submit) if args.submit else None
    jobs: list[GroupJob] = []
    t_start = time.monotonic()
    for p in chosen:
        for section in sections:
            group = f"{p.name}-{section}"
            data = cp.point_scene(c, p, section, thesis, args.runs)  # type: ignore[arg-type]
            scene_path = scenes_dir / f"{group}.yaml"
            header = (f"# campaign point {p.name} ({p.mass_kg * 1e9:.2f} ug, experimental mass "
                      f"{p.experimental_mass_kg * 1e9:.2f} ug, press target {p.press_target_m * 1e6:.1f} um), "
                      f"{section}: derived by bench/thesis/run.py from {c.base[section]}\n")  # type: ignore[index]
            _write_scene(scene_path, header, data)
            groups[group] = Path(f"{load_scene(scene_path).output_dir}-sweep")
            pressure_path = scenes_dir / f"{group}-pressure.yaml"
            if c.pressure_press is not None:
                _write_scene(pressure_path, f"# the second press of campaign point {group}: {scene_path.name} "
                             f"with press in pressure mode ({c.pressure_press.target_pressure_Pa:g} Pa), derived by "
                             "bench/thesis/run.py\n", cp.pressure_scene(c, data))
                pressure_groups[group] = Path(f"{load_scene(pressure_path).output_dir}-sweep")
            if args.collect_only:
                continue
            cmd = [*fiberform, "sweep", str(scene_path), "--seeds", str(seeds), "--build-dir", str(build)]
            if args.submit:
                cmd += ["--submit", args.submit]
            elif args.jobs > 1:
                cmd += ["--jobs", str(args.jobs)]
            if args.resume:
                cmd.append("--resume")
            jobs.append(GroupJob(group, cmd, scene_path, groups[group],
                                 pressure_path if c.pressure_press is not None else None))
    if args.points_at_once == 1 or len(jobs) <= 1:
        outcomes = [_run_group(job, seeds, build, opts, args, print_line, None) for job in jobs]
    else:
        logs = args.runs / "logs"
        logs.mkdir(parents=True, exist_ok=True)
        outcomes = _run_groups_at_once(jobs, args.points_at_once, logs, seeds, build, opts, args)
    for outcome in outcomes:
        failures.update(outcome.failures)
        pending.update(outcome.pending)

    collected: dict[str, list[dict[str, str]]] = {}
    variants: list[dict[str, Any]] = []
    for group, sweep_dir in groups.items():
        rows = _read_collect(sweep_dir, fiberform, build, group)
        if group in pressure_groups:
            rows, problems = cp.merge_pressure(rows, _read_collect(pressure_groups[group], fiberform, build,
                                                                   f"{group}-pressure"))
            if problems:
                failures[f"{group}-pressure"] = "; ".join(problems)
        if not rows and not (sweep_dir / "sweep.json").is_file():
            continue
        collected[group] = rows
        point, section = group.split("-", 1)
        scene = load_scene(next(iter(sorted((sweep_dir / "scenes").glob("*.yaml")))))
        ranks = {"laydown": scene.laydown.ranks if scene.laydown else 1,
                 "press": scene.press.ranks if scene.press else 1}
        for r in rows:
            variants.append({"point": point, "section": section, "ranks": ranks, **r})
    kept_from: dict[str, Any] | None = None
    point_rows = [{"name": p.name, "mass_kg": p.mass_kg, "experimental_mass_kg": p.experimental_mass_kg,
                   "press_target_m": p.press_target_m, "sem_mass_kg": p.sem_mass_kg} for p in chosen]
    # as the file is now: another call may have added to it meanwhile
    if args.keep and (previous := _kept_file(out, current, f_sem)) is not None:
        # a run replaces the groups it ran; --collect-only only those it found a sweep of here, so
        # that `--collect-only --keep` on a machine without (some of) the run folders keeps their rows
        kept = cp.kept_results(previous, set(collected) if args.collect_only else set(groups), f_sem)
        order = {p.name: i for i, p in enumerate(pts)}
        mine = {r["name"] for r in point_rows}
        point_rows = sorted([r for r in kept.points if r["name"] not in mine] + point_rows,
                            key=lambda r: order.get(r["name"], len(order)))
        variants = kept.variants + variants
        collected = {**kept.collected, **collected}
        failures = {**kept.failures, **failures}
        pending = {**kept.pending, **pending}
        kept_from = {"file": str(out), "groups": sorted(kept.collected), "command": previous.get("command"),
                     "machine": previous.get("machine"), "kept_from": previous.get("kept_from")}
        print(f"kept from {out}: {', '.join(sorted(kept.collected)) or 'nothing'}")
    summary = cp.summarise(collected)
    # the sections of this call and of any kept group
    table_sections = [s for s in ("circular", "rectangular")
                      if s in sections or any(g.split("-", 1)[1] == s for g in collected)]
    # per state (unpressed, pressed, pressure) the per-sheet ratios of its permeability metric, under
    # the key the report reads them from
    ratios = {f"sheets_{state}": {s: cp.sheet_ratios(sheets, pts, summary, s, metric)  # type: ignore[arg-type]
                                  for s in table_sections}
              for state, metric in campaign_report.QUANTITIES["permeability"].metric.items()}
    cp.write_json(out, {
        "campaign": str(args.campaign),
        "command": " ".join(sys.argv[1:]), "machine": machine_info(), "seeds": seeds,
        # the code of this call (each variant row has its products' git_revision / build_revision)
        "code": {"fiberform": package_version(), "git_revision": git_revision(),
                 "build_revision": build_revision(build), "campaign_sha256": file_hash(args.campaign)},
        "points": point_rows, "kept_from": kept_from,
        "pressure_press": current,
        # SEM convention: experimental mass = simulated mass x sem_factor (every point's sem_mass_kg)
        "sem_factor": f_sem,
        # --collect-only runs nothing: no wall time of its own (each stage's is in its variant row)
        "collect_only": bool(args.collect_only),
        "wall_s": None if args.collect_only else time.monotonic() - t_start, "failures": failures, "pending": pending, "variants": variants,
        "summary": summary, **ratios})
    print(f"wrote {out}")
    for path in campaign_report.write_report(json.loads(out.read_text()), sheets, out):
        print(f"wrote {path}")
    for group, stats in summary.items():
        line = ", ".join(f"{k} {v['mean']:.4g}" + (f" +- {v['sd']:.2g}" if v["n"] > 1 else "")
                         for k, v in stats.items())
        print(f"{group}: {line}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
