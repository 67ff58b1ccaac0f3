# SPDX-License-Identifier: GPL-3.0-or-later
"""The fix fiber/beam fields of the laydown section reach the generated LIGGGHTS input (no
binaries needed): integrator, rho_inf, Newton tolerance and cap, and the speed options, whose
defaults are the real fiber (1, 1)."""
from __future__ import annotations

import re

import pytest
import yaml

from fiberform.scene import parse_scene
from fiberform.stages import laydown

BASE = """
name: fields
run: {timestep_s: 1.0e-7, duration_s: 1.0e-3}
domain: {lo_m: [0.0, 0.0, 0.0], hi_m: [1.0e-3, 1.0e-3, 3.437e-3]}
fibers: {count: 2, length_m: 0.4e-3, width_m: 20.0e-6, segments: 8,
         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3}
flow: {delta_p_Pa: 100.0, cell_size_m: 50.0e-6, height_above_fabric_m: 0.8e-3}
laydown: {max_time_s: 0.001, check_interval_s: 5.0e-4%s}
"""


def beam_line(extra: str = "") -> str:
    scene = parse_scene(yaml.safe_load(BASE % extra), "fields.yaml")
    text = laydown.build_input(scene, 50, 2)
    lines = [ln for ln in text.splitlines() if re.match(r"fix\s+beam\s+all\s+fiber/beam", ln)]
    assert len(lines) == 1
    return lines[0]


def value(line: str, key: str) -> str:
    words = line.split()
    return words[words.index(key) + 1]


def test_defaults_are_the_real_fiber_and_the_implicit_integrator() -> None:
    line = beam_line()
    assert value(line, "integrator") == "implicit"
    assert float(value(line, "inertia_scale")) == 1.0
    assert float(value(line, "stiffness_scale")) == 1.0
    assert float(value(line, "rho_inf")) == 0.5
    assert float(value(line, "newton_tol")) == 1e-8
    assert int(value(line, "newton_max")) == 25


@pytest.mark.parametrize("field,key,new", [
    ("beam_integrator", "integrator", "explicit"),
    ("rho_inf", "rho_inf", "0.8"),
    ("newton_tolerance", "newton_tol", "1.0e-10"),
    ("newton_max_iterations", "newton_max", "40"),
    ("inertia_scale", "inertia_scale", "100.0"),
    ("stiffness_scale", "stiffness_scale", "0.5"),
    ("damping_time_s", "damping", "1.0e-6"),
    ("split_memory_steps", "split_memory", "20"),
])
def test_each_field_changes_the_fix_line(field: str, key: str, new: str) -> None:
    before = beam_line()
    after = beam_line(f", {field}: {new}")
    assert before != after
    got = value(after, key)
    assert got == new or float(got) == float(new)


def line_of(extra: str, style: str) -> str:
    scene = parse_scene(yaml.safe_load(BASE % extra), "fields.yaml")
    text = laydown.build_input(scene, 50, 2)
    lines = [ln for ln in text.splitlines() if style in ln]
    assert lines
    return lines[0]


def test_contact_integrator_reaches_the_yarn_and_wall_fixes() -> None:
    assert "integrator cvode" in line_of("", "wall/fiber/yarns")
    sub = line_of(", yarn_contact: averaged, contact_integrator: substep, contact_substeps: 40",
                  "wall/fiber/yarns")
    assert value(sub, "substep") == "40"
    assert value(sub, "implicit_force") == "impulse"
    wall = line_of(", walls: wall_fiber_dlvo, contact_integrator: substep, contact_substeps: 40",
                   "wall/fiber/dlvo")
    assert value(wall, "substep") == "40"
    assert "integrator cvode" in line_of(", walls: wall_fiber_dlvo", "wall/fiber/dlvo")


def test_yarn_contact_newton_is_the_implicit_default() -> None:
    from fiberform.errors import SceneError

    assert value(line_of("", "wall/fiber/yarns"), "implicit_force") == "newton"
    with pytest.raises(SceneError, match="yarn_contact"):
        parse_scene(yaml.safe_load(BASE % ", beam_integrator: explicit, yarn_contact: newton"),
                    "fields.yaml")
    # a sub-integration setting without anything to configure is refused
    with pytest.raises(SceneError, match="contact_integrator"):
        parse_scene(yaml.safe_load(BASE % ", contact_integrator: substep"), "fields.yaml")


def test_substeps_without_the_substep_integrator_is_an_error() -> None:
    from fiberform.errors import SceneError

    with pytest.raises(SceneError, match="contact_substeps"):
        parse_scene(yaml.safe_load(BASE % ", contact_substeps: 40"), "fields.yaml")
