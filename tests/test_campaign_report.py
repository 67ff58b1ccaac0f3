# SPDX-License-Identifier: GPL-3.0-or-later
"""fiberform.campaign_report (issue 15): the campaign JSON turned into the thesis' Figures
4.12/4.13 and per-sheet Markdown tables, checked against hand values (no simulation):

- the table shows the JSON's simulated permeability (mean +- sd, n) and ratios (620 / 310 CFM ->
  2.00), the thicknesses, and ``-`` where a sheet, a state or a section has no data, for the three
  states: unpressed, pressed to thickness, pressed to pressure (the second press, 410 kPa);
- run through the runner's own functions (merge_pressure, summarise, sheet_ratios) the table gives
  the hand ratios of both conventions, also for the pressure press;
- the figures plot exactly the hand values at the right masses / fiber counts, error bars = sd
  (read back from the drawn Axes), and the PNG files are written (also for an empty campaign,
  which then shows the experiments alone);
- SEM convention: every point, the sheet points too, is drawn and interpolated at its SEM mass
  f x its simulated mass (S1 at 4.10 ug); a results JSON written before ``sem_mass_kg`` and
  ``sem_factor`` existed takes f from the campaign definition it names, and without that the
  case points alone (at their SEM-mapped ``experimental_mass_kg``), without failing.
"""

from __future__ import annotations

import copy
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.container import ErrorbarContainer

from fiberform import campaign as cp
from fiberform import campaign_report as cr

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "scenes" / "thesis"
SHEETS = cp.read_experiments(THESIS / "experiments.csv")
F = 27.1 / 89.25  # SEM: experimental mass per simulated mass (case B = sheet 2)


def _st(mean: float, sd: float, n: int) -> dict[str, float]:
    return {"mean": mean, "sd": sd, "n": float(n)}


#: a hand-made campaign: circular points S1, S2, A, C; rectangular S1 with a permeability only;
#: the pressure press (pressure_* metrics, sheets_pressure) for circular S1, A and C. Thickness:
#: the compared metrics are the thicknesses above the fabric top; the 5-95 % spans (9xx um, never
#: expected in a figure or table) stay in the summary as the runner collects them
DATA: dict[str, Any] = {
    "command": "--collect-only", "seeds": 3, "failures": {}, "sem_factor": F,
    "pressure_press": {"target_pressure_Pa": 410e3, "pressure_rate_Pa_s": None, "hold_time_s": 1e-3,
                       "release_time_s": 1e-3},
    "points": [{"name": "A", "mass_kg": 35.7e-9, "experimental_mass_kg": 35.7e-9 * F, "press_target_m": 2e-6},
               {"name": "C", "mass_kg": 178.5e-9, "experimental_mass_kg": 178.5e-9 * F, "press_target_m": 87.6e-6},
               {"name": "S1", "mass_kg": 13.5e-9, "experimental_mass_kg": 13.5e-9, "press_target_m": 2e-6},
               {"name": "S2", "mass_kg": 27.1e-9, "experimental_mass_kg": 27.1e-9, "press_target_m": 10e-6}],
    "summary": {
        "S1-circular": {"fibers": _st(20, 1, 3), "permeability_cfm": _st(620, 10, 3),
                        "sheet_thickness_above_fabric_m": _st(250e-6, 20e-6, 3),
                        "sheet_thickness_m": _st(999e-6, 1e-6, 3),
                        "permeability_press_cfm": _st(600, 5, 2),
                        "pressed_thickness_above_fabric_m": _st(100e-6, 0, 2),
                        "pressed_span_thickness_m": _st(988e-6, 0, 2),
                        "pressure_permeability_press_cfm": _st(450, 15, 2),
                        "pressure_pressed_thickness_above_fabric_m": _st(60e-6, 4e-6, 2),
                        "pressure_pressed_span_thickness_m": _st(977e-6, 4e-6, 2)},
        "S2-circular": {"fibers": _st(40, 0, 1), "permeability_cfm": _st(510, 0, 1)},
        "A-circular": {"fibers": _st(58, 1, 2), "permeability_cfm": _st(700, 14, 2),
                       "sheet_thickness_above_fabric_m": _st(244.6e-6, 36.8e-6, 2),
                       "sheet_thickness_m": _st(966e-6, 1e-6, 2),
                       "pressure_permeability_press_cfm": _st(680, 6, 2),
                       "pressure_pressed_thickness_above_fabric_m": _st(200e-6, 10e-6, 2),
                       "pressure_pressed_span_thickness_m": _st(955e-6, 10e-6, 2)},
        "C-circular": {"fibers": _st(290, 0, 1), "permeability_cfm": _st(500, 0, 1),
                       "sheet_thickness_above_fabric_m": _st(300e-6, 0, 1), "sheet_thickness_m": _st(944e-6, 0, 1),
                       "pressure_permeability_press_cfm": _st(300, 0, 1),
                       "pressure_pressed_thickness_above_fabric_m": _st(100e-6, 0, 1),
                       "pressure_pressed_span_thickness_m": _st(933e-6, 0, 1)},
        "S1-rectangular": {"permeability_cfm": _st(400, 8, 2)},
    },
    "sheets_unpressed": {
        "circular": [{"sheet": 1, "measured_cfm": 310.0, "measured_thickness_m": 0.0,
                      "direct": {"mean": 620.0, "sd": 10.0, "n": 3.0, "ratio": 2.0},
                      "sem": {"mean": 651.0, "ratio": 2.1,
                              "support": [{"point": "A", "sem_mass_kg": 35.7e-9 * F, "mean": 700.0},
                                          {"point": "C", "sem_mass_kg": 178.5e-9 * F, "mean": 500.0}]}},
                     {"sheet": 2, "measured_cfm": 255.0, "measured_thickness_m": 10e-6,
                      "direct": {"mean": 510.0, "sd": 0.0, "n": 1.0, "ratio": 2.0}, "sem": None},
                     {"sheet": 4, "measured_cfm": 105.0, "measured_thickness_m": 93e-6, "direct": None, "sem": None}],
        "rectangular": [{"sheet": 1, "measured_cfm": 310.0, "measured_thickness_m": 0.0,
                         "direct": {"mean": 400.0, "sd": 8.0, "n": 2.0, "ratio": 400 / 310}, "sem": None}],
    },
    "sheets_pressed": {
        "circular": [{"sheet": 1, "measured_cfm": 310.0, "measured_thickness_m": 0.0,
                      "direct": {"mean": 600.0, "sd": 5.0, "n": 2.0, "ratio": 600 / 310}, "sem": None}],
        "rectangular": [],
    },
    "sheets_pressure": {  # SEM at 13.5 ug: 680 + (300 - 680) x 2.66 / 43.36 = 656.7 CFM
        "circular": [{"sheet": 1, "measured_cfm": 310.0, "measured_thickness_m": 0.0,
                      "direct": {"mean": 450.0, "sd": 15.0, "n": 2.0, "ratio": 450 / 310},
                      "sem": {"mean": 656.69, "ratio": 656.69 / 310}}],
        "rectangular": [],
    },
}


def _table(md: str, title: str) -> dict[str, list[str]]:
    """The rows of the table under ``## title``, by sheet number: the cells after the first."""
    lines = md.splitlines()
    i = lines.index(f"## {title}")
    rows: dict[str, list[str]] = {}
    for line in lines[i + 4:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows[cells[0]] = cells[1:]
    return rows


def test_table_shows_the_json_values_and_dashes() -> None:
    md = cr.markdown(DATA, SHEETS)
    t = _table(md, "circular, unpressed")
    assert list(t) == [str(k) for k in range(1, 8)]
    # mass, measured CFM, direct sim, ratio, SEM sim, ratio, SEM support, measured / direct / SEM
    # thickness; SEM thickness: the sheet point S1 (250 um) is a support point at 4.10 ug, below
    # sheet 1 (13.5 ug): sheet 1 lies between A (10.84 ug) and C (54.2 ug)
    a = (13.5 - 35.7 * F) / (178.5 * F - 35.7 * F)  # sheet 1 between cases A and C
    assert t["1"] == ["13.5", "310", "620.0 +- 10.0 (n=3)", "2.00", "651.0", "2.10", "A 10.84, C 54.20", "0",
                      "250.0 +- 20.0 (n=3)", f"{244.6 + a * (300.0 - 244.6):.1f}"]
    assert t["1"][-1] == "248.0"  # by hand: 244.6 + 2.66 / 43.36 x 55.4
    assert t["2"][:8] == ["27.1", "255", "510.0 +- 0.0 (n=1)", "2.00", "-", "-", "-", "10"]
    assert t["2"][8] == "-"  # S2 has no thickness
    assert t["4"] == ["62.9", "105", "-", "-", "-", "-", "-", "93", "-", "-"]  # beyond case C
    p = _table(md, "circular, pressed to thickness")
    assert p["1"][2:5] == ["600.0 +- 5.0 (n=2)", "1.94", "-"] and p["1"][8] == "100.0 +- 0.0 (n=2)"
    # S1's pressed thickness is the only support point: 4.10 ug, no sheet there
    assert p["3"][2:] == ["-"] * 5 + ["82", "-", "-"]
    # pressed to pressure: S1 450 +- 15 CFM (450 / 310 = 1.45), SEM 656.7 (2.12); thickness 60 um
    # direct, SEM 200 + (100 - 200) x 2.66 / 43.36 = 193.9 um
    q = _table(md, "circular, pressed to pressure")
    assert q["1"] == ["13.5", "310", "450.0 +- 15.0 (n=2)", "1.45", "656.7", "2.12", "-", "0",
                      "60.0 +- 4.0 (n=2)", "193.9"]  # this row's "sem" records no support points
    assert q["2"][2:7] == ["-"] * 5 and q["2"][8] == "-"  # no S2 pressure press
    assert q["2"][9] == "162.5"  # SEM thickness at sheet 2 (27.1 ug): 200 - 100 x 16.26 / 43.36
    assert q["4"][2:] == ["-"] * 5 + ["93", "-", "-"]  # beyond case C
    assert "410 kPa" in md.split("## ")[0]
    r = _table(md, "rectangular, unpressed")
    assert r["1"][2:4] == ["400.0 +- 8.0 (n=2)", "1.29"]
    assert all(r[k][2:6] == ["-"] * 4 for k in "234567")
    for state in ("pressed to thickness", "pressed to pressure"):
        assert all(row[2:6] == ["-"] * 4 for row in _table(md, f"rectangular, {state}").values())


def test_table_through_the_runner_functions() -> None:
    """The JSON as run.py builds it (cp.summarise, cp.sheet_ratios) from collect rows: 600 and
    640 CFM for S1 give 620 +- 28.3 and ratio 2.00; SEM at 13.5 ug between A (700 CFM, 10.84
    ug) and C (500 CFM, 54.2 ug): 700 - 200 x 2.66 / 43.36 = 687.7 CFM, ratio 2.22."""
    c = cp.load_campaign(THESIS / "campaign.yaml")
    pts = cp.points(c, SHEETS)
    s1 = [{"seed": "1", "permeability_cfm": "600"}, {"seed": "2", "permeability_cfm": "640"}]
    # the pressure press of the same sheets (seed for seed): 400 and 420 CFM; A 500, C 300 CFM
    s1, _ = cp.merge_pressure(s1, [{**r, "permeability_press_cfm": x} for r, x in zip(s1, ("400", "420"), strict=True)])
    a, _ = cp.merge_pressure([{"seed": "1", "permeability_cfm": "700"}],
                             [{"seed": "1", "permeability_cfm": "700", "permeability_press_cfm": "500"}])
    cc, _ = cp.merge_pressure([{"seed": "1", "permeability_cfm": "500"}],
                              [{"seed": "1", "permeability_cfm": "500", "permeability_press_cfm": "300"}])
    summary = cp.summarise({"S1-circular": s1, "A-circular": a, "C-circular": cc})
    data = {"points": [{"name": p.name, "mass_kg": p.mass_kg, "experimental_mass_kg": p.experimental_mass_kg,
                        "sem_mass_kg": p.sem_mass_kg} for p in pts], "summary": summary,
            "sheets_unpressed": {"circular": cp.sheet_ratios(SHEETS, pts, summary, "circular")},
            "sheets_pressed": {"circular": cp.sheet_ratios(SHEETS, pts, summary, "circular", "permeability_press_cfm")},
            "sheets_pressure": {"circular": cp.sheet_ratios(SHEETS, pts, summary, "circular",
                                                            "pressure_permeability_press_cfm")}}
    md = cr.markdown(data, SHEETS)
    t = _table(md, "circular, unpressed")
    # S1 is a support point too, at 13.5 x 27.1 / 89.25 = 4.10 ug, below A: not a neighbour of any sheet
    assert t["1"][2:7] == ["620.0 +- 28.3 (n=2)", "2.00", "687.7", "2.22", "A 10.84, C 54.20"]
    assert t["3"][2:7] == ["-", "-", "542.0", "3.10", "A 10.84, C 54.20"]  # 700 - 200 x 34.26 / 43.36; / 175
    assert t["4"][4:7] == ["-", "-", "-"]  # 62.9 ug: beyond case C
    # pressed to pressure: S1 410 +- 14.1 (410 / 310 = 1.32); SEM 500 - 200 x 2.66 / 43.36 = 487.7
    # (/ 310 = 1.57), sheet 3: 500 - 200 x 34.26 / 43.36 = 342.0 (/ 175 = 1.95)
    q = _table(md, "circular, pressed to pressure")
    assert q["1"][2:6] == ["410.0 +- 14.1 (n=2)", "1.32", "487.7", "1.57"]
    assert q["3"][2:6] == ["-", "-", "342.0", "1.95"]
    assert all(row[2:6] == ["-"] * 4 for row in _table(md, "circular, pressed to thickness").values())


def _container(ax: Any, label: str) -> ErrorbarContainer:
    (c,) = [c for c in ax.containers if isinstance(c, ErrorbarContainer) and c.get_label() == label]
    return c


def _drawn(c: ErrorbarContainer) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """x, y and the half-lengths of the x and y error bars as drawn."""
    xy = np.asarray(c.lines[0].get_xydata())
    bars = list(c.lines[2])
    yerr = xerr = None
    if c.has_yerr:  # matplotlib draws the x bars first, then the y bars
        seg = np.array(bars.pop().get_segments())
        assert np.allclose(seg[:, 0, 0], seg[:, 1, 0])
        yerr = (seg[:, 1, 1] - seg[:, 0, 1]) / 2
        assert np.allclose((seg[:, 1, 1] + seg[:, 0, 1]) / 2, xy[:, 1])
    if c.has_xerr:
        seg = np.array(bars.pop().get_segments())
        xerr = (seg[:, 1, 0] - seg[:, 0, 0]) / 2
    return xy[:, 0], xy[:, 1], xerr, yerr


def test_permeability_figure_plots_the_hand_values() -> None:
    fig, drawn = cr.figure(DATA, SHEETS, "permeability")
    axes = fig.axes  # rows: direct, SEM; columns: mass, fibers
    # direct, mass: the experiments at their scaled masses; S1, S2 at theirs, error bars = sd
    exp = drawn[("direct", "mass")][0]
    assert exp.label == "experiment (Table 4.1)" and exp.yerr is None
    assert exp.x.tolist() == pytest.approx([13.5, 27.1, 45.1, 62.9, 90.0, 134.7, 179.4])
    assert exp.y.tolist() == [310, 255, 175, 105, 58, 17, 5]
    x, y, xerr, yerr = _drawn(_container(axes[0], "circular, unpressed"))
    assert x.tolist() == pytest.approx([13.5, 27.1]) and y.tolist() == [620, 510]
    assert xerr is None and yerr is not None and yerr.tolist() == pytest.approx([10, 0])
    x, y, _, yerr = _drawn(_container(axes[0], "circular, pressed to thickness"))
    assert (x.tolist(), y.tolist(), yerr.tolist()) == (pytest.approx([13.5]), [600], pytest.approx([5]))  # type: ignore[union-attr]
    c = _container(axes[0], "circular, pressed to pressure")
    x, y, _, yerr = _drawn(c)
    assert (x.tolist(), y.tolist(), yerr.tolist()) == (pytest.approx([13.5]), [450], pytest.approx([15]))  # type: ignore[union-attr]
    assert (c.lines[0].get_marker(), c.lines[0].get_linestyle()) == ("D", "-.")
    x, y, _, yerr = _drawn(_container(axes[0], "rectangular, unpressed"))
    assert (x.tolist(), y.tolist(), yerr.tolist()) == (pytest.approx([13.5]), [400], pytest.approx([8]))  # type: ignore[union-attr]
    assert {s.label for s in drawn[("direct", "mass")]} == {
        "experiment (Table 4.1)", "circular, unpressed", "circular, pressed to thickness",
        "circular, pressed to pressure", "rectangular, unpressed"}
    assert "pressed to pressure: 410 kPa" in fig.texts[0].get_text()  # the suptitle
    # SEM, mass: every point at f x its mass: S1 13.5 x 27.1 / 89.25 = 4.099, S2 27.1 x 27.1 / 89.25
    # = 8.229, cases A, C at 10.84, 54.2 ug
    x, y, _, yerr = _drawn(_container(axes[2], "circular, unpressed"))
    assert x.tolist() == pytest.approx([4.0992, 8.2288, 10.84, 54.2], rel=1e-4) and y.tolist() == [620, 510, 700, 500]
    assert yerr.tolist() == pytest.approx([10, 0, 14, 0])  # type: ignore[union-attr]
    x, y, _, yerr = _drawn(_container(axes[2], "circular, pressed to pressure"))
    assert x.tolist() == pytest.approx([4.0992, 10.84, 54.2], rel=1e-4) and y.tolist() == [450, 680, 300]
    assert yerr.tolist() == pytest.approx([15, 6, 0])  # type: ignore[union-attr]
    x, y, _, _ = _drawn(_container(axes[2], "rectangular, unpressed"))
    assert x.tolist() == pytest.approx([4.0992], rel=1e-4) and y.tolist() == [400]
    # the panel says that the sheet points are SEM support points at f x their mass
    assert "sheet points S1-S7: SEM support at f x their mass" in axes[2].get_title()
    assert "f = 0.3036" in axes[2].get_title()
    assert [t.get_text() for t in axes[2].texts if t.get_color() == "tab:blue"] == ["S1", "S2", "A", "C"]
    # direct, fibers: S1, S2 at their fiber counts (x error bars = sd); the sheets at the same counts
    x, y, xerr, yerr = _drawn(_container(axes[1], "circular, unpressed"))
    assert x.tolist() == [20, 40] and xerr.tolist() == pytest.approx([1, 0]) and yerr.tolist() == pytest.approx([10, 0])  # type: ignore[union-attr]
    x, y, _, _ = _drawn(_container(axes[1], "experiment at the circular fiber count"))
    assert x.tolist() == [20, 40] and y.tolist() == [310, 255]
    # rectangular S1 has no fiber count: absent from the fiber panels
    assert not any(s.section == "rectangular" for s in drawn[("direct", "fibers")])
    # SEM, fibers: the sheets within A..C at the cases' fiber counts interpolated at their masses
    sem_exp = next(s for s in drawn[("sem", "fibers")] if s.label == "experiment at the circular fiber count")
    assert sem_exp.names == ("1", "2", "3")
    assert sem_exp.x.tolist() == pytest.approx([58 + 232 * 2.66 / 43.36, 58 + 232 * 16.26 / 43.36,
                                                58 + 232 * 34.26 / 43.36], rel=1e-4)
    assert sem_exp.y.tolist() == [310, 255, 175]


def test_every_panel_starts_at_zero() -> None:
    """Both quantities are >= 0; each panel shows them from zero (a panel of a few close points,
    e.g. the SEM fiber-count panel of one case point, would otherwise autoscale a spread of a few
    CFM to the whole panel height)."""
    for q in cr.QUANTITIES:
        fig, drawn = cr.figure(DATA, SHEETS, q)
        for ax, key in zip(fig.axes, [(c, a) for c in cr.CONVENTIONS for a in cr.AXES]):
            if drawn[key]:
                lo, hi = ax.get_ylim()
                top = max(float(np.max(s.y)) for s in drawn[key])
                assert lo == 0.0 and hi >= top, (q, key, lo, hi)


def test_thickness_figure_in_um() -> None:
    fig, drawn = cr.figure(DATA, SHEETS, "thickness")
    exp = drawn[("direct", "mass")][0]
    assert exp.y.tolist() == pytest.approx([0, 10, 82, 93, 97, 141, 149])
    x, y, _, yerr = _drawn(_container(fig.axes[0], "circular, unpressed"))
    assert x.tolist() == pytest.approx([13.5]) and y.tolist() == pytest.approx([250]) and yerr.tolist() == pytest.approx([20])  # type: ignore[union-attr]
    x, y, _, yerr = _drawn(_container(fig.axes[2], "circular, unpressed"))  # S1 at 4.10 ug, A, C
    assert y.tolist() == pytest.approx([250, 244.6, 300]) and yerr.tolist() == pytest.approx([20, 36.8, 0])  # type: ignore[union-attr]
    x, y, _, yerr = _drawn(_container(fig.axes[0], "circular, pressed to pressure"))
    assert y.tolist() == pytest.approx([60]) and yerr.tolist() == pytest.approx([4])  # type: ignore[union-attr]
    x, y, _, yerr = _drawn(_container(fig.axes[2], "circular, pressed to pressure"))
    assert y.tolist() == pytest.approx([60, 200, 100]) and yerr.tolist() == pytest.approx([4, 10, 0])  # type: ignore[union-attr]
    assert not any(s.section == "rectangular" for s in drawn[("direct", "mass")])
    # what the simulated thickness is: the axis label and the title say it
    assert fig.axes[0].get_ylabel() == "thickness above the fabric top (um)"
    assert "95th percentile of the fibers' upper surfaces" in fig.texts[0].get_text()
    assert "thickness above fabric (um)" in cr.markdown(DATA, SHEETS)


def test_empty_campaign_gives_the_experiments_alone(tmp_path: Path) -> None:
    for data in ({}, {**copy.deepcopy(DATA), "summary": {}, "sheets_unpressed": {}, "sheets_pressed": {},
                      "sheets_pressure": {}}):
        for q in cr.QUANTITIES:
            fig, drawn = cr.figure(data, SHEETS, q)
            assert [s.label for s in drawn[("direct", "mass")]] == ["experiment (Table 4.1)"]
            assert [s.label for s in drawn[("sem", "mass")]] == ["experiment (Table 4.1)"]
            assert drawn[("direct", "fibers")] == [] == drawn[("sem", "fibers")]
        md = cr.markdown(data, SHEETS)
        for title in ("circular, unpressed", "rectangular, pressed to thickness", "circular, pressed to pressure"):
            t = _table(md, title)
            assert t["5"] == ["90.0", "58", "-", "-", "-", "-", "-", "97", "-", "-"]
    written = cr.write_report({}, SHEETS, tmp_path / "campaign.json")
    assert [p.name for p in written] == ["campaign-fig412-thickness.png", "campaign-fig413-permeability.png",
                                         "campaign.md"]


def test_write_report_writes_the_files(tmp_path: Path) -> None:
    out = tmp_path / "results" / "campaign-reduced.json"
    out.parent.mkdir()
    written = cr.write_report(DATA, SHEETS, out)
    png = [p for p in written if p.suffix == ".png"]
    assert len(png) == 2
    for p in png:
        head = p.read_bytes()[:8]
        assert head == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 10_000
    assert (out.with_suffix(".md")).read_text() == cr.markdown(DATA, SHEETS)
    assert sorted(p.name for p in out.parent.iterdir()) == sorted(p.name for p in written)  # no temporaries left


def test_old_results_json_without_sem_masses(tmp_path: Path) -> None:
    """A results JSON written before ``sem_mass_kg`` and ``sem_factor`` (bench/thesis/results of
    sessions 9-22): the SEM masses are mass_kg x f with f of the campaign definition the file
    names; without a readable one the case points alone, at their SEM-mapped
    ``experimental_mass_kg`` (as before); the figures and tables are made either way."""
    old = copy.deepcopy(DATA)
    del old["sem_factor"]
    # a campaign definition with another mapping (case C = sheet 3): f = 45.1 / (5 x 35.7)
    camp = tmp_path / "camp"
    camp.mkdir()
    (camp / "campaign.yaml").write_text((THESIS / "campaign.yaml").read_text().replace(
        "sem_mapping: {case: B, sheet: 2}", "sem_mapping: {case: C, sheet: 3}"))
    shutil.copy(THESIS / "experiments.csv", camp / "experiments.csv")
    f = 45.1 / (5 * 35.7)
    (tmp_path / "old").mkdir()
    old["campaign"] = str(camp / "campaign.yaml")
    assert cr.sem_factor_of(old) == pytest.approx(f, rel=1e-12)
    _, drawn = cr.figure(old, SHEETS, "permeability")
    sem = next(s for s in drawn[("sem", "mass")] if s.label == "circular, unpressed")
    assert sem.names == ("S1", "S2", "A", "C")
    assert sem.x.tolist() == pytest.approx([13.5 * f, 27.1 * f, 35.7 * f, 178.5 * f], rel=1e-9)
    # the file's own sem_factor wins over the campaign definition
    assert cr.sem_factor_of({**old, "sem_factor": 0.5}) == 0.5
    # no campaign definition to read: the case points alone, at experimental_mass_kg
    for gone in ({**old, "campaign": str(tmp_path / "missing.yaml")}, {k: v for k, v in old.items() if k != "campaign"}):
        assert cr.sem_factor_of(gone) is None
        _, drawn = cr.figure(gone, SHEETS, "permeability")
        sem = next(s for s in drawn[("sem", "mass")] if s.label == "circular, unpressed")
        assert sem.names == ("A", "C") and sem.x.tolist() == pytest.approx([35.7 * F, 178.5 * F], rel=1e-9)
        written = cr.write_report(gone, SHEETS, tmp_path / "old" / "campaign.json")
        assert all(p.is_file() for p in written)
