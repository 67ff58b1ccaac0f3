# SPDX-License-Identifier: GPL-3.0-or-later
"""Stages: one module per stage, each a :class:`Stage` subclass registered in :data:`STAGES`.

To add a stage: write ``stages/<name>.py`` with a Stage subclass (name, summary, folder, requires,
uses, products, produce), then add it to ``STAGES`` below; the CLI gains a subcommand of that name.
"""

from __future__ import annotations

from ._stage import Outcome, Stage, StageContext
from .fabric import FabricStage
from .flow import FlowStage
from .particles import DemoParticles
from .permeability import PermeabilityPressStage, PermeabilityStage
from .generate import Generate
from .laydown import Laydown
from .press import Press

__all__ = ["STAGES", "Outcome", "Stage", "StageContext", "stage"]

#: Every stage by CLI name, in pipeline order.
STAGES: dict[str, Stage] = {s.name: s for s in (DemoParticles(), Generate(), FabricStage(), FlowStage(),
                                               Laydown(), Press(), PermeabilityStage(),
                                               PermeabilityPressStage())}


def stage(name: str) -> Stage:
    """The stage called ``name`` (KeyError lists the known ones)."""
    try:
        return STAGES[name]
    except KeyError:
        raise KeyError(f"unknown stage {name!r}; known: {', '.join(STAGES)}") from None
