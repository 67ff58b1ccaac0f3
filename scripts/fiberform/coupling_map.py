# SPDX-License-Identifier: GPL-3.0-or-later
"""The exchange map of a two-way coupled lay-down on the flow stage's mesh (graded in z, the yarn
cells removed): the uniform grid of flow.grid as exchange cells, and how the fluid solver maps
between its cells and them (format and C++ reader: coupling/layer/exchange_map.h; formulation:
docs/coupling/formulation.md, "Exchange grid").

- Sampling: exchange cell e's velocity = sum of w U over the <= 8 lattice cells around its centre,
  with the trilinear weights the flow stage uses to resample onto flow.grid
  (:func:`fiberform.stages.flow.sample_grid`: centres clamped to the lattice centres' box, removed
  cells U = 0). Equal weights on equal data give the frozen lay-down's flow.grid to round-off.
- Reaction: the force of exchange cell e goes whole to the fluid cell that contains its centre, or,
  when that lattice cell was removed (a yarn), to the fluid cell with the nearest centre.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .lattice import trilinear_stencil
from .openfoam_case import _nearest_layer

__all__ = ["MAP_NAME", "ExchangeGrid", "exchange_map", "write_exchange_map"]

MAP_NAME = "fiberExchangeMap"  # in the case's constant/ (read by fiberPimpleFoam -coupled)
MAGIC = b"FFXMAP1\n"

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class ExchangeGrid:
    """Exchange cell centres origin + (i, j, k) * spacing, shape (nx, ny, nz) (flow.grid's nodes)."""

    def __init__(self, origin: FloatArray, spacing: FloatArray, shape: tuple[int, int, int]) -> None:
        self.origin = np.asarray(origin, dtype=np.float64)
        self.spacing = np.asarray(spacing, dtype=np.float64)
        self.shape = tuple(int(n) for n in shape)

    def centres(self) -> FloatArray:
        axes = [self.origin[a] + np.arange(self.shape[a]) * self.spacing[a] for a in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _faces(centres: FloatArray, lo: float) -> FloatArray:
    """Cell faces of a 1-D lattice of cells with flat faces from its centres (each centre is the
    midpoint of its two faces) and the lowest face ``lo``."""
    f = np.empty(len(centres) + 1)
    f[0] = lo
    for k, c in enumerate(centres):
        f[k + 1] = 2.0 * c - f[k]
    return f


def exchange_map(grid: ExchangeGrid, lattice: tuple[FloatArray, FloatArray, FloatArray],
                 cell_centres: FloatArray) -> tuple[IntArray, FloatArray, IntArray]:
    """(stencil cells (n, 8), stencil weights (n, 8), receiving cell (n,)) of the exchange cells of
    ``grid`` for a fluid mesh whose cells (centres ``cell_centres`` (m, 3), fluid cell order) lie
    on the lattice of cell centres ``lattice`` (x, y, z axes; cells missing from the mesh were
    removed). Raises StageError when a cell centre is off the lattice."""
    lx, ly, lz = (np.asarray(a, dtype=np.float64) for a in lattice)
    shape = (len(lx), len(ly), len(lz))
    cell_of = np.full(shape, -1, dtype=np.int64)
    idx = [_nearest_layer(ax, cell_centres[:, a], 1e-6 * float(ax[-1] - ax[0] or 1.0))
           for a, ax in enumerate((lx, ly, lz))]  # StageError when a centre is off the lattice
    cell_of[tuple(idx)] = np.arange(len(cell_centres))
    P = grid.centres()
    # sampling: the flow stage's trilinear resampling (centres clamped to the lattice centres' box)
    idx, w = trilinear_stencil((lx, ly, lz), P)
    c = cell_of[idx[..., 0], idx[..., 1], idx[..., 2]]
    keep = (c >= 0) & (w > 0.0)
    cells = np.where(keep, c, -1)
    weights = np.where(keep, w, 0.0)
    # reaction: the fluid cell containing the exchange cell's centre, else the nearest fluid cell
    owner = []
    for a, ax in enumerate((lx, ly, lz)):
        h0 = ax[1] - ax[0] if len(ax) > 1 else 2.0 * ax[0]
        faces = _faces(ax, ax[0] - 0.5 * h0) if a < 2 else _faces(ax, 0.0)
        owner.append(np.clip(np.searchsorted(faces, P[:, a], side="right") - 1, 0, shape[a] - 1))
    target = cell_of[tuple(owner)]
    inside = target < 0
    if np.any(inside):
        from scipy.spatial import cKDTree

        _, near = cKDTree(cell_centres).query(P[inside])
        target[inside] = np.asarray(near, dtype=np.int64)
    return cells, weights, target


def write_exchange_map(path: Path, grid: ExchangeGrid, fluid_cells: int, cells: IntArray,
                       weights: FloatArray, target: IntArray) -> None:
    """The binary map file (format in coupling/layer/exchange_map.h), through a temporary file."""
    rec = np.zeros(len(target), dtype=[("c", "<i8", (8,)), ("w", "<f8", (8,))])
    rec["c"], rec["w"] = cells, weights
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(MAGIC)
        f.write(struct.pack("<3q", *grid.shape))
        f.write(struct.pack("<6d", *grid.origin, *grid.spacing))
        f.write(struct.pack("<q", int(fluid_cells)))
        f.write(rec.tobytes())
        f.write(np.asarray(target, dtype="<i8").tobytes())
    tmp.replace(path)
