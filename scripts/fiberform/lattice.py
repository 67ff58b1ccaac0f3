# SPDX-License-Identifier: GPL-3.0-or-later
"""Trilinear interpolation on a rectilinear lattice of cell centres: the one stencil the flow
stage resamples its solution with (:func:`fiberform.stages.flow.sample_grid`, flow.grid) and the
two-way coupling's exchange map samples the live fluid with (:mod:`fiberform.coupling_map`), so
the frozen and the coupled lay-down see the same velocities for the same fluid field."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["trilinear_stencil"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def _interval(axis: FloatArray, x: FloatArray) -> tuple[IntArray, FloatArray]:
    """Lower lattice index and weight of the upper one of points x already inside [axis0, axis-1]."""
    if len(axis) < 2:
        return np.zeros(len(x), np.int64), np.zeros(len(x))
    i = np.clip(np.searchsorted(axis, x, side="right") - 1, 0, len(axis) - 2)
    return i.astype(np.int64), (x - axis[i]) / (axis[i + 1] - axis[i])


def trilinear_stencil(axes: tuple[FloatArray, FloatArray, FloatArray],
                      points: FloatArray) -> tuple[IntArray, FloatArray]:
    """Lattice indices (n, 8, 3) and weights (n, 8) of the trilinear interpolation at ``points``
    (n, 3) on the lattice with increasing node coordinates ``axes`` (x, y, z). Points outside the
    lattice's box are clamped onto it (they take the boundary values). Corner s = 4 di + 2 dj + dk
    is the node (i + di, j + dj, k + dk); weights sum to 1; on an axis of one node the weight of
    the (repeated) upper neighbour is 0."""
    p = np.asarray(points, dtype=np.float64)
    lo_t = [_interval(np.asarray(ax, dtype=np.float64), np.clip(p[:, a], ax[0], ax[-1]))
            for a, ax in enumerate(axes)]
    n = len(p)
    idx = np.empty((n, 8, 3), dtype=np.int64)
    w = np.ones((n, 8))
    s = 0
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                for a, d in enumerate((di, dj, dk)):
                    i0, t = lo_t[a]
                    w[:, s] *= t if d else 1.0 - t
                    idx[:, s, a] = np.minimum(i0 + d, len(axes[a]) - 1)
                s += 1
    return idx, w
