# SPDX-License-Identifier: GPL-3.0-or-later
"""Fiber generation (stage ``generate``, thesis sec. 3.4): shapes, sampled distributions (KS
tests), target mass, no intersections, and the end-to-end CLI + fiberdem load."""

from __future__ import annotations

import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from scipy.spatial import cKDTree

from fiberform.fiber_io import Fiber, quat_to_frames
from fiberform.stages.generate import (
    FiberShape,
    Sampler,
    fiber_shape,
    generate_fibers,
    node_positions,
)

RHO = 1500.0


def test_shape_follows_the_recursion() -> None:
    rng = np.random.default_rng(1)
    n, L = 20, 2e-3
    # alpha = 1: amplitudes L (1 - alpha) vanish -> straight along e1
    e = np.eye(3)
    p = node_positions(L, np.ones((2, n + 1)), n, e, np.zeros(3))
    assert np.allclose(p[:, 1:], 0.0) and np.allclose(p[:, 0], np.linspace(0, L, n + 1))
    # curved: every element has length L / n (eq. 3.4), frames orthonormal, t3 = mean direction
    shape = FiberShape(length_m=L, width_m=15e-6, alpha=rng.uniform(0.7, 0.95, (2, n + 1)),
                       segments=n, cross_section="collapsed", wall_fraction=0.4,
                       twist_max_rad=0.2, radius_jitter=0.02)
    f = fiber_shape(shape, rng)
    le = np.linalg.norm(np.diff(f.x, axis=0), axis=1)
    assert np.allclose(le, L / n, rtol=1e-12)
    t1, t2, t3 = quat_to_frames(f.q)
    assert np.allclose(np.einsum("ij,ij->i", t1, t3), 0, atol=1e-12)
    assert np.allclose(np.cross(t1, t2), t3, atol=1e-12)
    d = np.diff(f.x, axis=0) / le[:, None]
    mid = d[:-1] + d[1:]
    mid /= np.linalg.norm(mid, axis=1)[:, None]
    assert np.allclose(t3[1:-1], mid, atol=1e-12)
    assert np.allclose(t3[0], d[0]) and np.allclose(t3[-1], d[-1])
    # t1 turns about t3 by at most twist_max_rad per node (plus the transport of the frame)
    # collapsed section: a1 = 0.8 w, a2 = 0.2 w (+-2%), hollow b = 0.6 a
    assert np.allclose(f.radii[:, 0], 0.8 * 15e-6, rtol=0.021)
    assert np.allclose(f.radii[:, 1], 0.2 * 15e-6, rtol=0.021)
    assert np.allclose(f.radii[:, 2:], 0.6 * f.radii[:, :2])
    # really curved
    assert np.linalg.norm(f.x[-1] - f.x[0]) < 0.99 * L


def independent_mass(x: np.ndarray, radii: np.ndarray) -> float:
    r = 0.5 * (radii[1:] + radii[:-1])
    area = math.pi * (r[:, 0] * r[:, 1] - r[:, 2] * r[:, 3])
    return float(RHO * np.sum(area * np.linalg.norm(np.diff(x, axis=0), axis=1)))


def no_intersections(fibers: list) -> tuple[bool, float]:
    """Independent check: points every radius/4 along every element; two points of different
    fibers must be farther apart than the sum of their element radii, up to the point spacing."""
    pts, rad, owner = [], [], []
    rmin = min(float(np.min(g.fiber.radii[:, :2])) for g in fibers)
    h = 0.25 * rmin
    for k, g in enumerate(fibers):
        f = g.fiber
        r_el = np.max(0.5 * (f.radii[1:, :2] + f.radii[:-1, :2]), axis=1)
        for e in range(f.n - 1):
            m = max(2, int(np.ceil(np.linalg.norm(f.x[e + 1] - f.x[e]) / h)) + 1)
            s = np.linspace(0, 1, m)[:, None]
            pts.append(f.x[e] + s * (f.x[e + 1] - f.x[e]))
            rad.append(np.full(m, r_el[e]))
            owner.append(np.full(m, k))
    P, R, O = np.vstack(pts), np.concatenate(rad), np.concatenate(owner)
    tree = cKDTree(P)
    pairs = tree.query_pairs(2 * R.max(), output_type="ndarray")
    pairs = pairs[O[pairs[:, 0]] != O[pairs[:, 1]]]
    if len(pairs) == 0:
        return True, math.inf
    d = np.linalg.norm(P[pairs[:, 0]] - P[pairs[:, 1]], axis=1)
    margin = d - (R[pairs[:, 0]] + R[pairs[:, 1]])
    return bool(np.all(margin > -h)), float(margin.min())


@pytest.fixture(scope="module")
def parametric() -> dict:
    length = Sampler({"kind": "lognormal", "mean": 1.5e-3, "sd": 0.5e-3, "min": 0.4e-3, "max": 3e-3})
    width = Sampler({"kind": "normal", "mean": 30e-6, "sd": 6e-6, "min": 15e-6, "max": 50e-6})
    curv = Sampler({"kind": "uniform", "low": 0.85, "high": 1.0})
    fines = Sampler({"kind": "uniform", "low": 0.1e-3, "high": 0.2e-3})
    rng = np.random.default_rng(2024)
    fibers = generate_fibers(rng=rng, box_lo=np.zeros(3), box_hi=np.full(3, 6e-3), density=RHO,
                             length=length, width=width, curvature=curv, segments=8,
                             wall_fraction=0.5, twist_max_rad=0.1, fines_fraction=0.1,
                             fines_length=fines, count=700)
    return {"fibers": fibers, "length": length, "width": width, "curv": curv}


def test_sampled_distributions_match(parametric: dict) -> None:
    fibers = parametric["fibers"]
    long = [g for g in fibers if not g.fine]
    assert len(long) >= 500
    # length: only the non-fines follow the length distribution
    p_len = stats.kstest([g.length_m for g in long], parametric["length"].cdf).pvalue
    p_w = stats.kstest([g.width_m for g in fibers], parametric["width"].cdf).pvalue
    # curvature: the first node's alpha of each fiber (independent draws)
    p_a = stats.kstest([g.alpha[0, 0] for g in fibers], parametric["curv"].cdf).pvalue
    assert min(p_len, p_w, p_a) > 0.01, (p_len, p_w, p_a)
    # the generated geometry has the sampled length (element lengths L / n)
    for g in fibers[:50]:
        contour = np.sum(np.linalg.norm(np.diff(g.fiber.x, axis=0), axis=1))
        assert contour == pytest.approx(g.length_m, rel=1e-12)
        assert 2 * np.max(g.fiber.radii[:, 0]) == pytest.approx(g.width_m, rel=0.021)
    # fines fraction: binomial 4-sigma band
    nf = sum(g.fine for g in fibers)
    sd = math.sqrt(len(fibers) * 0.1 * 0.9)
    assert abs(nf - 0.1 * len(fibers)) < 4 * sd
    assert all(0.1e-3 <= g.length_m <= 0.2e-3 for g in fibers if g.fine)


def test_no_two_fibers_intersect(parametric: dict) -> None:
    ok, margin = no_intersections(parametric["fibers"])
    assert ok, margin


def test_sampling_from_measured_data(tmp_path: Path) -> None:
    """'data' distributions sample the CSV values uniformly: two-sample KS against the data."""
    rng = np.random.default_rng(5)
    measured = {
        "length_m": rng.gamma(4.0, 0.4e-3, 300),
        "width_m": rng.uniform(20e-6, 40e-6, 300),
        "curvature_alpha": rng.uniform(0.8, 1.0, 300),
    }
    csv = tmp_path / "measured.csv"
    rows = ["length_m,width_m,curvature_alpha"] + [
        f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(*measured.values())
    ]
    csv.write_text("\n".join(rows) + "\n")
    from fiberform.stages.generate import read_csv_columns

    data = read_csv_columns(csv)
    s = {k: Sampler({"kind": "data"}, data, k) for k in measured}
    fibers = generate_fibers(rng=np.random.default_rng(9), box_lo=np.zeros(3),
                             box_hi=np.full(3, 1e-2), density=RHO, length=s["length_m"],
                             width=s["width_m"], curvature=s["curvature_alpha"], segments=6,
                             count=500)
    for key, got in (("length_m", [g.length_m for g in fibers]),
                     ("width_m", [g.width_m for g in fibers]),
                     ("curvature_alpha", [g.alpha[1, 0] for g in fibers])):
        p = stats.ks_2samp(got, measured[key]).pvalue
        assert p > 0.01, (key, p)
        assert set(np.round(got, 15)) <= set(np.round(measured[key], 15))


def test_target_mass_within_one_fiber() -> None:
    rng = np.random.default_rng(11)
    target = 2e-9  # kg
    fibers = generate_fibers(rng=rng, box_lo=np.zeros(3), box_hi=np.full(3, 4e-3), density=RHO,
                             length=Sampler({"kind": "uniform", "low": 0.5e-3, "high": 1.5e-3}),
                             width=Sampler({"kind": "fixed", "value": 25e-6}),
                             curvature=Sampler({"kind": "uniform", "low": 0.9, "high": 1.0}),
                             segments=10, wall_fraction=0.4, target_mass_kg=target)
    masses = [independent_mass(g.fiber.x, g.fiber.radii) for g in fibers]
    assert np.allclose(masses, [g.mass_kg for g in fibers], rtol=1e-12)
    assert abs(sum(masses) - target) <= max(masses)
    assert sum(masses) >= target
    ok, _ = no_intersections(fibers)
    assert ok


SCENE = """
name: gen_test
seed: 3
domain:
  lo_m: [0.0, 0.0, 0.0]
  hi_m: [0.003, 0.003, 0.003]
fibers:
  target_mass_kg: 1.0e-9
  width_m: 30.0e-6
  density_kg_m3: 1500.0
  youngs_modulus_Pa: 10.0e9
  shear_modulus_Pa: 4.0e9
fiber_generation:
  length_m: {kind: lognormal, mean: 1.0e-3, sd: 0.3e-3, min: 0.3e-3, max: 2.0e-3}
  width_m: {kind: normal, mean: 30.0e-6, sd: 5.0e-6, min: 15.0e-6, max: 45.0e-6}
  curvature_alpha: {kind: uniform, low: 0.9, high: 1.0}
  wall_fraction: 0.4
  fines_fraction: 0.1
  fines_length_m: {kind: uniform, low: 0.15e-3, high: 0.3e-3}
  element_length_m: 0.1e-3
run:
  timestep_s: 1.0e-9
  duration_s: 1.0e-8
"""


@pytest.mark.system
def test_cli_generate_then_fiberdem_loads(tmp_path: Path, build_dir: Path,
                                          fiberform_cmd: list[str]) -> None:
    exe = build_dir / "bin" / "fiberdem"
    if not exe.is_file():
        pytest.skip(f"{exe} not built")
    scene = tmp_path / "scene.yaml"
    scene.write_text(SCENE)
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    cmd = [*fiberform_cmd, "generate", str(scene), "--build-dir", str(build_dir)]
    p = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, errors="replace", timeout=600)
    assert p.returncode == 0, p.stderr
    out = tmp_path / "runs" / "gen_test" / "fibers"
    import h5py

    with h5py.File(out / "fibers.h5") as h5:
        total = float(h5["fibers"].attrs["total_mass_kg"])
        masses = h5["fibers/mass"][:]
        assert h5["fibers/x"].attrs["units"] == "m"
        assert h5.attrs["stage"] == "generate"
    assert abs(total - 1e-9) <= masses.max()
    # fiberdem loads the fibers with fix fiber/beam
    q = subprocess.run([str(exe), "-in", "in.fibers", "-log", "log.fiberdem"], cwd=out, env=env,
                       capture_output=True, text=True, errors="replace", timeout=300)
    assert q.returncode == 0, q.stdout[-2000:]
    log = (out / "log.fiberdem").read_text()
    assert f"fix fiber/beam: {len(masses)} fibers" in log
    # second run is up to date
    p2 = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, errors="replace", timeout=600)
    assert p2.returncode == 0 and "up to date" in p2.stdout


def test_periodic_placement_covers_the_sides_without_intersections() -> None:
    """laydown.walls periodic (period = the placement box in x and y): the fibers' bounding-box
    centres are uniform over the box, so the node mass in a band along the sides equals the band's
    area share (inside-the-box placement, the default, leaves that band at a fraction: fibers of
    half the box length cannot have their middle near a side); fibers cross the sides; and no two
    fibers intersect, periodic images included (checked here with segments_intersect on the 9
    images)."""
    from fiberform.stages.generate import segments_intersect

    L, band = 1.0e-3, 0.15e-3
    kw = dict(box_lo=np.array([0.0, 0.0, 0.0]), box_hi=np.array([L, L, 0.5e-3]), density=RHO,
              length=Sampler({"kind": "fixed", "value": 0.5e-3}),
              width=Sampler({"kind": "fixed", "value": 20e-6}),
              curvature=Sampler({"kind": "fixed", "value": 1.0}), segments=5, count=120)

    def band_share(sets: list) -> float:
        x = np.vstack([g.fiber.x for fibers in sets for g in fibers])
        x[:, :2] = np.mod(x[:, :2], L)
        edge = (x[:, 0] < band) | (x[:, 0] > L - band) | (x[:, 1] < band) | (x[:, 1] > L - band)
        return float(np.mean(edge))

    area_share = 1.0 - (1.0 - 2 * band / L) ** 2  # 0.51
    seeds = (4, 5, 6)
    inside = [generate_fibers(rng=np.random.default_rng(s), **kw) for s in seeds]
    sets = [generate_fibers(rng=np.random.default_rng(s), period=(L, L), **kw) for s in seeds]
    assert band_share(inside) < 0.85 * area_share  # measured 0.394
    assert band_share(sets) == pytest.approx(area_share, abs=0.035)  # measured 0.514
    periodic = sets[0]
    crossing = [g for g in periodic if np.any(g.fiber.x[:, :2] < 0.0) or np.any(g.fiber.x[:, :2] > L)]
    assert len(crossing) > 25
    for i, a in enumerate(periodic):
        for b in periodic[i + 1:]:
            for dx in (-L, 0.0, L):
                for dy in (-L, 0.0, L):
                    if abs(a.fiber.x[0, 0] - b.fiber.x[0, 0] - dx) > 1.2e-3 or \
                            abs(a.fiber.x[0, 1] - b.fiber.x[0, 1] - dy) > 1.2e-3:
                        continue  # too far apart to touch (0.5 mm fibers)
                    img = Fiber(x=b.fiber.x + np.array([dx, dy, 0.0]), q=b.fiber.q, radii=b.fiber.radii)
                    assert not segments_intersect(a.fiber, img)


BAD_GENERATION = {
    # (replaced line of SCENE, its replacement, words the error names)
    "negative fixed length": ("  length_m: {kind: lognormal, mean: 1.0e-3, sd: 0.3e-3, min: 0.3e-3, max: 2.0e-3}",
                              "  length_m: {kind: fixed, value: -1.0e-3}",
                              "fiber_generation.length_m", "must lie in (0, 0.1]"),
    "a field of another kind": ("  curvature_alpha: {kind: uniform, low: 0.9, high: 1.0}",
                                "  curvature_alpha: {kind: uniform, low: 0.9, high: 1.0, mean: 0.95}",
                                "fiber_generation.curvature_alpha.mean", "only used with kind normal"),
    "curvature above 1": ("  curvature_alpha: {kind: uniform, low: 0.9, high: 1.0}",
                          "  curvature_alpha: {kind: uniform, low: 0.9, high: 1.2}",
                          "fiber_generation.curvature_alpha", "must lie in (0, 1]"),
    "untruncated normal width": ("  width_m: {kind: normal, mean: 30.0e-6, sd: 5.0e-6, min: 15.0e-6, max: 45.0e-6}",
                                 "  width_m: {kind: normal, mean: 30.0e-6, sd: 5.0e-6}",
                                 "fiber_generation.width_m", "truncate with min and max"),
    "data without a file": ("  width_m: {kind: normal, mean: 30.0e-6, sd: 5.0e-6, min: 15.0e-6, max: 45.0e-6}",
                            "  width_m: {kind: data}", "fiber_generation.width_m", "needs fiber_generation.data_csv"),
    "min above max": ("  width_m: {kind: normal, mean: 30.0e-6, sd: 5.0e-6, min: 15.0e-6, max: 45.0e-6}",
                      "  width_m: {kind: normal, mean: 30.0e-6, sd: 5.0e-6, min: 45.0e-6, max: 15.0e-6}",
                      "fiber_generation.width_m.max", "must be greater than min"),
    "placement box inside out": ("  element_length_m: 0.1e-3",
                                 "  element_length_m: 0.1e-3\n  placement_lo_m: [0.0, 0.0, 2.0e-3]\n"
                                 "  placement_hi_m: [3.0e-3, 3.0e-3, 1.0e-3]",
                                 "fiber_generation.placement_hi_m", "must exceed placement_lo_m"),
    # a fixed value beside its sampled replacement would reach nothing: one of them
    "length given twice": ("  width_m: 30.0e-6\n", "  width_m: 30.0e-6\n  length_m: 1.0e-3\n",
                           "fibers.length_m", "give one of fibers.length_m and fiber_generation.length_m"),
    "segments beside element length": ("  width_m: 30.0e-6\n", "  width_m: 30.0e-6\n  segments: 10\n",
                                       "fibers.segments", "give one of fibers.segments and "
                                       "fiber_generation.element_length_m"),
    "no length at all": ("  length_m: {kind: lognormal, mean: 1.0e-3, sd: 0.3e-3, min: 0.3e-3, max: 2.0e-3}\n", "",
                         "fibers.length_m", "required unless fiber_generation.length_m"),
    "no element count": ("  element_length_m: 0.1e-3\n", "", "fibers.segments",
                         "required unless fiber_generation.element_length_m"),
}


@pytest.mark.parametrize("case", sorted(BAD_GENERATION))
def test_bad_distributions_exit_2_naming_the_field(tmp_path: Path, fiberform_cmd: list[str], case: str) -> None:
    old, new, field, words = BAD_GENERATION[case]
    assert old in SCENE
    (tmp_path / "scene.yaml").write_text(SCENE.replace(old, new))
    r = subprocess.run([*fiberform_cmd, "generate", "scene.yaml"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2, r.stderr
    assert field in r.stderr and words in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.yaml"]


@pytest.mark.parametrize("csv, words", [
    (None, "cannot read data_csv"),
    ("length_m,curvature_alpha\n1.0e-3,0.95\n", "has no such column"),
    ("length_m,width_m,curvature_alpha\n1.0e-3,30e-6,0.95\n1.2e-3,-2e-6,0.9\n", "1 value(s) outside (0, 0.01]"),
], ids=["missing file", "missing column", "negative width"])
def test_bad_measured_data_exit_2_before_anything_is_written(tmp_path: Path, fiberform_cmd: list[str],
                                                             csv: str | None, words: str) -> None:
    scene = SCENE.replace("  width_m: {kind: normal, mean: 30.0e-6, sd: 5.0e-6, min: 15.0e-6, max: 45.0e-6}",
                          "  width_m: {kind: data}\n  data_csv: measured.csv")
    (tmp_path / "scene.yaml").write_text(scene)
    if csv is not None:
        (tmp_path / "measured.csv").write_text(csv)
    r = subprocess.run([*fiberform_cmd, "generate", "scene.yaml"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2, r.stderr
    assert "fiber_generation." in r.stderr and words in r.stderr, r.stderr
    assert not (tmp_path / "runs").exists()
