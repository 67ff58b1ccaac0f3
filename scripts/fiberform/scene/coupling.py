# SPDX-License-Identifier: GPL-3.0-or-later
"""Section ``coupling``: how the lay-down's fibers and the fluid interact (issue 13)."""

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from ._fields import _Section, choice, quantity, scene_problem


class CouplingSection(_Section):
    """Fiber-fluid coupling of the lay-down (stage ``laydown``; docs/coupling/)."""

    mode: Literal["one_way", "two_way"] = choice(
        "one_way: the fibers settle in the flow stage's frozen steady flow; two_way: "
        "fiberPimpleFoam runs next to fiberdem under one mpirun, starting from the flow stage's "
        "solution, and receives the fibers' drag reaction every `interval` steps",
        default="one_way",
    )
    interval: int = quantity(
        "Fiber steps per exchange with the fluid (two_way); the fluid step is interval x "
        "laydown.timestep_s. Must divide the steps of one laydown.check_interval_s",
        "1", default=100, ge=1, le=10**6,
    )  # fmt: skip
    timeout_s: float = quantity(
        "Deadline of each blocking exchange on both sides (two_way): a partner silent this long "
        "ends the run with a message (status 4)", "s", default=300.0, gt=0.0, le=1e5,
    )  # fmt: skip
    fluid_ranks: int = quantity(
        "MPI ranks of the coupled fluid (two_way). > 1: the fluid case is decomposed into slabs "
        "across x (decomposePar, simple) and fiberPimpleFoam runs with -parallel and OpenFOAM's "
        "libPstream rebuilt with the MPMD split (make setup; $FIBERFORM_PSTREAM_DIR); "
        "laydown.ranks + fluid_ranks ranks in all",
        "1", default=1, ge=1, le=4096,
    )  # fmt: skip
    reaction: Literal["on", "off"] = choice(
        "two_way: on sends the fibers' drag reaction to the fluid; off sends zero (the fluid "
        "evolves on its own: the one-way limit through the coupled machinery, for tests)",
        default="on",
    )

    @model_validator(mode="after")
    def _check(self) -> CouplingSection:
        if self.mode == "one_way":
            unused = sorted({"interval", "timeout_s", "reaction", "fluid_ranks"} & self.model_fields_set)
            if unused:
                raise scene_problem(unused[0], "only used with mode two_way",
                                    getattr(self, unused[0]))
        return self
