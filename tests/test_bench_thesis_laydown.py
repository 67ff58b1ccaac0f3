# SPDX-License-Identifier: GPL-3.0-or-later
"""The sheet measures of bench/laydown/run_thesis.py (grammage map, mass profile, comparison with a
reference sheet) against hand-computed values of a two-fiber sheet."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import yaml

from bench_scripts import load_bench_script


@pytest.fixture(scope="module")
def bench() -> Any:
    return load_bench_script("bench/laydown/run_thesis.py", "run_thesis")


def write_run(d: Path, shift_m: float = 0.0) -> None:
    """Two fibers on a 3 x 3 mm piece (fabric top z = 2.0 mm): fiber 0 (3 nodes, 6 ug) in the
    corner bin near the fabric top, fiber 2 (2 nodes, 4 ug; fiber 1 was removed) in the last bin,
    15 um higher (+ shift_m)."""
    (d / "fibers").mkdir(parents=True)
    (d / "laydown").mkdir()
    (d / "scene.yaml").write_text(yaml.safe_dump({"fabric": {"size_x_m": 3e-3, "size_y_m": 3e-3}}))
    with h5py.File(d / "fibers" / "fibers.h5", "w") as f:
        f["fibers/mass"] = np.array([6e-9, 1e-9, 4e-9])
    x = np.array([[1e-4, 1e-4, 2.002e-3], [2e-4, 1e-4, 2.002e-3], [3e-4, 1e-4, 2.002e-3],
                  [2.9e-3, 2.9e-3, 2.017e-3 + shift_m], [2.8e-3, 2.9e-3, 2.017e-3 + shift_m]])
    with h5py.File(d / "laydown" / "laydown.h5", "w") as h:
        h["sheet/x"] = x
        h["sheet/fiber_id"] = np.array([0, 2])
        h["sheet/offsets"] = np.array([0, 3, 5])
        h["snapshots/min_fiber_fiber_gap"] = np.array([1e-9])  # read by products.read_sheet
        h["snapshots/min_element_clearance"] = np.array([1e-5])
        h.create_group("run").attrs["fabric_top_m"] = 2.0e-3


def test_sheet_measures_hand_values(bench: Any, tmp_path: Path) -> None:
    write_run(tmp_path)
    m = bench.sheet_measures(tmp_path)
    cell = (3e-3 / bench.MAP_BINS) ** 2
    assert m["map"].shape == (bench.MAP_BINS, bench.MAP_BINS)
    assert m["map"][0, 0] == pytest.approx(6e-9 / cell, rel=1e-12)
    assert m["map"][-1, -1] == pytest.approx(4e-9 / cell, rel=1e-12)
    assert m["map"].sum() * cell == pytest.approx(10e-9, rel=1e-12)  # the removed fiber not counted
    # profile: slabs of 10 um from 100 um below the fabric top: fiber 0 in slab 10, fiber 2 in slab 11
    prof = m["profile"]
    area = 9e-6
    assert prof[10] == pytest.approx(6e-9 / area, rel=1e-12)
    assert prof[11] == pytest.approx(4e-9 / area, rel=1e-12)
    assert prof.sum() == pytest.approx(10e-9 / area, rel=1e-12)


def test_compare_with_reference(bench: Any, tmp_path: Path) -> None:
    write_run(tmp_path / "ref")
    write_run(tmp_path / "var", shift_m=10e-6)  # fiber 2 one slab higher
    common = {"ranks": 2, "grammage_kg_m2": 1.0}
    ref = {"variant": "newton", "run_dir": str(tmp_path / "ref"), "sheet_thickness_m": 20e-6,
           "laydown_wall_s": 100.0, **common}
    row = {"variant": "loose", "run_dir": str(tmp_path / "var"), "sheet_thickness_m": 30e-6,
           "laydown_wall_s": 40.0, **common}
    c = bench.compare(row, ref)
    assert c["thickness_change_rel"] == pytest.approx(0.5)
    assert c["wall_ratio"] == pytest.approx(0.4)
    assert c["grammage_map_max_diff_rel"] == 0.0  # same bins
    # the profile: 4 ug moved from slab 11 to slab 12; the reference's largest slab holds 6 ug
    assert c["profile_max_diff_rel"] == pytest.approx(4.0 / 6.0, rel=1e-12)


def test_periodic_sheet_measures_wrap_the_unwrapped_chains(bench: Any, tmp_path: Path) -> None:
    """A periodic lay-down stores unwrapped chains: a fiber whose nodes lie past the piece's sides
    counts in the bins of their images in the piece (x mod size), so no mass is lost from the map."""
    write_run(tmp_path)
    scene = yaml.safe_load((tmp_path / "scene.yaml").read_text())
    scene["laydown"] = {"walls": "periodic"}
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene))
    with h5py.File(tmp_path / "laydown" / "laydown.h5", "r+") as h:
        x = h["sheet/x"][...]
        x[3:5, 0] += 3e-3   # fiber 2 one period further in x: the same images
        x[0:3, 1] -= 3e-3   # fiber 0 one period back in y
        h["sheet/x"][...] = x
    m = bench.sheet_measures(tmp_path)
    cell = (3e-3 / bench.MAP_BINS) ** 2
    assert m["map"][0, 0] == pytest.approx(6e-9 / cell, rel=1e-9)
    assert m["map"][-1, -1] == pytest.approx(4e-9 / cell, rel=1e-9)
    assert m["map"].sum() * cell == pytest.approx(10e-9, rel=1e-12)


def test_repeat_piece_is_whole_weave_repeats_at_the_case_grammage(bench: Any) -> None:
    """The thesis fabric (shed 8, 3000 weft columns and 5000 warps per metre) repeats every
    8/3000 m along x and 8/5000 m along y: the 3 x 3 mm case piece becomes 1 x 2 repeats,
    2.6667 x 3.2 mm, with the injected mass scaled by the area (the same injected grammage)."""
    data = yaml.safe_load((bench.THESIS / "case-C-circular.yaml").read_text())
    mass = float(data["fibers"]["target_mass_kg"])
    bench.repeat_piece(data)
    sx, sy = data["fabric"]["size_x_m"], data["fabric"]["size_y_m"]
    assert sx == pytest.approx(8 / 3000, rel=1e-12) and sy == pytest.approx(2 * 8 / 5000, rel=1e-12)
    assert data["fibers"]["target_mass_kg"] / (sx * sy) == pytest.approx(mass / 9e-6, rel=1e-12)
    assert data["fiber_generation"]["placement_hi_m"][:2] == [sx, sy]
    name, scene = bench.scene_for("A-circular", "loose_periodic", 2, 1, None, Path("runs/x"))
    assert scene["laydown"]["walls"] == "periodic" and scene["fabric"]["size_x_m"] == pytest.approx(sx)
