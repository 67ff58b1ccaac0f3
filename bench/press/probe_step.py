#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The cost of a press step under load, probed from a press's restart file (docs/stages/press.md,
"Cost under load").

A press of a real sheet spends its time in the fibers' implicit steps once the plate carries the
sheet: a step that does not converge within ``laydown.newton_max_iterations`` is split into halves
(physics/implicit_rod.h). This probe continues a press from one of its restart files for a short
simulated time with each of several variants of the step's settings and reports, per variant, the
wall time and the Newton iterations, splits, tangent formations and split-memory start depth per
step (fix fiber/beam's f_beam[14], [16], [18], [22]), and the plate force at the end.

The input is the press stage's own (fiberform.stages.press.build_input with the scene's press
plan, resumed at the restart step), cut to its first run and changed only as the variant says:

* ``timestep=<s>``: the step (the plate's speed is in m/s, so the plate moves as in the press);
* ``newton_max=<n>``: laydown.newton_max_iterations;
* ``split_memory=<n>``: laydown.split_memory_steps.

Example (the case-C press with the cap of docs/validation/table41.md, 20 us from step 25000)::

    .venv/bin/python bench/press/probe_step.py runs/press-cap/C-no_fines.yaml --step 25000 \\
        --time 2e-5 --variant timestep=1e-6 --variant timestep=1e-6,split_memory=20 \\
        --variant timestep=2.5e-7

Writes a JSON (``--out``, default bench/press/results/probe_step.json) with the scene, the
restart step, the machine and load, and per variant the rows and the totals. The press's own
folder is only read: each variant runs in a temporary folder with links to the restart file, the
nodes and the yarns. Measure on an idle machine; the load average is recorded with each variant.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

from fiberform.errors import ConfigError  # noqa: E402
from fiberform.liggghts_log import thermo_rows  # noqa: E402
from fiberform.provenance import atomic_write_text, machine_info  # noqa: E402
from fiberform.scene import Scene, load_scene  # noqa: E402
from fiberform.stages import press  # noqa: E402

BUILD = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()
#: the variant keys and the scene fields (or input line) they change, with their allowed ranges
KEYS = {"timestep": (1e-9, 1e-4), "newton_max": (1, 1000), "split_memory": (0, 1_000_000)}
#: fix fiber/beam outputs added to the thermo: mean Newton iterations per fiber, sub-step splits,
#: mean tangent formations per fiber (last step), deepest split-memory start depth
BEAM = ("f_beam[14]", "f_beam[16]", "f_beam[18]", "f_beam[22]")


def parse_variant(text: str) -> dict[str, float]:
    """``key=value,...`` of KEYS; exit status 2 with the field and its range on a bad one."""
    out: dict[str, float] = {}
    for part in filter(None, text.split(",")):
        key, _, value = part.partition("=")
        if key not in KEYS:
            raise ConfigError(f"--variant {text!r}: unknown key {key!r} (allowed: {', '.join(KEYS)})")
        lo, hi = KEYS[key]
        try:
            v = float(value)
        except ValueError:
            raise ConfigError(f"--variant {text!r}: {key} must be a number in [{lo:g}, {hi:g}]") from None
        if not lo <= v <= hi or (key != "timestep" and v != int(v)):
            raise ConfigError(f"--variant {text!r}: {key} must be {'a number' if key == 'timestep' else 'an integer'} "
                              f"in [{lo:g}, {hi:g}], not {value}")
        out[key] = v
    return out


def probe_input(scene: Scene, step: int, variant: dict[str, float], sim_time: float) -> tuple[str, int, float]:
    """The stage's press input of ``scene`` resumed at ``step``, with the variant's beam settings,
    cut to one run of ``sim_time`` at the variant's step; returns (text, steps, dt)."""
    ld = scene.laydown
    assert ld is not None and scene.press is not None
    update: dict[str, Any] = {}
    if "newton_max" in variant:
        update["newton_max_iterations"] = int(variant["newton_max"])
    if "split_memory" in variant:
        update["split_memory_steps"] = int(variant["split_memory"])
    scene = scene.model_copy(update={"laydown": ld.model_copy(update=update)})
    plan = press.plan(scene, scene.output_path)
    dt = variant.get("timestep", plan.dt)
    steps = max(1, round(sim_time / dt))
    text = press.build_input(scene, plan, resume_step=step)
    out: list[str] = []
    for line in text.splitlines():
        word = line.split(" ", 1)[0]
        if word in ("dump", "dump_modify", "restart"):
            continue  # no trajectory, no restart files
        if word == "timestep":
            line = f"timestep {dt!r}"
        if word == "thermo_style":
            line += " " + " ".join(BEAM)
        if word == "thermo":
            line = "thermo 1"
        if word == "run":
            out.append(f"run {steps}")
            break
        out.append(line)
    else:
        raise RuntimeError("the press input has no run command")
    return "\n".join(out) + "\n", steps, dt


def run_variant(scene: Scene, step: int, spec: str, sim_time: float) -> dict[str, Any]:
    variant = parse_variant(spec)
    text, steps, dt = probe_input(scene, step, variant, sim_time)
    work = (scene.output_path / "press" / "work").resolve()
    restart = work / f"press.{step}.restart"
    if not restart.is_file():
        raise ConfigError(f"--step {step}: {restart} not found (the press writes press.<step>.restart)")
    with tempfile.TemporaryDirectory(prefix="fiberform-probe-") as tmp:
        t = Path(tmp)
        for name in (restart.name, press.NODES_NAME, press.YARNS_NAME):
            os.symlink(work / name, t / name)
        (t / "in.probe").write_text(text)
        load = os.getloadavg()[0]
        t0 = time.monotonic()
        proc = subprocess.run([str(BUILD / "bin" / "fiberdem"), "-in", "in.probe", "-log", "log.probe",
                               "-screen", "none"], cwd=t, capture_output=True, text=True, errors="replace")
        wall = time.monotonic() - t0
        log = (t / "log.probe").read_text(errors="replace") if (t / "log.probe").exists() else ""
    if proc.returncode != 0:
        raise RuntimeError(f"variant {spec}: fiberdem failed ({proc.returncode}):\n{log[-3000:]}"
                           f"{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    ncol = len(press.COLUMNS) + len(BEAM)
    rows = [r for r in thermo_rows(log) if len(r) == ncol and r[0] > step]
    its = [r[-4] for r in rows]
    splits = [r[-3] for r in rows]
    tangents = [r[-2] for r in rows]
    depth = [r[-1] for r in rows]
    fz = press.COLUMNS.index("fz")
    return {
        "variant": spec, "timestep_s": dt, "steps": steps, "simulated_s": steps * dt, "wall_s": wall,
        "load_average_1min_at_start": load,
        "newton_iterations_per_fiber_per_step": {"min": min(its), "max": max(its), "mean": sum(its) / len(its)},
        "splits_per_step": {"min": min(splits), "max": max(splits), "total": sum(splits)},
        "tangents_per_fiber_per_step": {"min": min(tangents), "max": max(tangents)},
        "start_depth": {"min": min(depth), "max": max(depth)},
        "plate_force_z_N_last": rows[-1][fz],
        "rows": {"step": [r[0] for r in rows], "iterations": its, "splits": splits, "tangents": tangents,
                 "start_depth": depth},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", type=Path, help="the scene of a press with restart files")
    ap.add_argument("--step", type=int, required=True, help="the restart file's step (press.<step>.restart)")
    ap.add_argument("--time", type=float, default=2e-5, help="simulated time per variant, s (default 2e-5)")
    ap.add_argument("--variant", action="append", required=True,
                    help="key=value[,key=value] of timestep (s), newton_max, split_memory; repeat")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "probe_step.json")
    a = ap.parse_args(argv)
    try:
        if not 1e-9 <= a.time <= 1e-2 or not math.isfinite(a.time):
            raise ConfigError(f"--time {a.time}: must be in [1e-9, 1e-2] s")
        for spec in a.variant:
            parse_variant(spec)
        scene = load_scene(a.scene)
        results = []
        for spec in a.variant:
            r = run_variant(scene, a.step, spec, a.time)
            print(f"{spec}: {r['steps']} steps in {r['wall_s']:.1f} s; Newton iterations per step "
                  f"{r['newton_iterations_per_fiber_per_step']['min']:.0f}-"
                  f"{r['newton_iterations_per_fiber_per_step']['max']:.0f}, splits per step "
                  f"{r['splits_per_step']['min']:.0f}-{r['splits_per_step']['max']:.0f}, start depth "
                  f"{r['start_depth']['min']:.0f}-{r['start_depth']['max']:.0f}; plate force "
                  f"{r['plate_force_z_N_last']:.4g} N (load {r['load_average_1min_at_start']:.2f})", flush=True)
            results.append(r)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    doc = {"command": " ".join(["bench/press/probe_step.py", *(argv if argv is not None else sys.argv[1:])]),
           "scene": str(a.scene), "restart_step": a.step, "simulated_time_s": a.time,
           "build": str(BUILD), "machine": machine_info(), "variants": results}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(a.out, json.dumps(doc, indent=1) + "\n")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
