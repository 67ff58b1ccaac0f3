# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``permeability``: air flow through the fabric and the laid-down sheet, reported as the
superficial velocity at the pressure drop of the scene, in CFM and as a Darcy permeability
(Kettil 2016 sec. 4.2, Table 4.1, Fig. 4.11-4.13; issue 12).

Domain and boundary conditions are those of the thesis (sec. 3.1, eq. 3.1-3.3) and of the flow
stage: symmetry on the four vertical sides, fixed pressure at the top and the bottom with
zero-gradient velocity, no-slip on yarns and fibers; laminar steady Navier-Stokes (stock simpleFoam,
SIMPLEC) through :mod:`fiberform.openfoam_case`. Mode ``resolved``: the solid zone (fabric lower
side to the top of the sheet) has cubic cells of d_min / ``cells_across_fiber`` (d_min: the
thinnest fiber diameter or, for collapsed fibers, thickness; the thinnest yarn for a bare
fabric); each zone cell gets the fraction of its ``subsamples``^3 sample points inside a fiber or
yarn (capsule chains: the yarns of the generated fabric and circular fibers; box chains with
mitred joints: collapsed fibers, lying flat; imported fabrics through their voxel image), and the
cells with the largest fractions are removed until the removed volume equals the sampled solid
volume (:func:`fiberform.openfoam_case.volume_preserving`). Mode ``subgrid``: cells of
``subgrid_cell_size_m``; yarns removed as above, fibers as a Darcy resistance 1/k(phi) per cell from
the cell's fiber volume fraction and ``subgrid_law`` (Jackson & James 1986 or Drummond & Tahir 1984;
:mod:`fiberform.porous_media`; collapsed fibers: the law's radius is the hydraulic radius 2 A / P of
the section), applied through OpenFOAM's explicitPorositySource.

With ``forchheimer_pressure_drop_Pa`` a second case runs at that pressure drop (in
``forchheimer/``) and the Darcy permeability k_D and the Forchheimer coefficient beta of
dp / L = (mu / k_D) u + beta rho u^2 are fitted through the two superficial velocities.

Convergence (thesis sec. 5.2: the permeability "oscillates"): the outflow through the bottom is
recorded at every iteration, and the result is the mean over the last ``convergence_window``
iterations, with half its range as the uncertainty; it counts as converged when the range is at
most ``convergence_tolerance`` of the mean. simpleFoam stops at the first iteration where that
holds (``stop_at: converged``, the default: fiberform's function object flowRateConvergence,
coupling/functionObjects/), when the initial residuals of p and U fall below
``residual_tolerance``, or at ``max_iterations``.

Products in ``<output_dir>/permeability-laydown/`` (scene with a ``laydown`` section: fabric plus
the sheet of the lay-down) or ``<output_dir>/permeability-fabric/`` (bare fabric):
``permeability.h5``, ``report.md``, ``permeability.png``. Page: docs/stages/permeability.md.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt

from ..errors import ConfigError, StageError
from ..fabric_geometry import VoxelImage
from ..fiber_io import outer_half_axes
from ..openfoam_case import (
    FUNCTION_OBJECTS_LIB,
    BoxSetup, CaseResult, Lattice, SolidFraction, collect_case, load_prepared, make_lattice,
    plot_section, prepare_or_resume, solver_program, solver_wall_time, template_hash,
    write_solver_record,
)  # fmt: skip
from ..porous_media import (
    CFM_M_S, Convergence, chain_fraction, flow_rate_convergence, forchheimer_fit,
    hydraulic_radius, image_fraction, line_fraction, subgrid_resistance,
)  # fmt: skip
from ..products import (
    FABRIC_H5, FIBERS_H5, LAYDOWN_H5, PRESS_H5, Chain, read_fabric_image, read_sheet_chains,
    read_yarn_chains,
)  # fmt: skip
from ..fiber_sheet import lateral_period, periodic_images
from ..provenance import file_hash, report_origin, write_dataset
from ..scene import PermeabilitySection, Scene
from ._stage import Program, Stage, StageContext, resumes

__all__ = [
    "Forchheimer", "PermeabilityGeometry", "PermeabilityStage", "case_setup",
    "darcy_permeability", "fiber_resistance", "forchheimer_setup", "law_radius",
    "nominal_fiber_section", "nominal_fiber_thickness", "periodic_chains", "solid_fraction",
    "zone_layers",
]

H5_NAME, REPORT_NAME, PNG_NAME = "permeability.h5", "report.md", "permeability.png"
#: the second run of the Forchheimer fit: its case and logs, below the stage folder
FORCHHEIMER_DIR = "forchheimer"

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PermeabilityGeometry:
    """The solid of one permeability run (SI units)."""

    size_x_m: float
    size_y_m: float
    lower_z_m: float  # fabric lower side
    upper_z_m: float  # highest solid point (fabric or sheet)
    thinnest_m: float  # diameter (collapsed: thickness) of the thinnest fiber (or yarn; or voxel)
    yarns: tuple[Chain, ...]
    fiber_chains: tuple[Chain, ...] = ()
    image: object | None = None  # VoxelImage of an imported fabric (no yarn chains)
    law_radius_m: float | None = None  # sub-grid law's fiber radius (None: thinnest_m / 2)
    fabric_top_z_m: float | None = None  # the fabric's top (None: upper_z_m, no sheet above it)

    @property
    def fibers(self) -> int:
        return len(self.fiber_chains)


def darcy_permeability(u_s_m_s: float, mu_Pa_s: float, thickness_m: float, dp_Pa: float) -> float:
    """Darcy permeability k = mu u_s L / delta_p [m^2] of a layer of thickness L."""
    return mu_Pa_s * u_s_m_s * thickness_m / dp_Pa


def nominal_fiber_section(scene: Scene) -> tuple[float, float]:
    """(width, thickness) [m] of the scene's generated fiber section before the per-node jitter
    (:func:`fiberform.fiber_io.outer_half_axes`): circular both the diameter ``fibers.width_m``;
    collapsed 2 a1 = 0.8 ``fibers.width_m`` and 2 a2 = 0.8 ``fibers.thickness_m``."""
    f = scene.fibers
    assert f is not None
    aspect = f.thickness_m / f.width_m if f.thickness_m is not None else 0.25
    a1, a2 = outer_half_axes(f.cross_section, 0.5 * f.width_m, aspect)
    return 2.0 * max(a1, a2), 2.0 * min(a1, a2)


def nominal_fiber_thickness(scene: Scene) -> float:
    """The thinnest dimension [m] of the scene's fiber section (:func:`nominal_fiber_section`)."""
    return nominal_fiber_section(scene)[1]


def periodic_chains(chains: list[Chain], period: tuple[float, float]) -> list[Chain]:
    """The fiber chains of a periodic lay-down (``laydown.walls: periodic``: unwrapped, up to a
    fiber length out of the piece) with their images shifted by whole periods (Lx, Ly), m, that
    reach into the piece (fiber_sheet.periodic_images; margin: the widest chain's half-width, so
    every image whose section reaches in is taken, and one whose does not adds nothing): the
    volume-fraction fields clip chains to the piece, so a fiber across a side enters on both sides
    and no fiber volume is lost or counted twice."""
    if not chains:
        return []
    offsets = np.cumsum([0] + [len(c.points) for c in chains])
    x, offs, src, _ = periodic_images(np.vstack([c.points for c in chains]), offsets, period,
                                      margin=max(c.radius for c in chains))
    return [Chain(x[lo:hi].copy(), chains[k].radius, chains[k].half_thickness)
            for k, lo, hi in zip(src, offs[:-1], offs[1:])]


def law_radius(c: Chain) -> float:
    """The fiber radius [m] of the sub-grid laws for a chain: its radius (circular) or the
    hydraulic radius 2 A / P of its rectangular section (:func:`fiberform.porous_media.hydraulic_radius`)."""
    return c.radius if c.half_thickness is None else hydraulic_radius(c.radius, c.half_thickness)


def zone_layers(geo: PermeabilityGeometry, h: float) -> tuple[int, float]:
    """(cell layers, upper end [m]) of the solid zone for cells of about ``h``: the fabric (lower
    side to top) in the whole number of layers nearest to its height / h, as the flow stage cuts
    it, and as many more layers of that height as reach the highest solid point. A fabric is so
    cut into the same cells under every sheet: the permeabilities of a sheet before and after the
    press, and of the bare fabric, differ by the fibers only (before, every cell boundary in the
    fabric moved with the sheet's top: docs/stages/permeability.md, "Zone layers")."""
    fabric_top = geo.upper_z_m if geo.fabric_top_z_m is None else geo.fabric_top_z_m
    n = max(1, round((fabric_top - geo.lower_z_m) / h))
    hz = (fabric_top - geo.lower_z_m) / n
    n += max(0, math.ceil((geo.upper_z_m - fabric_top) / hz - 1e-9))
    return n, geo.lower_z_m + n * hz


def case_setup(perm: PermeabilitySection, geo: PermeabilityGeometry, stop_library: str = "") -> BoxSetup:
    """The box case of a permeability run: zone cells of thinnest / cells_across_fiber (resolved)
    or subgrid_cell_size_m (subgrid), in the layers of :func:`zone_layers`; the domain's top
    ``height_above_m`` above the zone. With ``stop_at: converged`` the solve ends at the
    convergence window (function object flowRateConvergence of ``stop_library``, the absolute
    path of the build's FUNCTION_OBJECTS_LIB)."""
    if perm.mode == "subgrid":
        h = perm.subgrid_cell_size_m
    else:
        h = geo.thinnest_m / perm.cells_across_fiber
    layers, zone_top = zone_layers(geo, h)
    return BoxSetup(
        size_x_m=geo.size_x_m,
        size_y_m=geo.size_y_m,
        fabric_lo_z_m=geo.lower_z_m,
        fabric_hi_z_m=zone_top,
        top_z_m=zone_top + perm.height_above_m,
        cell_size_m=h,
        max_cell_height_m=perm.max_cell_height_m or 8.0 * h,
        delta_p_Pa=perm.pressure_drop_Pa,
        density_kg_m3=perm.density_kg_m3,
        viscosity_Pa_s=perm.viscosity_Pa_s,
        max_iterations=perm.max_iterations,
        residual_tolerance=perm.residual_tolerance,
        ranks=perm.ranks,
        zone_layers=layers,
        stop_window=perm.convergence_window if perm.stop_at == "converged" else 0,
        stop_tolerance=perm.convergence_tolerance if perm.stop_at == "converged" else 0.0,
        stop_library=stop_library if perm.stop_at == "converged" else "",
    )


def forchheimer_setup(perm: PermeabilitySection, geo: PermeabilityGeometry,
                      stop_library: str = "") -> BoxSetup | None:
    """The second case of the Forchheimer fit (the first at ``forchheimer_pressure_drop_Pa``), None
    without that field."""
    if perm.forchheimer_pressure_drop_Pa is None:
        return None
    return dataclasses.replace(case_setup(perm, geo, stop_library),
                               delta_p_Pa=perm.forchheimer_pressure_drop_Pa)


def solid_fraction(geo: PermeabilityGeometry, perm: PermeabilitySection) -> SolidFraction:
    """The cells' solid fraction: yarns (or the voxel image) and, in mode resolved, the fibers."""
    chains = list(geo.yarns) + (list(geo.fiber_chains) if perm.mode == "resolved" else [])

    def frac(s: BoxSetup, lat: Lattice) -> npt.NDArray[np.float32]:
        out = chain_fraction(chains, s, lat, perm.subsamples)
        if geo.image is not None:
            img = geo.image
            assert isinstance(img, VoxelImage)
            out = np.maximum(out, image_fraction(img, s, lat, perm.subsamples))
        return out

    return frac


def fiber_resistance(geo: PermeabilityGeometry, perm: PermeabilitySection) -> SolidFraction | None:
    """Mode subgrid: Darcy resistance 1/k of each cell from its fiber volume fraction and the
    law ``subgrid_law`` (fiber radius ``geo.law_radius_m``: the thinnest fiber's radius, or the
    smallest hydraulic radius of collapsed sections); None in mode resolved."""
    if perm.mode != "subgrid" or not geo.fiber_chains:
        return None
    chains = list(geo.fiber_chains)
    a = geo.law_radius_m if geo.law_radius_m is not None else 0.5 * geo.thinnest_m

    def resistance(s: BoxSetup, lat: Lattice) -> npt.NDArray[np.float64]:
        phi = line_fraction(chains, s, lat)
        return subgrid_resistance(phi, a, perm.subgrid_law)

    return resistance


def _expected_cells(scene: Scene) -> tuple[float, float]:
    """(cell size, lattice cells) estimated from the scene alone, for the up-front check."""
    perm, fab = scene.permeability, scene.fabric
    assert perm is not None and fab is not None
    thick = fab.md_diameter_m * 3 + fab.cd_top_diameter_m + fab.cd_bottom_diameter_m
    thinnest = min(fab.md_diameter_m, fab.cd_top_diameter_m, fab.cd_bottom_diameter_m)
    if scene.laydown is not None and scene.fibers is not None:
        thinnest = nominal_fiber_thickness(scene)
    if fab.source != "generate":
        thinnest = fab.voxel_size_m
    h = perm.subgrid_cell_size_m if perm.mode == "subgrid" else thinnest / perm.cells_across_fiber
    return h, (fab.size_x_m / h) * (fab.size_y_m / h) * (thick / h)


class PermeabilityStage(Stage):
    name = "permeability"
    summary = "air permeability of the fabric (and the laid-down sheet) at 125 Pa, in CFM (OpenFOAM)"
    folder = "permeability"
    requires = ("fabric", "permeability")
    uses = ("fabric", "fibers", "laydown", "permeability")
    products = (H5_NAME, REPORT_NAME, PNG_NAME)
    code_version = 3  # 3: the fabric's zone layers independent of the sheet (zone_layers)
    splits = True

    #: the sheet this stage puts on the fabric (a product with /sheet/x, fiber_id, offsets)
    sheet_product = LAYDOWN_H5

    def stage_dir(self, ctx: StageContext) -> Path:
        kind = "laydown" if ctx.scene.laydown is not None else "fabric"
        return ctx.scene.output_path / f"{self.folder}-{kind}"

    def metrics(self, ctx: StageContext) -> dict[str, float]:
        key = self.name.replace("-", "_")
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            r = h5["result"]
            out = {f"{key}_cfm": float(r["cfm"][()]), f"{key}_cfm_uncertainty": float(r["cfm_uncertainty"][()]),
                   f"{key}_converged": float(bool(r.attrs["converged"])),
                   f"{key}_darcy_k_m2": float(r["darcy_k"][()])}
            if "forchheimer" in h5:
                out[f"{key}_forchheimer_beta_1_m"] = float(h5["forchheimer/beta"][()])
            return out

    def results(self, ctx: StageContext) -> list[str]:
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            r = h5["result"]
            what = self.stage_dir(ctx).name.removeprefix("permeability-")
            sheet = {"fabric": "bare fabric", "laydown": "fabric + laid-down sheet",
                     "press": "fabric + pressed sheet"}.get(what, what)
            lines = [f"air permeability ({sheet}) at {float(r['pressure_drop'][()]):g} Pa: "
                     f"{float(r['cfm'][()]):.4g} +- {float(r['cfm_uncertainty'][()]):.2g} CFM "
                     f"({'converged' if r.attrs['converged'] else 'NOT converged'})"]
            if "forchheimer" in h5:
                g = h5["forchheimer"]
                lines.append(
                    f"Forchheimer fit ({float(r['pressure_drop'][()]):g} and "
                    f"{float(g['pressure_drop'][()]):g} Pa): k_D = {float(g['darcy_k'][()]):.4g} "
                    f"+- {float(g['darcy_k_uncertainty'][()]):.2g} m^2, beta = "
                    f"{float(g['beta'][()]):.4g} +- {float(g['beta_uncertainty'][()]):.2g} 1/m")
            return lines

    def check_scene(self, scene: Scene) -> list[str]:
        problems = super().check_scene(scene)
        if problems:
            return problems
        perm = scene.permeability
        assert perm is not None
        h, cells = _expected_cells(scene)
        field = "subgrid_cell_size_m" if perm.mode == "subgrid" else "cells_across_fiber"
        if (perm.mode == "subgrid" and scene.laydown is not None and scene.fibers is not None
                and perm.subgrid_cell_size_m < nominal_fiber_section(scene)[0]):
            problems.append(
                f"permeability.subgrid_cell_size_m = {perm.subgrid_cell_size_m!r}: smaller than "
                f"the fiber width ({nominal_fiber_section(scene)[0]!r} m); the sub-grid laws "
                "need cells at least one fiber wide (use mode resolved for finer cells)"
            )
        if cells > perm.max_cells:
            problems.append(
                f"permeability.{field} = {getattr(perm, field)!r}: cells of "
                f"{h:.3g} m give about {cells:.3g} cells in the fabric zone alone (limit "
                f"permeability.max_cells = {perm.max_cells!r})"
            )
        return problems

    def needs(self, ctx: StageContext) -> dict[str, Path]:
        root = ctx.scene.output_path
        paths = {"fabric_h5": root / FABRIC_H5}
        if ctx.scene.laydown is not None:
            paths["sheet_h5"] = root / self.sheet_product
            paths["fibers_h5"] = root / FIBERS_H5
        return paths

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        hashes = super().input_hashes(ctx)
        hashes["case_template"] = template_hash()
        lib = Path(self.function_objects(ctx))
        if ctx.scene.permeability is not None and ctx.scene.permeability.stop_at == "converged":
            hashes["function_objects"] = file_hash(lib) if lib.is_file() else "missing"
        return hashes

    @staticmethod
    def function_objects(ctx: StageContext) -> str:
        """Absolute path of the build's function-object library (flowRateConvergence)."""
        return str((ctx.build_dir / FUNCTION_OBJECTS_LIB).resolve())

    def preflight(self, ctx: StageContext) -> None:
        for key, p in self.needs(ctx).items():
            if not p.is_file():
                raise StageError(f"permeability needs {p} ({key}): run the upstream stages first "
                                 "(fiberform run SCENE runs them in order)")  # fmt: skip
        if shutil.which("simpleFoam") is None:
            raise ConfigError("simpleFoam not found on PATH (install Debian's openfoam package)")
        perm = ctx.scene.permeability
        if perm is not None and perm.stop_at == "converged" and not Path(self.function_objects(ctx)).is_file():
            raise ConfigError(f"{self.function_objects(ctx)} not found (permeability.stop_at: converged "
                              "needs fiberform's function objects): build first (make build), or "
                              "set permeability.stop_at: max_iterations")

    def geometry(self, ctx: StageContext) -> PermeabilityGeometry:
        paths = self.needs(ctx)
        img = read_fabric_image(paths["fabric_h5"])
        yarns = read_yarn_chains(paths["fabric_h5"])
        section = ctx.scene.fibers.cross_section if ctx.scene.fibers is not None else "circular"
        fibers = (read_sheet_chains(paths["sheet_h5"], paths["fibers_h5"], section)
                  if "sheet_h5" in paths else [])  # fmt: skip
        period = lateral_period(ctx.scene)
        if period is not None and fibers:
            fibers = periodic_chains(fibers, period)
        up = img.upper
        top = float(up[2])
        for c in fibers:  # a flat element's top lies half a thickness above its axis (at most)
            top = max(top, float(np.max(c.points[:, 2])) + 0.5 * c.thickness)
        if fibers:
            thinnest = min(c.thickness for c in fibers)
        elif "sheet_h5" in paths and ctx.scene.fibers is not None:
            thinnest = nominal_fiber_thickness(ctx.scene)  # an empty sheet: the mesh of the sheets
        elif yarns:
            thinnest = 2.0 * min(c.radius for c in yarns)
        else:
            thinnest = float(np.min(img.spacing))
        return PermeabilityGeometry(
            size_x_m=float(up[0] - img.origin[0]),
            size_y_m=float(up[1] - img.origin[1]),
            lower_z_m=float(img.origin[2]),
            upper_z_m=top,
            thinnest_m=thinnest,
            yarns=tuple(yarns),
            fiber_chains=tuple(fibers),
            image=None if yarns else img,
            law_radius_m=min(law_radius(c) for c in fibers) if fibers else None,
            fabric_top_z_m=float(up[2]),
        )

    def cases(self, ctx: StageContext) -> tuple[PermeabilityGeometry, list[tuple[BoxSetup, Path]]]:
        """The geometry and the cases (setup, folder): the scene's pressure drop in the stage
        folder and, with ``forchheimer_pressure_drop_Pa``, the second point of the fit in its own
        folder."""
        perm = ctx.scene.permeability
        assert perm is not None
        geo = self.geometry(ctx)
        lib = self.function_objects(ctx)
        s = case_setup(perm, geo, lib)
        lat = make_lattice(s)
        if lat.cells > perm.max_cells:
            raise StageError(
                f"permeability: the lattice has {lat.cells} cells of {s.cell_size_m:.3g} m (limit "
                f"permeability.max_cells = {perm.max_cells}); lower cells_across_fiber or raise "
                "subgrid_cell_size_m"
            )
        s2 = forchheimer_setup(perm, geo, lib)
        d = self.stage_dir(ctx)
        return geo, [(s, d), *([(s2, d / FORCHHEIMER_DIR)] if s2 is not None else [])]

    def prepare(self, ctx: StageContext, hashes: Mapping[str, str]) -> None:
        perm = ctx.scene.permeability
        assert perm is not None
        geo, cases = self.cases(ctx)
        if len(cases) == 1:  # a stale second case
            shutil.rmtree(self.stage_dir(ctx) / FORCHHEIMER_DIR, ignore_errors=True)
        for s, work in cases:
            prepare_or_resume(s, solid_fraction(geo, perm), work, inputs=hashes, resume=resumes(ctx),
                              record_flow_rate=True, preserve_volume=True, resistance=fiber_resistance(geo, perm),
                              oversubscribe=ctx.oversubscribe, show_progress=ctx.show_progress)

    def programs(self, ctx: StageContext) -> list[Program]:
        perm = ctx.scene.permeability
        assert perm is not None
        d = self.stage_dir(ctx)
        works = [d, *([d / FORCHHEIMER_DIR] if perm.forchheimer_pressure_drop_Pa is not None else [])]
        return [solver_program(w, perm.ranks, perm.max_iterations) for w in works]

    def collect(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str],
                wall_times: Mapping[str, float]) -> None:
        perm = ctx.scene.permeability
        assert perm is not None
        geo, cases = self.cases(ctx)
        results = []
        for s_, work in cases:
            prep = load_prepared(work, s_)
            key = self.log_key(ctx, work / "log.simpleFoam")
            solve = wall_times[key] if key in wall_times else solver_wall_time(work)
            results.append(collect_case(s_, prep, {**prep.wall_times_s, "simpleFoam": solve}, record_flow_rate=True,
                                        oversubscribe=ctx.oversubscribe, show_progress=ctx.show_progress))
        wall = sum(sum(r.wall_times_s.values()) for r in results)
        (s, _), res = cases[0], results[0]
        conv = flow_rate_convergence(res.history_q_bottom_m3_s, perm.convergence_window,
                                     perm.convergence_tolerance)  # fmt: skip
        fh: Forchheimer | None = None
        if len(cases) > 1:  # the second point of the fit
            s2, res2 = cases[1][0], results[1]
            conv2 = flow_rate_convergence(res2.history_q_bottom_m3_s, perm.convergence_window,
                                          perm.convergence_tolerance)  # fmt: skip
            fh = fit_forchheimer(s, conv, s2, conv2, res2, geo.upper_z_m - geo.lower_z_m)
        summary = write_permeability_h5(h5, perm, geo, s, res, conv, wall)
        if fh is not None:
            write_forchheimer_h5(h5, fh)
        title = (f"permeability of scene '{ctx.scene.name}' ({geo.fibers} fibers): "
                 f"{summary['cfm']:.4g} +- {summary['cfm_uncertainty']:.2g} CFM at "
                 f"{s.delta_p_Pa:g} Pa")  # fmt: skip
        write_png(tmp[PNG_NAME], s, res, title)
        lines = report_lines(ctx.scene.name, perm, geo, s, res, conv, summary, wall)
        lines[2:2] = [report_origin(h5), ""]
        if fh is not None:
            lines[-2:-2] = forchheimer_lines(fh)
        tmp[REPORT_NAME].write_text("\n".join(lines) + "\n")
        for c, dp in ((conv, s.delta_p_Pa), *(((fh.conv, fh.s.delta_p_Pa),) if fh else ())):
            if not c.converged:
                print(f"permeability: warning: at {dp:g} Pa the outflow varied by "
                      f"{c.relative_amplitude:.2g} of its mean over the last {c.window} iterations "
                      f"(tolerance {perm.convergence_tolerance:g}); see "
                      f"{self.stage_dir(ctx) / REPORT_NAME}")  # fmt: skip
        if fh is not None and not fh.physical:
            print(f"permeability: warning: the Forchheimer fit gives k_D = {fh.darcy_k:.3g} m^2, "
                  f"beta = {fh.beta:.3g} 1/m (not both positive): the two points do not follow "
                  "the law; see the report")  # fmt: skip


@dataclass(frozen=True)
class Forchheimer:
    """The fit dp / L = (mu / k_D) u + beta rho u^2 through the runs at the two pressure drops."""

    s: BoxSetup  # the second case
    res: CaseResult
    conv: Convergence
    u1_m_s: float
    u2_m_s: float
    darcy_k: float  # m^2
    darcy_k_uncertainty: float  # m^2
    beta: float  # 1/m
    beta_uncertainty: float  # 1/m

    @property
    def physical(self) -> bool:
        return bool(self.darcy_k > 0.0 and math.isfinite(self.darcy_k) and self.beta >= 0.0)


def fit_forchheimer(s1: BoxSetup, conv1: Convergence, s2: BoxSetup, conv2: Convergence,
                    res2: CaseResult, thickness_m: float) -> Forchheimer:  # fmt: skip
    """The fit through the window means of the two runs; its uncertainty is half the range of
    the fit over the four combinations of u_i +- (the runs' uncertainties)."""
    area = s1.size_x_m * s1.size_y_m
    u1, u2 = conv1.mean_m3_s / area, conv2.mean_m3_s / area
    du1, du2 = conv1.amplitude_m3_s / area, conv2.amplitude_m3_s / area

    def fit(a: float, b: float) -> tuple[float, float]:
        return forchheimer_fit(a, s1.delta_p_Pa, b, s2.delta_p_Pa, thickness_m,
                               s1.viscosity_Pa_s, s1.density_kg_m3)  # fmt: skip

    k, beta = fit(u1, u2)
    corners = [fit(u1 + e1 * du1, u2 + e2 * du2) for e1 in (-1, 1) for e2 in (-1, 1)
               if u1 + e1 * du1 > 0 and u2 + e2 * du2 > 0 and u1 + e1 * du1 != u2 + e2 * du2]
    ks, bs = [c[0] for c in corners], [c[1] for c in corners]
    return Forchheimer(s2, res2, conv2, u1, u2, k, 0.5 * (max(ks) - min(ks)) if ks else math.nan,
                       beta, 0.5 * (max(bs) - min(bs)) if bs else math.nan)  # fmt: skip


def write_forchheimer_h5(h5: h5py.File, fh: Forchheimer) -> None:
    g = h5.create_group("forchheimer")
    g.attrs["converged"] = fh.conv.converged
    g.attrs["physical"] = fh.physical
    for name, val, unit, desc in (
        ("pressure_drop", fh.s.delta_p_Pa, "Pa", "pressure drop of the second run"),
        ("superficial_velocity", fh.u2_m_s, "m/s", "second run: mean outflow over the window / area"),
        ("superficial_velocity_uncertainty", fh.conv.amplitude_m3_s / (fh.s.size_x_m * fh.s.size_y_m),
         "m/s", "second run: half the range of the outflow over the window / area"),
        ("darcy_k", fh.darcy_k, "m^2", "k_D of dp / L = (mu / k_D) u + beta rho u^2 through the "
         "two runs, L = /result/layer_thickness"),
        ("darcy_k_uncertainty", fh.darcy_k_uncertainty, "m^2", "half the range of k_D over u_i +- "
         "their uncertainties"),
        ("beta", fh.beta, "1/m", "Forchheimer coefficient beta of the same fit"),
        ("beta_uncertainty", fh.beta_uncertainty, "1/m", "half the range of beta over u_i +- "
         "their uncertainties"),
        ("imbalance", fh.res.imbalance, "1", "second run: |q_top - q_bottom| / q_bottom"),
        ("window_relative_range", fh.conv.relative_amplitude, "1",
         "second run: (max - min) / mean of the outflow over the window"),
    ):  # fmt: skip
        write_dataset(g, name, val, unit, desc)
    write_dataset(g, "history_q_bottom", fh.res.history_q_bottom_m3_s, "m^3/s",
                  "second run: outflow through the bottom after each iteration")  # fmt: skip
    g.attrs["iterations"] = fh.res.iterations


def forchheimer_lines(fh: Forchheimer) -> list[str]:
    return [
        f"- second run at {fh.s.delta_p_Pa:g} Pa: superficial velocity {fh.u2_m_s * 1e3:.5g} mm/s "
        f"({fh.u2_m_s / CFM_M_S:.4g} CFM), outflow range over the window "
        f"{fh.conv.relative_amplitude:.2g} of its mean: "
        f"{'converged' if fh.conv.converged else '**NOT converged**'}; case `{FORCHHEIMER_DIR}/case/`",
        f"- Forchheimer fit dp / L = (mu / k_D) u + beta rho u^2 through the two runs: "
        f"**k_D = {fh.darcy_k:.4g} +- {fh.darcy_k_uncertainty:.2g} m^2, beta = {fh.beta:.4g} +- "
        f"{fh.beta_uncertainty:.2g} 1/m**"
        + ("" if fh.physical else " (**not both positive: the points do not follow the law**)"),
    ]


class PermeabilityPressStage(PermeabilityStage):
    """The same air flow through the fabric and the PRESSED sheet (press.h5 /sheet), products in
    ``<output_dir>/permeability-press/``, apart from the unpressed sheet's (issue 12)."""

    name = "permeability-press"
    summary = "air permeability of the fabric and the pressed sheet at 125 Pa, in CFM (OpenFOAM)"
    requires = ("fabric", "laydown", "press", "permeability")
    uses = ("fabric", "fibers", "laydown", "press", "permeability")
    sheet_product = PRESS_H5

    def stage_dir(self, ctx: StageContext) -> Path:
        return ctx.scene.output_path / f"{self.folder}-press"


def write_permeability_h5(
    h5: h5py.File, perm: PermeabilitySection, geo: PermeabilityGeometry, s: BoxSetup,
    res: CaseResult, conv: Convergence, wall_s: float,
) -> dict[str, float]:  # fmt: skip
    area = s.size_x_m * s.size_y_m
    thickness = geo.upper_z_m - geo.lower_z_m
    u_s = conv.mean_m3_s / area
    du = conv.amplitude_m3_s / area
    k = darcy_permeability(u_s, s.viscosity_Pa_s, thickness, s.delta_p_Pa)
    dk = darcy_permeability(du, s.viscosity_Pa_s, thickness, s.delta_p_Pa)
    re = s.density_kg_m3 * u_s * geo.thinnest_m / s.viscosity_Pa_s
    out = {"superficial_velocity": u_s, "superficial_velocity_uncertainty": du,
           "cfm": u_s / CFM_M_S, "cfm_uncertainty": du / CFM_M_S, "darcy_k": k,
           "darcy_k_uncertainty": dk, "reynolds": re}  # fmt: skip
    r = h5.create_group("result")
    r.attrs["converged"] = conv.converged
    r.attrs["mode"] = perm.mode
    for name, val, unit, desc in (
        ("superficial_velocity", u_s, "m/s", "mean outflow over the convergence window / area"),
        ("superficial_velocity_uncertainty", du, "m/s", "half the range of the outflow over the "
         "window / area"),
        ("cfm", u_s / CFM_M_S, "CFM", "superficial velocity in ft^3/ft^2/min (1 CFM = 5.08 mm/s)"),
        ("cfm_uncertainty", du / CFM_M_S, "CFM", "uncertainty of cfm"),
        ("darcy_k", k, "m^2", "mu u_s L / delta_p, L = solid zone thickness (fabric lower side "
         "to the top of the sheet)"),
        ("darcy_k_uncertainty", dk, "m^2", "uncertainty of darcy_k"),
        ("layer_thickness", thickness, "m", "L: fabric lower side to the highest solid point"),
        ("pressure_drop", s.delta_p_Pa, "Pa", "applied pressure drop top - bottom"),
        ("reynolds", re, "1", "rho u_s d_min / mu (d_min: thinnest fiber or yarn)"),
        ("q_top", res.q_top_m3_s, "m^3/s", "inflow through the top at the last iteration"),
        ("q_bottom", res.q_bottom_m3_s, "m^3/s", "outflow through the bottom at the last iteration"),
        ("imbalance", res.imbalance, "1", "|q_top - q_bottom| / q_bottom"),
        ("window_relative_range", conv.relative_amplitude, "1",
         "(max - min) / mean of the outflow over the convergence window"),
    ):  # fmt: skip
        write_dataset(r, name, val, unit, desc)
    hist = h5.create_group("history")
    write_dataset(hist, "iteration", res.history_iteration, "1", "SIMPLE iteration")
    write_dataset(hist, "q_bottom", res.history_q_bottom_m3_s, "m^3/s",
                  "outflow through the bottom after each iteration")  # fmt: skip
    write_dataset(hist, "window", conv.window, "1", "iterations in the convergence window")
    lg = h5.create_group("lattice")
    write_dataset(lg, "x", res.lattice_x, "m", "cell-centre x")
    write_dataset(lg, "y", res.lattice_y, "m", "cell-centre y")
    write_dataset(lg, "z", res.lattice_z, "m", "cell-centre z (graded above and below the zone)")
    for name, data, unit, desc in (
        ("U", res.U.astype(np.float32), "m/s", "velocity, 0 in removed cells"),
        ("fluid", res.fluid.astype(np.uint8), "1", "1 where the cell is part of the CFD mesh"),
    ):
        ds = lg.create_dataset(name, data=data, compression="gzip", shuffle=True)
        ds.attrs.update(units=unit, description=desc)
    sv = h5.create_group("solver")
    write_solver_record(sv, s, res)
    sv.attrs["fibers"] = geo.fibers
    sv.attrs["wall_time_total_s"] = wall_s
    return out


def report_lines(
    name: str, perm: PermeabilitySection, geo: PermeabilityGeometry, s: BoxSetup,
    res: CaseResult, conv: Convergence, summary: Mapping[str, float], wall_s: float,
) -> list[str]:  # fmt: skip
    what = f"fabric + sheet of {geo.fibers} fibers" if geo.fibers else "bare fabric"
    return [
        f"# Air permeability: scene `{name}` ({what})", "",
        f"- air permeability at {s.delta_p_Pa:g} Pa: **{summary['cfm']:.4g} +- "
        f"{summary['cfm_uncertainty']:.2g} CFM** (superficial velocity "
        f"{summary['superficial_velocity'] * 1e3:.5g} +- "
        f"{summary['superficial_velocity_uncertainty'] * 1e3:.2g} mm/s; 1 CFM = 5.08 mm/s)",
        f"- Darcy permeability of the layer ({(geo.upper_z_m - geo.lower_z_m) * 1e6:.1f} um, "
        f"fabric lower side to the top of the solid): {summary['darcy_k']:.4g} m^2 "
        f"(Reynolds number rho u_s d / mu = {summary['reynolds']:.3g} with d = "
        f"{geo.thinnest_m * 1e6:.3g} um: {'Darcy regime' if summary['reynolds'] < 1 else 'inertia not negligible; k is an apparent value at this pressure drop'})",
        f"- convergence: outflow range over the last {conv.window} iterations "
        f"{conv.relative_amplitude:.2g} of its mean (tolerance {perm.convergence_tolerance:g}): "
        f"{'converged' if conv.converged else '**NOT converged**'}; simpleFoam "
        f"{res.iterations} iterations ("
        + (f"stop_at converged: ends at the first converged window, at most {s.max_iterations}"
           if s.stop_window > 0 else f"stop_at max_iterations: {s.max_iterations}")
        + f"), residual criterion {s.residual_tolerance:g} "
        f"{'met' if res.converged else 'not met'}",
        f"- mass conservation: |inflow - outflow| / outflow = {res.imbalance:.2e}",
        (f"- sub-grid: fibers as a Darcy resistance 1/k(phi) per cell, k from {perm.subgrid_law} "
         f"(fiber radius {(geo.law_radius_m or 0.5 * geo.thinnest_m) * 1e6:.3g} um"
         f"{', hydraulic radius 2A/P of the collapsed section' if any(c.rectangular for c in geo.fiber_chains) else ''}"
         "), yarns removed"
         if perm.mode == "subgrid" else "- resolved: fibers and yarns removed from the mesh"),
        *([f"- fiber sections: collapsed (rectangular), lying flat (thickness vertical, as the "
           f"contact styles' reference direction), thinnest {geo.thinnest_m * 1e6:.3g} um thick"]
          if any(c.rectangular for c in geo.fiber_chains) else []),
        f"- mesh (mode {perm.mode}): cells of {s.cell_size_m * 1e6:.3g} um "
        f"({geo.thinnest_m / s.cell_size_m:.3g} across the thinnest fiber/yarn of "
        f"{geo.thinnest_m * 1e6:.3g} um), "
        f"{res.fluid_cells} fluid cells of {res.lattice_cells} lattice cells",
        f"- air: density {s.density_kg_m3:g} kg/m^3, viscosity {s.viscosity_Pa_s:g} Pa s",
        f"- wall time {wall_s:.1f} s on {s.ranks} rank(s)", "",
        f"Picture: `{PNG_NAME}`; data: `{H5_NAME}`; OpenFOAM case `case/`, logs `log.<tool>`.",
    ]  # fmt: skip


def write_png(path: Path, s: BoxSetup, res: CaseResult, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 5), gridspec_kw={"width_ratios": [1.4, 1]})
    j = len(res.lattice_y) // 2
    speed = np.linalg.norm(res.U[:, j, :, :], axis=-1)
    pc = plot_section(axes[0], s, res, speed, "speed |U|", 0.2e-3)
    ax = axes[0]
    fig.colorbar(pc, ax=ax, label="m/s", shrink=0.8)
    ax = axes[1]
    if len(res.history_iteration):
        ax.plot(res.history_iteration, res.history_q_bottom_m3_s / (s.size_x_m * s.size_y_m) * 1e3, "k-")
    ax.set_xlabel("SIMPLE iteration")
    ax.set_ylabel("outflow / area [mm/s]")
    ax.set_title("flow-rate history")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
