#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The press plate's accuracy and its measured limits (docs/bench/press.md, docs/stages/press.md).

1. Log-cabin stack (tests/test_press_stack.py's set-up: 3 layers, s = 1 mm, r = 10 um, layer-2 ends
   clamped, steric only): the middle span's deflection over P s^3 / (192 E I), force and deflection
   averaged over the last 100 steps of the hold, at time steps 1e-5, 5e-6, 2e-6 s, with the wall
   time of each run (the 1e-5 s run twice: spread).
2. Spring-back on the same stack after the plate is lifted again: the deflection left over the
   last 20 outputs (mean and largest, relative to the loaded deflection) and the largest rise of
   a layer-3 node above its start, at 1e-5 and 2e-6 s, without and with gravity.
3. The servo plate on one fiber across two yarns (tests/test_press_plate.py): the largest pressure
   deviation over the hold and the force-balance residual, at 4 Pa and 8 mPa.

    .venv/bin/python bench/press/run.py

Writes bench/press/results/press_bench.json. Measure on an idle machine.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "scripts"))

import test_press_plate as plate_case  # noqa: E402
import test_press_stack as stack  # noqa: E402

from fiberform.provenance import machine_info  # noqa: E402

BUILD = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()


def stack_run(dt: float, gravity: bool) -> dict[str, Any]:
    """One stack run at step dt (the test's own input; gravity on or off)."""
    stack.DT = dt
    with tempfile.TemporaryDirectory(prefix="fiberform-bench-press-") as tmp:
        t0 = time.monotonic()
        r = stack._run(Path(tmp), BUILD, "steric", gravity=gravity)
        wall = time.monotonic() - t0
    k = int(np.nonzero(r["step"] == int(r["hold_end"][0]))[0][0])
    hold = slice(k - 19, k + 1)
    P = -float(np.mean(r["fz"][hold])) / stack.N_CROSS
    loaded = float(np.mean(r["delta"][hold]))
    after = r["delta"][-20:]
    rise = r["top"][k + 1:] - r["top"][0]
    return {
        "dt_s": dt, "gravity": gravity, "wall_s": wall,
        "P_N": P, "P_over_Fmax": P / stack.F_MAX,
        "deflection_m": loaded, "closed_form_m": P * stack.C_BEND,
        "ratio": loaded / (P * stack.C_BEND),
        "plate_force_scatter": float(np.std(r["fz"][hold]) / abs(np.mean(r["fz"][hold]))),
        "springback_mean_rel": float(np.mean(after)) / loaded,
        "springback_max_rel": float(np.max(np.abs(after))) / loaded,
        "layer3_max_rise_m": float(np.max(rise)) if len(rise) else math.nan,
    }


def servo_run(p_t: float) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="fiberform-bench-press-") as tmp:
        t0 = time.monotonic()
        out = plate_case._press(BUILD, Path(tmp), p_t)
        wall = time.monotonic() - t0
    fpz, p, _, tc, fyz = out.T
    hold = tc > plate_case.RAMP + 0.5e-3
    weight = (plate_case.RHO - plate_case.RHO_F) * math.pi * plate_case.R**2 * plate_case.L * plate_case.G
    return {
        "target_Pa": p_t, "wall_s": wall,
        "hold_max_deviation": float(np.max(np.abs(p[hold] / p_t - 1.0))),
        "balance_residual_rel": float(np.max(np.abs(fpz[hold] + fyz[hold] - weight) / np.abs(fpz[hold]))),
        "weight_over_plate_force": float(weight / np.mean(np.abs(fpz[hold]))),
    }


def main() -> int:
    if not (BUILD / "bin" / "fiberdem").is_file():
        print(f"{BUILD / 'bin' / 'fiberdem'} not found: build first", file=sys.stderr)
        return 2
    res: dict[str, Any] = {"machine": machine_info(), "stack": [], "springback": [], "servo": []}
    for dt in (1e-5, 1e-5, 5e-6, 2e-6):
        res["stack"].append(stack_run(dt, gravity=False))
    for dt in (1e-5, 2e-6):
        res["springback"].append(stack_run(dt, gravity=True))
    for p_t in (4.0, 8e-3):
        res["servo"].append(servo_run(p_t))
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / "press_bench.json").write_text(json.dumps(res, indent=2) + "\n")
    print("log-cabin stack (steric, no gravity):")
    print("  dt (s)   deflection / closed form   P / F_max   plate force scatter   wall (s)")
    for s in res["stack"]:
        print(f"  {s['dt_s']:.0e}   {s['ratio']:.4f}                     {s['P_over_Fmax']:.3f}       "
              f"{s['plate_force_scatter']:.3f}                 {s['wall_s']:.1f}")
    print("spring-back after the plate is lifted (deflection left / loaded; layer-3 rise):")
    for s in res["stack"][::2] + res["springback"]:
        print(f"  dt {s['dt_s']:.0e}, gravity {'yes' if s['gravity'] else 'no '}: mean "
              f"{s['springback_mean_rel']:+.3f}, largest {s['springback_max_rel']:.3f}, "
              f"rise up to {s['layer3_max_rise_m'] * 1e9:.0f} nm")
    print("servo plate on one fiber across two yarns:")
    for s in res["servo"]:
        print(f"  {s['target_Pa']:g} Pa: hold deviation {s['hold_max_deviation']:.2e}, balance "
              f"residual {s['balance_residual_rel']:.2e} of the plate force (weight "
              f"{s['weight_over_plate_force']:.2e} of it), {s['wall_s']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
