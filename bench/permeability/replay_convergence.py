# SPDX-License-Identifier: GPL-3.0-or-later
"""Replay the stop rule of finished permeability solves at other tolerances (issue 15).

A permeability solve with ``stop_at: converged`` ends at the first iteration whose last
``window`` outflows vary by at most ``tolerance`` of their mean (fiberform.porous_media.
flow_rate_convergence, applied after every iteration by the function object). Given the outflow
histories of finished solves (``case/postProcessing/flowRateBottom/0/surfaceFieldValue.dat`` in a
permeability stage folder), this prints per solve and tolerance the iteration the rule would have
stopped at and its result relative to the solve's own (the mean of its last window), and the total
iterations per tolerance (docs/validation/table41.md "Permeability convergence"):

    .venv/bin/python bench/permeability/replay_convergence.py --tolerances 5e-3 1e-2 -- \\
        runs/thesis-campaign/S*-circular*-sweep/campaign_*/permeability-*/case/postProcessing/flowRateBottom/0/surfaceFieldValue.dat

Histories that are the same file reached twice (the pressure sweep adopts its point's unpressed
solve) count once. A solve that never met a tolerance counts with its own length.
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

import numpy as np

from fiberform.porous_media import flow_rate_convergence


def stop_iteration(q: np.ndarray, window: int, tolerance: float) -> tuple[int, float] | None:
    """The first iteration count at which the rule holds on the history ``q`` and the mean outflow
    of that window (None: never)."""
    for n in range(window, len(q) + 1):
        check = flow_rate_convergence(q[:n], window, tolerance)
        if check.converged:
            return n, check.mean_m3_s
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("histories", nargs="+", type=Path, help="surfaceFieldValue.dat files of flowRateBottom")
    ap.add_argument("--tolerances", nargs="+", type=float, default=[5e-3, 1e-2])
    ap.add_argument("--window", type=int, default=200)
    args = ap.parse_args()
    seen: set[str] = set()
    totals = dict.fromkeys(args.tolerances, 0)
    for path in args.histories:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        if digest in seen:
            continue
        seen.add(digest)
        q = np.abs(np.loadtxt(path, comments="#")[:, 1])
        own = flow_rate_convergence(q, args.window, 1.0).mean_m3_s
        cells = []
        for tol in args.tolerances:
            stop = stop_iteration(q, args.window, tol)
            if stop is None:
                totals[tol] += len(q)
                cells.append(f"{tol:g}: not met ({len(q)} run)")
            else:
                n, mean = stop
                totals[tol] += n
                cells.append(f"{tol:g}: {n} ({100.0 * (mean / own - 1.0):+.2f} %)")
        print(f"{'/'.join(path.parts[-7:-5])}: " + " | ".join(cells))
    print("total iterations: " + ", ".join(f"{tol:g}: {n}" for tol, n in totals.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
