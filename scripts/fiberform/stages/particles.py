# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``demo-particles``: two equal spheres collide head-on under a harmonic repulsion.

The smallest end-to-end run of the toolchain: scene -> generated LIGGGHTS input ->
``build/bin/fiberdem`` (``pair_style test/harmonic``, F = k * overlap) -> dump -> HDF5 + report,
compared with the closed-form answer.

Closed form (equal masses m, reduced mass mu = m/2, each sphere moving at speed v towards the other,
surface gap g): contact starts at t0 = g / (2 v) and lasts Tc = pi * sqrt(mu / k), the maximum
overlap is 2 v / omega with omega = sqrt(k / mu); the collision is elastic, so afterwards the
velocities are reversed and each sphere leaves the point where it touched the other at speed v:
x1(t) = -R - v (t - t0 - Tc), x2 = -x1.

Products in ``<output_dir>/particles/``: ``particles.h5`` and ``report.md``; working files
``in.particles``, ``log.fiberdem``, ``traj.dump``, ``final.dump``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt

from ..errors import ConfigError, StageError
from ..inputs import STAR, LiggghtsInput, dump_format, file_token
from ..liggghts_log import Frame, read_dump
from ..provenance import text_hash, write_dataset
from ..runner import Program, build_command, liggghts_progress
from ..scene import DemoParticlesSection, RunSection, Scene
from ._stage import Program, Stage, StageContext

__all__ = ["DemoParticles", "Frame", "TwoSphereCollision", "build_input", "read_dump"]

INPUT_NAME = "in.particles"
LOG_NAME = "log.fiberdem"
TRAJ_DUMP = "traj.dump"
FINAL_DUMP = "final.dump"
DUMP_COLUMNS = ("id", "x", "y", "z", "vx", "vy", "vz")

#: Time step must resolve the contact with at least this many steps.
MIN_STEPS_PER_CONTACT = 50
#: Largest allowed overlap relative to the radius (beyond it the harmonic model is meaningless).
MAX_OVERLAP_FRACTION = 0.5


@dataclass(frozen=True)
class TwoSphereCollision:
    """Closed-form description of the demo collision."""

    radius_m: float
    density_kg_m3: float
    speed_m_s: float
    gap_m: float
    stiffness_N_m: float

    @classmethod
    def from_section(cls, s: DemoParticlesSection) -> TwoSphereCollision:
        return cls(s.radius_m, s.density_kg_m3, s.speed_m_s, s.gap_m, s.stiffness_N_m)

    @property
    def mass_kg(self) -> float:
        return self.density_kg_m3 * 4.0 / 3.0 * math.pi * self.radius_m**3

    @property
    def omega_rad_s(self) -> float:
        return math.sqrt(self.stiffness_N_m / (0.5 * self.mass_kg))

    @property
    def contact_start_s(self) -> float:
        return self.gap_m / (2.0 * self.speed_m_s)

    @property
    def contact_duration_s(self) -> float:
        return math.pi / self.omega_rad_s

    @property
    def contact_end_s(self) -> float:
        return self.contact_start_s + self.contact_duration_s

    @property
    def max_overlap_m(self) -> float:
        return 2.0 * self.speed_m_s / self.omega_rad_s

    def initial_positions_m(self) -> npt.NDArray[np.float64]:
        x = self.radius_m + 0.5 * self.gap_m
        return np.array([[-x, 0.0, 0.0], [x, 0.0, 0.0]])

    def initial_velocities_m_s(self) -> npt.NDArray[np.float64]:
        v = self.speed_m_s
        return np.array([[v, 0.0, 0.0], [-v, 0.0, 0.0]])

    def positions_m(self, t: float) -> npt.NDArray[np.float64]:
        """Closed-form positions at time t (valid before contact and after it ends)."""
        if t <= self.contact_start_s:
            return self.initial_positions_m() + self.initial_velocities_m_s() * t
        if t < self.contact_end_s:
            raise ValueError("positions during contact are not needed here")
        x1 = -self.radius_m - self.speed_m_s * (t - self.contact_end_s)
        return np.array([[x1, 0.0, 0.0], [-x1, 0.0, 0.0]])

    def velocities_m_s(self, t: float) -> npt.NDArray[np.float64]:
        """Closed-form velocities at time t (before contact or after it ends)."""
        v0 = self.initial_velocities_m_s()
        return v0 if t <= self.contact_start_s else -v0 + 0.0  # + 0.0: no negative zeros

    def box_half_extent_m(self, end_time_s: float) -> tuple[float, float]:
        """Half sizes (along x, across) of a box the spheres never leave."""
        reach = self.radius_m + 0.5 * self.gap_m + self.speed_m_s * end_time_s
        return 1.2 * (reach + 2.0 * self.radius_m), 3.0 * self.radius_m


def check_collision(scene: Scene) -> list[str]:
    """Physics checks of the demo scene; lines name the field to change."""
    d = scene.demo_particles
    r = scene.run
    if d is None:
        return []
    c = TwoSphereCollision.from_section(d)
    problems = []
    dt_max = c.contact_duration_s / MIN_STEPS_PER_CONTACT
    if r.timestep_s > dt_max:
        problems.append(
            f"run.timestep_s = {r.timestep_s!r}: too large to resolve the contact, which lasts "
            f"{c.contact_duration_s:.4g} s; at most {dt_max:.4g} s "
            f"({MIN_STEPS_PER_CONTACT} steps per contact)"
        )
    end = r.steps * r.timestep_s
    need = c.contact_end_s + c.contact_duration_s
    if end < need:
        problems.append(
            f"run.duration_s = {r.duration_s!r}: too short, the collision ends at "
            f"{c.contact_end_s:.4g} s; at least {need:.4g} s"
        )
    if c.max_overlap_m > MAX_OVERLAP_FRACTION * c.radius_m:
        problems.append(
            f"demo_particles.stiffness_N_m = {d.stiffness_N_m!r}: too soft, the spheres would "
            f"overlap by {c.max_overlap_m:.4g} m (more than {MAX_OVERLAP_FRACTION} radius)"
        )
    return problems


def build_input(scene: Scene) -> str:
    """The LIGGGHTS input of the demo; every scene value passes through fiberform.inputs."""
    d = scene.demo_particles
    if d is None:
        raise StageError("the scene has no demo_particles section")
    r: RunSection = scene.run
    c = TwoSphereCollision.from_section(d)
    steps = r.steps
    lx, ly = c.box_half_extent_m(steps * r.timestep_s)
    skin = 0.5 * c.radius_m
    ghost_cut = 2.0 * (2.0 * c.radius_m + skin)
    p = c.initial_positions_m()
    v = c.initial_velocities_m_s()

    s = LiggghtsInput()
    s.comment("Generated by fiberform stage demo-particles; edit the scene, not this file.")
    s.comment("Two equal spheres approach head-on along x; harmonic repulsion F = k * overlap.")
    s.command("units", "si")
    s.command("atom_style", "sphere")
    s.command("atom_modify", "map", "array")
    s.command("boundary", "f", "f", "f")
    s.command("newton", "off")
    s.command("processors", STAR, 1, 1)
    s.command("communicate", "single", "cutoff", ghost_cut, "vel", "yes")
    s.blank()
    s.command("region", "box", "block", -lx, lx, -ly, ly, -ly, ly, "units", "box")
    s.command("create_box", 1, "box")
    s.command("neighbor", skin, "bin")
    s.command("neigh_modify", "delay", 0)
    s.blank()
    s.command("pair_style", "test/harmonic")
    s.command("pair_coeff", STAR, STAR, d.stiffness_N_m)
    s.blank()
    for i in range(2):
        s.command("create_atoms", 1, "single", p[i, 0], p[i, 1], p[i, 2], "units", "box")
    for i in range(2):
        s.command(
            "set", "atom", i + 1,
            "diameter", 2.0 * c.radius_m,
            "density", d.density_kg_m3,
            "vx", v[i, 0],
        )  # fmt: skip
    s.blank()
    s.command("fix", "integrate", "all", "nve/sphere")
    s.command("timestep", r.timestep_s)
    s.command("thermo_style", "custom", "step", "atoms", "ke")
    s.command("thermo", r.output_every_steps)
    fmt = dump_format(["int", "float", "float", "float", "float", "float", "float"])
    for dump_id, every, file in (
        ("traj", r.output_every_steps, TRAJ_DUMP),
        ("final", steps, FINAL_DUMP),
    ):
        s.command("dump", dump_id, "all", "custom", every, file_token(file), *DUMP_COLUMNS)
        s.command("dump_modify", dump_id, "sort", "id", "format", fmt)
    s.blank()
    s.command("run", steps)
    return s.render()


def _xyz(frame: Frame, prefix: str) -> npt.NDArray[np.float64]:
    keys = ("x", "y", "z") if prefix == "" else ("vx", "vy", "vz")
    return np.stack([frame.columns[k] for k in keys], axis=1)


_VERSION_LINE = re.compile(r"^LIGGGHTS \(Version (.*?)[,)]")


class DemoParticles(Stage):
    name = "demo-particles"
    summary = "two spheres collide head-on in fiberdem (pair_style test/harmonic); make demo"
    folder = "particles"
    requires = ("demo_particles", "run")
    uses = ("seed", "run", "demo_particles")
    products = ("particles.h5", "report.md")
    binaries = ("fiberdem",)
    splits = True

    def check_scene(self, scene: Scene) -> list[str]:
        return super().check_scene(scene) + check_collision(scene)

    def fiberdem(self, ctx: StageContext) -> Path:
        return ctx.build_dir / "bin" / "fiberdem"

    def ranks(self, ctx: StageContext) -> int:
        return ctx.scene.run.ranks

    def preflight(self, ctx: StageContext) -> None:
        exe = self.fiberdem(ctx)
        if not exe.is_file():
            raise StageError(
                f"{exe} not found: build it with 'make setup' (or point FIBERFORM_BUILD or "
                "--build-dir at a build directory)"
            )
        build_command([str(exe)], ctx.scene.run.ranks, ctx.oversubscribe)

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        hashes = super().input_hashes(ctx)
        hashes[INPUT_NAME] = text_hash(build_input(ctx.scene))
        return hashes

    def prepare(self, ctx: StageContext, hashes: Mapping[str, str]) -> None:
        work = self.stage_dir(ctx)
        (work / INPUT_NAME).write_text(build_input(ctx.scene))
        for stale in (TRAJ_DUMP, FINAL_DUMP):
            (work / stale).unlink(missing_ok=True)

    def programs(self, ctx: StageContext) -> list[Program]:
        # LIGGGHTS' own log file is off (-log none): its screen output is the runner's log, so
        # progress and the error tail come from one place.
        work = self.stage_dir(ctx).resolve()
        return [Program((str(self.fiberdem(ctx).resolve()), "-in", INPUT_NAME, "-log", "none"), ctx.scene.run.ranks,
                        work, work / LOG_NAME, liggghts_progress(ctx.scene.run.steps))]

    def collect(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str],
                wall_times: Mapping[str, float]) -> None:
        scene = ctx.scene
        d = scene.demo_particles
        assert d is not None
        work = self.stage_dir(ctx)
        prog = self.programs(ctx)[0]
        elapsed = self.liggghts_wall_time(ctx, prog.log, wall_times)
        try:  # the command line as fiberform starts it (a batch job may have used a larger node)
            cmd = build_command(list(prog.argv), prog.ranks, ctx.oversubscribe)
        except ConfigError:
            cmd = build_command(list(prog.argv), prog.ranks, oversubscribe=True)
        frames = read_dump(work / FINAL_DUMP)
        if len(frames) < 2 or frames[-1].step != scene.run.steps:
            raise StageError(f"{work / FINAL_DUMP} lacks the final frame (step {scene.run.steps})")
        first, last = frames[0], frames[-1]
        if list(last.ids) != [1, 2]:
            raise StageError(f"expected atoms 1 and 2 in the dump, found {list(last.ids)}")
        traj = read_dump(work / TRAJ_DUMP)

        c = TwoSphereCollision.from_section(d)
        t_end = scene.run.steps * scene.run.timestep_s
        x_end, v_end = _xyz(last, ""), _xyz(last, "v")
        x_exp, v_exp = c.positions_m(t_end), c.velocities_m_s(t_end)
        v_err = float(np.max(np.abs(v_end - v_exp)) / c.speed_m_s)
        x_err = float(np.max(np.abs(x_end - x_exp)) / c.radius_m)

        h5.attrs["units_note"] = "SI units; see each dataset's units attribute"
        g0 = h5.create_group("initial")
        write_dataset(g0, "positions", _xyz(first, ""), "m", "sphere centres at t = 0, by atom id")
        write_dataset(g0, "velocities", _xyz(first, "v"), "m/s", "velocities at t = 0")
        g1 = h5.create_group("final")
        write_dataset(g1, "time", t_end, "s", "simulated time of the final frame")
        write_dataset(g1, "positions", x_end, "m", "sphere centres at the end, by atom id")
        write_dataset(g1, "velocities", v_end, "m/s", "velocities at the end, by atom id")
        g2 = h5.create_group("expected")
        write_dataset(g2, "positions", x_exp, "m", "closed-form centres at the end")
        write_dataset(
            g2,
            "velocities",
            v_exp,
            "m/s",
            "closed-form velocities at the end: the initial ones reversed",
        )
        write_dataset(g2, "contact_start", c.contact_start_s, "s", "time contact begins, g/(2v)")
        write_dataset(
            g2, "contact_duration", c.contact_duration_s, "s", "contact duration pi*sqrt(m/(2k))"
        )
        write_dataset(g2, "max_overlap", c.max_overlap_m, "m", "largest overlap 2v/omega")
        write_dataset(g2, "mass", c.mass_kg, "kg", "mass of each sphere")
        g3 = h5.create_group("trajectory")
        write_dataset(
            g3, "time", np.array([f.step for f in traj]) * scene.run.timestep_s, "s", "frame times"
        )
        write_dataset(
            g3,
            "positions",
            np.stack([_xyz(f, "") for f in traj]),
            "m",
            "centres (frame, atom, xyz)",
        )
        write_dataset(
            g3,
            "velocities",
            np.stack([_xyz(f, "v") for f in traj]),
            "m/s",
            "velocities (frame, atom, xyz)",
        )
        g4 = h5.create_group("comparison")
        write_dataset(g4, "velocity_error", v_err, "1", "max |v - v_expected| / speed")
        write_dataset(g4, "position_error", x_err, "1", "max |x - x_expected| / radius")

        version = "unknown"
        for line in (work / LOG_NAME).read_text(errors="replace").splitlines()[:20]:
            m = _VERSION_LINE.match(line)
            if m:
                version = m.group(1)
                break
        report = _report(scene, c, cmd, elapsed, version,
                         x_end, v_end, x_exp, v_exp,
                         v_err, x_err, hashes)  # fmt: skip
        tmp["report.md"].write_text(report)


def _vec(a: npt.NDArray[np.float64]) -> str:
    return "(" + ", ".join(f"{x:.9g}" for x in a) + ")"


def _report(
    scene: Scene,
    c: TwoSphereCollision,
    cmd: list[str],
    elapsed_s: float,
    liggghts: str,
    x_end: npt.NDArray[np.float64],
    v_end: npt.NDArray[np.float64],
    x_exp: npt.NDArray[np.float64],
    v_exp: npt.NDArray[np.float64],
    v_err: float,
    x_err: float,
    hashes: Mapping[str, str],
) -> str:
    r = scene.run
    lines = [
        f"# demo-particles: scene `{scene.name}`",
        "",
        "Two equal spheres approach head-on along x and bounce off a harmonic repulsion",
        "F = k * overlap (`pair_style test/harmonic` in fiberdem). The collision is elastic, so",
        "the expected final velocities are the initial ones reversed.",
        "",
        "## What ran",
        "",
        f"- command: `{' '.join(cmd)}` on {r.ranks} MPI rank(s)",
        f"- folder: `{scene.output_path / 'particles'}`",
        f"- LIGGGHTS: {liggghts}",
        f"- wall time: {elapsed_s:.3f} s",
        f"- simulated: {r.steps} steps of {r.timestep_s:g} s = {r.steps * r.timestep_s:g} s",
        "",
        "## Inputs",
        "",
        "| quantity | value | unit |",
        "|---|---|---|",
        f"| radius | {c.radius_m:g} | m |",
        f"| density | {c.density_kg_m3:g} | kg/m^3 |",
        f"| mass of each sphere | {c.mass_kg:.6g} | kg |",
        f"| speed of each sphere | {c.speed_m_s:g} | m/s |",
        f"| initial gap | {c.gap_m:g} | m |",
        f"| stiffness k | {c.stiffness_N_m:g} | N/m |",
        f"| contact starts at | {c.contact_start_s:.6g} | s |",
        f"| contact duration pi*sqrt(m/(2k)) | {c.contact_duration_s:.6g} | s |",
        f"| largest overlap | {c.max_overlap_m:.6g} | m |",
        "",
        "## Results",
        "",
        "| atom | quantity | simulated | expected | unit |",
        "|---|---|---|---|---|",
    ]
    for i in range(2):
        lines.append(f"| {i + 1} | position | {_vec(x_end[i])} | {_vec(x_exp[i])} | m |")
        lines.append(f"| {i + 1} | velocity | {_vec(v_end[i])} | {_vec(v_exp[i])} | m/s |")
    lines += [
        "",
        f"- largest velocity error / speed: {v_err:.3e}",
        f"- largest position error / radius: {x_err:.3e}",
        "",
        "Input hashes: " + ", ".join(f"{k} `{v[:19]}`" for k, v in sorted(hashes.items())),
        "",
    ]
    return "\n".join(lines)
