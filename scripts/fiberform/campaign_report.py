# SPDX-License-Identifier: GPL-3.0-or-later
"""Figures and tables of the validation campaign (issue 15) from its results JSON.

``bench/thesis/run.py`` writes ``campaign[-reduced].json`` (per point and section the mean and sd
over seeds, per sheet the ratios of ``fiberform.campaign.sheet_ratios``); this module turns that
dict and the experiments (``campaign.read_experiments``) into

* the thesis' Figures 4.12 (sheet thickness, um) and 4.13 (air permeability at 125 Pa, CFM)
  redrawn: against the injection mass (ug on 3 x 3 mm) and against the number of generated
  fibers, the experiments (Table 4.1) against the simulation (circular and rectangular sections;
  unpressed, pressed to the experimental thickness and pressed to the campaign's stated pressure;
  error bars = sd over seeds), in both mass conventions: direct (points
  S1..S7 at the sheets' own scaled masses) and SEM (every point, the cases A..G and the sheet
  points S1..S7, at its SEM mass f x its simulated mass: the support points of the SEM values,
  the line through them the interpolation; ``sem_mass_kg`` of the JSON's points, or for a file
  written before that field mass_kg x f, :func:`sem_factor_of`). On the fiber axis an
  experimental sheet sits at the fiber count of its simulated counterpart in that convention and
  section (direct: point Sk; SEM: the points' counts interpolated at its mass);
* a Markdown table per section and state (unpressed, pressed to thickness, pressed to pressure):
  per sheet the measured and the simulated permeability and their ratio in both conventions, the
  points the SEM value comes from, and the thicknesses.

States (:data:`STATES`, their labels :data:`STATE_LABELS`): ``unpressed`` (the lay-down's sheet),
``pressed`` (the campaign's velocity-controlled press to the experimental thickness; JSON
``sheets_pressed``, metrics ``permeability_press_cfm``, ``pressed_thickness_above_fabric_m``) and
``pressure`` (the second press, pressure-controlled, of the same sheet; JSON ``sheets_pressure``,
metrics ``pressure_permeability_press_cfm``, ``pressure_pressed_thickness_above_fabric_m``); the
unpressed thickness is ``sheet_thickness_above_fabric_m``.

The simulated thickness compared with the experiments is the sheet's thickness above the fabric
top (``fiberform.fiber_sheet.thickness_above_fabric``: the 95th percentile of the fibers' upper
surfaces minus the fabric top, at least 0), as the experiments measure a sheet on its fabric
(sheet 1: 0 um). The 5-95 % node span + one width (``sheet_thickness_m``,
``pressed_span_thickness_m``), which counts the fibers hanging into the fabric's openings, stays in
the JSON but is not plotted.

Points without data are left out (figures) or shown as ``-`` (tables); an empty campaign gives
the experiments alone.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from .campaign import Sheet, load_campaign, read_experiments, row_sem_mass, sem_factor, sem_support, sem_value
from .errors import ConfigError
from .provenance import atomic_write_text, in_progress_path

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["QUANTITIES", "STATES", "STATE_LABELS", "Series", "figure", "figure_series", "markdown", "sem_factor_of",
           "write_figure", "write_report"]

Convention = Literal["direct", "sem"]
Axis = Literal["mass", "fibers"]
State = Literal["unpressed", "pressed", "pressure"]
Summary = dict[str, dict[str, dict[str, float]]]
Row = tuple[float, float, float, float, str]  # x, sd of x, y, sd of y, name

SECTIONS = ("circular", "rectangular")
STATES: tuple[State, ...] = ("unpressed", "pressed", "pressure")
STATE_LABELS: dict[State, str] = {"unpressed": "unpressed", "pressed": "pressed to thickness",
                                  "pressure": "pressed to pressure"}
CONVENTIONS: tuple[Convention, ...] = ("direct", "sem")
AXES: tuple[Axis, ...] = ("mass", "fibers")


@dataclass(frozen=True)
class Quantity:
    """One compared quantity: the collect.csv metric per state, the Sheet field, the plot scale."""

    metric: dict[State, str]
    measured: str  # Sheet attribute
    scale: float  # SI -> plotted unit
    label: str
    file_tag: str
    definition: str = ""  # what the simulated value is (figure title, table text)


QUANTITIES = {
    "thickness": Quantity({"unpressed": "sheet_thickness_above_fabric_m",
                           "pressed": "pressed_thickness_above_fabric_m",
                           "pressure": "pressure_pressed_thickness_above_fabric_m"},
                          "thickness_m", 1e6, "thickness above the fabric top (um)", "fig412-thickness",
                          "simulated: 95th percentile of the fibers' upper surfaces minus the fabric top "
                          "(not the 5-95 % node span)"),
    "permeability": Quantity({"unpressed": "permeability_cfm", "pressed": "permeability_press_cfm",
                              "pressure": "pressure_permeability_press_cfm"},
                             "permeability_cfm", 1.0, "air permeability at 125 Pa (CFM)", "fig413-permeability"),
}


@dataclass(frozen=True)
class Series:
    """One plotted line: experiments (section and state None; on the fiber axis with the section
    whose fiber counts place them) or one section and state of the simulation."""

    label: str
    names: tuple[str, ...]  # point names (A, S3) or sheet numbers (1..7)
    x: np.ndarray
    y: np.ndarray
    xerr: np.ndarray | None
    yerr: np.ndarray | None
    section: str | None = None
    state: State | None = None


def _group(point: str, section: str) -> str:
    return f"{point}-{section}"  # bench/thesis/run.py's variant group


def _is_sheet_point(name: str) -> bool:
    return name.startswith("S") and name[1:].isdigit()  # campaign.points: sheets S1.., cases one letter


@functools.lru_cache(maxsize=8)
def _campaign_sem_factor(path: str) -> float | None:
    """f of the campaign definition ``path`` (experiments.csv beside it); None if unreadable."""
    try:
        return sem_factor(load_campaign(Path(path)), read_experiments(Path(path).parent / "experiments.csv"))
    except (ConfigError, OSError, ValueError, KeyError):
        return None


def sem_factor_of(data: dict[str, Any]) -> float | None:
    """The SEM factor f (experimental mass per simulated mass) of a results JSON: its
    ``sem_factor``; for a file written before that field, f of the campaign definition it names
    (``campaign``, with ``experiments.csv`` beside it); None if neither can be read."""
    if data.get("sem_factor") is not None:
        return float(data["sem_factor"])
    return _campaign_sem_factor(str(data["campaign"])) if data.get("campaign") else None


def _mass(p: dict[str, Any], convention: Convention, f: float | None) -> float | None:
    """The experimental mass a JSON point row stands for in a convention: direct its own
    ``experimental_mass_kg``, SEM its ``sem_mass_kg`` (or mass_kg x f: campaign.row_sem_mass; a
    case point of an old file without any f: its SEM-mapped ``experimental_mass_kg``)."""
    if convention == "direct":
        return float(p["experimental_mass_kg"])
    m = row_sem_mass(p, f)
    if m is None and not _is_sheet_point(p["name"]) and "experimental_mass_kg" in p:
        return float(p["experimental_mass_kg"])
    return m


def _points(data: dict[str, Any], convention: Convention) -> list[tuple[dict[str, Any], float]]:
    """The JSON's points of a convention with the experimental mass each stands for: direct the
    sheet points at their own masses, SEM every point (cases and sheet points) at its SEM mass
    (points whose SEM mass cannot be had are left out)."""
    f = sem_factor_of(data) if convention == "sem" else None
    out: list[tuple[dict[str, Any], float]] = []
    for p in data.get("points", []):
        if convention == "direct" and not _is_sheet_point(p["name"]):
            continue
        if (m := _mass(p, convention, f)) is not None:
            out.append((p, m))
    return out


def _counterpart(data: dict[str, Any], sheet: Sheet, section: str, metric: str,
                 convention: Convention) -> float | None:
    """The simulated mean of ``metric`` that stands for ``sheet``: direct its own point, SEM every
    point at its SEM mass interpolated at the sheet's mass (campaign.sem_support, sem_value)."""
    summary: Summary = data.get("summary", {})
    if convention == "direct":
        st = summary.get(_group(f"S{sheet.sheet}", section), {}).get(metric)
        return None if st is None else st["mean"]
    support = sem_support([(p["name"], m) for p, m in _points(data, "sem")], summary, section, metric)
    v = sem_value(support, sheet.scaled_mass_kg)
    return None if v is None else v[0]


def _series(label: str, rows: list[Row], section: str | None,
            state: State | None, errors: tuple[bool, bool]) -> Series:
    rows = sorted(rows)
    a = np.array([r[:4] for r in rows], dtype=float).reshape(-1, 4)
    return Series(label, tuple(r[4] for r in rows), a[:, 0], a[:, 2], a[:, 1] if errors[0] else None,
                  a[:, 3] if errors[1] else None, section, state)


def figure_series(data: dict[str, Any], sheets: list[Sheet], quantity: str, convention: Convention,
                  axis: Axis) -> list[Series]:
    """The series of one panel (mass in ug, fibers as counts, thickness in um, permeability in
    CFM; error bars the sd over seeds). Series without any point are left out."""
    q = QUANTITIES[quantity]
    summary: Summary = data.get("summary", {})
    out: list[Series] = []
    if axis == "mass":
        out.append(_series("experiment (Table 4.1)",
                           [(s.scaled_mass_kg * 1e9, 0.0, getattr(s, q.measured) * q.scale, 0.0, str(s.sheet))
                            for s in sheets], None, None, (False, False)))
    else:
        for section in SECTIONS:
            exp: list[Row] = [(n, 0.0, getattr(s, q.measured) * q.scale, 0.0, str(s.sheet)) for s in sheets
                              if (n := _counterpart(data, s, section, "fibers", convention)) is not None]
            out.append(_series(f"experiment at the {section} fiber count", exp, section, None, (False, False)))
    for section in SECTIONS:
        for state in STATES:
            rows: list[Row] = []
            for p, mass in _points(data, convention):
                st = summary.get(_group(p["name"], section), {})
                if (v := st.get(q.metric[state])) is None:
                    continue
                if axis == "mass":
                    x, xsd = mass * 1e9, 0.0
                elif "fibers" in st:
                    x, xsd = st["fibers"]["mean"], st["fibers"]["sd"]
                else:
                    continue
                rows.append((x, xsd, v["mean"] * q.scale, v["sd"] * q.scale, p["name"]))
            out.append(_series(f"{section}, {STATE_LABELS[state]}", rows, section, state, (axis == "fibers", True)))
    return [s for s in out if len(s.x)]


_COLOURS: dict[str | None, str] = {"circular": "tab:blue", "rectangular": "tab:orange", None: "black"}
_MARKERS: dict[State, str] = {"unpressed": "o", "pressed": "v", "pressure": "D"}
_LINES: dict[State, str] = {"unpressed": "-", "pressed": "--", "pressure": "-."}
_XLABELS = {"mass": "injection mass on 3 x 3 mm (ug)", "fibers": "number of fibers (generated)"}


def _title(convention: Convention, f: float | None) -> str:
    """The panel title; SEM says that every point, the sheet points too, is a support point."""
    if convention == "direct":
        return "direct: sheets' scaled masses (points S1-S7)"
    return (f"SEM (case B = sheet 2): each point at f x its mass{'' if f is None else f', f = {f:.4f}'}"
            "\n(sheet points S1-S7: SEM support at f x their mass)")


def figure(data: dict[str, Any], sheets: list[Sheet], quantity: str) -> tuple[Figure, dict[tuple[str, str], list[Series]]]:
    """Figure 4.12 (``thickness``) or 4.13 (``permeability``): rows the two mass conventions,
    columns injection mass and number of fibers. Returns the figure and what each panel
    (convention, axis) shows."""
    import matplotlib.figure

    q = QUANTITIES[quantity]
    fig = matplotlib.figure.Figure(figsize=(11.0, 8.0))
    f = sem_factor_of(data)
    axes = fig.subplots(len(CONVENTIONS), len(AXES), squeeze=False)
    drawn: dict[tuple[str, str], list[Series]] = {}
    for i, conv in enumerate(CONVENTIONS):
        for j, axis in enumerate(AXES):
            ax = axes[i][j]
            drawn[(conv, axis)] = panel = figure_series(data, sheets, quantity, conv, axis)
            for s in panel:
                experiment = s.state is None
                ax.errorbar(s.x, s.y, yerr=s.yerr, xerr=s.xerr, label=s.label, color=_COLOURS[s.section],
                            marker="s" if s.state is None else _MARKERS[s.state],
                            mfc="none" if experiment and s.section else None,
                            ls=":" if experiment and s.section else ("-" if s.state is None else _LINES[s.state]),
                            capsize=3, lw=1.2)
                if conv == "sem" and axis == "mass" and s.state == "unpressed":
                    for name, x, y in zip(s.names, s.x, s.y, strict=True):  # which point supports where
                        ax.annotate(name, (x, y), xytext=(3, 3), textcoords="offset points", fontsize=6,
                                    color=_COLOURS[s.section])
            if not panel:
                ax.text(0.5, 0.5, "no simulated points yet", transform=ax.transAxes, ha="center", color="grey")
            ax.set_xlabel(_XLABELS[axis])
            ax.set_ylabel(q.label)
            ax.set_title(_title(conv, f), fontsize=9)
            ax.grid(alpha=0.3)
            if panel:
                ax.legend(fontsize=7)
                # both quantities are >= 0: every panel shows them from zero, so that a spread of
                # a few CFM among close points is not drawn across the whole panel
                top = max(float(np.max(np.asarray(s.y) + (0.0 if s.yerr is None else np.asarray(s.yerr))))
                          for s in panel)
                ax.set_ylim(bottom=0.0, top=max(1.08 * top, 1.0))
    fig.suptitle(f"{q.label}: experiment vs simulation (error bars: sd over seeds){_pressure_note(data)}"
                 + (f"\n{q.definition}" if q.definition else ""), fontsize=11)
    fig.tight_layout()
    return fig, drawn


def write_figure(data: dict[str, Any], sheets: list[Sheet], quantity: str,
                 out: Path) -> dict[tuple[str, str], list[Series]]:
    """figure() saved as PNG to ``out`` (through a temporary name in the same folder)."""
    fig, drawn = figure(data, sheets, quantity)
    tmp = in_progress_path(out)
    try:
        fig.savefig(tmp, format="png", dpi=110)
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    return drawn


def _pressure_note(data: dict[str, Any]) -> str:
    """``; pressed to pressure: 410 kPa`` when the JSON names the second press's pressure."""
    pp = data.get("pressure_press") or {}
    return f"; pressed to pressure: {pp['target_pressure_Pa'] / 1e3:g} kPa" if "target_pressure_Pa" in pp else ""


def _num(v: float | None, digits: int) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _stat(st: dict[str, float] | None, scale: float = 1.0) -> str:
    if st is None:
        return "-"
    return f"{st['mean'] * scale:.1f} +- {st['sd'] * scale:.1f} (n={int(st['n'])})"


def _f_text(data: dict[str, Any]) -> str:
    f = sem_factor_of(data)
    return "f = sheet 2's mass / case B's mass" if f is None else f"f = {f:.4f}"


def _support(sem: dict[str, Any] | None) -> str:
    """The SEM value's support points (campaign.sheet_ratios): ``A 10.84, S3 13.69``; ``-``
    without a value or in a file that does not record them."""
    if not sem or not sem.get("support"):
        return "-"
    return ", ".join(f"{p['point']} {p['sem_mass_kg'] * 1e9:.2f}" for p in sem["support"])


def markdown(data: dict[str, Any], sheets: list[Sheet]) -> str:
    """Per section and state one table: per sheet the measured permeability, the simulated one and
    simulated / measured in the direct and the SEM convention (the JSON's ``sheets_unpressed`` /
    ``sheets_pressed`` / ``sheets_pressure``), the points the SEM value comes from, the measured
    and simulated thickness; ``-`` where not available."""
    summary: Summary = data.get("summary", {})
    sections = list(data.get("sheets_unpressed") or SECTIONS)
    pp = data.get("pressure_press") or {}
    second = (f"{pp['target_pressure_Pa'] / 1e3:g} kPa" if "target_pressure_Pa" in pp else "the campaign's pressure")
    lines = ["# Validation campaign: experimental sheets against the simulation", "",
             f"From `bench/thesis/run.py {data.get('command', '')}` (seeds: {data.get('seeds', '-')}). Permeability in CFM "
             "(cubic feet per square foot per minute) at 125 Pa, thickness in um, masses in ug on 3 x 3 mm. "
             "Simulated values: mean +- sd over seeds (n seeds). direct: sheet k against point Sk (its own "
             "scaled mass); SEM (case B = sheet 2): every simulated point, case or sheet, stands for f x its "
             f"simulated mass ({_f_text(data)}), and the finished points' values are interpolated linearly at "
             "the sheet's mass, only within their range; 'SEM: from' names the points (at their SEM masses, "
             "ug) the SEM permeability comes from. "
             "Ratio: simulated / measured permeability. Simulated thickness: thickness above the fabric top, "
             "95th percentile of the fibers' upper surfaces minus the fabric top, at least 0 (pressed: at the "
             "end of the press; the 5-95 % span of node heights + one width, which counts fibers hanging into "
             "the fabric's openings, is in the JSON only). States: unpressed (the laid-down sheet); "
             "pressed to thickness (plate moved to the experimental thickness, or stopped by the overlap "
             f"guard); pressed to pressure (the same laid-down sheet pressed to {second}, or as far as the "
             "overlap guard allowed).", ""]
    if data.get("failures"):
        lines += ["Failed: " + "; ".join(f"{g}: {e}" for g, e in data["failures"].items()), ""]
    if data.get("pending"):
        lines += ["Pending (waiting for their lay-down): " + "; ".join(
            f"{g}: {', '.join(v)}" for g, v in data["pending"].items()), ""]
    for section in sections:
        for state in STATES:
            rows = {r["sheet"]: r for r in data.get(f"sheets_{state}", {}).get(section, [])}
            thick = QUANTITIES["thickness"].metric[state]
            lines += [f"## {section}, {STATE_LABELS[state]}", "",
                      "| sheet | mass (ug) | measured (CFM) | direct: simulated (CFM) | direct: ratio | "
                      "SEM: simulated (CFM) | SEM: ratio | SEM: from (point at SEM mass, ug) | measured thickness "
                      "(um) | direct: thickness above fabric (um) | SEM: thickness above fabric (um) |",
                      "|" + "---|" * 11]
            for s in sheets:
                r = rows.get(s.sheet, {})
                d, sem = r.get("direct"), r.get("sem")
                sem_t = _counterpart(data, s, section, thick, "sem")
                cells = [str(s.sheet), f"{s.scaled_mass_kg * 1e9:.1f}", f"{s.permeability_cfm:g}", _stat(d),
                         _num(d and d["ratio"], 2), _num(sem and sem["mean"], 1), _num(sem and sem["ratio"], 2),
                         _support(sem), f"{s.thickness_m * 1e6:g}",
                         _stat(summary.get(_group(f"S{s.sheet}", section), {}).get(thick), 1e6),
                         _num(None if sem_t is None else sem_t * 1e6, 1)]
                lines.append("| " + " | ".join(cells) + " |")
            lines.append("")
    return "\n".join(lines)


def write_report(data: dict[str, Any], sheets: list[Sheet], json_path: Path) -> list[Path]:
    """Next to ``campaign[-reduced].json``: ``<stem>-fig412-thickness.png``,
    ``<stem>-fig413-permeability.png`` and ``<stem>.md``. Returns the paths written."""
    out = []
    for name, q in QUANTITIES.items():
        png = json_path.with_name(f"{json_path.stem}-{q.file_tag}.png")
        write_figure(data, sheets, name, png)
        out.append(png)
    md = json_path.with_suffix(".md")
    atomic_write_text(md, markdown(data, sheets))
    return out + [md]

