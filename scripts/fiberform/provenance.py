# SPDX-License-Identifier: GPL-3.0-or-later
"""Provenance of stage products and atomic writes.

Every stage HDF5 file records on its root group (after signac's h5store and pyiron's job groups):

=================  ==========================================================
attribute          meaning
=================  ==========================================================
``stage``          stage name (``demo-particles``)
``fiberform``      package version, e.g. ``0.1.0``
``git_revision``   short commit, ``-dirty`` if modified, ``unknown`` outside git
``build_revision`` the commit the build folder's binaries come from (its ``REVISION`` file:
                   :func:`fiberform._versions.build_revision`), ``unknown`` without one
``scene_json``     the validated scene, defaults filled in, as canonical JSON
``seed``           the scene's seed
``input_hashes``   JSON object: input name -> ``sha256:<hex>``
``created_utc``    ISO 8601 time of writing
``options``        JSON object of the command-line options that shaped the run
=================  ==========================================================

Datasets written through :func:`write_dataset` carry ``units`` (and ``description``) attributes.
Files are written as ``<file>.in_progress`` and renamed with :func:`os.replace` when complete, so a
product that exists is whole.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from ._versions import build_revision, git_revision, package_version
from .scene import Scene

__all__ = [
    "IN_PROGRESS",
    "atomic_h5",
    "atomic_write_text",
    "file_hash",
    "in_progress_path",
    "read_provenance",
    "text_hash",
    "write_dataset",
    "write_provenance",
]

IN_PROGRESS = ".in_progress"


def in_progress_path(path: Path) -> Path:
    """``particles.h5`` -> ``particles.h5.in_progress``."""
    return path.with_name(path.name + IN_PROGRESS)


def text_hash(text: str | bytes) -> str:
    data = text.encode() if isinstance(text, str) else text
    return "sha256:" + hashlib.sha256(data).hexdigest()


def file_hash(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return "sha256:" + h.hexdigest()


def machine_info() -> dict[str, object]:
    """The machine a benchmark ran on: CPU model, cores, Python version, load average at start."""
    import platform

    model = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model, "cores": os.cpu_count(), "python": platform.python_version(),
            "load_average_at_start": os.getloadavg()}


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``path`` through ``<path>.in_progress`` and a rename."""
    tmp = in_progress_path(path)
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_h5(path: Path) -> Iterator[h5py.File]:
    """Open ``<path>.in_progress`` for writing; rename to ``path`` if the block succeeds,
    delete it if the block raises."""
    tmp = in_progress_path(path)
    tmp.unlink(missing_ok=True)
    try:
        with h5py.File(tmp, "w") as f:
            yield f
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_provenance(
    f: h5py.File,
    stage: str,
    scene: Scene,
    input_hashes: Mapping[str, str],
    options: Mapping[str, Any] | None = None,
    build: Path | None = None,
) -> None:
    """Write the provenance attributes (see the module docstring) on the root group; ``build``:
    the build folder whose binaries the stage ran (``build_revision``; ``unknown`` when None)."""
    f.attrs["stage"] = stage
    f.attrs["fiberform"] = package_version()
    f.attrs["git_revision"] = git_revision()
    f.attrs["build_revision"] = build_revision(build) if build is not None else "unknown"
    f.attrs["scene_json"] = scene.to_json()
    f.attrs["seed"] = np.int64(scene.seed)
    f.attrs["input_hashes"] = json.dumps(dict(input_hashes), sort_keys=True)
    f.attrs["created_utc"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    f.attrs["options"] = json.dumps(dict(options or {}), sort_keys=True)


def report_origin(h5: h5py.File) -> str:
    """The line a stage's ``report.md`` states its origin with, from the provenance already on
    the root of the stage's HDF5 product (:func:`write_provenance`): scene, seed, the Python
    package's version and revision and the binaries' build revision."""
    a = h5.attrs

    def text(key: str) -> str:
        v = a.get(key, "unknown")
        return v.decode() if isinstance(v, bytes) else str(v)

    name = json.loads(text("scene_json")).get("name", "?") if "scene_json" in a else "?"
    return (f"Made from scene `{name}`, seed {text('seed')}, by fiberform {text('fiberform')} (Python at "
            f"{text('git_revision')}, binaries of build {text('build_revision')}); the HDF5 product's root "
            "attributes hold the whole scene, its input hashes and the options.")


def read_provenance(path: Path) -> dict[str, Any]:
    """The root attributes of a stage file, JSON attributes decoded. Raises OSError if the
    file cannot be read as HDF5."""
    out: dict[str, Any] = {}
    with h5py.File(path, "r") as f:
        for key, value in f.attrs.items():
            if isinstance(value, bytes):
                value = value.decode()
            if key in ("input_hashes", "options") and isinstance(value, str):
                value = json.loads(value)
            elif isinstance(value, np.generic):
                value = value.item()
            out[key] = value
    return out


def write_dataset(
    group: h5py.Group,
    name: str,
    data: npt.ArrayLike,
    units: str,
    description: str,
) -> h5py.Dataset:
    """A dataset with ``units`` (``"1"`` for dimensionless) and ``description`` attributes."""
    ds = group.create_dataset(name, data=np.asarray(data))
    ds.attrs["units"] = units
    ds.attrs["description"] = description
    return ds


def append_result_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """Append ``rows`` to the ``rows`` list of the JSON results file ``path`` (created with its
    folder when missing; written through a rename: a killed benchmark leaves the old file)."""
    old = json.loads(path.read_text()).get("rows", []) if path.is_file() else []
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps({"rows": old + rows}, indent=2) + "\n")
