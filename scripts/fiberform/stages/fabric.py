# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``fabric``: the forming fabric as yarn centrelines, a voxel image, an STL and a picture.

Generates the double-layer weave of :mod:`fiberform.fabric_geometry` from the scene's ``fabric``
section, or imports a voxel image (HDF5) or a closed STL surface. Products in
``<output_dir>/fabric/``:

* ``fabric.h5``: ``/yarns`` (generated fabrics only: centreline polylines, radii, kinds),
  ``/voxels/solid`` (the image the CFD uses), ``/properties`` (open area, thickness, crimp,
  checks), provenance on the root;
* ``fabric.stl``: closed, consistently oriented surface (marching tetrahedra on the signed
  distance to the yarns, or on the voxel image for imports), binary, metres;
* ``fabric.png``: top view (height of the upper surface) and a side section.

Docs: docs/stages/fabric.md.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt

from ..errors import ConfigError, SceneError, StageError
from ..fabric_geometry import (
    KIND_NAMES,
    FabricGeometryError,
    VoxelImage,
    Yarn,
    analytic_open_area,
    build_weave,
    check_yarns,
    close_field,
    marching_tetrahedra,
    mesh_edge_report,
    mesh_volume,
    read_stl,
    signed_distance_image,
    voxel_open_area,
    voxelize_mesh,
    warp_crimp,
    write_stl,
)
from ..products import read_fabric_image
from ..provenance import file_hash, write_dataset
from ..scene import FabricSection, Scene
from ._stage import Stage, StageContext

__all__ = [
    "FabricStage",
    "FabricResult",
    "import_stl",
    "import_voxels",
    "make_fabric",
    "read_fabric_image",
    "read_yarns",
    "write_voxel_file",
]

H5_NAME, STL_NAME, PNG_NAME = "fabric.h5", "fabric.stl", "fabric.png"

#: Smallest accepted yarn-yarn clearance (m): touching crossings give about -1e-19.
YARN_CLEARANCE_TOL_M = 1e-10


class FabricResult:
    """Everything the stage computes, before it is written."""

    def __init__(self) -> None:
        self.yarns: list[Yarn] | None = None
        self.image: VoxelImage | None = None
        self.verts: npt.NDArray[np.float64] = np.zeros((0, 3))
        self.tris: npt.NDArray[np.int64] = np.zeros((0, 3), dtype=np.int64)
        self.props: dict[str, float | int | str] = {}


# --------------------------------------------------------------------------------------------
# Imports


def import_voxels(path: Path, lower_side_z_m: float) -> VoxelImage:
    """Read a user voxel image: HDF5 dataset ``solid`` (3-D, nonzero = solid, index order x, y, z)
    with attribute ``voxel_size_m`` (one value or three) and optionally ``origin_m``; a fiberform
    ``fabric.h5`` (``/voxels/solid``) works too. The image is placed with its x-y corner at the
    origin and its lowest solid layer at ``lower_side_z_m``; empty layers above and below are
    dropped."""
    try:
        with h5py.File(path, "r") as f:
            ds = f["voxels/solid"] if "voxels/solid" in f else f.get("solid")
            if not isinstance(ds, h5py.Dataset) or ds.ndim != 3:
                raise FabricGeometryError(
                    f"{path}: no 3-D dataset 'solid' (or '/voxels/solid') in the file"
                )
            if "voxel_size_m" not in ds.attrs:
                raise FabricGeometryError(f"{path}: attribute voxel_size_m missing on 'solid'")
            vs = ds.attrs["voxel_size_m"]
            solid = np.asarray(ds[...]) != 0
    except OSError as exc:
        raise FabricGeometryError(f"{path}: not readable as HDF5 ({exc})") from None
    spacing = np.broadcast_to(np.asarray(vs, dtype=np.float64).ravel(), (3,)).copy()
    if spacing.size != 3 or not np.all(np.isfinite(spacing)) or np.any(spacing <= 0):
        raise FabricGeometryError(f"{path}: voxel_size_m must be one or three positive numbers")
    if not solid.any():
        raise FabricGeometryError(f"{path}: the image holds no solid voxel")
    layers = np.nonzero(solid.any(axis=(0, 1)))[0]
    solid = solid[:, :, layers[0] : layers[-1] + 1]
    origin = np.array([0.0, 0.0, lower_side_z_m])
    return VoxelImage(np.ascontiguousarray(solid), origin, spacing, {"source": "voxels"})


def import_stl(
    path: Path, unit_m: float, voxel_size_m: float, lower_side_z_m: float
) -> tuple[VoxelImage, npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Read a closed STL, scale it to metres, move its bounding box to x, y >= 0 with its lower
    side at ``lower_side_z_m`` and voxelize it (ray parity). Returns the image and the moved mesh."""
    verts, tris = read_stl(path)
    report = mesh_edge_report(tris)
    if report["edges_not_shared_by_two"]:
        raise FabricGeometryError(
            f"{path}: the surface is not closed ({report['edges_not_shared_by_two']} edges not "
            "shared by exactly two triangles); the inside of an open surface is undefined"
        )
    verts = verts * unit_m
    lo = verts.min(axis=0)
    verts = verts - lo + np.array([0.0, 0.0, lower_side_z_m])
    hi = verts.max(axis=0)
    origin = np.array([0.0, 0.0, lower_side_z_m])
    ext = hi - origin
    shape_f = np.maximum(1, np.round(ext / voxel_size_m)).astype(int)
    shape = (int(shape_f[0]), int(shape_f[1]), int(shape_f[2]))
    spacing = ext / shape_f
    solid = voxelize_mesh(verts, tris, origin, spacing, shape)
    return VoxelImage(solid, origin, spacing, {"source": "stl"}), verts, tris


def write_voxel_file(path: Path, img: VoxelImage) -> None:
    """Write ``img`` in the user import format (dataset ``solid`` + ``voxel_size_m``)."""
    with h5py.File(path, "w") as f:
        ds = f.create_dataset("solid", data=img.solid.astype(np.uint8), compression="gzip")
        ds.attrs["voxel_size_m"] = img.spacing
        ds.attrs["origin_m"] = img.origin
        ds.attrs["units"] = "1"


# --------------------------------------------------------------------------------------------
# Generation


def make_fabric(sec: FabricSection, base_dir: Path | None = None) -> FabricResult:
    """Build the fabric described by ``sec`` (no files written)."""
    res = FabricResult()
    props = res.props
    props["source"] = sec.source
    if sec.source == "generate":
        p = sec.weave()
        yarns = build_weave(p)
        chk = check_yarns(yarns)
        if chk.min_clearance_m < -YARN_CLEARANCE_TOL_M:
            i, j = chk.worst_pair
            raise FabricGeometryError(
                f"yarns {i} ({KIND_NAMES[yarns[i].kind]}) and {j} ({KIND_NAMES[yarns[j].kind]}) "
                f"intersect by {-chk.min_clearance_m:.3g} m; lower the yarn counts or diameters"
            )
        lo = np.array([0.0, 0.0, p.lower_side_z_m])
        hi = np.array([p.size_x_m, p.size_y_m, p.lower_side_z_m + p.thickness_m])
        sdf, sp = signed_distance_image(yarns, lo, hi, sec.voxel_size_m)
        res.image = VoxelImage(sdf < 0, lo, sp, {"source": "generate"})
        # Surface from the signed distance sampled at the (coarser) STL step.
        sdf_s, sp_s = signed_distance_image(yarns, lo, hi, sec.stl_voxel_size_m)
        G = close_field(sdf_s, float(2 * sp_s.max()))
        res.verts, res.tris = marching_tetrahedra(G, lo - 0.5 * sp_s, sp_s, lo, hi)
        res.yarns = yarns
        oa = analytic_open_area(p)
        props.update(
            thickness_m=p.thickness_m,
            open_area_analytic=oa["open_area"],
            open_area_infinite_fabric=oa["open_area_infinite"],
            open_area_tolerance=(
                oa["strips_x"] * sp[0] / p.size_x_m + oa["strips_y"] * sp[1] / p.size_y_m
            ),
            warp_crimp=warp_crimp(yarns),
            min_yarn_clearance_m=chk.min_clearance_m,
            yarn_pairs_checked=chk.pairs_checked,
            md_pitch_m=p.md_pitch_m,
            cd_pitch_m=p.cd_pitch_m,
        )
    else:
        if sec.import_file is None:
            raise SceneError("<scene>", ["fabric.import_file: required for an import"])
        path = (base_dir or Path.cwd()) / sec.import_file
        if not path.is_file():
            raise StageError(f"fabric.import_file: {path} does not exist")
        if sec.source == "voxels":
            img = import_voxels(path, sec.lower_side_z_m)
        else:
            img, _, _ = import_stl(path, sec.import_unit_m, sec.voxel_size_m, sec.lower_side_z_m)
        res.image = img
        F = close_field(np.where(img.solid, -0.5, 0.5), 0.5)
        res.verts, res.tris = marching_tetrahedra(
            F, img.origin - 0.5 * img.spacing, img.spacing, img.origin, img.upper
        )
        props["thickness_m"] = float(img.upper[2] - img.origin[2])
    img = res.image
    assert img is not None
    props["open_area_voxels"] = voxel_open_area(img)
    props["solid_fraction"] = float(img.solid.mean())
    props["solid_volume_m3"] = float(img.solid.sum() * np.prod(img.spacing))
    rep = mesh_edge_report(res.tris)
    props["stl_triangles"] = rep["triangles"]
    props["stl_open_edges"] = rep["edges_not_shared_by_two"]
    props["stl_misoriented_edges"] = rep["directed_edges_repeated"]
    props["stl_volume_m3"] = mesh_volume(res.verts, res.tris)
    return res


# --------------------------------------------------------------------------------------------
# Output


def write_fabric_h5(h5: h5py.File, res: FabricResult) -> None:
    img = res.image
    assert img is not None
    if res.yarns is not None:
        g = h5.create_group("yarns")
        g.attrs["description"] = (
            "yarn centrelines: yarn i is the polyline points[offsets[i]:offsets[i+1]] swept by a "
            "sphere of radius[i]"
        )
        pts = np.concatenate([y.points for y in res.yarns])
        offs = np.cumsum([0] + [len(y.points) for y in res.yarns]).astype(np.int64)
        write_dataset(g, "points", pts, "m", "centreline vertices of all yarns, (P, 3)")
        write_dataset(g, "offsets", offs, "1", "yarn i owns points[offsets[i]:offsets[i+1]]")
        write_dataset(g, "radius", np.array([y.radius for y in res.yarns]), "m", "yarn radius")
        kinds = write_dataset(
            g, "kind", np.array([y.kind for y in res.yarns], dtype=np.int8), "1",
            "0 MD warp, 1 CD top weft, 2 CD bottom weft",
        )  # fmt: skip
        kinds.attrs["names"] = json.dumps({str(k): v for k, v in KIND_NAMES.items()})
    v = h5.create_group("voxels")
    ds = v.create_dataset(
        "solid", data=img.solid.astype(np.uint8), compression="gzip", shuffle=True
    )
    ds.attrs["units"] = "1"
    ds.attrs["description"] = (
        "1 = solid; voxel (i, j, k) has its centre at origin_m + (i+0.5, j+0.5, k+0.5) * voxel_size_m"
    )
    ds.attrs["voxel_size_m"] = img.spacing
    ds.attrs["origin_m"] = img.origin
    write_dataset(v, "origin", img.origin, "m", "lower corner of the image")
    write_dataset(v, "voxel_size", img.spacing, "m", "voxel edge lengths (x, y, z)")
    pg = h5.create_group("properties")
    for key, val in res.props.items():
        pg.attrs[key] = val
    pg.attrs["description"] = "scalar results; names carry their unit (_m, _m3), the rest are 1"
    pg.attrs["stl_file"] = STL_NAME


def write_png(path: Path, res: FabricResult, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    img = res.image
    assert img is not None
    nz = img.shape[2]
    zc = img.centres(2)
    top = np.where(
        img.solid.any(axis=2), zc[nz - 1 - np.argmax(img.solid[:, :, ::-1], axis=2)], np.nan
    )
    ext_xy = [img.origin[0] * 1e3, img.upper[0] * 1e3, img.origin[1] * 1e3, img.upper[1] * 1e3]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1, 1.3]})
    ax = axes[0]
    im = ax.imshow((top.T - img.origin[2]) * 1e6, origin="lower", extent=ext_xy, cmap="viridis")
    ax.set_xlabel("x (MD) [mm]")
    ax.set_ylabel("y (CD) [mm]")
    ax.set_title("top view: height of the upper surface (white: open)")
    fig.colorbar(im, ax=ax, label="height above lower side [um]", shrink=0.8)
    ax = axes[1]
    # Side section through the first warp (or the middle of the image).
    j = img.shape[1] // 2
    if res.yarns:
        warps = [y for y in res.yarns if y.kind == 0 and 0 < y.points[0, 1] < img.upper[1]]
        if warps:
            j = int(
                np.clip(
                    (warps[0].points[0, 1] - img.origin[1]) / img.spacing[1], 0, img.shape[1] - 1
                )
            )
    yj = img.centres(1)[j]
    ax.imshow(
        img.solid[:, j, :].T, origin="lower", cmap="Greys", interpolation="nearest",
        extent=[img.origin[0] * 1e3, img.upper[0] * 1e3, img.origin[2] * 1e3, img.upper[2] * 1e3],
    )  # fmt: skip
    if res.yarns:
        for y in res.yarns:
            if y.kind == 0 and abs(y.points[0, 1] - yj) < y.radius:
                ax.plot(y.points[:, 0] * 1e3, y.points[:, 2] * 1e3, "r-", lw=0.8)
    ax.set_xlim(img.origin[0] * 1e3, img.upper[0] * 1e3)
    ax.set_aspect("equal")
    ax.set_xlabel("x (MD) [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title(f"section y = {yj * 1e3:.3f} mm (red: warp centreline)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def read_yarns(path: Path) -> list[Yarn]:
    """The yarns of a generated ``fabric.h5`` (empty for imported fabrics)."""
    with h5py.File(path, "r") as f:
        if "yarns" not in f:
            return []
        g = f["yarns"]
        pts, offs, rad, kind = (
            np.asarray(g[n][...]) for n in ("points", "offsets", "radius", "kind")
        )
    return [
        Yarn(pts[offs[i] : offs[i + 1]].copy(), float(rad[i]), int(kind[i]), i)
        for i in range(len(rad))
    ]


class FabricStage(Stage):
    name = "fabric"
    summary = "forming fabric: woven geometry (or import), voxel image, STL, picture"
    folder = "fabric"
    requires = ("fabric",)
    uses = ("fabric",)
    products = (H5_NAME, STL_NAME, PNG_NAME)
    code_version = 1

    def check_scene(self, scene: Scene) -> list[str]:
        problems = super().check_scene(scene)
        sec = scene.fabric
        if sec is not None and sec.source == "generate":
            problems += [f"fabric: {p}" for p in sec.weave().problems()]
            if sec.voxel_size_m > 0.25 * min(sec.md_diameter_m, sec.cd_top_diameter_m):
                problems.append(
                    f"fabric.voxel_size_m = {sec.voxel_size_m!r}: coarser than a quarter of the "
                    "thinnest yarn; the image would not resolve the yarns"
                )
            cells = (sec.size_x_m * sec.size_y_m * 1e-3) / sec.voxel_size_m**3
            if cells > 2e8:
                problems.append(
                    f"fabric.voxel_size_m = {sec.voxel_size_m!r}: about {cells:.2g} voxels, more "
                    "than 2e8"
                )
        return problems

    def preflight(self, ctx: StageContext) -> None:
        """An imported fabric's file exists (relative to the working directory), before anything
        is written: ConfigError (exit status 2) naming the field."""
        sec = ctx.scene.fabric
        if sec is not None and sec.import_file is not None and not (Path.cwd() / sec.import_file).is_file():
            raise ConfigError(f"fabric.import_file: {Path.cwd() / sec.import_file} does not exist "
                              "(the path is relative to the working directory)")

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        hashes = super().input_hashes(ctx)
        sec = ctx.scene.fabric
        if sec is not None and sec.import_file is not None:
            path = Path.cwd() / sec.import_file
            if path.is_file():
                hashes["import_file"] = file_hash(path)
        return hashes

    def produce(
        self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path], hashes: Mapping[str, str]
    ) -> None:
        sec = ctx.scene.fabric
        assert sec is not None
        try:
            res = make_fabric(sec)
        except FabricGeometryError as exc:
            raise StageError(f"fabric: {exc}") from None
        write_fabric_h5(h5, res)
        write_stl(tmp[STL_NAME], res.verts, res.tris)
        pr = res.props
        oa = f"open area {float(pr['open_area_voxels']):.3f} (voxels)"
        if "open_area_analytic" in pr:
            oa += f", {float(pr['open_area_analytic']):.3f} (analytic)"
        title = (
            f"fabric of scene '{ctx.scene.name}' ({sec.source}): thickness "
            f"{float(pr['thickness_m']) * 1e3:.3f} mm, {oa}"
        )
        write_png(tmp[PNG_NAME], res, title)
