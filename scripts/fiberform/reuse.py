# SPDX-License-Identifier: GPL-3.0-or-later
"""Reuse of finished stage folders of a sibling run (issues 10 and 15).

Two runs whose scenes agree in everything an upstream stage reads (its ``uses`` sections, its
upstream products, its binaries and code version) would compute the same products. Instead of
running that stage twice, :func:`adopt_stages` copies the donor run's stage folder into the target
run, but only where the stage mechanism itself will then find the copy up to date: the donor's
HDF5 product must record exactly the input hashes that the target's stage computes now
(:meth:`fiberform.stages.Stage.input_hashes`, :meth:`~fiberform.stages.Stage.up_to_date`). So a
copied stage is skipped by ``fiberform run``, and a stage whose inputs differ is not copied at
all: it runs as usual. The copied products are left byte for byte as the donor made them (the
downstream stages hash them), so they name the donor's scene in their provenance; the copy's
``ADOPTED_NAME`` (``adopted.json``) records where it came from, into which scene, and the input
hashes that made it valid.

Users: ``bench/laydown/run_thesis.py`` (the generate, fabric and flow stages of another variant of
the same case and seed) and the validation campaign (:mod:`fiberform.campaign`: the pressure
press of a laid-down sheet reuses the velocity press run's generate, fabric, flow, lay-down and
unpressed permeability).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Literal

from .errors import ConfigError
from .pipeline import StageGraph, applicable_stages
from .provenance import read_provenance
from .stages import StageContext
from .stages._stage import STATE_NAME

__all__ = ["ADOPTED_NAME", "Adoption", "adopt_stages"]

#: the record of a copied stage folder (donor folder, target scene, input hashes, time)
ADOPTED_NAME = "adopted.json"

Action = Literal["kept", "copied", "absent", "differs", "busy"]


@dataclass(frozen=True)
class Adoption:
    """What :func:`adopt_stages` did with one stage of the target run.

    ``kept``: the target's own folder is already up to date; ``copied``: the donor's folder was
    copied and is up to date in the target; ``absent``: the donor has no finished products (not
    run, running, or failed); ``differs``: the donor's products were made from other inputs than
    the target's stage has now (``detail`` names them); ``busy``: the target's stage is running.
    """

    stage: str
    action: Action
    detail: str = ""

    @property
    def up_to_date(self) -> bool:
        return self.action in ("kept", "copied")


def _state(folder: Path) -> str | None:
    """The ``stage-state.json`` state of a stage folder (running / failed), None without one."""
    f = folder / STATE_NAME
    if not f.is_file():
        return None
    try:
        return str(json.loads(f.read_text()).get("state", "failed"))
    except (OSError, ValueError):
        return "failed"


def adopt_stages(target: StageContext, donor_root: Path, stages: Sequence[str]) -> list[Adoption]:
    """Make the named stages of the target run (``target``: its scene, whose ``output_path`` is
    where its stage folders live, and the build directory) up to date from the donor run's output
    folder ``donor_root`` where the donor's products fit the target's inputs; in pipeline order,
    so that each stage's hashes see the upstream folders copied before it. A target folder that
    is up to date is kept; one that is stale or failed is replaced by the donor's; a running one
    is left alone. Nothing else is written. ConfigError for a stage the target's scene does not
    enable."""
    graph = StageGraph(applicable_stages(target.scene), target)
    unknown = [s for s in stages if s not in graph.stages]
    if unknown:
        raise ConfigError(f"stage {unknown[0]!r}: not a stage of {target.scene_path} "
                          f"(its stages: {', '.join(graph.order)})")
    root = target.scene.output_path
    out: list[Adoption] = []
    for name in (n for n in graph.order if n in stages):
        st = graph.stages[name]
        hashes = st.input_hashes(target)
        dst = st.stage_dir(target)
        if st.up_to_date(target, hashes):
            out.append(Adoption(name, "kept"))
            continue
        if _state(dst) == "running":
            out.append(Adoption(name, "busy", f"{dst / STATE_NAME} says running"))
            continue
        src = donor_root / dst.relative_to(root)
        first = src / st.products[0]
        if _state(src) is not None or not all((src / p).is_file() for p in st.products):
            out.append(Adoption(name, "absent", f"{src}: no finished products"))
            continue
        try:
            recorded = read_provenance(first)
        except OSError as exc:
            out.append(Adoption(name, "absent", f"{first}: unreadable ({exc})"))
            continue
        made = recorded.get("input_hashes", {}) if recorded.get("stage") == name else {}
        changed = sorted(k for k in set(hashes) | set(made) if hashes.get(k) != made.get(k))
        if changed:
            out.append(Adoption(name, "differs", f"{src}: made from other inputs ({', '.join(changed)})"))
            continue
        tmp = dst.with_name(dst.name + ".adopting")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(src, tmp)
        (tmp / ADOPTED_NAME).write_text(json.dumps({
            "stage": name, "adopted_from": str(src.resolve()), "into_scene": str(target.scene_path),
            "input_hashes": dict(hashes), "time": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        }, indent=1) + "\n")
        if dst.exists():
            shutil.rmtree(dst)
        tmp.rename(dst)
        if st.up_to_date(target, hashes):
            out.append(Adoption(name, "copied", f"from {src}"))
        else:  # the donor changed while it was copied
            out.append(Adoption(name, "differs", f"{src}: changed while it was copied"))
    return out
