# SPDX-License-Identifier: GPL-3.0-or-later
"""Steady flow through a box holding a solid layer, with stock OpenFOAM (shared by the stages
``flow`` and ``permeability``).

Domain: [0, Lx] x [0, Ly] x [0, H] with a solid zone [zone_lo, zone_hi] in z (the fabric, or the
fabric plus the sheet's fibers). Boundary conditions of Kettil 2016 eq. 3.1-3.3: symmetry on the four
vertical sides, kinematic pressure delta_p / rho at the top and 0 at the bottom with zero-gradient
velocity there, no-slip on the solid (wall patch ``yarns``). Solver: stock ``simpleFoam``
(laminar steady Navier-Stokes, SIMPLEC), optionally on several ranks through ``decomposePar``.

Mesh: ``blockMesh`` builds a box of three blocks stacked in z; the zone has cells of
``cell_size_m`` (in z: the zone height over ``zone_layers``, or over the whole number of cells
nearest to height / ``cell_size_m``), the blocks above and below are graded geometrically up to
``max_cell_height_m``. The caller supplies the solid volume fraction of each zone cell (a
:data:`SolidFraction` callback); the cells to remove are those with fraction >= 1/2 or, with
``preserve_volume`` (both stages), the ones :func:`volume_preserving` picks; ``topoSet`` selects
the others that are face-connected to the top and ``subsetMesh`` keeps only those, turning the
exposed faces into the wall patch ``yarns`` (a "staircase" wall; the resolution trade is measured
in docs/bench/flow.md and docs/stages/permeability.md).

The case template is ``openfoam-cases/fabric-flow``; every value that changes is written through
foamlib from validated numbers (no text from a scene reaches a case file).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import shutil
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ._versions import repo_root
from .errors import ConfigError, StageError
from .provenance import atomic_write_text, file_hash, text_hash
from .runner import Program, openfoam_progress, run

__all__ = [
    "CASE_DIR",
    "DRAINAGE_FO",
    "is_time_name",
    "prepare_coupled_case",
    "read_patch_history",
    "BoxSetup",
    "CaseResult",
    "Lattice",
    "PreparedCase",
    "SolidFraction",
    "case_key",
    "collect_case",
    "load_prepared",
    "prepare_or_resume",
    "resume_point",
    "solver_wall_time",
    "solver_program",
    "geometric_cells",
    "make_lattice",
    "run_case",
    "template_dir",
    "template_hash",
    "volume_preserving",
    "plot_section",
    "write_solver_record",
]

CASE_DIR = "case"
TEMPLATE = "fabric-flow"
#: Largest growth ratio of neighbouring cell heights in the graded blocks.
MAX_GROWTH = 1.2
#: Name of the function object that records the outflow through ``bottom`` at every iteration.
FLOW_RATE_FO = "flowRateBottom"
FLOW_RATE_STOP_FO = "flowRateConverged"  # ends a recorded solve once its outflow converged
#: the shared library of fiberform's function objects, relative to the build directory
FUNCTION_OBJECTS_LIB = "lib/libfiberformFunctionObjects.so"
SAFE_LIBRARY_PATH = re.compile(r"/[A-Za-z0-9._+/-]+")
#: Iterations between the time directories simpleFoam writes while it runs (the points a killed
#: run resumes from); ``purgeWrite`` keeps the last two, so a half-written last one leaves the
#: one before it.
WRITE_EVERY_ITERATIONS = 100

FloatArray = npt.NDArray[np.float64]


def template_dir() -> Path:
    return repo_root() / "openfoam-cases" / TEMPLATE


def template_hash() -> str:
    """Hash of every file of the case template (an input of the stages that use it)."""
    parts = []
    for f in sorted(template_dir().rglob("*")):
        if f.is_file():
            parts.append(f"{f.relative_to(template_dir())}:{file_hash(f)}")
    return text_hash("\n".join(parts))


@dataclass(frozen=True)
class BoxSetup:
    """Numbers that define one steady flow run (SI units)."""

    size_x_m: float
    size_y_m: float
    fabric_lo_z_m: float  # lower end of the solid zone
    fabric_hi_z_m: float  # upper end of the solid zone
    top_z_m: float
    cell_size_m: float
    max_cell_height_m: float
    delta_p_Pa: float
    density_kg_m3: float
    viscosity_Pa_s: float
    max_iterations: int = 3000
    residual_tolerance: float = 1e-6
    ranks: int = 1
    #: cell layers of the zone (None: its height / cell_size_m, rounded); the permeability stage
    #: sets it so that a fabric is cut into the same layers under every sheet
    zone_layers: int | None = None
    #: end the solve at the first iteration whose last ``stop_window`` outflows vary by at most
    #: ``stop_tolerance`` of their mean (fiberform's function object flowRateConvergence, from the
    #: shared library ``stop_library``, an absolute path); 0: run to max_iterations
    stop_window: int = 0
    stop_tolerance: float = 0.0
    stop_library: str = ""


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


def make_lattice(s: BoxSetup) -> Lattice:
    h = s.cell_size_m
    nx = max(1, round(s.size_x_m / h))
    ny = max(1, round(s.size_y_m / h))
    nf = s.zone_layers or max(1, round((s.fabric_hi_z_m - s.fabric_lo_z_m) / h))
    hz = (s.fabric_hi_z_m - s.fabric_lo_z_m) / nf
    nb, eb = geometric_cells(s.fabric_lo_z_m, hz, s.max_cell_height_m)
    na, ea = geometric_cells(s.top_z_m - s.fabric_hi_z_m, hz, s.max_cell_height_m)
    return Lattice(nx, ny, nb, nf, na, 1.0 / eb, ea)


#: Solid volume fraction (0..1) of each zone cell, shape (nx, ny, n_fabric), from the setup and
#: the lattice. Zone cell (i, j, k) spans [i hx, (i+1) hx] x [j hy, (j+1) hy] x
#: [zone_lo + k hz, zone_lo + (k+1) hz].
SolidFraction = Callable[[BoxSetup, Lattice], npt.NDArray[np.float32]]


@dataclass
class CaseResult:
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
    #: Iteration numbers and outflow through ``bottom`` (m^3/s) at each; empty unless recorded.
    history_iteration: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    history_q_bottom_m3_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    #: Iteration the solve continued from (0: not resumed; > 0: a killed run's time directory).
    resumed_from_iteration: int = 0

    @property
    def imbalance(self) -> float:
        return abs(self.q_top_m3_s - self.q_bottom_m3_s) / max(abs(self.q_bottom_m3_s), 1e-300)


# --------------------------------------------------------------------------------------------
# Case set-up through foamlib


def _write_block_mesh(case: Path, s: BoxSetup, lat: Lattice) -> None:
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


def _reset_fields(case: Path, s: BoxSetup) -> None:
    from foamlib import FoamFieldFile

    zero = case / "0"
    shutil.rmtree(zero, ignore_errors=True)
    shutil.copytree(case / "0.orig", zero)
    with FoamFieldFile(zero / "p") as p:
        p.boundary_field["top"]["value"] = s.delta_p_Pa / s.density_kg_m3


def patch_flux_sum(patch: str) -> dict[str, Any]:
    """A function object writing sum(phi) over ``patch`` after every iteration or time step."""
    return {
        "type": "surfaceFieldValue",
        "libs": ['"libfieldFunctionObjects.so"'],
        "regionType": "patch",
        "name": patch,
        "operation": "sum",
        "fields": ["phi"],
        "writeFields": False,
        "log": False,
        "writeControl": "timeStep",
        "writeInterval": 1,
    }


def flow_rate_stop(patch: str, window: int, tolerance: float, library: str) -> dict[str, Any]:
    """A function object ending the solve once sum(phi) over ``patch`` varied by at most
    ``tolerance`` of its mean over the last ``window`` iterations (flowRateConvergence in the
    shared library ``library``, coupling/functionObjects/). ``library`` must be an absolute path
    of plain characters (it is written into controlDict)."""
    if not SAFE_LIBRARY_PATH.fullmatch(library):
        raise ConfigError(f"the function-object library path {library!r} must be absolute and "
                          "contain only letters, digits and . _ + - / (it goes into controlDict); "
                          "build fiberform in such a directory")
    if not (int(window) >= 2 and float(tolerance) > 0.0):
        raise ValueError(f"flow_rate_stop: window {window} (>= 2) and tolerance {tolerance} (> 0)")
    return {
        "type": "flowRateConvergence",
        "libs": [f'"{library}"'],
        "patch": patch,
        "window": int(window),
        "tolerance": float(tolerance),
    }


def seed_flow_rate_stop(case: Path, start: int, window: int) -> None:
    """A resumed solve's stop criterion starts from the recorded outflows of the last ``window``
    iterations up to ``start`` (the killed run's history), so that the resumed solve ends at the
    iteration an uninterrupted one would."""
    from foamlib import FoamFile

    its, q = read_patch_history(case, FLOW_RATE_FO)
    earlier = [float(v) for v in q[its <= start + 0.5][-int(window):] if math.isfinite(v)]
    with FoamFile(case / "system" / "controlDict") as c:
        c["functions"][FLOW_RATE_STOP_FO]["initial"] = earlier


def _set_controls(case: Path, s: BoxSetup, lat: Lattice, record_flow_rate: bool) -> None:
    from foamlib import FoamFile

    with FoamFile(case / "system" / "controlDict") as c:
        c["endTime"] = int(s.max_iterations)
        c["writeInterval"] = min(WRITE_EVERY_ITERATIONS, int(s.max_iterations))
        c["purgeWrite"] = 2
        c["writeFormat"] = "ascii"
        if record_flow_rate:
            # sum(phi) over the outlet after every SIMPLE iteration (the flow-rate history)
            functions: dict[str, Any] = {FLOW_RATE_FO: patch_flux_sum("bottom")}
            if s.stop_window > 0:
                functions[FLOW_RATE_STOP_FO] = flow_rate_stop("bottom", s.stop_window, s.stop_tolerance,
                                                              s.stop_library)
            c["functions"] = functions
    with FoamFile(case / "system" / "fvSolution") as f:
        f["SIMPLE"]["residualControl"]["p"] = float(s.residual_tolerance)
        f["SIMPLE"]["residualControl"]["U"] = float(s.residual_tolerance)
    with FoamFile(case / "constant" / "transportProperties") as t:
        t["nu"] = s.viscosity_Pa_s / s.density_kg_m3
    set_decomposition(case, s.ranks)
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


def _read_flow_rate_history(case: Path) -> tuple[npt.NDArray[np.int64], FloatArray]:
    """(iterations, sum(phi) over ``bottom``) written by the function object, m^3/s (a resumed
    run's files: :func:`read_patch_history`)."""
    its, qs = read_patch_history(case, FLOW_RATE_FO)
    return np.rint(its).astype(np.int64), qs


#: Resistances within this factor of each other share one cellZone (one porosity source).
ZONE_RATIO = 1.05


def _write_porous_zones(case: Path, d_cells: FloatArray) -> bool:
    """Bin the cells' Darcy resistances d [1/m^2] (0: none) in ratios of ZONE_RATIO, write the
    field ``resistance`` to 0/, a topoSetDict.porous that makes one cellZone per bin and
    constant/fvOptions with one explicitPorositySource (DarcyForchheimer, isotropic d = the bin's
    geometric mean, f = 0) per zone. Returns False when no cell has a resistance."""
    from foamlib import FoamFieldFile, FoamFile

    pos = d_cells[d_cells > 0]
    if len(pos) == 0:
        return False
    lo = float(pos.min())
    nbins = int(math.floor(math.log(float(pos.max()) / lo) / math.log(ZONE_RATIO))) + 1
    f = FoamFieldFile(case / "0" / "resistance")
    f.dimensions = [0, -2, 0, 0, 0, 0, 0]
    f.internal_field = np.asarray(d_cells, dtype=np.float64)
    f.boundary_field = {p: {"type": "zeroGradient"} for p in ("top", "bottom", "yarns")}
    f.boundary_field["sides"] = {"type": "symmetry"}
    actions: list[dict[str, object]] = []
    options: dict[str, object] = {}
    used = np.floor(np.log(pos / lo) / math.log(ZONE_RATIO)).astype(np.int64)
    for b in sorted(set(used.tolist())):
        a, c = lo * ZONE_RATIO**b, lo * ZONE_RATIO ** (b + 1)
        lo_edge = a * (1 - 1e-9) if b > 0 else a * 0.5
        hi_edge = c * (1 - 1e-9) if b < nbins - 1 else c * 2.0
        name = f"porous{b}"
        actions.append({"name": name, "type": "cellSet", "action": "new", "source": "fieldToCell",
                        "field": "resistance", "min": lo_edge, "max": hi_edge})  # fmt: skip
        actions.append({"name": name, "type": "cellZoneSet", "action": "new",
                        "source": "setToCellZone", "set": name})  # fmt: skip
        d = math.sqrt(a * c)
        options[name] = {
            "type": "explicitPorositySource", "active": True,
            "explicitPorositySourceCoeffs": {
                "type": "DarcyForchheimer", "selectionMode": "cellZone", "cellZone": name,
                "DarcyForchheimerCoeffs": {
                    "d": [d, d, d], "f": [0.0, 0.0, 0.0],
                    "coordinateSystem": {"type": "cartesian", "origin": [0.0, 0.0, 0.0],
                                         "rotation": {"type": "axes", "e1": [1.0, 0.0, 0.0],
                                                      "e2": [0.0, 1.0, 0.0]}},
                },
            },
        }  # fmt: skip
    header = {"version": 2.0, "format": "ascii", "class": "dictionary"}
    with FoamFile(case / "system" / "topoSetDict.porous") as t:
        t["FoamFile"] = {**header, "object": "topoSetDict"}
        t["actions"] = actions
    with FoamFile(case / "constant" / "fvOptions") as o:
        o["FoamFile"] = {**header, "object": "fvOptions"}
        for k, v in options.items():
            o[k] = v
    return True


def volume_preserving(frac: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """0/1 solid indicator of equal-volume cells: the m cells with the largest solid fractions,
    m = round(sum of the fractions), so the removed volume equals the sampled solid volume (the
    rule "fraction >= 1/2" overestimates the solid of thin cylinders by several percent at 8
    cells across: 0.107 instead of 0.1 for a square array at solid fraction 0.1)."""
    flat = np.asarray(frac, dtype=np.float64).ravel()
    m = int(round(float(flat.sum())))
    out = np.zeros(flat.size, dtype=np.float32)
    if m > 0:
        out[np.argsort(-flat, kind="stable")[:m]] = 1.0
    return out.reshape(np.shape(frac))


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


def is_time_name(text: str) -> bool:
    """Whether a folder name is a number (an OpenFOAM time folder)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


_CONVERGED = re.compile(r"SIMPLE solution converged in (\d+) iterations")
_TIME = re.compile(r"^Time = (\d+)\s*$", re.MULTILINE)
_RESIDUAL = re.compile(r"Solving for (Ux|Uy|Uz|p), Initial residual = ([0-9.eE+-]+)")


#: Files every time directory simpleFoam writes holds (the state it restarts from).
TIME_FILES = ("U", "p", "phi", "uniform/time")
#: The case record of a prepared case (inputs, setup, cell map), written last by prepare_or_resume.
CASE_RECORD, CASE_MAP = "fiberform-case.json", "fiberform-case.npz"
#: The solver log of a resumed run's earlier parts.
EARLIER_LOG = "log.simpleFoam.earlier"
_FOOTER = b"// ************************************************************************* //"


@dataclass(frozen=True)
class PreparedCase:
    """A meshed case with its initial fields: where each fluid cell sits on the lattice."""

    work: Path
    lattice: Lattice
    z_centres: FloatArray
    cell_index: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]
    solid_fraction: npt.NDArray[np.float32]
    wall_times_s: dict[str, float]
    #: iteration the solver starts from (0: a fresh solve; > 0: resumed from that time directory)
    start_iteration: int = 0


def _tool(work: Path, case: Path, cmd: list[str], name: str, times: dict[str, float], ranks: int = 1,
          progress: object = None, oversubscribe: bool = False, show_progress: bool | None = None) -> None:
    res = run(
        cmd, work / f"log.{name}", cwd=case, ranks=ranks, progress=progress,  # type: ignore[arg-type]
        oversubscribe=oversubscribe, description=name, show_progress=show_progress,
    )  # fmt: skip
    times[name] = res.elapsed_s


def case_key(s: BoxSetup, inputs: Mapping[str, str], **flags: object) -> str:
    """Identity of a prepared case: the stage's input hashes, the setup and the case options. A
    case directory is resumed only by a run with the same key."""
    return text_hash(json.dumps({"inputs": dict(inputs), "setup": asdict(s), "flags": flags},
                                sort_keys=True, default=str))


def _write_record(case: Path, key: str, times: Mapping[str, float], start_iteration: int) -> None:
    atomic_write_text(case / CASE_RECORD, json.dumps({"key": key, "wall_times_s": dict(times),
                                                      "start_iteration": int(start_iteration)}) + "\n")


def solver_program(work: Path, ranks: int, max_iterations: int) -> Program:
    """The solver's program line for the case in ``work`` (run in ``work/case``, output to
    ``work/log.simpleFoam``; ``startFrom latestTime`` makes the same line start a prepared case or
    continue a resumed one)."""
    work = work.resolve()
    return Program(("simpleFoam", "-parallel") if ranks > 1 else ("simpleFoam",), int(ranks), work / CASE_DIR,
                   work / "log.simpleFoam", openfoam_progress(0.0, float(max_iterations)))


def _complete_time(d: Path) -> bool:
    """Every file of TIME_FILES present, ending in OpenFOAM's closing divider, and readable."""
    from foamlib import FoamFieldFile

    for name in TIME_FILES:
        f = d / name
        try:
            with open(f, "rb") as fh:
                fh.seek(max(0, f.stat().st_size - 200))
                if _FOOTER not in fh.read():
                    return False
            if "/" not in name:
                FoamFieldFile(f).internal_field  # noqa: B018 - parses the values
        except Exception:  # missing, cut short or unparsable: not a state to trust  # noqa: BLE001
            return False
    return True


def _time_dirs(d: Path) -> dict[float, Path]:
    return {float(t.name): t for t in d.iterdir() if t.is_dir() and is_time_name(t.name) and float(t.name) > 0}


def resume_point(work: Path, key: str) -> int | None:
    """The iteration a killed solve in ``work/case`` continues from, or None (start over): the case
    must be prepared with the same ``key`` (inputs, setup, options); the latest time directory that
    is complete (:func:`_complete_time`) in the case or in every processor folder wins (0: the
    prepared initial state). Later, incomplete time directories are deleted, so simpleFoam's
    ``startFrom latestTime`` starts from the chosen one."""
    case = work.resolve() / CASE_DIR
    try:
        rec = json.loads((case / CASE_RECORD).read_text())
    except (OSError, ValueError):
        return None
    if not key or rec.get("key") != key or not (case / CASE_MAP).is_file():
        return None
    holders = sorted(case.glob("processor[0-9]*")) or [case]
    common: set[float] | None = None
    for h in holders:
        ok = {t for t, d in _time_dirs(h).items() if _complete_time(d)}
        common = ok if common is None else common & ok
    start = max(common or {0.0})
    for h in [case, *holders]:
        for t, d in _time_dirs(h).items():
            if t > start:
                shutil.rmtree(d)
    return round(start)


def load_prepared(work: Path, s: BoxSetup, key: str | None = None) -> PreparedCase:
    """The prepared case in ``work/case`` (cell map and record); with ``key``, StageError unless it
    was prepared from the same inputs."""
    case = work.resolve() / CASE_DIR
    try:
        rec = json.loads((case / CASE_RECORD).read_text())
        with np.load(case / CASE_MAP) as m:
            idx = (m["fi"], m["fj"], m["fk"])
            z, frac = m["z_centres"], m["frac"]
    except (OSError, ValueError, KeyError) as exc:
        raise StageError(f"{case}: no prepared case ({exc}); prepare it first") from None
    if key is not None and rec.get("key") != key:
        raise StageError(f"{case}: prepared from other inputs than the scene's now; prepare it again")
    return PreparedCase(work.resolve(), make_lattice(s), z, idx, frac, dict(rec.get("wall_times_s", {})),
                        int(rec.get("start_iteration", 0)))


def prepare_or_resume(
    s: BoxSetup,
    solid_fraction: SolidFraction,
    work: Path,
    *,
    inputs: Mapping[str, str] | None = None,
    resume: bool = False,
    record_flow_rate: bool = False,
    preserve_volume: bool = False,
    resistance: SolidFraction | None = None,
    oversubscribe: bool = False,
    show_progress: bool | None = None,
) -> PreparedCase:
    """The case of ``work`` ready for :func:`solver_program`. With ``resume``, a killed solve of the
    same inputs (``inputs``: the stage's input hashes, recorded with the case; None: no resume)
    continues from :func:`resume_point` (the killed run's log appended to EARLIER_LOG). Otherwise
    ``work/case`` is written anew: mesh (blockMesh, topoSet, subsetMesh), initial fields, porous
    zones, controls, the decomposition for ``s.ranks`` > 1, then the cell map and the case record
    last, so a case killed while being prepared is never taken for a prepared one. The iteration
    the solve starts from is recorded too."""
    key = "" if inputs is None else case_key(s, inputs, record_flow_rate=record_flow_rate,
                                               preserve_volume=preserve_volume,
                                               resistance=resistance is not None)
    start = resume_point(work, key) if key and resume else None
    if start is not None:
        prep = load_prepared(work, s, key)
        keep_earlier_log(prep.work)
        if record_flow_rate and s.stop_window > 0:
            seed_flow_rate_stop(prep.work / CASE_DIR, start, s.stop_window)
        _write_record(prep.work / CASE_DIR, key, prep.wall_times_s, start)
        return dataclasses.replace(prep, start_iteration=start)
    lat = make_lattice(s)
    work = work.resolve()
    case = work / CASE_DIR
    shutil.rmtree(case, ignore_errors=True)
    (work / EARLIER_LOG).unlink(missing_ok=True)
    shutil.copytree(template_dir(), case)
    (case / "0").mkdir(exist_ok=True)
    for f in (case / "0.orig").iterdir():
        shutil.copy(f, case / "0" / f.name)
    _write_block_mesh(case, s, lat)
    _set_controls(case, s, lat, record_flow_rate)
    times: dict[str, float] = {}

    def tool(cmd: list[str], name: str) -> None:
        _tool(work, case, cmd, name, times, oversubscribe=oversubscribe, show_progress=show_progress)

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
    frac_f = solid_fraction(s, lat)
    if frac_f.shape != (lat.nx, lat.ny, lat.n_fabric):
        raise StageError(f"solid fraction of shape {frac_f.shape}, expected "
                         f"{(lat.nx, lat.ny, lat.n_fabric)}")  # fmt: skip
    frac = np.zeros((lat.nx, lat.ny, lat.nz), dtype=np.float32)
    frac[:, :, lat.n_below : lat.n_below + lat.n_fabric] = frac_f
    removal = frac.copy()
    if preserve_volume:
        removal[:, :, lat.n_below : lat.n_below + lat.n_fabric] = volume_preserving(frac_f)
    _write_solid_field(case, removal[ci, cj, ck])
    tool(["topoSet"], "topoSet")
    tool(["subsetMesh", "fluid", "-patch", "yarns", "-overwrite"], "subsetMesh")
    # subsetMesh also subset the cell-centre field: the centres of the kept cells, in the new
    # mesh's order, locate each fluid cell on the lattice.
    Cf = _read_internal(case / "0" / "C").reshape(-1, 3)
    fi = np.clip(np.floor(Cf[:, 0] / hx).astype(np.int64), 0, lat.nx - 1)
    fj = np.clip(np.floor(Cf[:, 1] / hy).astype(np.int64), 0, lat.ny - 1)
    fk = _nearest_layer(z_centres, Cf[:, 2], tol)
    _reset_fields(case, s)
    if resistance is not None:
        d_zone = np.asarray(resistance(s, lat), dtype=np.float64)
        d_cells = np.zeros(len(Cf))
        inz = (fk >= lat.n_below) & (fk < lat.n_below + lat.n_fabric)
        d_cells[inz] = d_zone[fi[inz], fj[inz], fk[inz] - lat.n_below]
        if _write_porous_zones(case, d_cells):
            tool(["topoSet", "-dict", "system/topoSetDict.porous"], "topoSet.porous")
    for stale in case.glob("processor*"):
        shutil.rmtree(stale)
    shutil.rmtree(case / "postProcessing", ignore_errors=True)
    if s.ranks > 1:
        tool(["decomposePar", "-force"], "decomposePar")
    tmp_map = case / f"{CASE_MAP}.in_progress.npz"
    np.savez(tmp_map, fi=fi, fj=fj, fk=fk, z_centres=z_centres, frac=frac)
    tmp_map.replace(case / CASE_MAP)
    _write_record(case, key, times, 0)
    return PreparedCase(work, lat, z_centres, (fi, fj, fk), frac, times)


def run_case(
    s: BoxSetup,
    solid_fraction: SolidFraction,
    work: Path,
    *,
    record_flow_rate: bool = False,
    preserve_volume: bool = False,
    resistance: SolidFraction | None = None,
    oversubscribe: bool = False,
    show_progress: bool | None = None,
    inputs: Mapping[str, str] | None = None,
    resume: bool = False,
) -> CaseResult:
    """Mesh, solve and read back one case in ``work`` (``work/case`` is replaced; logs
    ``work/log.<tool>``): :func:`prepare_or_resume`, the solver, :func:`collect_case`.
    ``record_flow_rate`` adds the per-iteration outflow history; ``preserve_volume`` removes the
    cells of :func:`volume_preserving` instead of those with solid fraction >= 1/2;
    ``resistance`` gives the Darcy resistance 1/k [1/m^2] of each zone cell (sub-grid solid),
    applied by :func:`_write_porous_zones`; ``inputs``, ``resume``: continue a killed solve of the
    same inputs from its latest complete time directory instead of starting over."""
    prep = prepare_or_resume(s, solid_fraction, work, inputs=inputs, resume=resume,
                             record_flow_rate=record_flow_rate, preserve_volume=preserve_volume,
                             resistance=resistance, oversubscribe=oversubscribe, show_progress=show_progress)
    prog = solver_program(prep.work, s.ranks, s.max_iterations)
    times = dict(prep.wall_times_s)
    _tool(prep.work, prog.cwd, list(prog.argv), "simpleFoam", times, ranks=prog.ranks, progress=prog.progress,
          oversubscribe=oversubscribe, show_progress=show_progress)
    return collect_case(s, prep, times, record_flow_rate=record_flow_rate,
                        oversubscribe=oversubscribe, show_progress=show_progress)


def keep_earlier_log(work: Path) -> None:
    """Append the solver log of the killed run to EARLIER_LOG (the resumed run writes a new one)."""
    log = work / "log.simpleFoam"
    if log.is_file():
        with open(work / EARLIER_LOG, "a", encoding="utf-8", errors="replace") as out:
            out.write(log.read_text(errors="replace"))
            out.write("\n// ---- killed here; resumed from the latest complete time directory ----\n")
        log.unlink()


_CLOCK = re.compile(r"ClockTime = ([0-9.eE+-]+) s")


def solver_wall_time(work: Path) -> float:
    """Wall time of the solver from its log (the last ``ClockTime``, whole seconds), for a solve
    run outside fiberform (a batch job's program line); 0 when the log has none."""
    found = _CLOCK.findall((work / "log.simpleFoam").read_text(errors="replace"))
    return float(found[-1]) if found else 0.0


def collect_case(s: BoxSetup, prep: PreparedCase, times: dict[str, float], *, record_flow_rate: bool = False,
                 oversubscribe: bool = False, show_progress: bool | None = None) -> CaseResult:
    """Read back a solved case: reconstructPar (ranks > 1), the solver log (iterations,
    convergence, final residuals), the latest time directory and the outflow history."""
    work, case, lat = prep.work, prep.work / CASE_DIR, prep.lattice
    if s.ranks > 1:
        _tool(work, case, ["reconstructPar", "-latestTime"], "reconstructPar", times,
              oversubscribe=oversubscribe, show_progress=show_progress)
    log = (work / "log.simpleFoam").read_text(errors="replace")
    m = _CONVERGED.search(log)
    steps = [int(t) for t in _TIME.findall(log)]
    iterations = int(m.group(1)) if m else (steps[-1] if steps else prep.start_iteration)
    residuals: dict[str, float] = {}
    for name, val in _RESIDUAL.findall(log):
        residuals[name] = float(val)
    times_dirs = sorted(_time_dirs(case).items())
    if not times_dirs:
        raise StageError(f"simpleFoam wrote no solution in {case}")
    last = times_dirs[-1][1]
    fi, fj, fk = prep.cell_index
    n = len(fi)
    U = _read_internal(last / "U").reshape(-1, 3)
    p = _read_internal(last / "p").ravel()
    if p.size == 1:
        p = np.full(n, float(p[0]))
    if U.shape[0] == 1:
        U = np.repeat(U, n, axis=0)
    q_top = -_patch_sum(last / "phi", "top")
    q_bottom = _patch_sum(last / "phi", "bottom")
    Ul = np.zeros((lat.nx, lat.ny, lat.nz, 3))
    pl = np.full((lat.nx, lat.ny, lat.nz), np.nan)
    fluid = np.zeros((lat.nx, lat.ny, lat.nz), dtype=bool)
    idx = (fi, fj, fk)
    Ul[idx] = U
    pl[idx] = p * s.density_kg_m3
    fluid[idx] = True
    hist_it, hist_q = _read_flow_rate_history(case) if record_flow_rate else (
        np.zeros(0, np.int64), np.zeros(0))  # fmt: skip
    hx, hy = s.size_x_m / lat.nx, s.size_y_m / lat.ny
    return CaseResult(
        lattice_x=(np.arange(lat.nx) + 0.5) * hx,
        lattice_y=(np.arange(lat.ny) + 0.5) * hy,
        lattice_z=prep.z_centres,
        U=Ul,
        p=pl,
        fluid=fluid,
        solid_fraction=prep.solid_fraction,
        q_top_m3_s=q_top,
        q_bottom_m3_s=q_bottom,
        iterations=iterations,
        converged=m is not None,
        fluid_cells=int(n),
        lattice_cells=lat.cells,
        wall_times_s=times,
        final_residuals=residuals,
        history_iteration=hist_it,
        history_q_bottom_m3_s=hist_q,
        resumed_from_iteration=prep.start_iteration,
    )


# --------------------------------------------------------------------------------------------
# Output shared by the stages


def write_solver_record(group: Any, s: BoxSetup, res: CaseResult) -> None:
    """Attributes of an HDF5 group (``/solver``): application, iterations, residual convergence,
    cell counts, ranks, wall time per tool (s), final initial residuals and the setup."""
    group.attrs["application"] = "simpleFoam (laminar, SIMPLEC)"
    group.attrs["iterations"] = res.iterations
    group.attrs["converged"] = res.converged
    group.attrs["lattice_cells"] = res.lattice_cells
    group.attrs["fluid_cells"] = res.fluid_cells
    group.attrs["ranks"] = s.ranks
    group.attrs["resumed_from_iteration"] = res.resumed_from_iteration
    for k, v in res.wall_times_s.items():
        group.attrs[f"wall_time_{k}_s"] = v
    for k, v in res.final_residuals.items():
        group.attrs[f"final_initial_residual_{k}"] = v
    for k, v in asdict(s).items():
        group.attrs[f"setup_{k}"] = v if v is not None else "none"


def plot_section(ax: Any, s: BoxSetup, res: CaseResult, values: FloatArray, title: str,
                 margin_m: float) -> Any:  # fmt: skip
    """Colour map of ``values`` (nx, nz) on the lattice plane y = Ly / 2 (pass that plane's
    values), removed cells grey, z from ``margin_m`` below the zone to ``margin_m`` above it."""
    j = len(res.lattice_y) // 2
    X, Z = np.meshgrid(res.lattice_x * 1e3, res.lattice_z * 1e3, indexing="ij")
    pc = ax.pcolormesh(X, Z, np.where(res.fluid[:, j, :], values, np.nan), shading="nearest",
                       cmap="viridis")  # fmt: skip
    ax.pcolormesh(X, Z, np.where(res.fluid[:, j, :], np.nan, 1.0), shading="nearest",
                  cmap="Greys", vmin=0, vmax=1.5)  # fmt: skip
    ax.set_ylim((s.fabric_lo_z_m - margin_m) * 1e3, min(s.top_z_m, s.fabric_hi_z_m + margin_m) * 1e3)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title(f"{title} at y = {res.lattice_y[j] * 1e3:.3f} mm (grey: solid)")
    return pc


# --------------------------------------------------------------------------------------------
# The transient fluid of a two-way coupled lay-down (fiberPimpleFoam -coupled, issue 13)

#: Function objects of the coupled fluid: sum(phi) over ``bottom`` and ``top`` after every step.
DRAINAGE_FO = {"bottom": "drainageBottom", "top": "drainageTop"}


def prepare_coupled_case(flow_case: Path, dest: Path, fluid_step_s: float, write_every: int = 0) -> Path:
    """Copy the flow stage's case ``flow_case`` (mesh, boundary conditions) to ``dest`` with its
    steady solution (latest time: U, p, phi) as time 0, and turn it into a transient
    fiberPimpleFoam case (Euler, PIMPLE with 1 outer and 2 pressure correctors, no relaxation, the
    fluid step ``fluid_step_s``, the drainage function objects). ``write_every`` > 0: the state is
    written every that many fluid steps, in binary (exact: the restart points of a coupled
    lay-down); else only at the end. Returns ``dest``."""
    from foamlib import FoamFile

    times = sorted((d for d in flow_case.iterdir()
                    if d.is_dir() and is_time_name(d.name) and float(d.name) > 0),
                   key=lambda d: float(d.name))  # fmt: skip
    if not times:
        raise StageError(f"{flow_case}: no steady solution (run the flow stage first)")
    shutil.rmtree(dest, ignore_errors=True)
    dest.mkdir(parents=True)
    for part in ("constant", "system"):
        shutil.copytree(flow_case / part, dest / part)
    (dest / "0").mkdir()
    for name in ("U", "p", "phi"):
        if (times[-1] / name).is_file():
            shutil.copy(times[-1] / name, dest / "0" / name)
    with FoamFile(dest / "system" / "controlDict") as c:
        c["application"] = "fiberPimpleFoam"
        c["startFrom"] = "startTime"
        c["startTime"] = 0
        c["endTime"] = 1e9  # ignored in a coupled run: the fibers end it
        c["deltaT"] = float(fluid_step_s)
        c["writeControl"] = "timeStep"
        c["writeInterval"] = int(write_every) if write_every > 0 else 10**9  # and at the end
        c["writeFormat"] = "binary"  # exact restart states
        c["timePrecision"] = 12
        c["functions"] = {name: patch_flux_sum(patch) for patch, name in DRAINAGE_FO.items()}
    with FoamFile(dest / "system" / "fvSchemes") as f:
        f["ddtSchemes"] = {"default": "Euler"}
        f["divSchemes"]["div(phi,U)"] = ("Gauss", "linearUpwind", "grad(U)")
    with FoamFile(dest / "system" / "fvSolution") as f:
        solvers = f["solvers"]
        f["solvers"] = {
            "p": solvers["p"],
            "pFinal": {**dict(solvers["p"]), "relTol": 0},
            "U": {**dict(solvers["U"]), "relTol": 0},
            "UFinal": {**dict(solvers["U"]), "relTol": 0},
        }
        f["PIMPLE"] = {"momentumPredictor": True, "nOuterCorrectors": 1, "nCorrectors": 2,
                       "nNonOrthogonalCorrectors": 0}  # fmt: skip
        for stale in ("SIMPLE", "relaxationFactors"):
            if stale in f:
                del f[stale]
    return dest


def read_patch_history(case: Path, name: str) -> tuple[FloatArray, FloatArray]:
    """(times or iterations, value) of a surfaceFieldValue function object ``name`` (one value per
    line). A resumed run writes a new file, in a folder named by its start time or with that time
    as the file name's suffix: the files are read in the order of their start times, and each
    drops what the earlier ones hold after its start (what a killed run wrote past the time it is
    resumed from)."""
    files = []
    for f in (case / "postProcessing" / name).glob("*/surfaceFieldValue*.dat"):
        suffix = f.stem.partition("_")[2]
        t0 = float(suffix) if is_time_name(suffix) else float(f.parent.name) if is_time_name(f.parent.name) else 0.0
        files.append((t0, f.stat().st_mtime_ns, str(f), f))
    history: dict[float, float] = {}
    for t0, _, _, f in sorted(files):
        history = {t: v for t, v in history.items() if t <= t0 * (1 + 1e-9)}
        for line in f.read_text(errors="replace").splitlines():
            parts = line.split()
            if not parts or line.lstrip().startswith("#"):
                continue
            try:
                history[float(parts[0])] = float(parts[1])
            except (ValueError, IndexError):
                continue
    ts = sorted(history)
    return np.array(ts, dtype=np.float64), np.array([history[t] for t in ts], dtype=np.float64)


def cell_centres(case: Path) -> npt.NDArray[np.float64]:
    """The cell centres of the mesh at time 0 (m, (cells, 3)): ``postProcess -func
    writeCellCentres`` (log ``log.writeCellCentres`` in the case), read, and the written fields
    removed again."""
    run(["postProcess", "-func", "writeCellCentres", "-time", "0"], Path("log.writeCellCentres"), cwd=case,
        description="writeCellCentres")
    C = _read_internal(case / "0" / "C").reshape(-1, 3)
    for name in ("C", "Cx", "Cy", "Cz"):
        (case / "0" / name).unlink(missing_ok=True)
    return C


def set_decomposition(case: Path, ranks: int) -> None:
    """The case's decomposeParDict for ``ranks`` ranks: slabs across x (method simple; Debian's
    OpenFOAM has no scotch)."""
    from foamlib import FoamFile

    with FoamFile(case / "system" / "decomposeParDict") as d:
        d["numberOfSubdomains"] = int(ranks)
        d["method"] = "simple"
        d["coeffs"]["n"] = [int(ranks), 1, 1]


def decompose(case: Path, ranks: int) -> None:
    """Decompose the case for ``ranks`` ranks (:func:`set_decomposition`, ``decomposePar
    -force``); earlier processor folders go first."""
    for stale in case.glob("processor*"):
        shutil.rmtree(stale)
    if ranks <= 1:
        return
    set_decomposition(case, ranks)
    run(["decomposePar", "-force"], Path("log.decomposePar"), cwd=case, description="decomposePar")


def coupled_roots(case: Path) -> list[Path]:
    """Where a coupled fluid writes its time folders: the case, or its processor* folders when it
    ran on several ranks (decomposed)."""
    procs = sorted(case.glob("processor*"))
    return procs if procs else [case]


def coupled_state(case: Path, time_s: float, tolerance_s: float) -> list[Path] | None:
    """A coupled fluid's time folders of ``time_s`` (within ``tolerance_s``; one per fluid rank),
    if every rank wrote its state (U and phi)."""
    if not case.is_dir():
        return None
    states = []
    for root in coupled_roots(case):
        found = [d for d in root.iterdir() if d.is_dir() and is_time_name(d.name)
                 and abs(float(d.name) - time_s) <= tolerance_s]
        if not found or not ((found[0] / "U").is_file() and (found[0] / "phi").is_file()):
            return None
        states.append(found[0])
    return states


def cut_coupled_back(case: Path, states: list[Path]) -> None:
    """Cut a coupled fluid back to its state ``states`` (:func:`coupled_state`): later time folders
    and function-object records go, the fibers' source of that state is dropped (it is recomputed
    from the first reaction; a fiberSource file would be read as a background force), and the
    fluid starts from the latest time left."""
    from foamlib import FoamFile

    t = float(states[0].name)
    roots = coupled_roots(case)
    for d in [d for root in roots for d in root.iterdir()] + list((case / "postProcessing").glob("*/*")):
        if not is_time_name(d.name):
            continue
        later = float(d.name) > t if d.parent in roots else float(d.name) >= t
        if d.is_dir() and later:
            shutil.rmtree(d)
    for state in states:
        (state / "fiberSource").unlink(missing_ok=True)
    with FoamFile(case / "system" / "controlDict") as c:
        c["startFrom"] = "latestTime"
