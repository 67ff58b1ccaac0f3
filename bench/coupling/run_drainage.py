#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/coupling/run_drainage: the two-way demo against the one-way demo, and the drainage at the
end of the two-way lay-down against the permeability stage's water flow through the same sheet
(issue 13, benchmarks "Overhead" and "Drainage").

Pinned inputs: scenes/demo.yaml (one-way, frozen flow) and scenes/demo-two-way.yaml (the same scene,
coupling two_way, interval 100), each laid down until it settles, in ``runs/bench-coupling/``
(kept; a second call reuses finished stages). Then the permeability stage runs on the two-way sheet
with WATER (the flow stage's fluid, density and viscosity) at the flow stage's pressure drop
(100 Pa), resolved fabric, the fibers as a sub-grid Darcy resistance (the demo's permeability
settings otherwise). Printed and written to bench/coupling/results/drainage.json:

* lay-down wall time, simulated time to settle, sheet thickness and grammage, one-way and two-way;
* the two-way lay-down's superficial velocity at its start (the flow stage's bare fabric) and at
  its end (fabric + sheet, the fibers as momentum sources of the coupled fluid);
* the permeability stage's superficial velocity of water through fabric + the same sheet.

    .venv/bin/python bench/coupling/run_drainage.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import h5py
import yaml

from fiberform.provenance import atomic_write_text, machine_info

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
RUNS = Path("runs") / "bench-coupling"


def fiberform(*args: str) -> None:
    build = Path(os.environ.get("FIBERFORM_BUILD", ROOT / "build")).resolve()
    proc = subprocess.run([sys.executable, "-m", "fiberform", *args, "--build-dir", str(build)], cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"fiberform {' '.join(args)}: exit {proc.returncode}")


def scene(name: str, source: str, water: bool = False) -> Path:
    data: dict[str, Any] = yaml.safe_load((ROOT / "scenes" / source).read_text())
    data["output_dir"] = str(RUNS / name)
    if water:  # the permeability stage with the flow stage's fluid and pressure drop
        fl, perm = data["fluid"], data["permeability"]
        perm.update({"density_kg_m3": fl["density_kg_m3"], "viscosity_Pa_s": fl["viscosity_Pa_s"],
                     "pressure_drop_Pa": data["flow"]["delta_p_Pa"]})
    path = ROOT / RUNS / f"{name}{'-water' if water else ''}.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, yaml.safe_dump(data, sort_keys=False))
    return path


def laydown(out: Path) -> dict[str, Any]:
    with h5py.File(ROOT / out / "laydown" / "laydown.h5", "r") as h:
        a = h["run"].attrs
        row = {"wall_s": float(a["wall_time_s"]), "simulated_s": float(a["simulated_time_s"]),
               "settled": bool(a["settled"]), "thickness_m": float(a["sheet_thickness_m"]),
               "grammage_kg_m2": float(a["grammage_kg_m2"]), "fibers_on_sheet": int(h["sheet/fiber_id"].shape[0]),
               "flow_stage_superficial_velocity_m_s": float(a["superficial_velocity_m_s"])}
        if "drainage" in h:
            u = h["drainage/superficial_velocity"][...]
            row.update({"drainage_start_m_s": float(u[0]), "drainage_end_m_s": float(u[-1])})
    return row


def main() -> int:
    t0 = time.monotonic()
    one = scene("demo", "demo.yaml")
    two = scene("demo-two-way", "demo-two-way.yaml")
    fiberform("run", str(one), "--to", "laydown")
    fiberform("run", str(two), "--to", "laydown")
    water = scene("demo-two-way", "demo-two-way.yaml", water=True)
    fiberform("run", str(water), "--from", "permeability", "--to", "permeability")
    res: dict[str, Any] = {"machine": machine_info(), "one_way": laydown(RUNS / "demo"),
                           "two_way": laydown(RUNS / "demo-two-way")}
    with h5py.File(ROOT / RUNS / "demo-two-way" / "permeability-laydown" / "permeability.h5", "r") as h:
        r = h["result"]
        res["permeability_water"] = {k: float(r[k][()]) for k in r if r[k].shape == ()}
    res["wall_s"] = time.monotonic() - t0
    out = HERE / "results" / "drainage.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, json.dumps(res, indent=2) + "\n")
    print(json.dumps({k: v for k, v in res.items() if k != "machine"}, indent=2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
