# SPDX-License-Identifier: GPL-3.0-or-later
"""Geometry and numbers of the permeability stage that need no OpenFOAM.

* :func:`capsule_fraction`: solid volume fraction of the zone cells of an
  :class:`~fiberform.openfoam_case.Lattice` occupied by chains of capsules (fibers with circular
  cross-sections, yarns), sampled at ``subsamples``^3 points per cell.
* :func:`image_fraction`: the same for a voxel image (nearest voxel at each sample point), for
  fabrics imported as voxels or STL.
* :func:`flow_rate_convergence`: the flow-rate criterion (relative amplitude of the outflow over the
  last iterations) and the uncertainty it gives.
* Sub-grid laws: permeability of fibrous media from the fiber volume fraction phi and radius a,
  :func:`jackson_james` (random 3D fiber networks) and :func:`drummond_tahir` (square arrays,
  transverse flow), and :func:`subgrid_resistance` (Darcy resistance 1/k per cell).
* Unit conversions: 1 CFM (cubic foot per square foot per minute) = 0.3048 / 60 m/s = 5.08 mm/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .fabric_geometry import VoxelImage
from .openfoam_case import BoxSetup, Lattice

__all__ = [
    "CFM_M_S",
    "Convergence",
    "capsule_fraction",
    "drummond_tahir",
    "flow_rate_convergence",
    "image_fraction",
    "jackson_james",
    "line_fraction",
    "subgrid_resistance",
]

#: 1 CFM (ft^3 / ft^2 / min) in m/s: 0.3048 m / 60 s.
CFM_M_S = 0.3048 / 60.0

FloatArray = npt.NDArray[np.float64]


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
    """Solid volume fraction of the zone cells (nx, ny, n_fabric) inside the union of the
    capsule chains ``(points (m, 3) [m], radius [m])``: each cell is sampled at ``subsamples``^3
    regularly spaced points; a point is solid when it lies within ``radius`` of a segment of a
    chain (a capsule: cylinder with hemispherical ends)."""
    S = int(subsamples)
    h = _zone_spacing(s, lat)
    lo = np.array([0.0, 0.0, s.fabric_lo_z_m])
    n_sub = np.array([lat.nx * S, lat.ny * S, lat.n_fabric * S], dtype=np.int64)
    hs = h / S
    hits: list[npt.NDArray[np.int64]] = []
    for pts, r in chains:
        pts = np.asarray(pts, dtype=np.float64)
        for a, b in zip(pts[:-1], pts[1:], strict=True):
            lo_i = np.maximum(np.floor((np.minimum(a, b) - r - lo) / hs).astype(np.int64), 0)
            hi_i = np.minimum(np.ceil((np.maximum(a, b) + r - lo) / hs).astype(np.int64), n_sub)
            if np.any(hi_i <= lo_i):
                continue
            axes = [np.arange(lo_i[k], hi_i[k]) for k in range(3)]
            I, J, K = np.meshgrid(*axes, indexing="ij")
            P = lo + (np.stack([I.ravel(), J.ravel(), K.ravel()], axis=1) + 0.5) * hs
            inside = _point_segment_distance2(P, a, b) <= r * r
            flat = (I.ravel()[inside] * n_sub[1] + J.ravel()[inside]) * n_sub[2] + K.ravel()[inside]
            hits.append(flat)
    frac = np.zeros((lat.nx, lat.ny, lat.n_fabric), dtype=np.float32)
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
    chains: list[tuple[FloatArray, float]], s: BoxSetup, lat: Lattice, per_cell: int = 8
) -> npt.NDArray[np.float32]:
    """Fiber volume fraction of the zone cells (nx, ny, n_fabric) for the sub-grid mode: each
    segment's volume pi r^2 |b - a| is split over points along its axis (``per_cell`` per cell
    length, each spread over a 3^3 stencil of half-radius offsets) and added to the cells holding
    them; segments are first clipped to the zone box. The volume inside the box is exact (up to
    fiber overlaps; capsule end caps are not counted), its placement good for cells larger than
    the fiber width, where :func:`capsule_fraction` would need many samples per cell."""
    h = _zone_spacing(s, lat)
    lo = np.array([0.0, 0.0, s.fabric_lo_z_m])
    n = np.array([lat.nx, lat.ny, lat.n_fabric])
    vol = np.zeros(int(n.prod()))
    for pts, r in chains:
        pts = np.asarray(pts, dtype=np.float64)
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
            P = (a + t[:, None] * (b - a))[:, None, :] + 0.5 * r * _STENCIL[None, :, :]
            # the axis lies in the box; a stencil point past a face loads the cell at the face
            idx = np.clip(np.floor((P.reshape(-1, 3) - lo) / h).astype(np.int64), 0, n - 1)
            flat = (idx[:, 0] * n[1] + idx[:, 1]) * n[2] + idx[:, 2]
            share = math.pi * r * r * length / (m * len(_STENCIL))
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
