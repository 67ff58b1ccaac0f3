# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene files: YAML validated by a pydantic v2 schema.

Conventions (see docs/stages/scene-format.md, whose field table ``fiberform schema`` generates
from this module):

* Every number carries its SI unit as a name suffix (``length_m``, ``viscosity_Pa_s``) and a checked
  range; dimensionless numbers have none.
* Every string is a fixed choice (``Literal``), an identifier
  (``^[A-Za-z][A-Za-z0-9_]{0,63}$``) or a validated relative path, so nothing a scene holds can
  smuggle a LIGGGHTS ``shell`` command or an OpenFOAM ``#codeStream`` into generated input.
* Unknown keys are errors (``extra="forbid"``); types are strict (``"1e-3"`` in quotes is a string,
  not a number); optional sections may be absent, so each scene enables only what it needs.

Errors are reported as :class:`~fiberform.errors.SceneError` with one line per problem naming the
field path, the value given and the allowed range.
"""

from __future__ import annotations

import hashlib
import json
import re
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)
from pydantic.fields import FieldInfo
from pydantic_core import PydanticCustomError

from .errors import SceneError
from .inputs import IDENTIFIER_PATTERN, is_identifier

__all__ = [
    "ContactSection",
    "DemoParticlesSection",
    "DomainSection",
    "FabricSection",
    "FlowSection",
    "LaydownSection",
    "PermeabilitySection",
    "FibersSection",
    "FluidSection",
    "RunSection",
    "Scene",
    "SECTIONS",
    "field_table",
    "load_scene",
    "parse_scene",
    "read_scene_yaml",
    "scene_problem",
    "section_hash",
]

MAX_SCENE_BYTES = 1 << 20

# --------------------------------------------------------------------------------------------
# Field helpers


def _num(v: float) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


def _range_text(
    gt: float | None, ge: float | None, lt: float | None, le: float | None
) -> str | None:
    lo = f"{_num(gt)} < x" if gt is not None else (f"{_num(ge)} <= x" if ge is not None else None)
    hi = f"x < {_num(lt)}" if lt is not None else (f"x <= {_num(le)}" if le is not None else None)
    if lo and hi:
        return lo + hi[1:]
    return lo or hi


def quantity(
    meaning: str,
    unit: str,
    *,
    default: Any = ...,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
) -> Any:
    """A numeric field: ``meaning`` and ``unit`` go into the description (``1`` = dimensionless)."""
    rng = _range_text(gt, ge, lt, le)
    return Field(
        default,
        description=f"{meaning} [{unit}]",
        gt=gt,
        ge=ge,
        lt=lt,
        le=le,
        json_schema_extra={"unit": unit, "meaning": meaning, "range": rng or "any"},
    )


def _element_range(
    meaning: str, unit: str, rng: str, default: Any = ..., length: int = 3
) -> Any:
    return Field(
        default,
        description=f"{meaning} [{unit}]",
        min_length=length,
        max_length=length,
        json_schema_extra={
            "unit": unit,
            "meaning": meaning,
            "range": f"{length} values, each {rng}",
        },
    )


def choice(meaning: str, *, default: Any = ...) -> Any:
    """A field whose type is a ``Literal`` (or a list of one)."""
    return Field(default, description=meaning, json_schema_extra={"unit": "-", "meaning": meaning})


def _check_identifier(value: str) -> str:
    if not is_identifier(value):
        raise PydanticCustomError(
            "identifier",
            "not an identifier (a letter followed by up to 63 letters, digits or underscores)",
        )
    return value


Identifier = Annotated[str, AfterValidator(_check_identifier)]

_PATH_PART = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")


def _check_relative_path(value: str) -> str:
    bad = PydanticCustomError(
        "relative_path",
        "not a safe relative path (up to 16 parts separated by '/', each of letters, digits, "
        "'_', '.', '-', not starting with '.' or '-'; no '..', not absolute)",
    )
    if value.startswith("/") or "\\" in value or value.endswith("/"):
        raise bad
    parts = value.split("/")
    if not 1 <= len(parts) <= 16:
        raise bad
    for part in parts:
        if _PATH_PART.fullmatch(part) is None or part in (".", ".."):
            raise bad
    return value


RelativePath = Annotated[str, AfterValidator(_check_relative_path)]


def scene_problem(field: str, message: str, value: Any = None) -> PydanticCustomError:
    """An error for a cross-field check, attached to ``field`` of the section being validated."""
    return PydanticCustomError(
        "field_problem", "{message}", {"field": field, "value": value, "message": message}
    )


class _Section(BaseModel):
    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        allow_inf_nan=False,
        frozen=True,
        validate_default=True,
    )


Coordinate = Annotated[float, Field(ge=-10.0, le=10.0)]
Acceleration = Annotated[float, Field(ge=-1000.0, le=1000.0)]

# --------------------------------------------------------------------------------------------
# Sections


class DomainSection(_Section):
    """The simulation box."""

    lo_m: list[Coordinate] = _element_range(
        "Lower corner of the box (x, y, z)", "m", "-10 <= x <= 10"
    )
    hi_m: list[Coordinate] = _element_range(
        "Upper corner of the box (x, y, z), above lo_m in every component", "m", "-10 <= x <= 10"
    )
    periodic: list[Literal["x", "y", "z"]] = choice(
        "Periodic directions", default=[]
    )

    @model_validator(mode="after")
    def _check(self) -> DomainSection:
        for axis, (lo, hi) in enumerate(zip(self.lo_m, self.hi_m, strict=True)):
            if not hi > lo:
                raise scene_problem(
                    f"hi_m[{axis}]", f"must be greater than lo_m[{axis}] = {lo!r}", hi
                )
        if len(set(self.periodic)) != len(self.periodic):
            raise scene_problem("periodic", "directions must not repeat", self.periodic)
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
        "Fluid temperature (enters thermal energy kT of DLVO terms)",
        "K",
        default=293.15,
        ge=273.15,
        le=373.15,
    )


class FibersSection(_Section):
    """Flexible fibers, each a chain of segments (beads joined by beams)."""

    count: int | None = quantity(
        "Number of fibers (give this or target_mass_kg)", "1", default=None, ge=1, le=10_000_000
    )
    target_mass_kg: float | None = quantity(
        "Total fiber mass to insert (give this or count)", "kg", default=None, gt=0.0, le=1.0
    )
    length_m: float = quantity("Fiber length", "m", gt=0.0, le=0.1)
    width_m: float = quantity(
        "Fiber width (the diameter for a circular cross-section)", "m", gt=0.0, le=1.0e-3
    )
    thickness_m: float | None = quantity(
        "Fiber thickness (rectangular cross-section only)", "m", default=None, gt=0.0, le=1.0e-3
    )
    segments: int = quantity(
        "Segments per fiber (nodes = segments + 1)", "1", ge=1, le=1000
    )
    density_kg_m3: float = quantity("Fiber density", "kg/m^3", default=1500.0, gt=0.0, le=2.0e4)
    youngs_modulus_Pa: float = quantity(
        "Young's modulus of the fiber wall", "Pa", gt=0.0, le=1.0e12
    )
    shear_modulus_Pa: float = quantity("Shear modulus of the fiber wall", "Pa", gt=0.0, le=1.0e12)
    cross_section: Literal["circular", "rectangular"] = choice(
        "Cross-section shape", default="circular"
    )

    @model_validator(mode="after")
    def _check(self) -> FibersSection:
        if (self.count is None) == (self.target_mass_kg is None):
            raise scene_problem("count", "give exactly one of count and target_mass_kg", self.count)
        if self.cross_section == "rectangular" and self.thickness_m is None:
            raise scene_problem("thickness_m", "required when cross_section is rectangular")
        if self.cross_section == "circular" and self.thickness_m is not None:
            raise scene_problem(
                "thickness_m",
                "only used when cross_section is rectangular (circular uses width_m)",
                self.thickness_m,
            )
        return self


class DistributionSpec(_Section):
    """A sampled quantity (stage generate): fixed, uniform, normal, lognormal, or data (a column
    of fiber_generation.data_csv, sampled uniformly); min/max truncate. Units: those of the key
    holding it (length_m, width_m in m; curvature_alpha dimensionless)."""

    kind: Literal["fixed", "uniform", "normal", "lognormal", "data"] = choice(
        "Distribution kind", default="fixed"
    )
    value: float | None = quantity("Value (kind fixed), in the unit of the enclosing key", "-", default=None)
    low: float | None = quantity("Lower bound (kind uniform), unit of the key", "-", default=None)
    high: float | None = quantity("Upper bound (kind uniform), unit of the key", "-", default=None)
    mean: float | None = quantity("Mean (normal, lognormal), unit of the key", "-", default=None)
    sd: float | None = quantity(
        "Standard deviation (normal, lognormal), unit of the key", "-", default=None, ge=0.0
    )
    column: Identifier | None = Field(
        default=None,
        description="CSV column (kind data; default: the key name)",
        json_schema_extra={
            "unit": "-",
            "meaning": "CSV column (kind data; default: the key name)",
            "range": f"identifier ^{IDENTIFIER_PATTERN}$",
        },
    )
    min: float | None = quantity("Truncate below (resample), unit of the key", "-", default=None)
    max: float | None = quantity("Truncate above (resample), unit of the key", "-", default=None)

    @model_validator(mode="after")
    def _check(self) -> DistributionSpec:
        need = {"fixed": ("value",), "uniform": ("low", "high"), "normal": ("mean", "sd"),
                "lognormal": ("mean", "sd"), "data": ()}[self.kind]
        for name in need:
            if getattr(self, name) is None:
                raise scene_problem(name, f"required for kind {self.kind}")
        if self.kind == "uniform" and not (self.high or 0) > (self.low or 0):
            raise scene_problem("high", "must be greater than low", self.high)
        if self.kind == "lognormal" and not (self.mean or 0) > 0:
            raise scene_problem("mean", "must be > 0 for lognormal", self.mean)
        return self


class FiberGenerationSection(_Section):
    """Distributions and options of the ``generate`` stage (thesis sec. 3.4); absent entries
    fall back to the fixed values of the fibers section."""

    data_csv: RelativePath | None = Field(
        default=None,
        description="CSV of measured values (header: length_m, width_m, curvature_alpha), "
        "relative to the scene file",
        json_schema_extra={
            "unit": "-",
            "meaning": "CSV of measured values (columns length_m, width_m, curvature_alpha), "
            "relative to the scene file",
            "range": "relative path without '..'",
        },
    )
    length_m: DistributionSpec | None = Field(default=None, description="Fiber length [m]")
    width_m: DistributionSpec | None = Field(default=None, description="Fiber width [m]")
    curvature_alpha: DistributionSpec | None = Field(
        default=None, description="Curvature parameter alpha in (0, 1], per node (1: straight)"
    )
    fines_fraction: float = quantity(
        "Number fraction of fines (short fibers)", "1", default=0.0, ge=0.0, le=1.0
    )
    fines_length_m: DistributionSpec | None = Field(
        default=None, description="Length of fines [m] (required if fines_fraction > 0)"
    )
    element_length_m: float | None = quantity(
        "Target element length (absent: fibers.segments elements per fiber)", "m",
        default=None, gt=0.0, le=0.1,
    )
    wall_fraction: float = quantity(
        "Wall thickness / outer radius (1: solid; inner radii b = (1 - f) a)", "1",
        default=1.0, gt=0.0, le=1.0,
    )
    twist_max_rad: float = quantity(
        "Largest random rotation of t1 about t3 from node to node, in radians", "1",
        default=0.1, ge=0.0, le=3.2,
    )
    radius_jitter: float = quantity(
        "Relative random variation of the section radii per node", "1",
        default=0.02, ge=0.0, lt=0.5,
    )
    max_attempts: int = quantity(
        "Placement attempts per fiber before giving up", "1", default=1000, ge=1, le=10**7
    )
    placement_lo_m: list[Coordinate] | None = _element_range(
        "Lower corner of the box fibers are placed in (absent: domain.lo_m)", "m",
        "-10 <= x <= 10", default=None,
    )
    placement_hi_m: list[Coordinate] | None = _element_range(
        "Upper corner of the placement box (absent: domain.hi_m)", "m", "-10 <= x <= 10",
        default=None,
    )

    @model_validator(mode="after")
    def _check(self) -> FiberGenerationSection:
        if self.fines_fraction > 0 and self.fines_length_m is None:
            raise scene_problem("fines_length_m", "required when fines_fraction > 0")
        return self


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


class DemoParticlesSection(_Section):
    """Two equal spheres approaching head-on along x (the ``demo-particles`` stage)."""

    radius_m: float = quantity("Sphere radius", "m", gt=0.0, le=0.1)
    density_kg_m3: float = quantity("Sphere density", "kg/m^3", default=1500.0, gt=0.0, le=2.0e4)
    speed_m_s: float = quantity(
        "Speed of each sphere towards the other", "m/s", gt=0.0, le=100.0
    )
    gap_m: float = quantity("Initial surface-to-surface gap", "m", ge=0.0, le=1.0)
    stiffness_N_m: float = quantity(
        "Spring stiffness k of the harmonic repulsion F = k * overlap", "N/m", gt=0.0, le=1.0e12
    )


class FabricSection(_Section):
    """The forming fabric (the ``fabric`` stage): a generated double-layer weave or an import."""

    source: Literal["generate", "voxels", "stl"] = choice(
        "generate: the parametric double-layer weave; voxels: a voxel image (HDF5 dataset 'solid' "
        "with attribute voxel_size_m); stl: a closed surface mesh",
        default="generate",
    )
    import_file: RelativePath | None = Field(
        default=None,
        description="File to import (source voxels or stl), relative to the working directory",
        json_schema_extra={"unit": "-", "meaning": "File to import (voxels or stl)",
                           "range": "relative path without '..'"},
    )  # fmt: skip
    import_unit_m: float = quantity(
        "Length of one STL coordinate unit (1e-3 for a file in millimetres)", "m",
        default=1.0, gt=0.0, le=1.0,
    )  # fmt: skip
    size_x_m: float = quantity("Piece length along x (MD)", "m", default=3.0e-3, gt=0.0, le=0.02)
    size_y_m: float = quantity("Piece width along y (CD)", "m", default=3.0e-3, gt=0.0, le=0.02)
    lower_side_z_m: float = quantity(
        "Height of the fabric's lower side above the domain bottom", "m", default=2.0e-3,
        ge=0.0, le=0.1,
    )  # fmt: skip
    md_diameter_m: float = quantity("Warp (MD) yarn diameter", "m", default=0.11e-3, gt=0.0, le=2e-3)
    cd_top_diameter_m: float = quantity(
        "Top weft (CD) yarn diameter", "m", default=0.13e-3, gt=0.0, le=2e-3
    )
    cd_bottom_diameter_m: float = quantity(
        "Bottom weft (CD) yarn diameter", "m", default=0.177e-3, gt=0.0, le=2e-3
    )
    md_count_per_m: float = quantity("Warps per metre of width", "1/m", default=5000.0, gt=0.0, le=1e5)
    cd_count_per_m: float = quantity(
        "Weft columns per metre of length (each a top and a bottom weft)", "1/m",
        default=3000.0, gt=0.0, le=1e5,
    )  # fmt: skip
    shed: int = quantity("Columns in the weave repeat (8: eight-shed)", "1", default=8, ge=3, le=64)
    shed_step: int = quantity(
        "Column shift of the pattern from one warp to the next (coprime with shed)", "1",
        default=3, ge=1, le=63,
    )  # fmt: skip
    bottom_shift: int | None = quantity(
        "Columns from a warp's top crossing to its bottom crossing (absent: shed/2)", "1",
        default=None, ge=1, le=63,
    )  # fmt: skip
    clearance_m: float = quantity(
        "Extra gap between crossing yarns", "m", default=0.0, ge=0.0, le=1e-4
    )
    arc_step_deg: float = quantity(
        "Largest angle of one polyline segment where a warp wraps a weft", "deg",
        default=10.0, ge=1.0, le=30.0,
    )  # fmt: skip
    voxel_size_m: float = quantity(
        "Voxel size of the fabric image", "m", default=8e-6, ge=1e-6, le=1e-4
    )
    stl_voxel_size_m: float = quantity(
        "Sampling step of the STL surface (coarser than the image keeps the file small)", "m",
        default=25e-6, ge=1e-6, le=2e-4,
    )  # fmt: skip

    @model_validator(mode="after")
    def _check(self) -> FabricSection:
        if self.source != "generate" and self.import_file is None:
            raise scene_problem("import_file", f"required when source is {self.source}")
        if self.source == "generate" and self.import_file is not None:
            raise scene_problem(
                "import_file", "only used when source is voxels or stl", self.import_file
            )
        return self


class FlowSection(_Section):
    """Steady flow through the bare fabric (the ``flow`` stage, OpenFOAM simpleFoam)."""

    delta_p_Pa: float = quantity(
        "Pressure drop from the top to the bottom of the domain", "Pa", default=100.0,
        gt=0.0, le=1.0e5,
    )  # fmt: skip
    cell_size_m: float = quantity(
        "CFD cell size in the fabric zone (cubic cells)", "m", default=25e-6, ge=2e-6, le=5e-4
    )
    max_cell_height_m: float | None = quantity(
        "Largest cell height far above and below the fabric (absent: 4 x cell_size_m)", "m",
        default=None, gt=0.0, le=5e-3,
    )  # fmt: skip
    height_above_fabric_m: float = quantity(
        "Domain top above the fabric's upper side", "m", default=1.0e-3, gt=0.0, le=0.1
    )
    max_iterations: int = quantity(
        "Largest number of SIMPLE iterations", "1", default=3000, ge=10, le=100000
    )
    residual_tolerance: float = quantity(
        "Initial residual of p and U at which the steady solution counts as converged", "1",
        default=1e-6, gt=0.0, le=1e-2,
    )  # fmt: skip
    ranks: int = quantity(
        "MPI ranks of the solver (> 1: decomposePar + simpleFoam -parallel)", "1",
        default=1, ge=1, le=64,
    )  # fmt: skip
    sample_spacing_m: float | None = quantity(
        "Spacing of the regular output grid (absent: cell_size_m)", "m",
        default=None, ge=1e-6, le=1e-3,
    )  # fmt: skip


class PermeabilitySection(_Section):
    """Air permeability of the fabric and the laid-down sheet (stage ``permeability``, OpenFOAM
    simpleFoam; Kettil 2016 sec. 4.2: Frazier / ASTM D737 condition, 125 Pa)."""

    density_kg_m3: float = quantity(
        "Density of the air", "kg/m^3", default=1.204, gt=0.0, le=100.0
    )
    viscosity_Pa_s: float = quantity(
        "Dynamic viscosity of the air", "Pa s", default=1.81e-5, gt=0.0, le=1.0
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


class LaydownSection(_Section):
    """Lay-down of the generated fibers on the fabric in the frozen flow (stage ``laydown``)."""

    timestep_s: float = quantity("Fiber (DEM) time step", "s", default=1.0e-7, gt=0.0, le=1e-3)
    max_time_s: float = quantity(
        "Longest simulated time (the run ends earlier once settled)", "s", default=0.02,
        gt=0.0, le=10.0,
    )  # fmt: skip
    check_interval_s: float = quantity(
        "Simulated time between settle checks and sheet snapshots", "s", default=2.0e-4,
        gt=0.0, le=1.0,
    )  # fmt: skip
    settle_speed_m_s: float = quantity(
        "Settled when the largest node speed stays below this", "m/s", default=2.0e-3,
        gt=0.0, le=10.0,
    )  # fmt: skip
    settle_speed_fraction: float | None = quantity(
        "Settle threshold relative to the superficial velocity of the flow stage (replaces "
        "settle_speed_m_s when given)", "1", default=None, gt=0.0, le=10.0,
    )  # fmt: skip
    settle_measure: Literal["node", "fiber"] = choice(
        "Speed the settle criterion tests: node (largest node speed) or fiber (largest fiber "
        "centre-of-mass speed; free fiber ends fluttering in the flow do not count)",
        default="node",
    )
    settle_checks: int = quantity(
        "Consecutive checks below settle_speed_m_s that end the run", "1", default=5, ge=1,
        le=10000,
    )  # fmt: skip
    removal_height_m: float | None = quantity(
        "Fibers with a node below this height are removed (absent: fabric lower side - 50 um)",
        "m", default=None, ge=-10.0, le=10.0,
    )  # fmt: skip
    walls: Literal["fiber_yarns", "wall_fiber_dlvo", "wall_gran"] = choice(
        "The four vertical side planes: fiber_yarns (planes of fix fiber/yarns, fiber/dlvo law, "
        "sub-stepped), wall_fiber_dlvo (fix wall/fiber/dlvo of the contact styles) or wall_gran "
        "(stock LIGGGHTS fix wall/gran, Hertz, frictionless; for comparisons)",
        default="fiber_yarns",
    )
    terms: list[ContactTerm] = choice(
        "Terms of the fiber/dlvo law against yarns and walls", default=["steric"]
    )
    friction_coefficient: float = quantity(
        "Coulomb friction coefficient of fibers on yarns and side planes (fix fiber/yarns, "
        "velocity-level stick/slip; 0: frictionless as the fiber/dlvo law)", "1", default=0.0,
        ge=0.0, le=10.0,
    )  # fmt: skip
    contact_integrator: Literal["cvode", "substep"] = choice(
        "Sub-integration of each fiber-yarn and fiber-wall contact: cvode (as pair_style "
        "fiber/dlvo, the thesis' method) or substep (contact_substeps velocity-Verlet sub-steps)",
        default="cvode",
    )
    contact_substeps: int = quantity(
        "Velocity-Verlet sub-steps per step of each yarn/wall contact with contact_integrator "
        "substep (rejected with cvode)", "1", default=100, ge=1, le=100000,
    )  # fmt: skip
    restart_interval_s: float = quantity(
        "Simulated time between LIGGGHTS restart files of the lay-down (rounded to whole checks; "
        "`fiberform laydown SCENE --resume` continues a killed run from the last one; 0: none)",
        "s", default=5.0e-3, ge=0.0, le=1e3,
    )  # fmt: skip
    ranks: int = quantity(
        "MPI ranks of the lay-down (> 1 needs yarn_contact newton; at most the machine's cores "
        "unless --oversubscribe)", "1", default=1, ge=1, le=100000,
    )  # fmt: skip
    yarn_contact: Literal["newton", "averaged"] | None = choice(
        "How yarns and the fiber_yarns side planes act on implicit fibers: newton (the law inside "
        "each fiber's Newton solve, PD steric servo; docs/models/contact.md section 8) or averaged "
        "(the contact point sub-integrated with contact_integrator, its impulse handed to the step). "
        "Absent: newton with beam_integrator implicit, averaged with explicit",
        default=None,
    )
    fiber_contact: Literal["newton", "averaged"] | None = choice(
        "How fibers act on each other (contact section, pair_style fiber/dlvo): newton (fibers "
        "that may touch during a step are solved together in one Newton solve with the law inside; "
        "docs/models/contact.md section 9) or averaged (each contact point pair sub-integrated with "
        "contact.integrator, the averaged force handed to each fiber's step). Absent: newton with "
        "beam_integrator implicit, averaged with explicit",
        default=None,
    )
    inertia_scale: float = quantity(
        "fix fiber/beam inertia_scale (rotary inertia factor; speed option, 1 = real inertia)", "1",
        default=1.0, gt=0.0, le=1e8,
    )  # fmt: skip
    stiffness_scale: float = quantity(
        "fix fiber/beam stiffness_scale (EA, GA factor; speed option, 1 = real stiffness)", "1",
        default=1.0, gt=0.0, le=1.0,
    )  # fmt: skip
    beam_integrator: Literal["implicit", "explicit"] = choice(
        "fix fiber/beam integrator: implicit (generalized-alpha per fiber, steps set by accuracy; "
        "thesis sec. 2.2) or explicit (velocity Verlet below the critical step; comparison)",
        default="implicit",
    )
    rho_inf: float = quantity(
        "fix fiber/beam rho_inf: numerical dissipation of the implicit integrator (spectral "
        "radius at infinite frequency; 1 = none)", "1", default=0.5, ge=0.0, le=1.0,
    )  # fmt: skip
    newton_tolerance: float = quantity(
        "fix fiber/beam newton_tol: implicit convergence tolerance (translations relative to the "
        "section radius, rotations in rad)", "1", default=1.0e-8, gt=0.0, le=1e-2,
    )  # fmt: skip
    newton_max_iterations: int = quantity(
        "fix fiber/beam newton_max: Newton iterations per implicit step before it is split",
        "1", default=25, ge=1, le=1000,
    )  # fmt: skip
    damping_time_s: float = quantity(
        "fix fiber/beam Kelvin-Voigt damping time", "s", default=0.0, ge=0.0, le=1.0
    )

    @model_validator(mode="after")
    def _check(self) -> LaydownSection:
        if self.timestep_s > self.check_interval_s:
            raise scene_problem("check_interval_s", "must be at least timestep_s",
                                self.check_interval_s)
        if self.check_interval_s > self.max_time_s:
            raise scene_problem("check_interval_s", "must not exceed max_time_s",
                                self.check_interval_s)
        if not self.terms:
            raise scene_problem("terms", "needs at least one of vdw, es, steric", [])
        if self.contact_integrator == "cvode" and "contact_substeps" in self.model_fields_set:
            raise scene_problem("contact_substeps", "only used with contact_integrator substep",
                                self.contact_substeps)
        if self.ranks > 1 and self.yarn_contact_mode != "newton":
            raise scene_problem("ranks", "more than one rank needs yarn_contact newton (the "
                                "sub-integrated yarn contact needs both nodes of an element on one "
                                "rank)", self.ranks)
        if 0.0 < self.restart_interval_s < self.check_interval_s:
            raise scene_problem("restart_interval_s", "must be 0 or at least check_interval_s",
                                self.restart_interval_s)
        if self.yarn_contact == "newton" and self.beam_integrator == "explicit":
            raise scene_problem("yarn_contact", "newton needs beam_integrator implicit (allowed "
                                "with explicit: averaged)", self.yarn_contact)
        if self.fiber_contact == "newton" and self.beam_integrator == "explicit":
            raise scene_problem("fiber_contact", "newton needs beam_integrator implicit (allowed "
                                "with explicit: averaged)", self.fiber_contact)
        if (self.yarn_contact_mode == "newton" and self.walls != "wall_fiber_dlvo"
                and "contact_integrator" in self.model_fields_set):
            raise scene_problem("contact_integrator", "only used with yarn_contact averaged or "
                                "walls wall_fiber_dlvo (yarn_contact newton solves the contacts "
                                "inside the fiber step)", self.contact_integrator)
        return self

    @property
    def fiber_contact_mode(self) -> str:
        """fiber_contact with its default resolved: newton (implicit) or averaged (explicit)."""
        if self.fiber_contact is not None:
            return self.fiber_contact
        return "newton" if self.beam_integrator == "implicit" else "averaged"

    @property
    def yarn_contact_mode(self) -> str:
        """yarn_contact with its default resolved: newton (implicit) or averaged (explicit)."""
        if self.yarn_contact is not None:
            return self.yarn_contact
        return "newton" if self.beam_integrator == "implicit" else "averaged"


class PressSection(_Section):
    """Pressing of the laid-down sheet by a rigid horizontal plate (stage ``press``, thesis sec.
    3.5): quiescent water (drag stays), static yarns, the plate under the fiber/dlvo law."""

    mode: Literal["velocity", "pressure"] = choice(
        "velocity: the plate moves down at plate_speed_m_s until the plate-to-fabric distance is "
        "target_thickness_m, then rests for hold_time_s (thesis sec. 3.5); pressure: a servo "
        "drives the plate so that the contact pressure follows a ramp to target_pressure_Pa at "
        "pressure_rate_Pa_s, a hold of hold_time_s, an unloading at the same rate and a release "
        "of release_time_s at zero pressure (spring-back)",
        default="pressure",
    )
    timestep_s: float | None = quantity(
        "Fiber (DEM) time step of the press (absent: laydown.timestep_s)", "s", default=None,
        gt=0.0, le=1e-3,
    )  # fmt: skip
    output_interval_s: float = quantity(
        "Simulated time between sheet snapshots, curve points and overlap-guard checks", "s",
        default=1.0e-4, gt=0.0, le=1.0,
    )  # fmt: skip
    plate_start_gap_m: float = quantity(
        "Gap between the plate and the highest fiber surface of the laid-down sheet at the start",
        "m", default=5.0e-6, gt=0.0, le=1e-3,
    )  # fmt: skip
    plate_speed_m_s: float = quantity(
        "velocity mode: the plate speed; pressure mode: the servo's speed limit (also the speed "
        "of the approach before the first contact)", "m/s", default=5.0e-3, gt=0.0, le=10.0,
    )  # fmt: skip
    target_thickness_m: float | None = quantity(
        "velocity mode (required): the plate stops at this distance above the fabric top (the "
        "highest point of the yarns; in both modes the plate never passes the fabric top)", "m",
        default=None, gt=0.0, le=1e-2,
    )  # fmt: skip
    target_pressure_Pa: float | None = quantity(
        "pressure mode (required): the pressure held (plate force / plate area, the domain's "
        "x-y cross-section)", "Pa", default=None, gt=0.0, le=1e9,
    )  # fmt: skip
    pressure_rate_Pa_s: float | None = quantity(
        "pressure mode: loading and unloading rate (absent: target_pressure_Pa per 1 ms)", "Pa/s",
        default=None, gt=0.0, le=1e15,
    )  # fmt: skip
    hold_time_s: float = quantity(
        "Time the plate holds its target position (velocity) or pressure (pressure)", "s",
        default=1.0e-3, ge=0.0, le=10.0,
    )  # fmt: skip
    release_time_s: float = quantity(
        "pressure mode: time at zero target pressure after unloading, while the sheet springs "
        "back (the servo keeps the plate at zero contact force)", "s", default=1.0e-3, ge=0.0,
        le=10.0,
    )  # fmt: skip
    servo_band_Pa: float | None = quantity(
        "pressure mode: the servo's proportional band p_ref: the plate moves at the full speed "
        "limit when the pressure is this far from its target (absent: 0.1 x target_pressure_Pa)",
        "Pa", default=None, gt=0.0, le=1e9,
    )  # fmt: skip
    overlap_limit: float = quantity(
        "Overlap guard: the press stops (exit status 1) when it has pushed an element into another "
        "fiber, a yarn or the plate by more than this fraction of the thinner fiber's thickness "
        "(beyond the overlaps the lay-down left)", "1",
        default=0.2, gt=0.0, le=1.0,
    )  # fmt: skip
    ranks: int = quantity(
        "MPI ranks of the press (> 1 needs laydown.yarn_contact newton)", "1", default=1, ge=1,
        le=100000,
    )  # fmt: skip

    @model_validator(mode="after")
    def _check(self) -> PressSection:
        if self.mode == "velocity":
            if self.target_thickness_m is None:
                raise scene_problem("target_thickness_m", "required with mode velocity", None)
            for name in ("target_pressure_Pa", "pressure_rate_Pa_s", "servo_band_Pa"):
                if getattr(self, name) is not None:
                    raise scene_problem(name, "only used with mode pressure", getattr(self, name))
            if "release_time_s" in self.model_fields_set:
                raise scene_problem("release_time_s", "only used with mode pressure",
                                    self.release_time_s)
        else:
            if self.target_pressure_Pa is None:
                raise scene_problem("target_pressure_Pa", "required with mode pressure", None)
            if self.target_thickness_m is not None:
                raise scene_problem("target_thickness_m", "only used with mode velocity",
                                    self.target_thickness_m)
        return self

    @property
    def rate(self) -> float:
        """The loading/unloading rate (Pa/s) with its default resolved (pressure mode)."""
        assert self.target_pressure_Pa is not None
        return (self.pressure_rate_Pa_s if self.pressure_rate_Pa_s is not None
                else self.target_pressure_Pa / 1.0e-3)

    @property
    def band(self) -> float:
        """The servo band p_ref (Pa) with its default resolved (pressure mode)."""
        assert self.target_pressure_Pa is not None
        return self.servo_band_Pa if self.servo_band_Pa is not None else 0.1 * self.target_pressure_Pa


class Scene(_Section):
    """A complete scene. Only ``name`` and ``run`` are required; other sections are optional."""

    format_version: Literal[1] = choice("Scene format version", default=1)
    name: Identifier = Field(
        description="Scene name, an identifier",
        json_schema_extra={
            "unit": "-",
            "meaning": "Scene name",
            "range": f"identifier ^{IDENTIFIER_PATTERN}$",
        },
    )
    seed: int = quantity("Seed of every random choice", "1", default=0, ge=0, le=2**31 - 1)
    output_dir: RelativePath | None = Field(
        default=None,
        description="Output folder relative to the working directory (absent: runs/<name>)",
        json_schema_extra={
            "unit": "-",
            "meaning": "Output folder, relative to the working directory (absent: runs/<name>)",
            "range": "relative path without '..'",
        },
    )
    domain: DomainSection | None = Field(default=None, description="Simulation box")
    fluid: FluidSection | None = Field(default=None, description="Suspending fluid")
    fibers: FibersSection | None = Field(default=None, description="Fibers")
    fiber_generation: FiberGenerationSection | None = Field(
        default=None, description="Fiber length/width/curvature distributions (stage generate)"
    )
    contact: ContactSection | None = Field(default=None, description="Fiber contact model")
    run: RunSection = Field(description="Time stepping and parallel run")
    demo_particles: DemoParticlesSection | None = Field(
        default=None, description="Two-sphere collision demo"
    )
    fabric: FabricSection | None = Field(default=None, description="Forming fabric")
    flow: FlowSection | None = Field(default=None, description="Flow through the bare fabric")
    laydown: LaydownSection | None = Field(
        default=None, description="Lay-down of the fibers on the fabric (stage laydown)"
    )
    permeability: PermeabilitySection | None = Field(
        default=None, description="Air permeability of the fabric and sheet (stage permeability)"
    )
    press: PressSection | None = Field(
        default=None, description="Pressing of the laid-down sheet by a rigid plate (stage press)"
    )

    @property
    def output_path(self) -> Path:
        """The output folder (relative to the working directory)."""
        return Path(self.output_dir if self.output_dir is not None else f"runs/{self.name}")

    def to_json(self) -> str:
        """Canonical JSON (sorted keys, defaults filled in) of the whole scene."""
        return json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))


SECTIONS: tuple[str, ...] = (
    "domain", "fluid", "fibers", "contact", "run", "demo_particles", "fabric", "flow",
    "fiber_generation", "laydown", "permeability", "press",
)


def section_hash(scene: Scene, names: Iterable[str]) -> str:
    """sha256 of the canonical JSON of the given top-level entries (sections or fields)."""
    data = scene.model_dump(mode="json")
    picked = {n: data[n] for n in sorted(set(names))}
    text = json.dumps(picked, sort_keys=True, separators=(",", ":"))
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()


# --------------------------------------------------------------------------------------------
# YAML loading

_FLOAT_12 = re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")


class _SceneLoader(yaml.SafeLoader):
    """SafeLoader that reads ``1e-3`` as a float (YAML 1.2, as users expect) and refuses
    duplicate keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, yaml.Node] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    f"found duplicate key {key!r}",
                    key_node.start_mark,
                )
            seen[key] = key_node
        return super().construct_mapping(node, deep=deep)


_SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789")
)


def _fmt_loc(loc: Iterable[int | str]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + part
    return out or "(top level)"


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _model_in(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        for arg in typing.get_args(annotation):
            found = _model_in(arg)
            if found is not None:
                return found
    return None


def _field_info(loc: Iterable[int | str]) -> tuple[type[BaseModel], str, FieldInfo] | None:
    """The model class, field name and FieldInfo that a validation error location points at."""
    model: type[BaseModel] | None = Scene
    found: tuple[type[BaseModel], str, FieldInfo] | None = None
    for part in loc:
        if isinstance(part, int):
            continue
        if model is None or part not in model.model_fields:
            return None
        info = model.model_fields[part]
        found = (model, part, info)
        model = _model_in(info.annotation)
    return found


def _allowed(found: tuple[type[BaseModel], str, FieldInfo] | None) -> str:
    """`` (allowed: 0 < x <= 0.1 m; Fiber length)`` for the field an error points at."""
    if found is None:
        return ""
    _, _, info = found
    extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
    unit = str(extra.get("unit", "-"))
    rng = extra.get("range")
    meaning = str(extra.get("meaning", info.description or ""))
    bits = []
    if rng and rng != "any":
        bits.append(f"allowed: {rng}" + (f" {unit}" if unit not in ("-", "1") else ""))
    elif unit not in ("-", "1"):
        bits.append(f"unit: {unit}")
    if meaning:
        bits.append(meaning)
    return f" ({'; '.join(bits)})" if bits else ""


def _with_line(path: str, key_lines: Mapping[str, int]) -> str:
    probe = path
    while probe:
        if probe in key_lines:
            return f"{path} (line {key_lines[probe]})"
        probe = re.sub(r"(\[\d+\]|\.?[^.\[]+)$", "", probe)
    return path


def _format_errors(exc: ValidationError, key_lines: Mapping[str, int]) -> list[str]:
    problems: list[str] = []
    for err in exc.errors(include_url=False):
        loc: list[int | str] = list(err["loc"])
        kind = err["type"]
        value = err.get("input")
        msg = err["msg"]
        ctx = err.get("ctx") or {}
        if kind == "field_problem":
            parts = re.split(r"[\[\].]+", ctx["field"])
            loc += [int(p) if p.isdigit() else p for p in parts if p]
            value = ctx.get("value")
            msg = ctx["message"]
        # a union of a section and None reports on the section; the None alternative is noise
        if loc and loc[-1] in ("is-instance[NoneType]",):
            continue
        # drop pydantic's names of union branches and validators ("function-after[...]")
        loc = [p for p in loc if not (isinstance(p, str) and ("[" in p or p.startswith("func")))]
        path = _with_line(_fmt_loc(loc), key_lines)
        if kind == "extra_forbidden":
            parent = _field_info(loc[:-1])
            model = _model_in(parent[2].annotation) if parent else Scene
            keys = ", ".join(model.model_fields) if model else ""
            problems.append(f"{path}: unknown key (allowed keys here: {keys})")
            continue
        found = _field_info(loc)
        if kind == "missing":
            problems.append(f"{path}: required but missing{_allowed(found)}")
            continue
        if kind == "model_type" and isinstance(value, (str, int, float, list)):
            msg = "must be a mapping (a section of key: value lines)"
        problems.append(f"{path} = {_short(value)}: {msg}{_allowed(found)}")
    # pydantic may report one problem twice through union branches
    return list(dict.fromkeys(problems))


_CANNOT = "cannot read scene"


def _key_lines(text: str) -> dict[str, int]:
    """1-based line of every key path (``fibers.length_m``, ``domain.lo_m[1]``) in the YAML."""
    lines: dict[str, int] = {}

    def walk(node: yaml.Node, path: str) -> None:
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    sub = f"{path}.{key.value}" if path else str(key.value)
                    lines.setdefault(sub, key.start_mark.line + 1)
                    walk(value, sub)
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                sub = f"{path}[{i}]"
                lines.setdefault(sub, item.start_mark.line + 1)
                walk(item, sub)

    try:
        root = yaml.compose(text, Loader=_SceneLoader)  # noqa: S506 - SafeLoader subclass
    except yaml.YAMLError:
        return lines
    if root is not None:
        walk(root, "")
    return lines


def parse_scene(
    data: Mapping[str, Any] | Any,
    source: str = "<scene>",
    key_lines: Mapping[str, int] | None = None,
) -> Scene:
    """Validate already-loaded YAML data; raise SceneError naming every bad field.

    ``key_lines`` (field path -> line) adds line numbers to the messages."""
    if not isinstance(data, Mapping):
        raise SceneError(source, [f"(top level) = {_short(data)}: the scene must be a mapping"])
    try:
        return Scene.model_validate(data)
    except ValidationError as exc:
        raise SceneError(source, _format_errors(exc, key_lines or {})) from None


def read_scene_yaml(text: str) -> Any:
    """YAML text read as scene files are (``1e-3`` is a float, duplicate keys refused); raises
    yaml.YAMLError."""
    return yaml.load(text, Loader=_SceneLoader)  # noqa: S506 - SafeLoader subclass


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; every failure is a SceneError (exit status 2)."""
    p = Path(path)
    source = str(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise SceneError(source, ["file not found"], _CANNOT) from None
    except IsADirectoryError:
        raise SceneError(source, ["is a directory, not a scene file"], _CANNOT) from None
    except OSError as exc:
        raise SceneError(source, [str(exc.strerror)], _CANNOT) from None
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError(
            source, [f"file too large ({len(raw)} bytes > {MAX_SCENE_BYTES})"], _CANNOT
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(source, [f"not UTF-8 text (byte {exc.start})"], _CANNOT) from None
    try:
        data = read_scene_yaml(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "unknown position"
        what = " ".join(x for x in (exc.context, exc.problem) if x)
        raise SceneError(source, [f"{where}: {what}"], "YAML syntax error") from None
    except yaml.YAMLError as exc:
        raise SceneError(source, [str(exc)], "YAML error") from None
    if data is None:
        raise SceneError(source, ["the file is empty"])
    return parse_scene(data, source, _key_lines(text))


# --------------------------------------------------------------------------------------------
# Documentation


def _literal_values(annotation: Any) -> tuple[str, list[Any]] | None:
    """('one of'|'subset of', values) for Literal and list[Literal] annotations."""
    origin = typing.get_origin(annotation)
    if origin is Literal:
        return "one of", list(typing.get_args(annotation))
    if origin is list:
        inner = _literal_values(typing.get_args(annotation)[0])
        if inner is not None:
            return "subset of", inner[1]
    return None


def field_table() -> str:
    """A Markdown table of every scene field: name, meaning, unit, default, range."""
    rows = ["| field | meaning | unit | default | allowed |", "|---|---|---|---|---|"]

    def walk(model: type[BaseModel], prefix: str) -> None:
        for name, info in model.model_fields.items():
            sub = _model_in(info.annotation)
            path = f"{prefix}{name}"
            if sub is not None:
                req = "required" if info.is_required() else "optional"
                rows.append(f"| **`{path}`** | {info.description} ({req} section) | | | |")
                walk(sub, path + ".")
                continue
            extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
            unit = str(extra.get("unit", "-"))
            meaning = str(extra.get("meaning", info.description or ""))
            default = (
                "required"
                if info.is_required()
                else ("absent" if info.default is None else f"`{info.default!r}`")
            )
            lit = _literal_values(info.annotation)
            allowed = (
                f"{lit[0]}: " + ", ".join(f"`{v}`" for v in lit[1])
                if lit
                else str(extra.get("range", "any"))
            )
            cells = [f"`{path}`", meaning, unit, default, allowed]
            rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")

    walk(Scene, "")
    return "\n".join(rows) + "\n"
