# SPDX-License-Identifier: GPL-3.0-or-later
"""The sheet's thickness above the fabric top (issue 15: the number compared with the thesis'
Table 4.1), against hand-computed values (no simulation):

- ``fiber_sheet.thickness_above_fabric``: the 95th percentile (numpy's linear interpolation) of
  the fibers' upper surfaces minus the fabric top; one short fiber lying on top does not set it;
  a sheet sunk into the fabric is 0 thick (clipped, never negative);
- ``fiber_sheet.upper_surfaces``: node z + half the fiber's thickness, circular (the largest
  radius of the fiber's nodes) and rectangular (the largest half of the thin axis);
- the lay-down and press stages' metrics from stored products that predate the metric (no run
  attribute): ``sheet_thickness_above_fabric_m``, ``pressed_thickness_above_fabric_m``.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from fiberform.fiber_sheet import (
    product_thickness_above_fabric, sheet_thickness_above_fabric, thickness_above_fabric, upper_surfaces,
)
from fiberform.products import sheet_chains
from fiberform.scene import Scene, parse_scene, read_scene_yaml
from fiberform.stages import StageContext
from fiberform.stages.laydown import Laydown
from fiberform.stages.press import Press

ROOT = Path(__file__).resolve().parents[1]
UM = 1e-6


def test_95th_percentile_minus_the_fabric_top() -> None:
    # 20 tops 100, 101, ..., 119 um on a fabric top at 100 um: position 0.95 x 19 = 18.05 between
    # 118 and 119 um -> 118.05 um, i.e. 18.05 um above the fabric
    tops = (100.0 + np.arange(20.0)) * UM
    assert thickness_above_fabric(tops, 100 * UM) == pytest.approx(18.05 * UM, rel=1e-12)
    assert thickness_above_fabric(tops[::-1], 100 * UM) == pytest.approx(18.05 * UM, rel=1e-12)  # order-free
    # another percentile: the median, position 9.5 -> 109.5 um
    assert thickness_above_fabric(tops, 100 * UM, percentile=50.0) == pytest.approx(9.5 * UM, rel=1e-12)
    # the fabric top is subtracted: 10 um higher, 10 um thinner
    assert thickness_above_fabric(tops, 110 * UM) == pytest.approx(8.05 * UM, rel=1e-12)


def test_one_fiber_on_top_does_not_set_it() -> None:
    # 39 nodes with their tops 10 um above the fabric, one short fiber (2 nodes) lying 400 um up:
    # 41 samples, position 0.95 x 40 = 38 -> the 39th lowest, 10 um (the maximum would say 400 um)
    tops = np.concatenate([np.full(39, 10.0), [400.0, 400.0]]) * UM
    assert thickness_above_fabric(tops, 0.0) == pytest.approx(10 * UM, rel=1e-12)
    assert thickness_above_fabric(tops, 0.0, percentile=100.0) == pytest.approx(400 * UM, rel=1e-12)


def test_a_sheet_sunk_into_the_fabric_is_zero_thick() -> None:
    top = 2.637e-3
    sunk = top - np.array([5.0, 10.0, 20.0, 80.0]) * UM  # every upper surface below the fabric top
    assert thickness_above_fabric(sunk, top) == 0.0
    assert thickness_above_fabric(np.zeros(0), top) == 0.0  # no fibers
    # a sheet just above: 95th percentile of (top - 5, top + 1) um = top - 5 + 0.95 x 6 = top + 0.7 um
    assert thickness_above_fabric(np.array([top - 5 * UM, top + 1 * UM]), top) == pytest.approx(0.7 * UM, rel=1e-9)


def test_upper_surfaces_by_section() -> None:
    """Node z + half the fiber's thickness: circular the largest a1/a2 of the fiber's nodes,
    rectangular the largest min(a1, a2) (the collapsed fiber lies flat)."""
    x = np.array([[0, 0, 100], [10, 0, 102], [20, 0, 101], [0, 50, 90], [10, 50, 95]], dtype=float) * UM
    offsets = np.array([0, 3, 5])
    axes = np.array([[15, 15], [16, 16], [15.5, 15.5], [16.2, 4.1], [15.9, 3.9]]) * UM
    circ = upper_surfaces(sheet_chains(x, offsets, axes, "circular"))
    np.testing.assert_allclose(circ / UM, [116, 118, 117, 106.2, 111.2], rtol=1e-12)
    rect = upper_surfaces(sheet_chains(x, offsets, axes, "rectangular"))
    np.testing.assert_allclose(rect / UM, [116, 118, 117, 94.1, 99.1], rtol=1e-12)
    assert upper_surfaces([]).shape == (0,)
    with pytest.raises(ValueError, match="half-axes"):
        sheet_chains(x, offsets, axes[:4])


def _scene(section: str) -> Scene:
    """The thesis' case-A scene of ``section``, output folder ``out`` (of the working directory)."""
    data = read_scene_yaml((ROOT / "scenes" / "thesis" / f"case-A-{section}.yaml").read_text())
    data["output_dir"] = "out"
    return parse_scene(data, f"case A {section}")


def _old_products(root: Path) -> None:
    """fibers.h5 with two fibers (radii a1, a2 per node) and a laydown.h5 / press.h5 as earlier
    runs wrote them (no thickness-above-fabric attribute); only fiber 1 is on the sheet."""
    (root / "fibers").mkdir(parents=True)
    (root / "laydown").mkdir()
    (root / "press").mkdir()
    with h5py.File(root / "fibers" / "fibers.h5", "w") as f:
        f["fibers/offsets"] = np.array([0, 2, 5])
        f["fibers/radii"] = np.array([[9, 9, 0, 0], [9, 9, 0, 0], [16.2, 4.1, 0, 0],
                                      [15.9, 3.9, 0, 0], [16.0, 4.0, 0, 0]]) * UM
    x = np.array([[0, 0, 1000], [10, 0, 1004], [20, 0, 1008]], dtype=float) * UM
    with h5py.File(root / "laydown" / "laydown.h5", "w") as f:
        f["sheet/x"], f["sheet/offsets"], f["sheet/fiber_id"] = x, np.array([0, 3]), np.array([1])
        f.create_group("run").attrs.update({"settled": True, "simulated_time_s": 0.01, "sheet_thickness_m": 50 * UM,
                               "grammage_kg_m2": 1e-3, "fabric_top_m": 1000 * UM})
    with h5py.File(root / "press" / "press.h5", "w") as f:
        f["sheet/x"], f["sheet/offsets"], f["sheet/fiber_id"] = x - [0, 0, 3 * UM], np.array([0, 3]), np.array([1])
        f["curve/plate_z"] = np.array([1030, 1012]) * UM
        f["curve/pressure"] = np.array([0.0, 2.0])
        f["curve/thickness_span"] = np.array([50, 45]) * UM
        f.create_group("run").attrs.update({"fabric_top_z_m": 1000 * UM, "stopped_by_guard": 1})


@pytest.mark.parametrize("section, half", [("circular", 16.2), ("rectangular", 4.1)])
def test_stage_metrics_from_older_products(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, section: str,
                                           half: float) -> None:
    """Tops 1000, 1004, 1008 um + half; fabric top 1000 um: 95th percentile = 1000 + 7.6 + half
    (position 1.9 of 0, 4, 8); the pressed sheet 3 um lower."""
    monkeypatch.chdir(tmp_path)
    scene = _scene(section)
    assert scene.fibers is not None and scene.fibers.cross_section == section
    _old_products(scene.output_path)
    ctx = StageContext(scene=scene, scene_path=tmp_path / "s.yaml", build_dir=tmp_path)
    m = Laydown().metrics(ctx)
    assert m["sheet_thickness_above_fabric_m"] == pytest.approx((7.6 + half) * UM, rel=1e-9)
    assert m["sheet_thickness_m"] == 50 * UM  # the span stays
    assert f"{7.6 + half:.1f} um above the fabric top" in Laydown().results(ctx)[0]
    p = Press().metrics(ctx)
    assert p["pressed_thickness_above_fabric_m"] == pytest.approx((4.6 + half) * UM, rel=1e-9)
    assert p["press_plate_gap_m"] == pytest.approx(12 * UM) and p["pressed_span_thickness_m"] == 45 * UM
    # the arrays' twin (the stages' collect) gives the same number
    with h5py.File(scene.output_path / "laydown" / "laydown.h5") as f:
        arrays = (f["sheet/x"][...], f["sheet/offsets"][...], f["sheet/fiber_id"][...])
    assert sheet_thickness_above_fabric(scene, *arrays, 1000 * UM) == m["sheet_thickness_above_fabric_m"]
    # a fabric top above every upper surface: 0, not negative
    assert product_thickness_above_fabric(scene, scene.output_path / "laydown" / "laydown.h5", 1030 * UM) == 0.0
