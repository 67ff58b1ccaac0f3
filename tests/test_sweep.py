# SPDX-License-Identifier: GPL-3.0-or-later
"""``fiberform sweep`` and ``fiberform collect`` (issue 14): 2 values x 2 seeds through the real
generate stage, one CSV row per variant, and bad sweeps refused with nothing written."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from fiberform._versions import build_dir, build_revision
from fiberform.provenance import read_provenance
from fiberform.reuse import ADOPTED_NAME

from test_generate import SCENE as GENERATE_SCENE  # noqa: E402 - the generate tests' scene

SCENE = GENERATE_SCENE.replace("name: gen_test", "name: sw")


def _ff(d: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fiberform", *args], cwd=d, capture_output=True, text=True,
                          errors="replace", timeout=600, check=False)


def test_two_values_by_two_seeds(tmp_path: Path) -> None:
    (tmp_path / "s.yaml").write_text(SCENE)
    r = _ff(tmp_path, "sweep", "s.yaml", "--set", "fibers.target_mass_kg=1.0e-9,2.5e-9", "--seeds", "2")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    sweep = tmp_path / "runs" / "sw-sweep"
    rec = json.loads((sweep / "sweep.json").read_text())
    assert [(v["values"]["fibers.target_mass_kg"], v["seed"]) for v in rec["variants"]] == [
        (1.0e-9, 3), (1.0e-9, 4), (2.5e-9, 3), (2.5e-9, 4)]
    r = _ff(tmp_path, "collect", str(sweep))
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader((sweep / "collect.csv").open()))
    assert len(rows) == 4 and (sweep / "collect.png").stat().st_size > 0
    for row, v in zip(rows, rec["variants"], strict=True):
        assert row["variant"] == v["name"] and int(row["seed"]) == v["seed"]
        # generation adds fibers until the target mass is reached: target <= mass < target + one fiber
        with h5py.File(tmp_path / v["output_dir"] / "fibers" / "fibers.h5") as h5:
            heaviest = float(np.max(h5["fibers/mass"][...]))
            assert h5.attrs["seed"] == v["seed"]
        target = float(row["fibers.target_mass_kg"])
        assert target <= float(row["fiber_mass_kg"]) < target + heaviest, row
        assert float(row["generate_wall_s"]) > 0
        prov = read_provenance(tmp_path / v["output_dir"] / "fibers" / "fibers.h5")
        assert row["generate_git_revision"] == prov["git_revision"] != ""
        # the build folder's REVISION (cmake/WriteRevision.cmake), "unknown" without one
        assert row["generate_build_revision"] == prov["build_revision"] == build_revision(build_dir())
    # the seeds give different fiber sets; a second sweep finds every variant up to date
    assert rows[0]["fiber_mass_kg"] != rows[1]["fiber_mass_kg"]
    again = _ff(tmp_path, "sweep", "s.yaml", "--set", "fibers.target_mass_kg=1.0e-9,2.5e-9", "--seeds", "2")
    assert again.returncode == 0 and again.stdout.count("generate: up to date") == 4, again.stdout


@pytest.mark.parametrize("args, words", [
    (["--set", "fibers.target_mass_kg=-1.0e-9,1.0e-9"], "fibers.target_mass_kg"),
    (["--set", "fibers.no_such_field=1"], "no_such_field"),
    (["--set", "seed=1,2"], "--set"),
    (["--set", "fibers.target_mass_kg"], "--set"),
    (["--set", "fibers.target_mass_kg=1e-9,1e-9"], "repeated"),
    (["--set", "fibers.width_m=[1,2]"], "--set"),
    (["--set", "fibers.length_m=1e-3", "--set", "fibers.length_m=2e-3"], "twice"),
    (["--seeds", "0"], "--seeds"),
    (["--to", "lay-down"], "--to 'lay-down'"),
    (["--set", "fibers.length_m=1.0e-3;rm,2.0e-3"], "fibers.length_m"),
    (["--jobs", "0"], "--jobs"),
    (["--jobs", "2", "--submit", "slurm"], "--jobs"),
    (["--no-share", "--submit", "slurm"], "--no-share"),
])
def test_bad_sweep_exits_2_and_writes_nothing(tmp_path: Path, args: list[str], words: str) -> None:
    (tmp_path / "s.yaml").write_text(SCENE)
    r = _ff(tmp_path, "sweep", "s.yaml", *args)
    assert r.returncode == 2, r.stdout + r.stderr
    assert words in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]


def test_jobs_run_variants_at_once_with_the_same_results(tmp_path: Path) -> None:
    """``--jobs 2``: 3 variants, two at a time (both first variants start before any ends), each
    with its output in <sweep dir>/scenes/<variant>.log; the fibers equal those of the same sweep
    run one variant after the other."""
    seq, par = tmp_path / "seq", tmp_path / "par"
    for d in (seq, par):
        d.mkdir()
        (d / "s.yaml").write_text(SCENE)
    r = _ff(seq, "sweep", "s.yaml", "--seeds", "3")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    r = _ff(par, "sweep", "s.yaml", "--seeds", "3", "--jobs", "2")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    events = [ln for ln in r.stdout.splitlines() if " started " in ln or " done in " in ln]
    assert len(events) == 6 and all(" started " in ln for ln in events[:2]), events
    rec = json.loads((par / "runs" / "sw-sweep" / "sweep.json").read_text())
    for v in rec["variants"]:
        log = par / "runs" / "sw-sweep" / "scenes" / f"{v['name']}.log"
        assert "generate" in log.read_text(), log
        with h5py.File(seq / v["output_dir"] / "fibers" / "fibers.h5") as a, \
                h5py.File(par / v["output_dir"] / "fibers" / "fibers.h5") as b:
            assert np.array_equal(a["fibers/x"][...], b["fibers/x"][...])


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_resume_reaches_every_variants_stages(tmp_path: Path, jobs: str) -> None:
    """``sweep --resume`` means ``run --resume`` in every variant, one after the other (the stage
    context's options) and with ``--jobs 2`` (each variant's ``fiberform run`` gets ``--resume``):
    the stages run with the option ``resume``, as their products' provenance records (a killed
    lay-down reads it to continue from its restart files). Without --resume they run without it."""
    for resume in (False, True):
        d = tmp_path / f"resume-{resume}"
        d.mkdir()
        (d / "s.yaml").write_text(SCENE)
        r = _ff(d, "sweep", "s.yaml", "--seeds", "2", "--jobs", jobs, *(["--resume"] if resume else []))
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
        rec = json.loads((d / "runs" / "sw-sweep" / "sweep.json").read_text())
        assert len(rec["variants"]) == 2
        for v in rec["variants"]:
            options = read_provenance(d / v["output_dir"] / "fibers" / "fibers.h5")["options"]
            assert bool(options.get("resume")) is resume, (v["name"], options)


def test_collect_without_a_sweep_exits_2(tmp_path: Path) -> None:
    r = _ff(tmp_path, "collect", "nowhere")
    assert r.returncode == 2 and "sweep.json" in r.stderr or "not found" in r.stderr, r.stderr


FABRIC_SCENE = """name: swf
run: {timestep_s: 1.0e-6, duration_s: 1.0e-3}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3, voxel_size_m: 10.0e-6}
flow: {cell_size_m: 50.0e-6, delta_p_Pa: 100.0}
"""


def test_sweep_from_checks_each_variants_own_upstream(tmp_path: Path) -> None:
    """``sweep --from flow`` needs the fabric of each VARIANT (its own output folder), not of the
    base scene, which a sweep never runs: with the variants' fabrics made it is accepted (nothing
    is run with --no-run); a variant without one is refused (exit 2) naming its folder."""
    (tmp_path / "s.yaml").write_text(FABRIC_SCENE)
    r = _ff(tmp_path, "sweep", "s.yaml", "--seeds", "2", "--to", "fabric")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert not (tmp_path / "runs" / "swf").exists()  # the base scene's own folder: never run
    r = _ff(tmp_path, "sweep", "s.yaml", "--seeds", "2", "--from", "flow", "--no-run")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    r = _ff(tmp_path, "sweep", "s.yaml", "--seeds", "3", "--from", "flow", "--no-run")
    assert r.returncode == 2, r.stdout + r.stderr
    assert "--from flow" in r.stderr and "swf_002" in r.stderr and "fabric" in r.stderr, r.stderr


SHARED_SCENE = SCENE.replace("name: sw", "name: sws") + "fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3}\n"


def _adopted(d: Path, variant: dict[str, Any], folder: str) -> dict[str, Any] | None:
    f = d / variant["output_dir"] / folder / ADOPTED_NAME
    return json.loads(f.read_text()) if f.is_file() else None


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_stages_alike_in_every_variant_run_once(tmp_path: Path, jobs: str) -> None:
    """A stage that several variants would compute from the same inputs runs once, in the first
    of them, and the others get a copy of its folder (fiberform.reuse.adopt_stages): the fabric
    of a seed ensemble (generate hashes the seed: each variant generates its own fibers); the
    fibers of a sweep over a fabric field at one seed (the fabrics differ: each its own). With
    --no-share every variant runs everything itself. Checked on the products: a copy is
    byte-identical to the donor's and records where it came from."""
    (tmp_path / "s.yaml").write_text(SHARED_SCENE)
    r = _ff(tmp_path, "sweep", "s.yaml", "--seeds", "3", "--jobs", jobs)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert r.stdout.count("== shared:") == 1 and "shared: fabric of 3 variants" in r.stdout, r.stdout
    rec = json.loads((tmp_path / "runs" / "sws-sweep" / "sweep.json").read_text())
    first, *others = rec["variants"]
    assert _adopted(tmp_path, first, "fabric") is None
    for v in others:
        got = _adopted(tmp_path, v, "fabric")
        assert got is not None and got["adopted_from"] == str((tmp_path / first["output_dir"] / "fabric").resolve())
        assert (tmp_path / v["output_dir"] / "fabric" / "fabric.h5").read_bytes() == \
            (tmp_path / first["output_dir"] / "fabric" / "fabric.h5").read_bytes()
        assert _adopted(tmp_path, v, "fibers") is None
    fibers = [(tmp_path / v["output_dir"] / "fibers" / "fibers.h5").read_bytes() for v in rec["variants"]]
    assert len(set(fibers)) == 3
    # a second sweep finds everything up to date: nothing run, nothing copied again
    again = _ff(tmp_path, "sweep", "s.yaml", "--seeds", "3", "--jobs", jobs)
    assert again.returncode == 0, again.stdout[-2000:] + again.stderr[-2000:]
    assert "[1/1] fabric: up to date" in again.stdout and again.stdout.count("fabric kept") == 2, again.stdout

    d = tmp_path / "by-fabric"
    d.mkdir()
    (d / "s.yaml").write_text(SHARED_SCENE)
    r = _ff(d, "sweep", "s.yaml", "--set", "fabric.md_diameter_m=0.10e-3,0.11e-3", "--jobs", jobs)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert r.stdout.count("== shared:") == 1 and "shared: generate of 2 variants" in r.stdout, r.stdout
    a, b = json.loads((d / "runs" / "sws-sweep" / "sweep.json").read_text())["variants"]
    assert _adopted(d, b, "fibers") is not None and _adopted(d, b, "fabric") is None
    assert (d / a["output_dir"] / "fabric" / "fabric.h5").read_bytes() != \
        (d / b["output_dir"] / "fabric" / "fabric.h5").read_bytes()

    d = tmp_path / "no-share"
    d.mkdir()
    (d / "s.yaml").write_text(SHARED_SCENE)
    r = _ff(d, "sweep", "s.yaml", "--seeds", "2", "--jobs", jobs, "--no-share")
    assert r.returncode == 0 and "shared" not in r.stdout, r.stdout[-2000:] + r.stderr[-2000:]
    for v in json.loads((d / "runs" / "sws-sweep" / "sweep.json").read_text())["variants"]:
        assert _adopted(d, v, "fabric") is None and (d / v["output_dir"] / "fabric" / "fabric.h5").is_file()
