# SPDX-License-Identifier: GPL-3.0-or-later
"""Small typed readers of upstream stage products, for stages that must not import each other.

Paths are relative to the scene's output folder; ``tests/test_permeability.py`` checks that they
agree with the producing stages' ``folder`` and ``products``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt

from .fabric_geometry import VoxelImage

__all__ = [
    "FABRIC_H5",
    "FIBERS_DATA",
    "FIBERS_H5",
    "FIBERS_NODES",
    "FLOW_GRID",
    "FLOW_H5",
    "FlowGrid",
    "read_flow_grid",
    "read_superficial_velocity",
    "LAYDOWN_H5",
    "LAYDOWN_RESTART",
    "PRESS_H5",
    "Chain",
    "Sheet",
    "Yarns",
    "read_fiber_outer_axes",
    "read_sheet",
    "read_yarns",
    "read_fabric_image",
    "read_sheet_chains",
    "sheet_chains",
    "read_yarn_chains",
]

FABRIC_H5 = Path("fabric") / "fabric.h5"
FIBERS_H5 = Path("fibers") / "fibers.h5"
LAYDOWN_H5 = Path("laydown") / "laydown.h5"
LAYDOWN_RESTART = Path("laydown") / "sheet.restart"
FIBERS_NODES = Path("fibers") / "fibers.nodes"
FIBERS_DATA = Path("fibers") / "fibers.data"
FLOW_H5 = Path("flow") / "flow.h5"
FLOW_GRID = Path("flow") / "flow.grid"
PRESS_H5 = Path("press") / "press.h5"

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Chain:
    """A chain of fiber or yarn elements along the centre-line points (m, 3) [m]. Circular
    section (``half_thickness`` None): capsules of ``radius`` [m]. Rectangular section (collapsed
    fibers, thesis sec. 2.4.3): boxes ``2 radius`` wide and ``2 half_thickness`` thick [m], the
    thickness along :func:`fiberform.porous_media.flat_thickness_dir` of each element (the
    vertical made perpendicular to the element: the fiber lies flat)."""

    points: FloatArray
    radius: float  #: circular: the radius; rectangular: half the width [m]
    half_thickness: float | None = None  #: rectangular: half the thickness [m]; None: circular

    @property
    def rectangular(self) -> bool:
        return self.half_thickness is not None

    @property
    def thickness(self) -> float:
        """The thinnest dimension of the section [m]: the diameter, or the thickness."""
        return 2.0 * (self.radius if self.half_thickness is None else self.half_thickness)


def read_fabric_image(path: Path) -> VoxelImage:
    """The voxel image of a ``fabric.h5``."""
    with h5py.File(path, "r") as f:
        ds = f["voxels/solid"]
        return VoxelImage(
            np.asarray(ds[...]) != 0,
            np.asarray(ds.attrs["origin_m"], dtype=np.float64),
            np.asarray(ds.attrs["voxel_size_m"], dtype=np.float64),
            {
                k: (v.item() if isinstance(v, np.generic) else v)
                for k, v in f["properties"].attrs.items()
            },
        )


def read_yarn_chains(path: Path) -> list[Chain]:
    """The yarns of a generated ``fabric.h5`` as capsule chains (empty for imported fabrics)."""
    with h5py.File(path, "r") as f:
        if "yarns" not in f:
            return []
        g = f["yarns"]
        pts = np.asarray(g["points"][...], dtype=np.float64)
        offs = np.asarray(g["offsets"][...], dtype=np.int64)
        rad = np.asarray(g["radius"][...], dtype=np.float64)
    return [Chain(pts[offs[i] : offs[i + 1]].copy(), float(rad[i])) for i in range(len(rad))]


def sheet_chains(x: FloatArray, offsets: npt.NDArray[np.int64], outer_axes: FloatArray,
                 cross_section: str = "circular") -> list[Chain]:
    """The fibers of a sheet as element chains: fiber k's nodes ``x[offsets[k]:offsets[k+1]]``
    (m, 3) [m] with the largest outer section half-axes of its nodes (``outer_axes``: (a1, a2) per
    node, aligned with ``x``, as :func:`read_fiber_outer_axes` gives them). Sections as
    ``cross_section`` (the scene's ``fibers.cross_section``): circular, radius the largest a1 or
    a2; rectangular (collapsed), half-width the largest max(a1, a2) and half-thickness the largest
    min(a1, a2)."""
    if cross_section not in ("circular", "rectangular"):
        raise ValueError(f"cross_section {cross_section!r}: expected circular or rectangular")
    if len(outer_axes) != len(x):
        raise ValueError(f"{len(outer_axes)} section half-axes for {len(x)} nodes")
    chains = []
    for lo, hi in zip(offsets[:-1], offsets[1:]):
        ax = outer_axes[lo:hi]
        pts = x[lo:hi].copy()
        if cross_section == "circular":
            chains.append(Chain(pts, float(np.max(ax))))
        else:
            chains.append(Chain(pts, float(np.max(ax.max(axis=1))), float(np.max(ax.min(axis=1)))))
    return chains


def read_sheet_chains(laydown_h5: Path, fibers_h5: Path, cross_section: str = "circular") -> list[Chain]:
    """The fibers on the laid-down (or pressed: ``press.h5`` has the same ``/sheet``) sheet, final
    snapshot, as element chains (:func:`sheet_chains`) with the largest outer section half-axes of
    their fiber in ``fibers.h5`` (``/fibers/radii[:, :2]``, the per-node jitter of the generate
    stage)."""
    with h5py.File(laydown_h5, "r") as f:
        x = np.asarray(f["sheet/x"][...], dtype=np.float64)
        offs = np.asarray(f["sheet/offsets"][...], dtype=np.int64)
        ids = np.asarray(f["sheet/fiber_id"][...], dtype=np.int64)
    return sheet_chains(x, offs, read_fiber_outer_axes(fibers_h5, ids), cross_section)


@dataclass(frozen=True)
class Sheet:
    """The laid-down sheet of ``laydown.h5`` (its final snapshot) and the lay-down's last overlaps."""

    x: FloatArray  #: node positions (n, 3) [m], fiber by fiber
    fiber_id: npt.NDArray[np.int64]  #: 0-based fiber indices into fibers.h5
    offsets: npt.NDArray[np.int64]  #: fiber k owns nodes offsets[k]:offsets[k+1]
    min_fiber_fiber_gap: float  #: smallest surface gap of two fibers' elements, last snapshot [m]
    min_element_clearance: float  #: smallest element-yarn centre-line clearance, last snapshot [m]


def read_sheet(laydown_h5: Path) -> Sheet:
    """The sheet of a ``laydown.h5``."""
    with h5py.File(laydown_h5, "r") as f:
        return Sheet(
            np.asarray(f["sheet/x"][...], dtype=np.float64),
            np.asarray(f["sheet/fiber_id"][...], dtype=np.int64),
            np.asarray(f["sheet/offsets"][...], dtype=np.int64),
            float(f["snapshots/min_fiber_fiber_gap"][-1]),
            float(f["snapshots/min_element_clearance"][-1]),
        )


@dataclass(frozen=True)
class Yarns:
    """The yarn centre lines of a generated ``fabric.h5``."""

    points: FloatArray  #: (n, 3) [m]
    offsets: npt.NDArray[np.int64]  #: yarn k owns points offsets[k]:offsets[k+1]
    radius: FloatArray  #: one radius per yarn [m]

    @property
    def top(self) -> float:
        """The fabric top: the highest point of any yarn surface [m]."""
        return float(np.max(self.points[:, 2] + np.repeat(self.radius, np.diff(self.offsets))))


def read_yarns(fabric_h5: Path) -> Yarns:
    """The yarns of a generated ``fabric.h5``."""
    with h5py.File(fabric_h5, "r") as f:
        return Yarns(np.asarray(f["yarns/points"][...], dtype=np.float64),
                     np.asarray(f["yarns/offsets"][...], dtype=np.int64),
                     np.asarray(f["yarns/radius"][...], dtype=np.float64))


def read_superficial_velocity(flow_h5: Path) -> float:
    """The bare fabric's superficial velocity of the flow stage's ``flow.h5`` (m/s)."""
    with h5py.File(flow_h5, "r") as f:
        return float(f["flow_rate/superficial_velocity"][()])


@dataclass(frozen=True)
class FlowGrid:
    """The uniform grid of a ``flow.h5`` (the flow stage's velocity samples; the two-way
    coupling's exchange grid) and the lattice of its OpenFOAM mesh."""

    origin: FloatArray  #: (3,) [m]
    spacing: FloatArray  #: (3,) [m]
    shape: tuple[int, int, int]  #: cells along x, y, z
    lattice: tuple[FloatArray, FloatArray, FloatArray]  #: the mesh lattice's coordinates along x, y, z [m]


def read_flow_grid(flow_h5: Path) -> FlowGrid:
    """The grid and mesh lattice of a ``flow.h5``."""
    with h5py.File(flow_h5, "r") as f:
        lattice = tuple(np.asarray(f[f"lattice/{a}"][...], dtype=np.float64) for a in "xyz")
        return FlowGrid(np.asarray(f["grid/origin"][...], dtype=np.float64),
                        np.asarray(f["grid/spacing"][...], dtype=np.float64),
                        tuple(int(n) for n in f["grid/shape"][...]),  # type: ignore[arg-type]
                        lattice)  # type: ignore[arg-type]


def read_fiber_outer_axes(fibers_h5: Path, fiber_ids: npt.NDArray[np.int64]) -> FloatArray:
    """For the nodes of the fibers ``fiber_ids`` (in that order): the outer section half-axes
    (a1, a2) [m], shape (n, 2), from ``fibers.h5``."""
    with h5py.File(fibers_h5, "r") as f:
        offs = np.asarray(f["fibers/offsets"][...], dtype=np.int64)
        radii = np.asarray(f["fibers/radii"][...], dtype=np.float64)
    parts = [radii[offs[k]:offs[k + 1], :2] for k in fiber_ids]
    return np.concatenate(parts) if parts else np.zeros((0, 2))
