# SPDX-License-Identifier: GPL-3.0-or-later
"""The press report's summary (``fiberform.stages.press._summary``) of a pressure-mode press whose
hold is never reached: said in plain words, without numpy's "Mean of empty slice" warning (the
plate's thickness is NaN while it touches no fiber). Quick: synthetic curves, no fiberdem."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from fiberform.provenance import text_hash
from fiberform.scene import PressSection
from fiberform.stages.press import _summary

PRESS = PressSection(mode="pressure", target_pressure_Pa=4.1e5, hold_time_s=2.0e-4, release_time_s=1.0e-4)
NAN = math.nan
ROOT = Path(__file__).resolve().parent.parent


def summary(phase: list[str], pressure: list[float], thick_plate: list[float], at_stop: list[bool],
            guard_gap: float | None = None) -> dict[str, object]:
    n = len(phase)
    span = np.linspace(500e-6, 498e-6, n)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning (Mean of empty slice) fails the test
        return _summary(PRESS, np.arange(n) * 1e-4, np.array(pressure), np.array(thick_plate), span,
                        np.full(n, 80e-6), phase, np.array(at_stop), guard_gap)


def test_hold_without_plate_contact_is_never_reached() -> None:
    """The tiny campaign's 410 kPa press: the plate rests at the fabric top (touching no fiber)
    while the schedule's clock passes through the hold."""
    out = summary(["approach", "loading", "loading", "hold", "hold", "unloading", "release"],
                  [0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0], [NAN, 3e-6, NAN, NAN, NAN, NAN, NAN],
                  [False, False, True, True, True, True, True])
    lines = out["lines"]
    assert isinstance(lines, list)
    assert any(line.startswith("hold: **never reached**: the plate touched no fiber") for line in lines), lines
    assert not any("nan" in line for line in lines), lines
    assert "hold_pressure_mean_Pa" not in out and "thickness_plate_at_hold_m" not in out
    assert any("target pressure not reached" in line for line in lines)


def test_guard_stop_before_the_hold_is_never_reached() -> None:
    out = summary(["approach", "loading", "loading"], [0.0, 3.0e3, 9.0e3], [NAN, 70e-6, 65e-6],
                  [False, False, False], guard_gap=65e-6)
    lines = out["lines"]
    assert isinstance(lines, list)
    assert ("hold: **never reached**: the press ended in its loading phase, stopped by the overlap "
            "guard 65.00 um above the fabric top") in lines, lines
    assert "hold_pressure_mean_Pa" not in out


def test_hold_reached_averages_the_contact_points() -> None:
    """Plate thickness at the hold: the mean over the hold's points in contact (20 and 30 um:
    25 um); pressure over the whole hold ((4.0e5 + 4.2e5 + 4.1e5) / 3 = 4.1e5 Pa)."""
    out = summary(["loading", "hold", "hold", "hold"], [2.0e5, 4.0e5, 4.2e5, 4.1e5],
                  [40e-6, NAN, 20e-6, 30e-6], [False] * 4)
    assert out["thickness_plate_at_hold_m"] == pytest.approx(25e-6, rel=1e-12)
    assert out["hold_pressure_mean_Pa"] == pytest.approx(4.1e5, rel=1e-12)
    assert out["hold_pressure_max_dev"] == pytest.approx(0.01 / 0.41, rel=1e-9)
    lines = out["lines"]
    assert isinstance(lines, list)
    assert any(line.startswith("hold: pressure 4.1e+05 Pa") and line.endswith("plate thickness 25.00 um")
               for line in lines), lines


def test_pressure_method_is_hashed_for_pressure_presses_only(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A change of the pressure mode's method (PRESSURE_METHOD) makes pressure-mode press products
    stale and leaves velocity-mode ones valid: the entry is in the pressure mode's input hashes
    only, and the rest of the hashes is the base stage's."""
    from fiberform.scene import load_scene
    from fiberform.stages._stage import Stage, StageContext
    from fiberform.stages.press import PRESSURE_METHOD, Press

    scene = load_scene(ROOT / "scenes" / "demo.yaml")
    assert scene.press is not None
    monkeypatch.chdir(tmp_path)  # no upstream products here: their hashes read "missing"
    hashes = {}
    for mode, extra in (("velocity", {"target_thickness_m": 5e-5}), ("pressure", {"target_pressure_Pa": 1e3})):
        press = PressSection(mode=mode, **extra)
        ctx = StageContext(scene.model_copy(update={"press": press}), ROOT / "scenes" / "demo.yaml", tmp_path)
        hashes[mode] = (Press().input_hashes(ctx), Stage.input_hashes(Press(), ctx))
    own, base = hashes["velocity"]
    assert own == base and "pressure_method" not in own
    own, base = hashes["pressure"]
    assert set(own) - set(base) == {"pressure_method"}
    assert own["pressure_method"] == text_hash(f"press-pressure:{PRESSURE_METHOD}")
