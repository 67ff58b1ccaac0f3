# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene files: YAML validated by a pydantic v2 schema (a package: one module of sections per stage,
``common`` for the shared ones, ``model`` for the whole scene, ``loader`` for reading and error
messages, ``docs`` for the field table).

Conventions (see docs/stages/scene-format.md, whose field table ``fiberform schema`` generates
from this package):

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

from ._fields import scene_problem
from .common import ContactSection, DomainSection, FluidSection, RunSection
from .fibers import DistributionSpec, FiberGenerationSection, FibersSection
from .particles import DemoParticlesSection
from .fabric import FabricSection
from .flow import FlowSection
from .permeability import PermeabilitySection
from .laydown import LaydownSection
from .coupling import CouplingSection
from .press import PressSection
from .model import SECTIONS, Scene, section_hash
from .loader import load_scene, parse_scene, read_scene_yaml
from .docs import field_table

__all__ = [
    "ContactSection",
    "CouplingSection",
    "DemoParticlesSection",
    "DomainSection",
    "FabricSection",
    "FlowSection",
    "LaydownSection",
    "PermeabilitySection",
    "PressSection",
    "DistributionSpec",
    "FiberGenerationSection",
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

