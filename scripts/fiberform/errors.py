# SPDX-License-Identifier: GPL-3.0-or-later
"""Exceptions of fiberform and the exit status each one maps to in the CLI.

* exit 2 (bad input): :class:`SceneError`, :class:`InputFormatError`, :class:`ConfigError`
* exit 1 (run failure): :class:`RunError`, :class:`StageError`
"""

from __future__ import annotations

__all__ = [
    "Terminated",
    "ConfigError",
    "FiberformError",
    "InputFormatError",
    "RunError",
    "SceneError",
    "StageError",
]


class FiberformError(Exception):
    """Base class of every error fiberform reports to the user without a traceback."""

    exit_status: int = 1


class SceneError(FiberformError):
    """The scene file is missing, is not valid YAML, or does not satisfy the schema.

    ``problems`` holds one line per problem, each naming the field path (``fibers.length_m``),
    the value given and what is allowed.
    """

    exit_status = 2

    def __init__(self, source: str, problems: list[str], what: str = "invalid scene") -> None:
        self.source = source
        self.problems = list(problems)
        count = len(self.problems)
        head = f"{source}: {what} ({count} problem{'s' if count != 1 else ''})"
        if count == 1:
            super().__init__(f"{source}: {what}: {self.problems[0]}")
        else:
            super().__init__("\n".join([head, *(f"  - {p}" for p in self.problems)]))


class InputFormatError(FiberformError, ValueError):
    """A value that is not a finite number, an int or a validated identifier was about to be
    written into a LIGGGHTS or OpenFOAM input. This is a programming error or an attack."""

    exit_status = 2


class ConfigError(FiberformError):
    """A bad command-line option or environment (e.g. more MPI ranks than cores)."""

    exit_status = 2


class RunError(FiberformError):
    """An external program (fiberdem, an OpenFOAM utility, mpirun) failed.

    The message holds the command, the exit status and the last lines of its log.
    """

    exit_status = 1

    def __init__(
        self, cmd: list[str], returncode: int | None, log: str, tail: list[str], reason: str = ""
    ) -> None:
        self.cmd = list(cmd)
        self.returncode = returncode
        self.log = log
        self.tail = list(tail)
        status = (
            "could not be started" if returncode is None else f"exited with status {returncode}"
        )
        lines = [
            f"command {status}{': ' + reason if reason else ''}",
            f"  command: {' '.join(cmd)}",
            f"  log:     {log}",
        ]
        if tail:
            lines.append(f"  last {len(tail)} lines of the log:")
            lines.extend(f"    | {t}" for t in tail)
        super().__init__("\n".join(lines))


class StageError(FiberformError):
    """A stage could not produce its products (missing input, unreadable result, ...)."""

    exit_status = 1


class Terminated(BaseException):  # noqa: N818 - a signal, like KeyboardInterrupt
    """SIGTERM arrived (a batch system's time limit, ``kill``): raised in the main thread so the
    running program is stopped, the stage records ``failed`` and nothing half-written stays."""

    def __str__(self) -> str:
        return "terminated (SIGTERM)"
