# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``laydown``: the generated fibers settle on the fabric in the frozen flow (one-way coupling,
Kettil 2016 sec. 3.1-3.3).

fiberdem runs fix fiber/beam (flexible fibers), fix fiber/drag (drag eq. 2.14-2.16 in the frozen
grid of the flow stage, gravity, buoyancy), fix wall/fiber/yarns (fabric yarns as static cylinder
chains under the fiber/dlvo law, inside each fiber's implicit solve by default), one fix
wall/fiber/dlvo per vertical side plane, fix fiber/remove (removal of whole fibers below the
removal height) and fix fiber/settle (the settle counter). The
input is built through fiberform.inputs only. fiberdem runs on ``laydown.ranks`` MPI ranks and
writes restart files every ``restart_interval_s``; ``--resume`` continues a killed run from the
last complete one (docs/stages/laydown.md, "Resuming").

The run is a sequence of ``run`` commands of ``check_interval_s`` each; after each, the input ends
once fix fiber/settle has counted ``settle_checks`` consecutive checks with every node slower than
``settle_speed_m_s`` (the settle criterion), else it ends at ``max_time_s``. A snapshot of every
node is dumped at each check (``traj.dump``); the last snapshot is the sheet.

With ``coupling: {mode: two_way}`` fiberdem runs under one mpirun with ``fiberPimpleFoam -coupled``
(issue 13): the fluid case ``work/fluid`` is the flow stage's case with its steady solution as the
initial state, exchanging with the fibers on flow.grid's grid through the exchange map
(fiberform.coupling_map); the drainage (flow rate out through the bottom) after every fluid step goes
to laydown.h5 ``/drainage`` and the report. ``--resume`` restarts both sides.

Products in ``<output_dir>/laydown/``: ``laydown.h5``, ``sheet.vtu`` (ParaView), ``laydown.png``,
``report.md``. Page: docs/stages/laydown.md.
"""

from __future__ import annotations

import json
import math
import re
import shutil
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from ..coupling_map import MAP_NAME, ExchangeGrid, exchange_map, write_exchange_map
from ..errors import StageError
from ..fiber_io import (
    NODES_NAME, fiber_preamble, fibers_in_nodes, laydown_beam_options, outer_half_axes, write_nodes_subset,
)
from ..fiber_sheet import (
    contact_commands, contact_yarns, element_clearance, fiber_com_speeds, fiber_fiber_gap, frame_fibers,
    frame_positions, frame_quaternions, lateral_period, mass_fraction_speed, node_dump_columns,
    pair_options, product_thickness_above_fabric,
    sheet_thickness, sheet_thickness_above_fabric, wrap_chains, wrap_points,
    write_sheet_png, write_sheet_vtu, write_yarns, yarn_distances,
)
from ..inputs import LiggghtsInput, file_token, fix_ref, jump_if_at_least, step_file_token
from .. import liggghts_restart
from ..liggghts_log import dump_frame, read_dump
from ..liggghts_restart import (
    EARLIER_LOG, RESTART_EXT, cut_back, dump_snapshots, earlier_wall, prepared_step, read_text_if,
    record_prepared, restart_interval_steps, restart_name, run_log, run_log_parts, start_over,
)
from ..openfoam_case import (
    CASE_DIR, DRAINAGE_FO, cell_centres, coupled_state, cut_coupled_back, decompose, prepare_coupled_case,
    read_patch_history,
)
from ..products import (
    FABRIC_H5, FIBERS_DATA, FIBERS_H5, FIBERS_NODES, FLOW_GRID, FLOW_H5, read_flow_grid,
    read_superficial_velocity, read_yarns,
)
from ..provenance import atomic_write_text, file_hash, report_origin, write_dataset
from .._versions import pstream_dir
from ..runner import liggghts_progress, mpmd_command
from ..scene import FluidSection, Scene, section_hash
from ._stage import Outcome, Program, Stage, StageContext

__all__ = ["Laydown", "build_input", "sheet_thickness"]

Array = npt.NDArray[np.float64]
H5_NAME, VTU_NAME, PNG_NAME, REPORT_NAME = "laydown.h5", "sheet.vtu", "laydown.png", "report.md"
INPUT_NAME, LOG_NAME, TRAJ_NAME, YARNS_NAME = "in.laydown", "log.fiberdem", "traj.dump", "yarns.txt"
_REMOVED = re.compile(r"fix fiber/remove: step (\d+) removed fiber\(s\)((?: \d+)+)")
REMOVE_FIX, SETTLE_FIX = "remove", "settle"  # fix fiber/remove, fix fiber/settle
RESTART_STEM = "laydown"  # restart files laydown.<step>.restart
FLUID_CASE = "fluid"  # the coupled fluid's OpenFOAM case in the working folder (two_way)
FLUID_LOG = "log.fiberPimpleFoam"  # its output, in the working folder
SHEET_RESTART, SETTLED_LABEL = "sheet.restart", "laydown_end"


def removal_height(scene: Scene) -> float:
    ld, fab = scene.laydown, scene.fabric
    assert ld is not None and fab is not None
    return ld.removal_height_m if ld.removal_height_m is not None else fab.lower_side_z_m - 50e-6


def run_lengths(scene: Scene) -> tuple[int, int]:
    """Steps per settle check and the number of checks of the lay-down."""
    ld = scene.laydown
    assert ld is not None
    steps_per_check = max(1, round(ld.check_interval_s / ld.timestep_s))
    return steps_per_check, max(1, math.ceil(ld.max_time_s / (steps_per_check * ld.timestep_s)))


def settle_speed(scene: Scene, superficial_velocity_m_s: float) -> float:
    """The settle threshold (m/s): settle_speed_fraction x the superficial velocity, or
    settle_speed_m_s."""
    ld = scene.laydown
    assert ld is not None
    return (ld.settle_speed_fraction * abs(superficial_velocity_m_s)
            if ld.settle_speed_fraction is not None else ld.settle_speed_m_s)


def launch(scene: Scene, build_dir: Path) -> tuple[list[str], int]:
    """The fiberdem command line of the lay-down (run in the working folder) and its MPI ranks."""
    ld = scene.laydown
    assert ld is not None
    return [str((build_dir / "bin" / "fiberdem").resolve()), "-in", INPUT_NAME, "-log", "none"], ld.ranks


def two_way(scene: Scene) -> bool:
    return scene.coupling is not None and scene.coupling.mode == "two_way"


def coupled_launch(scene: Scene, build_dir: Path, oversubscribe: bool = False) -> list[str]:
    """The single mpirun (MPMD) of a two-way lay-down, run in the working folder: fiberdem on
    laydown.ranks ranks and fiberPimpleFoam -coupled on coupling.fluid_ranks ranks (case ``fluid``,
    its output appended to ``log.fiberPimpleFoam``; > 1 rank: ``-parallel`` with the rebuilt
    libPstream through LD_LIBRARY_PATH, docs/coupling/launch.md)."""
    argv, ranks = launch(scene, build_dir)
    cp = scene.coupling
    assert cp is not None
    fluid = [str((build_dir / "bin" / "fiberPimpleFoam").resolve()), "-coupled", "-case", FLUID_CASE,
             "-couplingTimeout", repr(float(cp.timeout_s))]
    # append: every fluid rank writes to the one log (only the master prints, errors aside)
    wrapper = ["sh", "-c", f'exec "$0" "$@" >> {FLUID_LOG}']  # MPI environment kept by exec
    if cp.fluid_ranks > 1:
        fluid.append("-parallel")
        wrapper = ["env", f"LD_LIBRARY_PATH={pstream_dir().resolve()}", *wrapper]
    return mpmd_command([(argv, ranks), ([*wrapper, *fluid], cp.fluid_ranks)], oversubscribe)


def restart_every(scene: Scene) -> int:
    """Steps between restart files (a whole number of checks; 0: none)."""
    ld = scene.laydown
    assert ld is not None
    steps_per_check, _ = run_lengths(scene)
    return restart_interval_steps(ld.restart_interval_s, ld.check_interval_s, steps_per_check)


def render_input(scene: Scene, superficial_velocity_m_s: float, resume_step: int | None = None) -> str:
    """The lay-down's LIGGGHTS input for a flow of the given superficial velocity (m/s): every
    field of the laydown and contact sections acts through here. ``resume_step``: continue from
    the restart file of that step (``laydown.<step>.restart``) instead of the generated fibers."""
    steps_per_check, checks = run_lengths(scene)
    return build_input(scene, steps_per_check, checks, settle_speed(scene, superficial_velocity_m_s),
                       resume_step=resume_step)


def build_input(scene: Scene, steps_per_check: int, checks: int,
                settle_speed: float | None = None, resume_step: int | None = None) -> str:
    """The LIGGGHTS input of the lay-down (files in the working folder: fibers.data,
    fibers.nodes, flow.grid, yarns.txt; with ``resume_step`` also laydown.<step>.restart)."""
    f, ld, dom = scene.fibers, scene.laydown, scene.domain
    assert f is not None and ld is not None and dom is not None
    fl = scene.fluid or FluidSection()
    s = LiggghtsInput()
    s.comment("Generated by fiberform stage laydown (docs/stages/laydown.md).")
    # pair_style fiber/dlvo needs newton on; the fiber fixes are indifferent to it
    restart = (file_token(restart_name(RESTART_STEM, int(resume_step)))
               if resume_step is not None else None)
    periodic = lateral_period(scene) is not None  # walls periodic: boundary p p f, no side planes
    fiber_preamble(s, f, scene.contact is not None,
                   *laydown_beam_options(ld), restart=restart,
                   flat_decomposition=True, periodic_xy=periodic)
    s.command("fix", "drag", "all", "fiber/drag", "flow", "grid", file_token("flow.grid"),
              "fluid_density", fl.density_kg_m3, "viscosity", fl.viscosity_Pa_s,
              "gravity", *fl.gravity_m_s2)
    contact_commands(s, scene, YARNS_NAME, steric_cap_m=ld.steric_cap_m)
    # removal of whole fibers below the removal height and the settle counter, every check
    s.command("fix", REMOVE_FIX, "all", "fiber/remove", "below", removal_height(scene),
              "every", steps_per_check)
    s.command("fix", SETTLE_FIX, "all", "fiber/settle",
              settle_speed if settle_speed is not None else ld.settle_speed_m_s, steps_per_check,
              "measure", ld.settle_measure,
              *(["mass_fraction", ld.settle_mass_fraction] if ld.settle_measure == "fiber" else []))
    cp = scene.coupling
    if two_way(scene) and cp is not None:
        # the fluid's cell velocities replace flow.grid at the first run (docs/coupling/launch.md)
        s.command("fix", "couple", "all", "fiber/coupling", "drag", "drag", "interval", cp.interval,
                  "timeout", cp.timeout_s, "reaction", "yes" if cp.reaction == "on" else "no")
    s.command("timestep", ld.timestep_s)
    s.command("variable", "settled", "equal", fix_ref(SETTLE_FIX, 1))
    s.command("thermo_style", "custom", "step", "atoms", fix_ref(REMOVE_FIX, 1), fix_ref(REMOVE_FIX, 2),
              fix_ref(SETTLE_FIX, 1), fix_ref(SETTLE_FIX, 2), fix_ref("drag", 3))
    # losses are caught by the accounting by fiber ID; flush: the log follows the run (a pipe
    # buffers fiberdem's screen output otherwise)
    s.command("thermo_modify", "lost", "ignore", "flush", "yes")
    s.command("thermo", steps_per_check)
    # collapsed fibers: also the node quaternions (their sections' orientation, the gap check);
    # periodic: the unwrapped positions (continuous chains)
    columns, dump_fmt = node_dump_columns(f, periodic)
    s.command("dump", "traj", "all", "custom", steps_per_check, file_token(TRAJ_NAME), *columns)
    s.command("dump_modify", "traj", "sort", "id", "format", dump_fmt)
    first = 0
    if resume_step is not None:
        # the snapshots before the restart are kept in traj.dump (the stage cut it there)
        s.command("dump_modify", "traj", "append", "yes")
        first = int(resume_step) // steps_per_check
    every = restart_every(scene)
    if every:
        s.command("restart", every, step_file_token(RESTART_STEM, RESTART_EXT))
    for k in range(first, checks):
        if k == first:
            s.command("run", steps_per_check)
        else:
            s.command("run", steps_per_check, "pre", "no", "post", "no")
        s.command("if", *jump_if_at_least("settled", ld.settle_checks, SETTLED_LABEL))
    s.label(SETTLED_LABEL)
    # the final state, for the stages after the lay-down (press): atoms and per-atom fix states
    s.command("write_restart", file_token(SHEET_RESTART))
    return s.render()


class Laydown(Stage):
    """Lay-down of the fibers on the fabric in the frozen flow."""

    name = "laydown"
    summary = ("lay the generated fibers down on the fabric in the frozen flow (one-way coupling) "
               "or with the fluid (coupling two_way)")
    folder = "laydown"
    requires = ("domain", "fibers", "fabric", "flow", "laydown")
    uses = ("seed", "domain", "fibers", "fiber_generation", "fabric", "flow", "fluid", "laydown",
            "contact", "coupling")
    products = (H5_NAME, VTU_NAME, PNG_NAME, REPORT_NAME, SHEET_RESTART)
    binaries = ("fiberdem",)
    code_version = 3
    splits = True
    restart_stem = RESTART_STEM

    def metrics(self, ctx: StageContext) -> dict[str, float]:
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            a = h5["run"].attrs
            return {"settled": float(bool(a["settled"])), "laydown_simulated_time_s": float(a["simulated_time_s"]),
                    "sheet_thickness_m": float(a["sheet_thickness_m"]),
                    "grammage_kg_m2": float(a["grammage_kg_m2"]),
                    "sheet_thickness_above_fabric_m": product_thickness_above_fabric(
                        ctx.scene, self.product_paths(ctx)[0], float(a["fabric_top_m"]))}

    def results(self, ctx: StageContext) -> list[str]:
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            a = h5["run"].attrs
            above = product_thickness_above_fabric(ctx.scene, self.product_paths(ctx)[0], a["fabric_top_m"])
            return [f"lay-down: {'settled' if a['settled'] else 'NOT settled'} after "
                    f"{a['simulated_time_s'] * 1e3:.2f} ms; sheet thickness {a['sheet_thickness_m'] * 1e6:.1f} um "
                    f"(5-95 % node span + width), {above * 1e6:.1f} um above the fabric top (95th percentile "
                    f"of the fibers' upper surfaces), grammage {a['grammage_kg_m2'] * 1e3:.3g} g/m^2"]

    def execute(self, ctx: StageContext) -> Outcome:
        out = super().execute(ctx)
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            settled = bool(h5["run"].attrs["settled"])
        if not settled:
            import sys

            print(f"fiberform laydown: WARNING: the sheet did NOT settle within max_time_s "
                  f"(see {self.product_paths(ctx)[3]})", file=sys.stderr)
            return Outcome(out.stage, out.skipped, out.products, out.elapsed_s,
                           out.message + ", NOT SETTLED")
        return out

    def check_scene(self, scene: Scene) -> list[str]:
        problems = super().check_scene(scene)
        if problems:
            return problems
        assert scene.laydown is not None and scene.domain is not None
        ld = scene.laydown
        if scene.contact is not None and scene.contact.model != "fiber_dlvo":
            problems.append("contact.model: the lay-down supports fiber_dlvo only (fiber-fiber "
                            "contact of the fix fiber/beam fibers)")
        c = scene.contact
        if c is not None and ld.fiber_contact_mode == "newton":
            unused = sorted({"integrator", "substeps", "points_per_element"} & c.model_fields_set)
            if unused:
                problems.append(f"contact.{unused[0]}: only used with laydown.fiber_contact averaged "
                                "(with newton, the default for implicit fibers, fiber contacts are "
                                "solved inside the fibers' Newton solves)")
        if removal_height(scene) <= scene.domain.lo_m[2]:
            problems.append("laydown.removal_height_m: must lie above domain.lo_m[2] (fibers "
                            "leaving the box would be lost)")
        if two_way(scene):
            assert scene.coupling is not None
            steps_per_check, _ = run_lengths(scene)
            if steps_per_check % scene.coupling.interval:
                problems.append(f"coupling.interval = {scene.coupling.interval}: must divide the "
                                f"{steps_per_check} steps of one laydown.check_interval_s")
        if round(ld.check_interval_s / ld.timestep_s) * round(ld.max_time_s / ld.check_interval_s) > 10**8:
            problems.append("laydown.max_time_s: more than 1e8 steps")
        return problems

    def needs(self, ctx: StageContext) -> dict[str, Path]:
        root = ctx.scene.output_path
        return {
            "fibers_h5": root / FIBERS_H5,
            "fibers_data": root / FIBERS_DATA,
            "fibers_nodes": root / FIBERS_NODES,
            "fabric_h5": root / FABRIC_H5,
            "flow_grid": root / FLOW_GRID,
        }

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        hashes = super().input_hashes(ctx)
        if two_way(ctx.scene):  # the coupled fluid: its solver and the flow stage's solution
            solver = ctx.build_dir / "bin" / "fiberPimpleFoam"
            hashes["fiberPimpleFoam"] = file_hash(solver) if solver.is_file() else "missing"
            flow_h5 = ctx.scene.output_path / FLOW_H5
            hashes["flow_h5"] = file_hash(flow_h5) if flow_h5.is_file() else "missing"
        return hashes

    def preflight(self, ctx: StageContext) -> None:
        for key, p in self.needs(ctx).items():
            if not p.is_file():
                raise StageError(f"{p} missing ({key}): run the generate, fabric and flow stages "
                                 "first (fiberform run SCENE runs them in order)")
        if not (ctx.build_dir / "bin" / "fiberdem").is_file():
            raise StageError(f"{ctx.build_dir / 'bin' / 'fiberdem'} not found: build first")
        if two_way(ctx.scene):
            if not (ctx.build_dir / "bin" / "fiberPimpleFoam").is_file():
                raise StageError(f"{ctx.build_dir / 'bin' / 'fiberPimpleFoam'} not found: build "
                                 "first (coupling.mode two_way)")
            case = ctx.scene.output_path / "flow" / CASE_DIR
            if not (case / "constant" / "polyMesh").is_dir():
                raise StageError(f"{case}: the flow stage's OpenFOAM case is missing (coupling.mode "
                                 "two_way starts from it): run `fiberform flow` first")
            cp = ctx.scene.coupling
            lib = pstream_dir() / "libPstream.so"
            if cp is not None and cp.fluid_ranks > 1 and not lib.is_file():
                raise StageError(f"{lib} missing: coupling.fluid_ranks = {cp.fluid_ranks} needs "
                                 "OpenFOAM's libPstream rebuilt with the MPMD split (make setup, or "
                                 "scripts/setup/openfoam-pstream.sh; $FIBERFORM_PSTREAM_DIR)")

    def prepare(self, ctx: StageContext, hashes: Mapping[str, str]) -> None:
        """The working folder: fresh (fibers.data, fibers.nodes, flow.grid copied in) or, with
        ``--resume``, the killed run's cut back to its last complete restart file; yarns.txt and
        the input script; the start step in PREPARED_STEP."""
        scene = ctx.scene
        paths = self.needs(ctx)
        work = self.stage_dir(ctx) / "work"
        end = math.prod(run_lengths(scene))  # a shortened lay-down resumes from before its new end

        def usable(step: int) -> bool:
            return step < end and (not two_way(scene) or fluid_state(work, scene, step) is not None)

        ident = self.restart_identity(ctx, hashes)
        resume_step = resume_point(work, ident, usable, legacy=hashes) if ctx.options.get("resume") else None
        if resume_step is None:
            start_over(work, RESTART_STEM, ident, "fiberform laydown", bool(ctx.options.get("resume")))
            for key, name in (("fibers_data", "fibers.data"), ("fibers_nodes", "fibers.nodes"),
                              ("flow_grid", "flow.grid")):
                shutil.copyfile(paths[key], work / name)
        else:
            prepare_resume(work, resume_step, paths["fibers_nodes"])
            nodes_left(work, paths["fibers_nodes"])
        write_yarns(work / YARNS_NAME, paths["fabric_h5"], lateral_period(scene))
        (work / INPUT_NAME).write_text(render_input(scene, self._superficial_velocity(ctx), resume_step))
        if two_way(scene):
            (work / FLUID_LOG).unlink(missing_ok=True)  # the fluid ranks append to it
        if two_way(scene) and resume_step is None:
            prepare_fluid(scene, work)
        elif two_way(scene):
            resume_fluid(work, scene, int(resume_step))
        record_prepared(work, resume_step)

    def restart_identity(self, ctx: StageContext, hashes: Mapping[str, str]) -> dict[str, str]:
        """The input hashes with ``laydown.max_time_s`` left out of the scene's: restart files
        carry on when only the end time changed (``--resume`` continues a lay-down that did not
        settle with a larger max_time_s, or ends one earlier with a smaller one)."""
        ld = ctx.scene.laydown
        assert ld is not None
        neutral = ctx.scene.model_copy(update={"laydown": ld.model_copy(update={"max_time_s": 0.0})})
        return {**hashes, "scene": section_hash(neutral, self.uses)}

    def resume_info(self, ctx: StageContext) -> str:
        steps = restart_steps(self.stage_dir(ctx) / "work")
        if not steps:
            return ""
        per, checks = run_lengths(ctx.scene)
        return f"restart files to step {steps[-1]} of at most {per * checks}"  # (it may settle earlier)

    def earlier_elapsed(self, ctx: StageContext) -> float:
        """A resumed lay-down: fiberdem's time in the parts before it, up to the restart step it
        continued from (EARLIER_WALL; 0 when not known)."""
        return earlier_wall(self.stage_dir(ctx) / "work") or 0.0

    def _superficial_velocity(self, ctx: StageContext) -> float:
        return read_superficial_velocity(ctx.scene.output_path / FLOW_H5)

    def programs(self, ctx: StageContext) -> list[Program]:
        argv, ranks = launch(ctx.scene, ctx.build_dir)
        if two_way(ctx.scene):  # one mpirun (MPMD) for fiberdem and fiberPimpleFoam
            argv, ranks = coupled_launch(ctx.scene, ctx.build_dir, ctx.oversubscribe), 1
        steps_per_check, checks = run_lengths(ctx.scene)
        work = (self.stage_dir(ctx) / "work").resolve()
        return [Program(tuple(argv), ranks, work, work / LOG_NAME, liggghts_progress(steps_per_check * checks))]

    def collect(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str],
                wall_times: Mapping[str, float]) -> None:
        scene = ctx.scene
        ld, f, dom = scene.laydown, scene.fibers, scene.domain
        assert ld is not None and f is not None and dom is not None
        paths = self.needs(ctx)
        work = self.stage_dir(ctx) / "work"
        resume_step = prepared_step(work)
        yarns = read_yarns(paths["fabric_h5"])
        # periodic x/y: the measures against the yarns tiled as fix wall/fiber/yarns had them, with
        # the nodes (elements: the chains) wrapped into the box
        period = lateral_period(scene)
        checked = contact_yarns(yarns, period)
        pts, offs, rad = checked.points, checked.offsets, checked.radius
        with h5py.File(paths["fibers_h5"], "r") as fh:
            f_off = np.asarray(fh["fibers/offsets"][...], dtype=np.int64)
            f_mass = np.asarray(fh["fibers/mass"][...], dtype=float)
            x0 = np.asarray(fh["fibers/x"][...], dtype=float)
            f_radii = np.asarray(fh["fibers/radii"][...], dtype=float)
        steps_per_check, checks = run_lengths(scene)
        u_s = self._superficial_velocity(ctx)
        v_settle = settle_speed(scene, u_s)
        wall_part = self.liggghts_wall_time(ctx, work / LOG_NAME, wall_times)
        # a resumed run: the parts before it, to the restart step it continued from, count too
        wall_before = earlier_wall(work)
        wall = wall_part + (wall_before or 0.0)
        log = run_log(work, LOG_NAME)
        frames = read_dump(work / TRAJ_NAME)
        if not frames:
            raise StageError(f"{work / TRAJ_NAME}: no snapshot written")
        last = frames[-1]
        steps_done = last.step
        settled = steps_done < steps_per_check * checks  # the input quit before max_time_s

        # ---- mass accounting: by fiber IDs (fibers.h5 masses), cross-checked with the fix ----
        n_fib = len(f_mass)
        # LIGGGHTS fiber IDs are 1-based (fiber_io first_fiber_id); fibers.h5 indices 0-based
        fid = np.rint(last.columns["f_beam[1]"]).astype(np.int64) - 1
        present = np.unique(fid)
        removed_ids = sorted(removed_fibers(log))
        on_sheet = np.zeros(n_fib, dtype=bool)
        on_sheet[present] = True
        removed = np.zeros(n_fib, dtype=bool)
        removed[removed_ids] = True
        if np.any(on_sheet & removed) or not np.all(on_sheet | removed):
            raise StageError("mass accounting failed: a fiber is both on the sheet and removed, or "
                             "neither (lost atoms?)")
        m_inj, m_sheet, m_rem = float(f_mass.sum()), float(f_mass[on_sheet].sum()), float(f_mass[removed].sum())
        m_nodes = float(last.columns["mass"].sum())  # LIGGGHTS' node masses of the fibers left
        # ---- sheet state, ordered by fiber and node ----
        order = np.lexsort((np.rint(last.columns["f_beam[2]"]), fid))
        xs = frame_positions(last.columns)[order]
        vs = np.stack([last.columns[c][order] for c in ("vx", "vy", "vz")], axis=1)
        fid_s = fid[order]
        counts = np.array([int(np.sum(fid_s == k)) for k in present], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        gaps = yarn_distances(wrap_points(xs, period), pts, offs, rad) if len(xs) else np.zeros(0)
        fabric_top = yarns.top
        thickness = sheet_thickness(xs[:, 2], f.width_m) if len(xs) else 0.0
        above = sheet_thickness_above_fabric(scene, xs, offsets, present, fabric_top)
        area = (dom.hi_m[0] - dom.lo_m[0]) * (dom.hi_m[1] - dom.lo_m[1])

        g = h5.create_group("sheet")
        write_dataset(g, "x", xs, "m", "node positions of the fibers on the sheet (final snapshot)")
        write_dataset(g, "v", vs, "m/s", "node velocities (half-step, final snapshot)")
        write_dataset(g, "fiber_id", present.astype(np.int64), "1",
                      "fiber IDs (index into fibers.h5 /fibers) of the fibers on the sheet")
        write_dataset(g, "offsets", offsets, "1", "fiber k owns nodes offsets[k]:offsets[k+1]")
        write_dataset(g, "yarn_gap", gaps, "m",
                      "node distance to the nearest yarn centreline minus the yarn radius")
        a = h5.create_group("accounting")
        write_dataset(a, "injected_mass", m_inj, "kg", "mass of all generated fibers (fibers.h5)")
        write_dataset(a, "sheet_mass", m_sheet, "kg", "mass of the fibers on the sheet")
        write_dataset(a, "removed_mass", m_rem, "kg", "mass of the removed fibers")
        write_dataset(a, "removed_fiber_id", np.array(removed_ids, dtype=np.int64), "1",
                      "IDs of the removed fibers")
        write_dataset(a, "sheet_node_mass", m_nodes, "kg",
                      "sum of LIGGGHTS node masses left (cross-check of sheet_mass)")

        def frame_clearance(columns: Mapping[str, Any]) -> float:
            x, _, offsets = frame_fibers(columns)
            return element_clearance(wrap_chains(x, offsets, period), offsets, pts, offs, rad)

        clearances = np.array([frame_clearance(fr.columns) if len(fr.ids) else math.inf for fr in frames])
        # sections of every generated node: outer half-axes (a1 != a2: a collapsed fiber's
        # rectangle, oriented by the dumped node quaternions) and the circles' radius
        node_axes = f_radii[:, :2]
        node_r = np.max(node_axes, axis=1)

        def frame_gap(columns: Mapping[str, Any]) -> float:
            x, present, offsets = frame_fibers(columns)
            sel = np.concatenate([np.arange(f_off[k], f_off[k + 1]) for k in present])
            q = frame_quaternions(columns)
            if q is None and f.cross_section != "circular":
                raise StageError(f"{work / TRAJ_NAME}: no node quaternions (f_beam[4..7]) for the "
                                 "collapsed fibers' sections: run the lay-down again")
            return fiber_fiber_gap(x, offsets, node_r[sel], node_axes[sel], q, period)

        fiber_gaps = np.array([frame_gap(fr.columns) if len(fr.ids) else math.inf for fr in frames])
        # the report's pass-through tolerance: 5 % of the nominal radius, or of a collapsed
        # fiber's half-thickness a2
        circular = f.cross_section == "circular"
        aspect = f.thickness_m / f.width_m if f.thickness_m is not None else 0.25
        half_thin = min(outer_half_axes(f.cross_section, 0.5 * f.width_m, aspect))  # m: w or a2
        overlap_tol = 0.05 * half_thin
        overlap_of = "a radius" if circular else f"the half-thickness a2 ({half_thin * 1e6:.3g} um)"
        max_speeds = np.array([
            float(np.max(np.linalg.norm(np.stack([fr.columns[c] for c in ("vx", "vy", "vz")], 1), axis=1)))
            if len(fr.ids) else 0.0 for fr in frames])
        # (mass, centre-of-mass speed) of every fiber, per snapshot: the settle measures and the
        # sheet's growth below
        coms = [fiber_com_speeds(fr.columns) if len(fr.ids) else (np.zeros(1), np.zeros(1)) for fr in frames]
        fiber_speeds = np.array([float(np.max(v)) for _, v in coms])
        q = ld.settle_mass_fraction
        settle_speeds = np.array([mass_fraction_speed(m, v, q) for m, v in coms]) if q < 1.0 else fiber_speeds
        measure = settle_speeds if ld.settle_measure == "fiber" else max_speeds
        r = h5.create_group("run")
        r.attrs.update({
            "steps": int(steps_done), "simulated_time_s": steps_done * ld.timestep_s,
            "settled": settled, "settle_speed_m_s": v_settle, "superficial_velocity_m_s": u_s,
            "settle_checks": ld.settle_checks, "settle_measure": ld.settle_measure,
            "settle_mass_fraction": ld.settle_mass_fraction, "wall_time_s": wall, "wall_time_this_part_s": wall_part,
            "wall_time_earlier_parts_s": math.nan if wall_before is None else wall_before,
            "steps_per_check": steps_per_check,
            "removal_height_m": removal_height(scene), "fabric_top_m": fabric_top,
            "sheet_thickness_m": thickness, "sheet_thickness_above_fabric_m": above,
            "min_element_clearance_m": float(clearances.min()) if len(clearances) else math.inf,
            "grammage_kg_m2": m_sheet / area,
            "approximations": json_list(approximations(scene)),
            "fiber_contact": ("pair_style fiber/dlvo " + " ".join(
                str(v) for v in pair_options(scene, ld.fiber_contact_mode, steric_cap_m=ld.steric_cap_m))
                              if scene.contact is not None else "none"),
            "walls": ld.walls,
            "lateral_period_m": np.array(period if period is not None else (0.0, 0.0), dtype=np.float64),
            "ranks": ld.ranks,
            "resumed_from_step": -1 if resume_step is None else int(resume_step),
        })
        snap = h5.create_group("snapshots")
        write_dataset(snap, "step", np.array([fr.step for fr in frames], dtype=np.int64), "1",
                      "steps of the snapshots (every check)")
        write_dataset(snap, "min_yarn_gap", np.array([
            float(yarn_distances(wrap_points(frame_positions(fr.columns), period), pts, offs, rad).min())
            if len(fr.ids) else math.inf for fr in frames]), "m",
            "smallest node-to-yarn gap (distance to centreline - yarn radius) per snapshot")
        write_dataset(snap, "min_element_clearance", clearances, "m",
                      "smallest distance between a fiber element's centre line and a yarn "
                      "centre line minus the yarn radius, per snapshot (< 0: fiber passes "
                      "through a yarn)")
        write_dataset(snap, "min_fiber_fiber_gap", fiber_gaps, "m",
                      "smallest surface gap between elements of two different fibers (centre-line "
                      "distance minus both elements' section extents along it: circles, or the "
                      "rectangles 2 a1 x 2 a2 of collapsed fibers), per snapshot (the contact law "
                      "keeps it above about -10 nm; below minus the radius or half-thickness: a "
                      "fiber passes through another)")
        write_dataset(snap, "max_speed", max_speeds, "m/s", "largest node speed per snapshot")
        write_dataset(snap, "max_fiber_speed", fiber_speeds, "m/s",
                      "largest fiber centre-of-mass speed per snapshot")
        if q < 1.0:
            write_dataset(snap, "settle_fiber_speed", settle_speeds, "m/s",
                          f"fiber centre-of-mass speed below which {q:g} of the mass moves, per snapshot")

        # step 0: the fibers are placed at rest, not settled
        growth = np.array([float(np.sum(m[v < v_settle])) if len(fr.ids) and fr.step > 0 else 0.0
                           for fr, (m, v) in zip(frames, coms)])
        write_dataset(snap, "settled_grammage", growth / area, "kg/m^2",
                      "mass of the fibers whose centre-of-mass speed is below the settle speed, per "
                      "fabric area, per snapshot (the sheet's growth; 0 at step 0)")
        drain_lines: list[str] = []
        if two_way(scene):
            t_q, q_out = read_patch_history(work / FLUID_CASE, DRAINAGE_FO["bottom"])
            dr = h5.create_group("drainage")
            write_dataset(dr, "time", t_q, "s", "fluid time after each coupled fluid step")
            write_dataset(dr, "flow_rate", q_out, "m^3/s", "volume flow out through the bottom (through "
                          "fabric and sheet) after each fluid step")
            write_dataset(dr, "superficial_velocity", q_out / area, "m/s", "flow_rate / fabric area")
            stride = max(1, len(t_q) // 10)
            drain_lines = ["", "Drainage (two-way coupling; flow stage: "
                           f"{u_s * 1e3:.4g} mm/s) next to the sheet's growth:", "",
                           "| time (ms) | superficial velocity (mm/s) | settled grammage (g/m^2) |",
                           "|---|---|---|"]
            steps = np.array([fr.step for fr in frames]) * ld.timestep_s
            for k in range(0, len(t_q), stride):
                g_k = growth[np.searchsorted(steps, t_q[k], side="right") - 1] / area if len(steps) else 0.0
                drain_lines.append(f"| {t_q[k] * 1e3:.3f} | {q_out[k] / area * 1e3:.4g} | {g_k * 1e3:.4g} |")
        write_sheet_vtu(tmp[VTU_NAME], xs, fid_s, offsets)
        final = work / SHEET_RESTART
        if not final.is_file():
            raise StageError(f"{final}: fiberdem wrote no final restart file (see work/{LOG_NAME})")
        h5["run"].attrs["sheet_restart_sha256"] = file_hash(final)
        shutil.copyfile(final, tmp[SHEET_RESTART])
        # on the fabric's own yarns (periodic: every image of a fiber that reaches into the box)
        write_sheet_png(tmp[PNG_NAME], xs, offsets, yarns.points, yarns.offsets, yarns.radius,
                   f"{scene.name}: {len(present)} fibers on the fabric after "
                   f"{steps_done * ld.timestep_s * 1e3:.2f} ms", (dom.lo_m, dom.hi_m), period=period)
        lines = [
            f"# Lay-down: scene `{scene.name}`", "", report_origin(h5), "",
            f"- fibers injected: {n_fib} ({m_inj:.6g} kg); initial heights "
            f"{x0[:, 2].min() * 1e3:.3f}-{x0[:, 2].max() * 1e3:.3f} mm",
            f"- on the sheet: {len(present)} ({m_sheet:.6g} kg); removed below "
            f"z = {removal_height(scene) * 1e3:.3f} mm: {len(removed_ids)} ({m_rem:.6g} kg)",
            f"- mass accounting: injected - (sheet + removed) = {m_inj - m_sheet - m_rem:.3g} kg "
            f"(by fiber IDs; LIGGGHTS node masses left {m_nodes:.6g} kg)",
            f"- simulated {steps_done * ld.timestep_s * 1e3:.3f} ms in {steps_done} steps of "
            f"{ld.timestep_s:g} s; settled: "
            f"{'yes' if settled else '**NO** (max_time_s reached before the criterion was met)'} "
            f"(criterion: {'largest ' if q >= 1.0 else ''}{ld.settle_measure} speed"
            f"{' (centre of mass)' if ld.settle_measure == 'fiber' else ''}"
            f"{f' below which {q:g} of the fiber mass moves' if q < 1.0 else ''} < {v_settle:.4g} m/s"
            + (f" = {ld.settle_speed_fraction:g} x superficial velocity {u_s:.4g} m/s"
               if ld.settle_speed_fraction is not None else "")
            + f" at {ld.settle_checks} consecutive checks every {ld.check_interval_s:g} s; "
            f"at the last checks: "
            f"{', '.join(f'{v:.3g}' for v in measure[-ld.settle_checks:])} m/s; largest node "
            f"speed at the end {max_speeds[-1]:.3g} m/s)",
            f"- sheet thickness estimate (5-95 % node heights + one width): {thickness * 1e6:.1f} um;"
            f" above the fabric top (95th percentile of the fibers' upper surfaces - fabric top, at "
            f"least 0): {above * 1e6:.1f} um; grammage {m_sheet / area * 1e3:.4g} g/m^2; fabric top at "
            f"{fabric_top * 1e3:.3f} mm",
            f"- smallest node-to-yarn gap at the end: "
            f"{(gaps.min() if len(gaps) else math.inf) * 1e9:.3g} nm (>= 0: no node inside a yarn)",
            f"- no fiber passes through a yarn: smallest element-to-yarn clearance (distance "
            f"between the centre lines of a fiber element and a yarn segment minus the yarn "
            f"radius) over all {len(frames)} snapshots: {clearances.min() * 1e6:.3f} um "
            f"({'OK, >= 0' if clearances.min() >= 0 else 'VIOLATED'}; fiber radius "
            f"{0.5 * f.width_m * 1e6:.1f} um)",
            f"- no fiber passes through another: smallest surface gap between elements of two "
            f"fibers (centre-line distance minus both sections' extents along it: "
            f"{'circles' if circular else 'the rectangles 2 a1 x 2 a2 of the collapsed fibers'}) "
            f"over all snapshots: {fiber_gaps.min() * 1e9:.1f} nm "
            f"({f'OK, no overlap beyond 5 % of {overlap_of}' if fiber_gaps.min() > -overlap_tol else 'VIOLATED'})",
            *([f"- lateral boundaries: periodic in x and y with periods {period[0] * 1e3:.4g} x "
               f"{period[1] * 1e3:.4g} mm (the fabric piece, whole weave repeats; yarns tiled over "
               f"the neighbouring images; positions above are unwrapped, `/run` lateral_period_m)"]
              if period is not None else []),
            f"- fiberdem wall time: {wall:.1f} s on {ld.ranks} rank(s)"
            + ("" if resume_step is None else
               f" ({wall_part:.1f} s in this part, resumed from the restart file of step {resume_step}, "
               + (f"and {wall_before:.1f} s in the parts before, their LIGGGHTS loop times up to that step)"
                  if wall_before is not None else "the parts before it not known: this part only)")), "",
            *drain_lines, "",
            "Approximations:", "", *[f"- {a}" for a in approximations(scene)], "",
            f"Pictures: `{PNG_NAME}`; ParaView: `{VTU_NAME}`; data: `{H5_NAME}`; log: "
            f"`work/{LOG_NAME}`.",
        ]
        tmp[REPORT_NAME].write_text("\n".join(lines) + "\n")


def prepare_fluid(scene: Scene, work: Path) -> None:
    """The coupled fluid's case in ``work/fluid``: the flow stage's case with its steady solution
    as time 0, transient controls, and the exchange map onto flow.grid's grid
    (fiberform.coupling_map); decomposed for ``coupling.fluid_ranks`` > 1 (the map keeps the
    undecomposed mesh's cell numbers; fiberPimpleFoam maps them to each rank's cells through
    cellProcAddressing)."""
    ld, cp = scene.laydown, scene.coupling
    assert ld is not None and cp is not None
    flow_case = scene.output_path / "flow" / CASE_DIR
    # the fluid writes its state (binary, exact) at every restart file of the fibers
    case = prepare_coupled_case(flow_case, work / FLUID_CASE, cp.interval * ld.timestep_s,
                                restart_every(scene) // cp.interval)
    C = cell_centres(case)
    fg = read_flow_grid(scene.output_path / FLOW_H5)
    grid = ExchangeGrid(fg.origin, fg.spacing, fg.shape)
    cells, weights, target = exchange_map(grid, fg.lattice, C)  # type: ignore[arg-type]
    write_exchange_map(case / "constant" / MAP_NAME, grid, len(C), cells, weights, target)
    decompose(case, cp.fluid_ranks)


def fluid_state(work: Path, scene: Scene, step: int) -> list[Path] | None:
    """The coupled fluid's time folders of fiber step ``step`` (time step x timestep_s; one per
    fluid rank), if every rank wrote its state."""
    ld, cp = scene.laydown, scene.coupling
    assert ld is not None and cp is not None
    return coupled_state(work / FLUID_CASE, step * ld.timestep_s, 1e-6 * cp.interval * ld.timestep_s)


def resume_fluid(work: Path, scene: Scene, step: int) -> None:
    """Cut the coupled fluid back to its state at fiber step ``step`` (openfoam_case.cut_coupled_back)."""
    states = fluid_state(work, scene, step)
    assert states is not None
    cut_coupled_back(work / FLUID_CASE, states)


def restart_steps(work: Path) -> list[int]:
    """Steps of the lay-down's restart files in the working folder, ascending."""
    return liggghts_restart.restart_steps(work, RESTART_STEM)


def resume_point(work: Path, hashes: Mapping[str, str],
                 usable: Callable[[int], bool] = lambda step: True,
                 legacy: Mapping[str, str] | None = None) -> int | None:
    """The step to resume a killed lay-down from (:func:`fiberform.liggghts_restart.resume_point`;
    ``usable``: before the end step, and two_way: the fluid's state of that step exists)."""
    return liggghts_restart.resume_point(work, hashes, RESTART_STEM, TRAJ_NAME, usable, legacy)


def prepare_resume(work: Path, step: int, generated_nodes: Path | None = None) -> None:
    """Cut the snapshots and the log of the killed run back to the restart step: the resumed run
    writes the snapshot of that step again and everything after it. The removals up to the
    restart step (they are in the restart file's state) keep their log lines in EARLIER_LOG; with
    ``generated_nodes`` (the generated fibers' nodes file) a removal whose log line the killed run
    did not get out (a buffered log) is recovered from the snapshots (:func:`removals_from_dump`)."""
    dump = work / TRAJ_NAME
    text = read_text_if(dump)
    before, current = run_log_parts(work, LOG_NAME)
    # removals up to the restart step are in the restart file's state: keep their log lines
    old = before + current
    kept = [m.group(0) for m in _REMOVED.finditer(old) if int(m.group(1)) <= step]
    if generated_nodes is not None:
        kept += [f"fix fiber/remove: step {s} removed fiber(s) "
                 + " ".join(str(i + 1) for i in sorted(ids)) + " (recovered from the snapshots)"
                 for s, ids in removals_from_dump(text, dump_snapshots(text), step,
                                                  fibers_in_nodes(generated_nodes), "\n".join(kept))]
    # (checked before anything is cut: a contradiction leaves the killed run's files as they were)
    cut_back(work, step, RESTART_STEM, TRAJ_NAME, LOG_NAME, text, current)
    atomic_write_text(work / EARLIER_LOG, "".join(line + "\n" for line in kept))


def snapshot_fibers(text: str, pos: int) -> set[int]:
    """0-based indices of the fibers (column f_beam[1], 1-based) in the dump snapshot whose header
    starts at ``pos`` of the dump text ``text``."""
    fid = np.rint(dump_frame(text, pos).columns["f_beam[1]"]).astype(np.int64) - 1
    return {int(i) for i in fid}


def removals_from_dump(text: str, snapshots: list[tuple[int, int]], up_to_step: int,
                       generated: set[int], log: str) -> list[tuple[int, set[int]]]:
    """Removals of the fibers ``generated`` that the lay-down log ``log`` does not report, from
    the snapshots of a lay-down dump (``snapshots``: :func:`dump_snapshots` of ``text``) up to and
    including ``up_to_step``: (the step of the first snapshot without the fiber, fibers), in step
    order. The step is the removal step when the dump interval is the removal check interval
    (the lay-down writes both every check) and an upper bound otherwise. Raises StageError when
    the log reports a fiber removed at or before the last of those snapshots that it still holds
    (the last snapshot may predate ``up_to_step``: a resumed run killed before its first snapshot)."""
    upto = [(s, pos) for s, pos in snapshots if s <= up_to_step]
    if not upto:
        return []
    logged = removed_fibers(log)
    present = snapshot_fibers(text, upto[-1][1])
    wrong = present & removed_fibers(log, upto[-1][0])
    if wrong:
        raise StageError(f"the lay-down log reports fibers {sorted(i + 1 for i in wrong)} "
                         f"removed, but the snapshot of step {upto[-1][0]} holds them")
    lost = generated - present - logged
    out: list[tuple[int, set[int]]] = []
    for s, pos in upto:
        if not lost:
            break
        gone = lost - snapshot_fibers(text, pos)
        if gone:
            out.append((s, gone))
            lost -= gone
    return out


def removed_fibers(log: str, up_to_step: int | None = None) -> set[int]:
    """0-based indices of the fibers that fix fiber/remove reports removed in a lay-down log (at
    steps up to and including ``up_to_step`` when given)."""
    return {int(i) - 1 for m in _REMOVED.finditer(log)
            if up_to_step is None or int(m.group(1)) <= up_to_step for i in m.group(2).split()}


def write_nodes_left(nodes: Path, dst: Path, log: str, up_to_step: int | None = None) -> None:
    """``dst``: the fibers of the nodes file ``nodes`` less those the lay-down log reports removed
    (up to and including ``up_to_step`` when given): the nodes file that goes with a restart file,
    since fix fiber/beam wants every fiber it lists to be in the restart file."""
    write_nodes_subset(nodes, dst, sorted(fibers_in_nodes(nodes) - removed_fibers(log, up_to_step)))


def nodes_left(work: Path, nodes: Path) -> None:
    """The working folder's nodes file of a resumed run: the fibers of ``nodes`` (the generated
    fibers) less those removed up to the restart step (the log lines prepare_resume kept)."""
    write_nodes_left(nodes, work / NODES_NAME, read_text_if(work / EARLIER_LOG))


def json_list(items: list[str]) -> str:
    return json.dumps(items)


def approximations(scene: Scene) -> list[str]:
    ld = scene.laydown
    assert ld is not None
    out = [
        (f"two-way coupling (fiberPimpleFoam, from the flow stage's steady solution): exchange every "
         f"{scene.coupling.interval} steps on flow.grid's grid, the fibers see the fluid of the "
         "last exchange (held over the interval), the fluid gets the interval-mean drag reaction "
         "(explicit source; not the fibers' volume fraction; docs/coupling/formulation.md)"
         if two_way(scene) and scene.coupling is not None else
         "one-way coupling: the flow through the bare fabric is frozen (fibers do not change it)"),
        (f"fix fiber/beam integrator implicit (generalized-alpha, rho_inf {ld.rho_inf:g}, Newton "
         f"tolerance {ld.newton_tolerance:g}): external loads held over each step (first order), "
         "drag linearly implicit" if ld.beam_integrator == "implicit" else
         "fix fiber/beam integrator explicit (velocity Verlet); drag evaluated with the half-step "
         "velocity"),
        f"fix fiber/beam speed options: inertia_scale {ld.inertia_scale:g}, stiffness_scale "
        f"{ld.stiffness_scale:g}" + (" (EA and GA scaled: fibers are extensible/shear-soft)"
                                     if ld.stiffness_scale != 1.0 else "") +
        (" (rotary inertia scaled)" if ld.inertia_scale != 1.0 else "") +
        (" (none: real stiffness and inertia)" if ld.inertia_scale == 1.0 and
         ld.stiffness_scale == 1.0 else ""),
        "drag per element at its centre",
        "yarn contact per fiber element (closest points of the element's and the yarn segment's "
        "centre lines, force split to the two nodes by the lever rule), "
        + ("no side planes (periodic x and y)" if ld.walls == "periodic" else
           "side-plane contact per " + ("node" if ld.yarn_contact_mode == "newton"
                                        else "contact point of the elements (fix wall/fiber/dlvo)"))
        + ("; sections: circles, or the rectangles 2 a1 x 2 a2 of collapsed fibers at their extent "
           "along the contact normal; " if ld.yarn_contact_mode == "newton" else "; radius max(a1, a2); ")
        + ("the law acts inside each fiber's implicit Newton solve at the end-of-step state "
           "(yarn_contact newton; steric servo S1 in PD form: every fiber-yarn collision sticks)"
           if ld.yarn_contact_mode == "newton" else
           "the contact point's motion sub-integrated over the step with the nodes' other forces "
           "held constant ("
           + ("CVODE" if ld.contact_integrator == "cvode" else f"{ld.contact_substeps} sub-steps")
           + ")")
        + f", terms {','.join(ld.terms)}; Coulomb friction {ld.friction_coefficient:g} on yarns "
        "and planes (" + ("regularised stick/slip inside the Newton solve"
                          if ld.yarn_contact_mode == "newton" else
                          "velocity-level stick/slip, physics/friction.h")
        + "; not part of the thesis' law)",
        "fibers are removed whole when any node passes the removal height",
        (f"steric servo S1 saturated at h_cap = {ld.steric_cap_m * 1e6:.3g} um in every contact "
         "(laydown.steric_cap_m; the thesis' S1 is not saturated)" if ld.steric_cap_m is not None else
         "steric servo S1 saturated at the law's h_cap = 2 nm: one contact carries at most "
         "2 mu h_cap / t_R^2 (about 1e-5 N for a fiber node; the thesis' S1 is not saturated; "
         "laydown.steric_cap_m)"),
    ]
    c = scene.contact
    if c is None:
        out.append("no fiber-fiber contact (fibers may overlap in the sheet)")
    else:
        newton = ld.fiber_contact_mode == "newton"
        out.append("fiber-fiber contact: pair_style fiber/dlvo " +
                   " ".join(str(v) for v in pair_options(scene, ld.fiber_contact_mode,
                                                         steric_cap_m=ld.steric_cap_m)) +
                   (" (fibers in contact solved together, law at the closest points of element "
                    "centre lines; sections are circles, or the thesis' rectangles 2 a1 x 2 a2 of "
                    "collapsed fibers (contact points moved along the line between the centre "
                    "lines to the surfaces); no self-contact; "
                    if newton else " (points 'auto' unless given; ") +
                   "steric parameters: the style's defaults, docs/models/contact.md; " +
                   (f"Coulomb friction {ld.fiber_friction_coefficient:g} between fibers, "
                    "regularised inside the Newton solve: not part of the thesis' law)"
                    if ld.fiber_friction_coefficient > 0.0 else
                    "frictionless, as the thesis' law)"))
    if ld.walls == "periodic":
        out.append("lateral boundaries periodic in x and y (the fabric piece of whole weave repeats; "
                   "yarns tiled over the neighbouring images); the frozen flow is the flow stage's "
                   "(symmetry sides), sampled at the element centre mapped into the box, so it is "
                   "not periodic at the box sides")
    if ld.walls == "wall_fiber_dlvo":
        out.append("side walls: fix wall/fiber/dlvo (contact developers' fix)")
    elif ld.walls == "wall_gran":
        out.append("side walls: stock LIGGGHTS fix wall/gran, model hertz, tangential no_history, "
                   "E 1e7 Pa, nu 0.3, restitution 0.5, friction 0 (comparison option)")
    return out
