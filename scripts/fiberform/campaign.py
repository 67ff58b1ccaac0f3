# SPDX-License-Identifier: GPL-3.0-or-later
"""The validation campaign of issue 15 (scenes/thesis/campaign.yaml, docs/validation/table41.md).

The thesis (Kettil 2016, sec. 4.2) compares simulated sheets with seven experimental sheets
(Table 4.1, ``scenes/thesis/experiments.csv``). This module reads the campaign definition and the
experiments, derives one scene per point (a thesis case by its mass factor, or an experimental
sheet by its scaled mass) and cross-section from the shipped case scenes, with the press stage
set to the experimental thickness, and turns the sweeps' ``collect.csv`` tables into per-point
statistics and per-sheet ratios in the two mass conventions:

* direct: an experimental sheet's scaled mass is laid down as it is (no re-matching);
* SEM (the thesis' sec. 5.1): simulated case B equals sheet 2, other masses linearly, i.e.
  experimental scaled mass = simulated mass x (sheet 2's mass / case B's mass).

``bench/thesis/run.py`` drives it (``fiberform sweep`` per point and section).
"""

from __future__ import annotations

import csv
import json
import math
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from .errors import ConfigError
from .scene import parse_scene, read_scene_yaml

__all__ = ["Campaign", "Point", "Sheet", "load_campaign", "points", "point_scene", "read_experiments",
           "sem_interp", "summarise", "sheet_ratios", "use_fiber_contact"]

Section = Literal["circular", "rectangular"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class CampaignPress(_Strict):
    plate_speed_m_s: float = Field(gt=0.0, le=10.0)
    min_target_m: float = Field(gt=0.0, le=1e-3)
    hold_time_s: float = Field(ge=0.0, le=10.0)
    output_interval_s: float = Field(gt=0.0, le=1.0)
    overlap_limit: float = Field(gt=0.0, le=1.0)


class Reduced(_Strict):
    points: list[str] = Field(min_length=1)
    seeds: int = Field(ge=1, le=100)


class SemMapping(_Strict):
    case: str
    sheet: int = Field(ge=1)


class Campaign(_Strict):
    """scenes/thesis/campaign.yaml (comments there)."""

    format_version: Literal[1]
    base: dict[Section, str]
    sections: list[Section] = Field(min_length=1)
    M_A_kg: float = Field(gt=0.0, le=1e-3)
    seeds: int = Field(ge=1, le=100)
    slab_per_M_A_m: dict[Section, float]
    flow_margin_m: float = Field(gt=0.0, le=1e-1)
    cases: dict[str, float]
    sheets: list[int]
    sem_mapping: SemMapping
    fiber_contact: Literal["averaged", "newton"] | None = None
    press: CampaignPress
    reduced: Reduced

    @field_validator("cases")
    @classmethod
    def _cases(cls, v: dict[str, float]) -> dict[str, float]:
        for name, k in v.items():
            if not (name.isalnum() and name.isupper() and len(name) == 1):
                raise ValueError(f"case name {name!r}: one capital letter")
            if not 0.0 < k <= 1000.0:
                raise ValueError(f"case {name}: mass factor {k} outside (0, 1000]")
        return v


@dataclass(frozen=True)
class Sheet:
    """One experimental sheet of Table 4.1."""

    sheet: int
    injection_mass_g: float
    permeability_cfm: float
    thickness_m: float
    scaled_mass_kg: float


@dataclass(frozen=True)
class Point:
    """One simulated mass: a thesis case (``A``) or an experimental sheet (``S3``)."""

    name: str
    mass_kg: float
    #: the experimental scaled mass this point stands for (direct: its own; cases: SEM-mapped)
    experimental_mass_kg: float
    #: the press target: the experimental thickness at that mass (at least press.min_target_m)
    press_target_m: float


def load_campaign(path: Path) -> Campaign:
    try:
        data = read_scene_yaml(path.read_text())
        return Campaign.model_validate(data)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: {exc}") from None


def read_experiments(path: Path) -> list[Sheet]:
    """experiments.csv (comment lines start with #)."""
    rows = [line for line in path.read_text().splitlines() if line and not line.startswith("#")]
    out = []
    for r in csv.DictReader(rows):
        out.append(Sheet(int(r["sheet"]), float(r["injection_mass_g"]), float(r["permeability_cfm"]),
                         float(r["thickness_um"]) * 1e-6, float(r["scaled_injection_mass_ug"]) * 1e-9))
    return out


def sem_factor(c: Campaign, sheets: list[Sheet]) -> float:
    """Experimental scaled mass per simulated mass in the thesis' SEM mapping (27.1 / 89.25)."""
    by = {s.sheet: s for s in sheets}
    if c.sem_mapping.case not in c.cases or c.sem_mapping.sheet not in by:
        raise ConfigError(f"sem_mapping {c.sem_mapping}: unknown case or sheet")
    return by[c.sem_mapping.sheet].scaled_mass_kg / (c.cases[c.sem_mapping.case] * c.M_A_kg)


def experimental_thickness(sheets: list[Sheet], mass_kg: float) -> float:
    """Measured thickness at an experimental scaled mass: linear between the sheets, the end values
    beyond them."""
    m = np.array([s.scaled_mass_kg for s in sheets])
    t = np.array([s.thickness_m for s in sheets])
    order = np.argsort(m)
    return float(np.interp(mass_kg, m[order], t[order]))


def points(c: Campaign, sheets: list[Sheet]) -> list[Point]:
    """The cases (SEM-mapped press targets) then the sheets (their own thickness)."""
    f = sem_factor(c, sheets)
    by = {s.sheet: s for s in sheets}
    out = []
    for name, k in c.cases.items():
        m = k * c.M_A_kg
        out.append(Point(name, m, m * f, max(c.press.min_target_m, experimental_thickness(sheets, m * f))))
    for n in c.sheets:
        if n not in by:
            raise ConfigError(f"sheets: sheet {n} is not in experiments.csv")
        s = by[n]
        out.append(Point(f"S{n}", s.scaled_mass_kg, s.scaled_mass_kg, max(c.press.min_target_m, s.thickness_m)))
    return out


def use_fiber_contact(data: dict[str, Any], mode: str) -> None:
    """Set ``laydown.fiber_contact`` of plain scene data; with ``newton`` the contact section's
    sub-integrator goes (it belongs to the averaged contact; the scene refuses it otherwise)."""
    data["laydown"]["fiber_contact"] = mode
    if mode == "newton" and isinstance(data.get("contact"), dict):
        data["contact"].pop("integrator", None)


def point_scene(c: Campaign, point: Point, section: Section, thesis_dir: Path, out_root: Path) -> dict[str, Any]:
    """The scene of ``point`` with ``section``: the case-A scene of the section with the mass, the
    placement slab and the flow box scaled (as the shipped case scenes scale them), output under
    ``out_root`` and the campaign's press section. Validated (SceneError names the problem)."""
    data: dict[str, Any] = read_scene_yaml((thesis_dir / c.base[section]).read_text())
    k = point.mass_kg / c.M_A_kg
    slab = c.slab_per_M_A_m[section] * k
    name = f"{point.name}-{section}"
    data["name"] = f"campaign_{point.name}_{section}"
    data["output_dir"] = str(out_root / name)
    data["fibers"]["target_mass_kg"] = float(f"{point.mass_kg:.6e}")
    gen = data["fiber_generation"]
    gen["placement_hi_m"][2] = float(f"{gen['placement_lo_m'][2] + slab:.6e}")
    data["flow"]["height_above_fabric_m"] = float(f"{slab + c.flow_margin_m:.6e}")
    if c.fiber_contact is not None and c.fiber_contact != data["laydown"].get("fiber_contact"):
        use_fiber_contact(data, c.fiber_contact)
    p = c.press
    data["press"] = {"mode": "velocity", "target_thickness_m": float(f"{point.press_target_m:.6e}"),
                     "plate_speed_m_s": p.plate_speed_m_s, "hold_time_s": p.hold_time_s,
                     "output_interval_s": p.output_interval_s, "overlap_limit": p.overlap_limit,
                     "overlap_action": "stop", "ranks": data["laydown"].get("ranks", 1)}
    parse_scene(data, f"campaign point {name}")
    return data


# -- results ---------------------------------------------------------------------------------------

#: the collect.csv columns the campaign reports (SI units in the names)
METRICS = ("fibers", "fiber_mass_kg", "settled", "laydown_simulated_time_s", "sheet_thickness_m",
           "grammage_kg_m2", "permeability_cfm", "press_plate_gap_m", "press_stopped_by_guard",
           "pressed_span_thickness_m", "permeability_press_cfm", "laydown_wall_s", "press_wall_s",
           "permeability_wall_s", "permeability_press_wall_s")


def _number(v: str) -> float | None:
    try:
        x = float(v)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def summarise(collected: dict[str, list[dict[str, str]]]) -> dict[str, dict[str, dict[str, float]]]:
    """{variant group (``A-circular``): collect.csv rows} -> {group: {metric: {mean, sd, n}}} over
    the seeds that finished the metric (sd 0 for one seed)."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for group, rows in collected.items():
        stats: dict[str, dict[str, float]] = {}
        for m in METRICS:
            vals = [x for r in rows if (x := _number(r.get(m, ""))) is not None]
            if vals:
                stats[m] = {"mean": statistics.fmean(vals), "sd": statistics.stdev(vals) if len(vals) > 1 else 0.0,
                            "n": float(len(vals))}
        out[group] = stats
    return out


def sem_interp(cases: list[tuple[float, float]], mass_kg: float) -> float | None:
    """The SEM convention's value at an experimental scaled mass: ``cases`` (experimental mass,
    value), sorted by mass, interpolated linearly; None without cases or outside their mass range
    (ends widened by 1e-6 relative: a case at the sheet's own mass counts, also when it is the
    only one)."""
    if not cases or not cases[0][0] * (1 - 1e-6) <= mass_kg <= cases[-1][0] * (1 + 1e-6):
        return None
    return float(np.interp(mass_kg, [m for m, _ in cases], [x for _, x in cases]))


def sheet_ratios(c: Campaign, sheets: list[Sheet], pts: list[Point],
                 summary: dict[str, dict[str, dict[str, float]]], section: Section,
                 metric: str = "permeability_cfm") -> list[dict[str, Any]]:
    """Per experimental sheet: the simulated ``metric`` (mean, sd) and simulated / measured
    permeability in both conventions. direct: the sheet's own point; SEM: the case points'
    means interpolated linearly in experimental mass (None outside the cases' range or where no
    case has finished)."""
    by_point = {p.name: p for p in pts}
    cases = sorted((by_point[n].experimental_mass_kg, summary[f"{n}-{section}"][metric]["mean"])
                   for n in c.cases if metric in summary.get(f"{n}-{section}", {}))
    out = []
    for s in sheets:
        row: dict[str, Any] = {"sheet": s.sheet, "measured_cfm": s.permeability_cfm,
                               "measured_thickness_m": s.thickness_m}
        d = summary.get(f"S{s.sheet}-{section}", {}).get(metric)
        row["direct"] = None if d is None else {"mean": d["mean"], "sd": d["sd"], "n": d["n"],
                                                "ratio": d["mean"] / s.permeability_cfm}
        v = sem_interp(cases, s.scaled_mass_kg)
        row["sem"] = None if v is None else {"mean": v, "ratio": v / s.permeability_cfm}
        out.append(row)
    return out


def write_json(path: Path, data: dict[str, Any]) -> None:
    from .provenance import atomic_write_text

    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(data, indent=2, default=float) + "\n")
