# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``flow``: steady flow of water through the bare fabric (Kettil 2016, section 3.1).

Domain: the box over the fabric piece, [0, Lx] x [0, Ly] x [0, H], the fabric's lower side at
``fabric.lower_side_z_m`` (2 mm). Boundary conditions as eq. 3.1-3.3: symmetry on the four vertical
sides, kinematic pressure delta_p / rho at the top and 0 at the bottom with zero-gradient velocity
there, no-slip on the yarns. Solver: stock ``simpleFoam`` (laminar, SIMPLEC), optionally on several
ranks through ``decomposePar``.

Mesh: ``blockMesh`` builds a box of three blocks stacked in z; the fabric zone has cubic cells of
``flow.cell_size_m`` on the lattice of the voxel image's box, the blocks above and below are graded
geometrically up to ``max_cell_height_m``. Each fabric-zone cell gets the solid volume fraction of
the fabric voxels it holds (field ``solid``); ``topoSet`` selects the cells with fraction < 1/2
that are face-connected to the top, and ``subsetMesh`` keeps only those, turning the exposed faces
into the wall patch ``yarns``. This "staircase" mesh is what the voxel image gives directly and needs
no surface: the trade is resolution (a yarn of diameter d spans d / cell_size cells; the openings
between yarns, about 0.09 mm in the default fabric, need at least 3-4 cells for the flow rate to
converge to a few percent; see docs/bench/flow.md). snappyHexMesh on ``fabric.stl`` would give
body-fitted cells, at several times the meshing cost and with a less predictable cell count.

Products in ``<output_dir>/flow/``: ``flow.h5`` (the regular sampling grid and the raw lattice
values, flow rates, solver record), ``flow.grid`` (binary companion of the grid velocity for the
C++ side, format in liggghts-fiber-style/src/physics/flow_grid.h) and ``flow.png``. The OpenFOAM
case stays in ``flow/case`` and the logs in ``flow/log.<tool>``.

Docs: docs/stages/flow.md.
"""

from __future__ import annotations

import math
import re
import shutil
import struct
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt

from .._versions import repo_root
from ..errors import StageError
from ..fabric_geometry import VoxelImage
from ..provenance import file_hash, text_hash, write_dataset
from ..runner import openfoam_progress, run
from ..scene import FlowSection, FluidSection, Scene
from ._stage import Stage, StageContext
from .fabric import FabricStage, read_fabric_image

__all__ = [
    "FlowResult",
    "FlowSetup",
    "FlowStage",
    "geometric_cells",
    "read_flow_grid",
    "run_flow_case",
    "write_flow_grid",
]

H5_NAME, GRID_NAME, PNG_NAME = "flow.h5", "flow.grid", "flow.png"
CASE_DIR = "case"
TEMPLATE = "fabric-flow"
#: Largest growth ratio of neighbouring cell heights in the graded blocks.
MAX_GROWTH = 1.2

FloatArray = npt.NDArray[np.float64]


def template_dir() -> Path:
    return repo_root() / "openfoam-cases" / TEMPLATE


@dataclass(frozen=True)
class FlowSetup:
    """Numbers that define one flow run (SI units)."""

    size_x_m: float
    size_y_m: float
    fabric_lo_z_m: float
    fabric_hi_z_m: float
    top_z_m: float
    cell_size_m: float
    max_cell_height_m: float
    delta_p_Pa: float
    density_kg_m3: float
    viscosity_Pa_s: float
    max_iterations: int = 3000
    residual_tolerance: float = 1e-6
    ranks: int = 1
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


def geometric_cells(length: float, first: float, largest: float) -> tuple[int, float]:
    """Cells for a block of ``length`` whose first cell is ``first`` high and whose heights grow
    geometrically (ratio <= MAX_GROWTH) up to at most ``largest``. Returns (n, last/first)."""
    if length <= 0:
        raise ValueError("block length must be > 0")
    if length <= first * (1 + MAX_GROWTH) or largest <= first:
        return max(1, round(length / first)), 1.0
    for n in range(2, 100000):
        if n * first >= length:
            return n, 1.0  # uniform cells slightly smaller than `first`
        s_max = first * (MAX_GROWTH**n - 1) / (MAX_GROWTH - 1)
        if s_max < length:
            continue
        lo, hi = 1.0, MAX_GROWTH
        for _ in range(200):
            q = 0.5 * (lo + hi)
            if first * (q**n - 1) / (q - 1) < length:
                lo = q
            else:
                hi = q
        q = 0.5 * (lo + hi)
        if first * q ** (n - 1) <= largest * (1 + 1e-9):
            return n, q ** (n - 1)
    raise ValueError("no grading found")


@dataclass
class Lattice:
    """The blockMesh lattice: cell counts and z layout of the three blocks."""

    nx: int
    ny: int
    n_below: int
    n_fabric: int
    n_above: int
    grading_below: float  # blockMesh expansion ratio (last/first cell along +z)
    grading_above: float

    @property
    def nz(self) -> int:
        return self.n_below + self.n_fabric + self.n_above

    @property
    def cells(self) -> int:
        return self.nx * self.ny * self.nz


def make_lattice(s: FlowSetup) -> Lattice:
    h = s.cell_size_m
    nx = max(1, round(s.size_x_m / h))
    ny = max(1, round(s.size_y_m / h))
    nf = max(1, round((s.fabric_hi_z_m - s.fabric_lo_z_m) / h))
    hz = (s.fabric_hi_z_m - s.fabric_lo_z_m) / nf
    nb, eb = geometric_cells(s.fabric_lo_z_m, hz, s.max_cell_height_m)
    na, ea = geometric_cells(s.top_z_m - s.fabric_hi_z_m, hz, s.max_cell_height_m)
    return Lattice(nx, ny, nb, nf, na, 1.0 / eb, ea)


@dataclass
class FlowResult:
    lattice_x: FloatArray
    lattice_y: FloatArray
    lattice_z: FloatArray
    U: npt.NDArray[np.float64]  # (nx, ny, nz, 3) on the lattice, 0 in removed cells
    p: npt.NDArray[np.float64]  # (nx, ny, nz) Pa, NaN in removed cells
    fluid: npt.NDArray[np.bool_]
    solid_fraction: npt.NDArray[np.float32]
    q_top_m3_s: float
    q_bottom_m3_s: float
    iterations: int
    converged: bool
    fluid_cells: int
    lattice_cells: int
    wall_times_s: dict[str, float]
    final_residuals: dict[str, float]

    @property
    def imbalance(self) -> float:
        return abs(self.q_top_m3_s - self.q_bottom_m3_s) / max(abs(self.q_bottom_m3_s), 1e-300)


# --------------------------------------------------------------------------------------------
# Case set-up through foamlib


def _write_block_mesh(case: Path, s: FlowSetup, lat: Lattice) -> None:
    from foamlib import FoamFile

    zs = [0.0, s.fabric_lo_z_m, s.fabric_hi_z_m, s.top_z_m]
    lx, ly = s.size_x_m, s.size_y_m
    verts = [[x, y, z] for z in zs for (x, y) in ((0.0, 0.0), (lx, 0.0), (lx, ly), (0.0, ly))]
    blocks: list[object] = []
    for b, (nz, grading) in enumerate(
        ((lat.n_below, lat.grading_below), (lat.n_fabric, 1.0), (lat.n_above, lat.grading_above))
    ):
        v = [4 * b + i for i in range(8)]
        blocks += ["hex", v, [lat.nx, lat.ny, nz], "simpleGrading", [1, 1, float(grading)]]
    with FoamFile(case / "system" / "blockMeshDict") as f:
        f["scale"] = 1
        f["vertices"] = verts
        f["blocks"] = blocks


def _write_solid_field(case: Path, frac: FloatArray) -> None:
    from foamlib import FoamFieldFile

    f = FoamFieldFile(case / "0" / "solid")
    f.dimensions = [0, 0, 0, 0, 0, 0, 0]
    f.internal_field = np.asarray(frac, dtype=np.float64)
    f.boundary_field = {
        "top": {"type": "zeroGradient"},
        "bottom": {"type": "zeroGradient"},
        "sides": {"type": "symmetry"},
        "yarns": {"type": "zeroGradient"},
    }


def _reset_fields(case: Path, s: FlowSetup) -> None:
    from foamlib import FoamFieldFile

    zero = case / "0"
    shutil.rmtree(zero, ignore_errors=True)
    shutil.copytree(case / "0.orig", zero)
    with FoamFieldFile(zero / "p") as p:
        p.boundary_field["top"]["value"] = s.delta_p_Pa / s.density_kg_m3


def _set_controls(case: Path, s: FlowSetup, lat: Lattice) -> None:
    from foamlib import FoamFile

    with FoamFile(case / "system" / "controlDict") as c:
        c["endTime"] = int(s.max_iterations)
        c["writeInterval"] = int(s.max_iterations)
        c["writeFormat"] = "ascii"
    with FoamFile(case / "system" / "fvSolution") as f:
        f["SIMPLE"]["residualControl"]["p"] = float(s.residual_tolerance)
        f["SIMPLE"]["residualControl"]["U"] = float(s.residual_tolerance)
    with FoamFile(case / "constant" / "transportProperties") as t:
        t["nu"] = s.viscosity_Pa_s / s.density_kg_m3
    with FoamFile(case / "system" / "decomposeParDict") as d:
        d["numberOfSubdomains"] = int(s.ranks)
        d["coeffs"]["n"] = [int(s.ranks), 1, 1]
    # A point inside the topmost layer of cells, away from faces: seed of the connected fluid.
    hx, hy = s.size_x_m / lat.nx, s.size_y_m / lat.ny
    seed = [(lat.nx // 2 + 0.5) * hx, (lat.ny // 2 + 0.5) * hy, s.top_z_m - 0.25 * s.cell_size_m]
    with FoamFile(case / "system" / "topoSetDict") as t:
        actions = t["actions"]
        actions[1]["insidePoints"] = [seed]
        t["actions"] = actions


def _read_internal(path: Path) -> npt.NDArray[np.float64]:
    from foamlib import FoamFieldFile

    return np.asarray(FoamFieldFile(path).internal_field, dtype=np.float64)


def _patch_sum(path: Path, patch: str) -> float:
    from foamlib import FoamFieldFile

    val = FoamFieldFile(path).boundary_field[patch]["value"]
    return float(np.sum(np.asarray(val, dtype=np.float64)))


def _solid_fraction(img: VoxelImage, s: FlowSetup, lat: Lattice) -> npt.NDArray[np.float32]:
    """Solid volume fraction of each fabric-zone lattice cell, from the voxels whose centres it
    holds. Shape (nx, ny, n_fabric)."""
    hx, hy = s.size_x_m / lat.nx, s.size_y_m / lat.ny
    hz = (s.fabric_hi_z_m - s.fabric_lo_z_m) / lat.n_fabric
    ix = np.clip(np.floor((img.centres(0) - 0.0) / hx).astype(np.int64), 0, lat.nx - 1)
    iy = np.clip(np.floor((img.centres(1) - 0.0) / hy).astype(np.int64), 0, lat.ny - 1)
    iz = np.clip(np.floor((img.centres(2) - s.fabric_lo_z_m) / hz).astype(np.int64), 0, lat.n_fabric - 1)
    flat = (ix[:, None, None] * lat.ny + iy[None, :, None]) * lat.n_fabric + iz[None, None, :]
    n = lat.nx * lat.ny * lat.n_fabric
    total = np.bincount(flat.ravel(), minlength=n).astype(np.float64)
    solid = np.bincount(flat.ravel(), weights=img.solid.ravel().astype(np.float64), minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(total > 0, solid / np.maximum(total, 1), 0.0)
    return frac.reshape(lat.nx, lat.ny, lat.n_fabric).astype(np.float32)


def _layers(z: FloatArray, tol: float) -> FloatArray:
    """Distinct heights of cell centres (values closer than ``tol`` are one layer)."""
    zs = np.sort(z)
    starts = np.concatenate([[0], np.nonzero(np.diff(zs) > tol)[0] + 1])
    return np.asarray(np.add.reduceat(zs, starts) / np.diff(np.append(starts, len(zs))))


def _nearest_layer(centres: FloatArray, z: FloatArray, tol: float) -> npt.NDArray[np.int64]:
    k = np.clip(np.searchsorted(centres, z), 1, len(centres) - 1) if len(centres) > 1 else np.zeros(len(z), dtype=np.int64)
    if len(centres) > 1:
        k = np.where(np.abs(centres[k - 1] - z) < np.abs(centres[k] - z), k - 1, k)
    if np.any(np.abs(centres[k] - z) > tol):
        raise StageError("cell centres do not lie on the blockMesh lattice")
    return np.asarray(k, dtype=np.int64)


_CONVERGED = re.compile(r"SIMPLE solution converged in (\d+) iterations")
_TIME = re.compile(r"^Time = (\d+)\s*$", re.MULTILINE)
_RESIDUAL = re.compile(r"Solving for (Ux|Uy|Uz|p), Initial residual = ([0-9.eE+-]+)")


def run_flow_case(
    s: FlowSetup,
    img: VoxelImage,
    work: Path,
    *,
    oversubscribe: bool = False,
    show_progress: bool | None = None,
) -> FlowResult:
    """Mesh, solve and read back one flow case in ``work`` (``work/case`` is replaced)."""
    lat = make_lattice(s)
    work = work.resolve()
    case = work / CASE_DIR
    shutil.rmtree(case, ignore_errors=True)
    shutil.copytree(template_dir(), case)
    (case / "0").mkdir(exist_ok=True)
    for f in (case / "0.orig").iterdir():
        shutil.copy(f, case / "0" / f.name)
    _write_block_mesh(case, s, lat)
    _set_controls(case, s, lat)
    times: dict[str, float] = {}

    def tool(cmd: list[str], name: str, ranks: int = 1, progress: object = None) -> None:
        res = run(
            cmd, work / f"log.{name}", cwd=case, ranks=ranks, progress=progress,  # type: ignore[arg-type]
            oversubscribe=oversubscribe, description=name, show_progress=show_progress,
        )  # fmt: skip
        times[name] = res.elapsed_s

    tool(["blockMesh"], "blockMesh")
    tool(["postProcess", "-func", "writeCellCentres", "-time", "0"], "writeCellCentres")
    C = _read_internal(case / "0" / "C").reshape(-1, 3)
    if len(C) != lat.cells:
        raise StageError(f"blockMesh made {len(C)} cells, expected {lat.cells}")
    hx, hy = s.size_x_m / lat.nx, s.size_y_m / lat.ny
    ci = np.clip(np.floor(C[:, 0] / hx).astype(np.int64), 0, lat.nx - 1)
    cj = np.clip(np.floor(C[:, 1] / hy).astype(np.int64), 0, lat.ny - 1)
    tol = 1e-3 * s.cell_size_m
    z_centres = _layers(C[:, 2], tol)
    if len(z_centres) != lat.nz:
        raise StageError(f"found {len(z_centres)} cell layers, expected {lat.nz}")
    ck = _nearest_layer(z_centres, C[:, 2], tol)
    frac_f = _solid_fraction(img, s, lat)
    frac = np.zeros((lat.nx, lat.ny, lat.nz), dtype=np.float32)
    frac[:, :, lat.n_below : lat.n_below + lat.n_fabric] = frac_f
    _write_solid_field(case, frac[ci, cj, ck])
    tool(["topoSet"], "topoSet")
    tool(["subsetMesh", "fluid", "-patch", "yarns", "-overwrite"], "subsetMesh")
    # subsetMesh also subset the cell-centre field: the centres of the kept cells, in the new
    # mesh's order, locate each fluid cell on the lattice.
    Cf = _read_internal(case / "0" / "C").reshape(-1, 3)
    fi = np.clip(np.floor(Cf[:, 0] / hx).astype(np.int64), 0, lat.nx - 1)
    fj = np.clip(np.floor(Cf[:, 1] / hy).astype(np.int64), 0, lat.ny - 1)
    fk = _nearest_layer(z_centres, Cf[:, 2], tol)
    _reset_fields(case, s)
    for stale in case.glob("processor*"):
        shutil.rmtree(stale)
    progress = openfoam_progress(0.0, float(s.max_iterations))
    if s.ranks > 1:
        tool(["decomposePar", "-force"], "decomposePar")
        tool(["simpleFoam", "-parallel"], "simpleFoam", ranks=s.ranks, progress=progress)
        tool(["reconstructPar", "-latestTime"], "reconstructPar")
    else:
        tool(["simpleFoam"], "simpleFoam", progress=progress)
    log = (work / "log.simpleFoam").read_text(errors="replace")
    m = _CONVERGED.search(log)
    steps = [int(t) for t in _TIME.findall(log)]
    iterations = int(m.group(1)) if m else (steps[-1] if steps else 0)
    residuals: dict[str, float] = {}
    for name, val in _RESIDUAL.findall(log):
        residuals[name] = float(val)
    times_dirs = sorted(
        (d for d in case.iterdir() if d.is_dir() and _is_number(d.name) and float(d.name) > 0),
        key=lambda d: float(d.name),
    )
    if not times_dirs:
        raise StageError(f"simpleFoam wrote no solution in {case}")
    last = times_dirs[-1]
    U = _read_internal(last / "U").reshape(-1, 3)
    p = _read_internal(last / "p").ravel()
    if p.size == 1:
        p = np.full(len(Cf), float(p[0]))
    if U.shape[0] == 1:
        U = np.repeat(U, len(Cf), axis=0)
    q_top = -_patch_sum(last / "phi", "top")
    q_bottom = _patch_sum(last / "phi", "bottom")
    Ul = np.zeros((lat.nx, lat.ny, lat.nz, 3))
    pl = np.full((lat.nx, lat.ny, lat.nz), np.nan)
    fluid = np.zeros((lat.nx, lat.ny, lat.nz), dtype=bool)
    idx = (fi, fj, fk)
    Ul[idx] = U
    pl[idx] = p * s.density_kg_m3
    fluid[idx] = True
    return FlowResult(
        lattice_x=(np.arange(lat.nx) + 0.5) * hx,
        lattice_y=(np.arange(lat.ny) + 0.5) * hy,
        lattice_z=z_centres,
        U=Ul,
        p=pl,
        fluid=fluid,
        solid_fraction=frac,
        q_top_m3_s=q_top,
        q_bottom_m3_s=q_bottom,
        iterations=iterations,
        converged=m is not None,
        fluid_cells=int(len(Cf)),
        lattice_cells=lat.cells,
        wall_times_s=times,
        final_residuals=residuals,
    )


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


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
    centres take the boundary values). Returns (grid, U (nx, ny, nz, 3), p (nx, ny, nz))."""
    from scipy.interpolate import RegularGridInterpolator

    h = s.sample_spacing_m or s.cell_size_m
    ext = np.array([s.size_x_m, s.size_y_m, s.top_z_m])
    n = np.maximum(1, np.round(ext / h)).astype(int)
    sp = ext / n
    grid = RegularGrid(0.5 * sp, sp, (int(n[0]), int(n[1]), int(n[2])))
    axes = (res.lattice_x, res.lattice_y, res.lattice_z)
    pts = [np.clip(grid.axis(a), axes[a][0], axes[a][-1]) for a in range(3)]
    P = np.stack(np.meshgrid(*pts, indexing="ij"), axis=-1).reshape(-1, 3)
    U = np.empty((P.shape[0], 3))
    for c in range(3):
        itp = RegularGridInterpolator(axes, res.U[..., c], method="linear")
        U[:, c] = itp(P)
    p_filled = np.where(np.isnan(res.p), 0.0, res.p)
    w = RegularGridInterpolator(axes, res.fluid.astype(np.float64), method="linear")(P)
    pv = RegularGridInterpolator(axes, p_filled, method="linear")(P)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.where(w > 0, pv / np.maximum(w, 1e-300), np.nan)  # fluid-weighted average
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
    sv = h5.create_group("solver")
    sv.attrs["application"] = "simpleFoam (laminar, SIMPLEC)"
    sv.attrs["iterations"] = res.iterations
    sv.attrs["converged"] = res.converged
    sv.attrs["lattice_cells"] = res.lattice_cells
    sv.attrs["fluid_cells"] = res.fluid_cells
    sv.attrs["ranks"] = s.ranks
    for k, v in res.wall_times_s.items():
        sv.attrs[f"wall_time_{k}_s"] = v
    for k, v in res.final_residuals.items():
        sv.attrs[f"final_initial_residual_{k}"] = v
    for k, v in asdict(s).items():
        sv.attrs[f"setup_{k}"] = v if v is not None else "none"


def write_png(path: Path, s: FlowSetup, res: FlowResult, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 5), gridspec_kw={"width_ratios": [1.4, 1]})
    j = len(res.lattice_y) // 2
    w = np.where(res.fluid[:, j, :], -res.U[:, j, :, 2], np.nan)
    zlo = s.fabric_lo_z_m - 0.5e-3
    zhi = min(s.top_z_m, s.fabric_hi_z_m + 0.5e-3)
    X, Z = np.meshgrid(res.lattice_x * 1e3, res.lattice_z * 1e3, indexing="ij")
    ax = axes[0]
    pc = ax.pcolormesh(X, Z, w, shading="nearest", cmap="viridis")
    ax.pcolormesh(X, Z, np.where(res.fluid[:, j, :], np.nan, 1.0), shading="nearest", cmap="Greys", vmin=0, vmax=1.5)
    ax.set_ylim(zlo * 1e3, zhi * 1e3)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title(f"downward velocity -U_z at y = {res.lattice_y[j] * 1e3:.3f} mm (grey: yarns)")
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
    code_version = 1

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
            top = (
                fab.lower_side_z_m + fab.md_diameter_m * 3 + fab.cd_top_diameter_m
                + fab.cd_bottom_diameter_m + 4 * fab.clearance_m + flow.height_above_fabric_m
            )  # fmt: skip
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

    def _fabric_h5(self, ctx: StageContext) -> Path:
        return ctx.scene.output_path / FabricStage.folder / FabricStage.products[0]

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        hashes = super().input_hashes(ctx)
        fab = self._fabric_h5(ctx)
        hashes["fabric_h5"] = file_hash(fab) if fab.is_file() else "missing"
        parts = []
        for f in sorted(template_dir().rglob("*")):
            if f.is_file():
                parts.append(f"{f.relative_to(template_dir())}:{file_hash(f)}")
        hashes["case_template"] = text_hash("\n".join(parts))
        return hashes

    def produce(
        self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str]
    ) -> None:
        fab_path = self._fabric_h5(ctx)
        if not fab_path.is_file():
            raise StageError(f"flow needs {fab_path}: run `fiberform fabric` first")
        flow = ctx.scene.flow
        assert flow is not None
        fluid = ctx.scene.fluid or FluidSection()
        img = read_fabric_image(fab_path)
        s = FlowSetup.from_scene(img, flow, fluid)
        start = time.monotonic()
        res = run_flow_case(
            s, img, self.stage_dir(ctx), oversubscribe=ctx.oversubscribe,
            show_progress=ctx.show_progress,
        )  # fmt: skip
        grid, Ug, pg = sample_grid(res, s)
        write_flow_h5(h5, s, res, grid, Ug, pg)
        h5["solver"].attrs["wall_time_total_s"] = time.monotonic() - start
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
