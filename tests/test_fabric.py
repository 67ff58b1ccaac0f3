# SPDX-License-Identifier: GPL-3.0-or-later
"""Tests of the forming-fabric generator (fiberform.fabric_geometry) and the ``fabric`` stage."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from fiberform.fabric_geometry import (
    FabricGeometryError,
    VoxelImage,
    WeaveParams,
    Yarn,
    analytic_open_area,
    build_weave,
    check_yarns,
    close_field,
    marching_tetrahedra,
    mesh_edge_report,
    mesh_volume,
    read_stl,
    signed_distance_image,
    voxel_open_area,
    write_stl,
)
from fiberform.stages.fabric import import_stl, import_voxels, write_voxel_file

SMALL = WeaveParams(size_x_m=1.0e-3, size_y_m=1.0e-3)


def _box(p: WeaveParams) -> tuple[np.ndarray, np.ndarray]:
    lo = np.array([0.0, 0.0, p.lower_side_z_m])
    hi = np.array([p.size_x_m, p.size_y_m, p.lower_side_z_m + p.thickness_m])
    return lo, hi


def _image(p: WeaveParams, h: float) -> VoxelImage:
    lo, hi = _box(p)
    f, sp = signed_distance_image(build_weave(p), lo, hi, h)
    return VoxelImage(f < 0, lo, sp)


def test_default_fabric_matches_thesis_thickness() -> None:
    p = WeaveParams()
    assert p.thickness_m == pytest.approx(0.637e-3, rel=1e-12)
    yarns = build_weave(p)
    zmin = min(float((y.points[:, 2] - y.radius).min()) for y in yarns)
    zmax = max(float((y.points[:, 2] + y.radius).max()) for y in yarns)
    assert zmin == pytest.approx(p.lower_side_z_m, abs=1e-12)
    assert zmax - zmin == pytest.approx(0.637e-3, rel=1e-9)


def test_yarns_do_not_intersect() -> None:
    # Default 3 x 3 mm fabric and a few variants: crossing yarns touch (clearance 0 up to
    # rounding) but never overlap.
    for p in (
        WeaveParams(),
        dataclasses.replace(SMALL, shed=6, shed_step=1, bottom_shift=2),
        dataclasses.replace(SMALL, clearance_m=2e-6, arc_step_deg=3.0),
        dataclasses.replace(SMALL, md_count_per_m=7000.0, md_diameter_m=0.1e-3),
    ):
        chk = check_yarns(build_weave(p))
        assert chk.pairs_checked > 0
        assert chk.min_clearance_m >= -1e-10, (p, chk)
    with_gap = check_yarns(build_weave(dataclasses.replace(SMALL, clearance_m=2e-6)))
    assert with_gap.min_clearance_m == pytest.approx(2e-6, rel=1e-6)


def test_intersection_is_detected() -> None:
    a = Yarn(np.array([[0.0, 0.0, 0.0], [1e-3, 0.0, 0.0]]), 50e-6, 0)
    b = Yarn(np.array([[0.5e-3, -1e-3, 80e-6], [0.5e-3, 1e-3, 80e-6]]), 50e-6, 1)
    chk = check_yarns([a, b])
    assert chk.min_clearance_m == pytest.approx(80e-6 - 100e-6, abs=1e-15)
    with pytest.raises(FabricGeometryError, match="cd_count_per_m"):
        build_weave(dataclasses.replace(SMALL, cd_count_per_m=5000.0))
    with pytest.raises(FabricGeometryError, match="md_count_per_m"):
        build_weave(dataclasses.replace(SMALL, md_count_per_m=10000.0))


def test_open_area_analytic_matches_voxels() -> None:
    # Each covered strip's sampled width is within one voxel of its true width, so
    # |voxel - analytic| <= (strips_x * h / Lx + strips_y * h / Ly) (0.04 here); in practice the
    # errors of the strip edges cancel and the stated tolerance is 0.005 at h = 5 um.
    an = analytic_open_area(SMALL)
    # The 1 x 1 mm piece holds whole repeats of both pitches: the piece value is the
    # infinite-fabric formula (1 - d_md n_md)(1 - d_cd n_cd).
    assert an["open_area"] == pytest.approx(an["open_area_infinite"], rel=1e-12)
    assert an["open_area"] == pytest.approx((1 - 0.11 * 5) * (1 - 0.177 * 3), rel=1e-12)
    img = _image(SMALL, 5e-6)
    bound = an["strips_x"] * img.spacing[0] / 1e-3 + an["strips_y"] * img.spacing[1] / 1e-3
    err = abs(voxel_open_area(img) - an["open_area"])
    assert err <= bound
    assert err <= 0.005, err
    # A piece that is not a whole number of repeats: the clipped strips still agree.
    odd = dataclasses.replace(SMALL, size_x_m=0.93e-3, size_y_m=0.71e-3)
    an_odd = analytic_open_area(odd)
    assert an_odd["open_area"] != pytest.approx(an_odd["open_area_infinite"], rel=1e-3)
    assert abs(voxel_open_area(_image(odd, 5e-6)) - an_odd["open_area"]) <= 0.005


def test_stl_is_closed_and_consistently_oriented(tmp_path: Path) -> None:
    p = dataclasses.replace(SMALL, size_x_m=0.6e-3, size_y_m=0.5e-3)
    lo, hi = _box(p)
    f, sp = signed_distance_image(build_weave(p), lo, hi, 10e-6)
    verts, tris = marching_tetrahedra(close_field(f, float(2 * sp.max())), lo - 0.5 * sp, sp)
    rep = mesh_edge_report(tris)
    assert rep["triangles"] > 1000
    assert rep["edges_not_shared_by_two"] == 0
    assert rep["directed_edges_repeated"] == 0
    assert rep["degenerate_triangles"] == 0
    vol = mesh_volume(verts, tris)
    vox = float((f < 0).sum() * np.prod(sp))
    assert vol > 0  # outward normals
    assert vol == pytest.approx(vox, rel=0.02)
    # Euler characteristic of a closed orientable surface is even.
    assert (len(verts) - rep["edges"] + rep["triangles"]) % 2 == 0
    # The binary STL file round-trips to the same closed surface.
    stl = tmp_path / "f.stl"
    write_stl(stl, verts, tris)
    v2, t2 = read_stl(stl)
    assert len(t2) == len(tris)
    rep2 = mesh_edge_report(t2)
    assert rep2["edges_not_shared_by_two"] == 0 and rep2["directed_edges_repeated"] == 0
    assert mesh_volume(v2, t2) == pytest.approx(vol, rel=1e-5)


def test_voxel_import_round_trip(tmp_path: Path) -> None:
    img = _image(SMALL, 10e-6)  # 1 x 1 mm holds the full thickness: no empty layers
    assert img.solid[:, :, 0].any() and img.solid[:, :, -1].any()
    path = tmp_path / "scan.h5"
    write_voxel_file(path, img)
    back = import_voxels(path, lower_side_z_m=img.origin[2])
    assert back.solid.shape == img.solid.shape
    assert np.array_equal(back.solid, img.solid)
    assert np.allclose(back.spacing, img.spacing)
    assert np.allclose(back.origin, img.origin)
    # Placed with its lowest solid layer at the requested height, empty layers dropped.
    padded = VoxelImage(np.pad(img.solid, ((0, 0), (0, 0), (3, 2))), img.origin, img.spacing)
    write_voxel_file(path, padded)
    moved = import_voxels(path, lower_side_z_m=1e-3)
    assert np.array_equal(moved.solid, img.solid)
    assert moved.origin[2] == 1e-3
    with h5py.File(path, "a") as f:
        del f["solid"].attrs["voxel_size_m"]
    with pytest.raises(FabricGeometryError, match="voxel_size_m"):
        import_voxels(path, 0.0)


def test_stl_import_round_trip(tmp_path: Path) -> None:
    p = SMALL  # 1 x 1 mm holds the full thickness
    lo, hi = _box(p)
    f, sp = signed_distance_image(build_weave(p), lo, hi, 10e-6)
    verts, tris = marching_tetrahedra(close_field(f, float(2 * sp.max())), lo - 0.5 * sp, sp, lo, hi)
    assert np.allclose(verts.min(axis=0), lo) and np.allclose(verts.max(axis=0), hi)
    stl = tmp_path / "fabric_mm.stl"
    write_stl(stl, verts * 1e3, tris)  # a file in millimetres
    img, v2, _ = import_stl(stl, unit_m=1e-3, voxel_size_m=10e-6, lower_side_z_m=p.lower_side_z_m)
    ref = f < 0
    assert img.solid.shape == ref.shape
    inter = np.logical_and(img.solid, ref).sum()
    union = np.logical_or(img.solid, ref).sum()
    assert inter / union > 0.97, inter / union
    assert abs(voxel_open_area(img) - float(1 - ref.any(axis=2).mean())) < 0.01


def _run_cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "fiberform", *args], cwd=cwd, capture_output=True, text=True, errors="replace",
        timeout=300, check=False,
    )  # fmt: skip


def test_fabric_stage_products(tmp_path: Path) -> None:
    (tmp_path / "s.yaml").write_text(
        "name: fab\nrun: {timestep_s: 1.0e-6, duration_s: 1.0e-3}\n"
        "fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3, voxel_size_m: 10.0e-6}\n"
    )
    r = _run_cli(["fabric", "s.yaml"], tmp_path)
    assert r.returncode == 0, r.stderr
    d = tmp_path / "runs" / "fab" / "fabric"
    for name in ("fabric.h5", "fabric.stl", "fabric.png"):
        assert (d / name).is_file()
    assert not list(d.glob("*.in_progress"))
    assert (d / "fabric.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with h5py.File(d / "fabric.h5") as f:
        assert f.attrs["stage"] == "fabric"
        assert "input_hashes" in f.attrs
        assert f["yarns/points"].attrs["units"] == "m"
        assert f["yarns/radius"].attrs["units"] == "m"
        assert f["voxels/solid"].ndim == 3
        props = dict(f["properties"].attrs)
        assert props["stl_open_edges"] == 0
        assert props["min_yarn_clearance_m"] >= -1e-10
        assert props["thickness_m"] == pytest.approx(0.637e-3)
        offs = f["yarns/offsets"][...]
        assert offs[-1] == len(f["yarns/points"])
        assert len(offs) == len(f["yarns/radius"]) + 1
    r2 = _run_cli(["fabric", "s.yaml"], tmp_path)
    assert r2.returncode == 0 and "up to date" in r2.stdout

    # The same fabric imported back from its STL (metres) through the stage.
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "f.stl").write_bytes((d / "fabric.stl").read_bytes())
    (tmp_path / "i.yaml").write_text(
        "name: imp\nrun: {timestep_s: 1.0e-6, duration_s: 1.0e-3}\n"
        "fabric: {source: stl, import_file: in/f.stl, voxel_size_m: 10.0e-6}\n"
    )
    r3 = _run_cli(["fabric", "i.yaml"], tmp_path)
    assert r3.returncode == 0, r3.stderr
    with h5py.File(tmp_path / "runs" / "imp" / "fabric" / "fabric.h5") as f:
        assert "yarns" not in f
        assert f["properties"].attrs["source"] == "stl"
        assert f["properties"].attrs["stl_open_edges"] == 0
        assert f["properties"].attrs["thickness_m"] == pytest.approx(0.637e-3, rel=0.03)


def test_bad_weave_is_a_scene_error(tmp_path: Path) -> None:
    (tmp_path / "s.yaml").write_text(
        "name: bad\nrun: {timestep_s: 1.0e-6, duration_s: 1.0e-3}\n"
        "fabric: {cd_count_per_m: 6000.0}\n"
    )
    r = _run_cli(["fabric", "s.yaml"], tmp_path)
    assert r.returncode == 2
    assert "cd_count_per_m" in r.stderr
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("fabric, words", [
    ("{source: voxels, import_file: in/f.h5, shed: 4}", "fabric.shed (line 3) = 4: only used when source is generate"),
    ("{source: stl, import_file: in/f.stl, md_diameter_m: 0.1e-3}", "fabric.md_diameter_m"),
    ("{source: voxels, import_file: in/f.h5, voxel_size_m: 10.0e-6}", "only used when source is generate or stl"),
    ("{source: generate, import_unit_m: 1.0e-3}", "fabric.import_unit_m"),
    ("{source: stl, import_file: in/missing.stl}", "fabric.import_file: "),
], ids=["weave field on voxels", "weave field on stl", "voxel size on voxels", "stl unit on a weave",
        "missing import file"])
def test_fields_the_source_does_not_use_and_missing_files_exit_2(tmp_path: Path, fabric: str, words: str) -> None:
    """A fabric field the chosen source does not use configures nothing: refused, naming it; an
    import file that does not exist is refused before anything is written."""
    (tmp_path / "s.yaml").write_text(
        "name: bad\nrun: {timestep_s: 1.0e-6, duration_s: 1.0e-3}\n" f"fabric: {fabric}\n")
    r = _run_cli(["fabric", "s.yaml"], tmp_path)
    assert r.returncode == 2, r.stderr
    assert words in r.stderr, r.stderr
    assert not (tmp_path / "runs").exists()
