#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Friction probe of the lay-down solver (issue 10): the cost of a short stretch of a lay-down,
continued from one of its restart files with other yarn-friction settings.

A thesis-scale lay-down spends its time in the Newton iterations of the fibers' contact clusters
once they pile up (docs/bench/laydown.md). This script takes a lay-down run folder (its
``scene.yaml`` and ``laydown/work`` with the restart files), and for every setting
``FRICTION:STICK`` (laydown.friction_coefficient and laydown.friction_stick) writes the stage's
own resumed input (fiberform.stages.laydown.build_input with ``resume_step``) into a folder of its
own, adds the solver's counters to the thermo output, runs ``--steps`` steps on one rank (or
``--ranks``) and reports:

* loop time (s, the sum of LIGGGHTS' ``Loop time`` lines: start-up excluded);
* mean Newton iterations and tangent formations per fiber and step over the probe
  (``f_beam[19]``, ``f_beam[20]``: counted since the fix was defined, i.e. over the probe);
* the largest Newton iterations of one fiber in a step (``f_beam[15]`` at the thermo steps);
* mean iterations per fiber and step whose correction the contact limiter shortened (landings;
  ``f_beam[21]``, over the probe).

``--steric-cap H`` sets laydown.steric_cap_m (the steric servo's saturation, m) in every probe;
``--anderson M`` sets laydown.anderson_depth (Anderson mixing of the Newton corrections),
``--tolerance T`` laydown.newton_tolerance and ``--timestep DT`` laydown.timestep_s in every probe
(``--steps`` and ``--step`` count steps of the restart's run up to the restart, then of the new
length; scale the stick factor with the step to keep the friction's damping c_stick = k m / dt,
docs/bench/laydown.md "Yarn friction").

The probes run one after another unless ``--parallel 2`` (one build, one rank and one repetition
only; then the loop times are loaded: compare the iteration counts, which do not depend on the
load). Rows are appended to ``bench/laydown/results/friction_probe.json``; the folders go to
``runs/probes/``.

    .venv/bin/python bench/laydown/probe_friction.py --run runs/lim-probe/C-circular-loose-r2-s1 \\
        --step 4000 --settings 0.5:100 0.5:10 0.5:1 0:100

The default run folder is the first 4 ms of thesis case C (circular, seed 1, tolerance 1e-6, the
fibers starting to pile up), made by

    .venv/bin/python bench/laydown/run_thesis.py --cases C-circular --variants loose --ranks 2 \\
        --max-time 4e-3 --runs runs/lim-probe

Every probe ends with a dump of the final state (``final.dump``: every node's id, x, y, z, vx, vy,
vz with ``%.17g``, sorted by id) and reports its sha256 (``final_state``), the CPU time of the
whole run (``cpu_s``: user + sys of fiberdem, or of mpirun and all its ranks, from os.wait4) and the
build (``launch``: the mpirun options, empty on one rank; ``mpi_env``: Open MPI's ``OMPI_MCA_*``
settings the ranks got, e.g. yield-when-idle; ``build``, ``fiberdem``: the sha256 of its
bin/fiberdem, ``build_revision``: the commit its
binaries come from, the build folder's ``REVISION`` file that every build writes,
cmake/WriteRevision.cmake; ``unknown`` for a build folder made before that file existed).

Builds and ranks: ``--builds DIR [DIR ...]`` (default ``$FIBERFORM_BUILD`` or ``build``) and
``--ranks R [R ...]`` (default 1; ``mpirun -np R`` when R > 1) run every (build, ranks)
combination for each setting, ``--repeat K`` times, alternating the combinations within each
repetition (ranks outer, builds inner: A1 B1 A2 B2 ...), one probe at a time. Each combination
has its folder (suffix ``-b<index>-np<R>`` when there is more than one build or R > 1; the
repetitions reuse it). At the end a table gives, per setting and combination, the loop time and
the CPU time (median and range over the repetitions) and whether the final states of all
combinations and repetitions are byte-identical. ``--concurrency [LOOPS]`` runs
bench/machine/run_concurrency.py (``--loops LOOPS``, default 2e7: about 30 s) before and after the
probes and records the machine's throughput (cores) in every row (docs/bench/machine.md: the second
vCPU of this kind of machine gives 1.0-2.0 cores). Two builds, 1 and 2 ranks, three rounds
(docs/bench/laydown.md "The waiting rank sleeps"):

    .venv/bin/python bench/laydown/probe_friction.py --run RUN --step 36000 --steps 300 \\
        --settings 0.5: --builds /work/build-old /work/build-new --ranks 1 2 --repeat 3 --concurrency

Side by side: ``--copies N [N ...]`` (default 1) runs every combination also as N copies at the
same time (folders suffixed ``-c<i>``; rows record ``copies`` and ``copy``), alternating with the
other counts within each repetition (copies outermost: all combinations alone, then all as two
copies, ...). The table then gives each count's loop time and, for N > 1, the throughput of the N
copies together relative to one copy alone (N x median loop alone / median loop of a copy): how
much a second lay-down beside the first gains on this machine (docs/bench/laydown.md "Two points
side by side"):

    .venv/bin/python bench/laydown/probe_friction.py --run RUN --step 36000 --steps 300 \\
        --settings 0.5: --ranks 2 --copies 1 2 --repeat 3 --concurrency
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import yaml

from fiberform._versions import build_revision
from fiberform.fiber_io import NODES_NAME
from fiberform.inputs import LiggghtsInput, dump_format, file_token, fix_ref
from fiberform.liggghts_log import thermo_rows
from fiberform.liggghts_restart import EARLIER_LOG, read_text_if
from fiberform.provenance import append_result_rows, atomic_write_text, file_hash, machine_info
from fiberform.runner import build_command, build_env
from fiberform.scene import parse_scene
from fiberform.stages import laydown
from fiberform.sweep import set_field

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
COPIED = ("flow.grid", "yarns.txt")
LOOP = re.compile(r"^Loop time of ([0-9.eE+-]+) on", re.M)
#: thermo columns of the probe (after step and atoms)
COLUMNS = ("iterations", "max_iterations", "tangents", "mean_iterations", "mean_tangents", "mean_limited")
#: the final state written at the end of every probe (its sha256 is the row's final_state)
FINAL_DUMP = "final.dump"
FINAL_COLUMNS = ("id", "x", "y", "z", "vx", "vy", "vz")
CONCURRENCY = ROOT / "bench" / "machine" / "run_concurrency.py"
MAX_REPEAT = 100


def parse_setting(text: str) -> tuple[float, float | None]:
    """``FRICTION:STICK`` (STICK may be omitted: the law's default k = 100, the scene's
    laydown.friction_stick dropped) -> (friction, stick)."""
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
    return "\n".join(lines) + "\n" + final_state_dump()


def final_state_dump() -> str:
    """The input line that writes every node's id, position and velocity (``%.17g``, sorted by id)
    to FINAL_DUMP: equal files mean equal final states, bit for bit."""
    s = LiggghtsInput()
    s.command("write_dump", "all", "custom", file_token(FINAL_DUMP), *FINAL_COLUMNS,
              "modify", "sort", "id", "format", dump_format(["int"] + ["float"] * (len(FINAL_COLUMNS) - 1)))
    return s.render()


def run_counted(argv: list[str], cwd: Path, stderr: Path) -> tuple[int, float, float]:
    """Run ``argv`` in ``cwd`` (standard output discarded, standard error to the file ``stderr``):
    (exit status, user CPU s, system CPU s of the process and all the descendants it waited for,
    i.e. of mpirun and every rank)."""
    with open(stderr, "wb") as err:
        proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.DEVNULL, stderr=err, env=build_env())
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        except BaseException:  # e.g. Ctrl-C: mpirun passes SIGTERM on to its ranks
            proc.terminate()
            proc.wait()
            raise
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
    return proc.returncode, usage.ru_utime, usage.ru_stime


def probe_fields(anderson: int = 0, tolerance: float | None = None,
                 timestep: float | None = None, landing: str | None = None,
                 fiber_friction: float | None = None, steric_cap: float | None = None) -> dict[str, Any]:
    """The scene fields of the options --anderson, --tolerance, --timestep, --landing,
    --fiber-friction, --steric-cap (only those given)."""
    out: dict[str, Any] = {}
    if steric_cap is not None:
        out["laydown.steric_cap_m"] = steric_cap
    if fiber_friction is not None:
        out["laydown.fiber_friction_coefficient"] = fiber_friction
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
              timestep: float | None = None, landing: str | None = None, *,
              ranks: int = 1, tag: str = "", fiber_friction: float | None = None,
              steric_cap: float | None = None) -> dict[str, Any]:
    """One probe of ``setting`` with ``build``'s fiberdem on ``ranks`` ranks, in the folder of the
    setting (+ ``tag``, e.g. ``-b1-np2``) under ``out_root``: its row."""
    mu, stick = parse_setting(setting)
    work = run / "laydown" / "work"
    restart = work / f"laydown.{step}.restart"
    if not restart.is_file():
        raise SystemExit(f"--step: no restart file {restart}")
    folder = out_root / (f"{run.name}-{step}-mu{mu:g}-k{stick if stick is not None else 'scene'}"
                         + (f"-aa{anderson}" if anderson else "")
                         + (f"-tol{tolerance:g}" if tolerance is not None else "")
                         + (f"-dt{timestep:g}" if timestep is not None else "")
                         + (f"-land-{landing}" if landing is not None else "")
                         + (f"-ff{fiber_friction:g}" if fiber_friction is not None else "")
                         + (f"-cap{steric_cap:g}" if steric_cap is not None else "") + tag)
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("log.probe", FINAL_DUMP, "traj.dump"):  # nothing of an earlier probe is read
        (folder / name).unlink(missing_ok=True)
    # the generated fibers less those removed up to the restart, as the stage's own resume writes
    # them: from the generate stage's nodes file and the whole log (a resumed lay-down's working
    # nodes file lacks the fibers removed before its own restart step, and its log.fiberdem
    # starts there: the earlier removals are in EARLIER_LOG)
    generated = run / "fibers" / NODES_NAME
    laydown.write_nodes_left(generated if generated.is_file() else work / NODES_NAME, folder / NODES_NAME,
                             read_text_if(work / EARLIER_LOG) + (work / "log.fiberdem").read_text(errors="replace"),
                             step)
    for name in (*COPIED, restart.name):
        target = folder / name
        if target.is_symlink() or target.exists():
            target.unlink()
        if name == restart.name:  # copied: the probe must never write into the run's own files
            shutil.copyfile(restart, target)
        else:
            target.symlink_to((work / name).resolve())
    atomic_write_text(folder / "in.probe", probe_input(run, step, steps, chunk, mu, stick,
                                                               probe_fields(anderson, tolerance, timestep, landing,
                                                                            fiber_friction, steric_cap)))
    fiberdem = build / "bin" / "fiberdem"
    program = [str(fiberdem), "-in", "in.probe", "-log", "log.probe"]
    argv = build_command(program, ranks)
    t0 = time.perf_counter()
    code, user, system = run_counted(argv, folder, folder / "stderr.probe")
    wall = time.perf_counter() - t0
    log = (folder / "log.probe").read_text() if (folder / "log.probe").is_file() else ""
    rows = [r for r in thermo_rows(log) if r[0] > step]
    row: dict[str, Any] = {"run": str(run), "step": step, "steps": steps, "friction": mu,
                           "friction_stick": stick if mu > 0.0 else None, "anderson": anderson,
                           "newton_tolerance": tolerance, "timestep_s": timestep, "landing": landing,
                           "fiber_friction": fiber_friction, "steric_cap_m": steric_cap,
                           "exit": code,
                           "wall_s": wall, "folder": str(folder), "build": str(build),
                           "fiberdem": file_hash(fiberdem)}
    row["build_revision"] = build_revision(build)
    # how the ranks were started (the mpirun options, e.g. --bind-to none; "" without mpirun)
    prefix = argv[:len(argv) - len(program)]
    row["launch"] = " ".join([Path(prefix[0]).name, *prefix[1:]]) if prefix else ""
    # and Open MPI's settings from the environment (e.g. yield-when-idle, fiberform.runner.MPI_ENVIRONMENT)
    row["mpi_env"] = {k: v for k, v in sorted(build_env().items()) if k.startswith("OMPI_MCA_")} if prefix else {}
    row.update({"ranks": ranks, "cpu_s": user + system, "cpu_user_s": user, "cpu_sys_s": system})
    final = folder / FINAL_DUMP
    if final.is_file():
        row["final_state"] = file_hash(final)
    if code != 0 or not rows:
        row["error"] = (folder / "stderr.probe").read_text(errors="replace")[-2000:]
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


def combinations(builds: list[Path], ranks: list[int], repeat: int) -> list[tuple[int, int, int]]:
    """(repetition, build index, ranks) in the order they run: per repetition every combination,
    ranks outer and builds inner (A1 B1 A2 B2 ...)."""
    return [(k, b, r) for k in range(repeat) for r in ranks for b in range(len(builds))]


def schedule(builds: list[Path], ranks: list[int], repeat: int, copies: list[int]) -> list[tuple[int, int, int, int]]:
    """(repetition, build index, ranks, copies at once) in the order they run: per repetition each
    count of copies (outermost), within it the combinations as :func:`combinations` orders them."""
    return [(k, b, r, n) for k in range(repeat) for n in copies
            for _, b, r in combinations(builds, ranks, 1)]


def concurrency(loops: float) -> float | None:
    """The machine's throughput in cores now: bench/machine/run_concurrency.py's
    throughput_cores (its JSON written to a temporary file); None (and a warning) if it failed."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "concurrency.json"
        proc = subprocess.run([sys.executable, str(CONCURRENCY), "--loops", repr(float(loops)),
                               "--out", str(out)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=False)
        if proc.returncode != 0 or not out.is_file():
            print(f"probe_friction.py: --concurrency: {CONCURRENCY.name} failed ({proc.returncode}), "
                  f"throughput not recorded: {proc.stderr[-1000:]}", file=sys.stderr)
            return None
        return float(json.loads(out.read_text())["throughput_cores"])


def spread(values: list[float]) -> str:
    """``median [min-max]`` of the values (s), or the value alone."""
    if len(values) == 1:
        return f"{values[0]:.2f}"
    return f"{statistics.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Per setting (friction, stick) and combination (build, ranks): loop time and CPU time,
    median and range over the repetitions; per setting whether every combination and repetition
    ended in the same final state (equal final_state hashes)."""
    out: list[str] = []
    settings: dict[tuple[Any, Any], list[dict[str, Any]]] = {}
    for r in rows:
        settings.setdefault((r["friction"], r["friction_stick"]), []).append(r)
    for (mu, stick), group in settings.items():
        out.append(f"setting friction {mu:g}" + (f", stick {stick:g}" if stick is not None else ""))
        combos: dict[tuple[int, str, int, int], list[dict[str, Any]]] = {}
        for r in group:
            combos.setdefault((r.get("build_index", 0), r["build"], r["ranks"], r.get("copies", 1)), []).append(r)
        for (b, build, ranks, n), runs in combos.items():
            done = [r for r in runs if "loop_s" in r]
            failed = len(runs) - len(done)
            if done:
                times = (f"loop {spread([r['loop_s'] for r in done])} s, "
                         f"CPU {spread([r['cpu_s'] for r in done])} s")
            else:
                times = "no loop time"
            at_once = f", {n} copies at once" if n > 1 else ""
            out.append(f"  build {b} ({build}, {runs[0]['fiberdem'][:19]}) on {ranks} rank(s){at_once}: "
                       f"{times} over {len(done)} run(s)" + (f", {failed} failed" if failed else ""))
            alone = [r["loop_s"] for r in combos.get((b, build, ranks, 1), []) if "loop_s" in r]
            if n > 1 and done and alone:
                gain = n * statistics.median(alone) / statistics.median([r["loop_s"] for r in done])
                out.append(f"    {n} copies together: {gain:.2f} x the throughput of one alone")
        states = {r.get("final_state") for r in group}
        same = len(states) == 1 and None not in states
        out.append(f"  final states: {'identical' if same else 'DIFFERENT'} "
                   f"({len(states)} distinct of {len(group)} probe(s))")
    return out


def bad(option: str, message: str) -> int:
    print(f"probe_friction.py: {option}: {message}", file=sys.stderr)
    return 2


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
    ap.add_argument("--fiber-friction", type=float, default=None, metavar="MU",
                    help="laydown.fiber_friction_coefficient of every probe (default: the run's scene)")
    ap.add_argument("--steric-cap", type=float, default=None, metavar="H",
                    help="laydown.steric_cap_m of every probe, m (default: the run's scene)")
    ap.add_argument("--parallel", type=int, default=1, choices=(1, 2), help="probes at once")
    ap.add_argument("--copies", type=int, nargs="+", default=[1], metavar="N",
                    help="run every combination also as N copies at the same time (default 1)")
    ap.add_argument("--builds", type=Path, nargs="+", metavar="DIR",
                    default=[Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build"))],
                    help="build folders (their bin/fiberdem) to compare (default: $FIBERFORM_BUILD or build)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1], metavar="R",
                    help="MPI ranks to run every build on (default 1; mpirun -np R when R > 1)")
    ap.add_argument("--repeat", type=int, default=1, metavar="K",
                    help="repetitions of every (build, ranks) combination, alternating within each")
    ap.add_argument("--concurrency", type=float, nargs="?", const=2.0e7, default=None, metavar="LOOPS",
                    help="measure the machine's throughput (bench/machine/run_concurrency.py --loops "
                         "LOOPS, default 2e7) before and after the probes")
    ap.add_argument("--probes", type=Path, default=Path("runs") / "probes")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "friction_probe.json")
    args = ap.parse_args()
    if not (args.run / "scene.yaml").is_file():
        print(f"--run: {args.run}/scene.yaml not found", file=sys.stderr)
        return 2
    for s in args.settings:
        parse_setting(s)
    if args.steric_cap is not None and not 1e-9 <= args.steric_cap <= 1e-4:
        return bad("--steric-cap", f"H must be 1e-9..1e-4 m (laydown.steric_cap_m), got {args.steric_cap:g}")
    cores = os.cpu_count() or 1
    if not all(1 <= r <= cores for r in args.ranks):
        return bad("--ranks", f"each R must be 1..{cores} (the cores), got {' '.join(map(str, args.ranks))}")
    if len(set(args.ranks)) != len(args.ranks):
        return bad("--ranks", f"each R once, got {' '.join(map(str, args.ranks))}")
    if max(args.ranks) > 1 and shutil.which("mpirun") is None:
        return bad("--ranks", "R > 1 needs mpirun on PATH")
    if not 1 <= args.repeat <= MAX_REPEAT:
        return bad("--repeat", f"K must be 1..{MAX_REPEAT}, got {args.repeat}")
    builds = [b.resolve() for b in args.builds]
    for given, b in zip(args.builds, builds):
        if not (b / "bin" / "fiberdem").is_file():
            return bad("--builds", f"{given}/bin/fiberdem not found (each DIR a build folder)")
    if args.concurrency is not None and not 1e5 <= args.concurrency <= 1e10:
        return bad("--concurrency", f"LOOPS must be 1e5..1e10, got {args.concurrency:g}")
    if not all(1 <= n <= cores for n in args.copies) or len(set(args.copies)) != len(args.copies):
        return bad("--copies", f"each N once, 1..{cores} (the cores), got {' '.join(map(str, args.copies))}")
    order = schedule(builds, args.ranks, args.repeat, args.copies)
    if args.parallel > 1 and (len(order) > 1 or args.copies != [1]):
        return bad("--parallel", "2 only with one build, one R, --repeat 1 and no --copies "
                   "(timing probes run one at a time)")
    several = len(builds) > 1 or args.ranks != [1]
    side_by_side = max(args.copies) > 1
    jobs = [(s, k, b, r, n) for s in args.settings for k, b, r, n in order]
    load = os.getloadavg()[0]
    before = concurrency(args.concurrency) if args.concurrency is not None else None

    def probe(job: tuple[str, int, int, int, int], copy: int = 0) -> dict[str, Any]:
        setting, k, b, r, n = job
        tag = (f"-b{b}-np{r}" if several else "") + (f"-c{copy}" if side_by_side else "")
        row = run_probe(args.run, args.step, args.steps, args.chunk, setting, builds[b], args.probes,
                        args.anderson, args.tolerance, args.timestep, args.landing, ranks=r, tag=tag,
                        fiber_friction=args.fiber_friction, steric_cap=args.steric_cap)
        row.update({"build_index": b, "repetition": k})
        if side_by_side:
            row.update({"copies": n, "copy": copy})
        return row

    def copies_at_once(job: tuple[str, int, int, int, int]) -> list[dict[str, Any]]:
        """The job's ``copies`` probes started together (one thread each)."""
        n = job[4]
        if n == 1:
            return [probe(job)]
        with ThreadPoolExecutor(max_workers=n) as side:
            return list(side.map(lambda i: probe(job, i), range(n)))

    rows: list[dict[str, Any]] = []
    with ThreadPoolExecutor(max_workers=args.parallel) as pool:
        for r in (row for batch in pool.map(copies_at_once, jobs) for row in batch):
            r["parallel"] = args.parallel
            r["load_average_before"] = load
            r["machine"] = machine_info()
            print(json.dumps({k: v for k, v in r.items() if k != "machine"}), flush=True)
            rows.append(r)
    if args.concurrency is not None:
        after = concurrency(args.concurrency)
        for r in rows:
            r["throughput_cores_before"] = before
            r["throughput_cores_after"] = after
        print("machine throughput (cores): "
              + ", ".join(f"{when} {'failed' if x is None else f'{x:.2f}'}"
                          for when, x in (("before the probes", before), ("after", after))))
    append_result_rows(args.out, rows)
    print("\n".join(summary(rows)))
    print(f"wrote {args.out}")
    return 0 if all(r.get("exit") == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
