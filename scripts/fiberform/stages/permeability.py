# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``permeability``: air flow through the fabric and the laid-down sheet, reported as the
superficial velocity at the pressure drop of the scene, in CFM and as a Darcy permeability
(Kettil 2016 sec. 4.2, Table 4.1, Fig. 4.11-4.13; issue 12).

Domain and boundary conditions are those of the thesis (sec. 3.1, eq. 3.1-3.3) and of the flow
stage: symmetry on the four vertical sides, fixed pressure at the top and the bottom with
zero-gradient velocity, no-slip on yarns and fibers; laminar steady Navier-Stokes (stock simpleFoam,
SIMPLEC) through :mod:`fiberform.openfoam_case`. Mode ``resolved``: the solid zone (fabric lower
side to the top of the sheet) has cubic cells of d_min / ``cells_across_fiber`` (d_min: the
thinnest fiber diameter, or the thinnest yarn for a bare fabric); each zone cell gets the fraction
of its ``subsamples``^3 sample points inside a fiber or yarn (capsule chains: the yarns of the
generated fabric and the sheet's fibers; imported fabrics through their voxel image), and the cells
with the largest fractions are removed until the removed volume equals the sampled solid volume
(:func:`fiberform.openfoam_case.volume_preserving`). Mode ``subgrid``: cells of
``subgrid_cell_size_m``; yarns removed as above, fibers as a Darcy resistance 1/k(phi) per cell from
the cell's fiber volume fraction and ``subgrid_law`` (Jackson & James 1986 or Drummond & Tahir 1984;
:mod:`fiberform.porous_media`), applied through OpenFOAM's explicitPorositySource.

Convergence (thesis sec. 5.2: the permeability "oscillates"): simpleFoam stops when the initial
residuals of p and U fall below ``residual_tolerance`` or at ``max_iterations``; the outflow through
the bottom is recorded at every iteration, and the result is the mean over the last
``convergence_window`` iterations, with half its range as the uncertainty; it counts as converged
when the range is at most ``convergence_tolerance`` of the mean.

Products in ``<output_dir>/permeability-laydown/`` (scene with a ``laydown`` section: fabric plus
the sheet of the lay-down) or ``<output_dir>/permeability-fabric/`` (bare fabric):
``permeability.h5``, ``report.md``, ``permeability.png``. Page: docs/stages/permeability.md.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt

from ..errors import ConfigError, StageError
from ..fabric_geometry import VoxelImage
from ..openfoam_case import (
    BoxSetup, CaseResult, Lattice, SolidFraction, make_lattice, plot_section, run_case,
    template_hash, write_solver_record,
)  # fmt: skip
from ..porous_media import (
    CFM_M_S, Convergence, capsule_fraction, flow_rate_convergence, image_fraction,
    line_fraction, subgrid_resistance,
)  # fmt: skip
from ..products import (
    FABRIC_H5, FIBERS_H5, LAYDOWN_H5, PRESS_H5, Chain, read_fabric_image, read_sheet_chains,
    read_yarn_chains,
)  # fmt: skip
from ..provenance import file_hash, write_dataset
from ..scene import PermeabilitySection, Scene
from ._stage import Stage, StageContext

__all__ = [
    "PermeabilityGeometry", "PermeabilityStage", "case_setup", "darcy_permeability",
    "fiber_resistance", "solid_fraction",
]

H5_NAME, REPORT_NAME, PNG_NAME = "permeability.h5", "report.md", "permeability.png"

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PermeabilityGeometry:
    """The solid of one permeability run (SI units)."""

    size_x_m: float
    size_y_m: float
    lower_z_m: float  # fabric lower side
    upper_z_m: float  # highest solid point (fabric or sheet)
    thinnest_m: float  # diameter of the thinnest fiber (or yarn; or the voxel size)
    yarns: tuple[Chain, ...]
    fiber_chains: tuple[Chain, ...] = ()
    image: object | None = None  # VoxelImage of an imported fabric (no yarn chains)

    @property
    def fibers(self) -> int:
        return len(self.fiber_chains)


def darcy_permeability(u_s_m_s: float, mu_Pa_s: float, thickness_m: float, dp_Pa: float) -> float:
    """Darcy permeability k = mu u_s L / delta_p [m^2] of a layer of thickness L."""
    return mu_Pa_s * u_s_m_s * thickness_m / dp_Pa


def case_setup(perm: PermeabilitySection, geo: PermeabilityGeometry) -> BoxSetup:
    """The box case of a permeability run: zone cells of thinnest / cells_across_fiber (resolved)
    or subgrid_cell_size_m (subgrid)."""
    if perm.mode == "subgrid":
        h = perm.subgrid_cell_size_m
    else:
        h = geo.thinnest_m / perm.cells_across_fiber
    return BoxSetup(
        size_x_m=geo.size_x_m,
        size_y_m=geo.size_y_m,
        fabric_lo_z_m=geo.lower_z_m,
        fabric_hi_z_m=geo.upper_z_m,
        top_z_m=geo.upper_z_m + perm.height_above_m,
        cell_size_m=h,
        max_cell_height_m=perm.max_cell_height_m or 8.0 * h,
        delta_p_Pa=perm.pressure_drop_Pa,
        density_kg_m3=perm.density_kg_m3,
        viscosity_Pa_s=perm.viscosity_Pa_s,
        max_iterations=perm.max_iterations,
        residual_tolerance=perm.residual_tolerance,
        ranks=perm.ranks,
    )


def solid_fraction(geo: PermeabilityGeometry, perm: PermeabilitySection) -> SolidFraction:
    """The cells' solid fraction: yarns (or the voxel image) and, in mode resolved, the fibers."""
    chains = list(geo.yarns) + (list(geo.fiber_chains) if perm.mode == "resolved" else [])

    def frac(s: BoxSetup, lat: Lattice) -> npt.NDArray[np.float32]:
        out = capsule_fraction([(c.points, c.radius) for c in chains], s, lat, perm.subsamples)
        if geo.image is not None:
            img = geo.image
            assert isinstance(img, VoxelImage)
            out = np.maximum(out, image_fraction(img, s, lat, perm.subsamples))
        return out

    return frac


def fiber_resistance(geo: PermeabilityGeometry, perm: PermeabilitySection) -> SolidFraction | None:
    """Mode subgrid: Darcy resistance 1/k of each cell from its fiber volume fraction and the
    law ``subgrid_law`` (fiber radius: the thinnest fiber's); None in mode resolved."""
    if perm.mode != "subgrid" or not geo.fiber_chains:
        return None
    chains = [(c.points, c.radius) for c in geo.fiber_chains]

    def resistance(s: BoxSetup, lat: Lattice) -> npt.NDArray[np.float64]:
        phi = line_fraction(chains, s, lat)
        return subgrid_resistance(phi, 0.5 * geo.thinnest_m, perm.subgrid_law)

    return resistance


def _expected_cells(scene: Scene) -> tuple[float, float]:
    """(cell size, lattice cells) estimated from the scene alone, for the up-front check."""
    perm, fab = scene.permeability, scene.fabric
    assert perm is not None and fab is not None
    thick = fab.md_diameter_m * 3 + fab.cd_top_diameter_m + fab.cd_bottom_diameter_m
    thinnest = min(fab.md_diameter_m, fab.cd_top_diameter_m, fab.cd_bottom_diameter_m)
    if scene.laydown is not None and scene.fibers is not None:
        thinnest = scene.fibers.width_m
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
    code_version = 1

    #: the sheet this stage puts on the fabric (a product with /sheet/x, fiber_id, offsets)
    sheet_product = LAYDOWN_H5

    def stage_dir(self, ctx: StageContext) -> Path:
        kind = "laydown" if ctx.scene.laydown is not None else "fabric"
        return ctx.scene.output_path / f"{self.folder}-{kind}"

    def results(self, ctx: StageContext) -> list[str]:
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            r = h5["result"]
            what = self.stage_dir(ctx).name.removeprefix("permeability-")
            sheet = {"fabric": "bare fabric", "laydown": "fabric + laid-down sheet",
                     "press": "fabric + pressed sheet"}.get(what, what)
            return [f"air permeability ({sheet}) at {float(r['pressure_drop'][()]):g} Pa: "
                    f"{float(r['cfm'][()]):.4g} +- {float(r['cfm_uncertainty'][()]):.2g} CFM "
                    f"({'converged' if r.attrs['converged'] else 'NOT converged'})"]

    def check_scene(self, scene: Scene) -> list[str]:
        problems = super().check_scene(scene)
        if problems:
            return problems
        perm = scene.permeability
        assert perm is not None
        if scene.laydown is not None and scene.fibers is not None:
            if scene.fibers.cross_section != "circular":
                problems.append(
                    "fibers.cross_section = 'rectangular': the permeability stage resolves circular "
                    "fiber sections only so far (allowed: circular)"
                )
        h, cells = _expected_cells(scene)
        field = "subgrid_cell_size_m" if perm.mode == "subgrid" else "cells_across_fiber"
        if (perm.mode == "subgrid" and scene.laydown is not None and scene.fibers is not None
                and perm.subgrid_cell_size_m < scene.fibers.width_m):
            problems.append(
                f"permeability.subgrid_cell_size_m = {perm.subgrid_cell_size_m!r}: smaller than "
                f"the fiber width ({scene.fibers.width_m!r} m); the sub-grid laws need cells at "
                "least one fiber wide (use mode resolved for finer cells)"
            )
        if cells > perm.max_cells:
            problems.append(
                f"permeability.{field} = {getattr(perm, field)!r}: cells of "
                f"{h:.3g} m give about {cells:.3g} cells in the fabric zone alone (limit "
                f"permeability.max_cells = {perm.max_cells!r})"
            )
        return problems

    def needs(self, ctx: StageContext) -> dict[str, Path]:
        return self._upstream(ctx)

    def _upstream(self, ctx: StageContext) -> dict[str, Path]:
        root = ctx.scene.output_path
        paths = {"fabric_h5": root / FABRIC_H5}
        if ctx.scene.laydown is not None:
            paths["sheet_h5"] = root / self.sheet_product
            paths["fibers_h5"] = root / FIBERS_H5
        return paths

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        hashes = super().input_hashes(ctx)
        for key, p in self._upstream(ctx).items():
            hashes[key] = file_hash(p) if p.is_file() else "missing"
        hashes["case_template"] = template_hash()
        return hashes

    def preflight(self, ctx: StageContext) -> None:
        for key, p in self._upstream(ctx).items():
            if not p.is_file():
                raise StageError(f"permeability needs {p} ({key}): run the upstream stages first "
                                 "(fiberform run SCENE runs them in order)")  # fmt: skip
        if shutil.which("simpleFoam") is None:
            raise ConfigError("simpleFoam not found on PATH (install Debian's openfoam package)")

    def geometry(self, ctx: StageContext) -> PermeabilityGeometry:
        paths = self._upstream(ctx)
        img = read_fabric_image(paths["fabric_h5"])
        yarns = read_yarn_chains(paths["fabric_h5"])
        fibers = read_sheet_chains(paths["sheet_h5"], paths["fibers_h5"]) if "sheet_h5" in paths else []
        up = img.upper
        top = float(up[2])
        for c in fibers:
            top = max(top, float(np.max(c.points[:, 2])) + c.radius)
        if fibers:
            thinnest = 2.0 * min(c.radius for c in fibers)
        elif "sheet_h5" in paths and ctx.scene.fibers is not None:
            thinnest = ctx.scene.fibers.width_m  # an empty sheet: the mesh of the sheets
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
        )

    def produce(
        self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str]
    ) -> None:
        perm = ctx.scene.permeability
        assert perm is not None
        geo = self.geometry(ctx)
        s = case_setup(perm, geo)
        lat = make_lattice(s)
        if lat.cells > perm.max_cells:
            raise StageError(
                f"permeability: the lattice has {lat.cells} cells of {s.cell_size_m:.3g} m (limit "
                f"permeability.max_cells = {perm.max_cells}); lower cells_across_fiber or raise "
                "subgrid_cell_size_m"
            )
        start = time.monotonic()
        res = run_case(
            s, solid_fraction(geo, perm), self.stage_dir(ctx), record_flow_rate=True,
            preserve_volume=True, resistance=fiber_resistance(geo, perm),
            oversubscribe=ctx.oversubscribe, show_progress=ctx.show_progress,
        )  # fmt: skip
        wall = time.monotonic() - start
        conv = flow_rate_convergence(res.history_q_bottom_m3_s, perm.convergence_window,
                                     perm.convergence_tolerance)  # fmt: skip
        summary = write_permeability_h5(h5, perm, geo, s, res, conv, wall)
        title = (f"permeability of scene '{ctx.scene.name}' ({geo.fibers} fibers): "
                 f"{summary['cfm']:.4g} +- {summary['cfm_uncertainty']:.2g} CFM at "
                 f"{s.delta_p_Pa:g} Pa")  # fmt: skip
        write_png(tmp[PNG_NAME], s, res, title)
        tmp[REPORT_NAME].write_text("\n".join(report_lines(ctx.scene.name, perm, geo, s, res, conv,
                                                           summary, wall)) + "\n")  # fmt: skip
        if not conv.converged:
            print(f"permeability: warning: the outflow varied by {conv.relative_amplitude:.2g} of "
                  f"its mean over the last {conv.window} iterations (tolerance "
                  f"{perm.convergence_tolerance:g}); see {self.stage_dir(ctx) / REPORT_NAME}")


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
        f"{res.iterations} iterations, residual criterion {s.residual_tolerance:g} "
        f"{'met' if res.converged else 'not met'}",
        f"- mass conservation: |inflow - outflow| / outflow = {res.imbalance:.2e}",
        (f"- sub-grid: fibers as a Darcy resistance 1/k(phi) per cell, k from {perm.subgrid_law} "
         f"(fiber radius {geo.thinnest_m * 0.5e6:.3g} um), yarns removed"
         if perm.mode == "subgrid" else "- resolved: fibers and yarns removed from the mesh"),
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
