# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage laydown (issue 5) on a tiny scene: exact mass accounting (injected = on the sheet +
removed, by fiber IDs and cross-checked with LIGGGHTS' node masses) and no fiber node inside a
yarn, at the end and at every snapshot."""

from __future__ import annotations

import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

pytestmark = pytest.mark.system

SCENE = """
name: tiny_laydown
seed: 3
run: {timestep_s: 1.0e-7, duration_s: 1.0e-3}
domain: {lo_m: [0.0, 0.0, 0.0], hi_m: [1.0e-3, 1.0e-3, 3.437e-3]}
fibers: {count: 6, length_m: 0.6e-3, width_m: 20.0e-6, segments: 12,
         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}
fiber_generation: {placement_lo_m: [0.0, 0.0, 2.66e-3], placement_hi_m: [1.0e-3, 1.0e-3, 3.43e-3]}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3}
flow: {delta_p_Pa: 100.0, cell_size_m: 50.0e-6, height_above_fabric_m: 0.8e-3}
laydown: {max_time_s: 0.012, check_interval_s: 5.0e-4, settle_speed_m_s: 2.0e-3, settle_checks: 3}
"""


@pytest.fixture(scope="module")
def laydown_run(tmp_path_factory: pytest.TempPathFactory, build_dir: Path,
                fiberform_cmd: list[str]) -> Path:
    if not (build_dir / "bin" / "fiberdem").is_file():
        pytest.skip("fiberdem not built")
    work = tmp_path_factory.mktemp("laydown")
    (work / "tiny.yaml").write_text(SCENE)
    proc = subprocess.run([*fiberform_cmd, "run", "tiny.yaml", "--build-dir", str(build_dir)],
                          cwd=work, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    return work / "runs" / "tiny_laydown"


def test_mass_accounting_is_exact(laydown_run: Path) -> None:
    with h5py.File(laydown_run / "fibers" / "fibers.h5", "r") as h:
        masses = h["fibers/mass"][...]
    with h5py.File(laydown_run / "laydown" / "laydown.h5", "r") as h:
        a = h["accounting"]
        on_sheet = h["sheet/fiber_id"][...]
        removed = a["removed_fiber_id"][...]
        assert sorted([*on_sheet, *removed]) == list(range(len(masses)))  # every fiber, once
        assert a["injected_mass"][()] == pytest.approx(masses.sum(), rel=1e-15)
        assert a["sheet_mass"][()] + a["removed_mass"][()] == pytest.approx(
            a["injected_mass"][()], rel=1e-14)
        # LIGGGHTS' node masses of the fibers left agree with fibers.h5's fiber masses
        assert a["sheet_node_mass"][()] == pytest.approx(masses[on_sheet].sum(), rel=1e-9)
    report = (laydown_run / "laydown" / "report.md").read_text()
    assert "mass accounting" in report
    for name in ("sheet.vtu", "laydown.png"):
        assert (laydown_run / "laydown" / name).stat().st_size > 0


def test_no_fiber_node_inside_a_yarn(laydown_run: Path) -> None:
    with h5py.File(laydown_run / "laydown" / "laydown.h5", "r") as h:
        gaps = h["sheet/yarn_gap"][...]
        per_snapshot = h["snapshots/min_yarn_gap"][...]
    # distance of every node to every yarn centreline >= yarn radius + (part of) the node radius
    assert np.all(gaps >= 0.0), gaps.min()
    assert np.all(per_snapshot >= 0.0), per_snapshot
    assert np.all(per_snapshot >= 0.5 * 10e-6), per_snapshot.min()
