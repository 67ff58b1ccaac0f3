# SPDX-License-Identifier: GPL-3.0-or-later
"""The validation campaign of issue 15 (scenes/thesis/campaign.yaml, docs/validation/table41.md).

The thesis (Kettil 2016, sec. 4.2) compares simulated sheets with seven experimental sheets
(Table 4.1, ``scenes/thesis/experiments.csv``). This module reads the campaign definition and the
experiments, derives one scene per point (a thesis case by its mass factor, or an experimental
sheet by its scaled mass) and cross-section from the shipped case scenes, with the press stage
set to the experimental thickness, and turns the sweeps' ``collect.csv`` tables into per-point
statistics and per-sheet ratios in the two mass conventions.

The second press (``pressure_press`` of campaign.yaml): every laid-down sheet is also pressed in
pressure mode. Its scene (:func:`pressure_scene`) equals the point's scene except in ``press``
(and name and output folder); its sweep (``<point output>-pressure-sweep``) has one variant per
seed like the point's own sweep, and :func:`run_pressure_sweep` copies each seed's finished
generate, fabric, flow, lay-down and unpressed-permeability folders from the point's variant into
it (:func:`fiberform.reuse.adopt_stages`, only where the stages' hash checks then skip them) before
running or submitting the press and the pressed permeability. A seed whose upstream stages are not
all adopted is not run: no sheet is laid down twice. Its metrics join the point's rows with the
prefix ``pressure_`` (:func:`merge_pressure`).

The two mass conventions:

* direct: an experimental sheet's scaled mass is laid down as it is (no re-matching): sheet k is
  compared with point Sk;
* SEM (the thesis' sec. 5.1): simulated case B equals sheet 2, other masses linearly, i.e.
  experimental scaled mass = simulated mass x f, f = sheet 2's mass / case B's mass
  (:func:`sem_factor`, 27.1 / 89.25 = 0.3036). Every simulated point, case or sheet, stands in
  this convention for the experimental mass f x its own mass (:attr:`Point.sem_mass_kg`: case A
  10.84 ug, S1 4.10 ug, S2 8.23 ug, S3 13.69 ug), and sheet k's SEM value is the linear
  interpolation of all points with a finished result at those masses, evaluated at sheet k's
  scaled mass (:func:`sem_support`, :func:`sem_value`; none outside the points' range). A sheet
  point thus serves twice: directly for its own sheet, and as an SEM support point at f x its
  mass (S3 at 13.69 ug, next to sheet 1's 13.5 ug).

``bench/thesis/run.py`` drives it (``fiberform sweep`` per point and section).
"""

from __future__ import annotations

import bisect
import csv
import json
import math
import statistics
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from .errors import ConfigError
from .scene import parse_scene, read_scene_yaml

if TYPE_CHECKING:
    from .executors import BatchOptions
    from .sweep import Variant

__all__ = ["Campaign", "CampaignPermeability", "CampaignSolver", "Kept", "Point", "PressureSweep", "SemPoint", "Sheet", "kept_results", "load_campaign",
           "merge_pressure", "points", "point_scene", "pressure_scene", "read_experiments", "row_sem_mass",
           "run_pressure_sweep", "sem_factor", "sem_interp", "sem_support", "sem_value", "summarise", "sheet_ratios",
           "use_fiber_contact"]

Section = Literal["circular", "rectangular"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class CampaignPress(_Strict):
    plate_speed_m_s: float = Field(gt=0.0, le=10.0)
    min_target_m: float = Field(gt=0.0, le=1e-3)
    hold_time_s: float = Field(ge=0.0, le=10.0)
    output_interval_s: float = Field(gt=0.0, le=1.0)
    overlap_limit: float = Field(gt=0.0, le=1.0)
    #: press.steric_cap_m of both presses (absent: the law's 2 nm)
    steric_cap_m: float | None = Field(default=None, ge=1e-9, le=1e-4)


class CampaignPressurePress(_Strict):
    """The second press of every laid-down sheet: pressure mode (docs/stages/press.md); plate
    speed (the servo's speed limit), output interval and overlap guard (limit, action stop) as
    in ``press``."""

    target_pressure_Pa: float = Field(gt=0.0, le=1e9)
    pressure_rate_Pa_s: float | None = Field(default=None, gt=0.0, le=1e15)
    hold_time_s: float = Field(ge=0.0, le=10.0)
    release_time_s: float = Field(ge=0.0, le=10.0)


class CampaignSolver(_Strict):
    """Numerical settings of the lay-down's implicit Newton solve that the campaign sets in every
    point scene (``laydown.newton_tolerance``, ``laydown.anderson_depth``; absent: the case
    scene's). Not physics: the tolerance of the converged step and an accelerator of its
    iterations (docs/validation/table41.md "Solver settings"). Bounds as the scene's fields."""

    newton_tolerance: float | None = Field(default=None, gt=0.0, le=1e-2)
    anderson_depth: int | None = Field(default=None, ge=0, le=8)


class CampaignPermeability(_Strict):
    """Convergence of the permeability solves that the campaign sets in every point scene
    (``permeability.convergence_tolerance``; absent: the case scene's). Not physics: when the
    outflow window counts as converged (docs/validation/table41.md "Permeability convergence").
    Bounds as the scene's field."""

    convergence_tolerance: float | None = Field(default=None, gt=0.0, le=0.5)


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
    solver: CampaignSolver | None = None
    permeability: CampaignPermeability | None = None
    press: CampaignPress
    pressure_press: CampaignPressurePress | None = None
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
    #: the experimental scaled mass whose thickness the press targets (sheets: their own, direct;
    #: cases: SEM-mapped, the same as ``sem_mass_kg``)
    experimental_mass_kg: float
    #: the press target: the experimental thickness at that mass (at least press.min_target_m)
    press_target_m: float
    #: the experimental scaled mass this simulation stands for in the SEM convention: mass_kg x
    #: :func:`sem_factor`, for every point (S3, 45.1 ug simulated: 13.69 ug)
    sem_mass_kg: float


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
    """The cases (SEM-mapped press targets) then the sheets (their own thickness); every point's
    SEM mass is its mass x :func:`sem_factor`."""
    f = sem_factor(c, sheets)
    by = {s.sheet: s for s in sheets}
    out = []
    for name, k in c.cases.items():
        m = k * c.M_A_kg
        out.append(Point(name, m, m * f, max(c.press.min_target_m, experimental_thickness(sheets, m * f)),
                         sem_mass_kg=m * f))
    for n in c.sheets:
        if n not in by:
            raise ConfigError(f"sheets: sheet {n} is not in experiments.csv")
        s = by[n]
        out.append(Point(f"S{n}", s.scaled_mass_kg, s.scaled_mass_kg, max(c.press.min_target_m, s.thickness_m),
                         sem_mass_kg=s.scaled_mass_kg * f))
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
    ``out_root``, the campaign's fiber contact, solver and permeability settings and its press
    section. Validated (SceneError names the problem)."""
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
    if c.solver is not None:
        data["laydown"].update(c.solver.model_dump(exclude_none=True))
    if c.permeability is not None:
        data["permeability"].update(c.permeability.model_dump(exclude_none=True))
    p = c.press
    data["press"] = {"mode": "velocity", "target_thickness_m": float(f"{point.press_target_m:.6e}"),
                     "plate_speed_m_s": p.plate_speed_m_s, "hold_time_s": p.hold_time_s,
                     "output_interval_s": p.output_interval_s, "overlap_limit": p.overlap_limit,
                     "overlap_action": "stop", "ranks": data["laydown"].get("ranks", 1)}
    if p.steric_cap_m is not None:
        data["press"]["steric_cap_m"] = p.steric_cap_m
    parse_scene(data, f"campaign point {name}")
    return data


def pressure_scene(c: Campaign, point: dict[str, Any]) -> dict[str, Any]:
    """The scene of a point's second press, from the point's scene data (:func:`point_scene`):
    the same in every section but ``press`` (pressure mode at ``pressure_press``; plate speed,
    output interval, overlap guard (stop) and steric cap of ``press``; the same ranks), with ``_pressure``
    added to the name and ``-pressure`` to the output folder. Validated (SceneError); ConfigError
    when the campaign has no ``pressure_press``."""
    pp = c.pressure_press
    if pp is None:
        raise ConfigError("pressure_press: not in the campaign (the second press is off)")
    data: dict[str, Any] = json.loads(json.dumps(point))  # a deep copy of plain YAML data
    data["name"] = f"{point['name']}_pressure"
    data["output_dir"] = f"{point['output_dir']}-pressure"
    press: dict[str, Any] = {"mode": "pressure", "target_pressure_Pa": pp.target_pressure_Pa}
    if pp.pressure_rate_Pa_s is not None:
        press["pressure_rate_Pa_s"] = pp.pressure_rate_Pa_s
    press.update(hold_time_s=pp.hold_time_s, release_time_s=pp.release_time_s,
                 plate_speed_m_s=c.press.plate_speed_m_s, output_interval_s=c.press.output_interval_s,
                 overlap_limit=c.press.overlap_limit, overlap_action="stop", ranks=point["press"]["ranks"])
    if c.press.steric_cap_m is not None:
        press["steric_cap_m"] = c.press.steric_cap_m
    data["press"] = press
    parse_scene(data, f"campaign pressure press {data['name']}")
    return data


#: the stages a pressure-press variant takes over from the point's variant of the same seed
REUSED_STAGES = ("generate", "fabric", "flow", "laydown", "permeability")


@dataclass
class PressureSweep:
    """What :func:`run_pressure_sweep` did: the sweep folder, the variants run (or submitted),
    those not started because their point variant has not finished the reused stages (variant
    -> why), and those that failed."""

    sweep_dir: Path
    started: list[str]
    waiting: dict[str, str]
    failed: list[str]
    submitted: bool = False


def run_pressure_sweep(point_path: Path, pressure_path: Path, seeds: int, build_dir: Path,
                       echo: Callable[[str], None], submit: BatchOptions | None = None,
                       jobs: int = 1, resume: bool = False) -> PressureSweep:
    """The second press of every seed of a point: the sweep of ``pressure_path`` (scene files and
    sweep.json as ``fiberform sweep PRESSURE --seeds N``), each variant's :data:`REUSED_STAGES`
    adopted from the variant of ``fiberform sweep POINT --seeds N`` with the same seed
    (:func:`fiberform.reuse.adopt_stages`: copied only where the stage then counts as up to date).
    Only variants whose reused stages are all up to date are started, and only from the press on
    (press, permeability-press), so no lay-down runs here. ``submit``: the press and pressed
    permeability as job arrays (:func:`fiberform.sweep.submit_sweep`), only once every variant
    is ready (a job array covers all variants). A second call skips what has finished. ``resume``:
    as ``fiberform sweep --resume`` (passed to :func:`~fiberform.sweep.run_sweep` and
    :func:`~fiberform.sweep.submit_sweep`; the stages run here lay nothing down, so it only keeps
    the two sweeps of a point alike)."""
    from .reuse import adopt_stages
    from .stages import StageContext
    from .sweep import expand, run_sweep, submit_sweep, variant_path, write_sweep

    _, point_variants = expand(point_path, [], seeds)
    sweep_dir, variants = expand(pressure_path, [], seeds)
    donors = {v.seed: Path(v.data["output_dir"]) for v in point_variants}
    write_sweep(pressure_path, sweep_dir, variants, [])  # the stages hash files beside the variant scenes
    ready: list[Variant] = []
    waiting: dict[str, str] = {}
    for v in variants:
        ctx = StageContext(scene=parse_scene(v.data, v.name), scene_path=variant_path(sweep_dir, v),
                           build_dir=build_dir)
        done = adopt_stages(ctx, donors[v.seed], REUSED_STAGES)
        echo(f"{v.name} (seed {v.seed}) from {donors[v.seed]}: "
             + ", ".join(f"{a.stage} {a.action}" for a in done))
        missing = [a for a in done if not a.up_to_date]
        if missing:
            waiting[v.name] = "; ".join(f"{a.stage} {a.action}" + (f" ({a.detail})" if a.detail else "")
                                        for a in missing)
        else:
            ready.append(v)
    out = PressureSweep(sweep_dir, [], waiting, [])
    if submit is not None:
        if waiting:
            echo(f"{sweep_dir}: not submitted: {len(waiting)} of {len(variants)} seed(s) wait for their point "
                 "variant's lay-down and permeability (not laid down again here); run again once those are done")
            return out
        submit_sweep(submit, pressure_path, sweep_dir, variants, [], build_dir, "press", None, dry_run=False,
                     echo=echo, resume=resume)
        out.started, out.submitted = [v.name for v in variants], True
        return out
    out.failed = run_sweep([variant_path(sweep_dir, v) for v in ready], build_dir, "press", None, echo,
                           jobs=jobs, resume=resume)
    out.started = [v.name for v in ready]
    return out


# -- results ---------------------------------------------------------------------------------------

#: the collect.csv columns of the press and the pressed permeability (prefix ``pressure_`` for
#: the second press, :func:`merge_pressure`); thicknesses: the pressed sheet's above the fabric
#: top (compared with the experiments, fiber_sheet.thickness_above_fabric) and its 5-95 % span
PRESS_METRICS = ("press_plate_gap_m", "press_max_pressure_Pa", "press_stopped_by_guard",
                 "pressed_span_thickness_m", "pressed_thickness_above_fabric_m", "permeability_press_cfm",
                 "press_wall_s", "permeability-press_wall_s")
#: the collect.csv columns the campaign reports (SI units in the names)
METRICS = ("fibers", "fiber_mass_kg", "settled", "laydown_simulated_time_s", "sheet_thickness_m",
           "sheet_thickness_above_fabric_m", "grammage_kg_m2", "permeability_cfm", *PRESS_METRICS,
           "laydown_wall_s", "permeability_wall_s", *(f"pressure_{m}" for m in PRESS_METRICS))
#: columns of the stages after the lay-down that a pressure-press row adds to the point's row
_PRESS_COLUMNS = ("press_", "pressed_", "permeability_press_", "permeability-press_")
#: columns that must agree between a point's row and its pressure-press row (the same sheet,
#: copied: the wall times are those recorded in the copied products)
SAME_SHEET = ("fibers", "fiber_mass_kg", "sheet_thickness_m", "sheet_thickness_above_fabric_m",
              "grammage_kg_m2", "permeability_cfm", "laydown_wall_s", "permeability_wall_s")


def merge_pressure(rows: list[dict[str, str]], pressure_rows: list[dict[str, str]]) -> tuple[list[dict[str, str]], list[str]]:
    """The point's collect rows with the pressure-press sweep's press and pressed-permeability
    columns added as ``pressure_<column>`` (joined by seed), and the problems: a pressure row
    whose sheet columns (:data:`SAME_SHEET`) differ from the point's is not joined."""
    by_seed = {r.get("seed"): r for r in pressure_rows}
    out: list[dict[str, str]] = []
    problems: list[str] = []
    for r in rows:
        merged = dict(r)
        p = by_seed.get(r.get("seed"))
        press = {} if p is None else {k: v for k, v in p.items() if k.startswith(_PRESS_COLUMNS) and v != ""}
        if press:
            assert p is not None
            differ = [k for k in SAME_SHEET if p.get(k, "") != r.get(k, "")]
            if differ:
                problems.append(f"seed {r.get('seed')}: the pressure press's {', '.join(differ)} differ from the "
                                "point's (not the same sheet); not joined")
            else:
                merged.update({f"pressure_{k}": v for k, v in press.items()})
        out.append(merged)
    return out, problems


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


def sem_interp(support: list[tuple[float, float]], mass_kg: float) -> float | None:
    """The SEM convention's value at an experimental scaled mass: ``support`` (SEM mass, value),
    sorted by mass, interpolated linearly; None without support points or outside their mass range
    (ends widened by 1e-6 relative: a point at the sheet's own mass counts, also when it is the
    only one)."""
    if not support or not support[0][0] * (1 - 1e-6) <= mass_kg <= support[-1][0] * (1 + 1e-6):
        return None
    return float(np.interp(mass_kg, [m for m, _ in support], [x for _, x in support]))


#: points whose SEM masses differ by at most this (relative) are one SEM support point
SEM_SAME_MASS = 1e-9


@dataclass(frozen=True)
class SemPoint:
    """One support point of the SEM convention: a simulated point at its SEM mass (mass x
    :func:`sem_factor`) and its mean over seeds; several points at the same SEM mass are one
    support point (their names, the mean of their means)."""

    names: tuple[str, ...]
    sem_mass_kg: float
    mean: float

    def row(self) -> dict[str, Any]:
        """As the results JSON records it: ``{"point": "A", "sem_mass_kg": ..., "mean": ...}``
        (merged points: names joined by ``+``)."""
        return {"point": "+".join(self.names), "sem_mass_kg": self.sem_mass_kg, "mean": self.mean}


def sem_support(named: list[tuple[str, float]], summary: dict[str, dict[str, dict[str, float]]],
                section: str, metric: str) -> list[SemPoint]:
    """The support points of ``metric`` in ``section`` in the SEM convention: every point of
    ``named`` (name, SEM mass), case or sheet, whose group (``S3-circular``) has a mean of
    ``metric`` in ``summary``, sorted by SEM mass. Points whose SEM masses lie within
    :data:`SEM_SAME_MASS` (relative) of the lightest of them are merged into one support point at
    their mean SEM mass, with the mean of their means and their names in sorted order, so the
    result does not depend on the order of ``named``."""
    found = sorted((m, name, summary[g][metric]["mean"]) for name, m in named
                   if metric in summary.get(g := f"{name}-{section}", {}))
    clusters: list[list[tuple[float, str, float]]] = []
    for item in found:
        if clusters and item[0] - clusters[-1][0][0] <= SEM_SAME_MASS * abs(clusters[-1][0][0]):
            clusters[-1].append(item)
        else:
            clusters.append([item])
    return [SemPoint(tuple(sorted(n for _, n, _ in cl)), statistics.fmean(m for m, _, _ in cl),
                     statistics.fmean(v for _, _, v in cl)) for cl in clusters]


def sem_value(support: list[SemPoint], mass_kg: float) -> tuple[float, list[SemPoint]] | None:
    """The SEM value at an experimental scaled mass (:func:`sem_interp` over ``support``, sorted
    as :func:`sem_support` returns it) and the support points it comes from: the two neighbours
    around the mass, or one point (at the mass itself within :data:`SEM_SAME_MASS`, or at an end
    of the range within its 1e-6 widening). None outside the support points' range."""
    masses = [p.sem_mass_kg for p in support]
    v = sem_interp([(p.sem_mass_kg, p.mean) for p in support], mass_kg)
    if v is None:
        return None
    i = bisect.bisect_left(masses, mass_kg)
    at = sorted((abs(masses[j] - mass_kg), j) for j in (i - 1, i)
                if 0 <= j < len(masses) and abs(masses[j] - mass_kg) <= SEM_SAME_MASS * abs(mass_kg))
    if at:
        used = [at[0][1]]
    elif i == 0:
        used = [0]
    elif i == len(masses):
        used = [i - 1]
    else:
        used = [i - 1, i]
    return v, [support[j] for j in used]


def sheet_ratios(sheets: list[Sheet], pts: list[Point],
                 summary: dict[str, dict[str, dict[str, float]]], section: Section,
                 metric: str = "permeability_cfm") -> list[dict[str, Any]]:
    """Per experimental sheet: the simulated ``metric`` (mean, sd) and simulated / measured
    permeability in both conventions. direct: the sheet's own point; SEM: the means of all points
    of ``pts`` (cases and sheet points) at their SEM masses (:attr:`Point.sem_mass_kg`)
    interpolated linearly at the sheet's scaled mass (:func:`sem_support`, :func:`sem_value`;
    None outside the range of the points that have finished ``metric``), with ``support``: the
    points it comes from (``[{"point", "sem_mass_kg", "mean"}]``, the two neighbours or one point
    at the sheet's mass)."""
    support = sem_support([(p.name, p.sem_mass_kg) for p in pts], summary, section, metric)
    out = []
    for s in sheets:
        row: dict[str, Any] = {"sheet": s.sheet, "measured_cfm": s.permeability_cfm,
                               "measured_thickness_m": s.thickness_m}
        d = summary.get(f"S{s.sheet}-{section}", {}).get(metric)
        row["direct"] = None if d is None else {"mean": d["mean"], "sd": d["sd"], "n": d["n"],
                                                "ratio": d["mean"] / s.permeability_cfm}
        sem = sem_value(support, s.scaled_mass_kg)
        row["sem"] = None if sem is None else {"mean": sem[0], "ratio": sem[0] / s.permeability_cfm,
                                               "support": [p.row() for p in sem[1]]}
        out.append(row)
    return out


def row_sem_mass(row: dict[str, Any], sem_factor: float | None) -> float | None:
    """The SEM mass of a results JSON's point row: its ``sem_mass_kg``, or for a row written before
    that field (bench/thesis/results/campaign.json of sessions 9-22) ``mass_kg`` x ``sem_factor``;
    None if neither can be had."""
    if "sem_mass_kg" in row:
        return float(row["sem_mass_kg"])
    if sem_factor is None or "mass_kg" not in row:
        return None
    return float(row["mass_kg"]) * sem_factor


#: the keys a results JSON's variant row has beside its collect.csv columns
_VARIANT_KEYS = ("point", "section", "ranks")


@dataclass(frozen=True)
class Kept:
    """What an earlier results JSON contributes to a new one (:func:`kept_results`)."""

    #: its ``points`` entries of the kept groups' points (``sem_mass_kg`` added where missing)
    points: list[dict[str, Any]]
    collected: dict[str, list[dict[str, str]]]  #: group -> its collect rows, as :func:`summarise` takes them
    variants: list[dict[str, Any]]  #: its variant rows of the kept groups, unchanged
    failures: dict[str, str]  #: its failures of the kept groups (``A-circular``, ``A-circular-pressure``)
    pending: dict[str, dict[str, str]]  #: its pending pressure presses of the kept groups


def kept_results(previous: dict[str, Any], replaced: set[str], sem_factor: float | None = None) -> Kept:
    """The groups (``"A-circular"``) of an earlier results JSON that this invocation does not run
    (not in ``replaced``), so that ``bench/thesis/run.py --keep`` can add points to a results file
    whose other points' run folders are gone (a new machine): their variant rows are taken over
    unchanged and enter the summary and the per-sheet ratios as if collected again. A point row
    written before ``sem_mass_kg`` existed gets it as ``mass_kg`` x f (:func:`row_sem_mass`), f
    the file's ``sem_factor`` or, in a file without one, ``sem_factor`` (the campaign's)."""
    f = previous.get("sem_factor", sem_factor)
    variants = [v for v in previous.get("variants", [])
                if f"{v['point']}-{v['section']}" not in replaced]
    collected: dict[str, list[dict[str, str]]] = {}
    for v in variants:
        collected.setdefault(f"{v['point']}-{v['section']}", []).append(
            {k: x for k, x in v.items() if k not in _VARIANT_KEYS})
    names = {v["point"] for v in variants}

    def kept(key: str) -> bool:
        return key.removesuffix("-pressure") in collected

    rows = []
    for p in previous.get("points", []):
        if p["name"] in names:
            m = row_sem_mass(p, f)
            rows.append(p if m is None or "sem_mass_kg" in p else {**p, "sem_mass_kg": m})
    return Kept(points=rows, collected=collected,
                variants=variants, failures={k: v for k, v in previous.get("failures", {}).items() if kept(k)},
                pending={k: v for k, v in previous.get("pending", {}).items() if kept(k)})


def write_json(path: Path, data: dict[str, Any]) -> None:
    from .provenance import atomic_write_text

    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(data, indent=2, default=float) + "\n")
