# SPDX-License-Identifier: GPL-3.0-or-later
"""scenes/thesis/case-{A..F}-{circular,rectangular}.yaml: the thesis' simulation cases (Kettil 2016,
Table 4.2: injection mass k x M_A, M_A = 35.7 ug, k = 1, 2.5, 5, 7.5, 10, 12.5; circular and
rectangular sections, a1 = 0.8 w and a2 = 0.2 w for the latter; sec. 3.4) on a 3 x 3 mm piece.

- every case scene is valid and uses the thesis' physics (real stiffness and inertia, implicit
  fibers, the extended DLVO law vdw + es + steric with CVODE for fiber-fiber contact and the same
  terms against yarns and side planes) with the cited colloidal parameters;
- the target mass is k x M_A with the published k; the twelve scenes differ only in what the case
  and the section change;
- generating case A (both sections) gives a fiber mass between the target and the target plus the
  heaviest fiber (fibers are added until the target is reached), fines at their number fraction
  (binomial, 4 standard deviations) and the thesis' section ratio a2 / a1 = 1/4.
"""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

from fiberform.scene.loader import load_scene

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "scenes" / "thesis"
M_A = 35.7e-9  # kg, thesis Table 4.2
K = {"A": 1.0, "B": 2.5, "C": 5.0, "D": 7.5, "E": 10.0, "F": 12.5}  # thesis Table 4.2
SECTIONS = ("circular", "rectangular")


def _path(case: str, section: str) -> Path:
    return THESIS / f"case-{case}-{section}.yaml"


def test_twelve_case_scenes_exist_and_nothing_else() -> None:
    want = {_path(c, s).name for c in K for s in SECTIONS}
    have = {p.name for p in THESIS.glob("case-*.yaml")}
    assert have == want


@pytest.mark.parametrize("case", list(K))
@pytest.mark.parametrize("section", SECTIONS)
def test_case_scene_follows_the_thesis(case: str, section: str) -> None:
    sc = load_scene(_path(case, section))
    assert sc.fibers.target_mass_kg == pytest.approx(K[case] * M_A, rel=1e-6)
    assert sc.fibers.cross_section == section
    if section == "rectangular":
        # thesis sec. 3.4: a1 = 0.8 w, a2 = 0.2 w
        assert sc.fibers.thickness_m / sc.fibers.width_m == pytest.approx(0.25)
    # 3 x 3 mm piece of the generated eight-shed fabric
    assert (sc.fabric.size_x_m, sc.fabric.size_y_m, sc.fabric.shed) == (3e-3, 3e-3, 8)
    # thesis physics: no speed option
    ld = sc.laydown
    assert (ld.stiffness_scale, ld.inertia_scale, ld.beam_integrator) == (1.0, 1.0, "implicit")
    assert ld.fiber_contact == "averaged" and sc.contact.integrator == "cvode"
    assert sorted(sc.contact.terms) == sorted(ld.terms) == ["es", "steric", "vdw"]
    assert sc.contact.points_per_element is None  # the pair style's own choice
    # the colloidal parameters cited in docs/styles/pair_fiber_dlvo.md
    assert sc.contact.hamaker_J == 8.0e-21
    assert sc.contact.surface_potential_V == -0.025
    assert sc.contact.ionic_strength_mol_m3 == 1.0
    # the fibers are placed above the fabric, inside the flow box
    assert sc.fiber_generation.placement_lo_m[2] > sc.fabric.top_z_m
    top = sc.fabric.top_z_m + sc.flow.height_above_fabric_m
    assert sc.fiber_generation.placement_hi_m[2] < top


def _dump(case: str, section: str) -> dict:
    d = load_scene(_path(case, section)).model_dump()
    d.pop("name"), d.pop("output_dir")
    d["fibers"].pop("target_mass_kg")
    for key in ("cross_section", "thickness_m"):
        d["fibers"].pop(key)
    d["fiber_generation"].pop("wall_fraction")
    d["fiber_generation"]["placement_hi_m"] = d["fiber_generation"]["placement_hi_m"][:2]
    d["flow"].pop("height_above_fabric_m")
    d.pop("domain")
    return d


def test_cases_differ_only_in_mass_section_and_slab() -> None:
    ref = _dump("A", "circular")
    for case in K:
        for section in SECTIONS:
            assert _dump(case, section) == ref, (case, section)


@pytest.fixture(scope="module")
def case_a(tmp_path_factory: pytest.TempPathFactory, fiberform_cmd: list[str]) -> Path:
    work = tmp_path_factory.mktemp("thesis_case_a")
    for section in SECTIONS:
        proc = subprocess.run([*fiberform_cmd, "generate", str(_path("A", section))], cwd=work,
                              capture_output=True, text=True, errors="replace", timeout=600)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return work


@pytest.mark.parametrize("section", SECTIONS)
def test_case_a_generates_its_mass(case_a: Path, section: str) -> None:
    sc = load_scene(_path("A", section))
    with h5py.File(case_a / sc.output_dir / "fibers" / "fibers.h5", "r") as h:
        mass = h["fibers/mass"][...]
        fine = h["fibers/is_fine"][...].astype(bool)
        radii = h["fibers/radii"][...]
        count = int(h["fibers"].attrs["count"])
    target = K["A"] * M_A
    assert count == len(mass) > 0
    # added until the target is reached: over it by less than the last (at most the heaviest) fiber
    assert target <= mass.sum() < target + mass.max(), (mass.sum(), target)
    f = sc.fiber_generation.fines_fraction
    assert abs(fine.sum() - f * count) <= 4 * math.sqrt(count * f * (1 - f)), (fine.sum(), count)
    if section == "rectangular":
        # per node the radii jitter by +-radius_jitter each: a2/a1 within (1 -+ j)/(1 +- j) of 1/4
        j = sc.fiber_generation.radius_jitter
        ratio = radii[:, 1] / radii[:, 0]
        assert np.all(ratio > 0.25 * (1 - j) / (1 + j) - 1e-12) and np.all(ratio < 0.25 * (1 + j) / (1 - j) + 1e-12)
    print(f"case A {section}: {count} fibers ({int(fine.sum())} fines), {mass.sum() * 1e9:.2f} ug")


def test_bare_fabric_scene() -> None:
    """scenes/thesis/bare-fabric.yaml: the case without fibers on the same 3 x 3 mm fabric."""
    sc = load_scene(THESIS / "bare-fabric.yaml")
    assert sc.fibers is None and sc.laydown is None and sc.permeability is not None
    assert (sc.fabric.size_x_m, sc.fabric.size_y_m, sc.fabric.shed) == (3e-3, 3e-3, 8)
    assert sc.permeability.pressure_drop_Pa == 125.0  # ASTM D737, the thesis' CFM


def test_bare_fabric_subgrid_scene_computes_as_the_cases() -> None:
    """scenes/thesis/bare-fabric-subgrid.yaml: the bare fabric with the case scenes' permeability
    settings and fabric, so that sheet and bare fabric are computed alike."""
    bare = load_scene(THESIS / "bare-fabric-subgrid.yaml")
    case = load_scene(_path("A", "circular"))
    assert bare.fibers is None and bare.laydown is None
    assert bare.permeability == case.permeability
    assert bare.fabric == case.fabric
