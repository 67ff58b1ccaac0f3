#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/contact: accuracy and wall time of pair_style fiber/dlvo's integrators (cvode, substep,
none) over a sweep of fiber time steps, on the head-on collision of thesis 4.1.1 (started 20 nm
before contact to keep the bench short). Accuracy: the resting fiber's final velocity against a
converged reference (cvode, dt = 1e-8 s, rtol 1e-9). Writes results/contact.json and contact.png.

Usage: bench/contact/run.py [--build DIR] [--quick]"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "liggghts-fiber-style" / "examples" / "in.fiber_collision"
V0, GAP, TEND = 0.05, 2e-8, 4e-5


def run(exe: Path, integ: str, dt: float, extra: str = "") -> tuple[float, float, bool]:
    with tempfile.TemporaryDirectory() as d:
        cmd = [str(exe), "-in", str(EXAMPLE), "-log", "log", "-screen", "none", "-var", "v0", str(V0),
               "-var", "gap", str(GAP), "-var", "tend", str(TEND), "-var", "dt", str(dt), "-var", "integ", integ,
               "-var", "every", "100000000", "-var", "extra", extra]
        env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
        t0 = time.perf_counter()
        r = subprocess.run(cmd, cwd=d, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if r.returncode != 0:
            return float("nan"), wall, False
        rows = [l.split() for l in Path(d, "final.dump").read_text().splitlines()[9:]]
        vx1 = float(sorted(rows, key=lambda w: int(w[0]))[0][5])
        return vx1, wall, True


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=os.environ.get("FIBERFORM_BUILD", ROOT / "build"))
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    exe = Path(a.build) / "bin" / "fiberdem"
    dts = [1e-8, 1e-7, 1e-6] if a.quick else [1e-8, 3e-8, 1e-7, 3e-7, 1e-6]
    ref, _, _ = run(exe, "cvode", 1e-8, "rtol 1e-9")
    res = {"machine": platform.node(), "cpu": platform.processor(), "reference_vx1": ref, "runs": []}
    for integ in ["cvode", "substep 100", "none"]:
        for dt in dts:
            vx1, wall, ok = run(exe, integ, dt)
            err = abs(vx1 - ref) / abs(ref) if ok else float("inf")
            res["runs"].append({"integrator": integ, "dt": dt, "vx1": vx1, "rel_error": err, "wall_s": wall, "ok": ok})
            print(f"{integ:12s} dt={dt:.0e} vx1={vx1:.6g} err={err:.3g} wall={wall:.2f}s", flush=True)
    best = {}
    for integ in ["cvode", "substep 100", "none"]:
        good = [r for r in res["runs"] if r["integrator"] == integ and r["rel_error"] < 0.01]
        if good:
            best[integ] = max(good, key=lambda r: r["dt"])
    res["best_within_1pct"] = best
    if "cvode" in best and "none" in best:
        res["headline_none_over_cvode_wall"] = best["none"]["wall_s"] / best["cvode"]["wall_s"]
    out = Path(__file__).parent / "results"
    out.mkdir(exist_ok=True)
    (out / "contact.json").write_text(json.dumps(res, indent=1))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
        for integ in ["cvode", "substep 100", "none"]:
            rr = [r for r in res["runs"] if r["integrator"] == integ and r["ok"]]
            ax[0].loglog([r["dt"] for r in rr], [max(r["rel_error"], 1e-12) for r in rr], "o-", label=integ)
            ax[1].loglog([r["dt"] for r in rr], [r["wall_s"] for r in rr], "o-", label=integ)
        ax[0].set_xlabel("fiber dt (s)"); ax[0].set_ylabel("rel. error of v_x(fiber 1)"); ax[0].legend()
        ax[1].set_xlabel("fiber dt (s)"); ax[1].set_ylabel("wall time (s)")
        fig.tight_layout(); fig.savefig(out / "contact.png", dpi=100)
    except ImportError:
        print("matplotlib missing: no plot")
    print(json.dumps({k: v for k, v in res.items() if k != "runs"}, indent=1))


if __name__ == "__main__":
    main()
