# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``press``: the laid-down sheet is pressed by a rigid horizontal plate (Kettil 2016 sec.
3.5, and beyond it: the plate force is computed, so the press can follow a pressure).

fiberdem continues from the lay-down's final state (``laydown/sheet.restart``: atoms and per-atom
states of fix fiber/beam) with the water at rest (fix fiber/drag with zero flow: drag, gravity
and buoyancy stay), the same yarn and side-plane contacts and fiber-fiber pair style as the
lay-down, and a plate: fix wall/fiber/dlvo with the plane's normal pointing down, under the
laydown section's contact terms and integrator.

- ``press.mode: velocity`` (thesis): the plate moves down at ``plate_speed_m_s`` until it is
  ``target_thickness_m`` above the fabric top, then rests for ``hold_time_s``.
- ``press.mode: pressure``: the fix's servo (docs/models/press.md) drives the plate so that the
  contact pressure (plate force / domain cross-section) follows a ramp to ``target_pressure_Pa``,
  a hold, an unloading and a release at zero pressure. The plate first approaches at
  ``plate_speed_m_s`` until the plate pressure reaches ``CONTACT_SHARE`` x the target (the sheet's
  body carries it, not a lone fiber standing up) or the plate reaches the fabric top; the
  schedule's clock starts there.

At every ``output_interval_s``: a snapshot of the nodes, the plate's position and force, the
overlap guard (the run ends when an element overlaps another fiber, a yarn or the plate by more
than ``overlap_limit`` x the thinner fiber's thickness; the stage then fails with exit status 1).

fiberdem writes restart files ``press.<step>.restart`` every ``restart_interval_s`` (whole output
intervals); ``fiberform press SCENE --resume`` continues a killed press from the last complete one
(fiberform.liggghts_restart), identical to the bit to an uninterrupted run: both define the plate
afresh at every restart step, at PressPlan.plate_height (velocity mode, and the pressure mode's
approach; the servo's state is not in the restart file, so a pressure-mode press resumes from a
restart file before the servo took over, else it starts over).

Products in ``<output_dir>/press/``: ``press.h5`` (curve, profiles, final sheet, provenance),
``sheet.vtu``, ``press.png``, ``curve.png``, ``report.md``, ``sheet.restart`` (the pressed state).
Page: docs/stages/press.md.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Callable, Mapping
from functools import cached_property
from pathlib import Path

import h5py
import numpy as np

from ..errors import ConfigError, SceneError, StageError
from ..fiber_io import NODES_NAME, fiber_preamble, laydown_beam_options, write_nodes_subset
from ..fiber_sheet import (
    YARNS_FIX, Array, contact_commands, contact_integrator_words, contact_yarns, element_clearance,
    fiber_fiber_gap, frame_fibers, frame_quaternions, lateral_period, law_words, node_dump_columns, node_extents,
    product_thickness_above_fabric, sheet_thickness, sheet_thickness_above_fabric,
    solid_fraction_profile, static_force_refs, wrap_chains, write_sheet_png,
    write_sheet_vtu, write_yarns,
)
from ..inputs import (
    LiggghtsInput, Token, file_token, fix_affine, fix_ref, fix_sum, ident_list, jump_if_at_least,
    print_values, step_file_token, var_affine, var_distance, var_ref, var_value,
)
from ..liggghts_log import log_up_to_step, read_dump, thermo_rows
from ..liggghts_restart import (
    EARLIER_LOG, RESTART_EXT, cut_back, earlier_wall, prepared_step, record_prepared,
    restart_interval_steps, restart_name, restart_steps, resume_point, run_log, run_log_parts, start_over,
)
from ..products import (
    FABRIC_H5, FIBERS_H5, FIBERS_NODES, LAYDOWN_H5, LAYDOWN_RESTART, Yarns, read_fiber_outer_axes,
    read_sheet, read_yarns,
)
from ..provenance import atomic_write_text, file_hash, report_origin, text_hash, write_dataset
from ..runner import liggghts_progress
from ..scene import FluidSection, PressSection, Scene
from ._stage import Program, Stage, StageContext

__all__ = ["Press", "PressPlan", "build_input", "plan"]

H5_NAME, VTU_NAME, PNG_NAME, CURVE_NAME = "press.h5", "sheet.vtu", "press.png", "curve.png"
REPORT_NAME, RESTART_NAME = "report.md", "sheet.restart"
INPUT_NAME, LOG_NAME, TRAJ_NAME, YARNS_NAME = "in.press", "log.fiberdem", "traj.dump", "yarns.txt"
START_NAME = "laydown.restart"
RESTART_STEM = "press"  # restart files press.<step>.restart
END_LABEL, GUARD_MARKER = "press_end", "FIBERFORM_OVERLAP"
#: pressure mode: the end of the approach (label), the log lines of its end (the contact pressure
#: reached) and of the servo's start (step, plate height)
SERVO_LABEL, CONTACT_MARKER, SERVO_MARKER = "press_servo", "FIBERFORM_CONTACT", "FIBERFORM_SERVO_START"
#: pressure mode: the approach ends when the plate pressure reaches this share of the target
CONTACT_SHARE = 0.01
#: the pressure mode's method, in the input hashes of pressure-mode presses only (velocity-mode
#: products stay valid when it changes): 2 = the approach until the contact pressure, then the
#: servo (1: the servo's clock started at the plate's first touch of any fiber, so on a sheet with a
#: fiber standing up the schedule ran out before the plate reached the sheet)
PRESSURE_METHOD = 2
#: the solid-fraction thickness: the height range where the profile exceeds this share of its maximum
PHI_SHARE = 0.1
#: thermo columns (the order of thermo_style in build_input)
COLUMNS = ("step", "atoms", "fx", "fy", "fz", "disp", "speed", "p_servo", "p_target", "t_contact",
           "h_plate", "h_yarn", "h_pair", "at_stop", "yarn_fx", "yarn_fy", "yarn_fz")


class PressPlan:
    """The numbers of one press run, from the scene and the lay-down's sheet."""

    def __init__(self, scene: Scene, sheet_top: float, fabric_top: float, t_min: float,
                 start_overlap: tuple[float, float] | Callable[[], tuple[float, float]] = (0.0, 0.0)
                 ) -> None:
        pr, ld, dom = scene.press, scene.laydown, scene.domain
        assert pr is not None and ld is not None and dom is not None
        self.dt = pr.timestep_s if pr.timestep_s is not None else ld.timestep_s
        self.every = max(1, round(pr.output_interval_s / self.dt))
        # steps between restart files (whole output intervals); 0: none
        self.restart_every = restart_interval_steps(pr.restart_interval_s, pr.output_interval_s, self.every)
        self.z0 = sheet_top + pr.plate_start_gap_m
        self.fabric_top = fabric_top
        self.area = (dom.hi_m[0] - dom.lo_m[0]) * (dom.hi_m[1] - dom.lo_m[1])
        self.centre = (0.5 * (dom.lo_m[0] + dom.hi_m[0]), 0.5 * (dom.lo_m[1] + dom.hi_m[1]))
        self.t_min = t_min
        # the overlaps the lay-down left (start_overlaps), or how to measure them when first asked
        self._start_overlap = start_overlap
        self.guard = pr.overlap_limit * t_min
        if pr.mode == "velocity":
            assert pr.target_thickness_m is not None
            travel = self.z0 - (fabric_top + pr.target_thickness_m)
            if travel <= 0.0:
                raise SceneError("press", [
                    f"press.target_thickness_m: {pr.target_thickness_m:g} m is not below the "
                    f"laid-down sheet: the plate starts {(self.z0 - fabric_top):.4g} m above the "
                    f"fabric top (sheet top {sheet_top:.6g} m + plate_start_gap_m); allowed: "
                    f"0 < target_thickness_m < {(self.z0 - fabric_top):.4g}"])
            # whole outputs: the plate stops exactly at the target after a whole number of
            # output intervals, at plate_speed_m_s or slightly slower
            self.move_steps = self.every * math.ceil(travel / (pr.plate_speed_m_s * self.dt) / self.every)
            self.speed = travel / (self.move_steps * self.dt)
            self.z_end = fabric_top + pr.target_thickness_m
            self.hold_steps = self.every * math.ceil(round(pr.hold_time_s / self.dt) / self.every)
            self.schedule: list[tuple[float, float]] = []
            self.approach_steps = 0
            self.contact_pressure = math.nan
            total = self.move_steps + self.hold_steps
        else:
            assert pr.target_pressure_Pa is not None
            p, ramp = pr.target_pressure_Pa, pr.target_pressure_Pa / pr.rate
            self.schedule = [(0.0, 0.0), (ramp, p), (ramp + pr.hold_time_s, p),
                             (2 * ramp + pr.hold_time_s, 0.0)]
            # the approach: at plate_speed_m_s until the plate pressure reaches the contact
            # pressure (checked at every output), at most until the plate reaches the fabric top
            self.contact_pressure = CONTACT_SHARE * p
            approach = (self.z0 - fabric_top) / pr.plate_speed_m_s
            self.approach_steps = self.every * math.ceil(approach / self.dt / self.every)
            # then the servo's schedule and the release (move_steps: the servo's part)
            t_servo = 2 * ramp + pr.hold_time_s + pr.release_time_s
            self.move_steps = self.every * math.ceil(t_servo / self.dt / self.every)
            self.speed = pr.plate_speed_m_s
            self.hold_steps = 0
            self.z_end = math.nan
            total = self.approach_steps + self.move_steps
        self.total_steps = total
        self.mode = pr.mode
        if total > 10**8:
            raise SceneError("press", ["press: more than 1e8 steps (timestep_s too small for the "
                                       "press's duration)"])

    def plate_height(self, step: int) -> float:
        """Where the uninterrupted press has its plate at ``step`` (m) of the velocity mode, or of
        the pressure mode's approach (the plate never passes the fabric top; in pressure mode the
        servo takes over at step approach_steps at the latest)."""
        if self.mode == "velocity":
            return self.z0 - self.speed * step * self.dt if step <= self.move_steps else self.z_end
        assert step <= self.approach_steps, (step, self.approach_steps)
        return max(self.fabric_top, self.z0 - self.speed * step * self.dt)  # speed: the approach's

    @cached_property
    def start_overlaps(self) -> tuple[float, float]:
        """The overlaps the lay-down left (m, >= 0): fiber-fiber (averaged contact lets fibers pass
        through each other) and fiber-yarn; measured on first use (:func:`plan`: the yarn part
        visits every element, about a second for a case-C sheet), so the stage's scene check and
        progress do not pay for it."""
        s = self._start_overlap
        return s() if callable(s) else s

    @property
    def start_overlap_fiber(self) -> float:
        return self.start_overlaps[0]

    @property
    def start_overlap_yarn(self) -> float:
        return self.start_overlaps[1]

    # the guard ends the run when the press adds more than overlap_limit x the thinner fiber's
    # thickness to either overlap
    @property
    def guard_fiber(self) -> float:
        return self.start_overlap_fiber + self.guard

    @property
    def guard_yarn(self) -> float:
        return self.start_overlap_yarn + self.guard


def plan(scene: Scene, root: Path) -> PressPlan:
    """The press plan of a scene whose lay-down products are under ``root`` (the output folder)."""
    sheet = read_sheet(root / LAYDOWN_H5)
    if len(sheet.x) == 0:
        raise StageError(f"{root / LAYDOWN_H5}: no fiber on the sheet: nothing to press")
    axes = read_fiber_outer_axes(root / FIBERS_H5, sheet.fiber_id)
    r_node = np.max(axes, axis=1)
    t_min = float(2.0 * np.min(axes))  # the thinner fiber's thickness
    yarns = read_yarns(root / FABRIC_H5)
    # the lay-down's own overlaps (m, >= 0): fiber-fiber from the product, fiber-yarn element by
    # element, each element's centre-line clearance less its own fiber's radius (a collapsed
    # fiber reaches a yarn at least by its half-thickness: the thinner half-axis, a lower bound of
    # its rectangle's extent, so the guard is not widened by a1 - a2). (Before session 28 the
    # largest fiber radius was taken off the smallest clearance of any element: 0.69 x thickness
    # for the S6 sheet, whose elements reach at most 0.076 x thickness into a yarn.)
    def start() -> tuple[float, float]:
        gap_ff = sheet.min_fiber_fiber_gap
        period = lateral_period(scene)
        checked = contact_yarns(yarns, period)
        surface = element_clearance(wrap_chains(sheet.x, sheet.offsets, period), sheet.offsets, checked.points,
                                    checked.offsets, checked.radius, np.min(axes, axis=1))
        return (max(0.0, -gap_ff) if math.isfinite(gap_ff) else 0.0,
                max(0.0, -surface) if math.isfinite(surface) else 0.0)

    return PressPlan(scene, float(np.max(sheet.x[:, 2] + r_node)), yarns.top, t_min, start)


def steric_cap(scene: Scene) -> float | None:
    """The steric servo's saturation h_cap of the press's contacts (m): press.steric_cap_m, else
    the lay-down's laydown.steric_cap_m (the press goes on with the sheet's law), else None (the
    law's 2 nm)."""
    pr, ld = scene.press, scene.laydown
    assert pr is not None and ld is not None
    return pr.steric_cap_m if pr.steric_cap_m is not None else ld.steric_cap_m


def build_input(scene: Scene, p: PressPlan, resume_step: int | None = None) -> str:
    """The press's LIGGGHTS input (files in the working folder: laydown.restart, fibers.nodes,
    yarns.txt). Every field of the press section acts through here or through PressPlan.
    ``resume_step``: continue a killed press from its restart file of that step (a whole number of
    output intervals; pressure mode: before the servo took over), the plate where the
    uninterrupted run had it (:meth:`PressPlan.plate_height`)."""
    k0 = 0 if resume_step is None else int(resume_step)  # the step the run starts from
    if k0 % p.every or not 0 <= k0 < p.total_steps or (p.mode == "pressure" and k0 >= p.approach_steps):
        raise StageError(f"press: cannot resume from step {k0} (whole output intervals of {p.every} "
                         f"steps before the end, {p.total_steps}; pressure mode: before the servo, "
                         f"{p.approach_steps})")
    f, ld, pr = scene.fibers, scene.laydown, scene.press
    assert f is not None and ld is not None and pr is not None
    fl = scene.fluid or FluidSection()
    s = LiggghtsInput()
    s.comment("Generated by fiberform stage press (docs/stages/press.md).")
    fiber_preamble(s, f, scene.contact is not None,
                   *laydown_beam_options(ld),
                   restart=file_token(START_NAME if resume_step is None else restart_name(RESTART_STEM, k0)),
                   flat_decomposition=True)
    # quiescent water (thesis sec. 3.5): drag against water at rest, gravity and buoyancy
    s.command("fix", "drag", "all", "fiber/drag", "flow", "uniform", 0.0, 0.0, 0.0,
              "fluid_density", fl.density_kg_m3, "viscosity", fl.viscosity_Pa_s,
              "gravity", *fl.gravity_m_s2)
    contact_commands(s, scene, YARNS_NAME, steric_cap_m=steric_cap(scene))
    s.command("timestep", p.dt)
    pair = scene.contact is not None and scene.contact.model == "fiber_dlvo"
    s.command("variable", "ovl_yarn", "equal", fix_ref(YARNS_FIX, 3, negate=True))
    # the yarns' (and fiber_yarns side planes') force on the fibers, x y z (N)
    for k, axis in enumerate("xyz"):
        s.command("variable", f"static_f{axis}", "equal",
                  fix_sum([(f, i + k) for f, i in static_force_refs(scene)]))
    s.command("variable", "ovl_plate", "equal", fix_ref("plate", 6, negate=True))
    if pair:
        s.command("variable", "ovl_pair", "equal", fix_ref("FIBER_DLVO_STEP", 6, negate=True))
    # collapsed fibers: also the node quaternions (their sections' orientation, the overlaps)
    # periodic x/y (laydown.walls periodic; boundary p p f from the restart): unwrapped positions
    columns, dump_fmt = node_dump_columns(f, lateral_period(scene) is not None)
    s.command("dump", "traj", "all", "custom", p.every, file_token(TRAJ_NAME), *columns)
    s.command("dump_modify", "traj", "sort", "id", "format", dump_fmt)
    if resume_step is not None:
        # the snapshots before the restart are kept in traj.dump (the stage cut it there)
        s.command("dump_modify", "traj", "append", "yes")
    s.command("thermo_modify", "lost", "ignore", "flush", "yes")  # flush: the log follows the run
    if p.restart_every:
        s.command("restart", p.restart_every, step_file_token(RESTART_STEM, RESTART_EXT))
    # the plate acts as the yarns do: inside the fibers' Newton solves (newton) or sub-integrated
    plate_words: list[object] = ["terms", ident_list(ld.terms), *law_words(scene, steric_cap_m=steric_cap(scene))] + (
        ["implicit_force", "newton"] if ld.yarn_contact_mode == "newton"
        else contact_integrator_words(ld))
    cx, cy = p.centre
    # the thermo's: the plate's displacement down since the press's start (m; its 8 printed digits
    # resolve the travel, where the height's would not), from plate_z (each plate fix defines it)
    s.command("variable", "press_disp", "equal", var_affine("plate_z", -1.0, p.z0))

    def plate(z: float | Token, *motion: object, stop: float | Token | None = None) -> None:
        # stop: the plate never passes the fabric top (it would rest on the yarn knuckles); a z
        # given as a variable's value needs its stop given alike
        if stop is None:
            assert isinstance(z, float)
            stop = max(0.0, z - p.fabric_top)
        s.command("fix", "plate", "all", "wall/fiber/dlvo", "plane", cx, cy, z, 0.0, 0.0, -1.0,
                  *motion, "stop", stop, *plate_words)
        # the plate's height (m): where this fix started less its displacement down (f_plate[10])
        s.command("variable", "plate_z", "equal", fix_affine("plate", 10, -1.0, z))

    def thermo() -> None:
        s.command("thermo_style", "custom", "step", "atoms",
                  *(fix_ref("plate", k) for k in (7, 8, 9)), var_ref("press_disp"),
                  *(fix_ref("plate", k) for k in (11, 12, 13, 14, 6)),
                  fix_ref(YARNS_FIX, 3), fix_ref("FIBER_DLVO_STEP", 6) if pair else fix_ref("plate", 6),
                  fix_ref("plate", 15), *(var_ref(f"static_f{axis}") for axis in "xyz"))
        s.command("thermo", p.every)

    started: list[bool] = [] if resume_step is None else [True]  # a resumed press keeps its steps

    def chunks(steps: int, first: bool, leave: tuple[tuple[str, float, str, str], ...] = (),
               start: int = 0, renew: Callable[[int], None] | None = None) -> None:
        # leave: (variable, threshold, label, marker): also leave for LABEL when VARIABLE >= threshold;
        # start: the press step the chunks begin at; renew(step): define the plate again at a
        # restart step, where a resumed run defines it afresh (the plate's height is then the
        # stage's number in both, not the fix's sum of steps: they go on identical to the bit)
        done = 0
        full = first
        while done < steps:
            n = min(p.every, steps - done)
            if full:
                if not started:
                    # outputs at whole output intervals from the press's start (LIGGGHTS wants it
                    # right before a run after read_restart)
                    s.command("reset_timestep", 0)
                    started.append(True)
                s.command("run", n)  # (with setup: a fix defined since the last run)
                full = False
            else:
                s.command("run", n, "pre", "no", "post", "no")
            done += n
            guards = [("ovl_yarn", p.guard_yarn), ("ovl_plate", p.guard)]
            if pair:
                guards.append(("ovl_pair", p.guard_fiber))
            for var, bound in guards:
                s.command("if", *jump_if_at_least(var, bound, END_LABEL, GUARD_MARKER))
            for var, bound, label, marker in leave:
                s.command("if", *jump_if_at_least(var, bound, label, marker))
            if renew is not None and p.restart_every and (start + done) % p.restart_every == 0 and done < steps:
                s.command("unfix", "plate")
                renew(start + done)
                thermo()
                full = True

    if pr.mode == "velocity":
        def moving(step: int) -> None:
            plate(p.plate_height(step), "velocity", 0.0, 0.0, -p.speed)

        def holding(step: int) -> None:
            plate(p.z_end)

        if k0 < p.move_steps:
            moving(k0)
            thermo()
            chunks(p.move_steps - k0, True, start=k0, renew=moving)
        if p.hold_steps:
            if k0 < p.move_steps:
                s.command("unfix", "plate")
            holding(max(k0, p.move_steps))
            thermo()
            chunks(p.hold_steps - max(0, k0 - p.move_steps), True, start=max(k0, p.move_steps), renew=holding)
    else:
        assert pr.target_pressure_Pa is not None
        sched: list[object] = [len(p.schedule)]
        for t, pv in p.schedule:
            sched += [t, pv]
        # the approach: the plate moves down at the speed limit until the sheet carries the
        # contact pressure (f_plate[9]: the force on the fibers along z, < 0 when pressed)
        s.command("variable", "p_plate", "equal", fix_affine("plate", 9, -1.0 / p.area, 0.0))
        def approaching(step: int) -> None:
            plate(p.plate_height(step), "velocity", 0.0, 0.0, -pr.plate_speed_m_s)

        approaching(k0)
        thermo()
        chunks(p.approach_steps - k0, True, (("p_plate", p.contact_pressure, SERVO_LABEL, CONTACT_MARKER),),
               start=k0, renew=approaching)
        s.label(SERVO_LABEL)
        # the servo takes the plate where the approach left it (its clock starts at its first
        # contact, at once when the contact pressure was reached); abs(): the approach's plate
        # never passes the fabric top, so the remaining travel is >= 0 up to round-off
        s.command("variable", "servo_z", "equal", var_value("plate_z"))
        s.command("variable", "servo_stop", "equal", var_distance("servo_z", p.fabric_top))
        s.command("variable", "servo_step", "equal", "step")
        s.command("print", print_values(SERVO_MARKER, "servo_step", "servo_z"))
        s.command("unfix", "plate")
        plate(var_value("servo_z"), "servo", p.area, pr.plate_speed_m_s, pr.band, *sched,
              stop=var_value("servo_stop"))
        thermo()
        chunks(p.move_steps, True)
    s.label(END_LABEL)
    s.command("write_restart", file_token(RESTART_NAME))
    return s.render()


def has_marker(log: str, marker: str) -> bool:
    """True if a line of the log is the marker (a ``print`` of jump_if_at_least)."""
    return any(line.strip() == marker for line in log.splitlines())


def servo_start(log: str) -> tuple[int, float] | None:
    """Pressure mode: the step and the plate height (m) where the servo took over from the
    approach (the ``FIBERFORM_SERVO_START`` line of the log), or None (the run ended before it)."""
    for line in log.splitlines():
        words = line.split()
        if len(words) == 3 and words[0] == SERVO_MARKER:
            return int(float(words[1])), float(words[2])
    return None


def phases(mode: str, t_contact: Array, schedule: list[tuple[float, float]]) -> list[str]:
    """The phase of each curve point: approach, loading, hold, unloading, release (pressure mode;
    from the time since the first contact) or moving, hold (velocity mode, from the speed)."""
    out = []
    for t in t_contact:
        if mode == "velocity":
            out.append("moving" if t > 0 else "hold")  # t > 0: the plate's first fix
        elif t < 0:
            out.append("approach")
        elif t <= schedule[1][0]:
            out.append("loading")
        elif t <= schedule[2][0]:
            out.append("hold")
        elif t <= schedule[3][0]:
            out.append("unloading")
        else:
            out.append("release")
    return out


class Press(Stage):
    """Pressing of the laid-down sheet by a rigid plate."""

    name = "press"
    summary = "press the laid-down sheet with a rigid plate (velocity- or pressure-controlled)"
    folder = "press"
    requires = ("domain", "fibers", "fabric", "laydown", "press")
    uses = ("seed", "domain", "fibers", "fiber_generation", "fabric", "flow", "fluid", "laydown",
            "contact", "press")
    products = (H5_NAME, VTU_NAME, PNG_NAME, CURVE_NAME, REPORT_NAME, RESTART_NAME)
    binaries = ("fiberdem",)
    code_version = 2  # 2: fiber-yarn overlaps element by element (session 28)
    splits = True
    restart_stem = RESTART_STEM

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        hashes = super().input_hashes(ctx)
        if ctx.scene.press is not None and ctx.scene.press.mode == "pressure":
            hashes["pressure_method"] = text_hash(f"press-pressure:{PRESSURE_METHOD}")
        return hashes

    def metrics(self, ctx: StageContext) -> dict[str, float]:
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            c, a = h5["curve"], h5["run"].attrs
            return {"press_plate_gap_m": float(c["plate_z"][-1] - a["fabric_top_z_m"]),
                    "press_max_pressure_Pa": float(np.nanmax(c["pressure"][...])),
                    "pressed_span_thickness_m": float(c["thickness_span"][-1]),
                    "press_stopped_by_guard": float(a.get("stopped_by_guard", 0)),
                    "pressed_thickness_above_fabric_m": product_thickness_above_fabric(
                        ctx.scene, self.product_paths(ctx)[0], float(a["fabric_top_z_m"]))}

    def results(self, ctx: StageContext) -> list[str]:
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            c, a = h5["curve"], h5["run"].attrs
            span = c["thickness_span"][...]
            p = c["pressure"][...]
            above = product_thickness_above_fabric(ctx.scene, self.product_paths(ctx)[0], a["fabric_top_z_m"])
            line = (f"press ({a['mode']}): plate at {(c['plate_z'][-1] - a['fabric_top_z_m']) * 1e6:.1f} um "
                    f"above the fabric top, largest pressure {np.nanmax(p):.3g} Pa; span thickness "
                    f"{span[0] * 1e6:.1f} -> {span[-1] * 1e6:.1f} um; pressed sheet {above * 1e6:.1f} um above "
                    "the fabric top (95th percentile of the fibers' upper surfaces)")
            if a.get("stopped_by_guard", 0):
                line += "; stopped by the overlap guard before its target"
            if "hold_pressure_mean_Pa" in a:
                line += (f"; hold {a['hold_pressure_mean_Pa']:.4g} Pa (largest deviation "
                         f"{a['hold_pressure_max_dev'] * 100:.2f} %)")
            return [line]

    def needs(self, ctx: StageContext) -> dict[str, Path]:
        root = ctx.scene.output_path
        return {"laydown_h5": root / LAYDOWN_H5, "laydown_restart": root / LAYDOWN_RESTART,
                "fibers_h5": root / FIBERS_H5, "fibers_nodes": root / FIBERS_NODES,
                "fabric_h5": root / FABRIC_H5}

    def check_scene(self, scene: Scene) -> list[str]:
        problems = super().check_scene(scene)
        if problems:
            return problems
        pr, ld = scene.press, scene.laydown
        assert pr is not None and ld is not None
        if pr.ranks > 1 and ld.yarn_contact_mode != "newton":
            problems.append("press.ranks: more than one rank needs laydown.yarn_contact newton")
        dt = pr.timestep_s if pr.timestep_s is not None else ld.timestep_s
        if dt > pr.output_interval_s:
            problems.append(f"press.output_interval_s: must be at least the time step ({dt:g} s)")
        return problems

    def preflight(self, ctx: StageContext) -> None:
        for key, path in self.needs(ctx).items():
            if not path.is_file():
                raise ConfigError(f"press: {path} missing ({key}): run the lay-down first "
                                  "(`fiberform laydown SCENE`, or `fiberform run SCENE`)")
        if not (ctx.build_dir / "bin" / "fiberdem").is_file():
            raise StageError(f"{ctx.build_dir / 'bin' / 'fiberdem'} not found: build first")
        plan(ctx.scene, ctx.scene.output_path)  # a target thickness above the sheet: exit 2 now

    def prepare(self, ctx: StageContext, hashes: Mapping[str, str]) -> None:
        """The working folder: fresh (the lay-down's final restart file, the nodes of the fibers
        left on the sheet, yarns.txt) or, with ``--resume``, the killed press's cut back to its last
        complete restart file (the log up to there kept in EARLIER_LOG); the input script; the
        start step in PREPARED_STEP."""
        scene = ctx.scene
        up = self.needs(ctx)
        p = plan(scene, scene.output_path)
        work = self.stage_dir(ctx) / "work"
        resume_step = None
        if ctx.options.get("resume") and work.is_dir():
            before, current = run_log_parts(work, LOG_NAME)
            log = before + current
            servo = servo_start(log)
            # pressure mode: the servo's state is not in the restart files; before it took over,
            # the approach is repeated exactly
            resume_step = resume_point(work, hashes, RESTART_STEM, TRAJ_NAME,
                                       lambda step: p.mode == "velocity" or step < (
                                           servo[0] if servo is not None else p.approach_steps))
            if resume_step is not None:
                cut_back(work, resume_step, RESTART_STEM, TRAJ_NAME, LOG_NAME, log_text=current)
                atomic_write_text(work / EARLIER_LOG, log_up_to_step(log, resume_step))
        if resume_step is None:
            start_over(work, RESTART_STEM, hashes, "fiberform press", bool(ctx.options.get("resume")),
                       "no snapshot after it; pressure mode: before the servo took over")
            shutil.copyfile(up["laydown_restart"], work / START_NAME)
            # the fibers left on the sheet (the lay-down may have removed some)
            write_nodes_subset(up["fibers_nodes"], work / NODES_NAME,
                               read_sheet(up["laydown_h5"]).fiber_id.tolist())
        write_yarns(work / YARNS_NAME, up["fabric_h5"], lateral_period(scene))
        (work / INPUT_NAME).write_text(build_input(scene, p, resume_step))
        record_prepared(work, resume_step)

    def resume_info(self, ctx: StageContext) -> str:
        steps = restart_steps(self.stage_dir(ctx) / "work", RESTART_STEM)
        if not steps:
            return ""
        try:
            # (pressure mode: the approach may end before its largest travel)
            total = f" of at most {plan(ctx.scene, ctx.scene.output_path).total_steps}"
        except (OSError, KeyError, StageError, SceneError):  # lay-down products gone or changed
            total = ""
        return f"restart files to step {steps[-1]}{total}"

    def earlier_elapsed(self, ctx: StageContext) -> float:
        """A resumed press: fiberdem's time in the parts before it, up to the restart step it
        continued from (0 when not known)."""
        return earlier_wall(self.stage_dir(ctx) / "work") or 0.0

    def programs(self, ctx: StageContext) -> list[Program]:
        pr = ctx.scene.press
        assert pr is not None
        work = (self.stage_dir(ctx) / "work").resolve()
        p = plan(ctx.scene, ctx.scene.output_path) if self.needs(ctx)["laydown_h5"].is_file() else None
        return [Program((str((ctx.build_dir / "bin" / "fiberdem").resolve()), "-in", INPUT_NAME, "-log", "none"),
                        pr.ranks, work, work / LOG_NAME, liggghts_progress(p.total_steps) if p else None)]

    def collect(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str],
                wall_times: Mapping[str, float]) -> None:
        scene = ctx.scene
        pr = scene.press
        assert pr is not None
        p = plan(scene, scene.output_path)
        work = self.stage_dir(ctx) / "work"
        yarns = read_yarns(self.needs(ctx)["fabric_h5"])
        wall = self.liggghts_wall_time(ctx, work / LOG_NAME, wall_times)
        # a resumed press: the parts before it, up to the restart step it continued from
        # (EARLIER_LOG: their log text; their fiberdem time)
        wall += earlier_wall(work) or 0.0
        log = run_log(work, LOG_NAME)
        if has_marker(log, GUARD_MARKER):
            rows = thermo_rows(log)
            last = dict(zip(COLUMNS, rows[-1])) if rows else {}
            # overlap added by the press, per kind (m): the guard's measure
            added = {"another fiber": -last.get("h_pair", 1.0) - p.start_overlap_fiber,
                     "a yarn": -last.get("h_yarn", 1.0) - p.start_overlap_yarn,
                     "the plate": -last.get("h_plate", 1.0)}
            worst = max(added.items(), key=lambda kv: kv[1])
            what = (f"at step {int(last.get('step', -1))} the press has pushed an element "
                    f"{worst[1] * 1e6:.3g} um = {worst[1] / p.t_min:.2f} x the thinner fiber's "
                    f"thickness ({p.t_min * 1e6:.3g} um) into {worst[0]} (beyond the lay-down's own "
                    f"overlap), above press.overlap_limit {pr.overlap_limit:g}")
            if pr.overlap_action == "fail":
                raise StageError(
                    f"press: overlap guard: {what}: the contact law cannot carry this load (raise "
                    f"steric_cap_m, lower target_pressure_Pa or plate_speed_m_s, raise "
                    f"target_thickness_m, or a smaller timestep_s, or overlap_action stop; "
                    f"docs/stages/press.md, limits); snapshots "
                    f"up to there: {work / TRAJ_NAME}")
            guard_stop = f"stopped by the overlap guard (overlap_action stop): {what}"
        else:
            guard_stop = ""
        self._collect(ctx, h5, tmp, p, work, yarns, wall, log, guard_stop)

    def _collect(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], p: PressPlan,
                 work: Path, yarns: Yarns, wall: float, log_text: str, guard_stop: str = "") -> None:
        scene = ctx.scene
        pr, dom, f = scene.press, scene.domain, scene.fibers
        assert pr is not None and dom is not None and f is not None
        cap = steric_cap(scene)
        # periodic x/y: the measures against the yarns tiled as fix wall/fiber/yarns has them, with
        # each chain shifted so its first node lies in the box, fiber pairs by closest images
        period = lateral_period(scene)
        checked = contact_yarns(yarns, period)
        pts, offs, rad = checked.points, checked.offsets, checked.radius
        rows = np.array(thermo_rows(log_text), dtype=float)
        if rows.ndim != 2 or rows.shape[1] != len(COLUMNS):
            raise StageError(f"{work / LOG_NAME}: no thermo table of {len(COLUMNS)} columns")
        # rows of the run commands: each chunk prints its first and last step; keep one per step
        _, first = np.unique(rows[:, 0], return_index=True)
        rows = rows[np.sort(first)]
        col = {name: rows[:, k] for k, name in enumerate(COLUMNS)}
        step = col["step"].astype(np.int64)
        steps = step  # from 0 (reset_timestep before the press's first run; a resume keeps them)
        t = steps * p.dt
        start = servo_start(log_text) if pr.mode == "pressure" else None
        plate_z = p.z0 - col["disp"]  # the displacement since the press's start (variable press_disp)
        if pr.mode == "velocity":
            t_contact = np.where(steps <= p.move_steps, 1.0, -1.0)
        else:
            servo = steps > start[0] if start is not None else np.zeros(len(steps), bool)
            t_contact = np.where(servo, col["t_contact"], -1.0)
        force = np.stack([col["fx"], col["fy"], col["fz"]], axis=1)
        pressure = 0.0 - force[:, 2] / p.area  # the plate pushes the fibers down: F_z < 0 (no -0)
        in_contact = np.abs(force[:, 2]) > 0.0
        thick_plate = np.where(in_contact, plate_z - p.fabric_top, np.nan)
        phase = phases(pr.mode, t_contact, p.schedule)

        frames = {fr.step: fr for fr in read_dump(work / TRAJ_NAME)}
        span, phi_thick, ovl_fiber, ovl_yarn, ovl_plate, profiles = [], [], [], [], [], []
        z_lo = p.fabric_top - 4 * p.t_min
        z_hi = p.z0 + p.t_min
        nbins = max(8, int(math.ceil((z_hi - z_lo) / (0.25 * p.t_min))))
        edges = np.linspace(z_lo, z_hi, nbins + 1)
        x_last = fid_last = off_last = None
        axes: dict[bytes, Array] = {}  # node outer half-axes per set of fibers present (read once)
        for k, st in enumerate(step):
            fr = frames.get(int(st))
            if fr is None:
                for lst in (span, phi_thick, ovl_fiber, ovl_yarn, ovl_plate):
                    lst.append(math.nan)
                profiles.append(np.full(nbins, np.nan))
                continue
            x, present, offsets = frame_fibers(fr.columns)
            key = present.tobytes()
            if key not in axes:
                axes[key] = read_fiber_outer_axes(ctx.scene.output_path / FIBERS_H5, present)
            r = np.max(axes[key], axis=1)
            span.append(sheet_thickness(x[:, 2], f.width_m))
            phi = solid_fraction_profile(x, offsets, r, edges, p.area)
            profiles.append(phi)
            above = np.nonzero(phi >= PHI_SHARE * phi.max())[0] if phi.max() > 0 else np.zeros(0, int)
            phi_thick.append(float(edges[above[-1] + 1] - edges[above[0]]) if len(above) else 0.0)
            q = frame_quaternions(fr.columns)
            if q is None and f.cross_section != "circular":
                raise StageError(f"{work / TRAJ_NAME}: no node quaternions (f_beam[4..7]) for the "
                                 "collapsed fibers' sections: run the press again")
            # sections: circles, or the collapsed fibers' rectangles (as the lay-down's gaps)
            ovl_fiber.append(max(0.0, -fiber_fiber_gap(x, offsets, r, axes[key], q, period)) / p.t_min)
            # yarns: each element's centre-line clearance less its fiber's thinner half-axis
            # (circles: the radius; a collapsed fiber's rectangle reaches at least that far);
            # plate: each node's extent upwards (a rectangle's in its frame, as fix
            # wall/fiber/dlvo's plane contact)
            clear = element_clearance(wrap_chains(x, offsets, period), offsets, pts, offs, rad,
                                      np.min(axes[key], axis=1))
            ovl_yarn.append(max(0.0, -clear) / p.t_min)
            up_ext = r if q is None else node_extents(axes[key], q, np.array([0.0, 0.0, 1.0]))
            ovl_plate.append(max(0.0, float(np.max(x[:, 2] + up_ext - plate_z[k]))) / p.t_min)
            x_last, fid_last, off_last = x, present, offsets
        if x_last is None or fid_last is None or off_last is None:
            raise StageError(f"{work / TRAJ_NAME}: no snapshot written")

        g = h5.create_group("curve")
        write_dataset(g, "step", steps, "1", "time step since the start of the press")
        write_dataset(g, "time", t, "s", "simulated time since the start of the press")
        write_dataset(g, "phase", np.array(phase, dtype="S10"), "-",
                      "approach, loading, hold, unloading, release (pressure) or moving, hold")
        write_dataset(g, "plate_z", plate_z, "m", "plate height")
        write_dataset(g, "plate_force", -force, "N",
                      "contact force on the plate (minus the force on the fibers; step average)")
        write_dataset(g, "pressure", pressure, "Pa", "plate force / domain cross-section")
        write_dataset(g, "target_pressure", col["p_target"], "Pa", "servo target (pressure mode)")
        write_dataset(g, "time_since_contact", col["t_contact"] if pr.mode == "pressure"
                      else np.full(len(t), math.nan), "s",
                      "pressure mode: time since the plate's first contact, the servo schedule's "
                      "clock (-1 before it); velocity mode: NaN")
        # at the fabric top: the fix's flag, or the plate's height (a servo that takes over at the
        # fabric top has a zero travel left and its flag may read 0 while it rests there)
        at_stop = (col["at_stop"] > 0.5) | (plate_z <= p.fabric_top + 1e-12)
        write_dataset(g, "plate_at_stop", at_stop.astype(np.int8), "1",
                      "1 while the plate rests at the fabric top (it never passes it)")
        write_dataset(g, "yarn_force", np.stack([col["yarn_fx"], col["yarn_fy"], col["yarn_fz"]], 1),
                      "N", "contact force of the yarns and side planes on the fibers (last step "
                      "before the output; yarn_contact newton only, else 0)")
        write_dataset(g, "thickness_plate", thick_plate, "m",
                      "plate to fabric top while the plate touches fibers (NaN otherwise)")
        write_dataset(g, "thickness_span", np.array(span), "m",
                      "5-95 % node-height span + one fiber width (as the lay-down)")
        write_dataset(g, "thickness_solid_fraction", np.array(phi_thick), "m",
                      f"height range where the solid fraction exceeds {PHI_SHARE:g} x its maximum")
        write_dataset(g, "overlap_fiber", np.array(ovl_fiber), "1",
                      "largest element-element overlap of two fibers / thinner fiber thickness")
        write_dataset(g, "overlap_yarn", np.array(ovl_yarn), "1",
                      "largest element-yarn overlap / thinner fiber thickness")
        write_dataset(g, "overlap_plate", np.array(ovl_plate), "1",
                      "largest node-plate overlap / thinner fiber thickness")
        pg = h5.create_group("profiles")
        write_dataset(pg, "z_edges", edges, "m", "bin edges of the solid-fraction profiles")
        write_dataset(pg, "solid_fraction", np.array(profiles), "1",
                      "fiber volume per bin / (bin height x domain cross-section), per curve point")
        sg = h5.create_group("sheet")
        write_dataset(sg, "x", x_last, "m", "node positions of the pressed sheet (last snapshot)")
        write_dataset(sg, "fiber_id", fid_last.astype(np.int64), "1",
                      "fiber IDs (index into fibers.h5 /fibers)")
        write_dataset(sg, "offsets", off_last, "1", "fiber k owns nodes offsets[k]:offsets[k+1]")
        rg = h5.create_group("run")
        rg.attrs["mode"] = pr.mode
        rg.attrs["timestep_s"] = p.dt
        rg.attrs["plate_area_m2"] = p.area
        rg.attrs["plate_start_z_m"] = p.z0
        rg.attrs["fabric_top_z_m"] = p.fabric_top
        rg.attrs["thinner_fiber_thickness_m"] = p.t_min
        rg.attrs["start_overlap_fiber_m"] = p.start_overlap_fiber
        rg.attrs["start_overlap_yarn_m"] = p.start_overlap_yarn
        rg.attrs["overlap_limit"] = pr.overlap_limit
        rg.attrs["fiberdem_wall_s"] = wall
        resumed = prepared_step(work)
        rg.attrs["resumed_from_step"] = -1 if resumed is None else resumed
        rg.attrs["ranks"] = pr.ranks
        rg.attrs["stopped_by_guard"] = int(bool(guard_stop))
        approach_line = []
        if pr.mode == "pressure":
            reached = has_marker(log_text, CONTACT_MARKER)
            rg.attrs["contact_pressure_Pa"] = p.contact_pressure
            rg.attrs["contact_pressure_reached"] = int(reached)
            rg.attrs["servo_start_z_m"] = start[1] if start is not None else math.nan
            rg.attrs["servo_start_time_s"] = start[0] * p.dt if start is not None else math.nan
            if start is None:
                how = (f"did not bring the sheet to {p.contact_pressure:.4g} Pa ({CONTACT_SHARE:g} x the "
                       "target): the press ended in the approach, before the servo took over")
            elif reached:
                how = (f"reached {p.contact_pressure:.4g} Pa ({CONTACT_SHARE:g} x the target) "
                       f"{(start[1] - p.fabric_top) * 1e6:.2f} um above the fabric top after "
                       f"{start[0] * p.dt * 1e3:.3f} ms: the servo's schedule starts there")
            else:
                how = (f"came down to {(start[1] - p.fabric_top) * 1e6:.2f} um above the fabric top "
                       f"without the sheet carrying {p.contact_pressure:.4g} Pa ({CONTACT_SHARE:g} x the "
                       "target): the servo's schedule starts there")
            approach_line = [f"- approach at {pr.plate_speed_m_s:g} m/s: the plate {how}"]
        above = sheet_thickness_above_fabric(scene, x_last, off_last, fid_last, p.fabric_top)
        rg.attrs["pressed_thickness_above_fabric_m"] = above
        final = work / RESTART_NAME
        if not final.is_file():
            raise StageError(f"{final}: fiberdem wrote no final restart file (see work/{LOG_NAME})")
        rg.attrs["sheet_restart_sha256"] = file_hash(final)
        shutil.copyfile(final, tmp[RESTART_NAME])

        write_sheet_vtu(tmp[VTU_NAME], x_last, fid_last, off_last)
        # on the fabric's own yarns (periodic: every image of a fiber that reaches into the box)
        write_sheet_png(tmp[PNG_NAME], x_last, off_last, yarns.points, yarns.offsets, yarns.radius,
                        f"{scene.name}: pressed sheet ({pr.mode} mode), plate at "
                        f"{plate_z[-1] * 1e3:.4f} mm", (dom.lo_m, dom.hi_m), plate_z=float(plate_z[-1]),
                        period=period)
        _write_curve(tmp[CURVE_NAME], thick_plate, np.array(span), pressure, phase,
                     f"{scene.name}: pressure vs thickness ({pr.mode} mode)")
        summary = _summary(pr, t, pressure, thick_plate, np.array(span), np.array(phi_thick),
                           phase, at_stop, float(plate_z[-1] - p.fabric_top) if guard_stop else None)
        for key, value in summary.items():
            if isinstance(value, float):
                rg.attrs[key] = value
        lines = [
            f"# Press: scene `{scene.name}`", "", report_origin(h5), "",
            f"- mode {pr.mode}; plate area {p.area * 1e6:.4g} mm^2 (domain cross-section); plate "
            f"start {p.z0 * 1e3:.4f} mm ({pr.plate_start_gap_m * 1e6:.3g} um above the sheet); "
            f"fabric top {p.fabric_top * 1e3:.4f} mm",
            f"- {int(steps[-1])} steps of {p.dt:g} s = {t[-1] * 1e3:.3f} ms simulated; fiberdem "
            f"wall time {wall:.1f} s on {pr.ranks} rank(s)"
            + ("" if resumed is None else f" (resumed from the restart file of step {resumed}; the "
               "parts before it counted up to there)"),
            *approach_line,
            *([f"- **{guard_stop}**; the plate was {(plate_z[-1] - p.fabric_top) * 1e6:.2f} um above "
               "the fabric top there: the pressed sheet is that of this moment"] if guard_stop else []),
            *[f"- {line}" for line in summary["lines"]],
            f"- pressed sheet (last snapshot) above the fabric top: {above * 1e6:.1f} um (95th percentile "
            "of the fibers' upper surfaces - fabric top, at least 0)",
            f"- overlap guard: {pr.overlap_limit:g} x the thinner fiber's thickness "
            f"({p.t_min * 1e6:.3g} um) added by the press to the lay-down's own overlaps "
            f"(fiber-fiber {p.start_overlap_fiber / p.t_min:.3f}, fiber-yarn "
            f"{p.start_overlap_yarn / p.t_min:.3f} x thickness at the start); largest overlaps "
            f"over the run: fiber-fiber {np.nanmax(ovl_fiber):.3f}, fiber-yarn "
            f"{np.nanmax(ovl_yarn):.3f}, plate {np.nanmax(ovl_plate):.3f} (x thickness)",
            "- steric servo saturation h_cap in the press's contacts: "
            + ("the law's 2 nm (press.steric_cap_m absent: a contact carries about 1e-5 N; "
               "docs/stages/press.md, 'Load per contact')" if cap is None else
               f"{cap * 1e6:.3g} um (" + ("press.steric_cap_m)" if pr.steric_cap_m is not None else
                                         "laydown.steric_cap_m; press.steric_cap_m absent)")),
            "", "Thickness definitions (docs/stages/press.md): plate = plate height - fabric top "
            "while the plate touches fibers; span = 5-95 % node heights + one fiber width; above the "
            "fabric = 95th percentile of the fibers' upper surfaces - fabric top; solid "
            f"fraction = height range where the profile exceeds {PHI_SHARE:g} x its maximum.", "",
            f"Pictures: `{PNG_NAME}`, `{CURVE_NAME}`; ParaView: `{VTU_NAME}`; data: `{H5_NAME}`; "
            f"log: `work/{LOG_NAME}`.",
        ]
        tmp[REPORT_NAME].write_text("\n".join(lines) + "\n")


def _summary(pr: PressSection, t: Array, pressure: Array, thick_plate: Array, span: Array,
             phi_thick: Array, phase: list[str], at_stop: Array,
             guard_gap: float | None = None) -> dict[str, object]:
    """Key numbers of the run (floats stored as attributes) and report lines; ``guard_gap``: the
    plate's height above the fabric top where the overlap guard stopped it (overlap_action stop)."""
    ph = np.array(phase)
    out: dict[str, object] = {}
    lines = []
    first_span = float(span[0]) if len(span) and not math.isnan(span[0]) else math.nan
    out["thickness_span_start_m"] = first_span
    out["thickness_span_end_m"] = float(span[-1])
    if pr.mode == "pressure":
        assert pr.target_pressure_Pa is not None
        hold = ph == "hold"
        # the hold is reached when the plate presses fibers in it (thickness_plate is NaN while
        # the plate touches none, e.g. resting at the fabric top as the schedule's clock runs on)
        contact = hold & ~np.isnan(thick_plate)
        if np.any(contact):
            ph_hold = pressure[hold]
            out["hold_pressure_mean_Pa"] = float(np.mean(ph_hold))
            out["hold_pressure_max_dev"] = float(np.max(np.abs(ph_hold / pr.target_pressure_Pa - 1)))
            out["thickness_plate_at_hold_m"] = float(np.mean(thick_plate[contact]))
            lines.append(f"hold: pressure {np.mean(ph_hold):.4g} Pa (target "
                         f"{pr.target_pressure_Pa:.4g} Pa, largest deviation "
                         f"{out['hold_pressure_max_dev'] * 100:.2f} %); plate thickness "
                         f"{out['thickness_plate_at_hold_m'] * 1e6:.2f} um")
        elif np.any(hold):
            lines.append(f"hold: **never reached**: the plate touched no fiber in the schedule's hold "
                         f"(pressure {np.mean(pressure[hold]):.4g} Pa, target {pr.target_pressure_Pa:.4g} Pa)")
        else:
            stop = (f", stopped by the overlap guard {guard_gap * 1e6:.2f} um above the fabric top"
                    if guard_gap is not None else "")
            lines.append(f"hold: **never reached**: the press ended in its "
                         f"{ph[-1] if len(ph) else 'first'} phase{stop}")
        if np.any(at_stop):
            lines.append(f"**target pressure not reached**: the plate came down to the fabric top "
                         f"(it rests on the yarn knuckles and never passes them) at "
                         f"{100 * np.mean(at_stop):.0f} % of the outputs; the sheet carried at "
                         f"most {np.max(pressure):.4g} Pa there (a sparse sheet lies partly in the "
                         "fabric's valleys)")
            out["plate_at_stop_fraction"] = float(np.mean(at_stop))
        rel = ph == "release"
        if np.any(rel):
            out["thickness_span_after_release_m"] = float(span[rel][-1])
            lines.append(f"spring-back: span thickness {first_span * 1e6:.2f} um before, "
                         f"{float(span[rel][-1]) * 1e6:.2f} um at the end of the release")
    else:
        target = pr.target_thickness_m * 1e6 if pr.target_thickness_m else 0.0
        if guard_gap is None:
            lines.append(f"plate stopped at {target:.2f} um above the fabric top; pressure at the end "
                         f"{pressure[-1]:.4g} Pa")
        else:
            lines.append(f"plate target {target:.2f} um above the fabric top NOT reached: stopped at "
                         f"{guard_gap * 1e6:.2f} um; pressure at the end {pressure[-1]:.4g} Pa")
    lines.append(f"span thickness {first_span * 1e6:.2f} um at the start, "
                 f"{float(span[-1]) * 1e6:.2f} um at the end; solid-fraction thickness "
                 f"{float(phi_thick[0]) * 1e6:.2f} -> {float(phi_thick[-1]) * 1e6:.2f} um")
    out["lines"] = lines
    return out


def _write_curve(path: Path, thick_plate: Array, span: Array, pressure: Array, phase: list[str],
                 title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    ph = np.array(phase)
    big = bool(np.nanmax(np.abs(pressure), initial=0.0) >= 1e3)
    scale, unit = (1e-3, "kPa") if big else (1.0, "Pa")
    for name, color in (("approach", "0.6"), ("moving", "C0"), ("loading", "C0"), ("hold", "C2"),
                        ("unloading", "C3"), ("release", "C1")):
        sel = ph == name
        if not np.any(sel):
            continue
        ax1.plot(thick_plate[sel] * 1e6, pressure[sel] * scale, ".", color=color, label=name)
        ax2.plot(span[sel] * 1e6, pressure[sel] * scale, ".", color=color, label=name)
    ax1.set(xlabel="plate-to-fabric thickness (um)", ylabel=f"pressure ({unit})",
            title="plate thickness (while in contact)")
    ax2.set(xlabel="span thickness (um)", ylabel=f"pressure ({unit})",
            title="5-95 % node span + fiber width")
    ax1.legend()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
