# SPDX-License-Identifier: GPL-3.0-or-later
"""Geometry of woven forming fabrics: generator, checks, voxel image, surface mesh, imports.

One geometry serves every consumer (Kettil 2016, section 3.3):

* yarn centrelines (polylines) with radii: static bodies for fiber-fabric contact;
* a voxel image (solid = 1) for the CFD mesh of the flow stage;
* a closed, consistently oriented triangle surface (STL) for visualisation or snappyHexMesh.

The weave
---------
A double-layer fabric with one warp system (MD, along x) and two stacked weft systems (CD, along
y): in every weft column a top weft lies straight above a bottom weft, with a gap of exactly one
warp diameter between them. In a repeat of ``shed`` columns each warp passes over the top weft of
one column, under the bottom weft of another (``bottom_shift`` columns later) and between the two
layers elsewhere; neighbouring warps shift their pattern by ``shed_step`` columns (a satin-like
move). The defaults give an 8-shed double-layer fabric 0.637 mm thick, the thickness of the
PRINTEX Q13 fabric of the thesis (its exact yarn data are not published; the defaults are plausible
fine forming-fabric values).

Warp paths follow Peirce's geometry of circular, incompressible yarns: each warp wraps the weft
yarns it touches in circular arcs (radius = sum of the two yarn radii, plus an optional clearance)
joined by common tangents, like a belt over pulleys. This is the crimp of the warp; it follows from
the diameters, counts and shed pattern and is reported (``warp_crimp``). Wefts are straight (no weft
crimp). A sinusoidal warp path was rejected: for realistic yarn sizes its curvature at the crossing
points is too high and the warp cuts into the wefts (a sinusoid of half-period p clears a cylinder
of clearance radius R only if p >= pi R; for the defaults p = 0.33 mm < pi R = 0.38 mm).

Arcs are written as circumscribed polylines: every polyline segment is tangent to the true arc, so
the polyline tube never enters the weft it wraps (checked by :func:`check_yarns`).

Coordinates are those of the simulation domain: the piece covers [0, size_x] x [0, size_y] and its
lower side lies at ``lower_side_z_m`` (2 mm above the domain bottom, thesis section 3.1).
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

__all__ = [
    "CD_BOTTOM",
    "CD_TOP",
    "KIND_NAMES",
    "MD_WARP",
    "FabricGeometryError",
    "VoxelImage",
    "WeaveParams",
    "Yarn",
    "analytic_open_area",
    "build_weave",
    "close_field",
    "check_yarns",
    "marching_tetrahedra",
    "mesh_edge_report",
    "mesh_volume",
    "read_stl",
    "signed_distance_image",
    "voxel_open_area",
    "voxelize_mesh",
    "warp_crimp",
    "weave_states",
    "write_stl",
]

FloatArray = npt.NDArray[np.float64]

#: Kinds of yarn (stored in fabric.h5 /yarns/kind).
MD_WARP, CD_TOP, CD_BOTTOM = 0, 1, 2
KIND_NAMES = {MD_WARP: "MD warp", CD_TOP: "CD top weft", CD_BOTTOM: "CD bottom weft"}


class FabricGeometryError(ValueError):
    """The parameters describe no valid fabric (yarns would have to intersect), or an imported
    file is unusable. The message names the parameter to change."""


@dataclass(frozen=True)
class WeaveParams:
    """Parameters of the double-layer weave (SI units)."""

    size_x_m: float = 3.0e-3
    size_y_m: float = 3.0e-3
    md_diameter_m: float = 0.11e-3
    cd_top_diameter_m: float = 0.13e-3
    cd_bottom_diameter_m: float = 0.177e-3
    md_count_per_m: float = 5000.0
    cd_count_per_m: float = 3000.0
    shed: int = 8
    shed_step: int = 3
    bottom_shift: int | None = None
    clearance_m: float = 0.0
    lower_side_z_m: float = 2.0e-3
    arc_step_deg: float = 10.0

    @property
    def md_pitch_m(self) -> float:
        return 1.0 / self.md_count_per_m

    @property
    def cd_pitch_m(self) -> float:
        return 1.0 / self.cd_count_per_m

    @property
    def shift(self) -> int:
        return self.shed // 2 if self.bottom_shift is None else self.bottom_shift

    @property
    def thickness_m(self) -> float:
        """d_top + d_bottom + 3 d_md + 4 clearances: warp over the top weft, through the gap
        between the stacked wefts, and under the bottom weft."""
        return (
            self.cd_top_diameter_m
            + self.cd_bottom_diameter_m
            + 3.0 * self.md_diameter_m
            + 4.0 * self.clearance_m
        )

    def levels(self) -> tuple[float, float, float]:
        """Centre heights of the bottom weft, the top weft and the mid-plane between them."""
        rw = 0.5 * self.md_diameter_m
        rt = 0.5 * self.cd_top_diameter_m
        rb = 0.5 * self.cd_bottom_diameter_m
        c = self.clearance_m
        z_b = self.lower_side_z_m + 2 * rw + rb + c
        z_t = z_b + rb + 2 * rw + rt + 2 * c
        z_mid = z_b + rb + rw + c
        return z_b, z_t, z_mid

    def problems(self) -> list[str]:
        """Parameter combinations for which no non-intersecting weave exists."""
        out: list[str] = []
        for name in ("size_x_m", "size_y_m", "md_diameter_m", "cd_top_diameter_m",
                     "cd_bottom_diameter_m", "md_count_per_m", "cd_count_per_m"):  # fmt: skip
            if not getattr(self, name) > 0:
                out.append(f"{name} must be > 0")
        if out:
            return out
        if self.shed < 3:
            out.append(f"shed = {self.shed}: a double-layer repeat needs at least 3 columns")
        if not 1 <= self.shed_step < self.shed or math.gcd(self.shed_step, self.shed) != 1:
            out.append(
                f"shed_step = {self.shed_step}: must lie in [1, shed) and share no factor with "
                f"shed = {self.shed}"
            )
        if self.shed >= 3 and self.shift % self.shed in (0,):
            out.append(f"bottom_shift = {self.shift}: must not be a multiple of shed")
        if self.md_pitch_m < self.md_diameter_m + 2 * self.clearance_m:
            out.append(
                f"md_count_per_m = {self.md_count_per_m:g}: warps of diameter "
                f"{self.md_diameter_m:g} m overlap (at most {1 / self.md_diameter_m:g} per m)"
            )
        # A warp passing from above a weft to below its neighbour needs the gap between two
        # neighbouring wefts to exceed one warp diameter (Peirce geometry, common tangent).
        for label, d in (("top", self.cd_top_diameter_m), ("bottom", self.cd_bottom_diameter_m)):
            need = d + self.md_diameter_m + 2 * self.clearance_m
            if self.cd_pitch_m <= need:
                out.append(
                    f"cd_count_per_m = {self.cd_count_per_m:g}: the gap between neighbouring "
                    f"{label} wefts is narrower than a warp; need cd pitch > {need:g} m "
                    f"(cd_count_per_m < {1 / need:g})"
                )
        if not 1.0 <= self.arc_step_deg <= 30.0:
            out.append(f"arc_step_deg = {self.arc_step_deg:g}: must lie in [1, 30]")
        return out


@dataclass
class Yarn:
    """A yarn: circular cross-section of ``radius`` swept along the polyline ``points`` (m)."""

    points: FloatArray
    radius: float
    kind: int
    index: int = 0

    def segments(self) -> tuple[FloatArray, FloatArray]:
        return self.points[:-1], self.points[1:]

    def length(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self.points, axis=0), axis=1)))


# --------------------------------------------------------------------------------------------
# The weave


def weave_states(p: WeaveParams, warp: int, columns: range) -> list[int]:
    """State of ``warp`` at each column: +1 over the top weft, -1 under the bottom weft, 0
    between the layers."""
    n, step, shift = p.shed, p.shed_step, p.shift
    out = []
    for k in columns:
        if (k - warp * step) % n == 0:
            out.append(1)
        elif (k - warp * step - shift) % n == 0:
            out.append(-1)
        else:
            out.append(0)
    return out


@dataclass(frozen=True)
class _Pulley:
    x: float
    z: float
    rho: float  # signed wrap radius: > 0 the warp passes above the centre, < 0 below


def _normal(phi: float) -> tuple[float, float]:
    return -math.sin(phi), math.cos(phi)


def _tangent_phi(a: _Pulley, b: _Pulley) -> float:
    """Direction angle of the common tangent from pulley a to pulley b (path moving in +x)."""
    dx, dz = b.x - a.x, b.z - a.z
    length = math.hypot(dx, dz)
    s = (a.rho - b.rho) / length
    if abs(s) > 1.0 + 1e-12:
        raise FabricGeometryError(
            "no common tangent between two wrapped wefts: the weft spacing is too small for the "
            "yarn diameters (lower cd_count_per_m or the diameters)"
        )
    s = max(-1.0, min(1.0, s))
    return math.atan2(dz, dx) - math.asin(s)


def _pulleys(p: WeaveParams, states: list[int], xs: list[float]) -> list[_Pulley]:
    rw = 0.5 * p.md_diameter_m
    r_top = 0.5 * p.cd_top_diameter_m + rw + p.clearance_m
    r_bot = 0.5 * p.cd_bottom_diameter_m + rw + p.clearance_m
    z_b, z_t, _ = p.levels()
    top_under = lambda x: _Pulley(x, z_t, -r_top)  # noqa: E731  below the top weft
    bot_over = lambda x: _Pulley(x, z_b, r_bot)  # noqa: E731  above the bottom weft

    def mid_side(neighbour: int | None) -> str | None:
        if neighbour == 1:
            return "top"
        if neighbour == -1:
            return "bot"
        return None

    out: list[_Pulley] = []
    for i, (s, x) in enumerate(zip(states, xs)):
        if s == 1:
            out.append(_Pulley(x, z_t, r_top))
        elif s == -1:
            out.append(_Pulley(x, z_b, -r_bot))
        else:
            left = mid_side(states[i - 1]) if i > 0 else None
            right = mid_side(states[i + 1]) if i + 1 < len(states) else None
            if left is None and right is None:
                left = right = "top"
            elif left is None:
                left = right
            elif right is None:
                right = left
            for side in (left, right) if left != right else (left,):
                out.append(top_under(x) if side == "top" else bot_over(x))
    return out


def _belt(pulleys: list[_Pulley], arc_step: float) -> FloatArray:
    """(x, z) polyline of a belt over the pulleys, arcs as circumscribed polygons."""
    pulleys = list(pulleys)
    # Drop pulleys the belt does not touch (the wrap direction would be reversed).
    while True:
        phis = [_tangent_phi(a, b) for a, b in zip(pulleys[:-1], pulleys[1:])]
        bad = None
        for i in range(1, len(pulleys) - 1):
            turn = phis[i] - phis[i - 1]
            if (pulleys[i].rho > 0 and turn > 1e-12) or (pulleys[i].rho < 0 and turn < -1e-12):
                bad = i
                break
        if bad is None:
            break
        del pulleys[bad]
    pts: list[tuple[float, float]] = []
    for i, pl in enumerate(pulleys):
        # The path starts and ends at the top or bottom point of the end pulleys (phi = 0),
        # unless that would wrap the wrong way.
        if i == 0:
            phi_out = phis[0] if phis else 0.0
            phi_in = 0.0 if (phi_out <= 0.0) == (pl.rho > 0) else phi_out
        else:
            phi_in = phis[i - 1]
            if i < len(phis):
                phi_out = phis[i]
            else:
                phi_out = 0.0 if (phi_in >= 0.0) == (pl.rho > 0) else phi_in
        delta = phi_out - phi_in
        m = int(math.ceil(abs(delta) / arc_step - 1e-9)) if delta != 0.0 else 0
        nx, nz = _normal(phi_in)
        pts.append((pl.x + pl.rho * nx, pl.z + pl.rho * nz))
        if m > 0:
            d = delta / m
            rho_c = pl.rho / math.cos(0.5 * d)
            for q in range(1, m + 1):
                nx, nz = _normal(phi_in + (q - 0.5) * d)
                pts.append((pl.x + rho_c * nx, pl.z + rho_c * nz))
            nx, nz = _normal(phi_out)
            pts.append((pl.x + pl.rho * nx, pl.z + pl.rho * nz))
    arr = np.array(pts, dtype=np.float64)
    keep = np.ones(len(arr), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(arr, axis=0), axis=1) > 1e-15
    return arr[keep]


def build_weave(p: WeaveParams) -> list[Yarn]:
    """All yarns of the piece (each extends a little beyond the piece so a cut is clean)."""
    problems = p.problems()
    if problems:
        raise FabricGeometryError("; ".join(problems))
    pcd, pmd = p.cd_pitch_m, p.md_pitch_m
    rw = 0.5 * p.md_diameter_m
    rt, rb = 0.5 * p.cd_top_diameter_m, 0.5 * p.cd_bottom_diameter_m
    z_b, z_t, _ = p.levels()
    rmax = max(rt, rb)
    # Weft columns touching the piece, plus one more on each side for the warp paths.
    k_lo = math.floor((-rmax) / pcd - 0.5)
    k_hi = math.ceil((p.size_x_m + rmax) / pcd - 0.5)
    cols = range(k_lo - 1, k_hi + 2)
    xs = [(k + 0.5) * pcd for k in cols]
    yarns: list[Yarn] = []
    arc_step = math.radians(p.arc_step_deg)
    j_lo = math.floor(-rw / pmd - 0.5)
    j_hi = math.ceil((p.size_y_m + rw) / pmd - 0.5)
    for j in range(j_lo, j_hi + 1):
        y = (j + 0.5) * pmd
        if y + rw <= 0.0 or y - rw >= p.size_y_m:
            continue
        xz = _belt(_pulleys(p, weave_states(p, j, cols), xs), arc_step)
        pts = np.column_stack([xz[:, 0], np.full(len(xz), y), xz[:, 1]])
        yarns.append(Yarn(pts, rw, MD_WARP))
    # Straight wefts, split into segments no longer than half a warp pitch.
    y0, y1 = -pmd, p.size_y_m + pmd
    nseg = max(1, math.ceil((y1 - y0) / (0.5 * pmd)))
    ys = np.linspace(y0, y1, nseg + 1)
    for x in xs:
        for z, r, kind in ((z_t, rt, CD_TOP), (z_b, rb, CD_BOTTOM)):
            if x + r <= 0.0 or x - r >= p.size_x_m:
                continue
            pts = np.column_stack([np.full_like(ys, x), ys, np.full_like(ys, z)])
            yarns.append(Yarn(pts, r, kind))
    for i, yarn in enumerate(yarns):
        yarn.index = i
    return yarns


def warp_crimp(yarns: list[Yarn]) -> float:
    """Mean of (path length / projected length - 1) over the warps."""
    vals = []
    for y in yarns:
        if y.kind == MD_WARP:
            span = float(y.points[-1, 0] - y.points[0, 0])
            vals.append(y.length() / span - 1.0)
    return float(np.mean(vals)) if vals else 0.0


# --------------------------------------------------------------------------------------------
# Checks


def segment_closest_differences(
    p1: FloatArray, q1: FloatArray, p2: FloatArray, q2: FloatArray
) -> FloatArray:
    """c1 - c2 (..., 3), m: the closest point c1 of segment [p1,q1] minus the closest point c2 of
    segment [p2,q2] (arrays (..., 3), broadcast; e.g. rows of two (n, 3) arrays pairwise, or all
    pairs with p1[:, None] and p2[None, :]), both parameters clamped to [0, 1] (C++ twin:
    contact_geometry.h closest_params_segment_segment). The one implementation of the closest
    points, used by :func:`segment_distances` and the sheet's fiber-fiber gaps
    (fiber_sheet.fiber_fiber_gap: the contact normal)."""
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = np.sum(d1 * d1, axis=-1)
    e = np.sum(d2 * d2, axis=-1)
    f = np.sum(d2 * r, axis=-1)
    c = np.sum(d1 * r, axis=-1)
    b = np.sum(d1 * d2, axis=-1)
    a, e, f, c, b = np.broadcast_arrays(a, e, f, c, b)
    tiny = 1e-300
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-12 * a * e, np.clip((b * f - c * e) / np.maximum(denom, tiny), 0, 1), 0.0)
        t = (b * s + f) / np.maximum(e, tiny)
        s = np.where(t < 0, np.clip(-c / np.maximum(a, tiny), 0, 1), s)
        s = np.where(t > 1, np.clip((b - c) / np.maximum(a, tiny), 0, 1), s)
        t = np.clip(t, 0, 1)
    c1 = p1 + d1 * s[..., None]
    c2 = p2 + d2 * t[..., None]
    return np.asarray(c1 - c2)


def segment_distances(
    p1: FloatArray, q1: FloatArray, p2: FloatArray, q2: FloatArray
) -> FloatArray:
    """Distance between segments [p1,q1] and [p2,q2] (arrays (..., 3), broadcast; e.g. rows of
    two (n, 3) arrays pairwise, or all pairs with p1[:, None] and p2[None, :]), m: the norm of
    :func:`segment_closest_differences` (both parameters clamped to [0, 1]). Used by the fabric
    checks, fiber placement (stage generate) and the lay-down's clearances."""
    return np.asarray(np.linalg.norm(segment_closest_differences(p1, q1, p2, q2), axis=-1))


@dataclass(frozen=True)
class YarnCheck:
    min_clearance_m: float  # min over yarn pairs of (centreline distance - r_i - r_j)
    pairs_checked: int
    worst_pair: tuple[int, int]


def check_yarns(yarns: list[Yarn]) -> YarnCheck:
    """Smallest surface-to-surface clearance between any two different yarns (negative:
    they intersect). Tube geometry: a yarn is every point within its radius of its polyline."""
    boxes = []
    for y in yarns:
        boxes.append((y.points.min(axis=0) - y.radius, y.points.max(axis=0) + y.radius))
    best, worst, pairs = math.inf, (-1, -1), 0
    for i in range(len(yarns)):
        for j in range(i + 1, len(yarns)):
            lo = np.maximum(boxes[i][0], boxes[j][0])
            hi = np.minimum(boxes[i][1], boxes[j][1])
            if np.any(lo > hi):
                continue
            pairs += 1
            a0, a1 = yarns[i].segments()
            b0, b1 = yarns[j].segments()
            # Only segments whose tube boxes reach the overlap region: a point inside both tubes
            # lies in both yarn boxes and in the tube boxes of the two nearest segments.
            ra, rb = yarns[i].radius + 1e-12, yarns[j].radius + 1e-12
            ma = np.all((np.minimum(a0, a1) - ra <= hi) & (np.maximum(a0, a1) + ra >= lo), axis=1)
            mb = np.all((np.minimum(b0, b1) - rb <= hi) & (np.maximum(b0, b1) + rb >= lo), axis=1)
            if not ma.any() or not mb.any():
                continue
            d = segment_distances(
                a0[ma][:, None, :], a1[ma][:, None, :], b0[mb][None, :, :], b1[mb][None, :, :]
            )
            clear = float(d.min()) - yarns[i].radius - yarns[j].radius
            if clear < best:
                best, worst = clear, (i, j)
    return YarnCheck(best, pairs, worst)


def _covered_length(intervals: list[tuple[float, float]], lo: float, hi: float) -> float:
    clipped = sorted((max(a, lo), min(b, hi)) for a, b in intervals if b > lo and a < hi)
    total, cur_a, cur_b = 0.0, None, None
    for a, b in clipped:
        if cur_b is None or a > cur_b:
            if cur_b is not None and cur_a is not None:
                total += cur_b - cur_a
            cur_a, cur_b = a, b
        else:
            cur_b = max(cur_b, b)
    if cur_b is not None and cur_a is not None:
        total += cur_b - cur_a
    return total


def analytic_open_area(p: WeaveParams) -> dict[str, float]:
    """Projected open area of the piece from the parameters alone.

    Seen from above, each warp covers a strip of width d_md around its line y_j, and each weft
    column a strip of width max(d_top, d_bottom) around x_k (the two wefts are stacked). The open
    area is the product of the uncovered fractions along x and y, computed for the actual piece
    (strips clipped at its edges). For an infinite fabric it is
    (1 - d_md * n_md) * (1 - max(d_top, d_bottom) * n_cd).
    """
    pcd, pmd = p.cd_pitch_m, p.md_pitch_m
    rw = 0.5 * p.md_diameter_m
    rx = 0.5 * max(p.cd_top_diameter_m, p.cd_bottom_diameter_m)
    kx = range(math.floor(-1 / 2 - rx / pcd) - 1, math.ceil(p.size_x_m / pcd) + 2)
    ky = range(math.floor(-1 / 2 - rw / pmd) - 1, math.ceil(p.size_y_m / pmd) + 2)
    cov_x = _covered_length([((k + 0.5) * pcd - rx, (k + 0.5) * pcd + rx) for k in kx], 0.0, p.size_x_m)
    cov_y = _covered_length([((j + 0.5) * pmd - rw, (j + 0.5) * pmd + rw) for j in ky], 0.0, p.size_y_m)
    open_x = 1.0 - cov_x / p.size_x_m
    open_y = 1.0 - cov_y / p.size_y_m
    infinite = (1.0 - p.md_diameter_m * p.md_count_per_m) * (
        1.0 - 2 * rx * p.cd_count_per_m
    )
    return {
        "open_area": open_x * open_y,
        "open_fraction_x": open_x,
        "open_fraction_y": open_y,
        "open_area_infinite": infinite,
        "strips_x": float(sum(1 for k in kx if (k + 0.5) * pcd + rx > 0 and (k + 0.5) * pcd - rx < p.size_x_m)),
        "strips_y": float(sum(1 for j in ky if (j + 0.5) * pmd + rw > 0 and (j + 0.5) * pmd - rw < p.size_y_m)),
    }


# --------------------------------------------------------------------------------------------
# Voxel image


@dataclass
class VoxelImage:
    """A boolean image: ``solid[i, j, k]`` is the voxel whose centre is
    ``origin + (i + 0.5, j + 0.5, k + 0.5) * spacing`` (m)."""

    solid: npt.NDArray[np.bool_]
    origin: FloatArray
    spacing: FloatArray
    meta: dict[str, object] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int, int]:
        s = self.solid.shape
        return int(s[0]), int(s[1]), int(s[2])

    @property
    def upper(self) -> FloatArray:
        return np.asarray(self.origin + np.array(self.shape) * self.spacing)

    def centres(self, axis: int) -> FloatArray:
        return np.asarray(self.origin[axis] + (np.arange(self.shape[axis]) + 0.5) * self.spacing[axis])


def _grid(lo: FloatArray, hi: FloatArray, voxel_size: float) -> tuple[tuple[int, int, int], FloatArray]:
    ext = hi - lo
    n = np.maximum(1, np.round(ext / voxel_size)).astype(int)
    return (int(n[0]), int(n[1]), int(n[2])), ext / n


def signed_distance_image(
    yarns: list[Yarn], lo: FloatArray, hi: FloatArray, voxel_size: float
) -> tuple[npt.NDArray[np.float32], FloatArray]:
    """Signed distance (m) to the yarn surfaces at voxel centres (negative inside), exact within
    two voxels of the surface and clipped to +2 voxels beyond. Returns (field, spacing)."""
    shape, sp = _grid(lo, hi, voxel_size)
    band = float(2.0 * sp.max())
    f = np.full(shape, band, dtype=np.float32)
    axes = [lo[a] + (np.arange(shape[a]) + 0.5) * sp[a] for a in range(3)]
    for y in yarns:
        a0, a1 = y.segments()
        r = y.radius
        for p, q in zip(a0, a1):
            bmin = np.minimum(p, q) - r - band
            bmax = np.maximum(p, q) + r + band
            i0 = np.maximum(0, np.ceil((bmin - lo) / sp - 0.5).astype(int))
            i1 = np.minimum(np.array(shape) - 1, np.floor((bmax - lo) / sp - 0.5).astype(int))
            if np.any(i1 < i0):
                continue
            X = axes[0][i0[0] : i1[0] + 1][:, None, None]
            Y = axes[1][i0[1] : i1[1] + 1][None, :, None]
            Z = axes[2][i0[2] : i1[2] + 1][None, None, :]
            d = q - p
            L2 = float(d @ d)
            t = ((X - p[0]) * d[0] + (Y - p[1]) * d[1] + (Z - p[2]) * d[2]) / L2
            t = np.clip(t, 0.0, 1.0)
            dist = np.sqrt(
                (X - p[0] - t * d[0]) ** 2 + (Y - p[1] - t * d[1]) ** 2 + (Z - p[2] - t * d[2]) ** 2
            ) - r
            sub = f[i0[0] : i1[0] + 1, i0[1] : i1[1] + 1, i0[2] : i1[2] + 1]
            np.minimum(sub, dist.astype(np.float32), out=sub)
    return f, sp


def voxel_open_area(img: VoxelImage) -> float:
    """Fraction of the (x, y) columns of the image that hold no solid voxel."""
    return float(1.0 - np.mean(img.solid.any(axis=2)))


# --------------------------------------------------------------------------------------------
# Surface mesh: marching tetrahedra on a node field

# Kuhn decomposition of the unit cube into 6 tetrahedra sharing the main diagonal; it splits each
# cube face along the diagonal from its lowest to its highest corner, the same in both cubes that
# share the face, so the surface is closed across cubes.
_CUBE_CORNERS = np.array([[(c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)])
_TETS: list[list[int]] = []
for _perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
    _v = [0, 0, 0]
    _tet = [0]
    for _ax in _perm[:2]:
        _v[_ax] = 1
        _tet.append(_v[0] | (_v[1] << 1) | (_v[2] << 2))
    _tet.append(7)
    _TETS.append(_tet)


def _case_triangles(case: int) -> list[tuple[tuple[int, int], ...]]:
    """Triangles (as triples of tetra edges) for a sign pattern (bit v set: vertex v inside)."""
    inside = [v for v in range(4) if case >> v & 1]
    outside = [v for v in range(4) if not case >> v & 1]
    if len(inside) in (0, 4):
        return []
    if len(inside) == 1 or len(outside) == 1:
        lone, others = (inside[0], outside) if len(inside) == 1 else (outside[0], inside)
        return [tuple((lone, o) for o in others)]
    a, b = inside
    c, d = outside
    return [((a, c), (a, d), (b, d)), ((a, c), (b, d), (b, c))]


_CASES = [_case_triangles(c) for c in range(16)]


def marching_tetrahedra(
    values: npt.NDArray[np.floating],
    origin: FloatArray,
    spacing: FloatArray,
    clip_lo: FloatArray | None = None,
    clip_hi: FloatArray | None = None,
) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """Closed surface {values = 0} of a node field (inside: values < 0), nodes at
    ``origin + index * spacing``. Returns (vertices (V, 3), triangles (T, 3)), triangles oriented
    with normals pointing outwards (towards values > 0). Vertices are shared between triangles
    through the lattice edge they lie on, so the mesh is closed when the field is negative only
    away from the array border. ``clip_lo``/``clip_hi`` clamp the vertices into a box (used to
    put the caps of yarns cut by the piece's sides exactly on the sides: on diagonal lattice
    edges of the padding layer the interpolated crossing can lie up to half a node spacing
    outside)."""
    F = np.asarray(values, dtype=np.float64)
    F = np.where(F == 0.0, 1e-30, F)  # no vertex exactly on a node
    neg = F < 0
    nx, ny, nz = F.shape
    cnt = np.zeros((nx - 1, ny - 1, nz - 1), dtype=np.int8)
    for c in _CUBE_CORNERS:
        cnt += neg[c[0] : nx - 1 + c[0], c[1] : ny - 1 + c[1], c[2] : nz - 1 + c[2]]
    ci, cj, ck = np.nonzero((cnt > 0) & (cnt < 8))
    stride = np.array([ny * nz, nz, 1], dtype=np.int64)
    base = ci * stride[0] + cj * stride[1] + ck
    corner_off = _CUBE_CORNERS @ stride
    flatF = F.ravel()
    t_all, a_all, b_all, orient_all = [], [], [], []
    for tet in _TETS:
        ids = base[:, None] + corner_off[tet][None, :]  # (M, 4) node ids
        vals = flatF[ids]
        inside = vals < 0
        case = (inside * np.array([1, 2, 4, 8])).sum(axis=1)
        for cs in range(1, 15):
            rows = np.nonzero(case == cs)[0]
            if rows.size == 0:
                continue
            for tri in _CASES[cs]:
                corners_a = np.stack([ids[rows, e[0]] for e in tri], axis=1)  # (R, 3)
                corners_b = np.stack([ids[rows, e[1]] for e in tri], axis=1)
                a_all.append(corners_a)
                b_all.append(corners_b)
                # Orientation reference: from the inside corners' centroid to the outside ones'.
                ins = np.array([cs >> v & 1 for v in range(4)], dtype=bool)
                orient_all.append(np.broadcast_to(ins, (rows.size, 4)))
                t_all.append(ids[rows])
    if not a_all:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    A = np.concatenate(a_all)  # (T, 3) first node of each triangle corner's edge
    B = np.concatenate(b_all)
    TET = np.concatenate(t_all)  # (T, 4)
    INS = np.concatenate(orient_all)

    def node_xyz(idx: npt.NDArray[np.int64]) -> FloatArray:
        i = idx // stride[0]
        j = (idx // stride[1]) % ny
        k = idx % nz
        return np.asarray(origin + np.stack([i, j, k], axis=-1) * spacing)

    lo_id = np.minimum(A, B)
    hi_id = np.maximum(A, B)
    total = np.int64(nx) * ny * nz
    keys = lo_id * total + hi_id
    uniq, inverse = np.unique(keys.ravel(), return_inverse=True)
    e_lo = uniq // total
    e_hi = uniq % total
    f_lo = flatF[e_lo]
    f_hi = flatF[e_hi]
    # Keep every vertex at least 1e-3 of a lattice edge away from the nodes, so vertices on
    # different edges stay distinct after rounding to float32 in an STL file.
    t = np.clip(f_lo / (f_lo - f_hi), 1e-3, 1.0 - 1e-3)
    verts = node_xyz(e_lo) + t[:, None] * (node_xyz(e_hi) - node_xyz(e_lo))
    if clip_lo is not None or clip_hi is not None:
        verts = np.clip(verts, clip_lo, clip_hi)
    tris = inverse.reshape(-1, 3).astype(np.int64)
    # Orient: normal . (outside centroid - inside centroid) > 0.
    P = verts[tris]
    nrm = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    tet_xyz = node_xyz(TET)  # (T, 4, 3)
    insf = INS.astype(np.float64)[..., None]
    c_in = (tet_xyz * insf).sum(axis=1) / insf.sum(axis=1)
    c_out = (tet_xyz * (1 - insf)).sum(axis=1) / (1 - insf).sum(axis=1)
    flip = np.einsum("ij,ij->i", nrm, c_out - c_in) < 0
    tris[flip] = tris[flip][:, ::-1]
    return verts, tris


def close_field(values: npt.NDArray[np.floating], outside: float) -> npt.NDArray[np.float64]:
    """Pad a voxel-centre field by one layer so its zero surface closes on the box faces: a pad
    node next to an inside value v < 0 gets -v (zero crossing exactly on the face), else
    ``outside`` (> 0)."""
    F = np.asarray(values, dtype=np.float64)
    G = np.pad(F, 1, mode="edge")
    G = np.where(G < 0, -G, outside)
    G[1:-1, 1:-1, 1:-1] = F
    return G


def mesh_edge_report(tris: npt.NDArray[np.int64]) -> dict[str, int]:
    """Counts that decide whether a triangle mesh is closed and consistently oriented:
    every undirected edge in exactly two triangles, every directed edge exactly once."""
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]).astype(np.int64)
    nv = np.int64(e.max() + 1) if e.size else np.int64(1)
    und = np.minimum(e[:, 0], e[:, 1]) * nv + np.maximum(e[:, 0], e[:, 1])
    _, counts = np.unique(und, return_counts=True)
    _, dcounts = np.unique(e[:, 0] * nv + e[:, 1], return_counts=True)
    return {
        "triangles": int(len(tris)),
        "edges": int(len(counts)),
        "edges_not_shared_by_two": int(np.sum(counts != 2)),
        "directed_edges_repeated": int(np.sum(dcounts != 1)),
        "degenerate_triangles": int(
            np.sum((tris[:, 0] == tris[:, 1]) | (tris[:, 1] == tris[:, 2]) | (tris[:, 0] == tris[:, 2]))
        ),
    }


def mesh_volume(verts: FloatArray, tris: npt.NDArray[np.int64]) -> float:
    """Enclosed volume by the divergence theorem (positive for outward normals)."""
    P = verts[tris]
    return float(np.einsum("ij,ij->i", P[:, 0], np.cross(P[:, 1], P[:, 2])).sum() / 6.0)


# --------------------------------------------------------------------------------------------
# STL I/O


def write_stl(path: Path, verts: FloatArray, tris: npt.NDArray[np.int64], name: str = "fabric") -> None:
    """Binary STL (float32 coordinates in metres)."""
    P = verts[tris].astype(np.float64)
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    ln = np.linalg.norm(n, axis=1)
    n = n / np.where(ln > 0, ln, 1.0)[:, None]
    rec = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"] = n
    rec["v"] = P
    header = f"fiberform {name} binary STL, metres".encode()[:80].ljust(80, b" ")
    with open(path, "wb") as fh:
        fh.write(header)
        fh.write(struct.pack("<I", len(tris)))
        fh.write(rec.tobytes())


_ASCII_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)")


def read_stl(path: Path) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """Read an ASCII or binary STL; vertices with identical coordinates are merged."""
    data = Path(path).read_bytes()
    if len(data) >= 84:
        (count,) = struct.unpack("<I", data[80:84])
        binary = len(data) == 84 + 50 * count
    else:
        binary = False
    if binary:
        rec = np.frombuffer(data, dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")],
                            count=count, offset=84)  # fmt: skip
        P = rec["v"].astype(np.float64).reshape(-1, 3)
    else:
        if not data.lstrip().startswith(b"solid"):
            raise FabricGeometryError(f"{path}: neither a binary nor an ASCII STL file")
        found = _ASCII_VERTEX.findall(data)
        if not found or len(found) % 3:
            raise FabricGeometryError(f"{path}: ASCII STL without whole triangles")
        try:
            P = np.array([[float(a), float(b), float(c)] for a, b, c in found])
        except ValueError:
            raise FabricGeometryError(f"{path}: unreadable vertex coordinates") from None
    if len(P) == 0:
        raise FabricGeometryError(f"{path}: no triangles")
    if not np.all(np.isfinite(P)):
        raise FabricGeometryError(f"{path}: non-finite coordinates")
    verts, inverse = np.unique(P, axis=0, return_inverse=True)
    return verts, inverse.reshape(-1, 3).astype(np.int64)


def voxelize_mesh(
    verts: FloatArray,
    tris: npt.NDArray[np.int64],
    origin: FloatArray,
    spacing: FloatArray,
    shape: tuple[int, int, int],
) -> npt.NDArray[np.bool_]:
    """Inside test of a closed mesh at voxel centres by ray parity along z.

    Each (x, y) column's ray is moved off the lattice by a tiny irrational offset so it does not
    pass exactly through mesh edges or vertices (which lie on lattice lines for meshes made from
    voxel images)."""
    nx, ny, nz = shape
    jitter = np.array([math.pi * 1e-5, math.e * 1e-5]) * spacing[:2]
    P = verts[tris]  # (T, 3, 3)
    xy = P[:, :, :2]
    bmin = xy.min(axis=1)
    bmax = xy.max(axis=1)
    i0 = np.maximum(0, np.ceil((bmin - origin[:2] - jitter) / spacing[:2] - 0.5).astype(np.int64))
    i1 = np.minimum(np.array([nx, ny]) - 1, np.floor((bmax - origin[:2] - jitter) / spacing[:2] - 0.5).astype(np.int64))
    cnt_i = np.maximum(0, i1[:, 0] - i0[:, 0] + 1)
    cnt_j = np.maximum(0, i1[:, 1] - i0[:, 1] + 1)
    per = cnt_i * cnt_j
    hits = np.zeros((nx, ny, nz + 1), dtype=np.int32)
    tri_idx = np.repeat(np.arange(len(tris)), per)
    if tri_idx.size == 0:
        return np.zeros(shape, dtype=bool)
    start = np.repeat(np.cumsum(per) - per, per)
    local = np.arange(tri_idx.size) - start
    ci = i0[tri_idx, 0] + local // cnt_j[tri_idx]
    cj = i0[tri_idx, 1] + local % cnt_j[tri_idx]
    px = origin[0] + (ci + 0.5) * spacing[0] + jitter[0]
    py = origin[1] + (cj + 0.5) * spacing[1] + jitter[1]
    A, B, C = P[tri_idx, 0], P[tri_idx, 1], P[tri_idx, 2]
    # Edge functions in the xy plane.
    def edge(u: FloatArray, v: FloatArray) -> FloatArray:
        return np.asarray((v[:, 0] - u[:, 0]) * (py - u[:, 1]) - (v[:, 1] - u[:, 1]) * (px - u[:, 0]))
    w0 = edge(B, C)
    w1 = edge(C, A)
    w2 = edge(A, B)
    area = w0 + w1 + w2
    inside = ((w0 >= 0) & (w1 >= 0) & (w2 >= 0) | (w0 <= 0) & (w1 <= 0) & (w2 <= 0)) & (area != 0)
    w0, w1, w2, area = w0[inside], w1[inside], w2[inside], area[inside]
    zc = (w0 * A[inside, 2] + w1 * B[inside, 2] + w2 * C[inside, 2]) / area
    ci, cj = ci[inside], cj[inside]
    k = np.clip(np.ceil((zc - origin[2]) / spacing[2] - 0.5).astype(np.int64), 0, nz)
    np.add.at(hits, (ci, cj, k), 1)
    parity = np.cumsum(hits, axis=2)[:, :, :nz] % 2
    return parity.astype(bool)
