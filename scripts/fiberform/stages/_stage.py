# SPDX-License-Identifier: GPL-3.0-or-later
"""The stage mechanism (after signac/row): declared products, skip when up to date, atomic output.

A stage lives in ``<output_dir>/<folder>/``. Its products are files in that folder; the first one
is the stage's HDF5 file, which is written last and marks completion. A run

1. checks the scene (schema, required sections, the stage's own checks) and writes nothing if it
   is bad (:class:`~fiberform.errors.SceneError`, exit status 2);
2. computes hashes of its inputs (scene sections, generated input text, binaries, upstream files);
3. returns early if every product exists and the HDF5 file records the same input hashes,
   unless ``force``;
4. checks its environment (:meth:`Stage.preflight`: binaries present, ranks possible);
5. removes stale products, lets the stage write ``<product>.in_progress`` files, and renames them
   (the HDF5 file last) when all succeeded; on failure the ``.in_progress`` files are deleted.

While it runs, ``<stage folder>/stage-state.json`` says ``running`` (pid, host, start); a failed or
interrupted run leaves it saying ``failed`` with the error; a successful run removes it. The HDF5
file records the stage's wall time (``elapsed_s``; a resumed stage adds the time of the parts
before it, :meth:`Stage.earlier_elapsed`, also stored as ``elapsed_earlier_parts_s``). ``fiberform status`` reads both
(:mod:`fiberform.pipeline`). A stage declares the upstream products it reads in :meth:`Stage.needs`;
the pipeline order follows from those declarations.

A stage that runs an external program splits its work in three (``splits``): :meth:`Stage.prepare`
writes the program's inputs, :meth:`Stage.programs` names the program lines (arguments, MPI ranks,
folder, log; from the scene alone, so a batch script can carry them before anything ran) and
:meth:`Stage.collect` reads the outputs and writes the products. ``fiberform run`` does the three in
one process (:meth:`Stage.produce`, through :func:`fiberform.runner.run`: progress bar, SIGTERM
handling); a batch job runs ``fiberform prepare STAGE SCENE`` (:meth:`Stage.execute_prepare`), the
program lines themselves and ``fiberform collect STAGE SCENE`` (:meth:`Stage.execute_collect`).
Stages without an external program (generate, fabric) have no program lines and implement
:meth:`Stage.produce` themselves.
"""

from __future__ import annotations

import abc
import dataclasses
import datetime as _dt
import json
import os
import socket
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import h5py

from ..errors import ConfigError, SceneError, StageError
from ..provenance import (
    atomic_write_text,
    file_hash,
    in_progress_path,
    read_provenance,
    text_hash,
    write_provenance,
)
from ..liggghts_log import total_wall_time
from ..liggghts_restart import refuse_to_discard
from ..runner import Program, build_command, run
from ..scene import Scene, section_hash

__all__ = ["STATE_NAME", "Outcome", "Program", "Stage", "StageContext", "resumes"]

#: Run-state file in a stage folder (running / failed); absent after a successful run.
STATE_NAME = "stage-state.json"
#: Written by ``fiberform prepare``: the input hashes the stage folder was prepared from.
PREPARED_NAME = "prepared.json"


@dataclass
class StageContext:
    """Everything a stage run may depend on besides the stage's own code."""

    scene: Scene
    scene_path: Path
    build_dir: Path
    force: bool = False
    oversubscribe: bool = False
    show_progress: bool | None = None
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Outcome:
    """Result of :meth:`Stage.execute`."""

    stage: str
    skipped: bool
    products: tuple[Path, ...]
    elapsed_s: float
    message: str


class Stage(abc.ABC):
    """Base class of stages. Subclasses set the class attributes and implement
    :meth:`produce`; they may extend :meth:`check_scene` and :meth:`input_hashes`."""

    #: CLI command name, e.g. ``demo-particles``.
    name: ClassVar[str]
    #: One-line help text.
    summary: ClassVar[str]
    #: Folder under the scene's output_dir.
    folder: ClassVar[str]
    #: Scene sections that must be present.
    requires: ClassVar[tuple[str, ...]]
    #: Top-level scene entries whose values are inputs (hashed).
    uses: ClassVar[tuple[str, ...]]
    #: Product file names in the stage folder; ``products[0]`` is the HDF5 file.
    products: ClassVar[tuple[str, ...]]
    #: Bump to invalidate products written by older code.
    code_version: ClassVar[int] = 1
    #: Programs in ``<build_dir>/bin`` the stage runs (hashed as inputs).
    binaries: ClassVar[tuple[str, ...]] = ()
    #: True when the stage is split into prepare / programs / collect (see the module docstring).
    splits: ClassVar[bool] = False
    #: Stem of the restart files its runs write in ``work/`` (``<stem>.<step>.restart``), or None.
    restart_stem: ClassVar[str | None] = None

    # -- paths ---------------------------------------------------------------------------------

    def stage_dir(self, ctx: StageContext) -> Path:
        return ctx.scene.output_path / self.folder

    def product_paths(self, ctx: StageContext) -> tuple[Path, ...]:
        d = self.stage_dir(ctx)
        return tuple(d / p for p in self.products)

    def needs(self, ctx: StageContext) -> dict[str, Path]:
        """The upstream products this stage reads, by key (absolute paths under the scene's
        output_dir; they may depend on the scene). The pipeline orders stages by these
        declarations: a stage runs after the stages whose products it needs. None by default."""
        return {}

    def ranks(self, ctx: StageContext) -> int:
        """MPI ranks the stage's external programs run on (what a batch job for the stage asks
        for). Default: the ``ranks`` field of the stage's own scene section (the last of
        :attr:`requires`), else 1."""
        section = getattr(ctx.scene, self.requires[-1], None) if self.requires else None
        value = getattr(section, "ranks", 1)
        return value if isinstance(value, int) and not isinstance(value, bool) and value >= 1 else 1

    def state_path(self, ctx: StageContext) -> Path:
        return self.stage_dir(ctx) / STATE_NAME

    def metrics(self, ctx: StageContext) -> dict[str, float]:
        """Key numbers of a finished stage, read back from its HDF5 product, for sweeps
        (``fiberform collect``); SI units in the key names (``sheet_thickness_m``). None by
        default."""
        return {}

    def results(self, ctx: StageContext) -> list[str]:
        """Key results of a finished stage, one line each, read back from its HDF5 product (the
        run report's "Results"); none by default."""
        return []

    # -- checks and hashes ---------------------------------------------------------------------

    def check_scene(self, scene: Scene) -> list[str]:
        """Problems beyond the schema, one line each naming the field path. The base checks
        that the required sections are present."""
        problems = []
        for section in self.requires:
            if getattr(scene, section) is None:
                problems.append(f"{section}: required but missing (stage {self.name} needs it)")
        return problems

    def validate(self, ctx: StageContext) -> None:
        problems = self.check_scene(ctx.scene)
        if problems:
            raise SceneError(str(ctx.scene_path), problems)

    def preflight(self, ctx: StageContext) -> None:  # noqa: B027 - optional hook
        """Check the environment (binaries present, ...) before anything is written; raise
        StageError or ConfigError. The base does nothing."""

    def check_start_over(self, ctx: StageContext, hashes: Mapping[str, str]) -> None:
        """A run without ``--resume`` or ``--force`` of a stage whose runs leave restart files
        (``restart_stem``, in its ``work/`` folder) must not discard those of a killed run of the
        same inputs: ConfigError (fiberform.liggghts_restart.refuse_to_discard)."""
        if self.restart_stem is None or ctx.force or ctx.options.get("resume"):
            return
        refuse_to_discard(self.stage_dir(ctx) / "work", self.restart_stem, self.restart_identity(ctx, hashes),
                          f"fiberform {self.name} {ctx.scene_path}", legacy=hashes)

    def restart_identity(self, ctx: StageContext, hashes: Mapping[str, str]) -> dict[str, str]:
        """The inputs a run's restart files belong to (recorded in its working folder, compared on
        ``--resume``): the input hashes ``hashes``, less what may change between a run and its
        continuation (the lay-down: its end time). The products' hashes stay ``hashes``."""
        return dict(hashes)

    def check_launch(self, ctx: StageContext) -> None:
        """A local run (:meth:`execute`): the stage's program lines can be launched here, their MPI
        ranks against the machine's cores (ConfigError, exit status 2, unless ``--oversubscribe``),
        checked before anything is written or removed (:func:`fiberform.runner.build_command`
        checks the same when it runs). Not for batch jobs: their program lines run under the
        scheduler's allocation, which may span nodes."""
        for prog in self.programs(ctx):
            build_command(list(prog.argv), prog.ranks, ctx.oversubscribe)

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        """Hashes of everything the products depend on: the scene entries in ``uses``, the code
        version, every upstream product of :meth:`needs` and every program of ``binaries``
        (``"missing"`` for an absent file). Subclasses add their own entries."""
        hashes = {
            "scene": section_hash(ctx.scene, self.uses),
            "stage_code": text_hash(f"{self.name}:{self.code_version}"),
        }
        files = {**self.needs(ctx), **{b: ctx.build_dir / "bin" / b for b in self.binaries}}
        for key, path in files.items():
            hashes[key] = file_hash(path) if path.is_file() else "missing"
        return hashes

    def up_to_date(self, ctx: StageContext, hashes: Mapping[str, str]) -> bool:
        paths = self.product_paths(ctx)
        if not all(p.is_file() for p in paths):
            return False
        try:
            prov = read_provenance(paths[0])
        except OSError:
            return False
        return prov.get("stage") == self.name and prov.get("input_hashes") == dict(hashes)

    # -- running: prepare, programs, collect (the split), produce, execute ---------------------

    def prepare(self, ctx: StageContext, hashes: Mapping[str, str]) -> None:  # noqa: B027 - optional
        """Write the inputs of the stage's programs into the stage folder (split stages)."""

    def programs(self, ctx: StageContext) -> list[Program]:
        """The program lines of the stage, in order, from the scene alone (absolute paths); none by
        default."""
        return []

    def log_key(self, ctx: StageContext, log: Path) -> str:
        """The key of a program's wall time in :meth:`collect`: its ``log`` relative to the stage
        folder (``log.simpleFoam``)."""
        d, log = self.stage_dir(ctx).resolve(), log.resolve()
        return str(log.relative_to(d)) if log.is_relative_to(d) else str(log)

    def liggghts_wall_time(self, ctx: StageContext, log: Path, wall_times: Mapping[str, float]) -> float:
        """A LIGGGHTS program's wall time (s): as fiberform measured it (``wall_times``, a local
        run), else the sum of the Loop times of its log (a batch job ran it)."""
        key = self.log_key(ctx, log)
        return wall_times[key] if key in wall_times else total_wall_time(log.read_text(errors="replace"))

    def collect(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str],
                wall_times: Mapping[str, float]) -> None:
        """Read the programs' outputs and write the products as :meth:`produce` does;
        ``wall_times``: seconds per program (:meth:`log_key`) as measured by fiberform (empty when a
        batch job ran them)."""
        raise NotImplementedError(f"stage {self.name} is not split into prepare / programs / collect")

    def produce(
        self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str]
    ) -> None:
        """Do the work. Write datasets into ``h5`` (provenance is already on its root) and the
        other products to ``tmp[name]`` (their ``.in_progress`` paths). The default (split stages):
        :meth:`prepare`, each of :meth:`programs` through :func:`fiberform.runner.run`,
        :meth:`collect`."""
        if not self.splits:
            raise NotImplementedError(f"stage {self.name} implements neither produce nor the split")
        self.prepare(ctx, hashes)
        times: dict[str, float] = {}
        for prog in self.programs(ctx):
            res = run(list(prog.argv), prog.log, cwd=prog.cwd, ranks=prog.ranks, progress=prog.progress,
                      oversubscribe=ctx.oversubscribe,
                      description=f"{self.name}: {prog.log.name.removeprefix('log.')}",
                      show_progress=ctx.show_progress)
            times[self.log_key(ctx, prog.log)] = res.elapsed_s
        self.collect(ctx, h5, tmp, hashes, times)

    def execute(self, ctx: StageContext) -> Outcome:
        start = time.monotonic()
        self.validate(ctx)
        hashes = self.input_hashes(ctx)
        if not ctx.force and self.up_to_date(ctx, hashes):
            return Outcome(self.name, True, self.product_paths(ctx), time.monotonic() - start,
                           "up to date")  # fmt: skip
        self.preflight(ctx)
        self.check_launch(ctx)
        self.check_start_over(ctx, hashes)
        started = self._begin(ctx, os.getpid())
        self._write_products(ctx, hashes, started, start,
                             lambda h5, tmp: self.produce(ctx, h5, tmp, hashes))
        return Outcome(self.name, False, self.product_paths(ctx), time.monotonic() - start, "done")

    def execute_prepare(self, ctx: StageContext) -> bool:
        """``fiberform prepare``: the first part of a batch job. False (nothing written) when the
        products are up to date; else the stage folder is prepared for :meth:`programs` and marked
        running for the batch job (the parent process: the job script)."""
        self._split_only()
        self.validate(ctx)
        hashes = self.input_hashes(ctx)
        if not ctx.force and self.up_to_date(ctx, hashes):
            return False
        self.preflight(ctx)
        self.check_start_over(ctx, hashes)
        started = self._begin(ctx, os.getppid())
        prepared = self.stage_dir(ctx) / PREPARED_NAME
        prepared.unlink(missing_ok=True)
        try:
            self.prepare(ctx, hashes)
        except BaseException as exc:
            self._failed(ctx, started, exc)
            raise
        atomic_write_text(prepared, json.dumps({"stage": self.name, "input_hashes": dict(hashes),
                                                "options": dict(ctx.options)}) + "\n")
        return True

    def execute_collect(self, ctx: StageContext) -> Outcome:
        """``fiberform collect``: the last part of a batch job, after the program lines; the stage
        folder must be prepared from the inputs of now."""
        self._split_only()
        start = time.monotonic()
        self.validate(ctx)
        hashes = self.input_hashes(ctx)
        prepared = self.stage_dir(ctx) / PREPARED_NAME
        try:
            rec = json.loads(prepared.read_text())
        except (OSError, ValueError):
            raise StageError(f"{prepared}: missing or unreadable; run `fiberform prepare {self.name} SCENE` "
                             "and the program lines first") from None
        if rec.get("input_hashes") != dict(hashes):
            raise StageError(f"{self.stage_dir(ctx)}: prepared from other inputs than the scene's now; "
                             f"prepare it again (`fiberform prepare {self.name} SCENE`)")
        started = _now()
        # the products record the options the run was prepared with (--force, --resume, ...), not
        # those of the collect command, which has none
        ctx = dataclasses.replace(ctx, options=dict(rec.get("options", ctx.options)))
        self._write_products(ctx, hashes, started, start,
                             lambda h5, tmp: self.collect(ctx, h5, tmp, hashes, {}))
        prepared.unlink(missing_ok=True)
        return Outcome(self.name, False, self.product_paths(ctx), time.monotonic() - start, "done")

    def resume_info(self, ctx: StageContext) -> str:
        """For ``fiberform status`` of a running or failed stage: what a ``--resume`` would continue
        from (the latest restart file and the run's length); "" for a stage that does not resume."""
        return ""

    def earlier_elapsed(self, ctx: StageContext) -> float:
        """Seconds spent before this run on the work it continues (a resumed stage: the killed
        parts up to the point it resumed from), added to the product's ``elapsed_s``; 0 here."""
        return 0.0

    def _split_only(self) -> None:
        if not self.splits:
            raise ConfigError(f"stage {self.name} runs in one step (`fiberform {self.name} SCENE`): it is not "
                             "split into prepare / program lines / collect")

    def _begin(self, ctx: StageContext, pid: int) -> str:
        """Create the stage folder, mark it running (``pid``) and remove the old products."""
        self.stage_dir(ctx).mkdir(parents=True, exist_ok=True)
        started = _now()
        atomic_write_text(self.state_path(ctx), json.dumps({
            "state": "running", "stage": self.name, "pid": pid, "host": socket.gethostname(),
            "started_utc": started}) + "\n")
        for p in self.product_paths(ctx):
            p.unlink(missing_ok=True)
        return started

    def _failed(self, ctx: StageContext, started: str, exc: BaseException) -> None:
        reason = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else (str(exc) or type(exc).__name__)
        atomic_write_text(self.state_path(ctx), json.dumps({"state": "failed", "stage": self.name,
                                                            "started_utc": started, "failed_utc": _now(),
                                                            "error": reason[:2000]}) + "\n")

    def _write_products(self, ctx: StageContext, hashes: Mapping[str, str], started: str, start: float,
                        work: Callable[[h5py.File, Mapping[str, Path]], None]) -> None:
        """Run ``work`` on the ``.in_progress`` products (the HDF5 file with provenance) and rename
        them (the HDF5 file last); on failure delete them and mark the stage failed."""
        paths = self.product_paths(ctx)
        tmp = {p.name: in_progress_path(p) for p in paths}
        try:
            for t in tmp.values():
                t.unlink(missing_ok=True)
            with h5py.File(tmp[paths[0].name], "w") as h5:
                write_provenance(h5, self.name, ctx.scene, hashes, ctx.options, ctx.build_dir)
                work(h5, tmp)
                earlier = self.earlier_elapsed(ctx)
                h5.attrs["elapsed_s"] = time.monotonic() - start + earlier
                if earlier > 0.0:
                    h5.attrs["elapsed_earlier_parts_s"] = earlier
            for p in paths[1:]:
                tmp[p.name].replace(p)
            tmp[paths[0].name].replace(paths[0])
        except BaseException as exc:
            for t in tmp.values():
                t.unlink(missing_ok=True)
            self._failed(ctx, started, exc)
            raise
        self.state_path(ctx).unlink(missing_ok=True)


def resumes(ctx: StageContext) -> bool:
    """Whether an OpenFOAM stage continues a killed solve of the same inputs (its case directory
    must hold a case prepared from the input hashes of this run): unless forced (``--force``
    starts over; ``--force --resume`` resumes)."""
    return not ctx.force or bool(ctx.options.get("resume"))


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
