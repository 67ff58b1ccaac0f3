# SPDX-License-Identifier: GPL-3.0-or-later
"""The whole scene: its sections, cross-section checks, canonical JSON and section hashes."""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationError, model_validator

from ..inputs import IDENTIFIER_PATTERN
from ._fields import HASHED_AS, HASHED_AT_DEFAULT, Identifier, RelativePath, _Section, choice, quantity, scene_problem
from .common import ContactSection, DomainSection, FluidSection, RunSection
from .fibers import FiberGenerationSection, FibersSection
from .particles import DemoParticlesSection
from .fabric import FabricSection
from .flow import FlowSection
from .permeability import PermeabilitySection
from .laydown import LaydownSection
from .coupling import CouplingSection
from .press import PressSection


class Scene(_Section):
    """A complete scene. Only ``name`` is required; each stage needs its own sections. Without a
    ``domain`` section, a scene with a generated ``fabric`` and a ``flow`` gets the flow box as its
    domain: [0, size_x] x [0, size_y] x [0, fabric top + flow.height_above_fabric_m]."""

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
    run: RunSection | None = Field(
        default=None, description="Time stepping and parallel run of the particle demo (stage demo-particles)"
    )
    demo_particles: DemoParticlesSection | None = Field(
        default=None, description="Two-sphere collision demo"
    )
    fabric: FabricSection | None = Field(default=None, description="Forming fabric")
    flow: FlowSection | None = Field(default=None, description="Flow through the bare fabric")
    laydown: LaydownSection | None = Field(
        default=None, description="Lay-down of the fibers on the fabric (stage laydown)"
    )
    coupling: CouplingSection | None = Field(
        default=None,
        description="Fiber-fluid coupling of the lay-down (absent: one_way, the frozen flow)",
    )
    permeability: PermeabilitySection | None = Field(
        default=None, description="Air permeability of the fabric and sheet (stage permeability)"
    )
    press: PressSection | None = Field(
        default=None, description="Pressing of the laid-down sheet by a rigid plate (stage press)"
    )

    @model_validator(mode="before")
    @classmethod
    def _derive_domain(cls, data: Any) -> Any:
        """domain absent, fabric generated, flow present: the flow box (flow.py checks an
        explicit domain against the same box)."""
        if not (isinstance(data, dict) and data.get("domain") is None
                and isinstance(data.get("fabric"), dict) and isinstance(data.get("flow"), dict)):
            return data
        try:
            fab = FabricSection.model_validate(data["fabric"])
            flow = FlowSection.model_validate(data["flow"])
        except ValidationError:
            return data  # reported by the normal validation, field by field
        if fab.source != "generate":
            return data
        box = {"lo_m": [0.0, 0.0, 0.0],
               "hi_m": [fab.size_x_m, fab.size_y_m, fab.top_z_m + flow.height_above_fabric_m]}
        return {**data, "domain": box}

    @model_validator(mode="after")
    def _check_run(self) -> Scene:
        if self.demo_particles is not None and self.run is None:
            raise scene_problem("run", "required when demo_particles is present (its time step and ranks)")
        return self

    @model_validator(mode="after")
    def _check_fiber_shape_fields(self) -> Scene:
        """Each fiber shape setting in one place: the length in fibers.length_m or sampled by
        fiber_generation.length_m, the elements per fiber in fibers.segments or from
        fiber_generation.element_length_m (a field that the other one overrides would reach
        nothing)."""
        f, g = self.fibers, self.fiber_generation
        if f is None:
            return self
        pairs = (("length_m", "length_m", "the fiber length"),
                 ("segments", "element_length_m", "the elements per fiber"))
        for own, gen, what in pairs:
            given, sampled = getattr(f, own), (getattr(g, gen) if g is not None else None)
            if given is not None and sampled is not None:
                raise scene_problem(f"fibers.{own}", f"{what} is set by fiber_generation.{gen}: give one of "
                                    f"fibers.{own} and fiber_generation.{gen}, not both", given)
            if given is None and sampled is None:
                raise scene_problem(f"fibers.{own}", f"required unless fiber_generation.{gen} is given ({what})")
        return self

    def longest_fiber_m(self) -> tuple[float, str] | None:
        """The longest fiber the generate stage can make, m, and the field that sets it:
        fibers.length_m, or the upper end of the support of fiber_generation.length_m (or of
        fines_length_m, if longer; inf for an untruncated or data distribution); None without
        fibers."""
        f, g = self.fibers, self.fiber_generation
        if f is None:
            return None
        if f.length_m is not None:
            longest = (f.length_m, "fibers.length_m")
        else:
            assert g is not None and g.length_m is not None  # _check_fiber_shape_fields
            longest = (g.length_m.support()[1], "fiber_generation.length_m")
        if g is not None and g.fines_fraction > 0 and g.fines_length_m is not None:
            longest = max(longest, (g.fines_length_m.support()[1], "fiber_generation.fines_length_m"))
        return longest

    @model_validator(mode="after")
    def _check_periodic(self) -> Scene:
        """laydown.walls periodic: a one-way lay-down on a generated fabric of whole weave repeats
        that fills the domain in x and y, with fibers shorter than the period (the yarns are tiled
        over one neighbouring image on each side)."""
        ld, fab = self.laydown, self.fabric
        if ld is None or ld.walls != "periodic":
            return self
        if self.coupling is not None and self.coupling.mode == "two_way":
            raise scene_problem("laydown.walls", "periodic is one-way only: the coupled fluid case "
                                "(coupling.mode two_way) has symmetry sides, not periodic ones; use "
                                "side planes (fiber_yarns) or coupling one_way", ld.walls)
        if fab is None:
            return self  # no lay-down without a fabric (the stage requires the section)
        if fab.source != "generate":
            raise scene_problem("fabric.source", "laydown.walls periodic needs a generated fabric "
                                "(whole weave repeats, tiled over the periodic images)", fab.source)
        for name, count_name in (("size_x_m", "cd_count_per_m"), ("size_y_m", "md_count_per_m")):
            size, count = float(getattr(fab, name)), float(getattr(fab, count_name))
            problem = whole_repeat_problem(size, fab.shed, count, count_name)
            if problem is not None:
                raise scene_problem(f"fabric.{name}", problem, size)
        dom = self.domain
        if dom is not None:
            for axis, size in ((0, fab.size_x_m), (1, fab.size_y_m)):
                if not math.isclose(dom.lo_m[axis], 0.0, abs_tol=1e-12):
                    raise scene_problem(f"domain.lo_m[{axis}]", "laydown.walls periodic: the periodic "
                                        "box is the fabric piece, starting at 0", dom.lo_m[axis])
                if not math.isclose(dom.hi_m[axis], size, rel_tol=1e-9):
                    raise scene_problem(f"domain.hi_m[{axis}]", "laydown.walls periodic: the periodic "
                                        f"box is the fabric piece, ending at {size!r} m "
                                        f"(fabric.{('size_x_m', 'size_y_m')[axis]})", dom.hi_m[axis])
        period = min(fab.size_x_m, fab.size_y_m)
        longest = self.longest_fiber_m()
        if longest is not None and longest[0] >= period:
            raise scene_problem(longest[1], "laydown.walls periodic needs fibers shorter than the periodic box "
                                f"({period!r} m, the smaller fabric size): the yarns are tiled over one "
                                "periodic image on each side; a sampled length needs a max below it", longest[0])
        return self

    @property
    def output_path(self) -> Path:
        """The output folder (relative to the working directory)."""
        return Path(self.output_dir if self.output_dir is not None else f"runs/{self.name}")

    def to_json(self) -> str:
        """Canonical JSON (sorted keys, defaults filled in) of the whole scene."""
        return json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))


def _fmt_m(v: float) -> str:
    """A length as ``2.6667e-3`` (up to 5 significant digits, no exponent padding: ``2e-3``)."""
    mant, exp = f"{v:.4e}".split("e")
    return f"{mant.rstrip('0').rstrip('.')}e{int(exp)}"


def whole_repeat_problem(size_m: float, shed: int, count_per_m: float, count_name: str) -> str | None:
    """None if ``size_m`` is a whole number (>= 1) of weave repeats of ``shed`` / ``count_per_m``
    (relative tolerance 1e-6), else the problem with the nearest allowed sizes (m)."""
    repeat = shed / count_per_m
    n = size_m / repeat
    k = round(n)
    if k >= 1 and abs(n - k) <= 1e-6 * n:
        return None
    lo, hi = math.floor(n), math.ceil(n)
    allowed = " or ".join(_fmt_m(m * repeat) for m in ((lo, hi) if lo >= 1 else (hi,)))
    return (f"laydown.walls periodic needs whole weave repeats of shed / {count_name} = "
            f"{_fmt_m(repeat)} m: {allowed} m")


SECTIONS: tuple[str, ...] = (
    "domain", "fluid", "fibers", "contact", "run", "demo_particles", "fabric", "flow",
    "fiber_generation", "laydown", "coupling", "permeability", "press",
)


def _hash_neutral_defaults(section: Any, data: dict[str, Any]) -> None:
    """Drop from a section's dumped ``data`` the fields declared ``hashed_at_default=False``
    (:func:`._fields.quantity`) that hold their default, and record the values of fields declared
    ``hashed_as`` as declared."""
    if not isinstance(section, _Section):
        return
    for name, info in type(section).model_fields.items():
        extra = info.json_schema_extra
        if not isinstance(extra, dict) or name not in data:
            continue
        if extra.get(HASHED_AT_DEFAULT) is False and getattr(section, name) == info.default:
            del data[name]
            continue
        for value, recorded in extra.get(HASHED_AS, ()):
            if data[name] == value:
                data[name] = recorded


def section_hash(scene: Scene, names: Iterable[str]) -> str:
    """sha256 of the canonical JSON of the given top-level entries (sections or fields). A field
    declared ``hashed_at_default=False`` is left out while it holds its default, so adding such a
    field keeps the products of earlier scenes up to date."""
    data = scene.model_dump(mode="json")
    for n in set(names):
        if isinstance(data.get(n), dict):
            _hash_neutral_defaults(getattr(scene, n, None), data[n])
    picked = {n: data[n] for n in sorted(set(names))}
    text = json.dumps(picked, sort_keys=True, separators=(",", ":"))
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()
