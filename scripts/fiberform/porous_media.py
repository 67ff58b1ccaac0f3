# SPDX-License-Identifier: GPL-3.0-or-later
"""Geometry and numbers of the permeability stage that need no OpenFOAM.

* :func:`capsule_fraction`: solid volume fraction of the zone cells of an
  :class:`~fiberform.openfoam_case.Lattice` occupied by chains of capsules (fibers with circular
  cross-sections, yarns), sampled at ``subsamples``^3 points per cell.
* :func:`image_fraction`: the same for a voxel image (nearest voxel at each sample point), for
  fabrics imported as voxels or STL.
* :func:`flow_rate_convergence`: the flow-rate criterion (relative amplitude of the outflow over the
  last iterations) and the uncertainty it gives.
* Unit conversions: 1 CFM (cubic foot per square foot per minute) = 0.3048 / 60 m/s = 5.08 mm/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .fabric_geometry import VoxelImage
from .openfoam_case import BoxSetup, Lattice

__all__ = [
    "CFM_M_S",
    "Convergence",
    "capsule_fraction",
    "flow_rate_convergence",
    "image_fraction",
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
    converged: bool  # relative_amplitude <= tolerance and the window was complete


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
