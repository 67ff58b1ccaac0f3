# SPDX-License-Identifier: GPL-3.0-or-later
"""Periodic lateral boundaries of the lay-down (issue 15 (d), ``laydown.walls: periodic``).

Without binaries: the scene checks (exit 2 naming the field and the allowed sizes), the periodicity
of the generated weave for whole repeats (fabric_geometry), the tiled yarns against the yarns the
generator makes for a larger piece (an independent point-to-segment distance), and the sheet helpers
on hand numbers.

System (fiberdem): a small periodic lay-down through ``fiberform run --to laydown`` (continuous
unwrapped chains, exact mass accounting, no node or element inside the tiled yarns by an independent
check, a fiber across a periodic side); translation invariance of a direct LIGGGHTS input (a uniform
flow, a box of 2 x 1 weave repeats, the fibers shifted by one repeat: the same motion within 1e-9 m,
with a fiber-fiber contact across the periodic side in one run and inside the box in the other);
the periodic lay-down on 1 and 2 MPI ranks (the same sheet within 1e-9 m)."""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

from fiberform.fabric_geometry import MD_WARP, WeaveParams, build_weave
from fiberform.fiber_io import Fiber
from fiberform.products import Yarns
from fiberform.errors import SceneError
from fiberform.scene import parse_scene, read_scene_yaml

from test_laydown import _min_element_yarn_distance, _point_segment_distance

L = 1.0e-3  # m: the periodic box of the lay-down scene: one weave repeat in x and in y
# shed 4 at 4000 columns and warps per metre: one weave repeat is 4 x 0.25 mm = 1 mm in x and in y;
# thinner yarns than the defaults so that 4000 per metre fit (a bottom weft + a warp < the pitch)
WEAVE = dict(shed=4, shed_step=1, md_count_per_m=4000.0, cd_count_per_m=4000.0,
             md_diameter_m=0.1e-3, cd_top_diameter_m=0.12e-3, cd_bottom_diameter_m=0.12e-3)
FABRIC = ("fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3, shed: 4, shed_step: 1, md_count_per_m: 4000.0,\n"
          "         cd_count_per_m: 4000.0, md_diameter_m: 0.1e-3, cd_top_diameter_m: 0.12e-3,\n"
          "         cd_bottom_diameter_m: 0.12e-3}\n")
# 5 fibers of 0.6 mm just above the fabric top (2.54 mm), placed in x from -0.4 mm: most straddle
# the periodic side x = 0 (read_data maps their nodes into the box; the dump's xu keeps the chain)
SCENE = """
name: periodic_laydown
seed: 3
output_dir: runs/%(out)s
fibers: {count: 5, length_m: 0.6e-3, width_m: 20.0e-6, segments: 12,
         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}
fiber_generation: {placement_lo_m: [-0.4e-3, 0.0, 2.56e-3], placement_hi_m: [0.6e-3, 1.0e-3, 2.9e-3]}
""" + FABRIC + """flow: {delta_p_Pa: 100.0, cell_size_m: 50.0e-6, height_above_fabric_m: 0.8e-3}
laydown: {terms: [steric], walls: periodic, max_time_s: 0.005, check_interval_s: 5.0e-4, settle_speed_m_s: 2.0e-3,
          settle_checks: 3, timestep_s: 1.0e-6, restart_interval_s: 0.0, ranks: %(ranks)d}
contact: {model: fiber_dlvo, terms: [steric]}
"""


def scene_text(out: str = "a", ranks: int = 1) -> str:
    return SCENE % {"out": out, "ranks": ranks}


def weave_yarns(**kw: float) -> Yarns:
    p = WeaveParams(**{**WEAVE, **kw})  # type: ignore[arg-type]
    ys = build_weave(p)
    return Yarns(np.vstack([y.points for y in ys]),
                 np.cumsum([0] + [len(y.points) for y in ys]).astype(np.int64),
                 np.array([y.radius for y in ys]))


def _segments(pts: np.ndarray, offs: np.ndarray, rad: np.ndarray) -> tuple[np.ndarray, ...]:
    a = np.vstack([pts[offs[k]:offs[k + 1] - 1] for k in range(len(rad))])
    b = np.vstack([pts[offs[k] + 1:offs[k + 1]] for k in range(len(rad))])
    r = np.concatenate([np.full(offs[k + 1] - offs[k] - 1, rad[k]) for k in range(len(rad))])
    return a, b, r


def _surface_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, r: np.ndarray) -> np.ndarray:
    """min over segments a-b of (point-segment distance - r), for points p (n, 3): m."""
    return np.concatenate([(_point_segment_distance(c[None], a, b)[0] - r[None, :]).min(axis=1)
                           for c in np.array_split(p, max(1, len(p) // 50))])


def periodic_fabric_segments(fabric_h5: Path, period: tuple[float, float], reach: float = 0.2e-3
                             ) -> tuple[np.ndarray, ...]:
    """Independently of fiber_sheet.tile_yarns: the generator's own yarn segments (fabric.h5) within
    ``reach`` of the box along their yarn (the generator's yarns run on beyond the piece; their far
    ends are cut off), copied at -L, 0, +L in x and y. Overlapping copies do not matter for a
    smallest distance."""
    with h5py.File(fabric_h5, "r") as h:
        pts, offs, rad = h["yarns/points"][...], h["yarns/offsets"][...], h["yarns/radius"][...]
    a, b, r = _segments(pts, offs, rad)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keep = np.all((hi[:, :2] > -reach) & (lo[:, :2] < np.array(period) + reach), axis=1)
    a, b, r = a[keep], b[keep], r[keep]
    shifts = [np.array([i * period[0], j * period[1], 0.0]) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    return (np.vstack([a + s for s in shifts]), np.vstack([b + s for s in shifts]), np.tile(r, len(shifts)))


def _min_clearance(x0: np.ndarray, x1: np.ndarray, a: np.ndarray, b: np.ndarray, r: np.ndarray,
                   reach: float = 100e-6) -> float:
    """test_laydown's golden-section element-to-segment distance minus r, min over all pairs, each
    element against the segments that may come within ``reach`` (m) of it (a lower bound from the
    midpoints and half-lengths); exact when the result is below ``reach``, else a lower bound
    of at least ``reach`` (a snapshot before the fibers reach the fabric)."""
    ma, ha = 0.5 * (x0 + x1), 0.5 * np.linalg.norm(x1 - x0, axis=1)
    ms, hs = 0.5 * (a + b), 0.5 * np.linalg.norm(b - a, axis=1)
    lower = np.linalg.norm(ma[:, None, :] - ms[None, :, :], axis=-1) - ha[:, None] - hs[None, :] - r[None, :]
    best = math.inf
    for i in range(len(x0)):
        near = lower[i] < reach
        if near.any():
            best = min(best, _min_element_yarn_distance(x0[i:i + 1], x1[i:i + 1], a[near], b[near], r[near]))
    return best if best < reach else max(reach, float(lower.min()))


# ------------------------------------------------------------------------------------------------
# scene checks (no binaries)


def _check(tmp_path: Path, fiberform_cmd: list[str], text: str) -> subprocess.CompletedProcess[str]:
    (tmp_path / "p.yaml").write_text(text)
    return subprocess.run([*fiberform_cmd, "check", "p.yaml"], cwd=tmp_path, capture_output=True,
                          text=True, errors="replace", timeout=120)


BAD_PERIODIC = {
    "averaged_yarn_contact": (
        ("walls: periodic,", "walls: periodic, yarn_contact: averaged,"),
        ("laydown.yarn_contact", "'averaged'", "walls periodic needs yarn_contact newton")),
    "explicit_fibers": (
        ("walls: periodic,", "walls: periodic, beam_integrator: explicit, inertia_scale: 1.0e4,"),
        ("laydown.yarn_contact", "walls periodic needs yarn_contact newton")),
    "two_way": (
        ("contact: {model", "coupling: {mode: two_way}\ncontact: {model"),
        ("laydown.walls", "coupling.mode two_way", "symmetry sides")),
    "imported_fabric": (
        (FABRIC, "fabric: {source: voxels, import_file: f.h5, size_x_m: 1.0e-3, size_y_m: 1.0e-3}\n"),
        ("fabric.source", "'voxels'", "generated fabric")),
    # shed 8 at 4000 columns per metre: repeats of 2 mm; 1 mm is half of one (the only size offered: 2 mm)
    "part_repeat_x": (
        ("shed: 4, shed_step: 1,", "shed: 8, shed_step: 3,"),
        ("fabric.size_x_m", "0.001: laydown.walls periodic needs whole weave repeats of shed / "
         "cd_count_per_m = 2e-3 m: 2e-3 m")),
    # 1.2 mm in y: between 1 and 2 repeats of 1 mm; x stays 1 mm
    "part_repeat_y": (
        ("size_y_m: 1.0e-3", "size_y_m: 1.2e-3"),
        ("fabric.size_y_m", "0.0012", "shed / md_count_per_m = 1e-3 m: 1e-3 or 2e-3 m",
         "allowed: 0 < x <= 0.02 m")),
    "domain_not_the_piece": (
        ("fibers: {count", "domain: {lo_m: [0.0, 0.0, 0.0], hi_m: [1.2e-3, 1.0e-3, 3.34e-3]}\nfibers: {count"),
        ("domain.hi_m[0]", "0.0012", "the periodic box is the fabric piece, ending at 0.001 m")),
    "fibers_longer_than_the_box": (
        ("length_m: 0.6e-3", "length_m: 1.0e-3"),
        ("fibers.length_m", "shorter than the periodic box")),
    "sampled_lengths_reach_the_box": (  # the longest fiber the distribution allows counts
        ("length_m: 0.6e-3, width_m: 20.0e-6, segments: 12,\n         youngs_modulus_Pa: 10.0e+9, "
         "shear_modulus_Pa: 4.0e+9}\nfiber_generation: {",
         "width_m: 20.0e-6, segments: 12,\n         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}\n"
         "fiber_generation: {length_m: {kind: uniform, low: 0.3e-3, high: 1.1e-3}, "),
        ("fiber_generation.length_m", "shorter than the periodic box", "0.0011")),
}


@pytest.mark.parametrize("case", sorted(BAD_PERIODIC))
def test_periodic_scene_errors_name_the_field(case: str, tmp_path: Path, fiberform_cmd: list[str]) -> None:
    (old, new), expect = BAD_PERIODIC[case]
    text = scene_text()
    assert old in text, old
    proc = _check(tmp_path, fiberform_cmd, text.replace(old, new, 1))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    for part in expect:
        assert part in proc.stderr, f"{part!r} not in:\n{proc.stderr}"


def test_periodic_scene_passes_and_its_error_gives_the_nearest_sizes(tmp_path: Path,
                                                                    fiberform_cmd: list[str]) -> None:
    proc = _check(tmp_path, fiberform_cmd, scene_text())
    assert proc.returncode == 0, proc.stderr
    # the brief's example: the default fabric (shed 8, 3000 columns per metre) on 3 mm
    data = read_scene_yaml("name: p\nfabric: {size_x_m: 3.0e-3, size_y_m: 1.6e-3}\n"
                           "flow: {height_above_fabric_m: 0.8e-3}\nlaydown: {walls: periodic}\n")
    with pytest.raises(SceneError) as err:
        parse_scene(data)
    text = str(err.value)
    assert ("fabric.size_x_m = 0.003: laydown.walls periodic needs whole weave repeats of shed / "
            "cd_count_per_m = 2.6667e-3 m: 2.6667e-3 or 5.3333e-3 m") in text, text
    # 1.6 mm = 1 repeat of 8 / 5000 in y: accepted; whole repeats within the relative 1e-6
    def two_repeats(rel: float) -> object:
        return read_scene_yaml(f"name: p\nfabric: {{size_x_m: {2 * 8 / 3000 * (1 + rel)!r}, size_y_m: 1.6e-3}}\n"
                               "flow: {height_above_fabric_m: 0.8e-3}\nlaydown: {walls: periodic}\n")

    assert parse_scene(two_repeats(5e-7)).laydown is not None
    with pytest.raises(SceneError, match="5.3333e-3 or 8e-3 m"):
        parse_scene(two_repeats(5e-6))


# ------------------------------------------------------------------------------------------------
# the weave and the tiled yarns (no binaries)


def test_generated_weave_is_periodic_for_whole_repeats() -> None:
    """The generator (fabric_geometry.build_weave) for whole repeats: every warp's centre line z(x)
    near x = 0 equals the one near x = L shifted by L (1 x 1 mm = one repeat of shed 4 at 4000
    per metre, and on a 2 x 1 mm piece); on a 1 x 2 mm piece warp j + 4 (one repeat further in y) runs as warp j; the
    wefts lie at the same x modulo L. Not whole repeats (1.1 mm): the warps differ there."""
    pcd = 1.0 / WEAVE["cd_count_per_m"]
    grid = np.linspace(-0.5 * pcd, 0.5 * pcd, 2001)

    def z_of(y: object, x: np.ndarray) -> np.ndarray:
        return np.interp(x, y.points[:, 0], y.points[:, 2])  # type: ignore[attr-defined]

    for size, period, expect_periodic in ((1.0e-3, 1.0e-3, True), (2.0e-3, 1.0e-3, True),
                                          (1.1e-3, 1.1e-3, False)):
        ys = build_weave(WeaveParams(size_x_m=size, size_y_m=1.0e-3, **WEAVE))  # type: ignore[arg-type]
        warps = [y for y in ys if y.kind == MD_WARP]
        assert len(warps) == 4
        worst = max(float(np.max(np.abs(z_of(w, grid) - z_of(w, grid + period)))) for w in warps)
        if not expect_periodic:
            assert worst > 1e-6, worst
            continue
        assert worst < 1e-12, worst
        # the weft columns continue across the sides: modulo the period, one every pitch
        wefts = np.unique(np.round([float(y.points[0, 0]) % period for y in ys if y.kind != MD_WARP], 12))
        wefts = np.unique(np.round(np.where(wefts >= period - 1e-12, wefts - period, wefts), 12))
        assert len(wefts) == round(period / pcd)
        assert np.allclose(np.diff(wefts), pcd, rtol=1e-9, atol=0.0)
    # y: warp j + shed (one repeat of 4 warps = 1 mm further) repeats warp j
    ys = build_weave(WeaveParams(size_x_m=1.0e-3, size_y_m=2.0e-3, **WEAVE))  # type: ignore[arg-type]
    warps = sorted((y for y in ys if y.kind == MD_WARP), key=lambda y: float(y.points[0, 1]))
    assert len(warps) == 8
    x = np.linspace(-pcd, 1.0e-3 + pcd, 3001)
    for j in range(4):
        assert warps[j + 4].points[0, 1] - warps[j].points[0, 1] == pytest.approx(1.0e-3, rel=1e-12)
        assert np.max(np.abs(z_of(warps[j + 4], x) - z_of(warps[j], x))) < 1e-12


def test_tiled_yarns_are_the_fabric_over_its_periodic_images() -> None:
    """fiber_sheet.tile_yarns on the 1 x 1 mm (one repeat) and 2 x 1 mm pieces: the surface
    distance of points near the fabric to the tiled yarns equals (1e-12 m) that to the yarns the
    generator makes for a piece 5 x 5 times as large, at the same place in its middle image (the
    reference fabric, independent of the tiling). Points: random in the box, on its sides and
    1e-12 m inside them (where the yarns are cut and joined), and all of these shifted by -L or +L
    in x or y (periodic; where the tiled yarns reach far enough around the point). The piece's
    yarns (4 warps, a top and a bottom weft per column in the box) give 3 chains each, each over
    3 periods along its yarn."""
    from fiberform.fiber_sheet import tile_yarns

    rng = np.random.default_rng(7)
    for size_x, n_own in ((1.0e-3, 4 + 2 * 4), (2.0e-3, 4 + 2 * 8)):
        per = (size_x, 1.0e-3)
        own = weave_yarns(size_x_m=size_x, size_y_m=1.0e-3)
        tiled = tile_yarns(own, per)
        assert len(tiled.radius) == 3 * n_own
        for k in range(len(tiled.radius)):
            span = np.ptp(tiled.points[tiled.offsets[k]:tiled.offsets[k + 1], :2], axis=0)
            along = int(np.argmax(span))
            assert span[along] == pytest.approx(3 * per[along], rel=1e-12) and span[1 - along] == 0.0
        big = weave_yarns(size_x_m=5 * size_x, size_y_m=5 * 1.0e-3)
        middle = np.array([2 * size_x, 2 * 1.0e-3, 0.0])  # the box's place in the big piece
        z_lo = own.points[:, 2].min() - 2e-4
        z_hi = own.points[:, 2].max() + 2e-4
        n = 400
        p = np.column_stack([rng.uniform(0, size_x, n), rng.uniform(0, 1.0e-3, n), rng.uniform(z_lo, z_hi, n)])
        side = np.linspace(0.0, 1.0, 30)
        zs = np.linspace(z_lo, z_hi, 30)
        for v in (0.0, 1e-12, size_x - 1e-12, size_x):
            p = np.vstack([p, np.column_stack([np.full(30, v), side * 1.0e-3, zs])])
        for v in (0.0, 1e-12, 1.0e-3 - 1e-12, 1.0e-3):
            p = np.vstack([p, np.column_stack([side * size_x, np.full(30, v), zs])])
        a_t, b_t, r_t = _segments(tiled.points, tiled.offsets, tiled.radius)
        a_b, b_b, r_b = _segments(big.points, big.offsets, big.radius)
        for shift in ((0.0, 0.0, 0.0), (size_x, 0.0, 0.0), (-size_x, 0.0, 0.0), (0.0, 1.0e-3, 0.0),
                      (0.0, -1.0e-3, 0.0)):
            q = p + np.array(shift)
            d_tiled = _surface_distance(q, a_t, b_t, r_t)
            # the tiled centre lines cover [-L, 2L]: compare where every yarn as near as the
            # nearest one found lies inside that cover
            room = np.min(np.column_stack([q[:, 0] + size_x, 2 * size_x - q[:, 0],
                                           q[:, 1] + 1.0e-3, 2.0e-3 - q[:, 1]]), axis=1)
            sure = d_tiled + r_t.max() < room
            assert sure.mean() > 0.5, sure.mean()
            if shift == (0.0, 0.0, 0.0):
                assert sure.all()  # the box and its sides: everywhere
            d_ref = _surface_distance(q[sure] + middle, a_b, b_b, r_b)
            assert np.max(np.abs(d_tiled[sure] - d_ref)) < 1e-12, shift
            assert np.min(d_ref) < 0.0 < np.max(d_ref)  # the points sample inside and outside the yarns
    # not whole repeats in x: the cut ends differ, tile_yarns refuses
    with pytest.raises(ValueError, match="not periodic"):
        tile_yarns(weave_yarns(size_x_m=1.1e-3, size_y_m=1.0e-3), (1.1e-3, 1.0e-3))


def test_periodic_images_wrapping_and_gaps_on_hand_numbers() -> None:
    """fiber_sheet.periodic_images, wrap_points, wrap_chains and fiber_fiber_gap's periodic images,
    on a 1 x 2 mm box."""
    from fiberform.fiber_sheet import fiber_fiber_gap, periodic_images, wrap_chains, wrap_points

    per = (1.0e-3, 2.0e-3)
    across = np.array([[-0.1e-3, 0.5e-3, 0.0], [0.2e-3, 0.5e-3, 0.0]])  # across x = 0
    inside = np.array([[0.3e-3, 1.0e-3, 0.0], [0.6e-3, 1.2e-3, 0.0]])
    beyond = np.array([[1.05e-3, 2.1e-3, 0.0], [1.3e-3, 2.5e-3, 0.0]])  # one period out in x and y
    x = np.vstack([across, inside, beyond])
    offs = np.array([0, 2, 4, 6])
    xi, oi, src, sh = periodic_images(x, offs, per)
    assert src.tolist() == [0, 0, 1, 2]
    assert sh.tolist() == [[0.0, 0.0, 0.0], [1.0e-3, 0.0, 0.0], [0.0, 0.0, 0.0], [-1.0e-3, -2.0e-3, 0.0]]
    assert oi.tolist() == [0, 2, 4, 6, 8]
    assert np.array_equal(xi[2:4], across + [1.0e-3, 0.0, 0.0]) and np.array_equal(xi[6:8], beyond - [1.0e-3, 2.0e-3, 0.0])
    # a margin of 0.15 mm: a chain ending 0.1 mm short of the box (y from -0.3 to -0.1 mm) gives
    # itself (within the margin) and its image one period up
    _, _, src_m, _ = periodic_images(np.array([[0.5e-3, -0.3e-3, 0.0], [0.6e-3, -0.1e-3, 0.0]]),
                                     np.array([0, 2]), per, margin=0.15e-3)
    assert src_m.tolist() == [0, 0]
    assert len(periodic_images(np.array([[0.5e-3, -0.3e-3, 0.0], [0.6e-3, -0.1e-3, 0.0]]),
                               np.array([0, 2]), per)[2]) == 1  # without the margin: the image only
    assert periodic_images(x, offs, (0.0, 0.0))[2].tolist() == [0, 1, 2]  # not periodic: as given
    assert wrap_points(beyond, per) == pytest.approx(np.array([[0.05e-3, 0.1e-3, 0.0], [0.3e-3, 0.5e-3, 0.0]]),
                                                     abs=1e-15)
    w = wrap_chains(x, offs, per)
    assert w[0:2] == pytest.approx(across + [1.0e-3, 0.0, 0.0], abs=1e-15)  # first node into the box
    assert np.array_equal(w[2:4], inside)
    assert w[4:6] == pytest.approx(beyond - [1.0e-3, 2.0e-3, 0.0], abs=1e-15)
    assert wrap_points(x, None) is x and wrap_chains(x, offs, None) is x
    # two fibers crossing at the side x = 0 (= 1 mm): one along y at x = 0.999 mm, one along x
    # from 0.001 mm to 0.2 mm, c above it: gap c - r1 - r2 only through the periodic image
    r1, r2, c = 10e-6, 9e-6, 30e-6
    fa = np.array([[0.999e-3, 0.4e-3, c], [0.999e-3, 0.5e-3, c], [0.999e-3, 0.6e-3, c]])
    fb = np.array([[0.001e-3, 0.5e-3, 0.0], [0.1e-3, 0.5e-3, 0.0], [0.2e-3, 0.5e-3, 0.0]])
    radius = np.array([r1] * 3 + [r2] * 3)
    two = np.vstack([fa, fb])
    expect = math.hypot(c, 0.002e-3) - r1 - r2  # closest points (0.999, 0.5, c) and (1.001, 0.5, 0)
    assert fiber_fiber_gap(two, np.array([0, 3, 6]), radius, period=per) == pytest.approx(expect, rel=1e-9)
    assert fiber_fiber_gap(two, np.array([0, 3, 6]), radius) > 0.7e-3  # without: across the box


# ------------------------------------------------------------------------------------------------
# the lay-down (fiberdem)


@pytest.fixture(scope="module")
def periodic_run(tmp_path_factory: pytest.TempPathFactory, build_dir: Path,
                 fiberform_cmd: list[str]) -> Path:
    if not (build_dir / "bin" / "fiberdem").is_file():
        pytest.skip("fiberdem not built")
    work = tmp_path_factory.mktemp("periodic")
    (work / "a.yaml").write_text(scene_text("a", 1))
    proc = subprocess.run([*fiberform_cmd, "run", "a.yaml", "--to", "laydown", "--build-dir", str(build_dir)],
                          cwd=work, capture_output=True, text=True, errors="replace", timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    return work


@pytest.mark.system
def test_periodic_input_has_no_side_planes_and_tiled_yarns(periodic_run: Path) -> None:
    work = periodic_run / "runs/a/laydown/work"
    text = (work / "in.laydown").read_text()
    assert "boundary p p f\n" in text and "wall/fiber/dlvo" not in text and "wall/gran" not in text
    assert " xu yu zu " in text
    ids = {int(line.split()[0]) for line in (work / "yarns.txt").read_text().splitlines()[1:]}
    with h5py.File(periodic_run / "runs/a/fabric/fabric.h5", "r") as h:
        n_own = len(h["yarns/radius"])
    assert len(ids) == 3 * n_own == 36  # the 12 yarns of the piece, 3 chains each


@pytest.mark.system
def test_periodic_ghost_reach_is_set_by_the_elements_not_the_box(periodic_run: Path) -> None:
    """Fibers cross the sides at step 0: the longest element, which sets the contact styles'
    neighbour and ghost reach at init (before any ghost image exists), must be measured by the
    minimum image. Measured with the closest local copy instead, an element across a side looked
    a box length long: 2035 ghosts for 65 atoms here, and a neighbour-list overflow on the
    case-A piece (session 17). The ghosts of the run stay a fraction of a box's worth."""
    log = (periodic_run / "runs/a/laydown/work/log.fiberdem").read_text()
    local = [float(v) for v in re.findall(r"^Nlocal:\s+(\S+)", log, re.M)]
    ghost = [float(v) for v in re.findall(r"^Nghost:\s+(\S+)", log, re.M)]
    assert local and len(ghost) == len(local)
    assert max(g / n for g, n in zip(ghost, local)) < 2.0, (ghost[:3], local[:3])


@pytest.mark.system
def test_periodic_chains_are_continuous_and_a_fiber_crosses_a_side(periodic_run: Path) -> None:
    """Every element keeps its length within 1 % (the fibers are nearly inextensible; a chain
    broken at a periodic side would jump by about L), at every snapshot of the dump and in
    laydown.h5; a fiber's unwrapped nodes lie outside [0, L] (it crosses a periodic side) at the
    end, and a node moved by more than 20 um laterally (the run did something)."""
    from fiberform.fiber_sheet import frame_fibers
    from fiberform.liggghts_log import read_dump

    run = periodic_run / "runs/a"
    with h5py.File(run / "fibers/fibers.h5", "r") as h:
        x0, off0 = h["fibers/x"][...], h["fibers/offsets"][...]
    with h5py.File(run / "laydown/laydown.h5", "r") as h:
        xs, offs, ids = h["sheet/x"][...], h["sheet/offsets"][...], h["sheet/fiber_id"][...]
        assert h["run"].attrs["lateral_period_m"].tolist() == [L, L]
        assert h["run"].attrs["walls"] == "periodic"
    l0 = {k: np.linalg.norm(np.diff(x0[off0[k]:off0[k + 1]], axis=0), axis=1) for k in range(len(off0) - 1)}
    frames = read_dump(run / "laydown/work/traj.dump")
    assert len(frames) >= 10
    for fr in frames + [None]:
        x, present, o = (xs, ids, offs) if fr is None else frame_fibers(fr.columns)
        for j, k in enumerate(present):
            el = np.linalg.norm(np.diff(x[o[j]:o[j + 1]], axis=0), axis=1)
            assert np.max(np.abs(el / l0[int(k)] - 1.0)) < 0.01, (k, np.max(np.abs(el / l0[int(k)] - 1.0)))
    # a fiber lies across a periodic side: its unwrapped nodes on both sides of x (or y) = 0 or L
    across = [int(k) for j, k in enumerate(ids) for axis in (0, 1)
              if any(xs[offs[j]:offs[j + 1], axis].min() < side < xs[offs[j]:offs[j + 1], axis].max()
                     for side in (0.0, L))]
    assert across, "no fiber across a periodic side at the end"
    start = np.vstack([x0[off0[k]:off0[k + 1]] for k in ids])
    assert np.max(np.linalg.norm(xs[:, :2] - start[:, :2], axis=1)) > 20e-6


@pytest.mark.system
def test_periodic_mass_accounting_is_exact(periodic_run: Path) -> None:
    run = periodic_run / "runs/a"
    with h5py.File(run / "fibers/fibers.h5", "r") as h:
        masses = h["fibers/mass"][...]
    with h5py.File(run / "laydown/laydown.h5", "r") as h:
        a = h["accounting"]
        on_sheet, removed = h["sheet/fiber_id"][...], a["removed_fiber_id"][...]
        assert sorted([*on_sheet, *removed]) == list(range(len(masses)))
        assert a["injected_mass"][()] == pytest.approx(masses.sum(), rel=1e-15)
        assert a["sheet_mass"][()] + a["removed_mass"][()] == pytest.approx(a["injected_mass"][()], rel=1e-14)
        assert a["sheet_node_mass"][()] == pytest.approx(masses[on_sheet].sum(), rel=1e-9)
        assert h["run"].attrs["grammage_kg_m2"] == pytest.approx(a["sheet_mass"][()] / L ** 2, rel=1e-12)
    assert (run / "laydown/laydown.png").stat().st_size > 0


@pytest.mark.system
def test_no_node_or_element_inside_the_tiled_yarns(periodic_run: Path) -> None:
    """At every snapshot: no fiber node within a yarn and no element centre line through one,
    against the generator's yarns copied to the 8 neighbouring images (computed here, independent of
    fiber_sheet.tile_yarns), each node wrapped into the box and each element shifted so that its
    midpoint is in the box; the stage's closed forms (tiled yarns, chains wrapped by their first
    node) agree within 1e-9 m."""
    from fiberform.liggghts_log import read_dump

    run = periodic_run / "runs/a"
    a, b, r = periodic_fabric_segments(run / "fabric/fabric.h5", (L, L))
    worst_el, worst_node = math.inf, math.inf
    for fr in read_dump(run / "laydown/work/traj.dump"):
        c = fr.columns
        fid, node = np.rint(c["f_beam[1]"]).astype(int), np.rint(c["f_beam[2]"]).astype(int)
        order = np.lexsort((node, fid))
        x = np.stack([c[k][order] for k in ("xu", "yu", "zu")], axis=1)
        same = fid[order][1:] == fid[order][:-1]
        x0, x1 = x[:-1][same], x[1:][same]
        shift = np.zeros_like(x0)
        shift[:, :2] = -np.floor(0.5 * (x0 + x1)[:, :2] / L) * L
        worst_el = min(worst_el, _min_clearance(x0 + shift, x1 + shift, a, b, r))
        xw = x.copy()
        xw[:, :2] = np.mod(xw[:, :2], L)
        worst_node = min(worst_node, float(_surface_distance(xw, a, b, r).min()))
    assert worst_el < 100e-6, worst_el  # fibers reached the yarns (and the minimum is exact)
    assert worst_el >= 0.0, f"a fiber centre line passes {-worst_el * 1e6:.3f} um inside a yarn"
    assert worst_node >= 5e-6, worst_node  # a node keeps (about) its radius from the yarn surface
    with h5py.File(run / "laydown/laydown.h5", "r") as h:
        stage_el = h["snapshots/min_element_clearance"][...]
        stage_node = h["snapshots/min_yarn_gap"][...]
    assert stage_el.min() == pytest.approx(worst_el, abs=1e-9)
    assert stage_node.min() == pytest.approx(worst_node, abs=1e-9)
    assert worst_el < 12e-6  # fibers rest on the yarns (centre line about a radius, 10 um, above)


def _periodic_input(yarns_h5: Path, steps: int) -> str:
    """A direct lay-down input built with the package's builders: box 2 x 1 mm (2 x 1 weave
    repeats) periodic in x and y, tiled yarns, fiber-fiber contact inside the Newton solve, a
    uniform downward flow of 0.1 m/s, dump of the unwrapped positions at the end."""
    from fiberform.fiber_io import fiber_preamble, laydown_beam_options
    from fiberform.fiber_sheet import contact_commands, node_dump_columns
    from fiberform.inputs import LiggghtsInput, file_token

    scene = parse_scene(read_scene_yaml(
        "name: shift\n"
        "domain: {lo_m: [0.0, 0.0, 0.0], hi_m: [2.0e-3, 1.0e-3, 1.0e-3]}\n"
        "fibers: {count: 3, length_m: 0.5e-3, width_m: 20.0e-6, segments: 10,\n"
        "         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9}\n"
        + FABRIC.replace("size_x_m: 1.0e-3", "size_x_m: 2.0e-3").replace("cd_bottom_diameter_m: 0.12e-3}",
                                                                          "cd_bottom_diameter_m: 0.12e-3, lower_side_z_m: 0.1e-3}")
        + "laydown: {terms: [steric], walls: periodic, timestep_s: 1.0e-6, check_interval_s: 1.0e-4, max_time_s: 1.0e-3}\n"
        "contact: {model: fiber_dlvo, terms: [steric]}\n"))
    assert scene.fibers is not None and scene.laydown is not None
    s = LiggghtsInput()
    fiber_preamble(s, scene.fibers, True, *laydown_beam_options(scene.laydown), periodic_xy=True)
    s.command("fix", "drag", "all", "fiber/drag", "flow", "uniform", 0.0, 0.0, -0.1,
              "fluid_density", 998.2, "viscosity", 1.0e-3, "gravity", 0.0, 0.0, -9.81)
    contact_commands(s, scene, "yarns.txt")
    s.command("timestep", scene.laydown.timestep_s)
    s.command("thermo", 100)
    columns, fmt = node_dump_columns(scene.fibers, True)
    s.command("run", steps)
    s.command("dump", "end", "all", "custom", 1, file_token("end.dump"), *columns)
    s.command("dump_modify", "end", "sort", "id", "format", fmt)
    s.command("run", 0)
    return s.render()


SHIFT_X = 1.0e-3  # m: one weave repeat in x
STEPS = 2000  # of 1 us: A lands on the top wefts after about 0.5 ms, C on A soon after


def _fibers(shift: float) -> list[Fiber]:
    """Three fibers of 0.5 mm, radius 10 um, 60 um above the top wefts (surface at 0.54 mm) and
    clear of the warps' knuckles (0.64 mm): A along x across x = 0 at y = 0.5 mm, between two
    warps; C along y at x = 1.9 mm (A's node at x = -0.1 mm, through the periodic side), 5 um
    above A: it lands on A once A rests on the wefts; B along x from 0.7 to 1.2 mm at y = 0.2 mm
    (shifted: across x = 2 mm)."""
    from fiberform.fiber_io import quat_from_frames

    ex, ey, ez = np.eye(3)
    out = []
    for start, direction, t1 in (((-0.25e-3, 0.5e-3, 0.60e-3), ex, ey), ((1.9e-3, 0.3e-3, 0.625e-3), ey, ez),
                                 ((0.7e-3, 0.2e-3, 0.60e-3), ex, ey)):
        n = 11
        x = np.array(start) + np.linspace(0.0, 0.5e-3, n)[:, None] * direction + [shift, 0.0, 0.0]
        t2 = np.cross(direction, t1)
        q = quat_from_frames(np.tile(t1, (n, 1)), np.tile(t2, (n, 1)), np.tile(direction, (n, 1)))
        out.append(Fiber(x=x, q=q, radii=np.tile([10e-6, 10e-6, 0.0, 0.0], (n, 1))))
    return out


def _run_shifted(work: Path, build_dir: Path, shift: float, yarns_h5: Path) -> np.ndarray:
    from fiberform.fiber_io import DATA_NAME, NODES_NAME, write_fibers_liggghts
    from fiberform.fiber_sheet import write_yarns
    from fiberform.liggghts_log import read_dump

    work.mkdir()
    # unwrapped positions: read_data maps the nodes outside the box into it (image flags kept)
    write_fibers_liggghts(work / DATA_NAME, work / NODES_NAME, _fibers(shift),
                          [0.0, 0.0, 0.0], [2.0e-3, 1.0e-3, 1.0e-3])
    write_yarns(work / "yarns.txt", yarns_h5, (2.0e-3, 1.0e-3))
    (work / "in.shift").write_text(_periodic_input(yarns_h5, STEPS))
    proc = subprocess.run(["nice", str(build_dir / "bin" / "fiberdem"), "-in", "in.shift", "-log", "log.shift"],
                          cwd=work, capture_output=True, text=True, errors="replace", timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    c = read_dump(work / "end.dump")[-1].columns
    return np.stack([c[k] for k in ("xu", "yu", "zu")], axis=1)


@pytest.mark.system
def test_translation_by_one_weave_repeat_changes_nothing(tmp_path: Path, fiberdem_build: Path) -> None:
    """The same fibers in a uniform flow over the periodic 2 x 1 repeat box, once as given and once
    shifted by one weave repeat (1 mm) in x: the final unwrapped positions of the shifted run
    minus the shift equal the first within 1e-9 m. In the first run fiber A straddles x = 0 and
    fiber C lands on it through the periodic side; in the second A lies inside and B straddles
    x = 2 mm. The fibers fell and met the yarns and each other (checked), so the test measures
    the periodic yarn, fiber-fiber and beam images, not fibers at rest."""
    yarns_h5 = tmp_path / "fabric.h5"
    own = weave_yarns(size_x_m=2.0e-3, size_y_m=1.0e-3, lower_side_z_m=0.1e-3)
    with h5py.File(yarns_h5, "w") as h:
        h["yarns/points"], h["yarns/offsets"], h["yarns/radius"] = own.points, own.offsets, own.radius
    first = _run_shifted(tmp_path / "as_given", fiberdem_build, 0.0, yarns_h5)
    second = _run_shifted(tmp_path / "shifted", fiberdem_build, SHIFT_X, yarns_h5)
    start = np.vstack([f.x for f in _fibers(0.0)])
    diff = second - np.array([SHIFT_X, 0.0, 0.0]) - first
    print(f"largest difference {np.abs(diff).max():.3g} m; largest motion {np.abs(first - start).max():.3g} m")
    assert np.abs(diff).max() < 1e-9
    assert np.abs(first - start).max() > 30e-6  # the fibers moved
    a, c = first[0:11], first[11:22]
    assert a[:, 0].min() < 0.0 < a[:, 0].max()  # A straddles x = 0 in the first run
    b2 = second[22:33]
    assert b2[:, 0].min() < 2.0e-3 < b2[:, 0].max()  # B straddles x = 2 mm in the second
    top = float(np.max(own.points[:, 2] + np.repeat(own.radius, np.diff(own.offsets))))
    wefts = top - 0.1e-3  # the top wefts' surface: the warps' knuckles reach one warp diameter higher
    assert abs(float(np.median(a[:, 2])) - (wefts + 10e-6)) < 5e-6  # A rests on the top wefts
    # C rests on A through the periodic side: C at x = 1.9 mm on A's image (A + 2 mm in x); the
    # surface gap of the two centre lines (radii 10 um each) by the independent element distance
    a_img = a + np.array([2.0e-3, 0.0, 0.0])
    gap = _min_element_yarn_distance(a_img[:-1], a_img[1:], c[:-1], c[1:], np.full(10, 10e-6)) - 10e-6
    print(f"surface gap between C and A's image: {gap * 1e9:.3g} nm")
    assert abs(gap) < 1e-6, gap


@pytest.mark.system
def test_one_and_two_ranks_lay_down_the_same_periodic_sheet(periodic_run: Path, build_dir: Path,
                                                            fiberform_cmd: list[str]) -> None:
    """The periodic lay-down again on 2 MPI ranks (the box split in x or y, processors * * 1; the
    periodic sides are rank boundaries too): the same sheet within 1e-9 m, the same accounting."""
    if (os.cpu_count() or 1) < 2:
        pytest.skip("needs 2 cores")
    work = periodic_run
    # the upstream products as they are (their hashes match: only the lay-down runs again)
    shutil.copytree(work / "runs/a", work / "runs/b", ignore=shutil.ignore_patterns("laydown"))
    (work / "b.yaml").write_text(scene_text("b", 2))
    proc = subprocess.run([*fiberform_cmd, "run", "b.yaml", "--to", "laydown", "--build-dir", str(build_dir)],
                          cwd=work, capture_output=True, text=True, errors="replace", timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    sheets = []
    for out in ("a", "b"):
        with h5py.File(work / f"runs/{out}/laydown/laydown.h5", "r") as h:
            sheets.append((h["sheet/x"][...], h["sheet/fiber_id"][...], h["sheet/offsets"][...],
                           [float(h["accounting"][k][()]) for k in ("sheet_mass", "removed_mass")],
                           int(h["run"].attrs["ranks"])))
    (x1, id1, _, m1, r1), (x2, id2, off2, m2, r2) = sheets
    assert (r1, r2) == (1, 2)
    assert np.array_equal(id1, id2) and m1 == m2
    log = (work / "runs/b/laydown/work/log.fiberdem").read_text()
    grid = "1 by 2 by 1" if "1 by 2 by 1 MPI" in log else "2 by 1 by 1"
    assert f"{grid} MPI processor grid" in log  # the sheet plane is split, not z
    axis = 1 if grid == "1 by 2 by 1" else 0
    wrapped = np.mod(x2[:, axis], L)
    assert any(np.any(wrapped[lo:hi] < 0.5 * L) and np.any(wrapped[lo:hi] >= 0.5 * L)
               for lo, hi in zip(off2[:-1], off2[1:])), \
        "no fiber on both ranks"
    print(f"largest difference 1 vs 2 ranks: {np.abs(x2 - x1).max():.3g} m")
    assert np.abs(x2 - x1).max() < 1e-9
