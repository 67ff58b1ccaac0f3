# SPDX-License-Identifier: GPL-3.0-or-later
"""Section of the ``demo-particles`` stage."""

from __future__ import annotations



from ._fields import _Section, quantity


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
