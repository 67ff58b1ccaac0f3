# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene validation through the real CLI: every bad scene exits with status 2, names the field,
and writes nothing; good scenes pass."""

from __future__ import annotations

import subprocess
import typing
from dataclasses import dataclass
from pathlib import Path

import pytest

from fiberform.scene import Scene, field_table, load_scene, parse_scene, read_scene_yaml

GOOD = """\
name: demo
seed: 7
output_dir: out/demo
run:
  timestep_s: 1.0e-6
  duration_s: 1.0e-2
  ranks: 1
demo_particles:
  radius_m: 1.0e-3
  speed_m_s: 0.1
  gap_m: 1.0e-3
  stiffness_N_m: 1000.0
"""

FIBERS = """\
fibers:
  count: 10
  length_m: 1.0e-3
  width_m: 3.0e-5
  segments: 10
  youngs_modulus_Pa: 1.0e10
  shear_modulus_Pa: 1.0e9
"""

ALL_SECTIONS = (
    GOOD
    + FIBERS
    + """\
domain:
  lo_m: [-1.0e-3, -1.0e-3, 0.0]
  hi_m: [1.0e-3, 1.0e-3, 2.0e-3]
fluid:
  density_kg_m3: 998.2
  viscosity_Pa_s: 1.0e-3
  gravity_m_s2: [0.0, 0.0, -9.81]
contact:
  model: fiber_dlvo
  integrator: cvode
  terms: [vdw, es, steric]
  hamaker_J: 8.0e-21
  ionic_strength_mol_m3: 1.0
  surface_potential_V: -0.03
"""
)


def replace(old: str, new: str, base: str = GOOD) -> str:
    assert old in base, old
    return base.replace(old, new)


@dataclass(frozen=True)
class Bad:
    text: str | None  # None: no file at all
    expect: tuple[str, ...]  # substrings of stderr (the field path first)


BAD: dict[str, Bad] = {
    "wrong_type_quoted_number": Bad(
        replace("radius_m: 1.0e-3", 'radius_m: "1.0e-3"'),
        ("demo_particles.radius_m", "'1.0e-3'", "valid number"),
    ),
    "wrong_type_section_not_mapping": Bad(
        replace(
            "demo_particles:\n  radius_m: 1.0e-3", "fluid: 3\ndemo_particles:\n  radius_m: 1.0e-3"
        ),
        ("fluid", "mapping"),
    ),
    "wrong_type_bool_for_int": Bad(replace("seed: 7", "seed: true"), ("seed", "True")),
    "negative_length": Bad(
        GOOD + FIBERS.replace("length_m: 1.0e-3", "length_m: -1.0e-3"),
        ("fibers.length_m", "-0.001", "0 < x <= 0.1 m"),
    ),
    "zero_timestep": Bad(
        replace("timestep_s: 1.0e-6", "timestep_s: 0"), ("run.timestep_s", "= 0", "0 < x <= 1 s")
    ),
    "nan": Bad(
        replace("speed_m_s: 0.1", "speed_m_s: .nan"), ("demo_particles.speed_m_s", "finite")
    ),
    "unknown_key_top": Bad(GOOD + "colour: red\n", ("colour", "unknown key")),
    "unknown_key_nested": Bad(
        replace("gap_m: 1.0e-3", "gap_m: 1.0e-3\n  colour: red"),
        ("demo_particles.colour", "unknown key", "stiffness_N_m"),
    ),
    "bad_identifier": Bad(
        replace("name: demo", "name: 9lives"), ("name", "'9lives'", "identifier")
    ),
    "identifier_too_long": Bad(replace("name: demo", "name: " + "a" * 65), ("name", "identifier")),
    "injection_shell_newline": Bad(
        replace("name: demo", 'name: "x\\nshell rm -rf /"'), ("name", "identifier")
    ),
    "injection_shell_semicolon": Bad(
        replace("name: demo", 'name: "x; shell touch /tmp/pwned"'), ("name", "identifier")
    ),
    "injection_codestream_name": Bad(
        replace("name: demo", "name: '#codeStream { code #{ system(\"touch /tmp/pwned\"); #}; }'"),
        ("name", "identifier"),
    ),
    "injection_codestream_enum": Bad(
        GOOD + "contact:\n  model: '#codeStream'\n", ("contact.model", "fiber_dlvo")
    ),
    "injection_in_list": Bad(
        GOOD + "contact:\n  model: fiber_dlvo\n  terms: ['vdw\\nshell ls']\n  hamaker_J: 1.0e-20\n",
        ("contact.terms[0]",),
    ),
    "injection_output_dir": Bad(
        replace("output_dir: out/demo", "output_dir: 'out/#codeStream'"), ("output_dir",)
    ),
    "ranks_zero": Bad(replace("ranks: 1", "ranks: 0"), ("run.ranks", "1 <= x <= 64")),
    "ranks_too_many": Bad(replace("ranks: 1", "ranks: 65"), ("run.ranks", "1 <= x <= 64")),
    "missing_section": Bad(
        GOOD.split("run:")[0] + "demo_particles:" + GOOD.split("demo_particles:")[1],
        ("run", "required when demo_particles is present"),
    ),
    "missing_field": Bad(
        replace("  radius_m: 1.0e-3\n", ""), ("demo_particles.radius_m", "required")
    ),
    "missing_name": Bad(replace("name: demo\n", ""), ("name", "required")),
    "yaml_syntax": Bad(replace("ranks: 1", "ranks: [1"), ("YAML syntax error", "line")),
    "yaml_duplicate_key": Bad(GOOD + "name: other\n", ("duplicate key", "name")),
    "empty_file": Bad("", ("empty",)),
    "missing_file": Bad(None, ("scene.yaml", "not found")),
    "not_a_mapping": Bad("- 1\n- 2\n", ("mapping",)),
    "absolute_output_dir": Bad(
        replace("output_dir: out/demo", "output_dir: /tmp/fiberform_out"),
        ("output_dir", "relative"),
    ),
    "dotdot_output_dir": Bad(
        replace("output_dir: out/demo", "output_dir: out/../.."), ("output_dir",)
    ),
    "cross_field_domain": Bad(
        GOOD + "domain:\n  lo_m: [0.0, 0.0, 0.0]\n  hi_m: [1.0, -1.0, 1.0]\n", ("domain.hi_m[1]",)
    ),
    "cross_field_fibers_count_and_mass": Bad(
        GOOD + FIBERS.replace("count: 10", "count: 10\n  target_mass_kg: 1.0e-6"),
        ("fibers.count", "exactly one"),
    ),
    "cross_field_vdw_needs_hamaker": Bad(
        GOOD + "contact:\n  model: fiber_dlvo\n  terms: [vdw]\n", ("contact.hamaker_J", "vdw")
    ),
    "cross_field_friction_stick_needs_friction": Bad(
        GOOD + FIBERS + "laydown:\n  yarn_contact: newton\n  friction_stick: 10.0\n",
        ("laydown.friction_stick", "friction_coefficient > 0"),
    ),
    "friction_stick_range": Bad(
        GOOD + FIBERS + "laydown:\n  friction_coefficient: 0.5\n  friction_stick: 0.5\n",
        ("laydown.friction_stick", "1 <= x <= 10000"),
    ),
    "cross_field_anderson_needs_implicit": Bad(
        GOOD + FIBERS + "laydown:\n  beam_integrator: explicit\n  anderson_depth: 3\n",
        ("laydown.anderson_depth", "beam_integrator implicit"),
    ),
    "cross_field_landing_needs_implicit": Bad(
        GOOD + FIBERS + "laydown:\n  beam_integrator: explicit\n  newton_landing: predict\n",
        ("laydown.newton_landing", "beam_integrator implicit"),
    ),
    "newton_landing_choice": Bad(
        GOOD + FIBERS + "laydown:\n  newton_landing: guess\n", ("laydown.newton_landing", "limit"),
    ),
    "anderson_depth_range": Bad(
        GOOD + FIBERS + "laydown:\n  anderson_depth: 9\n", ("laydown.anderson_depth", "0 <= x <= 8"),
    ),
    "stage_check_timestep_too_large": Bad(
        replace("timestep_s: 1.0e-6", "timestep_s: 1.0e-4"), ("run.timestep_s", "contact")
    ),
    "stage_check_duration_too_short": Bad(
        replace("duration_s: 1.0e-2", "duration_s: 1.0e-3"), ("run.duration_s", "too short")
    ),
}


def _tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.mark.parametrize("command", ["check", "demo-particles"])
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_scene_exits_2_names_field_writes_nothing(
    case: str, command: str, tmp_path: Path, fiberform_cmd: list[str]
) -> None:
    bad = BAD[case]
    if bad.text is not None:
        (tmp_path / "scene.yaml").write_text(bad.text)
    before = _tree(tmp_path)
    proc = subprocess.run(
        [*fiberform_cmd, command, "scene.yaml", "--build-dir", str(tmp_path / "nobuild")]
        if command != "check"
        else [*fiberform_cmd, command, "scene.yaml"],
        cwd=tmp_path,
        capture_output=True,
        text=True, errors="replace",
        timeout=60,
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stdout == ""
    for text in bad.expect:
        assert text in proc.stderr, f"{text!r} not in:\n{proc.stderr}"
    assert _tree(tmp_path) == before, "a bad scene must not write anything"
    assert not Path("/tmp/pwned").exists()
    assert not Path("/tmp/fiberform_out").exists()


def test_yaml_syntax_error_names_the_line(tmp_path: Path, fiberform_cmd: list[str]) -> None:
    (tmp_path / "scene.yaml").write_text(replace("ranks: 1", "ranks: [1"))
    proc = subprocess.run(
        [*fiberform_cmd, "check", "scene.yaml"], cwd=tmp_path, capture_output=True, text=True, errors="replace"
    )
    assert proc.returncode == 2
    assert "line 8" in proc.stderr or "line 9" in proc.stderr, proc.stderr


def test_errors_carry_the_yaml_line(tmp_path: Path, fiberform_cmd: list[str]) -> None:
    (tmp_path / "scene.yaml").write_text(replace("timestep_s: 1.0e-6", "timestep_s: -1.0"))
    proc = subprocess.run(
        [*fiberform_cmd, "check", "scene.yaml"], cwd=tmp_path, capture_output=True, text=True, errors="replace"
    )
    assert proc.returncode == 2
    assert "run.timestep_s (line 5) = -1.0" in proc.stderr, proc.stderr


def test_several_problems_are_all_reported(tmp_path: Path, fiberform_cmd: list[str]) -> None:
    text = replace("ranks: 1", "ranks: 0", replace("timestep_s: 1.0e-6", "timestep_s: 0"))
    (tmp_path / "scene.yaml").write_text(text + "colour: red\n")
    proc = subprocess.run(
        [*fiberform_cmd, "check", "scene.yaml"], cwd=tmp_path, capture_output=True, text=True, errors="replace"
    )
    assert proc.returncode == 2
    for field in ("run.ranks", "run.timestep_s", "colour"):
        assert field in proc.stderr


@pytest.mark.parametrize("text", [GOOD, ALL_SECTIONS], ids=["demo", "all_sections"])
def test_good_scene_passes_and_writes_nothing(
    text: str, tmp_path: Path, fiberform_cmd: list[str]
) -> None:
    (tmp_path / "scene.yaml").write_text(text)
    proc = subprocess.run(
        [*fiberform_cmd, "check", "scene.yaml"], cwd=tmp_path, capture_output=True, text=True, errors="replace"
    )
    assert proc.returncode == 0, proc.stderr
    assert "valid scene 'demo'" in proc.stdout
    assert "out/demo" in proc.stdout
    assert _tree(tmp_path) == {"scene.yaml"}


def test_shipped_demo_scene_is_valid(repo_root: Path, fiberform_cmd: list[str]) -> None:
    proc = subprocess.run(
        [*fiberform_cmd, "check", str(repo_root / "scenes" / "two-particles.yaml")],
        capture_output=True,
        text=True, errors="replace",
    )
    assert proc.returncode == 0, proc.stderr
    assert "demo-particles" in proc.stdout


def test_defaults_and_yaml12_floats(tmp_path: Path) -> None:
    p = tmp_path / "s.yaml"
    p.write_text(replace("gap_m: 1.0e-3", "gap_m: 1e-3") + "fluid: {}\n")
    scene = load_scene(p)
    assert scene.demo_particles is not None and scene.demo_particles.gap_m == 1e-3
    assert scene.demo_particles.density_kg_m3 == 1500.0
    assert scene.fluid is not None
    assert scene.fluid.density_kg_m3 == 998.2
    assert scene.fluid.viscosity_Pa_s == 1.0e-3
    assert scene.fluid.gravity_m_s2 == [0.0, 0.0, -9.81]
    assert scene.fibers is None and scene.contact is None and scene.domain is None
    assert scene.output_path == Path("out/demo")
    assert scene.run.steps == 10000


def test_output_dir_defaults_to_runs_name(tmp_path: Path) -> None:
    p = tmp_path / "s.yaml"
    p.write_text(replace("output_dir: out/demo\n", ""))
    assert load_scene(p).output_path == Path("runs/demo")


# ---- schema conventions ---------------------------------------------------------------------

UNIT_SUFFIXES = ("_m", "_s", "_kg", "_kg_m3", "_Pa", "_Pa_s", "_m_s", "_m_s2", "_J", "_K",
                 "_mol_m3", "_V", "_N_m", "_N", "_deg", "_per_m")  # fmt: skip


def _models() -> list[type]:
    from pydantic import BaseModel

    from fiberform.scene.loader import _model_in

    out: list[type[BaseModel]] = [Scene]
    for info in Scene.model_fields.values():
        sub = _model_in(info.annotation)
        if sub is not None:
            out.append(sub)
    return out


def test_every_field_has_a_description_and_dimensional_fields_a_unit_suffix() -> None:
    from fiberform.scene.loader import _model_in

    for model in _models():
        assert model.model_config.get("extra") == "forbid", model
        for name, info in model.model_fields.items():
            assert info.description, f"{model.__name__}.{name} has no description"
            if _model_in(info.annotation) is not None:
                continue  # a section
            extra = info.json_schema_extra
            assert isinstance(extra, dict)
            unit = extra.get("unit")
            if unit not in (None, "-", "1"):
                assert name.endswith(UNIT_SUFFIXES), f"{name} ({unit}) lacks a unit suffix"
                assert f"[{unit}]" in info.description


def _has_str(annotation: object) -> bool:
    if annotation is str:
        return True
    return any(_has_str(a) for a in typing.get_args(annotation) if not isinstance(a, str))


def _safe_validators(annotation: object, metadata: list[object]) -> bool:
    """Every ``str`` in the annotation sits in an Annotated with the identifier or path check."""
    from pydantic import AfterValidator

    from fiberform.scene._fields import _check_identifier, _check_relative_path

    checks = (_check_identifier, _check_relative_path)
    if annotation is str:
        return any(isinstance(m, AfterValidator) and m.func in checks for m in metadata)
    if typing.get_origin(annotation) is typing.Annotated:
        base, *meta = typing.get_args(annotation)
        return _safe_validators(base, [*metadata, *meta])
    if typing.get_origin(annotation) is typing.Literal:
        return True
    return all(_safe_validators(a, metadata) for a in typing.get_args(annotation))


def test_every_string_field_is_an_enum_identifier_or_path() -> None:
    for model in _models():
        for name, info in model.model_fields.items():
            if _has_str(info.annotation):
                assert _safe_validators(info.annotation, list(info.metadata)), (
                    f"free string field {model.__name__}.{name}: use a Literal, Identifier or "
                    "RelativePath"
                )


def test_docs_field_table_is_current(repo_root: Path) -> None:
    doc = (repo_root / "docs" / "stages" / "scene-format.md").read_text()
    assert field_table() in doc, (
        "regenerate the table: fiberform schema --update docs/stages/scene-format.md"
    )


def test_domain_is_the_flow_box_when_absent() -> None:
    """No domain section, a generated fabric and a flow: the domain is the flow box, from the
    weave's own thickness (fabric_geometry.WeaveParams) plus the height above; for the default
    weave and 0.8 mm that is the 3.437 mm the demo used to spell out (fabric top 2.637 mm)."""
    from fiberform.fabric_geometry import WeaveParams

    text = ("name: d\nfabric: {size_x_m: 1.0e-3, size_y_m: 2.0e-3}\n"
            "flow: {height_above_fabric_m: 0.8e-3}\n")
    scene = parse_scene(read_scene_yaml(text))
    assert scene.domain is not None and scene.run is None
    w = WeaveParams()
    assert scene.domain.lo_m == [0.0, 0.0, 0.0]
    assert scene.domain.hi_m == pytest.approx([1.0e-3, 2.0e-3, w.lower_side_z_m + w.thickness_m + 0.8e-3], rel=1e-12)
    assert scene.domain.hi_m[2] == pytest.approx(3.437e-3, rel=1e-12)  # the demo's old explicit value
    # an explicit domain is kept (and checked against the flow box by the flow stage)
    explicit = parse_scene(read_scene_yaml(text + "domain: {lo_m: [0.0, 0.0, 0.0], hi_m: [1.0e-3, 2.0e-3, 5.0e-3]}\n"))
    assert explicit.domain is not None and explicit.domain.hi_m[2] == 5.0e-3
    # without a flow section there is no box to derive
    assert parse_scene(read_scene_yaml("name: d\nfabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3}\n")).domain is None


def _laydown_scene(**laydown: object) -> Scene:
    data = read_scene_yaml(ALL_SECTIONS)
    data["laydown"] = dict(laydown)
    return parse_scene(data, "s.yaml")


def test_hash_neutral_field_at_default_keeps_earlier_hashes() -> None:
    """A field declared hashed_at_default=False (laydown.fiber_friction_coefficient, added in
    session 28) is left out of the stage hash at its default: the hash equals the one taken over
    the section without that field (what the code before the field computed), so finished
    products stay up to date; any other value changes the hash."""
    import hashlib
    import json

    from fiberform.scene.model import section_hash

    absent = _laydown_scene(friction_coefficient=0.5)
    explicit = _laydown_scene(friction_coefficient=0.5, fiber_friction_coefficient=0.0)
    data = absent.model_dump(mode="json")
    del data["laydown"]["fiber_friction_coefficient"]
    before = "sha256:" + hashlib.sha256(json.dumps({"laydown": data["laydown"]}, sort_keys=True,
                                                   separators=(",", ":")).encode()).hexdigest()
    assert section_hash(absent, ["laydown"]) == before
    assert section_hash(explicit, ["laydown"]) == before
    changed = _laydown_scene(friction_coefficient=0.5, fiber_friction_coefficient=0.3)
    assert section_hash(changed, ["laydown"]) != before
    # an ordinary field is hashed at its default too (changing a default makes products stale)
    assert "friction_stick" in data["laydown"]


def test_fiber_friction_needs_newton_fiber_contact() -> None:
    with pytest.raises(Exception, match="fiber_friction_coefficient"):
        _laydown_scene(fiber_friction_coefficient=0.5, fiber_contact="averaged")
    # friction_stick is used by the fiber-fiber friction alone (no yarn friction)
    s = _laydown_scene(fiber_friction_coefficient=0.5, friction_stick=10.0)
    assert s.laydown is not None and s.laydown.friction_stick == 10.0
    with pytest.raises(Exception, match="friction_stick"):
        _laydown_scene(friction_stick=10.0)
