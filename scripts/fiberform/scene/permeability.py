# SPDX-License-Identifier: GPL-3.0-or-later
"""Section of the ``permeability`` stages."""

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from ._fields import _Section, choice, quantity, scene_problem


class PermeabilitySection(_Section):
    """Air permeability of the fabric and the laid-down sheet (stage ``permeability``, OpenFOAM
    simpleFoam; Kettil 2016 sec. 4.2: Frazier / ASTM D737 condition, 125 Pa)."""

    density_kg_m3: float = quantity(
        "Density of the fluid: air (the default) for the thesis' CFM; water (998.2) to compare "
        "with the lay-down's drainage", "kg/m^3", default=1.204, gt=0.0, le=2000.0
    )
    viscosity_Pa_s: float = quantity(
        "Dynamic viscosity of the fluid (default: air)", "Pa s", default=1.81e-5, gt=0.0, le=1.0
    )
    pressure_drop_Pa: float = quantity(
        "Pressure drop from the top to the bottom of the domain (125 Pa: ASTM D737)", "Pa",
        default=125.0, gt=0.0, le=1.0e5,
    )  # fmt: skip
    forchheimer_pressure_drop_Pa: float | None = quantity(
        "Second pressure drop: a second run at it, and the Darcy permeability k_D and Forchheimer "
        "coefficient beta of dp / L = (mu / k_D) u + beta rho u^2 fitted through the two runs "
        "(absent: one run, no fit; must differ from pressure_drop_Pa)", "Pa", default=None,
        gt=0.0, le=1.0e5,
    )  # fmt: skip
    mode: Literal["resolved", "subgrid"] = choice(
        "How the fibers enter the flow: resolved (cells removed where fibers and yarns are, cells "
        "of thinnest fiber / cells_across_fiber) or subgrid (cells of subgrid_cell_size_m; yarns "
        "removed, fibers as a Darcy resistance from the fiber volume fraction of each cell)",
        default="resolved",
    )
    subgrid_cell_size_m: float = quantity(
        "Cell size of the solid zone in mode subgrid (at least the fiber width)", "m",
        default=50e-6, ge=1e-6, le=1e-3,
    )  # fmt: skip
    subgrid_law: Literal["jackson_james", "drummond_tahir"] = choice(
        "Permeability law of the fiber-filled cells in mode subgrid: jackson_james (random 3D "
        "fiber networks, Jackson & James 1986) or drummond_tahir (square arrays, transverse flow, "
        "Drummond & Tahir 1984)", default="jackson_james",
    )
    cells_across_fiber: int = quantity(
        "CFD cells across the thinnest fiber (its diameter, or the thickness of a collapsed "
        "fiber; bare fabric: across the thinnest yarn); sets the cubic cell size of the solid "
        "zone", "1", default=4, ge=1, le=64,
    )  # fmt: skip
    subsamples: int = quantity(
        "Sample points per cell edge for the solid volume fraction of a cell (subsamples^3 per "
        "cell; the cells with the largest fractions are removed up to the sampled solid volume)",
        "1", default=4, ge=1, le=16,
    )  # fmt: skip
    height_above_m: float = quantity(
        "Domain top above the highest solid point (fabric or sheet)", "m", default=0.5e-3,
        gt=0.0, le=0.1,
    )  # fmt: skip
    max_cell_height_m: float | None = quantity(
        "Largest cell height far above and below the solid zone (absent: 8 cells of the zone)",
        "m", default=None, gt=0.0, le=5e-3,
    )  # fmt: skip
    max_cells: int = quantity(
        "Largest number of lattice cells (the scene is refused above it, before any run)", "1",
        default=2_000_000, ge=1000, le=100_000_000,
    )  # fmt: skip
    max_iterations: int = quantity(
        "Largest number of SIMPLE iterations", "1", default=3000, ge=10, le=100000
    )
    residual_tolerance: float = quantity(
        "Initial residual of p and U at which simpleFoam stops", "1", default=1e-6,
        gt=0.0, le=1e-2,
    )  # fmt: skip
    convergence_window: int = quantity(
        "Iterations at the end of the run over which the outflow must be steady", "1",
        default=200, ge=2, le=100000,
    )  # fmt: skip
    convergence_tolerance: float = quantity(
        "Largest (max - min) / mean of the outflow over the window for a converged result", "1",
        default=1e-3, gt=0.0, le=0.5,
    )  # fmt: skip
    stop_at: Literal["converged", "max_iterations"] = choice(
        "When simpleFoam stops: converged = at the first iteration whose last convergence_window "
        "outflows meet convergence_tolerance (fiberform's function object flowRateConvergence; "
        "the result is the mean over that window), max_iterations = only at max_iterations or "
        "residual_tolerance (the result is the mean over the last window then)",
        default="converged",
    )
    ranks: int = quantity(
        "MPI ranks of the solver (> 1: decomposePar + simpleFoam -parallel)", "1",
        default=1, ge=1, le=64,
    )  # fmt: skip

    @model_validator(mode="after")
    def _check(self) -> PermeabilitySection:
        if self.mode == "resolved":
            for name in ("subgrid_cell_size_m", "subgrid_law"):
                if name in self.model_fields_set:
                    raise scene_problem(name, "only used with mode subgrid", getattr(self, name))
        elif "cells_across_fiber" in self.model_fields_set:
            raise scene_problem("cells_across_fiber", "only used with mode resolved (subgrid: "
                                "subgrid_cell_size_m)", self.cells_across_fiber)
        if self.convergence_window > self.max_iterations:
            raise scene_problem("convergence_window", "must not exceed max_iterations "
                                f"= {self.max_iterations!r}", self.convergence_window)
        if self.forchheimer_pressure_drop_Pa == self.pressure_drop_Pa:
            raise scene_problem("forchheimer_pressure_drop_Pa", "must differ from "
                                f"pressure_drop_Pa = {self.pressure_drop_Pa!r} (two points are "
                                "needed for the fit)", self.forchheimer_pressure_drop_Pa)
        return self
