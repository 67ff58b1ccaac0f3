# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``flow``: steady flow of water through the bare fabric (Kettil 2016, section 3.1).

Domain: the box over the fabric piece, [0, Lx] x [0, Ly] x [0, H], the fabric's lower side at
``fabric.lower_side_z_m`` (2 mm). Boundary conditions as eq. 3.1-3.3: symmetry on the four vertical
sides, kinematic pressure delta_p / rho at the top and 0 at the bottom with zero-gradient velocity
there, no-slip on the yarns. Solver: stock ``simpleFoam`` (laminar, SIMPLEC), optionally on several
ranks through ``decomposePar``.

Mesh: ``blockMesh`` builds a box of three blocks stacked in z; the fabric zone has cubic cells of
``flow.cell_size_m`` on the lattice of the voxel image's box, the blocks above and below are graded
geometrically up to ``max_cell_height_m``. The solid is the permeability stage's (one solid for
both, so that water and air give one Darcy permeability; tests/test_permeability.py): each
fabric-zone cell gets the fraction of its ``SUBSAMPLES``^3 sample points inside a yarn (capsule
chains of ``fabric.h5`` ``/yarns``; an imported fabric: its voxel image), the cells with the largest
fractions are removed until the removed volume equals the sampled yarn volume
(:func:`fiberform.openfoam_case.volume_preserving`), ``topoSet`` keeps the rest that is
face-connected to the top and ``subsetMesh`` turns the exposed faces into the wall patch ``yarns``.
This "staircase" mesh needs no surface: the trade is resolution (a yarn of diameter d spans
d / cell_size cells; the openings between yarns, about 0.09 mm in the default fabric, need at least
3-4 cells for the flow rate to converge to a few percent; see docs/bench/flow.md). snappyHexMesh on
``fabric.stl`` would give body-fitted cells, at several times the meshing cost and with a less
predictable cell count.

Products in ``<output_dir>/flow/``: ``flow.h5`` (the regular sampling grid and the raw lattice
values, flow rates, solver record), ``flow.grid`` (binary companion of the grid velocity for the
C++ side, format in liggghts-fiber-style/src/physics/flow_grid.h) and ``flow.png``. The OpenFOAM
case stays in ``flow/case`` and the logs in ``flow/log.<tool>``.

Docs: docs/stages/flow.md.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt

from ..errors import StageError
from ..fabric_geometry import VoxelImage
from ..lattice import trilinear_stencil
from ..openfoam_case import (
    BoxSetup, CaseResult, Lattice, SolidFraction, collect_case, load_prepared, plot_section,
    prepare_or_resume, run_case, solver_program, solver_wall_time, template_hash, write_solver_record,
)  # fmt: skip
from ..porous_media import capsule_fraction, image_fraction
from ..products import FABRIC_H5, read_fabric_image, read_yarn_chains
from ..provenance import write_dataset
from ..scene import FlowSection, FluidSection, Scene
from ._stage import Program, Stage, StageContext, resumes

__all__ = [
    "FlowResult",
    "FlowSetup",
    "FlowStage",
    "fabric_solid",
    "read_flow_grid",
    "run_flow_case",
    "write_flow_grid",
]

H5_NAME, GRID_NAME, PNG_NAME = "flow.h5", "flow.grid", "flow.png"

FloatArray = npt.NDArray[np.float64]
#: The result of one flow run (the shared case runner's result).
FlowResult = CaseResult


@dataclass(frozen=True)
class FlowSetup(BoxSetup):
    """Numbers that define one flow run (SI units): the box case plus the output grid spacing."""

    sample_spacing_m: float | None = None

    @classmethod
    def from_scene(cls, img: VoxelImage, flow: FlowSection, fluid: FluidSection) -> FlowSetup:
        up = img.upper
        return cls(
            size_x_m=float(up[0] - img.origin[0]),
            size_y_m=float(up[1] - img.origin[1]),
            fabric_lo_z_m=float(img.origin[2]),
            fabric_hi_z_m=float(up[2]),
            top_z_m=float(up[2] + flow.height_above_fabric_m),
            cell_size_m=flow.cell_size_m,
            max_cell_height_m=flow.max_cell_height_m or 4.0 * flow.cell_size_m,
            delta_p_Pa=flow.delta_p_Pa,
            density_kg_m3=fluid.density_kg_m3,
            viscosity_Pa_s=fluid.viscosity_Pa_s,
            max_iterations=flow.max_iterations,
            residual_tolerance=flow.residual_tolerance,
            ranks=flow.ranks,
            sample_spacing_m=flow.sample_spacing_m,
        )


#: Sample points per cell edge for the yarn fraction of a cell (the permeability stage's default
#: ``permeability.subsamples``, so that both stages remove the same cells).
SUBSAMPLES = 4


def fabric_solid(img: VoxelImage, yarns: Sequence[tuple[FloatArray, float]]) -> SolidFraction:
    """Solid fraction of the zone cells of the bare fabric, computed as the permeability stage
    does: the yarns ``(centre line (m, 3) [m], radius [m])`` sampled at SUBSAMPLES^3 points per
    cell (:func:`fiberform.porous_media.capsule_fraction`) or, with no yarns (imported fabric), the
    voxel image ``img`` at the same points (:func:`fiberform.porous_media.image_fraction`)."""
    chains = [(np.asarray(p, dtype=np.float64), float(r)) for p, r in yarns]

    def frac(s: BoxSetup, lat: Lattice) -> npt.NDArray[np.float32]:
        if chains:
            return capsule_fraction(chains, s, lat, SUBSAMPLES)
        return image_fraction(img, s, lat, SUBSAMPLES)

    return frac


def run_flow_case(
    s: BoxSetup,
    img: VoxelImage,
    work: Path,
    *,
    yarns: Sequence[tuple[FloatArray, float]] = (),
    oversubscribe: bool = False,
    show_progress: bool | None = None,
    inputs: Mapping[str, str] | None = None,
    resume: bool = False,
) -> FlowResult:
    """Mesh, solve and read back one flow case through the bare fabric in ``work``: the yarns
    ``yarns`` (generated fabric) or the voxel image ``img`` (imported fabric, ``yarns`` empty),
    removed by :func:`fabric_solid` and the volume-preserving rule. ``inputs``, ``resume``: resume
    a killed solve of the same inputs (:func:`fiberform.openfoam_case.run_case`)."""
    return run_case(
        s, fabric_solid(img, yarns), work, preserve_volume=True, oversubscribe=oversubscribe,
        show_progress=show_progress, inputs=inputs, resume=resume,
    )  # fmt: skip


# --------------------------------------------------------------------------------------------
# Regular grid


@dataclass(frozen=True)
class RegularGrid:
    origin: FloatArray
    spacing: FloatArray
    shape: tuple[int, int, int]

    def axis(self, a: int) -> FloatArray:
        return np.asarray(self.origin[a] + np.arange(self.shape[a]) * self.spacing[a])


def sample_grid(res: FlowResult, s: FlowSetup) -> tuple[RegularGrid, FloatArray, FloatArray]:
    """Trilinear resampling of the lattice values onto a regular node grid covering the domain
    (nodes at cell-centre positions (i + 1/2) * spacing; positions outside the outermost lattice
    centres take the boundary values; :func:`fiberform.lattice.trilinear_stencil`, the stencil the
    two-way coupling samples the live fluid with). The pressure is the fluid-weighted average
    (removed cells do not count; NaN where no fluid cell contributes). Returns (grid,
    U (nx, ny, nz, 3), p (nx, ny, nz))."""
    h = s.sample_spacing_m or s.cell_size_m
    ext = np.array([s.size_x_m, s.size_y_m, s.top_z_m])
    n = np.maximum(1, np.round(ext / h)).astype(int)
    sp = ext / n
    grid = RegularGrid(0.5 * sp, sp, (int(n[0]), int(n[1]), int(n[2])))
    axes = (res.lattice_x, res.lattice_y, res.lattice_z)
    P = np.stack(np.meshgrid(*(grid.axis(a) for a in range(3)), indexing="ij"), axis=-1).reshape(-1, 3)
    idx, w = trilinear_stencil(axes, P)
    at = (idx[..., 0], idx[..., 1], idx[..., 2])
    U = np.einsum("ns,nsc->nc", w, res.U[at])
    wf = np.sum(w * res.fluid[at], axis=1)
    pv = np.sum(w * np.where(np.isnan(res.p), 0.0, res.p)[at], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.where(wf > 0, pv / np.maximum(wf, 1e-300), np.nan)  # fluid-weighted average
    return grid, U.reshape(*grid.shape, 3), p.reshape(grid.shape)


def write_flow_grid(path: Path, grid: RegularGrid, U: FloatArray) -> None:
    """Binary companion for C++ (read_flow_grid in physics/flow_grid.h), little-endian."""
    with open(path, "wb") as f:
        f.write(b"FFGRID1\n")
        f.write(struct.pack("<3q", *grid.shape))
        f.write(struct.pack("<6d", *grid.origin, *grid.spacing))
        f.write(np.ascontiguousarray(U, dtype="<f8").tobytes())


def read_flow_grid(path: Path) -> tuple[RegularGrid, FloatArray]:
    data = Path(path).read_bytes()
    if data[:8] != b"FFGRID1\n":
        raise StageError(f"{path}: not a fiberform flow grid")
    shape = struct.unpack("<3q", data[8:32])
    vals = struct.unpack("<6d", data[32:80])
    U = np.frombuffer(data, dtype="<f8", offset=80).reshape(*shape, 3)
    return RegularGrid(np.array(vals[:3]), np.array(vals[3:]), (shape[0], shape[1], shape[2])), U


# --------------------------------------------------------------------------------------------
# Output


def write_flow_h5(h5: h5py.File, s: FlowSetup, res: FlowResult, grid: RegularGrid, Ug: FloatArray, pg: FloatArray) -> None:
    area = s.size_x_m * s.size_y_m
    g = h5.create_group("grid")
    g.attrs["description"] = (
        "regular node grid: node (i, j, k) at origin + (i, j, k) * spacing; trilinear "
        "interpolation between nodes; U = 0 inside yarns"
    )
    write_dataset(g, "origin", grid.origin, "m", "position of node (0, 0, 0)")
    write_dataset(g, "spacing", grid.spacing, "m", "node spacing (x, y, z)")
    write_dataset(g, "shape", np.array(grid.shape, dtype=np.int64), "1", "nodes (nx, ny, nz)")
    ds = g.create_dataset("U", data=Ug, compression="gzip", shuffle=True)
    ds.attrs.update(units="m/s", description="fluid velocity at the nodes, (nx, ny, nz, 3)")
    ds = g.create_dataset("p", data=pg, compression="gzip", shuffle=True)
    ds.attrs.update(units="Pa", description="pressure at the nodes (NaN inside yarns), (nx, ny, nz)")
    lg = h5.create_group("lattice")
    lg.attrs["description"] = "cell-centre values of the CFD lattice (the blockMesh cells before removal)"
    write_dataset(lg, "x", res.lattice_x, "m", "cell-centre x")
    write_dataset(lg, "y", res.lattice_y, "m", "cell-centre y")
    write_dataset(lg, "z", res.lattice_z, "m", "cell-centre z (graded above and below the fabric)")
    for name, data, unit, desc in (
        ("U", res.U, "m/s", "velocity, 0 in removed cells"),
        ("p", res.p, "Pa", "pressure, NaN in removed cells"),
        ("fluid", res.fluid.astype(np.uint8), "1", "1 where the cell is part of the CFD mesh"),
        ("solid_fraction", res.solid_fraction, "1", "fabric volume fraction of the cell"),
    ):
        ds = lg.create_dataset(name, data=data, compression="gzip", shuffle=True)
        ds.attrs.update(units=unit, description=desc)
    fr = h5.create_group("flow_rate")
    write_dataset(fr, "top", res.q_top_m3_s, "m^3/s", "volume flow in through the top")
    write_dataset(fr, "bottom", res.q_bottom_m3_s, "m^3/s", "volume flow out through the bottom")
    write_dataset(fr, "imbalance", res.imbalance, "1", "|top - bottom| / bottom")
    write_dataset(fr, "superficial_velocity", res.q_bottom_m3_s / area, "m/s",
                  "bottom flow rate / piece area")  # fmt: skip
    write_dataset(fr, "delta_p", s.delta_p_Pa, "Pa", "pressure drop top - bottom")
    write_solver_record(h5.create_group("solver"), s, res)


def write_png(path: Path, s: FlowSetup, res: FlowResult, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 5), gridspec_kw={"width_ratios": [1.4, 1]})
    j = len(res.lattice_y) // 2
    pc = plot_section(axes[0], s, res, -res.U[:, j, :, 2], "downward velocity -U_z", 0.5e-3)
    ax = axes[0]
    fig.colorbar(pc, ax=ax, label="m/s", shrink=0.8)
    ax = axes[1]
    area = s.size_x_m * s.size_y_m
    mean_w = -np.nanmean(np.where(res.fluid, res.U[..., 2], 0.0), axis=(0, 1))
    ax.plot(mean_w * 1e3, res.lattice_z * 1e3, "k.-", ms=3, label="plane average of cell values")
    ax.axvline(res.q_bottom_m3_s / area * 1e3, color="r", ls="--", label="Q_bottom / area")
    ax.axhspan(s.fabric_lo_z_m * 1e3, s.fabric_hi_z_m * 1e3, color="0.85", label="fabric")
    ax.set_xlabel("velocity [mm/s]")
    ax.set_ylabel("z [mm]")
    ax.legend(fontsize=8)
    ax.set_title("plane average of cell-centre -U_z vs flow rate / area")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


class FlowStage(Stage):
    name = "flow"
    summary = "steady water flow through the bare fabric (OpenFOAM simpleFoam), sampled to a grid"
    folder = "flow"
    requires = ("fabric", "flow")
    uses = ("fabric", "flow", "fluid")
    products = (H5_NAME, GRID_NAME, PNG_NAME)
    code_version = 2  # 2: the permeability stage's solid (yarn capsules, volume-preserving removal)
    splits = True

    def check_scene(self, scene: Scene) -> list[str]:
        problems = super().check_scene(scene)
        fab, flow = scene.fabric, scene.flow
        if fab is None or flow is None:
            return problems
        h = flow.cell_size_m
        if fab.lower_side_z_m < h:
            problems.append(
                f"fabric.lower_side_z_m = {fab.lower_side_z_m!r}: the flow needs at least one cell "
                f"({h!r} m) below the fabric"
            )
        if flow.height_above_fabric_m < h:
            problems.append(
                f"flow.height_above_fabric_m = {flow.height_above_fabric_m!r}: smaller than one "
                f"cell ({h!r} m)"
            )
        if fab.source == "generate":
            nx = fab.size_x_m / h
            ny = fab.size_y_m / h
            nz = (fab.md_diameter_m * 3 + fab.cd_top_diameter_m + fab.cd_bottom_diameter_m) / h
            if nx * ny * nz > 5e6:
                problems.append(
                    f"flow.cell_size_m = {h!r}: the fabric zone alone would hold about "
                    f"{nx * ny * nz:.2g} cells (limit 5e6)"
                )
            if h > 0.5 * fab.md_diameter_m:
                problems.append(
                    f"flow.cell_size_m = {h!r}: larger than half the warp diameter; the yarns "
                    "would not be resolved"
                )
        if scene.domain is not None and fab.source == "generate":
            d = scene.domain
            top = fab.top_z_m + flow.height_above_fabric_m
            want_lo, want_hi = [0.0, 0.0, 0.0], [fab.size_x_m, fab.size_y_m, top]
            for axis in range(3):
                if not math.isclose(d.lo_m[axis], want_lo[axis], abs_tol=1e-12):
                    problems.append(
                        f"domain.lo_m[{axis}] = {d.lo_m[axis]!r}: the flow domain starts at "
                        f"{want_lo[axis]!r} (fabric piece corner / domain bottom)"
                    )
                if not math.isclose(d.hi_m[axis], want_hi[axis], rel_tol=1e-9):
                    problems.append(
                        f"domain.hi_m[{axis}] = {d.hi_m[axis]!r}: the flow domain ends at "
                        f"{want_hi[axis]!r} (fabric size, fabric top + flow.height_above_fabric_m)"
                    )
        return problems

    def needs(self, ctx: StageContext) -> dict[str, Path]:
        return {"fabric_h5": ctx.scene.output_path / FABRIC_H5}

    def metrics(self, ctx: StageContext) -> dict[str, float]:
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            return {"flow_superficial_velocity_m_s": float(h5["flow_rate/superficial_velocity"][()]),
                    "flow_iterations": float(h5["solver"].attrs["iterations"])}

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        hashes = super().input_hashes(ctx)
        hashes["case_template"] = template_hash()
        return hashes

    def setup(self, ctx: StageContext) -> tuple[FlowSetup, VoxelImage, list[tuple[FloatArray, float]]]:
        """The case setup, the fabric image and the yarns (centre line, radius) from fabric.h5."""
        fab_path = self.needs(ctx)["fabric_h5"]
        if not fab_path.is_file():
            raise StageError(f"flow needs {fab_path}: run `fiberform fabric` first")
        flow = ctx.scene.flow
        assert flow is not None
        img = read_fabric_image(fab_path)
        s = FlowSetup.from_scene(img, flow, ctx.scene.fluid or FluidSection())
        return s, img, [(c.points, c.radius) for c in read_yarn_chains(fab_path)]

    def prepare(self, ctx: StageContext, hashes: Mapping[str, str]) -> None:
        s, img, yarns = self.setup(ctx)
        prepare_or_resume(s, fabric_solid(img, yarns), self.stage_dir(ctx), inputs=hashes, resume=resumes(ctx),
                          preserve_volume=True, oversubscribe=ctx.oversubscribe,
                          show_progress=ctx.show_progress)

    def programs(self, ctx: StageContext) -> list[Program]:
        flow = ctx.scene.flow
        assert flow is not None
        return [solver_program(self.stage_dir(ctx), flow.ranks, flow.max_iterations)]

    def collect(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str],
                wall_times: Mapping[str, float]) -> None:
        s, _, _ = self.setup(ctx)
        work = self.stage_dir(ctx)
        prep = load_prepared(work, s)
        key = self.log_key(ctx, work / "log.simpleFoam")
        solve = wall_times[key] if key in wall_times else solver_wall_time(work)
        times = {**prep.wall_times_s, "simpleFoam": solve}
        res = collect_case(s, prep, times, oversubscribe=ctx.oversubscribe, show_progress=ctx.show_progress)
        grid, Ug, pg = sample_grid(res, s)
        write_flow_h5(h5, s, res, grid, Ug, pg)
        h5["solver"].attrs["wall_time_total_s"] = sum(res.wall_times_s.values())
        write_flow_grid(tmp[GRID_NAME], grid, Ug)
        area = s.size_x_m * s.size_y_m
        title = (
            f"flow of scene '{ctx.scene.name}': delta_p {s.delta_p_Pa:g} Pa, superficial velocity "
            f"{res.q_bottom_m3_s / area * 1e3:.4g} mm/s, in/out imbalance {res.imbalance:.2e}, "
            f"{res.fluid_cells} cells, {res.iterations} iterations"
        )
        write_png(tmp[PNG_NAME], s, res, title)
        if not res.converged:
            print(
                f"flow: warning: simpleFoam did not reach residual {s.residual_tolerance:g} in "
                f"{s.max_iterations} iterations (see {self.stage_dir(ctx) / 'log.simpleFoam'})"
            )
