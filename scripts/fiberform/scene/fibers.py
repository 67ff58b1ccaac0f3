# SPDX-License-Identifier: GPL-3.0-or-later
"""Sections of the fibers and of the ``generate`` stage."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import Field, model_validator

from ..inputs import IDENTIFIER_PATTERN
from ._fields import Coordinate, Identifier, RelativePath, _Section, _element_range, choice, quantity, scene_problem


class FibersSection(_Section):
    """Flexible fibers, each a chain of segments (beads joined by beams)."""

    count: int | None = quantity(
        "Number of fibers (give this or target_mass_kg)", "1", default=None, ge=1, le=10_000_000
    )
    target_mass_kg: float | None = quantity(
        "Total fiber mass to insert (give this or count)", "kg", default=None, gt=0.0, le=1.0
    )
    length_m: float | None = quantity(
        "Fiber length (required unless fiber_generation.length_m samples it; not both)", "m",
        default=None, gt=0.0, le=0.1,
    )
    width_m: float = quantity(
        "Fiber width (the diameter for a circular cross-section)", "m", gt=0.0, le=1.0e-3
    )
    thickness_m: float | None = quantity(
        "Fiber thickness (rectangular cross-section only)", "m", default=None, gt=0.0, le=1.0e-3
    )
    segments: int | None = quantity(
        "Segments per fiber, nodes = segments + 1 (required unless fiber_generation.element_length_m "
        "sets the element length; not both)", "1", default=None, ge=1, le=1000,
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
        need = _KIND_FIELDS[self.kind]
        for name in _KIND_FIELDS_REQUIRED[self.kind]:
            if getattr(self, name) is None:
                raise scene_problem(name, f"required for kind {self.kind}")
        for names in _KIND_FIELDS.values():
            for name in names:
                if name not in need and getattr(self, name) is not None:
                    used = " and ".join(k for k, n in _KIND_FIELDS.items() if name in n)
                    raise scene_problem(name, f"only used with kind {used} (this one is {self.kind})",
                                        getattr(self, name))
        if self.kind == "uniform" and not (self.high or 0) > (self.low or 0):
            raise scene_problem("high", "must be greater than low", self.high)
        if self.kind == "lognormal" and not (self.mean or 0) > 0:
            raise scene_problem("mean", "must be > 0 for lognormal", self.mean)
        if self.min is not None and self.max is not None and not self.max > self.min:
            raise scene_problem("max", "must be greater than min", self.max)
        return self

    def support(self) -> tuple[float, float]:
        """The interval its samples can fall in (a data column's: (-inf, inf), unknown here)."""
        inf = float("inf")
        lo, hi = {"fixed": (self.value, self.value), "uniform": (self.low, self.high),
                  "normal": (-inf, inf), "lognormal": (math.ulp(0.0), inf), "data": (-inf, inf)}[self.kind]
        assert lo is not None and hi is not None
        if self.min is not None:
            lo = max(lo, self.min)
        if self.max is not None:
            hi = min(hi, self.max)
        return lo, hi


#: the fields each distribution kind uses (min, max: every kind)
_KIND_FIELDS: dict[str, tuple[str, ...]] = {
    "fixed": ("value",), "uniform": ("low", "high"), "normal": ("mean", "sd"), "lognormal": ("mean", "sd"),
    "data": ("column",),
}
_KIND_FIELDS_REQUIRED = {k: tuple(n for n in v if n != "column") for k, v in _KIND_FIELDS.items()}


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
        for key, allowed in DISTRIBUTION_RANGES.items():
            spec: DistributionSpec | None = getattr(self, key)
            if spec is None:
                continue
            if spec.kind == "data":  # its column's values: checked by the generate stage (preflight)
                if self.data_csv is None:
                    raise scene_problem(key, "kind data needs fiber_generation.data_csv", spec.kind)
                continue
            s_lo, s_hi = spec.support()
            if not (allowed.contains(s_lo) and allowed.contains(s_hi)):
                where = (f"the value {spec.value}" if spec.kind == "fixed" else
                         f"[low, high] = [{spec.low}, {spec.high}]" if spec.kind == "uniform" and
                         (spec.min is None and spec.max is None) else
                         f"the samples (kind {spec.kind}, truncated to [min, max] = [{spec.min}, {spec.max}])")
                need = (str(allowed)
                        + ("" if spec.kind in ("fixed", "uniform") else ": truncate with min and max inside it"))
                raise scene_problem(key, f"{where} must lie in {need}", spec.kind)
        if self.placement_lo_m is not None and self.placement_hi_m is not None and not all(
                h > lo for lo, h in zip(self.placement_lo_m, self.placement_hi_m, strict=False)):
            raise scene_problem("placement_hi_m", "must exceed placement_lo_m in x, y and z", self.placement_hi_m)
        return self


@dataclass(frozen=True)
class ValueRange:
    """The values a sampled quantity may take: (lo, hi], lo excluded, hi included."""

    lo: float
    hi: float

    def contains(self, x: Any) -> Any:
        """Whether x lies in the range (a number, or elementwise for an array)."""
        return (x > self.lo) & (x <= self.hi)

    def __str__(self) -> str:
        return f"({self.lo:g}, {self.hi:g}]"


#: the allowed values of the sampled quantities. A data column's values are checked when the
#: generate stage reads the CSV (before anything is written).
DISTRIBUTION_RANGES: dict[str, ValueRange] = {
    "length_m": ValueRange(0.0, 0.1),
    "width_m": ValueRange(0.0, 0.01),
    "curvature_alpha": ValueRange(0.0, 1.0),
    "fines_length_m": ValueRange(0.0, 0.1),
}
