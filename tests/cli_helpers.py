# SPDX-License-Identifier: GPL-3.0-or-later
"""Helpers of the command-line tests (tests/test_pipeline.py, test_submit.py,
test_laydown_resume.py): reading `fiberform status` output and finding processes left behind."""

from __future__ import annotations

import os
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
