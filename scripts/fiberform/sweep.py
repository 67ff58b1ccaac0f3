# SPDX-License-Identifier: GPL-3.0-or-later
"""Parameter sweeps and seed ensembles (issue 14): ``fiberform sweep`` and ``fiberform collect``.

A sweep expands a base scene into variants: the Cartesian product of the ``--set PATH=V1,V2,...``
values and ``--seeds N`` seeds (base seed, base seed + 1, ...). Each variant is a complete scene file
``<sweep dir>/scenes/<name>_<k>.yaml`` (name ``<base name>_<k>``, output in ``<sweep dir>/<name>_<k>/``),
validated like any scene before anything is written; ``<sweep dir>/sweep.json`` records the base
scene (path and hash), the grid and every variant (file, output folder, seed, values). The sweep
dir is ``<base output_dir>-sweep``. Variants then run one after the other through the stage graph
(:func:`fiberform.pipeline.run_pipeline`), each skipped stage by stage when up to date, so a sweep is
resumed by running the same command again; with ``--jobs N`` up to N variants run at once, each as
its own ``fiberform run`` process writing ``<sweep dir>/scenes/<name>_<k>.log`` (:func:`run_sweep`).
Before they run, a stage that several variants would compute from the same inputs runs once and is
copied into the others (:func:`share_stages`; e.g. the fabric and flow of a seed ensemble).
``--resume`` has the meaning of ``fiberform run --resume`` in every variant (a killed lay-down
continues from its last restart file instead of starting over), whether the variants run here one
after the other, with ``--jobs`` or as job arrays (``--submit``).
``fiberform collect SWEEP_DIR`` reads each variant's key results (:meth:`Stage.metrics`) and stage
wall times into ``collect.csv`` and ``collect.png``.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from . import __version__, executors
from .errors import ConfigError, FiberformError
from .pipeline import StageGraph, applicable_stages, plan_run, run_pipeline
from .provenance import atomic_write_text, file_hash, read_provenance
from .scene import load_scene, parse_scene, read_scene_yaml
from .stages import Stage, StageContext

__all__ = ["SWEEP_JSON", "Variant", "collect", "expand", "parse_set", "run_sweep", "set_field", "share_groups",
           "share_stages", "submit_sweep", "write_sweep"]

SWEEP_JSON, COLLECT_CSV, COLLECT_PNG = "sweep.json", "collect.csv", "collect.png"
#: fields a sweep sets itself
RESERVED = ("name", "seed", "output_dir")
MAX_VARIANTS = 1000


@dataclass(frozen=True)
class Variant:
    name: str
    seed: int
    values: dict[str, Any]  # dotted field path -> value
    data: dict[str, Any]  # the complete scene mapping


def parse_set(text: str) -> tuple[str, list[Any]]:
    """``fibers.target_mass_kg=1e-9,2e-9`` -> ("fibers.target_mass_kg", [1e-9, 2e-9]); each value
    is read as a YAML scalar (number, bool, string). ConfigError names the option."""
    path, sep, values = text.partition("=")
    parts = path.split(".")
    if not sep or not values or not all(p.isidentifier() for p in parts):
        raise ConfigError(f"--set {text!r}: expected SECTION.FIELD=V1[,V2,...] (a dotted scene field path, "
                          "then comma-separated values)")
    if parts[0] in RESERVED:
        raise ConfigError(f"--set {text!r}: {parts[0]} is set by the sweep itself (use --seeds for seeds)")
    out = []
    for v in values.split(","):
        try:
            x = read_scene_yaml(v)
        except yaml.YAMLError:
            x = None
        if not isinstance(x, (int, float, str, bool)) or v.strip() == "":
            raise ConfigError(f"--set {text!r}: value {v!r} is not a number, boolean or word")
        out.append(x)
    if len(set(map(repr, out))) != len(out):
        raise ConfigError(f"--set {text!r}: a value is repeated")
    return path, out


def set_field(data: dict[str, Any], path: str, value: Any) -> None:
    """Set the dotted scene field ``path`` (``laydown.ranks``) of plain scene data, creating missing
    sections; ConfigError when a part of the path is not a section."""
    node = data
    keys = path.split(".")
    for k in keys[:-1]:
        child = node.get(k)
        if child is None:
            child = node[k] = {}
        if not isinstance(child, dict):
            raise ConfigError(f"--set {path}: {k} is not a section")
        node = child
    node[keys[-1]] = value


def expand(base_path: Path, sets: Sequence[tuple[str, list[Any]]], seeds: int,
           first_seed: int | None = None) -> tuple[Path, list[Variant]]:
    """The sweep dir and the validated variants (SceneError / ConfigError before anything is
    written)."""
    base = load_scene(base_path)
    raw = read_scene_yaml(base_path.read_text())
    if seeds < 1:
        raise ConfigError(f"--seeds {seeds}: must be at least 1")
    paths = [p for p, _ in sets]
    if len(set(paths)) != len(paths):
        raise ConfigError(f"--set: field given twice ({', '.join(paths)})")
    s0 = base.seed if first_seed is None else first_seed
    if not 0 <= s0 <= 2**31 - 1 - seeds:
        raise ConfigError(f"--first-seed {s0}: seeds must lie in [0, 2^31 - 1]")
    grid = list(itertools.product(*(v for _, v in sets), range(s0, s0 + seeds)))
    if len(grid) > MAX_VARIANTS:
        raise ConfigError(f"--set/--seeds: {len(grid)} variants (limit {MAX_VARIANTS})")
    sweep_dir = Path(f"{base.output_path}-sweep")
    stem = base.name[:56]
    variants = []
    for k, combo in enumerate(grid):
        data = json.loads(json.dumps(raw))  # a deep copy of plain YAML data
        values = dict(zip(paths, combo[:-1], strict=True))
        for p, v in values.items():
            set_field(data, p, v)
        name = f"{stem}_{k:03d}"
        data.update(name=name, seed=combo[-1], output_dir=str(sweep_dir / name))
        label = ", ".join(f"{p}={v!r}" for p, v in values.items()) or "base"
        parse_scene(data, f"{base_path} variant {k} ({label}, seed {combo[-1]})")
        variants.append(Variant(name, int(combo[-1]), values, data))
    return sweep_dir, variants


def write_sweep(base_path: Path, sweep_dir: Path, variants: Sequence[Variant],
                sets: Sequence[tuple[str, list[Any]]]) -> list[Path]:
    """Write the variant scene files and sweep.json (each atomically); returns the scene files.
    A data file the base scene names relative to itself (``fiber_generation.data_csv``) is
    copied beside the variants."""
    scenes = sweep_dir / "scenes"
    scenes.mkdir(parents=True, exist_ok=True)
    base = load_scene(base_path)
    gen = getattr(base, "fiber_generation", None)
    csv_name = getattr(gen, "data_csv", None) if gen is not None else None
    if csv_name:
        src = base_path.parent / csv_name
        dst = scenes / csv_name
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst)
    files = []
    for v in variants:
        f = variant_path(sweep_dir, v)
        header = (f"# fiberform sweep variant of {base_path} (fiberform {__version__}); "
                  f"values: {json.dumps(v.values)}; seed {v.seed}\n")
        atomic_write_text(f, header + yaml.safe_dump(v.data, sort_keys=False))
        files.append(f)
    record = {
        "fiberform": __version__,
        "base_scene": str(base_path),
        "base_scene_hash": file_hash(base_path),
        "set": {p: vals for p, vals in sets},
        "seeds": sorted({v.seed for v in variants}),
        "variants": [{"name": v.name, "scene": str(f.relative_to(sweep_dir)), "output_dir": v.data["output_dir"],
                      "seed": v.seed, "values": v.values} for v, f in zip(variants, files, strict=True)],
    }
    atomic_write_text(sweep_dir / SWEEP_JSON, json.dumps(record, indent=2) + "\n")
    return files


def variant_ranks(files: Sequence[Path], build_dir: Path, start: str | None, stop: str | None) -> int:
    """The most MPI ranks any selected stage of any variant runs on (Stage.ranks)."""
    most = 1
    for f in files:
        ctx = StageContext(scene=load_scene(f), scene_path=f, build_dir=build_dir)
        stages, _ = plan_run(ctx, start, stop, None, require_upstream=False)
        most = max([most] + [st.ranks(ctx) for st in stages])
    return most


def _own_hashes(st: Stage, graph: StageGraph, ctx: StageContext) -> dict[str, str]:
    """The stage's input hashes without those of the products of its upstream stages (which are
    shared when the upstream stage is)."""
    made = {p for up in graph.upstream[st.name] for p in graph.stages[up].product_paths(ctx)}
    skip = {k for k, p in st.needs(ctx).items() if p in made}
    return {k: v for k, v in st.input_hashes(ctx).items() if k not in skip}


def share_groups(graphs: Sequence[StageGraph], selected: Sequence[str]) -> list[tuple[str, list[int]]]:
    """The stages (of ``selected``, in pipeline order) that two or more variants (their stage
    graphs, each with its scene's context) would compute alike, and for each the indices of those
    variants (the first one the donor). Variants share
    a stage when its own input hashes agree (scene sections of its ``uses``, code version,
    programs, files the stage reads that no stage makes) and they share every upstream stage of
    it; so a stage is grouped at most as widely as the stages it reads from."""
    group_of: dict[str, list[int]] = {}  # stage -> group id per variant (negative: alone)
    out: list[tuple[str, list[int]]] = []
    for name in graphs[0].order:
        if name not in selected:
            continue
        keys: dict[tuple[Any, ...], int] = {}
        ids = []
        for i, g in enumerate(graphs):
            if name not in g.stages or any(up not in group_of for up in g.upstream[name]):
                ids.append(-1 - i)  # alone: the stage is absent, or an upstream stage is not shared
                continue
            key = (tuple(group_of[up][i] for up in g.upstream[name]),
                   json.dumps(_own_hashes(g.stages[name], g, g.ctx), sort_keys=True))
            ids.append(keys.setdefault(key, len(keys)))
        group_of[name] = ids
        for gid in sorted({i for i in ids if i >= 0}):
            members = [i for i, x in enumerate(ids) if x == gid]
            if len(members) > 1:
                out.append((name, members))
    return out


def share_stages(files: Sequence[Path], build_dir: Path, start: str | None, stop: str | None,
                 echo: Callable[[str], None], resume: bool = False) -> list[tuple[str, list[int]]]:
    """Run each stage that several variants would compute alike once, in the first of them, and
    copy its folder into the others (:func:`fiberform.reuse.adopt_stages`, which copies only
    where the target's stage then counts as up to date), before the variants run; e.g. the
    fabric and flow of a seed ensemble, or the lay-down of a sweep over press settings. A donor
    stage that fails is reported and left to the variants' own runs. Returns the groups shared
    (:func:`share_groups`)."""
    from .reuse import adopt_stages

    if len(files) < 2:
        return []
    try:
        ctxs = [StageContext(scene=load_scene(f), scene_path=f, build_dir=build_dir, options={"resume": resume})
                for f in files]
        selected = [st.name for st in plan_run(ctxs[0], start, stop, None, require_upstream=False)[0]]
        graphs = [StageGraph(applicable_stages(c.scene), c) for c in ctxs]
        groups = share_groups(graphs, selected)
    except FiberformError as exc:  # the variants' own runs report it
        echo(f"sweep: no stage shared ({exc})")
        return []
    lacking: dict[int, set[str]] = {i: set() for i in range(len(files))}  # shared stages not up to date
    for name, members in groups:
        members = [i for i in members if not lacking[i] & set(graphs[i].upstream[name])]
        if len(members) < 2:
            continue
        donor, ctx = members[0], ctxs[members[0]]
        echo(f"== shared: {name} of {len(members)} variants runs once in {files[donor].stem} ==")
        try:
            run_pipeline(ctx, [graphs[donor].stages[name]], set(), echo)
        except FiberformError as exc:
            echo(f"shared {name} FAILED in {files[donor].stem} ({exc}); each variant runs it itself")
            for i in members:
                lacking[i].add(name)
            continue
        for i in members[1:]:
            a = adopt_stages(ctxs[i], ctx.scene.output_path, [name])[0]
            echo(f"{files[i].stem}: {name} {a.action}" + (f" ({a.detail})" if a.detail and not a.up_to_date else ""))
            if not a.up_to_date:
                lacking[i].add(name)
    return groups


def run_sweep(files: Sequence[Path], build_dir: Path, start: str | None, stop: str | None,
              echo: Callable[[str], None], jobs: int = 1, resume: bool = False, share: bool = True) -> list[str]:
    """Run each variant's pipeline; returns the names of the variants that failed (the others
    still run). ``share``: first the stages several variants would compute alike, once each
    (:func:`share_stages`). ``jobs`` > 1: up to that many variants at once
    (:func:`_run_concurrently`). ``resume``: as ``fiberform run --resume`` (the stage option
    ``resume``: a killed lay-down continues from its last restart file instead of starting over)."""
    if share:
        share_stages(files, build_dir, start, stop, echo, resume)
    if jobs > 1 and len(files) > 1:
        return _run_concurrently(files, build_dir, start, stop, echo, jobs, resume)
    failed = []
    for i, f in enumerate(files, 1):
        echo(f"== variant {i}/{len(files)}: {f} ==")
        try:
            scene = load_scene(f)
            ctx = StageContext(scene=scene, scene_path=f, build_dir=build_dir, options={"resume": resume})
            stages, forced = plan_run(ctx, start, stop, None)
            run_pipeline(ctx, stages, forced, echo)
        except FiberformError as exc:
            echo(f"variant {f.stem} FAILED: {exc}")
            failed.append(f.stem)
    return failed


def _run_concurrently(files: Sequence[Path], build_dir: Path, start: str | None, stop: str | None,
                      echo: Callable[[str], None], jobs: int, resume: bool = False) -> list[str]:
    """Up to ``jobs`` variants at once, each as ``fiberform run SCENE`` (with --from/--to, and
    --resume when ``resume``) in a process of its own, its output in the scene file's ``.log``; a
    line when each starts and ends. On SIGTERM or Ctrl-C (Terminated, KeyboardInterrupt) the
    running variants get SIGTERM (each stops its programs and records its stage as failed, as
    `fiberform run` does) and the exception goes on."""
    cmd0 = [sys.executable, "-m", "fiberform", "run", "--build-dir", str(build_dir)]
    cmd0 += (["--from", start] if start else []) + (["--to", stop] if stop else [])
    cmd0 += ["--resume"] if resume else []
    env = dict(os.environ)
    here = str(Path(__file__).resolve().parents[1])  # the package's parent: importable in the child
    env["PYTHONPATH"] = here + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    queue = list(enumerate(files, 1))
    running: dict[subprocess.Popen[bytes], tuple[int, Path, float]] = {}
    failed: list[str] = []
    try:
        while queue or running:
            while queue and len(running) < jobs:
                i, f = queue.pop(0)
                log = f.with_suffix(".log")
                with open(log, "wb") as out:
                    proc = subprocess.Popen([*cmd0, str(f)], stdout=out, stderr=subprocess.STDOUT, env=env)
                running[proc] = (i, f, time.monotonic())
                echo(f"== variant {i}/{len(files)}: {f} started (output: {log}) ==")
            done = [p for p in running if p.poll() is not None]
            if not done:
                time.sleep(0.5)
                continue
            for proc in done:
                i, f, t0 = running.pop(proc)
                wall = time.monotonic() - t0
                if proc.returncode == 0:
                    echo(f"variant {i}/{len(files)} {f.stem} done in {wall:.0f} s")
                else:
                    tail = f.with_suffix(".log").read_text(errors="replace").strip().splitlines()[-3:]
                    echo(f"variant {f.stem} FAILED (exit {proc.returncode} after {wall:.0f} s; "
                         f"{f.with_suffix('.log')}): " + " | ".join(tail))
                    failed.append(f.stem)
    except BaseException:
        for proc in running:
            proc.terminate()
        for proc in running:
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
        raise
    return sorted(failed, key=[f.stem for f in files].index)


def variant_path(sweep_dir: Path, v: Variant) -> Path:
    """The scene file of variant ``v``."""
    return sweep_dir / "scenes" / f"{v.name}.yaml"


def submit_sweep(opts: executors.BatchOptions, base_path: Path, sweep_dir: Path, variants: Sequence[Variant],
                 sets: Sequence[tuple[str, list[Any]]], build_dir: Path, start: str | None, stop: str | None,
                 *, dry_run: bool, echo: Callable[[str], None], resume: bool = False) -> int:
    """``fiberform sweep --submit``: one job array per selected stage over the variants
    (:func:`fiberform.executors.plan_array_jobs`), scripts and ``variants.txt`` in
    ``<sweep dir>/jobs/``, array job IDs in its ``jobs.json`` and task k's ID in variant k's own
    job records (``fiberform status VARIANT``). Everything is checked before anything is written.
    ``resume``: the scripts run each stage with ``--resume`` (as ``fiberform run --resume``)."""
    workdir = Path.cwd()
    sweep_abs = (workdir / sweep_dir).resolve()
    graphs = []
    for v in variants:
        scene = parse_scene(v.data, f"variant {v.name}")
        ctx = StageContext(scene=scene, scene_path=(workdir / variant_path(sweep_dir, v)).absolute(),
                           build_dir=build_dir, options={"resume": resume})
        graphs.append(StageGraph(applicable_stages(scene), ctx))
    jobs_folder = executors.jobs_dir(sweep_abs)
    records = executors.read_records(sweep_abs)
    states = executors.queue_states(records) if records else {}
    specs, listing = executors.plan_array_jobs(
        graphs, opts, start=start, stop=stop, sweep_name=f"{load_scene(base_path).name[:40]}_sweep",
        base_scene=(workdir / base_path).resolve(), jobs_folder=jobs_folder, workdir=workdir,
        python=executors.default_python(), states=states, resume=resume)
    if not dry_run:
        executors.check_submit_program(opts)
    files = write_sweep(base_path, sweep_dir, variants, sets)
    echo(f"sweep: {len(files)} variant(s) in {sweep_dir} (record {sweep_dir / SWEEP_JSON})")
    jobs_folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(jobs_folder / executors.VARIANTS_NAME, listing)
    replay = executors.write_scripts(opts, specs, workdir)
    if dry_run:
        for s in specs:
            echo(f"==> {s.script} <==\n{s.text}")
        echo(f"sweep: dry run: {len(specs)} array script(s) written, nothing submitted; {replay} submits them")
        return 0
    made = executors.submit_jobs(opts, specs, sweep_abs, workdir)
    executors.record_array_tasks(opts, made, [g.ctx.scene.output_path if g.ctx.scene.output_path.is_absolute()
                                              else workdir / g.ctx.scene.output_path for g in graphs])
    for rec in made:
        after = f" after {':'.join(rec.after)}" if rec.after else ""
        echo(f"{rec.stage}: {rec.scheduler} job array {rec.job_id} ({len(graphs)} tasks){after} ({rec.script})")
    echo(f"sweep: {len(made)} job array(s) recorded in {jobs_folder / executors.RECORDS_NAME}; `fiberform status "
         f"{variant_path(sweep_dir, variants[0])}` shows a variant's stages, `fiberform collect {sweep_dir}` "
         "tabulates the finished ones")
    return 0


def _read_record(sweep_dir: Path) -> dict[str, Any]:
    path = sweep_dir / SWEEP_JSON if sweep_dir.is_dir() else sweep_dir
    try:
        rec: dict[str, Any] = json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: not found (give the sweep folder that `fiberform sweep` wrote)") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: unreadable sweep record ({exc})") from None
    return rec


def collect(sweep_dir: Path, build_dir: Path) -> tuple[Path, Path, int]:
    """collect.csv (one row per variant: seed, swept values, every stage's metrics, wall time and
    git revision of the code that made its product; empty where a stage has not finished) and
    collect.png; returns the paths and the row count."""
    rec = _read_record(sweep_dir)
    root = sweep_dir if sweep_dir.is_dir() else sweep_dir.parent
    paths = list(rec["set"])
    rows: list[dict[str, Any]] = []
    columns: list[str] = []
    for v in rec["variants"]:
        f = root / v["scene"]
        scene = load_scene(f)
        ctx = StageContext(scene=scene, scene_path=f, build_dir=build_dir)
        row: dict[str, Any] = {"variant": v["name"], "seed": v["seed"], **v["values"]}
        for st in applicable_stages(scene):
            prods = st.product_paths(ctx)
            if not all(p.is_file() for p in prods):
                continue
            for key, value in st.metrics(ctx).items():
                row[key] = value
                columns.append(key)
            prov = read_provenance(prods[0])
            if "elapsed_s" in prov:
                row[f"{st.name}_wall_s"] = float(prov["elapsed_s"])
                columns.append(f"{st.name}_wall_s")
            for rev in ("git_revision", "build_revision"):  # the code (Python, binaries) that made it
                if rev in prov:  # (rows of other versions can mix)
                    row[f"{st.name}_{rev}"] = str(prov[rev])
                    columns.append(f"{st.name}_{rev}")
        rows.append(row)
    header = ["variant", "seed", *paths, *dict.fromkeys(c for c in columns if c not in paths)]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=header, restval="", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    out_csv, out_png = root / COLLECT_CSV, root / COLLECT_PNG
    atomic_write_text(out_csv, buf.getvalue())
    _plot(rows, paths, [c for c in header[2 + len(paths):] if not c.endswith(("_wall_s", "_git_revision", "_build_revision"))],
          out_png)
    return out_csv, out_png, len(rows)


def _plot(rows: list[dict[str, Any]], paths: list[str], metrics: list[str], out: Path) -> None:
    """Each metric against the first swept field (or the variant number), one point per variant,
    the mean over seeds as a line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = metrics[:6] or ["seed"]
    xkey = paths[0] if paths and all(isinstance(r.get(paths[0]), (int, float)) for r in rows) else None
    fig, axes = plt.subplots(1, len(shown), figsize=(3.2 * len(shown), 3.0), squeeze=False)
    for ax, m in zip(axes[0], shown, strict=False):
        pts = [(float(r[xkey]) if xkey else i, float(r[m])) for i, r in enumerate(rows)
               if isinstance(r.get(m), (int, float)) and math.isfinite(float(r[m]))]
        if pts:
            xs, ys = zip(*pts, strict=True)
            ax.plot(xs, ys, "o", alpha=0.6)
            means = {x: sum(y for xx, y in pts if xx == x) / sum(1 for xx, _ in pts if xx == x) for x in sorted(set(xs))}
            ax.plot(list(means), list(means.values()), "-", color="k", lw=1)
        ax.set_xlabel(xkey or "variant")
        ax.set_title(m, fontsize=9)
    fig.tight_layout()
    tmp = out.with_name(out.name + ".in_progress.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(out)
