# SPDX-License-Identifier: GPL-3.0-or-later
"""Helpers of the command-line tests (tests/test_pipeline.py, test_submit.py,
test_laydown_resume.py, test_flow.py, test_permeability.py): reading `fiberform status` output,
killing a stage mid-run and finding processes left behind."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path


def parse_status(stdout: str) -> dict[str, tuple[str, str]]:
    """`fiberform status` output -> {stage: (state, detail)} (the first line names the scene)."""
    out = {}
    for line in stdout.splitlines()[1:]:
        name, state, *detail = line.split(maxsplit=2)
        out[name] = (state, detail[0] if detail else "")
    return out


def processes_under(d: Path) -> list[str]:
    """Command lines of the processes (other than this one) whose working directory lies under d."""
    out = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            if Path(os.readlink(f"/proc/{pid}/cwd")).is_relative_to(d) and int(pid) != os.getpid():
                out.append(Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode())
        except OSError:
            continue
    return out


def terminate_when(cmd: Sequence[str], cwd: Path, marker: Path | Callable[[], bool],
                   timeout_s: float = 300, kill_group: bool = False) -> int:
    """Start ``cmd`` in ``cwd`` (its own session), send it SIGTERM as soon as ``marker`` exists
    (a path) or returns True (a callable) and return its exit status (a stage ends with 143);
    ``kill_group``: SIGKILL to its whole process group instead (a node failure). AssertionError
    when the command ended before; the process group is killed in any case."""
    ready = marker if callable(marker) else marker.exists
    proc = subprocess.Popen(list(cmd), cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    seen = False
    try:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and proc.poll() is None:
            if ready():
                seen = True
                if kill_group:
                    os.killpg(proc.pid, signal.SIGKILL)
                else:
                    proc.send_signal(signal.SIGTERM)
                proc.wait(timeout=60)
                break
            time.sleep(0.02)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert seen, f"{' '.join(cmd)} ended before {marker} appeared"
    return proc.returncode
