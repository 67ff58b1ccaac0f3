# SPDX-License-Identifier: GPL-3.0-or-later
"""Sections several stages share: domain, fluid, contact law, run."""

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from ._fields import Acceleration, Coordinate, _Section, _element_range, choice, quantity, scene_problem


class DomainSection(_Section):
    """The simulation box."""

    lo_m: list[Coordinate] = _element_range(
        "Lower corner of the box (x, y, z)", "m", "-10 <= x <= 10"
    )
    hi_m: list[Coordinate] = _element_range(
        "Upper corner of the box (x, y, z), above lo_m in every component", "m", "-10 <= x <= 10"
    )

    @model_validator(mode="after")
    def _check(self) -> DomainSection:
        for axis, (lo, hi) in enumerate(zip(self.lo_m, self.hi_m, strict=True)):
            if not hi > lo:
                raise scene_problem(
                    f"hi_m[{axis}]", f"must be greater than lo_m[{axis}] = {lo!r}", hi
                )
        return self


class FluidSection(_Section):
    """The suspending fluid (water by default)."""

    density_kg_m3: float = quantity("Fluid density", "kg/m^3", default=998.2, gt=0.0, le=2.0e4)
    viscosity_Pa_s: float = quantity(
        "Dynamic viscosity of the fluid", "Pa s", default=1.0e-3, gt=0.0, le=1.0e3
    )
    gravity_m_s2: list[Acceleration] = _element_range(
        "Gravitational acceleration (x, y, z)",
        "m/s^2",
        "-1000 <= x <= 1000",
        default=[0.0, 0.0, -9.81],
    )
    temperature_K: float = quantity(
        "Fluid temperature: the thermal energy kT and the Debye length of the contact law's "
        "electrostatic term (permittivity: water's at 25 C, 78.5)",
        "K",
        default=298.15,
        ge=273.15,
        le=373.15,
        # until session 30 the default read 293.15 K but reached nothing: the law kept its own
        # 298.15 K. The products made then hold 293.15 in their hashes, so the default hashes as
        # that: it is what they were computed with.
        hashed_as={298.15: 293.15},
    )


ContactTerm = Literal["vdw", "es", "steric"]


class ContactSection(_Section):
    """Contact model between fibers."""

    model: Literal["fiber_dlvo"] = choice(
        "Contact model: fiber_dlvo (pair_style fiber/dlvo: the thesis' extended DLVO plus steric "
        "repulsion, sub-integrated per contact)"
    )
    integrator: Literal["cvode", "substep", "none"] = choice(
        "Per-contact time integration (none: forces from the plain DEM step)", default="none"
    )
    terms: list[ContactTerm] = choice(
        "Colloidal force terms (fiber_dlvo only)", default=[]
    )
    hamaker_J: float | None = quantity(
        "Hamaker constant of the van der Waals term (required with vdw)",
        "J",
        default=None,
        gt=0.0,
        le=1.0e-18,
    )
    ionic_strength_mol_m3: float | None = quantity(
        "Ionic strength of the electrolyte (required with es)",
        "mol/m^3",
        default=None,
        gt=0.0,
        le=1.0e4,
    )
    surface_potential_V: float | None = quantity(
        "Surface potential of the fibers (required with es)", "V", default=None, ge=-1.0, le=1.0
    )
    cutoff_m: float | None = quantity(
        "Range of the colloidal forces beyond contact (absent: chosen by the model)",
        "m",
        default=None,
        gt=0.0,
        le=1.0e-3,
    )
    substeps: int = quantity(
        "Velocity-Verlet sub-steps per step of each contact (integrator substep only)", "1",
        default=100, ge=1, le=100000,
    )  # fmt: skip
    points_per_element: int | None = quantity(
        "Contact points per fiber element (fiber_dlvo; absent: chosen by the pair style, "
        "auto 1e-9)", "1", default=None, ge=1, le=64,
    )  # fmt: skip

    @model_validator(mode="after")
    def _check(self) -> ContactSection:
        if len(set(self.terms)) != len(self.terms):
            raise scene_problem("terms", "terms must not repeat", self.terms)
        if self.model == "fiber_dlvo" and not self.terms:
            raise scene_problem("terms", "fiber_dlvo needs at least one of vdw, es, steric", [])
        if "vdw" in self.terms and self.hamaker_J is None:
            raise scene_problem("hamaker_J", "required when terms contains vdw")
        if "es" in self.terms:
            if self.ionic_strength_mol_m3 is None:
                raise scene_problem("ionic_strength_mol_m3", "required when terms contains es")
            if self.surface_potential_V is None:
                raise scene_problem("surface_potential_V", "required when terms contains es")
        return self


class RunSection(_Section):
    """Time stepping and parallel run."""

    timestep_s: float = quantity("Time step of the particle (DEM) solver", "s", gt=0.0, le=1.0)
    duration_s: float = quantity("Simulated time", "s", gt=0.0, le=1.0e6)
    ranks: int = quantity(
        "MPI ranks (at most the machine's cores, unless --oversubscribe)",
        "1",
        default=1,
        ge=1,
        le=64,
    )
    output_interval_s: float | None = quantity(
        "Simulated time between outputs (absent: 100 outputs per run)",
        "s",
        default=None,
        gt=0.0,
        le=1.0e6,
    )

    @model_validator(mode="after")
    def _check(self) -> RunSection:
        if self.timestep_s > self.duration_s:
            raise scene_problem(
                "timestep_s", f"must not exceed duration_s = {self.duration_s!r}", self.timestep_s
            )
        if self.steps > 10**10:
            raise scene_problem(
                "duration_s",
                f"too many steps ({self.steps:.3g} > 1e10) for timestep_s = {self.timestep_s!r}",
                self.duration_s,
            )
        if self.output_interval_s is not None and not (
            self.timestep_s <= self.output_interval_s <= self.duration_s
        ):
            raise scene_problem(
                "output_interval_s",
                f"must lie between timestep_s = {self.timestep_s!r} and "
                f"duration_s = {self.duration_s!r}",
                self.output_interval_s,
            )
        return self

    @property
    def steps(self) -> int:
        """Number of time steps, at least 1."""
        return max(1, round(self.duration_s / self.timestep_s))

    @property
    def output_every_steps(self) -> int:
        """Output interval in steps, at least 1."""
        if self.output_interval_s is None:
            return max(1, self.steps // 100)
        return max(1, round(self.output_interval_s / self.timestep_s))
