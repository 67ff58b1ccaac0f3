# SPDX-License-Identifier: GPL-3.0-or-later
"""Section of the ``flow`` stage."""

from __future__ import annotations



from ._fields import _Section, quantity


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
