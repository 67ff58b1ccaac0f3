#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Friction probe of the lay-down solver (issue 10): the cost of a short stretch of a lay-down,
continued from one of its restart files with other yarn-friction settings.

A thesis-scale lay-down spends its time in the Newton iterations of the fibers' contact clusters
once they pile up (docs/bench/laydown.md). This script takes a lay-down run folder (its
``scene.yaml`` and ``laydown/work`` with the restart files), and for every setting
``FRICTION:STICK`` (laydown.friction_coefficient and laydown.friction_stick) writes the stage's
own resumed input (fiberform.stages.laydown.build_input with ``resume_step``) into a folder of its
own, adds the solver's counters to the thermo output, runs ``--steps`` steps on one rank and
reports:

* loop time (s, the sum of LIGGGHTS' ``Loop time`` lines: start-up excluded);
* mean Newton iterations and tangent formations per fiber and step over the probe
  (``f_beam[19]``, ``f_beam[20]``: counted since the fix was defined, i.e. over the probe);
* the largest Newton iterations of one fiber in a step (``f_beam[15]`` at the thermo steps);
* mean iterations per fiber and step whose correction the contact limiter shortened (landings;
  ``f_beam[21]``, over the probe).

``--anderson M`` sets laydown.anderson_depth (Anderson mixing of the Newton corrections),
``--tolerance T`` laydown.newton_tolerance and ``--timestep DT`` laydown.timestep_s in every probe
(``--steps`` and ``--step`` count steps of the restart's run up to the restart, then of the new
length; scale the stick factor with the step to keep the friction's damping c_stick = k m / dt,
docs/bench/laydown.md "Yarn friction").

The probes run one after another unless ``--parallel 2`` (then the loop times are loaded: compare
the iteration counts, which do not depend on the load). Rows are appended to
``bench/laydown/results/friction_probe.json``; the folders go to ``runs/probes/``.

    .venv/bin/python bench/laydown/probe_friction.py --run runs/lim-probe/C-circular-loose-r2-s1 \\
        --step 4000 --settings 0.5:100 0.5:10 0.5:1 0:100

The default run folder is the first 4 ms of thesis case C (circular, seed 1, tolerance 1e-6, the
fibers starting to pile up), made by

    .venv/bin/python bench/laydown/run_thesis.py --cases C-circular --variants loose --ranks 2 \\
        --max-time 4e-3 --runs runs/lim-probe
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import yaml

from fiberform.fiber_io import NODES_NAME
from fiberform.inputs import LiggghtsInput, fix_ref
from fiberform.liggghts_log import thermo_rows
from fiberform.provenance import append_result_rows, atomic_write_text, file_hash, machine_info
from fiberform.scene import parse_scene
from fiberform.stages import laydown
from fiberform.sweep import set_field

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
COPIED = ("flow.grid", "yarns.txt")
LOOP = re.compile(r"^Loop time of ([0-9.eE+-]+) on", re.M)
#: thermo columns of the probe (after step and atoms)
COLUMNS = ("iterations", "max_iterations", "tangents", "mean_iterations", "mean_tangents", "mean_limited")


def parse_setting(text: str) -> tuple[float, float | None]:
    """``FRICTION:STICK`` (STICK may be omitted: the scene's) -> (friction, stick)."""
    parts = text.split(":")
    try:
        mu = float(parts[0])
        stick = float(parts[1]) if len(parts) > 1 and parts[1] else None
    except (ValueError, IndexError):
        raise SystemExit(f"--settings: expected FRICTION:STICK (e.g. 0.5:10), got {text!r}") from None
    return mu, stick


def probe_input(run: Path, step: int, steps: int, chunk: int, mu: float, stick: float | None,
                fields: dict[str, Any] | None = None) -> str:
    """The lay-down's resumed input with the setting, ``steps`` steps in runs of ``chunk``
    (``fields``: further scene fields, e.g. laydown.anderson_depth, by dotted path)."""
    data = yaml.safe_load((run / "scene.yaml").read_text())
    set_field(data, "laydown.ranks", 1)
    for path, value in (fields or {}).items():
        set_field(data, path, value)
    set_field(data, "laydown.friction_coefficient", mu)
    if stick is not None and mu > 0.0:
        set_field(data, "laydown.friction_stick", stick)
    elif "friction_stick" in data.get("laydown", {}):
        del data["laydown"]["friction_stick"]
    scene = parse_scene(data, str(run / "scene.yaml"))
    if step % chunk or steps % chunk:
        raise SystemExit(f"--step {step} and --steps {steps} must be multiples of --chunk {chunk}")
    text = laydown.build_input(scene, chunk, (step + steps) // chunk, resume_step=step)
    counters = LiggghtsInput()
    counters.command("thermo_style", "custom", "step", "atoms",
                     *(fix_ref("beam", k) for k in (14, 15, 18, 19, 20, 21)))
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("thermo_style"))
    lines[at] = counters.render().strip().splitlines()[-1]
    return "\n".join(lines) + "\n"


def probe_fields(anderson: int = 0, tolerance: float | None = None,
                 timestep: float | None = None, landing: str | None = None) -> dict[str, Any]:
    """The scene fields of the options --anderson, --tolerance, --timestep, --landing (only those
    given)."""
    out: dict[str, Any] = {}
    if landing is not None:
        out["laydown.newton_landing"] = landing
    if anderson:
        out["laydown.anderson_depth"] = anderson
    if tolerance is not None:
        out["laydown.newton_tolerance"] = tolerance
    if timestep is not None:
        out["laydown.timestep_s"] = timestep
    return out


def run_probe(run: Path, step: int, steps: int, chunk: int, setting: str, build: Path, out_root: Path,
              anderson: int = 0, tolerance: float | None = None,
              timestep: float | None = None, landing: str | None = None) -> dict[str, Any]:
    mu, stick = parse_setting(setting)
    work = run / "laydown" / "work"
    restart = work / f"laydown.{step}.restart"
    if not restart.is_file():
        raise SystemExit(f"--step: no restart file {restart}")
    folder = out_root / (f"{run.name}-{step}-mu{mu:g}-k{stick if stick is not None else 'scene'}"
                         + (f"-aa{anderson}" if anderson else "")
                         + (f"-tol{tolerance:g}" if tolerance is not None else "")
                         + (f"-dt{timestep:g}" if timestep is not None else "")
                         + (f"-land-{landing}" if landing is not None else ""))
    folder.mkdir(parents=True, exist_ok=True)
    # the generated fibers less those removed up to the restart, as the stage's own resume writes them
    laydown.write_nodes_left(work / NODES_NAME, folder / NODES_NAME,
                             (work / "log.fiberdem").read_text(errors="replace"), step)
    for name in (*COPIED, restart.name):
        target = folder / name
        if target.is_symlink() or target.exists():
            target.unlink()
        if name == restart.name:  # copied: the probe must never write into the run's own files
            shutil.copyfile(restart, target)
        else:
            target.symlink_to((work / name).resolve())
    atomic_write_text(folder / "in.probe", probe_input(run, step, steps, chunk, mu, stick,
                                                               probe_fields(anderson, tolerance, timestep, landing)))
    fiberdem = build / "bin" / "fiberdem"
    t0 = time.perf_counter()
    proc = subprocess.run([str(fiberdem), "-in", "in.probe", "-log", "log.probe"], cwd=folder,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=False)
    wall = time.perf_counter() - t0
    log = (folder / "log.probe").read_text() if (folder / "log.probe").is_file() else ""
    rows = [r for r in thermo_rows(log) if r[0] > step]
    row: dict[str, Any] = {"run": str(run), "step": step, "steps": steps, "friction": mu,
                           "friction_stick": stick if mu > 0.0 else None, "anderson": anderson,
                           "newton_tolerance": tolerance, "timestep_s": timestep, "landing": landing,
                           "exit": proc.returncode,
                           "wall_s": wall, "folder": str(folder), "fiberdem": file_hash(fiberdem)}
    if proc.returncode != 0 or not rows:
        row["error"] = proc.stderr[-2000:]
        return row
    last = dict(zip(COLUMNS, rows[-1][2:]))
    row.update({
        "loop_s": sum(float(x) for x in LOOP.findall(log)),
        "simulated_steps": int(rows[-1][0]) - step,
        "nodes": int(rows[-1][1]),
        "newton_iterations_per_fiber_step": last["mean_iterations"],
        "tangents_per_fiber_step": last["mean_tangents"],
        "limited_iterations_per_fiber_step": last["mean_limited"],
        "largest_iterations_one_fiber": max(r[3] for r in rows),
    })
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, default=Path("runs") / "lim-probe" / "C-circular-loose-r2-s1",
                    help="lay-down run folder (scene.yaml, laydown/work/laydown.<step>.restart)")
    ap.add_argument("--step", type=int, default=4000, help="restart step to continue from")
    ap.add_argument("--steps", type=int, default=300, help="steps of each probe")
    ap.add_argument("--chunk", type=int, default=50, help="steps per run command (thermo interval)")
    ap.add_argument("--settings", nargs="+", default=["0.5:100", "0.5:10", "0.5:1", "0:100"],
                    help="FRICTION:STICK pairs (laydown.friction_coefficient, laydown.friction_stick)")
    ap.add_argument("--anderson", type=int, default=0, choices=range(9), metavar="M",
                    help="laydown.anderson_depth of every probe (0: the run's scene)")
    ap.add_argument("--tolerance", type=float, default=None, metavar="T",
                    help="laydown.newton_tolerance of every probe (default: the run's scene)")
    ap.add_argument("--timestep", type=float, default=None, metavar="DT",
                    help="laydown.timestep_s of every probe (default: the run's scene)")
    ap.add_argument("--landing", choices=("limit", "predict"), default=None,
                    help="laydown.newton_landing in every probe (default: the run's scene)")
    ap.add_argument("--parallel", type=int, default=1, choices=(1, 2), help="probes at once")
    ap.add_argument("--probes", type=Path, default=Path("runs") / "probes")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "friction_probe.json")
    args = ap.parse_args()
    if not (args.run / "scene.yaml").is_file():
        print(f"--run: {args.run}/scene.yaml not found", file=sys.stderr)
        return 2
    for s in args.settings:
        parse_setting(s)
    build = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()
    load = os.getloadavg()[0]
    with ThreadPoolExecutor(max_workers=args.parallel) as pool:
        rows = list(pool.map(lambda s: run_probe(args.run, args.step, args.steps, args.chunk, s, build,
                                                 args.probes, args.anderson, args.tolerance, args.timestep,
                                                 args.landing),
                                 args.settings))
    for r in rows:
        r["parallel"] = args.parallel
        r["load_average_before"] = load
        r["machine"] = machine_info()
        print(json.dumps({k: v for k, v in r.items() if k != "machine"}), flush=True)
    append_result_rows(args.out, rows)
    print(f"wrote {args.out}")
    return 0 if all(r.get("exit") == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
