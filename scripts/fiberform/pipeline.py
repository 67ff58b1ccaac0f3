# SPDX-License-Identifier: GPL-3.0-or-later
"""The stage graph of a scene: order, selection and status (issue 14).

Each stage declares the upstream products it reads (:meth:`Stage.needs`) and the products it makes
(:meth:`Stage.product_paths`); stage B runs after stage A when B needs one of A's products. The
order is a topological sort of that graph (ties broken by the registration order of
:data:`fiberform.stages.STAGES`), so adding a stage never needs an edit here.

Status of a stage (``fiberform status SCENE``):

* ``done``: every product exists and its HDF5 file records the input hashes the stage would
  compute now;
* ``stale``: products exist but an input changed (scene section, upstream file, binary, code
  version), or an upstream stage is not done;
* ``missing``: products absent;
* ``running``: the stage folder's ``stage-state.json`` names a live process on this host;
* ``failed``: it names an error, or a process that is gone (killed).
"""

from __future__ import annotations

import dataclasses
import json
import os
import socket
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from . import __version__
from .errors import ConfigError, SceneError
from .provenance import atomic_write_text, read_provenance
from .scene import Scene
from .stages import STAGES, Outcome, Stage, StageContext

__all__ = ["StageGraph", "StageStatus", "applicable_stages", "plan_run", "run_pipeline"]


def applicable_stages(scene: Scene) -> list[Stage]:
    """The stages whose required scene sections are present, in registration order."""
    return [s for s in STAGES.values() if all(getattr(scene, r) is not None for r in s.requires)]


@dataclass(frozen=True)
class StageStatus:
    """One line of ``fiberform status``."""

    stage: str
    state: str  # done | stale | missing | running | failed
    detail: str  # why stale, the error, times


class StageGraph:
    """The dependency graph of the given stages for one scene (``ctx``)."""

    def __init__(self, stages: Sequence[Stage], ctx: StageContext) -> None:
        self.ctx = ctx
        self.stages = {s.name: s for s in stages}
        producer = {p: s.name for s in stages for p in s.product_paths(ctx)}
        #: stage -> the stages it needs, and the needed files no stage here makes
        self.upstream: dict[str, tuple[str, ...]] = {}
        self.external: dict[str, tuple[Path, ...]] = {}
        for s in stages:
            needs = s.needs(ctx).values()
            self.upstream[s.name] = tuple(dict.fromkeys(producer[p] for p in needs if p in producer))
            self.external[s.name] = tuple(p for p in needs if p not in producer)
        self.order = self._sorted()

    def _sorted(self) -> list[str]:
        rank = {name: i for i, name in enumerate(self.stages)}
        pending = {n: set(up) for n, up in self.upstream.items()}
        order: list[str] = []
        while pending:
            ready = sorted((n for n, up in pending.items() if not up), key=rank.__getitem__)
            if not ready:
                raise ConfigError("stage graph has a cycle among: " + ", ".join(sorted(pending)))
            n = ready[0]
            order.append(n)
            del pending[n]
            for up in pending.values():
                up.discard(n)
        return order

    def _closure(self, name: str, down: bool) -> set[str]:
        edges = self.upstream if not down else {
            n: tuple(m for m, up in self.upstream.items() if n in up) for n in self.upstream}
        seen, todo = {name}, [name]
        while todo:
            for m in edges[todo.pop()]:
                if m not in seen:
                    seen.add(m)
                    todo.append(m)
        return seen

    def _known(self, name: str, option: str) -> None:
        if name not in self.stages:
            raise ConfigError(f"{option} {name!r}: not a stage of this scene (its stages: "
                              f"{', '.join(self.order)})")

    def select(self, start: str | None = None, stop: str | None = None) -> list[Stage]:
        """The stages from ``start`` (it and everything downstream of it) to ``stop`` (it and
        everything upstream of it), in pipeline order; all when both are None."""
        keep = set(self.order)
        if start is not None:
            self._known(start, "--from")
            keep &= self._closure(start, down=True)
        if stop is not None:
            self._known(stop, "--to")
            keep &= self._closure(stop, down=False)
        if not keep:
            raise ConfigError(f"--from {start!r} --to {stop!r}: {stop!r} does not depend on {start!r}, "
                              "so nothing lies between them")
        return [self.stages[n] for n in self.order if n in keep]

    def check_names(self, names: Sequence[str], option: str) -> None:
        for n in names:
            self._known(n, option)

    def status(self) -> list[StageStatus]:
        """The state of every stage, in pipeline order (reads files only)."""
        out: dict[str, StageStatus] = {}
        for name in self.order:
            st = _stage_status(self.stages[name], self.ctx)
            late = [u for u in self.upstream[name] if out[u].state != "done"]
            if st.state == "done" and late:
                st = StageStatus(name, "stale", f"upstream not done: {', '.join(late)}")
            out[name] = st
        return list(out.values())


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _resumable(info: str) -> str:
    return f"; {info}: `--resume` continues from the last complete one" if info else ""


def _stage_status(stage: Stage, ctx: StageContext) -> StageStatus:
    name = stage.name
    state_file = stage.state_path(ctx)
    if state_file.is_file():
        try:
            rec = json.loads(state_file.read_text())
        except (OSError, ValueError):
            rec = {"state": "failed", "error": f"unreadable {state_file}"}
        # a lay-down or press with restart files: how far `--resume` would continue from
        info = stage.resume_info(ctx) if rec.get("state") in ("running", "failed") else ""
        if rec.get("state") == "running":
            here = rec.get("host") == socket.gethostname()
            if not here or _pid_alive(int(rec.get("pid", 0))):
                where = "" if here else f" on {rec.get('host')}"
                return StageStatus(name, "running", f"since {rec.get('started_utc')}{where} (pid {rec.get('pid')})"
                                   + (f"; {info}" if info else ""))
            return StageStatus(name, "failed", f"process {rec.get('pid')} started {rec.get('started_utc')} "
                                               "is gone (killed?)" + _resumable(info))
        if rec.get("state") == "failed":
            return StageStatus(name, "failed", f"at {rec.get('failed_utc')}: {rec.get('error')}" + _resumable(info))
    paths = stage.product_paths(ctx)
    if not all(p.is_file() for p in paths):
        return StageStatus(name, "missing", "")
    try:
        prov = read_provenance(paths[0])
    except OSError:
        return StageStatus(name, "stale", f"{paths[0].name} unreadable")
    when = f"{prov.get('created_utc', '?')}"
    if "elapsed_s" in prov:
        when += f", {float(prov['elapsed_s']):.1f} s"
    try:
        hashes = stage.input_hashes(ctx)
    except Exception as exc:  # a scene a stage cannot hash yet (missing upstream): stale  # noqa: BLE001
        return StageStatus(name, "stale", f"inputs unreadable: {exc}")
    recorded = prov.get("input_hashes", {})
    changed = sorted(k for k in set(hashes) | set(recorded) if hashes.get(k) != recorded.get(k))
    if prov.get("stage") != name or changed:
        return StageStatus(name, "stale", f"changed: {', '.join(changed) or 'stage'} (made {when})")
    return StageStatus(name, "done", when)


def plan_run(ctx: StageContext, start: str | None = None, stop: str | None = None,
             force: Sequence[str] | None = None, require_upstream: bool = True) -> tuple[list[Stage], set[str]]:
    """The stages of ``fiberform run`` (``--from``/``--to``) and the ones to redo (``--force``:
    None = none, empty = all selected, else those named), after every selected stage's scene
    checks (SceneError, exit status 2, before anything is written). ``require_upstream``: the
    products of upstream stages left out by ``--from`` must exist (``submit`` checks queued jobs
    instead)."""
    graph = StageGraph(applicable_stages(ctx.scene), ctx)
    if not graph.order:
        raise SceneError(str(ctx.scene_path), ["(scene): enables no stage; see docs/stages/scene-format.md"])
    stages = graph.select(start, stop)
    names = [st.name for st in stages]
    if force is None:
        forced: set[str] = set()
    elif not force:
        forced = set(names)
    else:
        graph.check_names(force, "--force")
        outside = [n for n in force if n not in names]
        if outside:
            raise ConfigError(f"--force {outside[0]!r}: not among the stages selected by --from/--to "
                              f"({', '.join(names)})")
        forced = set(force)
    problems = [p for st in stages for p in st.check_scene(ctx.scene)]
    if problems:
        raise SceneError(str(ctx.scene_path), list(dict.fromkeys(problems)))
    for st in stages if require_upstream else ():  # products of stages left out by --from exist
        for up in graph.upstream[st.name]:
            if up in names:
                continue
            for key, path in st.needs(ctx).items():
                if path in graph.stages[up].product_paths(ctx) and not path.is_file():
                    raise ConfigError(f"--from {start}: {st.name} needs {path} ({key}) from stage {up}, "
                                      f"which is missing; run `fiberform run {ctx.scene_path} --to {up}` "
                                      "first, or start earlier")
    return stages, forced


def run_pipeline(ctx: StageContext, stages: Sequence[Stage], forced: set[str],
                 echo: Callable[[str], None] = lambda line: print(line, flush=True)) -> list[Outcome]:
    """Execute ``stages`` in order (each skipped when up to date unless forced) and write
    ``<output_dir>/report.md``: one row per stage and each stage's key results."""
    outcomes = []
    for i, st in enumerate(stages, 1):
        echo(f"[{i}/{len(stages)}] {st.name}: {st.summary}")
        redo = st.name in forced
        outcome = st.execute(dataclasses.replace(ctx, force=redo, options={**ctx.options, "force": redo}))
        outcomes.append(outcome)
        state = "up to date" if outcome.skipped else f"done in {outcome.elapsed_s:.2f} s"
        if outcome.message not in ("done", "up to date"):
            state += f" ({outcome.message})"
        echo(f"[{i}/{len(stages)}] {st.name}: {state}")
    scene, root = ctx.scene, ctx.scene.output_path
    lines = [
        f"# fiberform run: scene `{scene.name}`",
        "",
        f"Scene file `{ctx.scene_path}`, seed {scene.seed}, fiberform {__version__}.",
        "",
        "| stage | status | wall time (s) | products |",
        "|---|---|---|---|",
    ]
    for o in outcomes:
        products = ", ".join(f"`{p.relative_to(root) if p.is_relative_to(root) else p}`" for p in o.products)
        status = "up to date (earlier run)" if o.skipped else "ran"
        if o.message not in ("done", "up to date"):
            status += f" ({o.message})"
        lines.append(f"| {o.stage} | {status} | {o.elapsed_s:.2f} | {products} |")
    results = [line for st in stages for line in st.results(ctx)]
    if results:
        lines += ["", "## Results", "", *(f"- {line}" for line in results)]
    lines += ["", "Each stage folder holds its own `report.md` (where the stage writes one) and the logs "
              "of the programs it ran (`log.<tool>`)."]
    atomic_write_text(root / "report.md", "\n".join(lines) + "\n")
    return outcomes
