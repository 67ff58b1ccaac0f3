# SPDX-License-Identifier: GPL-3.0-or-later
"""fiberform: simulator of early paper forming (fibers in LIGGGHTS, fluid in OpenFOAM).

The public Python API; the ``fiberform`` command (``fiberform.cli``) is built on it.
"""

from __future__ import annotations

from importlib import metadata as _metadata

from .errors import (
    ConfigError,
    FiberformError,
    InputFormatError,
    RunError,
    SceneError,
    StageError,
)
from .inputs import (
    LiggghtsInput,
    fmt_float,
    fmt_ident,
    fmt_int,
    fmt_value,
    foam_entry,
    foam_value,
    is_identifier,
)
from .provenance import atomic_h5, atomic_write_text, read_provenance, write_dataset
from .runner import RunResult, run
from .scene import Scene, load_scene, parse_scene
from .stages import STAGES, Stage, StageContext

try:
    __version__: str = _metadata.version("fiberform")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "STAGES",
    "ConfigError",
    "FiberformError",
    "InputFormatError",
    "LiggghtsInput",
    "RunError",
    "RunResult",
    "Scene",
    "SceneError",
    "Stage",
    "StageContext",
    "StageError",
    "__version__",
    "atomic_h5",
    "atomic_write_text",
    "fmt_float",
    "fmt_ident",
    "fmt_int",
    "fmt_value",
    "foam_entry",
    "foam_value",
    "is_identifier",
    "load_scene",
    "parse_scene",
    "read_provenance",
    "run",
    "write_dataset",
]
