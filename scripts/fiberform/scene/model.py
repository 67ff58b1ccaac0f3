# SPDX-License-Identifier: GPL-3.0-or-later
"""The whole scene: its sections, cross-section checks, canonical JSON and section hashes."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Literal

from pydantic import Field

from ..inputs import IDENTIFIER_PATTERN
from ._fields import Identifier, RelativePath, _Section, choice, quantity
from .common import ContactSection, DomainSection, FluidSection, RunSection
from .fibers import FiberGenerationSection, FibersSection
from .particles import DemoParticlesSection
from .fabric import FabricSection
from .flow import FlowSection
from .permeability import PermeabilitySection
from .laydown import LaydownSection
from .press import PressSection


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
