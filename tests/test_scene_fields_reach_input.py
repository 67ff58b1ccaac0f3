# SPDX-License-Identifier: GPL-3.0-or-later
"""Every field of the laydown, contact and coupling sections reaches the generated LIGGGHTS input of the
lay-down (issue 10: a field that configures nothing must not exist). The fields are enumerated from
the pydantic models, so a new field without an effect (or without an entry in ALTERNATIVES) fails
this test. No binaries needed: the input is rendered by the stage's own function."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from fiberform.scene import ContactSection, CouplingSection, LaydownSection, parse_scene
from fiberform.stages import laydown

BASE = {
    "name": "fields",
    "run": {"timestep_s": 1.0e-7, "duration_s": 1.0e-3},
    "domain": {"lo_m": [0.0, 0.0, 0.0], "hi_m": [1.0e-3, 1.0e-3, 3.437e-3]},
    "fibers": {"count": 2, "length_m": 0.4e-3, "width_m": 20.0e-6, "segments": 8,
               "youngs_modulus_Pa": 10.0e9, "shear_modulus_Pa": 4.0e9},
    "fabric": {"size_x_m": 1.0e-3, "size_y_m": 1.0e-3},
    "flow": {"delta_p_Pa": 100.0, "cell_size_m": 50.0e-6, "height_above_fabric_m": 0.8e-3},
    "laydown": {"max_time_s": 2.0e-3, "check_interval_s": 5.0e-4, "contact_integrator": "substep",
                "walls": "wall_fiber_dlvo", "yarn_contact": "averaged", "fiber_contact": "averaged"},
    "contact": {"model": "fiber_dlvo", "integrator": "substep", "terms": ["vdw", "es", "steric"],
                "hamaker_J": 8.0e-21, "ionic_strength_mol_m3": 1.0, "surface_potential_V": -0.025},
}
U_S = 0.1  # m/s, superficial velocity of the flow stage

# another valid value of every field (merged into BASE's section)
ALTERNATIVES: dict[str, dict[str, object]] = {
    "laydown": {
        "timestep_s": 2.0e-7, "max_time_s": 3.0e-3, "check_interval_s": 2.5e-4,
        "settle_speed_m_s": 3.0e-3, "settle_speed_fraction": 0.05, "settle_measure": "fiber",
        "settle_checks": 7, "removal_height_m": 1.5e-3, "walls": "wall_gran",
        "terms": ["steric", "vdw"], "friction_coefficient": 0.3, "contact_integrator": "cvode",
        "contact_substeps": 37, "inertia_scale": 10.0, "stiffness_scale": 0.5,
        "beam_integrator": "explicit", "rho_inf": 0.8, "newton_tolerance": 1.0e-9,
        "newton_max_iterations": 40, "damping_time_s": 1.0e-6, "yarn_contact": "newton",
        "restart_interval_s": 1.0e-3, "ranks": 2, "fiber_contact": "newton",
        "settle_mass_fraction": 0.99, "tangent_steps": 50, "anderson_depth": 3, "friction_stick": 10.0,
        "newton_landing": "predict", "fiber_friction_coefficient": 0.4, "split_memory_steps": 20,
        "steric_cap_m": 1.0e-6,
    },
    "coupling": {"mode": "two_way", "interval": 250, "timeout_s": 60.0, "reaction": "off",
                 "fluid_ranks": 2},
    "contact": {
        "integrator": "cvode", "terms": ["vdw", "steric"], "hamaker_J": 1.0e-20,
        "ionic_strength_mol_m3": 2.0, "surface_potential_V": -0.03, "cutoff_m": 3.0e-8,
        "substeps": 33, "points_per_element": 3,
    },
}
# fields whose only value cannot be changed (a single allowed choice)
SINGLE_CHOICE = {("contact", "model")}
# fields that configure how fiberdem is launched, not its input
LAUNCH = {("laydown", "ranks")}
# fields that configure the coupled launch (one mpirun for fiberdem and fiberPimpleFoam)
COUPLED_LAUNCH = {("coupling", "fluid_ranks")}
# laydown fields that act only together with other laydown values (set in both renderings)
NEEDS: dict[tuple[str, str], dict[str, object]] = {
    ("laydown", "settle_mass_fraction"): {"settle_measure": "fiber"},
    ("laydown", "friction_stick"): {"yarn_contact": "newton", "friction_coefficient": 0.5},
    ("laydown", "fiber_friction_coefficient"): {"fiber_contact": "newton"},
}
# coupling fields other than mode only act with mode two_way: their base scene is two-way
TWO_WAY_BASE = {"mode": "two_way"}


def scene_with(section: str | None = None, field: str | None = None,
               base: dict[str, object] | None = None):  # type: ignore[no-untyped-def]
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["laydown"].update(base or {})
    if section == "coupling" and field != "mode":
        data["coupling"] = dict(TWO_WAY_BASE)
    if section is not None and field is not None:
        data.setdefault(section, {})[field] = ALTERNATIVES[section][field]
    return parse_scene(data, "fields.yaml")


def render(section: str | None = None, field: str | None = None,
           base: dict[str, object] | None = None, base_section: str | None = None) -> str:
    if base_section == "coupling":  # the two-way base scene without the changed field
        data = yaml.safe_load(yaml.safe_dump(BASE))
        data["coupling"] = dict(TWO_WAY_BASE)
        return laydown.render_input(parse_scene(data, "fields.yaml"), U_S)
    return laydown.render_input(scene_with(section, field, base), U_S)


def cases() -> list[tuple[str, str]]:
    out = []
    for section, model in (("laydown", LaydownSection), ("contact", ContactSection),
                           ("coupling", CouplingSection)):
        out += [(section, f) for f in model.model_fields if (section, f) not in SINGLE_CHOICE]
    return out


def test_every_field_has_an_alternative() -> None:
    missing = [f"{s}.{f}" for s, f in cases() if f not in ALTERNATIVES[s]]
    assert not missing, f"add an alternative value for: {missing}"


@pytest.mark.parametrize("section,field", cases())
def test_field_changes_the_generated_input(section: str, field: str) -> None:
    if (section, field) in LAUNCH:
        build, newton = Path("build"), {"yarn_contact": "newton"}  # > 1 rank needs newton
        assert (laydown.launch(scene_with(base=newton), build)
                != laydown.launch(scene_with(section, field, newton), build)), \
            f"{section}.{field} does not reach the fiberdem launch"
        return
    if (section, field) in COUPLED_LAUNCH:
        build = Path("build")
        base_cmd = laydown.coupled_launch(scene_with(section, "mode"), build, oversubscribe=True)
        alt_cmd = laydown.coupled_launch(scene_with(section, field), build, oversubscribe=True)
        assert base_cmd != alt_cmd, f"{section}.{field} does not reach the coupled launch"
        # the value itself reaches mpirun: -np fluid_ranks for the fluid, which runs -parallel
        fluid = alt_cmd[alt_cmd.index(":") + 1:]
        assert fluid[:2] == ["-np", str(ALTERNATIVES[section][field])] and "-parallel" in fluid
        return
    needs = NEEDS.get((section, field))
    base = render(base=needs, base_section=section if section == "coupling" and field != "mode" else None)
    assert base != render(section, field, needs), f"{section}.{field} does not reach the input"


def test_thesis_law_by_default() -> None:
    """A scene without laydown.terms lays down with the thesis' law against yarns and walls (van der
    Waals, electrostatics, steric; issue 10: thesis physics by default, fewer terms only when asked
    for), and the law's terms reach every yarn and wall fix of the generated input."""
    assert LaydownSection.model_fields["terms"].default == ["vdw", "es", "steric"]

    def law_fixes(text: str) -> list[str]:
        return [ln for ln in text.splitlines()
                if ln.startswith("fix") and ("wall/fiber/yarns" in ln or "wall/fiber/dlvo" in ln)]

    fixes = law_fixes(render())
    assert len(fixes) == 5, fixes  # the yarns and the four side planes
    assert all(" terms vdw,es,steric " in f" {ln} " for ln in fixes), fixes
    other = law_fixes(render("laydown", "terms"))  # the alternative [steric, vdw]
    assert other and not any(" terms vdw,es,steric " in f" {ln} " for ln in other), other


LAW = {("fluid", "temperature_K"): ("temperature", 310.0), ("contact", "hamaker_J"): ("hamaker", 1.0e-20),
       ("contact", "ionic_strength_mol_m3"): ("ionic_strength", 2.0),
       ("contact", "surface_potential_V"): ("psi", -0.03), ("contact", "cutoff_m"): ("h_cut", 3.0e-8)}


def _law_lines(text: str) -> list[str]:
    """The generated commands that set up a contact law: the fiber-fiber pair style and every fix
    of a body the fibers touch (yarns, side planes, press plate)."""
    return [ln for ln in text.splitlines() if ln.startswith("pair_style fiber/dlvo")
            or (ln.startswith("fix") and ("wall/fiber/yarns" in ln or "wall/fiber/dlvo" in ln))]


@pytest.mark.parametrize("walls", ["wall_fiber_dlvo", "fiber_yarns"])
@pytest.mark.parametrize("key", sorted(LAW), ids=lambda k: ".".join(k))
def test_law_parameters_reach_every_contact(key: tuple[str, str], walls: str) -> None:
    """One law for fibers, yarns, side planes and the press plate (the mission; thesis sec. 2.4):
    a changed law parameter (fluid temperature, Hamaker constant, ionic strength, surface
    potential, cut-off) reaches every one of them with its value, in the lay-down's input and the
    press's. (Until session 30 only the pair style got the contact section's values and no
    command the temperature: the yarns and walls kept the law's defaults.)"""
    from fiberform.stages import press

    section, field = key
    word, value = LAW[key]
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["laydown"]["walls"] = walls
    data.setdefault(section, {})[field] = value
    scene = parse_scene(data, "law.yaml")
    lines = _law_lines(laydown.render_input(scene, U_S))
    assert len(lines) == 6, lines  # pair style, yarns, four side planes
    data["laydown"].update({"yarn_contact": "newton", "fiber_contact": "newton"})
    data["laydown"].pop("contact_integrator")
    data["contact"].pop("integrator")
    data["press"] = {"mode": "velocity", "target_thickness_m": 20.0e-6}
    scene = parse_scene(data, "law.yaml")
    plan = press.PressPlan(scene, sheet_top=2.677e-3, fabric_top=2.637e-3, t_min=20e-6)
    pressed = _law_lines(press.build_input(scene, plan))
    assert any(" plate " in f" {ln} " for ln in pressed), pressed
    lines += pressed
    for ln in lines:
        words = ln.split()
        assert word in words and float(words[words.index(word) + 1]) == value, (word, ln)


@pytest.mark.parametrize("walls", ["wall_fiber_dlvo", "fiber_yarns"])
def test_press_steric_cap_reaches_every_press_contact(walls: str) -> None:
    """press.steric_cap_m is the h_cap of every contact of the press (pair style, yarns, the four
    side planes, the plate) and of none of the lay-down's (the lay-down keeps the law's 2 nm)."""
    from fiberform.stages import press

    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["laydown"].update({"walls": walls, "yarn_contact": "newton", "fiber_contact": "newton"})
    data["laydown"].pop("contact_integrator")
    data["contact"].pop("integrator")
    data["press"] = {"mode": "velocity", "target_thickness_m": 20.0e-6, "steric_cap_m": 3.0e-7}
    scene = parse_scene(data, "cap.yaml")
    assert not any("h_cap" in ln.split() for ln in _law_lines(laydown.render_input(scene, U_S)))
    plan = press.PressPlan(scene, sheet_top=2.677e-3, fabric_top=2.637e-3, t_min=20e-6)
    pressed = _law_lines(press.build_input(scene, plan))
    # pair style, yarns, four side planes and the plate (defined again at each of its phases)
    assert len(pressed) > 6 and sum(" plate " in f" {ln} " for ln in pressed) == len(pressed) - 6, pressed
    for ln in pressed:
        words = ln.split()
        assert words.count("h_cap") == 1 and float(words[words.index("h_cap") + 1]) == 3.0e-7, ln


@pytest.mark.parametrize("walls", ["wall_fiber_dlvo", "fiber_yarns"])
def test_laydown_steric_cap_reaches_every_contact_and_the_press(walls: str) -> None:
    """laydown.steric_cap_m is the h_cap of every contact of the lay-down (pair style, yarns, the
    four side planes) and, with press.steric_cap_m absent, of every contact of the press; a
    press.steric_cap_m of its own wins in the press."""
    from fiberform.stages import press

    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["laydown"].update({"walls": walls, "yarn_contact": "newton", "fiber_contact": "newton",
                            "steric_cap_m": 5.0e-7})
    data["laydown"].pop("contact_integrator")
    data["contact"].pop("integrator")
    data["press"] = {"mode": "velocity", "target_thickness_m": 20.0e-6}
    for press_cap, want in ((None, 5.0e-7), (3.0e-7, 3.0e-7)):
        if press_cap is not None:
            data["press"]["steric_cap_m"] = press_cap
        scene = parse_scene(data, "cap.yaml")
        laid = _law_lines(laydown.render_input(scene, U_S))
        assert len(laid) == 6, laid  # pair style, yarns, four side planes
        plan = press.PressPlan(scene, sheet_top=2.677e-3, fabric_top=2.637e-3, t_min=20e-6)
        for ln, cap in [(ln, 5.0e-7) for ln in laid] + [(ln, want) for ln in _law_lines(press.build_input(scene, plan))]:
            words = ln.split()
            assert words.count("h_cap") == 1 and float(words[words.index("h_cap") + 1]) == cap, ln


# ---- permeability (issue 12): every field reaches the box case, the run options or the output --

PERM_ALTERNATIVES: dict[str, object] = {
    "density_kg_m3": 1.1, "viscosity_Pa_s": 1.9e-5, "pressure_drop_Pa": 200.0,
    "cells_across_fiber": 6, "subsamples": 3, "height_above_m": 0.4e-3,
    "max_cell_height_m": 1.0e-4, "max_cells": 3_000_000, "max_iterations": 500,
    "residual_tolerance": 1.0e-5, "convergence_window": 50, "convergence_tolerance": 1.0e-2,
    "ranks": 2, "mode": "subgrid", "subgrid_cell_size_m": 40.0e-6, "stop_at": "max_iterations",
    "subgrid_law": "drummond_tahir", "forchheimer_pressure_drop_Pa": 60.0,
}
PERM_SINGLE_CHOICE: set[str] = set()
PERM_SUBGRID_ONLY = {"subgrid_cell_size_m", "subgrid_law"}


def _perm_effect(perm_fields: dict[str, object]) -> tuple[object, ...]:
    """Everything a permeability section configures, from the stage's own functions: the box case,
    the solid sampling, the refusal limit and the convergence criterion."""
    from fiberform.porous_media import flow_rate_convergence, subgrid_resistance
    from fiberform.scene import PermeabilitySection
    from fiberform.stages.permeability import PermeabilityGeometry, case_setup, forchheimer_setup

    perm = PermeabilitySection.model_validate(perm_fields)
    geo = PermeabilityGeometry(1.0e-3, 1.0e-3, 2.0e-3, 2.6e-3, 20.0e-6, ())
    history = 1.0 + 1.0e-3 * np.sin(np.arange(1000.0))  # an oscillating outflow
    conv = flow_rate_convergence(history, perm.convergence_window, perm.convergence_tolerance)
    law = (subgrid_resistance(np.array([0.1]), 10e-6, perm.subgrid_law).tolist()
           if perm.mode == "subgrid" else None)  # fmt: skip
    return (case_setup(perm, geo), forchheimer_setup(perm, geo), perm.subsamples, perm.max_cells,
            conv, law)  # fmt: skip


def test_every_permeability_field_has_an_alternative() -> None:
    from fiberform.scene import PermeabilitySection

    missing = [f for f in PermeabilitySection.model_fields
               if f not in PERM_ALTERNATIVES and f not in PERM_SINGLE_CHOICE]
    assert not missing, f"add an alternative value for: {missing}"


@pytest.mark.parametrize("field", sorted(PERM_ALTERNATIVES))
def test_permeability_field_changes_the_case(field: str) -> None:
    base: dict[str, object] = {"mode": "subgrid"} if field in PERM_SUBGRID_ONLY else {}
    assert _perm_effect(base) != _perm_effect({**base, field: PERM_ALTERNATIVES[field]}), \
        f"permeability.{field} does not reach the case"


# ---- press section: every field reaches the press's input (stage press, issue 11) -------------
PRESS_BASES: dict[str, dict[str, object]] = {
    "pressure": {"mode": "pressure", "target_pressure_Pa": 20.0},
    "velocity": {"mode": "velocity", "target_thickness_m": 10.0e-6},
}
# field -> (base it changes, another valid value)
PRESS_ALTERNATIVES: dict[str, tuple[str, object]] = {
    "mode": ("velocity", "pressure"),  # with target_pressure_Pa added below
    "timestep_s": ("pressure", 2.0e-7),
    "output_interval_s": ("pressure", 2.0e-4),
    "plate_start_gap_m": ("pressure", 7.0e-6),
    "plate_speed_m_s": ("pressure", 3.0e-3),
    "target_thickness_m": ("velocity", 12.0e-6),
    "target_pressure_Pa": ("pressure", 30.0),
    "pressure_rate_Pa_s": ("pressure", 1.0e5),
    "hold_time_s": ("pressure", 2.0e-3),
    "release_time_s": ("pressure", 3.0e-3),
    "servo_band_Pa": ("pressure", 5.0),
    "overlap_limit": ("pressure", 0.3),
    "steric_cap_m": ("pressure", 5.0e-7),
    "overlap_action": ("velocity", "stop"),
    "ranks": ("pressure", 2),
    "restart_interval_s": ("velocity", 4.0e-4),
}


def _press_input(base: str, field: str | None = None) -> str:
    from fiberform.stages import press

    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["laydown"].update({"yarn_contact": "newton", "fiber_contact": "newton"})
    data["press"] = dict(PRESS_BASES[base])
    if field is not None:
        data["press"][field] = PRESS_ALTERNATIVES[field][1]
        if field == "mode":
            data["press"].pop("target_thickness_m")
            data["press"]["target_pressure_Pa"] = 20.0
    scene = parse_scene(data, "press.yaml")
    # a sheet 40 um above the fabric top (2.637 mm), fibers 20 um thick
    plan = press.PressPlan(scene, sheet_top=2.677e-3, fabric_top=2.637e-3, t_min=20e-6)
    return press.build_input(scene, plan)


def test_every_press_field_has_an_alternative() -> None:
    from fiberform.scene import PressSection

    assert set(PressSection.model_fields) == set(PRESS_ALTERNATIVES)


@pytest.mark.parametrize("field", sorted(PRESS_ALTERNATIVES))
def test_press_field_changes_the_input(field: str) -> None:
    base = PRESS_ALTERNATIVES[field][0]
    if field == "ranks":  # configures the launch: the stage's program line runs on press.ranks
        from fiberform.stages import press
        from fiberform.stages._stage import StageContext

        def ranks(alt: bool) -> int:
            data = yaml.safe_load(yaml.safe_dump(BASE))
            data["laydown"].update({"yarn_contact": "newton", "fiber_contact": "newton"})
            data["press"] = {**PRESS_BASES[base], **({"ranks": PRESS_ALTERNATIVES["ranks"][1]} if alt else {})}
            ctx = StageContext(parse_scene(data, "press.yaml"), Path("press.yaml"), Path("build"))
            (program,) = press.Press().programs(ctx)
            return program.ranks

        assert ranks(False) != ranks(True) == PRESS_ALTERNATIVES["ranks"][1]
        return
    if field == "overlap_action":
        # configures the stage's reading of a run the guard ended, not the input (the guard ends
        # the run either way): test_press.py::test_overlap_action_stop_keeps_the_sheet_where_the_guard_trips
        assert _press_input(base) == _press_input(base, field)
        return
    assert _press_input(base) != _press_input(base, field), f"press.{field} does not reach the input"
