# SPDX-License-Identifier: GPL-3.0-or-later
"""Geometry and numbers of the permeability stage that need no OpenFOAM.

* :func:`chain_fraction`: solid volume fraction of the zone cells of an
  :class:`~fiberform.openfoam_case.Lattice` occupied by element chains, sampled at
  ``subsamples``^3 points per cell: capsules (fibers with circular cross-sections, yarns;
  :func:`capsule_fraction`) or boxes with mitred joints (collapsed fibers, rectangular sections,
  thickness direction :func:`flat_thickness_dir`).
* :func:`image_fraction`: the same for a voxel image (nearest voxel at each sample point), for
  fabrics imported as voxels or STL.
* :func:`flow_rate_convergence`: the flow-rate criterion (relative amplitude of the outflow over the
  last iterations) and the uncertainty it gives.
* Sub-grid laws: permeability of fibrous media from the fiber volume fraction phi and radius a,
  :func:`jackson_james` (random 3D fiber networks) and :func:`drummond_tahir` (square arrays,
  transverse flow), and :func:`subgrid_resistance` (Darcy resistance 1/k per cell).
* :func:`forchheimer_fit`: Darcy permeability and Forchheimer coefficient through two
  (superficial velocity, pressure drop) points.
* Sections: :func:`section_area`, :func:`hydraulic_radius` (the sub-grid laws' radius of a
  rectangular section).
* Unit conversions: 1 CFM (cubic foot per square foot per minute) = 0.3048 / 60 m/s = 5.08 mm/s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .fabric_geometry import VoxelImage
from .openfoam_case import BoxSetup, Lattice
from .products import Chain

__all__ = [
    "CFM_M_S",
    "UP",
    "Convergence",
    "capsule_fraction",
    "chain_fraction",
    "drummond_tahir",
    "flat_thickness_dir",
    "flow_rate_convergence",
    "forchheimer_fit",
    "hydraulic_radius",
    "image_fraction",
    "jackson_james",
    "line_fraction",
    "section_area",
    "subgrid_resistance",
]

#: 1 CFM (ft^3 / ft^2 / min) in m/s: 0.3048 m / 60 s.
CFM_M_S = 0.3048 / 60.0

FloatArray = npt.NDArray[np.float64]

#: The reference direction of flat (rectangular) elements: global z, as the contact styles'
#: default ``up`` (liggghts-fiber-style/src/physics/contact_geometry.h, rect_thickness_dir).
UP = np.array([0.0, 0.0, 1.0])

#: a chain given as a Chain or as (points (m, 3) [m], radius [m]) of a circular section
ChainLike = Chain | tuple[FloatArray, float]


def _as_chain(c: ChainLike) -> Chain:
    if isinstance(c, Chain):
        return c
    pts, r = c
    return Chain(np.asarray(pts, dtype=np.float64), float(r))


def flat_thickness_dir(axis: FloatArray, up: FloatArray = UP) -> FloatArray:
    """Unit thickness directions (n, 3) of flat (rectangular) elements with unit axes ``axis``
    (n, 3) or (3,): ``up`` made perpendicular to the axis, or x made perpendicular when the axis
    is parallel to ``up`` (|perpendicular part| < 1e-8). The convention of the contact styles
    (contact_geometry.h ``rect_thickness_dir``): the fiber products store no section
    orientation of the sheet, so a collapsed fiber is taken to lie flat, its thickness as
    vertical as its axis allows; the width direction is thickness x axis (horizontal)."""
    u = np.atleast_2d(np.asarray(axis, dtype=np.float64))
    up = np.asarray(up, dtype=np.float64)
    t = up[None, :] - (u @ up)[:, None] * u
    n = np.linalg.norm(t, axis=1)
    flat = n < 1e-8
    if np.any(flat):
        x = np.array([1.0, 0.0, 0.0])
        t[flat] = x[None, :] - (u[flat] @ x)[:, None] * u[flat]
        n[flat] = np.linalg.norm(t[flat], axis=1)
    out = t / n[:, None]
    return out if np.ndim(axis) > 1 else out[0]


def section_area(c: Chain) -> float:
    """Cross-section area [m^2]: pi r^2 (circular) or (2 r)(2 half_thickness) (rectangular)."""
    if c.half_thickness is None:
        return math.pi * c.radius**2
    return 4.0 * c.radius * c.half_thickness


def hydraulic_radius(half_width: float, half_thickness: float) -> float:
    """Radius [m] of the circular fiber with the surface-to-volume ratio of a rectangular section
    2 half_width x 2 half_thickness: 2 A / P = 2 half_width half_thickness / (half_width +
    half_thickness) (Kozeny-Carman's equivalence by specific surface, Carman 1937; for a circle
    2 A / P = r)."""
    return 2.0 * half_width * half_thickness / (half_width + half_thickness)


def _zone_spacing(s: BoxSetup, lat: Lattice) -> FloatArray:
    return np.array([s.size_x_m / lat.nx, s.size_y_m / lat.ny,
                     (s.fabric_hi_z_m - s.fabric_lo_z_m) / lat.n_fabric])  # fmt: skip


def _point_segment_distance2(P: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Squared distance of the points P (n, 3) to the segment a-b."""
    d = b - a
    dd = float(d @ d)
    t = np.zeros(len(P)) if dd == 0.0 else np.clip((P - a) @ d / dd, 0.0, 1.0)
    q = a + t[:, None] * d
    return np.asarray(np.einsum("ij,ij->i", P - q, P - q))


def capsule_fraction(
    chains: list[tuple[FloatArray, float]], s: BoxSetup, lat: Lattice, subsamples: int = 4
) -> npt.NDArray[np.float32]:
    """:func:`chain_fraction` of capsule chains ``(points (m, 3) [m], radius [m])``."""
    return chain_fraction([_as_chain(c) for c in chains], s, lat, subsamples)


#: Largest sample mask (bytes, one per sample point) :func:`chain_fraction` allocates.
SAMPLE_MASK_BYTES = 1 << 28


def _unit_axes(pts: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Element vectors (m-1, 3) and unit axes (zero-length elements: 0)."""
    d = np.diff(pts, axis=0)
    n = np.linalg.norm(d, axis=1)
    return d, np.divide(d, n[:, None], out=np.zeros_like(d), where=n[:, None] > 0)


def _mitre_normal(u0: FloatArray, u1: FloatArray, own: FloatArray) -> FloatArray:
    """Normal of the joint plane between elements of unit axes u0 and u1 as seen by the element
    of axis ``own`` (u0 or u1): their bisector (a mitred joint) for bends up to 90 degrees, else
    ``own`` (a square end: a gap at the outside of the bend, an overlap inside)."""
    if float(u0 @ u1) < 0.0:
        return own
    m = u0 + u1
    return m / float(np.linalg.norm(m))


def chain_fraction(
    chains: Sequence[Chain], s: BoxSetup, lat: Lattice, subsamples: int = 4
) -> npt.NDArray[np.float32]:
    """Solid volume fraction of the zone cells (nx, ny, n_fabric) inside the union of the element
    chains: each cell is sampled at ``subsamples``^3 regularly spaced points; a point is solid when
    it lies inside an element. Circular sections: within ``radius`` of a segment (a capsule:
    cylinder with hemispherical ends). Rectangular sections: inside the box of the element (width
    2 ``radius`` along thickness x axis, thickness 2 ``half_thickness`` along
    :func:`flat_thickness_dir`), cut at each inner joint by the plane bisecting the two elements (a
    mitred joint, so a bend neither gaps nor overlaps at the width's edges; bends over 90 degrees
    get square ends) and square at the fiber's two ends: a straight chain is exactly one box."""
    S = int(subsamples)
    h = _zone_spacing(s, lat)
    lo = np.array([0.0, 0.0, s.fabric_lo_z_m])
    n_sub = np.array([lat.nx * S, lat.ny * S, lat.n_fabric * S], dtype=np.int64)
    hs = h / S
    hits: list[npt.NDArray[np.int64]] = []
    total = int(n_sub.prod())
    # the union of the samples: a mask when it fits in SAMPLE_MASK_BYTES (faster than np.unique
    # of all hits at many samples per cell), else a sorted list of the hit indices
    mask = np.zeros(total, dtype=bool) if total <= SAMPLE_MASK_BYTES else None
    for c in chains:
        pts = np.asarray(c.points, dtype=np.float64)
        r = c.radius
        if c.half_thickness is None:
            reach = r
        else:
            t2 = c.half_thickness
            keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 0])
            pts = pts[keep]  # repeated points would make zero-length elements
            _, u = _unit_axes(pts)
            e_t = flat_thickness_dir(u) if len(u) else np.zeros((0, 3))
            e_w = np.cross(e_t, u)
            reach = 2.0 * math.hypot(r, t2)  # a mitre reaches at most this far past a node
        for j, (a, b) in enumerate(zip(pts[:-1], pts[1:], strict=True)):
            lo_i = np.maximum(np.floor((np.minimum(a, b) - reach - lo) / hs).astype(np.int64), 0)
            hi_i = np.minimum(np.ceil((np.maximum(a, b) + reach - lo) / hs).astype(np.int64), n_sub)
            if np.any(hi_i <= lo_i):
                continue
            axes = [np.arange(lo_i[k], hi_i[k]) for k in range(3)]
            I, J, K = np.meshgrid(*axes, indexing="ij")
            P = lo + (np.stack([I.ravel(), J.ravel(), K.ravel()], axis=1) + 0.5) * hs
            if c.half_thickness is None:
                inside = _point_segment_distance2(P, a, b) <= r * r
            else:
                n0 = u[j] if j == 0 else _mitre_normal(u[j - 1], u[j], u[j])
                n1 = u[j] if j == len(u) - 1 else _mitre_normal(u[j], u[j + 1], u[j])
                Pa = P - a
                inside = ((Pa @ n0 >= 0.0) & ((P - b) @ n1 <= 0.0)
                          & (np.abs(Pa @ e_w[j]) <= r) & (np.abs(Pa @ e_t[j]) <= t2))  # fmt: skip
            flat = (I.ravel()[inside] * n_sub[1] + J.ravel()[inside]) * n_sub[2] + K.ravel()[inside]
            if mask is not None:
                mask[flat] = True
            else:
                hits.append(flat)
    frac = np.zeros((lat.nx, lat.ny, lat.n_fabric), dtype=np.float32)
    if mask is not None:
        counts_m = mask.reshape(lat.nx, S, lat.ny, S, lat.n_fabric, S).sum(axis=(1, 3, 5))
        return (counts_m.astype(np.float64) / S**3).astype(np.float32)
    if not hits:
        return frac
    flat = np.unique(np.concatenate(hits))
    ii, rem = np.divmod(flat, n_sub[1] * n_sub[2])
    jj, kk = np.divmod(rem, n_sub[2])
    cell = ((ii // S) * lat.ny + jj // S) * lat.n_fabric + kk // S
    counts = np.bincount(cell, minlength=frac.size).astype(np.float64) / S**3
    return counts.reshape(frac.shape).astype(np.float32)


def _clip_segment(a: FloatArray, b: FloatArray, lo: FloatArray,
                  hi: FloatArray) -> tuple[FloatArray, FloatArray] | None:  # fmt: skip
    """The part of the segment a-b inside the box [lo, hi] (slab clipping), None if none."""
    t0, t1 = 0.0, 1.0
    d = b - a
    for k in range(3):
        if d[k] == 0.0:
            if not lo[k] <= a[k] <= hi[k]:
                return None
            continue
        u, v = (lo[k] - a[k]) / d[k], (hi[k] - a[k]) / d[k]
        t0, t1 = max(t0, min(u, v)), min(t1, max(u, v))
    if t1 <= t0:
        return None
    return a + t0 * d, a + t1 * d


_STENCIL = np.stack(np.meshgrid(*([np.array([-1.0, 0.0, 1.0])] * 3), indexing="ij"), -1).reshape(-1, 3)


def line_fraction(
    chains: Sequence[ChainLike], s: BoxSetup, lat: Lattice, per_cell: int = 8
) -> npt.NDArray[np.float32]:
    """Fiber volume fraction of the zone cells (nx, ny, n_fabric) for the sub-grid mode: each
    segment's volume A |b - a| (A = :func:`section_area`: pi r^2, or 4 r half_thickness for a
    rectangular section) is split over points along its axis (``per_cell`` per cell length, each
    spread over a 3^3 stencil of half-radius offsets: along x, y, z for circular sections, along
    axis, width and thickness (half-width, half-width, half-thickness) for rectangular ones) and
    added to the cells holding them; segments are first clipped to the zone box. The volume inside
    the box is exact (up to fiber overlaps; capsule end caps are not counted), its placement good
    for cells larger than the fiber width, where :func:`chain_fraction` would need many samples per
    cell."""
    h = _zone_spacing(s, lat)
    lo = np.array([0.0, 0.0, s.fabric_lo_z_m])
    n = np.array([lat.nx, lat.ny, lat.n_fabric])
    vol = np.zeros(int(n.prod()))
    for ch in map(_as_chain, chains):
        pts = np.asarray(ch.points, dtype=np.float64)
        r = ch.radius
        area = section_area(ch)
        for a0, b0 in zip(pts[:-1], pts[1:], strict=True):
            clipped = _clip_segment(a0, b0, lo, lo + n * h)
            if clipped is None:
                continue
            a, b = clipped
            length = float(np.linalg.norm(b - a))
            m = max(1, math.ceil(length / float(h.min()) * per_cell))
            t = (np.arange(m) + 0.5) / m
            # each axis point's share is spread over a 3 x 3 x 3 stencil of half-radius offsets
            # (a fiber on a cell face then loads both cells)
            if ch.half_thickness is None:
                offsets = 0.5 * r * _STENCIL
            else:
                d0 = b0 - a0
                u = d0 / float(np.linalg.norm(d0))
                e_t = flat_thickness_dir(u)
                frame = np.stack([r * u, r * np.cross(e_t, u), ch.half_thickness * e_t])
                offsets = 0.5 * _STENCIL @ frame
            P = (a + t[:, None] * (b - a))[:, None, :] + offsets[None, :, :]
            # the axis lies in the box; a stencil point past a face loads the cell at the face
            idx = np.clip(np.floor((P.reshape(-1, 3) - lo) / h).astype(np.int64), 0, n - 1)
            flat = (idx[:, 0] * n[1] + idx[:, 1]) * n[2] + idx[:, 2]
            share = area * length / (m * len(_STENCIL))
            vol += np.bincount(flat, minlength=vol.size) * share
    return np.minimum(vol / float(h.prod()), 1.0).reshape(tuple(n)).astype(np.float32)


def image_fraction(
    img: VoxelImage, s: BoxSetup, lat: Lattice, subsamples: int = 4
) -> npt.NDArray[np.float32]:
    """Solid volume fraction of the zone cells from a voxel image, taking the nearest voxel at
    ``subsamples``^3 points per cell (outside the image: fluid). Works for cells smaller or larger
    than the voxels."""
    S = int(subsamples)
    h = _zone_spacing(s, lat)
    lo = np.array([0.0, 0.0, s.fabric_lo_z_m])
    idx = []
    valid = []
    for k, n in enumerate((lat.nx, lat.ny, lat.n_fabric)):
        x = lo[k] + (np.arange(n * S) + 0.5) * h[k] / S
        i = np.floor((x - img.origin[k]) / img.spacing[k]).astype(np.int64)
        valid.append((i >= 0) & (i < img.shape[k]))
        idx.append(np.clip(i, 0, img.shape[k] - 1))
    frac = np.zeros((lat.nx, lat.ny, lat.n_fabric), dtype=np.float64)
    sub_x = img.solid[idx[0]][:, idx[1]]  # (nx S, ny S, image nz)
    sub_x &= (valid[0][:, None] & valid[1][None, :])[:, :, None]
    for kz in range(lat.n_fabric):  # one layer of cells at a time keeps memory small
        zsel = slice(kz * S, (kz + 1) * S)
        block = sub_x[:, :, idx[2][zsel]] & valid[2][zsel][None, None, :]
        frac[:, :, kz] = block.reshape(lat.nx, S, lat.ny, S, S).mean(axis=(1, 3, 4))
    return frac.astype(np.float32)


@dataclass(frozen=True)
class Convergence:
    """The flow-rate criterion over the last ``window`` iterations of the history."""

    window: int  # iterations in the window actually used
    mean_m3_s: float  # mean outflow over the window
    amplitude_m3_s: float  # (max - min) / 2 over the window: the reported uncertainty
    relative_amplitude: float  # (max - min) / |mean|
    converged: bool  # relative_amplitude <= tolerance


def flow_rate_convergence(q: FloatArray, window: int, tolerance: float) -> Convergence:
    """Criterion on the outflow history ``q`` (one value per iteration): over the last ``window``
    iterations (all but the first half when fewer were run) the flow rate must vary by at most
    ``tolerance`` relative to its mean. The half range is the uncertainty of the result."""
    q = np.asarray(q, dtype=np.float64)
    if len(q) == 0:
        return Convergence(0, float("nan"), float("nan"), float("inf"), False)
    w = min(int(window), max(1, len(q) // 2))
    tail = q[-w:]
    mean = float(tail.mean())
    span = float(tail.max() - tail.min())
    rel = span / abs(mean) if mean != 0.0 else float("inf")
    return Convergence(w, mean, 0.5 * span, rel, bool(rel <= tolerance))


def forchheimer_fit(
    u1_m_s: float, dp1_Pa: float, u2_m_s: float, dp2_Pa: float, thickness_m: float,
    viscosity_Pa_s: float, density_kg_m3: float,
) -> tuple[float, float]:  # fmt: skip
    """Darcy permeability k_D [m^2] and Forchheimer coefficient beta [1/m] of a layer of
    ``thickness_m`` through two points (superficial velocity u_i [m/s], pressure drop dp_i [Pa])
    of the Forchheimer law dp / L = (mu / k_D) u + beta rho u^2: dp / (L u) is linear in u, with
    slope beta rho and intercept mu / k_D. Raises ValueError for equal or non-positive
    velocities. k_D comes out negative or infinite when the points do not fit the law (a
    non-positive intercept): the caller reports it as such."""
    if not (u1_m_s > 0.0 and u2_m_s > 0.0) or u1_m_s == u2_m_s:
        raise ValueError(f"forchheimer_fit needs two different positive velocities, got "
                         f"{u1_m_s!r} and {u2_m_s!r} m/s")  # fmt: skip
    y1 = dp1_Pa / (thickness_m * u1_m_s)
    y2 = dp2_Pa / (thickness_m * u2_m_s)
    slope = (y2 - y1) / (u2_m_s - u1_m_s)  # beta rho [Pa s^2 / m^3 / m]
    intercept = y1 - slope * u1_m_s  # mu / k_D [Pa s / m^2]
    k = viscosity_Pa_s / intercept if intercept != 0.0 else math.inf
    return k, slope / density_kg_m3


#: Largest fiber volume fraction the sub-grid laws are used at; denser cells take its value.
SUBGRID_PHI_MAX = 0.3
#: Cells with less fiber than this get no resistance.
SUBGRID_PHI_MIN = 1e-4


def jackson_james(phi: FloatArray, a: float) -> FloatArray:
    """Permeability [m^2] of a random 3D network of fibers of radius ``a`` at volume fraction phi:
    Jackson & James (1986), Can. J. Chem. Eng. 64, 364-374, k / a^2 = 3 / (20 phi) (-ln phi -
    0.931), for phi up to about 0.3 (its accuracy against real fibrous media is not measured
    here)."""
    phi = np.asarray(phi, dtype=np.float64)
    return np.asarray(3.0 * a * a / (20.0 * phi) * (-np.log(phi) - 0.931))


def drummond_tahir(phi: FloatArray, a: float) -> FloatArray:
    """Permeability [m^2] of a square array of cylinders of radius ``a`` in transverse flow:
    Drummond & Tahir (1984), Int. J. Multiphase Flow 10, 515-540, k / a^2 = (-ln phi - 1.476 +
    2 phi - 1.774 phi^2 + 4.078 phi^3) / (8 phi) (an expansion for small phi; the tests use it at
    0.05 and 0.1)."""
    phi = np.asarray(phi, dtype=np.float64)
    return np.asarray(a * a * (-np.log(phi) - 1.476 + 2 * phi - 1.774 * phi**2
                               + 4.078 * phi**3) / (8.0 * phi))  # fmt: skip


SUBGRID_LAWS = {"jackson_james": jackson_james, "drummond_tahir": drummond_tahir}


def subgrid_resistance(phi: npt.NDArray[np.float32], a: float, law: str) -> FloatArray:
    """Darcy resistance 1/k [1/m^2] of cells with fiber volume fraction ``phi`` (0 where phi <
    SUBGRID_PHI_MIN; phi above SUBGRID_PHI_MAX is clipped to it)."""
    p = np.clip(np.asarray(phi, dtype=np.float64), SUBGRID_PHI_MIN, SUBGRID_PHI_MAX)
    d = 1.0 / SUBGRID_LAWS[law](p, a)
    return np.where(np.asarray(phi) >= SUBGRID_PHI_MIN, d, 0.0)


#: Tomadakis & Sotirchos (1993) constants for 2D random fiber structures (fibers lying in parallel
#: planes, random in-plane directions, freely overlapping): percolation threshold porosity and
#: exponent for flow perpendicular to the fiber planes (through the sheet); 0.521 is the exponent
#: for flow parallel to the planes. Tomadakis & Robertson (2005), J. Compos. Mater. 39, 163-188,
#: apply the 1993 constants to the viscous permeability.
TS_2D_PERCOLATION_POROSITY = 0.11
TS_2D_ALPHA_THROUGH_PLANE = 0.785


def tomadakis_sotirchos(phi: FloatArray, a: float, eps_p: float = TS_2D_PERCOLATION_POROSITY,
                        alpha: float = TS_2D_ALPHA_THROUGH_PLANE) -> FloatArray:  # fmt: skip
    """Permeability [m^2] of random fiber structures of radius ``a`` at fiber volume fraction phi
    (porosity eps = 1 - phi): Tomadakis & Sotirchos (1993), AIChE J. 39, 397-412; Tomadakis &
    Robertson (2005), k / a^2 = eps (eps - eps_p)^(alpha + 2) / (8 (ln eps)^2 (1 - eps_p)^alpha
    ((alpha + 1) eps - eps_p)^2); zero at and below the percolation threshold eps_p. Defaults: 2D
    random structures, flow through the fiber planes."""
    eps = 1.0 - np.asarray(phi, dtype=np.float64)
    open_ = np.maximum(eps - eps_p, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = (eps * open_ ** (alpha + 2) / (8.0 * np.log(eps) ** 2 * (1.0 - eps_p) ** alpha
                                           * ((alpha + 1) * eps - eps_p) ** 2))  # fmt: skip
    return np.asarray(a * a * np.where(open_ > 0, k, 0.0))
