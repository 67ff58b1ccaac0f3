#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""How much the machine's cores give when they all compute at once (the ceiling of any
multi-rank speed-up measured on it).

A fixed compute-bound kernel (a pure-Python loop: no memory traffic, no I/O, no MPI) runs first
alone, then as P copies at once (P = the number of cores the process may use, or ``--copies``).
On P independent cores each copy takes as long as the single run; on P virtual CPUs that share
physical cores (SMT siblings on the host, an oversubscribed host) each copy is slower. Reported:
the slowdown of a copy (t_P / t_1) and the machine's throughput in single-core units,
P t_1 / t_P, which bounds the speed-up of any P-rank run of compute-bound code on this machine
(a 2-rank lay-down cannot be faster than this times the 1-rank one).

    .venv/bin/python bench/machine/run_concurrency.py              # about 30 s
    .venv/bin/python bench/machine/run_concurrency.py --repeat 5 --loops 4e7

Run it on an idle machine (anything else running lowers both numbers). Writes
bench/machine/results/concurrency.json (the runs' wall times, their spread, the machine).
docs/bench/machine.md discusses the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "concurrency.json"


def kernel(loops: int) -> float:
    """Wall time (s) of ``loops`` floating-point additions in the interpreter loop."""
    t0 = time.perf_counter()
    s = 0.0
    for i in range(loops):
        s += i * 1e-9
    if s < 0.0:  # keeps the sum live
        print(s)
    return time.perf_counter() - t0


def cpu_model() -> str:
    """The first ``model name`` of /proc/cpuinfo (Linux), else platform.processor()."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--copies", type=int, default=len(os.sched_getaffinity(0)),
                    help="copies run at once (default: the usable cores)")
    ap.add_argument("--loops", type=float, default=2.0e7, help="loop iterations of one kernel run")
    ap.add_argument("--repeat", type=int, default=3, help="repetitions of each measurement")
    ap.add_argument("--out", type=Path, default=RESULTS, help="JSON file to write")
    a = ap.parse_args()
    if a.copies < 2 or a.copies > 1024:
        print(f"run_concurrency.py: --copies must be 2..1024, got {a.copies}", file=sys.stderr)
        return 2
    if not 1e5 <= a.loops <= 1e10 or not 1 <= a.repeat <= 100:
        print("run_concurrency.py: --loops must be 1e5..1e10 and --repeat 1..100", file=sys.stderr)
        return 2
    loops = int(a.loops)
    single: list[float] = []
    together: list[list[float]] = []
    with ProcessPoolExecutor(max_workers=a.copies) as pool:
        list(pool.map(kernel, [loops // 20] * a.copies))  # start the workers, warm up
        for _ in range(a.repeat):
            single.append(pool.submit(kernel, loops).result())
            together.append(list(pool.map(kernel, [loops] * a.copies)))
    t1 = statistics.median(single)
    tp = statistics.median([max(r) for r in together])
    slowdown = tp / t1
    result = {
        "what": "bench/machine/run_concurrency.py: a compute-bound kernel alone and as P copies at once",
        "machine": {"node": platform.node(), "cpu_count": os.cpu_count(),
                    "usable_cores": len(os.sched_getaffinity(0)), "processor": cpu_model(),
                    "python": platform.python_version()},
        "loops": loops, "copies": a.copies, "repeat": a.repeat,
        "single_s": single, "together_s": together,
        "slowdown_per_copy": slowdown,
        "throughput_cores": a.copies / slowdown,
        "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    print(f"one copy alone: {t1:.3f} s (runs {', '.join(f'{t:.3f}' for t in single)})")
    print(f"{a.copies} copies at once: {tp:.3f} s, the slowest of each run "
          f"({', '.join(f'{max(r):.3f}' for r in together)})")
    print(f"slowdown per copy {slowdown:.2f}; throughput {a.copies / slowdown:.2f} single-core units "
          f"on {a.copies} cores (the ceiling of a {a.copies}-rank speed-up of compute-bound code)")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile("w", dir=a.out.parent, delete=False, suffix=".tmp") as fh:
        json.dump(result, fh, indent=1)
        fh.write("\n")
    os.replace(fh.name, a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
