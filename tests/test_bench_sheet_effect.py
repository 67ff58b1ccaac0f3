# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/coupling/run_sheet_effect.py (issue 13, "Effect on the sheet") end to end on the tiny
campaign of tests/test_campaign.py (1 x 1 mm fabric, 2.2 ug of fibers): its point A laid down
one-way and two-way for 1 ms from the same fibers, compared every 0.5 ms, and the air
permeability of both sheets.

- the one-way drainage is the flow stage's superficial velocity (the frozen flow), read
  independently from flow.h5;
- the coupled fluid starts from the flow stage's steady solution and 2.2 ug of fibers that have
  not reached the fabric barely resist it: its drainage stays within 2 % of the bare fabric's;
- the same fiber lies in both runs within a few micrometres after 0.5 ms (the reaction changes the
  flow by about 1 %; a mix-up of fiber IDs between the runs would give hundreds of micrometres);
- the lay-down products' thickness above the fabric (laydown.h5) equals the last snapshot's
  (the dump, the comparison's own reading), and both sheets have a converged permeability;
- two runs that generated different fibers are refused (not a controlled comparison);
- the ``soft`` variant against the first run's results JSON as its reference (not laid down
  again): its scene has the reference's moduli over 3 and nothing else changed, it generates the
  same fibers, the reference columns are the JSON's, and its product's thickness is its last
  snapshot's.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import pytest
import yaml

from fiberform.products import read_superficial_velocity

from test_campaign import write_tiny_campaign

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "bench" / "coupling" / "run_sheet_effect.py"


def test_one_way_and_two_way_of_a_tiny_point(tmp_path: Path, fiberdem_build: Path) -> None:
    camp = write_tiny_campaign(tmp_path)
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "FIBERFORM_BUILD": str(fiberdem_build)}
    out = tmp_path / "effect.json"
    cmd = [sys.executable, str(SCRIPT), "--campaign", str(camp / "campaign.yaml"), "--point", "A",
           "--max-time", "1e-3", "--restart", "5e-4", "--interval", "20", "--every", "5e-4",
           "--runs", "runs/se", "--to", "permeability", "--out", str(out)]
    proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    res = json.loads(out.read_text())
    rows = res["rows"]
    assert [round(r["time_s"] * 1e4) for r in rows] == [5, 10]
    u_s = read_superficial_velocity(tmp_path / "runs/se/one_way/flow/flow.h5")
    with h5py.File(tmp_path / "runs/se/one_way/fibers/fibers.h5", "r") as f:
        generated = len(f["fibers/mass"])
    for r in rows:
        assert r["drainage_one_way_m_s"] == u_s
        assert abs(r["drainage_two_way_m_s"] / u_s - 1.0) < 0.02, r
        assert 0 < r["one_way_fibers"] <= generated and 0 < r["two_way_fibers"] <= generated
        assert 0.0 < r["one_way_mass_fraction"] <= 1.0
        assert r["one_way_fines_fraction"] is None  # the tiny campaign has no fines
    assert rows[0]["com_apart_90_m"] < 5e-6, rows[0]
    # the finished products: the lay-down's own thickness (from laydown.h5's sheet) is the last
    # snapshot's (from the dump); the permeability ran on both sheets
    for name in ("one_way", "two_way"):
        got = res["products"][name]
        assert got["laydown_simulated_time_s"] == pytest.approx(1e-3)
        assert got["sheet_thickness_above_fabric_m"] == pytest.approx(rows[-1][f"{name}_thickness_above_fabric_m"],
                                                                      rel=1e-9)
        assert got["permeability_cfm"] > 0.0 and got["permeability_converged"] == 1.0
    assert res["code"]["git_revision"] and res["scenes"]["two_way"] == "runs/se/two_way.yaml"

    # another seed's fibers in the two-way run: not a controlled comparison, refused
    with h5py.File(tmp_path / "runs/se/two_way/fibers/fibers.h5", "r+") as f:
        f["fibers/x"][0, 0] += 1e-6
    again = subprocess.run([*cmd[:-4], "--out", str(tmp_path / "again.json"), "--compare"], cwd=tmp_path, env=env,
                           capture_output=True, text=True, timeout=600)
    assert again.returncode != 0 and "different fibers" in again.stderr, again.stderr[-2000:]
    assert not (tmp_path / "again.json").exists()

    # the reference JSON is never the output
    clash = subprocess.run([*cmd[:-4], "--compare", "--variants", "soft", "--reference-json", str(out),
                            "--out", str(out)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert clash.returncode == 2 and "--reference-json file" in clash.stderr, clash.stderr[-2000:]
    assert json.loads(out.read_text()) == res

    # the soft variant against the results JSON above as its reference
    soft_out = tmp_path / "soft.json"
    soft = subprocess.run([*cmd[:-4], "--to", "laydown", "--variants", "soft", "--reference-json", str(out),
                           "--out", str(soft_out)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=1200)
    assert soft.returncode == 0, soft.stdout[-3000:] + soft.stderr[-3000:]
    ref_scene = yaml.safe_load((tmp_path / "runs/se/one_way.yaml").read_text())
    soft_scene = yaml.safe_load((tmp_path / "runs/se/soft.yaml").read_text())
    for key in ("youngs_modulus_Pa", "shear_modulus_Pa"):
        assert soft_scene["fibers"][key] == pytest.approx(ref_scene["fibers"].pop(key) / 3.0, rel=1e-12)
        soft_scene["fibers"].pop(key)
    for key in ("name", "output_dir"):
        ref_scene.pop(key), soft_scene.pop(key)
    assert soft_scene == ref_scene  # nothing else changed
    with h5py.File(tmp_path / "runs/se/one_way/fibers/fibers.h5", "r") as a, \
            h5py.File(tmp_path / "runs/se/soft/fibers/fibers.h5", "r") as b:
        assert (a["fibers/x"][...] == b["fibers/x"][...]).all()
    got = json.loads(soft_out.read_text())
    assert got["names"] == ["one_way", "soft"] and got["reference_from"] == str(out)
    assert [r["time_s"] for r in got["rows"]] == [r["time_s"] for r in rows]
    for mine, theirs in zip(got["rows"], rows):
        assert mine["one_way_thickness_above_fabric_m"] == theirs["one_way_thickness_above_fabric_m"]
        assert mine["one_way_fibers"] == theirs["one_way_fibers"]
        assert mine["grammage_map_rms_diff_rel"] is None and mine["com_apart_90_m"] is None
        assert mine["drainage_soft_m_s"] == u_s
    assert got["products"]["one_way"] == res["products"]["one_way"]
    assert got["products"]["soft"]["sheet_thickness_above_fabric_m"] == pytest.approx(
        got["rows"][-1]["soft_thickness_above_fabric_m"], rel=1e-9)

    # a reference laid down from another version of the campaign file: accepted when the point's
    # scene is the same (only the presses changed), refused with exit status 2 when it is not
    text = (camp / "campaign.yaml").read_text()
    assert "overlap_limit: 0.2}" in text and "M_A_kg: 2.2e-9" in text
    (camp / "presses.yaml").write_text(text.replace("overlap_limit: 0.2}", "overlap_limit: 0.3, steric_cap_m: 1.0e-6}"))
    (camp / "mass.yaml").write_text(text.replace("M_A_kg: 2.2e-9", "M_A_kg: 2.3e-9"))
    base_cmd = [sys.executable, str(SCRIPT), *cmd[4:-4], "--compare", "--variants", "soft", "--reference-json", str(out)]
    for name, code in (("presses.yaml", 0), ("mass.yaml", 2)):
        done = subprocess.run([*base_cmd, "--campaign", str(camp / name), "--out", str(tmp_path / f"soft-{name}.json")],
                              cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == code, (name, done.stdout[-2000:] + done.stderr[-2000:])
    assert "laid down from another scene" in done.stderr, done.stderr[-2000:]
    assert json.loads((tmp_path / "soft-presses.yaml.json").read_text())["rows"] == got["rows"]
    assert not (tmp_path / "soft-mass.yaml.json").exists()

    # with a reference JSON the variant's fibers are still checked against the reference scene's
    # (generated here with its fabric and flow)
    with h5py.File(tmp_path / "runs/se/soft/fibers/fibers.h5", "r+") as f:
        f["fibers/x"][0, 0] += 1e-6
    moved = subprocess.run([*base_cmd, "--campaign", str(camp / "campaign.yaml"), "--out", str(tmp_path / "moved.json")],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert moved.returncode != 0 and "different fibers" in moved.stderr, moved.stderr[-2000:]
    assert not (tmp_path / "moved.json").exists()
