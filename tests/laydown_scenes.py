# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene text shared by tests that need a tiny real lay-down (6 fibers of 0.6 mm on 1 x 1 mm of
fabric, 1 us steps, restart files every 1 ms; steric contact only): tests/test_laydown_resume.py
and tests/test_bench_friction_probe.py; its fibers, fabric and flow (tiny_piece) also
tests/test_laydown.py's."""

from __future__ import annotations

def tiny_piece(placement_top_m: float) -> str:
    """The sections every tiny lay-down scene shares (run, domain, 6 fibers of 0.6 mm x 20 um with
    real stiffness, fabric and flow on 1 x 1 mm), the fibers placed from 2.66 mm up to
    ``placement_top_m``; also tests/test_laydown.py's scene."""
    return f"""run: {{timestep_s: 1.0e-7, duration_s: 1.0e-3}}
domain: {{lo_m: [0.0, 0.0, 0.0], hi_m: [1.0e-3, 1.0e-3, 3.437e-3]}}
fibers: {{count: 6, length_m: 0.6e-3, width_m: 20.0e-6, segments: 12,
         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}}
fiber_generation: {{placement_lo_m: [0.0, 0.0, 2.66e-3], placement_hi_m: [1.0e-3, 1.0e-3, {placement_top_m!r}]}}
fabric: {{size_x_m: 1.0e-3, size_y_m: 1.0e-3}}
flow: {{delta_p_Pa: 100.0, cell_size_m: 50.0e-6, height_above_fabric_m: 0.8e-3}}
"""


def tiny_laydown_scene(name: str, out: str, ranks: int, max_time_s: float) -> str:
    """The tiny lay-down scene (module docstring) named ``name``, writing to ``runs/<out>``, on
    ``ranks`` ranks, for ``max_time_s`` of lay-down (its settle check never ends it earlier)."""
    return f"""
name: {name}
seed: 3
output_dir: runs/{out}
{tiny_piece(2.9e-3)}laydown: {{terms: [steric], max_time_s: {max_time_s!r}, check_interval_s: 5.0e-4, settle_speed_m_s: 1.0e-9,
          settle_checks: 3, timestep_s: 1.0e-6, restart_interval_s: 1.0e-3, ranks: {ranks}}}
contact: {{model: fiber_dlvo, terms: [steric]}}
"""
