# SPDX-License-Identifier: GPL-3.0-or-later
"""The sheet's fiber-fiber gap with the sections of the contacts inside the implicit step: circles,
or collapsed fibers' rectangles 2 a1 x 2 a2 oriented by the node quaternions (fiber_sheet.rect_extent,
the twin of contact_geometry.h rect_extent; fiber_sheet.fiber_fiber_gap), and the node quaternion
columns of the stages' dumps for collapsed fibers. No binaries needed."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from fiberform.fabric_geometry import segment_closest_differences, segment_distances
from fiberform.fiber_io import quat_from_frames, quat_rotate
from fiberform.fiber_sheet import (
    element_clearance, fiber_fiber_gap, frame_fibers, frame_quaternions, node_dump_columns, rect_extent,
)
from fiberform.scene import parse_scene

X, Y, Z = np.eye(3)
A1, A2 = 8.0e-6, 2.0e-6  # m, a collapsed fiber's half-width and half-thickness
S45 = math.sqrt(0.5)


def rotation(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation by angle_deg about the unit axis."""
    h = 0.5 * math.radians(angle_deg)
    return np.concatenate([[math.cos(h)], math.sin(h) * np.asarray(axis, dtype=float)])


def qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Quaternion product p q (q applied first, in p's rotated frame: a body rotation)."""
    w1, v1, w2, v2 = p[0], p[1:], q[0], q[1:]
    return np.concatenate([[w1 * w2 - v1 @ v2], w1 * v2 + w2 * v1 + np.cross(v1, v2)])


# flat along y: t1 = x (width horizontal), t2 = -z (thickness vertical), t3 = y
Q_FLAT_Y = rotation(X, -90.0)
# flat along x: rotation about y by +90 deg, then a body rotation of +90 deg about t3
Q_FLAT_X = qmul(rotation(Y, 90.0), rotation(Z, 90.0))
# on its edge along x: t1 = -z (width vertical), t2 = y
Q_EDGE_X = rotation(Y, 90.0)


def frame(q: np.ndarray) -> tuple[np.ndarray, ...]:
    return tuple(quat_rotate(q[None, :], e)[0] for e in (X, Y, Z))


def test_the_test_quaternions_have_the_intended_frames() -> None:
    for q, (t1, t2, t3) in ((Q_FLAT_Y, (X, -Z, Y)), (Q_FLAT_X, (Y, Z, X)), (Q_EDGE_X, (-Z, Y, X))):
        np.testing.assert_allclose(np.array(frame(q)), np.array([t1, t2, t3]), atol=1e-15)


# ---- the extent of a rectangle (closed forms) --------------------------------------------------
def test_rect_extent_closed_forms() -> None:
    """Axis z, t2 = y (a2 along y), so a1 along t2 x axis = x."""
    def ext(n: np.ndarray, a1: float = A1, a2: float = A2, t2: np.ndarray = Y) -> float:
        return float(rect_extent(Z, t2, a1, a2, np.asarray(n, dtype=float)))

    assert ext(Y) == pytest.approx(A2, rel=1e-15)  # face along t2
    assert ext(-X) == pytest.approx(A1, rel=1e-15)  # face along t1
    assert ext([S45, S45, 0.0]) == pytest.approx(A2 / S45, rel=1e-15)  # 45 deg, a1 > a2
    assert ext([S45, S45, 0.0], a1=A2, a2=A1) == pytest.approx(A2 / S45, rel=1e-15)
    corner = np.array([A1, A2, 0.0]) / math.hypot(A1, A2)
    assert ext(corner) == pytest.approx(math.hypot(A1, A2), rel=1e-14)
    assert ext([0.0, S45, S45]) == pytest.approx(A2, rel=1e-15)  # axial part dropped
    assert ext([0.0, 0.6, -0.8]) == pytest.approx(A2, rel=1e-15)
    assert ext(Z) == A2 and ext(-Z, a1=1e-6) == 1e-6  # along the axis: min(a1, a2)
    assert ext(np.zeros(3)) == A2  # no direction (touching centre lines)
    # t2 made normal to the axis and unit
    assert ext(Y, t2=3.0 * (Y + 0.5 * Z)) == pytest.approx(A2, rel=1e-15)
    assert ext(X, t2=3.0 * (Y + 0.5 * Z)) == pytest.approx(A1, rel=1e-15)
    # t2 along the axis or zero: x instead (zero: z first, along this axis too)
    for t2 in (2.0 * Z, np.zeros(3)):
        assert ext(X, t2=t2) == pytest.approx(A2, rel=1e-15)
        assert ext(Y, t2=t2) == pytest.approx(A1, rel=1e-15)


def test_rect_extent_is_vectorised() -> None:
    rng = np.random.default_rng(3)
    n = rng.normal(size=(5, 4, 3))
    n /= np.linalg.norm(n, axis=-1)[..., None]
    axis = np.broadcast_to(Z, (5, 4, 3))
    got = rect_extent(axis, np.array([0.0, 2.0, 0.3]), np.full((5, 4), A1), A2, n)
    assert got.shape == (5, 4)
    one = [float(rect_extent(Z, np.array([0.0, 2.0, 0.3]), A1, A2, v)) for v in n.reshape(-1, 3)]
    np.testing.assert_array_equal(got.ravel(), one)
    assert np.all((got >= A2 * (1 - 1e-15)) & (got <= math.hypot(A1, A2) * (1 + 1e-15)))


# ---- closest points: one implementation ---------------------------------------------------------
def test_segment_distances_are_the_norm_of_the_closest_point_differences() -> None:
    d = segment_closest_differences(np.array([-1.0, 0, 0]), np.array([1.0, 0, 0]),
                                    np.array([0.25, -1, 3]), np.array([0.25, 1, 3]))
    np.testing.assert_array_equal(d, [0.0, 0.0, -3.0])  # c1 - c2
    rng = np.random.default_rng(1)
    p1, q1, p2, q2 = rng.normal(size=(4, 50, 3))
    np.testing.assert_array_equal(
        segment_distances(p1[:, None], q1[:, None], p2[None], q2[None]),
        np.linalg.norm(segment_closest_differences(p1[:, None], q1[:, None], p2[None], q2[None]), axis=-1))


# ---- fiber-fiber gaps of collapsed fibers -------------------------------------------------------
def two_fibers(xa: np.ndarray, qa: np.ndarray, xb: np.ndarray, qb: np.ndarray,
               axes_a: np.ndarray, axes_b: np.ndarray) -> tuple[np.ndarray, ...]:
    x = np.vstack([xa, xb])
    q = np.vstack([np.tile(qa, (len(xa), 1)), np.tile(qb, (len(xb), 1))])
    axes = np.vstack([axes_a, axes_b])
    return x, np.array([0, len(xa), len(xa) + len(xb)]), np.max(axes, axis=1), axes, q


def test_flat_ribbons_crossing_one_above_the_other() -> None:
    """A flat ribbon along x at z = 0 under a flat one along y: centre lines 2 a2 + 5 nm apart
    (the larger a2 of each element's nodes), gap 5 nm."""
    line = np.array([-30e-6, 10e-6, 40e-6])  # crossing inside the middle elements, not at a node
    # the crossing elements: A's nodes 0-1 (larger a2: A2), B's nodes 0-1 (1.02 A2)
    axes_a = np.array([[A1, A2], [0.99 * A1, 0.98 * A2], [1.01 * A1, 1.01 * A2]])
    axes_b = np.array([[A1, 0.97 * A2], [1.02 * A1, 1.02 * A2], [A1, A2]])
    c = A2 + 1.02 * A2 + 5e-9
    xa = np.stack([line, np.full(3, 1e-6), np.zeros(3)], axis=1)
    xb = np.stack([np.full(3, 2e-6), line, np.full(3, c)], axis=1)
    args = two_fibers(xa, Q_FLAT_X, xb, Q_FLAT_Y, axes_a, axes_b)
    assert fiber_fiber_gap(*args) == pytest.approx(5e-9, abs=1e-15)
    # circles of the larger half-axis: a large false overlap
    assert fiber_fiber_gap(*args[:3]) < -10e-6


def test_ribbon_on_its_edge_under_a_flat_one() -> None:
    """On its edge along x (a1 vertical) under a flat ribbon along y (a2 vertical): centre lines
    a1 + a2 + 5 nm apart, gap 5 nm; then the lower one turned flat: 5 nm + a1 - a2."""
    line = np.array([-30e-6, 0.0, 30e-6])
    axes = np.tile([A1, A2], (3, 1))
    c = A1 + A2 + 5e-9
    xa = np.stack([line, np.zeros(3), np.zeros(3)], axis=1)
    xb = np.stack([np.zeros(3), line, np.full(3, c)], axis=1)
    assert fiber_fiber_gap(*two_fibers(xa, Q_EDGE_X, xb, Q_FLAT_Y, axes, axes)) == pytest.approx(5e-9, abs=1e-15)
    assert fiber_fiber_gap(*two_fibers(xa, Q_FLAT_X, xb, Q_FLAT_Y, axes, axes)) == pytest.approx(
        5e-9 + A1 - A2, abs=1e-15)


def test_a_gap_needs_the_quaternions_of_rectangles() -> None:
    x, offsets, r, axes, _ = two_fibers(np.array([[0.0, 0, 0], [1e-5, 0, 0]]), Q_FLAT_X,
                                        np.array([[0.0, 0, 1e-5], [0, 1e-5, 1e-5]]), Q_FLAT_Y,
                                        np.tile([A1, A2], (2, 1)), np.tile([A1, A2], (2, 1)))
    with pytest.raises(ValueError, match="quaternions"):
        fiber_fiber_gap(x, offsets, r, axes)


def random_sheet(rng: np.random.Generator, fibers: int, nodes: int,
                 rect: bool) -> tuple[np.ndarray, ...]:
    """Fibers of random straight-ish chains in a 200 um box with random frames."""
    xs, qs, ax = [], [], []
    for _ in range(fibers):
        start = rng.uniform(0.0, 200e-6, 3)
        steps = rng.normal(size=(nodes - 1, 3)) * 5e-6 + rng.normal(size=3) * 15e-6
        xs.append(np.vstack([start, start + np.cumsum(steps, axis=0)]))
        t3 = rng.normal(size=(nodes, 3))
        t3 /= np.linalg.norm(t3, axis=1)[:, None]
        t1 = np.cross(t3, rng.normal(size=(nodes, 3)))
        t1 /= np.linalg.norm(t1, axis=1)[:, None]
        qs.append(quat_from_frames(t1, np.cross(t3, t1), t3))
        a = rng.uniform(0.95, 1.05, (nodes, 2)) * ([A1, A2] if rect else [A1, A1])
        ax.append(a if rect else a[:, :1].repeat(2, axis=1))
    x, q, axes = np.vstack(xs), np.vstack(qs), np.vstack(ax)
    return x, np.arange(0, fibers * nodes + 1, nodes), np.max(axes, axis=1), axes, q


def brute_gap(x: np.ndarray, offsets: np.ndarray, radius: np.ndarray, axes: np.ndarray,
              q: np.ndarray) -> float:
    """Every element pair of different fibers, each with its extents (no pruning, no chunks)."""
    owner = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets) - 1)
    el = np.concatenate([np.arange(lo, hi - 1) for lo, hi in zip(offsets[:-1], offsets[1:])])
    a, b = np.meshgrid(el, el, indexing="ij")
    d = segment_closest_differences(x[a], x[a + 1], x[b], x[b + 1])
    dist = np.linalg.norm(d, axis=-1)
    with np.errstate(invalid="ignore"):  # an element with itself: left out below
        n = d / dist[..., None]
    rect = axes[:, 0] != axes[:, 1]
    gap = dist
    for k in (a, b):
        chord = x[k + 1] - x[k]
        axis = chord / np.linalg.norm(chord, axis=-1)[..., None]
        t2 = (quat_rotate(q[k].reshape(-1, 4), Y) + quat_rotate(q[k + 1].reshape(-1, 4), Y)).reshape(k.shape + (3,))
        e = rect_extent(axis, t2, np.maximum(axes[k, 0], axes[k + 1, 0]), np.maximum(axes[k, 1], axes[k + 1, 1]), n)
        gap = gap - np.where(rect[k] | rect[k + 1], e, np.maximum(radius[k], radius[k + 1]))
    return float(np.min(gap[owner[:, None] != owner[None, :]]))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pruned_gap_equals_every_pair(seed: int) -> None:
    """450 elements: the k-d tree search finds the smallest gap of all pairs."""
    args = random_sheet(np.random.default_rng(seed), 50, 10, rect=True)
    assert fiber_fiber_gap(*args) == pytest.approx(brute_gap(*args), abs=1e-18)


def brute_periodic_gap(x: np.ndarray, offsets: np.ndarray, radius: np.ndarray, period: tuple[float, float]) -> float:
    """Circles, periodic x/y: every element pair of different fibers, B at the image whose midpoint
    is closest to A's."""
    owner = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets) - 1)
    el = np.concatenate([np.arange(lo, hi - 1) for lo, hi in zip(offsets[:-1], offsets[1:])])
    a, b = np.meshgrid(el, el, indexing="ij")
    diff = 0.5 * (x[b] + x[b + 1]) - 0.5 * (x[a] + x[a + 1])
    sh = np.zeros_like(diff)
    for k in (0, 1):
        sh[..., k] = -np.round(diff[..., k] / period[k]) * period[k]
    dist = segment_distances(x[a], x[a + 1], x[b] + sh, x[b + 1] + sh)
    gap = dist - np.maximum(radius[a], radius[a + 1]) - np.maximum(radius[b], radius[b + 1])
    return float(np.min(gap[owner[:, None] != owner[None, :]]))


@pytest.mark.parametrize("seed", [3, 4])
def test_periodic_gap_equals_every_pair(seed: int) -> None:
    """Periodic x/y (chains reaching out of the 200 x 200 um box): the k-d tree search with its
    minimal images finds the smallest gap of all pairs at their closest images."""
    x, offsets, r, _, _ = random_sheet(np.random.default_rng(seed), 40, 8, rect=False)
    period = (200e-6, 200e-6)
    assert fiber_fiber_gap(x, offsets, r, period=period) == pytest.approx(
        brute_periodic_gap(x, offsets, r, period), abs=1e-18)


def test_far_apart_fibers_give_their_exact_gap() -> None:
    """Two short fibers 1 mm apart (far beyond the first search radius): the search radius grows
    until the gap is certain, the value is the closed form."""
    x = np.array([[0.0, 0.0, 0.0], [10e-6, 0.0, 0.0], [20e-6, 0.0, 0.0],
                  [0.0, 1e-3, 0.0], [10e-6, 1e-3, 0.0], [20e-6, 1e-3, 0.0]])
    r = np.full(6, 10e-6)
    assert fiber_fiber_gap(x, np.array([0, 3, 6]), r) == pytest.approx(1e-3 - 20e-6, rel=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_clearance_equals_every_pair(seed: int) -> None:
    """Element-yarn clearance: the k-d tree search equals the minimum over every element and yarn
    segment (random fibers among random yarn polylines); with per-node radii, the surface gap."""
    rng = np.random.default_rng(seed)
    x, offsets, _, _, _ = random_sheet(rng, 30, 8, rect=False)
    ypts = np.vstack([np.linspace(rng.uniform(0, 200e-6, 3), rng.uniform(0, 200e-6, 3), 12) for _ in range(6)])
    yoff = np.arange(0, 6 * 12 + 1, 12)
    yrad = rng.uniform(5e-6, 30e-6, 6)
    el = np.concatenate([np.arange(lo, hi - 1) for lo, hi in zip(offsets[:-1], offsets[1:])])
    sa = np.vstack([ypts[yoff[k]:yoff[k + 1] - 1] for k in range(6)])
    sb = np.vstack([ypts[yoff[k] + 1:yoff[k + 1]] for k in range(6)])
    sr = np.repeat(yrad, 11)
    brute = float(np.min(segment_distances(x[el][:, None], x[el + 1][:, None], sa[None], sb[None]) - sr[None]))
    assert element_clearance(x, offsets, ypts, yoff, yrad) == pytest.approx(brute, abs=1e-18)
    # with the fibers' radii (one per fiber, very different): the surface gap, element by element,
    # not the smallest clearance less the largest radius (the press's overlap before session 28)
    rf = rng.uniform(2e-6, 40e-6, len(offsets) - 1)
    rn = np.repeat(rf, np.diff(offsets))
    brute_s = float(np.min(segment_distances(x[el][:, None], x[el + 1][:, None], sa[None], sb[None])
                           - sr[None] - rn[el][:, None]))
    assert element_clearance(x, offsets, ypts, yoff, yrad, rn) == pytest.approx(brute_s, abs=1e-18)


def test_circular_fibers_give_the_same_gap_as_before() -> None:
    """Circles (a1 == a2): the sections and quaternions change nothing; the gap is the centre-line
    distance minus the elements' larger node radius, pair by pair."""
    x, offsets, r, axes, q = random_sheet(np.random.default_rng(7), 50, 10, rect=False)
    before = fiber_fiber_gap(x, offsets, r)
    assert fiber_fiber_gap(x, offsets, r, axes) == before
    assert fiber_fiber_gap(x, offsets, r, axes, q) == before
    assert brute_gap(x, offsets, r, axes, q) == before


def test_frame_quaternions_follow_frame_fibers_order() -> None:
    rng = np.random.default_rng(5)
    fid = np.array([2, 1, 2, 1, 1, 2], dtype=float)
    node = np.array([1, 2, 0, 0, 1, 2], dtype=float)
    q = rng.normal(size=(6, 4))
    cols = {"f_beam[1]": fid, "f_beam[2]": node, "x": 10 * fid + node, "y": node, "z": fid,
            **{f"f_beam[{4 + k}]": q[:, k] for k in range(4)}}
    x, present, offsets = frame_fibers(cols)
    got = frame_quaternions(cols)
    assert got is not None
    for row, (xr, qr) in enumerate(zip(x, got)):
        k = int(np.nonzero(10 * fid + node == xr[0])[0][0])
        np.testing.assert_array_equal(qr, q[k])
    np.testing.assert_array_equal(present, [0, 1])
    np.testing.assert_array_equal(offsets, [0, 3, 6])
    del cols["f_beam[7]"]
    assert frame_quaternions(cols) is None


# ---- the stages' dumps --------------------------------------------------------------------------
SCENE = """
name: sections
run: {timestep_s: 1.0e-7, duration_s: 1.0e-3}
domain: {lo_m: [0.0, 0.0, 0.0], hi_m: [1.0e-3, 1.0e-3, 3.437e-3]}
fibers: {count: 2, length_m: 0.4e-3, width_m: 20.0e-6, segments: 8,
         youngs_modulus_Pa: 10.0e+9, shear_modulus_Pa: 4.0e+9%s}
fabric: {size_x_m: 1.0e-3, size_y_m: 1.0e-3}
flow: {delta_p_Pa: 100.0, cell_size_m: 50.0e-6, height_above_fabric_m: 0.8e-3}
laydown: {terms: [steric], max_time_s: 0.001, check_interval_s: 5.0e-4}
contact: {model: fiber_dlvo, terms: [vdw, steric], hamaker_J: 8.0e-21}
press: {mode: pressure, target_pressure_Pa: 20.0}
"""
COLLAPSED = ", cross_section: rectangular, thickness_m: 5.0e-6"
CIRCULAR_DUMP = ["dump traj all custom 50 traj.dump id mass x y z vx vy vz f_beam[1] f_beam[2]",
                 'dump_modify traj sort id format "%d' + " %.17g" * 9 + '"']


def dump_lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.startswith(("dump traj", "dump_modify traj sort"))]


def test_laydown_dump_has_the_quaternions_of_collapsed_fibers_only() -> None:
    from fiberform.stages import laydown

    circular = parse_scene(yaml.safe_load(SCENE % ""), "s.yaml")
    assert dump_lines(laydown.build_input(circular, 50, 2)) == CIRCULAR_DUMP  # unchanged
    collapsed = parse_scene(yaml.safe_load(SCENE % COLLAPSED), "s.yaml")
    text = laydown.build_input(collapsed, 50, 2)
    assert dump_lines(text) == [CIRCULAR_DUMP[0] + " f_beam[4] f_beam[5] f_beam[6] f_beam[7]",
                                'dump_modify traj sort id format "%d' + " %.17g" * 13 + '"']
    # nothing else changes
    assert [ln for ln in text.splitlines() if ln not in dump_lines(text)] == [
        ln for ln in laydown.build_input(circular, 50, 2).splitlines() if ln not in CIRCULAR_DUMP]


def test_press_dump_has_the_quaternions_of_collapsed_fibers_only() -> None:
    from fiberform.stages import press

    for extra, cols in (("", []), (COLLAPSED, ["f_beam[4]", "f_beam[5]", "f_beam[6]", "f_beam[7]"])):
        scene = parse_scene(yaml.safe_load(SCENE % extra), "s.yaml")
        plan = press.PressPlan(scene, sheet_top=2.677e-3, fabric_top=2.637e-3, t_min=20e-6)
        dump, modify = dump_lines(press.build_input(scene, plan))
        assert dump.split()[6:] == ["id", "mass", "x", "y", "z", "vx", "vy", "vz", "f_beam[1]", "f_beam[2]", *cols]
        assert modify.count("%.17g") == 9 + len(cols)
        columns, _ = node_dump_columns(scene.fibers)
        assert [str(c) for c in columns] == dump.split()[6:]
