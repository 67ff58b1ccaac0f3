# SPDX-License-Identifier: GPL-3.0-or-later
"""scenes/thesis/campaign.yaml and fiberform.campaign (issue 15): the validation campaign's points,
their scenes and the per-sheet ratios, against the thesis' numbers and hand values.

- a point of a case's mass gives exactly the shipped case scene (apart from name, output folder
  and the campaign's press section): the derivation scales as the twelve case scenes do;
- the SEM mapping is the thesis' (case B = sheet 2, linear) and G is sheet 7's counterpart;
- press targets: a sheet's own measured thickness, a case's the thickness at its mapped mass;
- every point scene of both sections is valid and presses with the overlap guard's stop;
- the second press (pressure_press, 410 kPa, ISO 5269-1): its fields are checked (exit 2 naming
  the field); its scene equals the point's in every section but press (so every stage before the
  press hashes the same inputs) and presses in pressure mode with the same guard;
- statistics over seeds and ratios from hand-made collect rows, the pressure press's rows joined
  by seed (and refused when they are not the same sheet); an earlier results file's other points
  kept (run.py --keep);
- the SEM convention: every point, the sheet points too, is a support point at f x its simulated
  mass (S3: 45.1 ug -> 13.69 ug, next to sheet 1's 13.5 ug); hand interpolations, None outside
  the support range, points at one SEM mass merged deterministically; a results JSON written
  before ``sem_mass_kg`` / ``sem_factor`` is kept and redrawn (``run.py --collect-only --keep``
  on the committed bench/thesis/results/campaign.json, stripped of both fields);
- end to end on a tiny campaign: both presses of one laid-down sheet, the lay-down not run twice.
"""

from __future__ import annotations

import copy
import json
import shutil
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from fiberform import campaign as cp
from fiberform import executors
from fiberform.scene import parse_scene, read_scene_yaml, section_hash
from fiberform.stages import STAGES

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "scenes" / "thesis"
RUNNER = ROOT / "bench" / "thesis" / "run.py"


@pytest.fixture(scope="module")
def setup() -> tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]:
    c = cp.load_campaign(THESIS / "campaign.yaml")
    sheets = cp.read_experiments(THESIS / "experiments.csv")
    return c, sheets, cp.points(c, sheets)


def test_points_cover_cases_and_sheets(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    c, sheets, pts = setup
    names = [p.name for p in pts]
    assert names == ["A", "B", "C", "D", "E", "F", "G", "S1", "S2", "S3", "S4", "S5", "S6", "S7"]
    # thesis Table 4.2: k x 35.7 ug
    for name, k in zip("ABCDEF", (1.0, 2.5, 5.0, 7.5, 10.0, 12.5), strict=True):
        assert next(p for p in pts if p.name == name).mass_kg == pytest.approx(k * 35.7e-9, rel=1e-12)
    # thesis Table 4.1: scaled masses used directly
    for s, ug in zip(range(1, 8), (13.5, 27.1, 45.1, 62.9, 90.0, 134.7, 179.4), strict=True):
        p = next(p for p in pts if p.name == f"S{s}")
        assert p.mass_kg == p.experimental_mass_kg == pytest.approx(ug * 1e-9, rel=1e-12)
    assert c.reduced.points == ["A", "C"] and c.reduced.seeds == 1 and c.seeds == 3


def test_sem_mapping_is_the_thesis(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    c, sheets, pts = setup
    by = {p.name: p for p in pts}
    f = 27.1 / (2.5 * 35.7)  # thesis sec. 5.1: case B (2.5 M_A) = sheet 2 (27.1 ug), linear
    assert cp.sem_factor(c, sheets) == pytest.approx(f, rel=1e-12)
    assert by["B"].experimental_mass_kg == pytest.approx(27.1e-9, rel=1e-12)
    assert by["B"].press_target_m == pytest.approx(10e-6)  # sheet 2's thickness
    assert by["G"].experimental_mass_kg == pytest.approx(179.4e-9, rel=1e-3)  # sheet 7
    assert by["G"].press_target_m == pytest.approx(149e-6, rel=1e-3)
    # case C maps between sheets 3 (45.1 ug, 82 um) and 4 (62.9 ug, 93 um), as the thesis says
    m = 5.0 * 35.7e-9 * f
    assert 45.1e-9 < m < 62.9e-9
    assert by["C"].press_target_m == pytest.approx(82e-6 + (m - 45.1e-9) / (17.8e-9) * 11e-6, rel=1e-9)
    # sheets press to their own thickness; sheet 1 (0 um) to the campaign's minimum
    assert by["S4"].press_target_m == pytest.approx(93e-6)
    assert by["S1"].press_target_m == c.press.min_target_m


@pytest.mark.parametrize("case, k", [("A", 1.0), ("C", 5.0), ("F", 12.5)])
@pytest.mark.parametrize("section", ["circular", "rectangular"])
def test_case_point_is_the_shipped_case_scene(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]],
                                              case: str, k: float, section: str) -> None:
    c, _, pts = setup
    p = next(p for p in pts if p.name == case)
    shipped = read_scene_yaml((THESIS / f"case-{case}-{section}.yaml").read_text())
    # the scenes' own fiber contact (the campaign's fiber_contact override: test_fiber_contact_override)
    own = c.model_copy(update={"fiber_contact": None, "solver": None, "permeability": None})
    data = cp.point_scene(own, p, section, THESIS, Path("runs/x"))  # type: ignore[arg-type]
    press = data.pop("press")
    for d in (data, shipped):
        d.pop("name"), d.pop("output_dir")
    assert data == shipped
    assert press["mode"] == "velocity" and press["overlap_action"] == "stop"
    assert press["target_thickness_m"] == pytest.approx(p.press_target_m, rel=1e-6)


def test_every_point_scene_is_valid(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    c, _, pts = setup
    for p in pts:
        for section in c.sections:
            data = cp.point_scene(c, p, section, THESIS, Path("runs/x"))
            sc = parse_scene(data, p.name)
            assert sc.press is not None and sc.press.overlap_action == "stop"
            assert sc.laydown.fiber_contact == c.fiber_contact == "newton"
            assert c.solver is not None
            assert (sc.laydown.newton_tolerance, sc.laydown.anderson_depth) == (
                c.solver.newton_tolerance, c.solver.anderson_depth) == (1.0e-5, 3)
            assert sc.permeability is not None and c.permeability is not None
            assert sc.permeability.convergence_tolerance == c.permeability.convergence_tolerance == 1.0e-2
            assert sc.fibers.target_mass_kg == pytest.approx(p.mass_kg, rel=1e-6)
            slab = sc.fiber_generation.placement_hi_m[2] - sc.fiber_generation.placement_lo_m[2]
            # placement heights are written with 7 significant digits (1e-9 m at 3 mm)
            assert slab == pytest.approx(c.slab_per_M_A_m[section] * p.mass_kg / c.M_A_kg, abs=1e-9)


def test_summary_and_ratios_from_hand_rows(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    c, sheets, pts = setup
    collected = {
        "S2-circular": [{"permeability_cfm": "240.0"}, {"permeability_cfm": "260.0"}, {"permeability_cfm": ""}],
        "A-circular": [{"permeability_cfm": "300.0"}],
        "C-circular": [{"permeability_cfm": "200.0"}],
    }
    s = cp.summarise(collected)
    assert s["S2-circular"]["permeability_cfm"] == {"mean": 250.0, "sd": statistics.stdev([240.0, 260.0]), "n": 2.0}
    assert s["A-circular"]["permeability_cfm"]["sd"] == 0.0
    rows = {r["sheet"]: r for r in cp.sheet_ratios(sheets, pts, s, "circular")}
    assert rows[2]["direct"]["ratio"] == pytest.approx(250.0 / 255.0)
    assert rows[1]["direct"] is None
    # SEM: A maps to 10.84 ug, C to 54.2 ug: sheets 2 (27.1) and 3 (45.1) lie between, linearly
    f = 27.1 / (2.5 * 35.7)
    ma, mc = 35.7 * f, 5 * 35.7 * f
    for sheet, m in ((2, 27.1), (3, 45.1)):
        want = 300.0 + (m - ma) / (mc - ma) * (200.0 - 300.0)
        assert rows[sheet]["sem"]["mean"] == pytest.approx(want, rel=1e-9)
    assert rows[1]["sem"] is not None  # 13.5 ug lies between A and C too
    assert rows[4]["sem"] is None and rows[7]["sem"] is None  # beyond case C


def test_every_point_has_its_sem_mass(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    """sem_mass_kg = simulated mass x 27.1 / 89.25 for every point; for a case the SEM-mapped mass
    its press targets (experimental_mass_kg), for a sheet point not its own mass."""
    _, _, pts = setup
    by = {p.name: p for p in pts}
    f = 27.1 / 89.25
    for p in pts:
        assert p.sem_mass_kg == pytest.approx(p.mass_kg * f, rel=1e-12), p.name
        if not p.name.startswith("S"):
            assert p.sem_mass_kg == pytest.approx(p.experimental_mass_kg, rel=1e-12), p.name
    # by hand: 13.5 x 27.1 / 89.25, 27.1 x 27.1 / 89.25, 45.1 x 27.1 / 89.25 (ug)
    assert by["S1"].sem_mass_kg == pytest.approx(4.0992e-9, rel=1e-4)
    assert by["S2"].sem_mass_kg == pytest.approx(8.2287e-9, rel=1e-4)
    assert by["S3"].sem_mass_kg == pytest.approx(13.694e-9, rel=1e-4)
    assert by["A"].sem_mass_kg == pytest.approx(10.84e-9, rel=1e-4)
    assert by["S3"].experimental_mass_kg == pytest.approx(45.1e-9, rel=1e-12)  # direct: its own


def test_sem_value_from_a_case_and_a_sheet_point(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    """With case A and S3 finished only: A stands for 35.7 x f = 10.84 ug, S3 for 45.1 x f = 13.69
    ug (f = 27.1 / 89.25); sheet 1 (13.5 ug) lies between them, every other sheet beyond S3."""
    c, sheets, pts = setup
    s = cp.summarise({"A-circular": [{"permeability_cfm": "700.0"}],
                      "S3-circular": [{"permeability_cfm": "400.0"}, {"permeability_cfm": "420.0"}]})
    rows = {r["sheet"]: r for r in cp.sheet_ratios(sheets, pts, s, "circular")}
    f = 27.1 / (2.5 * 35.7)
    ma, m3 = 35.7 * f, 45.1 * f  # ug
    want = 700.0 + (13.5 - ma) / (m3 - ma) * (410.0 - 700.0)  # S3: mean of 400 and 420
    assert want == pytest.approx(429.7, abs=0.1)  # 700 - 290 x 2.66 / 2.854
    assert rows[1]["sem"]["mean"] == pytest.approx(want, rel=1e-9)
    assert rows[1]["sem"]["ratio"] == pytest.approx(want / 310.0, rel=1e-9)
    assert [p["point"] for p in rows[1]["sem"]["support"]] == ["A", "S3"]
    assert [p["sem_mass_kg"] for p in rows[1]["sem"]["support"]] == pytest.approx([ma * 1e-9, m3 * 1e-9], rel=1e-9)
    assert [p["mean"] for p in rows[1]["sem"]["support"]] == [700.0, 410.0]
    assert all(rows[k]["sem"] is None for k in range(2, 8))  # 27.1 ug and up: beyond S3's 13.69 ug
    assert rows[3]["direct"]["ratio"] == pytest.approx(410.0 / 175.0)  # S3 is sheet 3's direct point too
    assert rows[1]["direct"] is None
    # only A: no range around sheet 1; the pressed metric: no point has finished it
    only_a = cp.summarise({"A-circular": [{"permeability_cfm": "700.0"}]})
    assert all(r["sem"] is None for r in cp.sheet_ratios(sheets, pts, only_a, "circular"))
    assert all(r["sem"] is None for r in cp.sheet_ratios(sheets, pts, s, "circular", "permeability_press_cfm"))
    # the rectangular section has its own support points: none here
    assert all(r["sem"] is None for r in cp.sheet_ratios(sheets, pts, s, "rectangular"))


def test_sem_support_of_the_points_run_so_far(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    """A, S1 and S2 (the points of bench/thesis/results/campaign.json) stand for 10.84, 4.10 and
    8.23 ug in the SEM convention, all below sheet 1 (13.5 ug): no sheet has an SEM value yet.
    A point at a sheet's own SEM mass (B = sheet 2) is that sheet's value alone, also beside
    others."""
    c, sheets, pts = setup
    s = cp.summarise({g: [{"permeability_cfm": x}] for g, x in
                      (("A-circular", "740"), ("S1-circular", "765"), ("S2-circular", "745"))})
    assert all(r["sem"] is None for r in cp.sheet_ratios(sheets, pts, s, "circular"))
    s = cp.summarise({g: [{"permeability_cfm": x}] for g, x in
                      (("B-circular", "600"), ("S2-circular", "745"), ("C-circular", "500"))})
    rows = {r["sheet"]: r for r in cp.sheet_ratios(sheets, pts, s, "circular")}
    assert rows[2]["sem"]["mean"] == pytest.approx(600.0, rel=1e-9)
    assert [p["point"] for p in rows[2]["sem"]["support"]] == ["B"]
    assert rows[1]["sem"]["mean"] == pytest.approx(745.0 + (13.5 - 8.2287) / (27.1 - 8.2287) * (600.0 - 745.0),
                                                   rel=1e-4)
    assert [p["point"] for p in rows[1]["sem"]["support"]] == ["S2", "B"]
    assert [p["point"] for p in rows[3]["sem"]["support"]] == ["B", "C"]
    assert rows[4]["sem"] is None  # C: 178.5 x 27.1 / 89.25 = 54.2 ug < 62.9 ug


def test_sem_points_at_one_mass_are_merged() -> None:
    """Two points at the same SEM mass (within 1e-9 relative) are one support point: the mean of
    their means, their names in sorted order, whatever order they come in."""
    summary = {"X-circular": {"m": {"mean": 100.0}}, "Y-circular": {"m": {"mean": 300.0}},
               "Z-circular": {"m": {"mean": 500.0}}, "W-circular": {"other": {"mean": 1.0}}}
    named = [("Y", 1e-8 * (1 + 1e-12)), ("X", 1e-8), ("Z", 2e-8), ("W", 1.5e-8)]
    for order in (named, named[::-1]):
        sup = cp.sem_support(order, summary, "circular", "m")
        assert [p.names for p in sup] == [("X", "Y"), ("Z",)]  # W has no "m"
        assert [p.mean for p in sup] == [200.0, 500.0]
        assert sup[0].sem_mass_kg == pytest.approx(1e-8, rel=1e-11)
        v = cp.sem_value(sup, 1.5e-8)
        assert v is not None and v[0] == pytest.approx(350.0) and [p.row()["point"] for p in v[1]] == ["X+Y", "Z"]
    sup = cp.sem_support(named, summary, "circular", "m")
    # the ends: widened by 1e-6 relative, one support point there; beyond: None
    assert cp.sem_value(sup, 1e-8 * (1 - 5e-7))[1][0].names == ("X", "Y")  # type: ignore[index]
    assert cp.sem_value(sup, 2e-8 * (1 + 5e-7))[1][0].names == ("Z",)  # type: ignore[index]
    assert cp.sem_value(sup, 1e-8 * (1 - 2e-6)) is None and cp.sem_value(sup, 2e-8 * (1 + 2e-6)) is None
    assert cp.sem_value([], 1e-8) is None


def test_kept_results_take_over_other_groups(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    """run.py --keep: the groups of an earlier results JSON that a call does not run keep their rows
    (and failures, pending presses) and enter the summary as if collected again; a group the call
    runs is replaced, not doubled."""
    c, sheets, pts = setup
    previous = {
        "points": [{"name": "A"}, {"name": "S2"}],
        "variants": [
            {"point": "A", "section": "circular", "ranks": {"laydown": 2}, "seed": "1", "permeability_cfm": "300"},
            {"point": "S2", "section": "circular", "ranks": {"laydown": 2}, "seed": "1", "permeability_cfm": "240"},
            {"point": "S2", "section": "circular", "ranks": {"laydown": 2}, "seed": "2", "permeability_cfm": "260"},
            {"point": "A", "section": "rectangular", "ranks": {"laydown": 2}, "seed": "1", "permeability_cfm": "1"},
        ],
        "failures": {"S2-circular-pressure": "x", "A-rectangular": "y"},
        "pending": {"S2-circular-pressure": {"v": "waits"}},
    }
    kept = cp.kept_results(previous, {"A-rectangular", "S3-circular"})
    assert sorted(kept.collected) == ["A-circular", "S2-circular"]
    assert [p["name"] for p in kept.points] == ["A", "S2"]
    assert kept.collected["S2-circular"] == [{"seed": "1", "permeability_cfm": "240"},
                                             {"seed": "2", "permeability_cfm": "260"}]
    assert len(kept.variants) == 3 and all(v["section"] == "circular" for v in kept.variants)
    assert kept.failures == {"S2-circular-pressure": "x"} and kept.pending == previous["pending"]
    s = cp.summarise(kept.collected)
    assert s["S2-circular"]["permeability_cfm"]["mean"] == 250.0
    rows = {r["sheet"]: r for r in cp.sheet_ratios(sheets, pts, s, "circular")}
    assert rows[2]["direct"]["ratio"] == pytest.approx(250.0 / 255.0)
    # nothing kept when the call runs every group
    assert not cp.kept_results(previous, {"A-circular", "S2-circular", "A-rectangular"}).variants
    # point rows of a file written before sem_mass_kg: mass_kg x f, f the file's sem_factor or the
    # campaign's; a row with sem_mass_kg keeps it
    old = {**previous, "points": [{"name": "A", "mass_kg": 35.7e-9}, {"name": "S2", "mass_kg": 27.1e-9}]}
    kept = cp.kept_results(old, set(), 27.1 / 89.25)
    assert [p["sem_mass_kg"] for p in kept.points] == pytest.approx([10.84e-9, 27.1e-9 * 27.1 / 89.25], rel=1e-12)
    assert "sem_mass_kg" not in old["points"][0]  # the earlier file's rows are not changed
    kept = cp.kept_results({**old, "sem_factor": 0.5}, set(), 27.1 / 89.25)
    assert [p["sem_mass_kg"] for p in kept.points] == pytest.approx([17.85e-9, 13.55e-9], rel=1e-12)
    kept = cp.kept_results({**old, "points": [{"name": "A", "mass_kg": 35.7e-9, "sem_mass_kg": 1e-9}]}, set(), 0.3)
    assert kept.points == [{"name": "A", "mass_kg": 35.7e-9, "sem_mass_kg": 1e-9}]


def test_campaign_file_errors_name_the_field(tmp_path: Path) -> None:
    text = (THESIS / "campaign.yaml").read_text().replace("seeds: 3 ", "seeds: 0 ")
    bad = tmp_path / "campaign.yaml"
    bad.write_text(text)
    with pytest.raises(cp.ConfigError, match="seeds"):
        cp.load_campaign(bad)


@pytest.mark.parametrize("field, value", [("target_pressure_Pa", "0.0"), ("target_pressure_Pa", "2.0e+9"),
                                          ("hold_time_s", "-1.0e-3"), ("release_time_s", "11.0"),
                                          ("pressure_rate_Pa_s", "0.0"), ("plate_force_N", "1.0")])
def test_pressure_press_errors_name_the_field(tmp_path: Path, field: str, value: str) -> None:
    head, sep, block = (THESIS / "campaign.yaml").read_text().partition("\npressure_press:\n")
    assert sep and block.startswith("  target_pressure_Pa: 4.1e+5")
    block, blank, tail = block.partition("\n\n")
    lines = [line for line in block.splitlines() if not line.startswith(f"  {field}:")]  # the shipped value
    bad = tmp_path / "campaign.yaml"
    text = head + sep + "\n".join([f"  {field}: {value}", *lines]) + blank + tail
    bad.write_text(text)
    with pytest.raises(cp.ConfigError, match=f"pressure_press.{field}"):
        cp.load_campaign(bad)
    # the runner: exit 2 naming the field, before anything is run or written
    proc = subprocess.run([sys.executable, str(RUNNER), "--campaign", str(bad), "--runs", "runs/c",
                           "--collect-only", "--out", str(tmp_path / "r.json")], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and f"pressure_press.{field}" in proc.stderr, proc.stderr[-2000:]
    assert not (tmp_path / "r.json").exists() and not (tmp_path / "runs").exists()


def test_pressure_press_is_iso_5269(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    c, _, _ = setup
    assert c.pressure_press is not None
    assert c.pressure_press.target_pressure_Pa == 410e3  # ISO 5269-1 wet pressing (an assumption)
    text = (THESIS / "campaign.yaml").read_text()
    assert "ISO 5269-1" in text and "ASSUMPTION, not a thesis value" in text
    # the campaign without it has no second press
    assert cp.Campaign.model_validate({**c.model_dump(), "pressure_press": None}).pressure_press is None


def test_pressure_scene_differs_from_the_point_only_in_press(
        setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    c, _, pts = setup
    assert c.pressure_press is not None
    upstream = [STAGES[n] for n in cp.REUSED_STAGES]
    for p in pts:
        for section in c.sections:
            point = cp.point_scene(c, p, section, THESIS, Path("runs/x"))
            data = cp.pressure_scene(c, point)
            a, b = dict(point), dict(data)
            pa, pb = a.pop("press"), b.pop("press")
            assert b.pop("name") == a.pop("name") + "_pressure"
            assert b.pop("output_dir") == a.pop("output_dir") + "-pressure"
            assert a == b
            assert pb == {"mode": "pressure", "target_pressure_Pa": 410e3,
                          "hold_time_s": c.pressure_press.hold_time_s,
                          "release_time_s": c.pressure_press.release_time_s,
                          "plate_speed_m_s": pa["plate_speed_m_s"], "output_interval_s": pa["output_interval_s"],
                          "overlap_limit": pa["overlap_limit"], "overlap_action": "stop", "ranks": pa["ranks"],
                          "steric_cap_m": c.press.steric_cap_m}
            assert pa["steric_cap_m"] == c.press.steric_cap_m == 1e-6  # both presses (campaign.yaml)
            # validated, and every stage before the press hashes the same scene entries
            sp, sq = parse_scene(point, "point"), parse_scene(data, "pressure")
            assert sq.press is not None and sq.press.mode == "pressure" and sq.press.overlap_action == "stop"
            for st in upstream:
                assert section_hash(sp, st.uses) == section_hash(sq, st.uses), st.name
            assert section_hash(sp, STAGES["press"].uses) != section_hash(sq, STAGES["press"].uses)
    with pytest.raises(cp.ConfigError, match="pressure_press"):
        cp.pressure_scene(c.model_copy(update={"pressure_press": None}), point)
    # an optional loading rate reaches the scene
    c2 = c.model_copy(update={"pressure_press": c.pressure_press.model_copy(update={"pressure_rate_Pa_s": 1e8})})
    assert cp.pressure_scene(c2, point)["press"]["pressure_rate_Pa_s"] == 1e8


def test_pressure_rows_join_by_seed(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    """The pressure press's collect rows join the point's by seed as pressure_<column>; a row of
    another sheet (a differing lay-down column, also the thickness above the fabric) is refused;
    statistics and ratios follow."""
    c, sheets, pts = setup
    sheet = {"fibers": "40", "sheet_thickness_m": "2.5e-04", "sheet_thickness_above_fabric_m": "6e-05",
             "permeability_cfm": "600", "laydown_wall_s": "90.5"}
    point = [{"seed": "1", **sheet, "permeability_press_cfm": "550", "press_wall_s": "10"},
             {"seed": "2", **sheet, "permeability_press_cfm": "530"},
             {"seed": "3", **sheet}, {"seed": "4", **sheet}]
    pressure = [{"seed": "2", **sheet, "permeability_press_cfm": "400", "pressed_span_thickness_m": "5e-05",
                 "pressed_thickness_above_fabric_m": "3e-05", "press_max_pressure_Pa": "12.5",
                 "permeability-press_wall_s": "20"},
                {"seed": "1", **sheet, "permeability_press_cfm": "420", "pressed_span_thickness_m": "7e-05",
                 "pressed_thickness_above_fabric_m": "4e-05"},
                {"seed": "3", **{**sheet, "laydown_wall_s": "91.0"}, "permeability_press_cfm": "1"},
                {"seed": "4", **{**sheet, "sheet_thickness_above_fabric_m": "6.1e-05"}, "permeability_press_cfm": "2"}]
    rows, problems = cp.merge_pressure(point, pressure)
    assert rows[0]["pressure_permeability_press_cfm"] == "420" and rows[0]["permeability_press_cfm"] == "550"
    assert rows[1]["pressure_press_max_pressure_Pa"] == "12.5" and rows[1]["pressure_permeability-press_wall_s"] == "20"
    assert rows[0]["press_wall_s"] == "10" and "pressure_press_wall_s" not in rows[0]
    assert rows[1]["pressure_pressed_thickness_above_fabric_m"] == "3e-05"
    assert not any(k.startswith("pressure_") for k in rows[2])  # seed 3: another lay-down
    assert not any(k.startswith("pressure_") for k in rows[3])  # seed 4: another sheet above the fabric
    assert len(problems) == 2 and "seed 3" in problems[0] and "laydown_wall_s" in problems[0]
    assert "seed 4" in problems[1] and "press's sheet_thickness_above_fabric_m differ" in problems[1]
    assert cp.merge_pressure(point, []) == (point, [])
    s = cp.summarise({"S2-circular": rows})
    assert s["S2-circular"]["pressure_permeability_press_cfm"] == {"mean": 410.0, "sd": statistics.stdev([420, 400]),
                                                                  "n": 2.0}
    assert s["S2-circular"]["pressure_pressed_span_thickness_m"]["mean"] == pytest.approx(6e-5)
    assert s["S2-circular"]["pressure_pressed_thickness_above_fabric_m"]["mean"] == pytest.approx(3.5e-5)
    assert s["S2-circular"]["sheet_thickness_above_fabric_m"] == {"mean": 6e-5, "sd": 0.0, "n": 4.0}
    assert s["S2-circular"]["permeability_press_cfm"]["mean"] == 540.0
    r = {x["sheet"]: x for x in cp.sheet_ratios(sheets, pts, s, "circular", "pressure_permeability_press_cfm")}
    assert r[2]["direct"]["ratio"] == pytest.approx(410.0 / 255.0)


# ---- the runner end to end on a tiny campaign (1 x 1 mm, a few fibers): every stage through the
# sweep machinery, the results JSON, and the resume (a second call runs nothing again)
TINY_BASE = """\
format_version: 1
name: tiny_campaign_base
seed: 3
output_dir: runs/unused
fluid: {density_kg_m3: 998.2, viscosity_Pa_s: 1.0e-3}
fibers: {target_mass_kg: 2.2e-9, length_m: 0.6e-3, width_m: 20.0e-6, segments: 12,
         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}
fiber_generation: {placement_lo_m: [0.0, 0.0, 2.66e-3], placement_hi_m: [1.0e-3, 1.0e-3, 2.76e-3]}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3}
flow: {delta_p_Pa: 100.0, cell_size_m: 50.0e-6, height_above_fabric_m: 0.6e-3}
laydown: {terms: [steric], max_time_s: 0.006, check_interval_s: 5.0e-4, settle_speed_m_s: 2.0e-3, settle_checks: 3,
          timestep_s: 1.0e-6, friction_coefficient: 0.5}
contact: {model: fiber_dlvo, terms: [steric]}
permeability: {mode: subgrid, subgrid_cell_size_m: 100.0e-6, convergence_tolerance: 2.0e-2}
"""
TINY_CAMPAIGN = """\
format_version: 1
base: {circular: base.yaml, rectangular: base.yaml}
sections: [circular]
M_A_kg: 2.2e-9
seeds: 2
slab_per_M_A_m: {circular: 0.1e-3, rectangular: 0.1e-3}
flow_margin_m: 0.7e-3
cases: {A: 1.0, B: 2.0}
sheets: [2]
sem_mapping: {case: B, sheet: 2}
press: {plate_speed_m_s: 0.02, min_target_m: 2.0e-6, hold_time_s: 2.0e-4, output_interval_s: 1.0e-4,
        overlap_limit: 0.2}
pressure_press: {target_pressure_Pa: 4.1e+5, hold_time_s: 2.0e-4, release_time_s: 1.0e-4}
reduced: {points: [A], seeds: 1}
"""
TINY_EXPERIMENTS = """\
# two made-up sheets for the runner test (not the thesis' values)
sheet,injection_mass_g,permeability_cfm,thickness_um,scaled_injection_mass_ug
1,1.0,500,0,0.5
2,2.0,400,10,1.0
"""


def write_tiny_campaign(root: Path) -> Path:
    """The tiny campaign's folder ``root/camp``: base scene, campaign and experiments."""
    camp = root / "camp"
    camp.mkdir()
    (camp / "base.yaml").write_text(TINY_BASE)
    (camp / "campaign.yaml").write_text(TINY_CAMPAIGN)
    (camp / "experiments.csv").write_text(TINY_EXPERIMENTS)
    return camp


def tiny_point(root: Path) -> tuple[cp.Campaign, dict[str, Any]]:
    """The tiny campaign written to ``root/camp`` and the scene data of its first point (circular,
    output under the relative folder runs/)."""
    camp = write_tiny_campaign(root)
    c = cp.load_campaign(camp / "campaign.yaml")
    point = cp.point_scene(c, cp.points(c, cp.read_experiments(camp / "experiments.csv"))[0], "circular", camp,
                           Path("runs"))
    return c, point


def test_runner_keep_adds_to_an_earlier_results_file(tmp_path: Path) -> None:
    """run.py --keep --collect-only on the tiny campaign (nothing has run): the earlier file's other
    point survives with its rows and ratios; an earlier file of another pressure_press is refused
    before anything runs (exit 2, the file untouched)."""
    camp = write_tiny_campaign(tmp_path)
    c = cp.load_campaign(camp / "campaign.yaml")
    assert c.pressure_press is not None
    out = tmp_path / "result.json"
    earlier = {"command": "--points S2", "pressure_press": c.pressure_press.model_dump(),
               "points": [{"name": "S2", "mass_kg": 1e-9, "experimental_mass_kg": 1e-9, "press_target_m": 4e-4}],
               "variants": [{"point": "S2", "section": "circular", "ranks": {"laydown": 1, "press": 1},
                             "seed": "3", "permeability_cfm": "5.0"}],
               "failures": {}, "pending": {}}
    out.write_text(json.dumps(earlier))
    cmd = [sys.executable, str(RUNNER), "--campaign", str(camp / "campaign.yaml"), "--runs", "runs/c",
           "--points", "A", "--sections", "circular", "--collect-only", "--keep", "--out", str(out)]
    proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    res = json.loads(out.read_text())
    # the code of the call: the package's version and revisions, the campaign file's hash
    from fiberform._versions import git_revision, package_version
    from fiberform.provenance import file_hash
    assert res["code"]["fiberform"] == package_version() and res["code"]["git_revision"] == git_revision()
    assert res["code"]["campaign_sha256"] == file_hash(camp / "campaign.yaml") and res["code"]["build_revision"]
    assert [p["name"] for p in res["points"]] == ["A", "S2"]  # campaign order
    assert res["kept_from"]["groups"] == ["S2-circular"] and res["kept_from"]["command"] == "--points S2"
    assert res["variants"] == earlier["variants"]
    assert res["summary"]["S2-circular"]["permeability_cfm"]["mean"] == 5.0
    sheet2 = next(r for r in res["sheets_unpressed"]["circular"] if r["sheet"] == 2)
    assert sheet2["direct"]["ratio"] == pytest.approx(5.0 / 400.0)  # TINY_EXPERIMENTS: sheet 2 measured 400 CFM
    # SEM factor: sheet 2 (1.0 ug) / case B (2 x 2.2 ug); the earlier S2 row (no sem_mass_kg) gets
    # its 1 ug x f, the new row of A its 2.2 ug x f = 0.5 ug (sheet 1's mass)
    assert res["sem_factor"] == pytest.approx(1.0 / 4.4, rel=1e-12)
    assert [p["sem_mass_kg"] for p in res["points"]] == pytest.approx([0.5e-9, 1e-9 / 4.4], rel=1e-12)
    # S2 (SEM 0.227 ug) is the only support point: below both sheets (0.5 and 1.0 ug)
    assert all(r["sem"] is None for r in res["sheets_unpressed"]["circular"])
    # another pressure_press: refused, the file kept byte for byte
    earlier["pressure_press"] = {**earlier["pressure_press"], "target_pressure_Pa": 1.0}
    out.write_text(text := json.dumps(earlier))
    shutil.rmtree(tmp_path / "runs")
    bad = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "--keep" in bad.stderr and "pressure_press" in bad.stderr, bad.stderr
    assert out.read_text() == text and not (tmp_path / "runs").exists()
    # another SEM factor recorded in the earlier file (its pressure_press the campaign's): refused
    # the same way
    earlier["pressure_press"] = c.pressure_press.model_dump()
    out.write_text(text := json.dumps({**earlier, "sem_factor": 0.5}))
    bad = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "--keep" in bad.stderr and "SEM factor" in bad.stderr, bad.stderr
    assert out.read_text() == text and not (tmp_path / "runs").exists()


def test_runner_collect_only_keeps_an_old_results_file(tmp_path: Path) -> None:
    """run.py --collect-only --keep (every point, both sections) on the committed
    bench/thesis/results/campaign.json as written before sem_mass_kg and sem_factor existed (both
    taken out here, whatever the committed file holds by then), on a machine without its run
    folders (runs/ under tmp_path): every group of the file is kept, as a group without a sweep
    folder here is not replaced by --collect-only; its point rows get mass_kg x 27.1 / 89.25, the
    file the SEM factor, and the figures and tables are drawn."""
    committed = json.loads((ROOT / "bench" / "thesis" / "results" / "campaign.json").read_text())
    old = copy.deepcopy(committed)
    old.pop("sem_factor", None)
    for p in old["points"]:
        p.pop("sem_mass_kg", None)
    c = cp.load_campaign(THESIS / "campaign.yaml")
    assert c.pressure_press is not None
    old["pressure_press"] = c.pressure_press.model_dump()  # the format is tested here, not the press
    out = tmp_path / "results" / "campaign.json"
    out.parent.mkdir()
    out.write_text(json.dumps(old))
    proc = subprocess.run([sys.executable, str(RUNNER), "--runs", "runs/c", "--collect-only", "--keep",
                           "--out", str(out)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    res = json.loads(out.read_text())
    groups = sorted({f"{v['point']}-{v['section']}" for v in old["variants"]})
    assert groups and res["kept_from"]["groups"] == groups
    assert res["variants"] == old["variants"]
    f = 27.1 / 89.25
    assert res["sem_factor"] == pytest.approx(f, rel=1e-12)
    by = {p["name"]: p for p in res["points"]}
    assert len(by) == len(res["points"]) == 14  # every point of the call once, the kept ones too
    for p in old["points"]:
        assert by[p["name"]]["sem_mass_kg"] == pytest.approx(p["mass_kg"] * f, rel=1e-12), p["name"]
        assert by[p["name"]]["experimental_mass_kg"] == pytest.approx(p["experimental_mass_kg"], rel=1e-12)
    for g in groups:
        assert res["summary"][g]["permeability_cfm"]["mean"] == pytest.approx(
            old["summary"][g]["permeability_cfm"]["mean"], rel=1e-12)
    for name in ("campaign-fig412-thickness.png", "campaign-fig413-permeability.png", "campaign.md"):
        assert (out.parent / name).is_file(), name


@pytest.mark.parametrize("resume", [False, True])
def test_runner_resume_reaches_every_sweep(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, resume: bool) -> None:
    """run.py --resume (on the tiny campaign, both seeds of point A): the point's `fiberform sweep`
    command line carries --resume and the pressure presses' sweep (fiberform.campaign.run_pressure_sweep,
    which goes through the same run_sweep / submit_sweep) gets resume=True; without --resume
    neither does. The sweep itself is not run here (a stand-in records its command line), so the
    pressure presses wait for their lay-downs."""
    from bench_scripts import load_bench_script

    runner = load_bench_script("bench/thesis/run.py", "thesis_campaign_run")
    camp = write_tiny_campaign(tmp_path)
    monkeypatch.chdir(tmp_path)
    sweeps: list[list[str]] = []
    real_run = subprocess.run

    def run(cmd: list[str], *args: Any, **kwargs: Any) -> subprocess.CompletedProcess[Any]:
        if "sweep" in cmd:
            sweeps.append([str(c) for c in cmd])
            return subprocess.CompletedProcess(cmd, 0)
        return real_run(cmd, *args, **kwargs)

    monkeypatch.setattr(runner, "subprocess", type("StandIn", (), {"run": staticmethod(run)}))
    pressure_calls: list[dict[str, Any]] = []
    real_pressure = cp.run_pressure_sweep

    def pressure(*args: Any, **kwargs: Any) -> cp.PressureSweep:
        pressure_calls.append(kwargs)
        return real_pressure(*args, **kwargs)

    monkeypatch.setattr(cp, "run_pressure_sweep", pressure)
    monkeypatch.setattr(sys, "argv", ["run.py", "--campaign", str(camp / "campaign.yaml"), "--runs", "runs/c",
                                      "--points", "A", "--sections", "circular", "--out", str(tmp_path / "r.json"),
                                      *(["--resume"] if resume else [])])
    assert runner.main() == 0
    assert len(sweeps) == 1 and sweeps[0][sweeps[0].index("sweep") + 1].endswith("A-circular.yaml"), sweeps
    assert ("--resume" in sweeps[0]) is resume, sweeps
    assert [kw.get("resume") for kw in pressure_calls] == [resume]
    pending = json.loads((tmp_path / "r.json").read_text())["pending"]
    assert sorted(pending["A-circular-pressure"]) == ["campaign_A_circular_pressure_000",
                                                      "campaign_A_circular_pressure_001"]


def test_runner_runs_points_side_by_side(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """run.py --points-at-once 2 (tiny campaign, points A and B): the two points' `fiberform sweep`
    run at the same time (each stand-in sweep waits at a two-party barrier, which times out if they
    run one after the other), each writes its output and its pressure presses' lines to
    RUNS/logs/GROUP.log, and a sweep that fails is recorded under its own group while the other
    point's results stay. Out-of-range values and --submit are refused with exit 2."""
    import threading

    from bench_scripts import load_bench_script

    runner = load_bench_script("bench/thesis/run.py", "thesis_campaign_run_at_once")
    camp = write_tiny_campaign(tmp_path)
    monkeypatch.chdir(tmp_path)
    barrier = threading.Barrier(2, timeout=30)
    met: list[str] = []
    real_run = subprocess.run

    def run(cmd: list[str], *args: Any, **kwargs: Any) -> subprocess.CompletedProcess[Any]:
        if "sweep" not in cmd:
            return real_run(cmd, *args, **kwargs)
        scene = Path(str(cmd[cmd.index("sweep") + 1])).stem
        kwargs["stdout"].write(f"stand-in sweep of {scene}\n")
        barrier.wait()  # BrokenBarrierError (a failed group) unless the other sweep runs meanwhile
        met.append(scene)
        return subprocess.CompletedProcess(cmd, 3 if scene.startswith("B-") else 0)

    monkeypatch.setattr(runner, "subprocess", type("StandIn", (), {"run": staticmethod(run),
                                                                    "STDOUT": subprocess.STDOUT}))
    base = ["run.py", "--campaign", str(camp / "campaign.yaml"), "--runs", "runs/c", "--points", "A,B",
            "--sections", "circular", "--out", str(tmp_path / "r.json")]
    for bad in (["--points-at-once", "0"], ["--points-at-once", "65"], ["--points-at-once", "2", "--submit", "slurm"]):
        monkeypatch.setattr(sys, "argv", [*base, *bad])
        assert runner.main() == 2, bad
    assert not (tmp_path / "r.json").exists()
    monkeypatch.setattr(sys, "argv", [*base, "--points-at-once", "2"])
    assert runner.main() == 1  # B's sweep failed
    assert sorted(met) == ["A-circular", "B-circular"]
    res = json.loads((tmp_path / "r.json").read_text())
    logs = tmp_path / "runs" / "c" / "logs"
    assert set(res["failures"]) == {"B-circular"}
    assert res["failures"]["B-circular"] == f"fiberform sweep exit 3 (see {Path('runs/c/logs/B-circular.log')})"
    for group, status in (("A-circular", 0), ("B-circular", 3)):
        text = (logs / f"{group}.log").read_text()
        assert f"stand-in sweep of {group}" in text and f"== {group}: exit {status} after" in text, text
        assert f"== {group}-pressure: 2 seed(s) wait for their lay-down" in text, text
    assert sorted(res["pending"]) == ["A-circular-pressure", "B-circular-pressure"]


@pytest.mark.system
def test_runner_runs_a_tiny_campaign_and_resumes(tmp_path: Path, build_dir: Path) -> None:
    if not (build_dir / "bin" / "fiberdem").is_file():
        pytest.fail(f"fiberdem not built in {build_dir}")
    camp = write_tiny_campaign(tmp_path)
    out = tmp_path / "result.json"
    cmd = [sys.executable, str(RUNNER), "--campaign", str(camp / "campaign.yaml"), "--runs", "runs/c",
           "--reduced", "--out", str(out)]
    env = {**__import__("os").environ, "FIBERFORM_BUILD": str(build_dir)}
    proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, errors="replace", timeout=900, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    res = json.loads(out.read_text())
    assert [p["name"] for p in res["points"]] == ["A"] and res["seeds"] == 1 and not res["failures"]
    # SEM factor: sheet 2 (1.0 ug) / case B (2 x 2.2 ug); A maps to 0.5 ug = sheet 1 (0 um)
    assert res["points"][0]["experimental_mass_kg"] == pytest.approx(0.5e-9)
    assert res["points"][0]["press_target_m"] == pytest.approx(2.0e-6)
    (v,) = res["variants"]
    assert (v["point"], v["section"], v["seed"]) == ("A", "circular", "3")
    # every stage ran: the lay-down, both permeabilities and the press report their numbers
    for key in ("sheet_thickness_m", "permeability_cfm", "press_plate_gap_m", "permeability_press_cfm"):
        assert float(v[key]) > 0.0, key
    # thicknesses above the fabric top (collected; the report compares these): the pressed sheet's
    # highest surfaces lie at most the overlap guard's 0.2 x 20 um (+ radius jitter) above the plate
    assert 0.0 <= float(v["pressed_thickness_above_fabric_m"]) <= float(v["press_plate_gap_m"]) + 5e-6
    assert float(v["sheet_thickness_above_fabric_m"]) >= 0.0 and "pressure_pressed_thickness_above_fabric_m" in v
    assert float(v["fiber_mass_kg"]) >= 2.2e-9
    stats = res["summary"]["A-circular"]
    assert stats["permeability_cfm"]["n"] == 1.0
    assert stats["permeability_cfm"]["mean"] == pytest.approx(float(v["permeability_cfm"]))
    scene = (tmp_path / "runs" / "c" / "scenes" / "A-circular.yaml").read_text()
    assert "overlap_action: stop" in scene
    # the second press: the same sheet pressed to 410 kPa, its permeability; one lay-down only
    assert res["pressure_press"]["target_pressure_Pa"] == 4.1e5 and not res["pending"]
    for key in ("pressure_pressed_span_thickness_m", "pressure_permeability_press_cfm"):
        assert float(v[key]) > 0.0, key
    assert float(v["pressure_press_max_pressure_Pa"]) >= 0.0
    assert stats["pressure_permeability_press_cfm"]["n"] == 1.0
    assert [r["sheet"] for r in res["sheets_pressure"]["circular"]] == [1, 2]
    assert "mode: pressure" in (tmp_path / "runs" / "c" / "scenes" / "A-circular-pressure.yaml").read_text()
    assert proc.stdout.count("laydown: done in") == 1 and "laydown copied" in proc.stdout, proc.stdout[-3000:]
    runs = tmp_path / "runs" / "c"
    for f in ("laydown/laydown.h5", "laydown/sheet.restart", "permeability-laydown/permeability.h5"):
        assert ((runs / "A-circular-pressure-sweep" / "campaign_A_circular_pressure_000" / f).read_bytes()
                == (runs / "A-circular-sweep" / "campaign_A_circular_000" / f).read_bytes()), f
    # resumed: a second call finds every stage up to date
    again = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, errors="replace", timeout=300, env=env)
    assert again.returncode == 0, again.stdout[-3000:] + again.stderr[-3000:]
    assert "up to date" in again.stdout and "done in" not in again.stdout, again.stdout[-3000:]
    assert "laydown kept" in again.stdout and "copied" not in again.stdout, again.stdout[-3000:]


def test_fiber_contact_override(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]]) -> None:
    """campaign.fiber_contact newton: every point scene has the fiber-fiber contact inside the
    Newton solve, the same terms, and no sub-integrator (it belongs to the averaged contact)."""
    c, _, pts = setup
    c2 = c.model_copy(update={"fiber_contact": "newton"})
    for section in ("circular", "rectangular"):
        data = cp.point_scene(c2, pts[0], section, THESIS, Path("runs/x"))  # type: ignore[arg-type]
        sc = parse_scene(data, "x")
        assert sc.laydown.fiber_contact == "newton" and "integrator" not in data["contact"]
        assert sorted(sc.contact.terms) == ["es", "steric", "vdw"]
        base = cp.point_scene(c.model_copy(update={"fiber_contact": None}), pts[0], section, THESIS,
                              Path("runs/x"))  # type: ignore[arg-type]
        assert base["laydown"]["fiber_contact"] == "averaged" and base["contact"]["integrator"] == "cvode"


def test_pressure_presses_wait_for_their_laydown(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 build_dir: Path) -> None:
    """Before the point's sweep has laid its sheets down, its pressure presses are neither run nor
    submitted (nothing is laid down for them): every seed waits, naming what is missing."""
    import yaml

    monkeypatch.chdir(tmp_path)
    c, point = tiny_point(tmp_path)
    Path("point.yaml").write_text(yaml.safe_dump(point))
    Path("pressure.yaml").write_text(yaml.safe_dump(cp.pressure_scene(c, point)))
    lines: list[str] = []
    for submit in (None, executors.batch_options("slurm")):
        pr = cp.run_pressure_sweep(Path("point.yaml"), Path("pressure.yaml"), 2, build_dir, lines.append, submit)
        assert pr.started == [] and pr.failed == [] and not pr.submitted
        assert sorted(pr.waiting) == ["campaign_A_circular_pressure_000", "campaign_A_circular_pressure_001"]
        assert all("laydown absent" in w and "permeability absent" in w for w in pr.waiting.values())
    assert pr.sweep_dir == Path("runs/A-circular-pressure-sweep") and (pr.sweep_dir / "sweep.json").is_file()
    assert not (pr.sweep_dir / "jobs").exists() and not list(pr.sweep_dir.glob("campaign_*/*"))
    assert any("not submitted" in line for line in lines)


def test_permeability_settings_reach_every_point(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]],
                                                tmp_path: Path) -> None:
    """campaign.permeability.convergence_tolerance reaches the point scene's and its pressure
    scene's permeability section and the solve's stop criterion (the function object's tolerance
    in the case setup); left out, the case scene's stays; out of range, it is refused naming the
    field."""
    from fiberform.stages.permeability import PermeabilityGeometry, case_setup

    c, _, pts = setup
    case = read_scene_yaml((THESIS / c.base["circular"]).read_text())
    geo = PermeabilityGeometry(1.0e-3, 1.0e-3, 2.0e-3, 2.6e-3, 20.0e-6, ())
    for tol in (1.0e-2, 2.5e-2):
        camp = c.model_copy(update={"permeability": cp.CampaignPermeability(convergence_tolerance=tol)})
        data = cp.point_scene(camp, pts[0], "circular", THESIS, Path("runs/x"))
        for scene in (data, cp.pressure_scene(camp, data)):
            perm = parse_scene(scene, "p").permeability
            assert perm is not None and perm.convergence_tolerance == tol
            assert case_setup(perm, geo).stop_tolerance == tol
    none = cp.point_scene(c.model_copy(update={"permeability": None}), pts[0], "circular", THESIS, Path("runs/x"))
    assert none["permeability"]["convergence_tolerance"] == case["permeability"]["convergence_tolerance"]
    assert c.permeability is not None and c.permeability.convergence_tolerance == 1.0e-2  # the shipped campaign's
    camp_file = tmp_path / "campaign.yaml"
    camp_file.write_text((THESIS / "campaign.yaml").read_text().replace(
        "permeability: {convergence_tolerance: 1.0e-2}", "permeability: {convergence_tolerance: 0.9}"))
    with pytest.raises(cp.ConfigError, match="convergence_tolerance"):
        cp.load_campaign(camp_file)


def test_solver_settings_reach_every_point(setup: tuple[cp.Campaign, list[cp.Sheet], list[cp.Point]],
                                           tmp_path: Path) -> None:
    """campaign.solver: each setting given reaches the point scene's laydown section (and the
    generated fiberdem input), one left out keeps the case scene's; out-of-range values are
    refused naming the field."""
    from fiberform.stages import laydown

    c, _, pts = setup
    only_tol = c.model_copy(update={"solver": cp.CampaignSolver(newton_tolerance=3e-6)})
    data = cp.point_scene(only_tol, pts[0], "circular", THESIS, Path("runs/x"))
    case = read_scene_yaml((THESIS / c.base["circular"]).read_text())
    assert data["laydown"]["newton_tolerance"] == 3e-6
    assert data["laydown"].get("anderson_depth") == case["laydown"].get("anderson_depth")
    full = cp.point_scene(c, pts[0], "circular", THESIS, Path("runs/x"))
    assert (full["laydown"]["newton_tolerance"], full["laydown"]["anderson_depth"]) == (1.0e-5, 3)
    beam = [line for line in laydown.render_input(parse_scene(full, "p"), 0.01).splitlines() if "fiber/beam" in line]
    assert len(beam) == 1 and " newton_tol 1e-05 " in beam[0] and beam[0].endswith(" anderson 3"), beam
    camp = tmp_path / "campaign.yaml"
    for bad, field in (("{newton_tolerance: 0.5}", "newton_tolerance"), ("{anderson_depth: 9}", "anderson_depth"),
                       ("{newton_max_iterations: 5}", "newton_max_iterations")):
        camp.write_text((THESIS / "campaign.yaml").read_text().replace(
            "solver: {newton_tolerance: 1.0e-5, anderson_depth: 3}", f"solver: {bad}"))
        with pytest.raises(cp.ConfigError, match=field):
            cp.load_campaign(camp)
