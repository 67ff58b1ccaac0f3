# SPDX-License-Identifier: GPL-3.0-or-later
"""Section of the ``fabric`` stage."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from ..fabric_geometry import WeaveParams
from ._fields import RelativePath, _Section, choice, quantity, scene_problem


class FabricSection(_Section):
    """The forming fabric (the ``fabric`` stage): a generated double-layer weave or an import."""

    source: Literal["generate", "voxels", "stl"] = choice(
        "generate: the parametric double-layer weave; voxels: a voxel image (HDF5 dataset 'solid' "
        "with attribute voxel_size_m); stl: a closed surface mesh",
        default="generate",
    )
    import_file: RelativePath | None = Field(
        default=None,
        description="File to import (source voxels or stl), relative to the working directory",
        json_schema_extra={"unit": "-", "meaning": "File to import (voxels or stl)",
                           "range": "relative path without '..'"},
    )  # fmt: skip
    import_unit_m: float = quantity(
        "Length of one STL coordinate unit (1e-3 for a file in millimetres)", "m",
        default=1.0, gt=0.0, le=1.0,
    )  # fmt: skip
    size_x_m: float = quantity("Piece length along x (MD)", "m", default=3.0e-3, gt=0.0, le=0.02)
    size_y_m: float = quantity("Piece width along y (CD)", "m", default=3.0e-3, gt=0.0, le=0.02)
    lower_side_z_m: float = quantity(
        "Height of the fabric's lower side above the domain bottom", "m", default=2.0e-3,
        ge=0.0, le=0.1,
    )  # fmt: skip
    md_diameter_m: float = quantity("Warp (MD) yarn diameter", "m", default=0.11e-3, gt=0.0, le=2e-3)
    cd_top_diameter_m: float = quantity(
        "Top weft (CD) yarn diameter", "m", default=0.13e-3, gt=0.0, le=2e-3
    )
    cd_bottom_diameter_m: float = quantity(
        "Bottom weft (CD) yarn diameter", "m", default=0.177e-3, gt=0.0, le=2e-3
    )
    md_count_per_m: float = quantity("Warps per metre of width", "1/m", default=5000.0, gt=0.0, le=1e5)
    cd_count_per_m: float = quantity(
        "Weft columns per metre of length (each a top and a bottom weft)", "1/m",
        default=3000.0, gt=0.0, le=1e5,
    )  # fmt: skip
    shed: int = quantity("Columns in the weave repeat (8: eight-shed)", "1", default=8, ge=3, le=64)
    shed_step: int = quantity(
        "Column shift of the pattern from one warp to the next (coprime with shed)", "1",
        default=3, ge=1, le=63,
    )  # fmt: skip
    bottom_shift: int | None = quantity(
        "Columns from a warp's top crossing to its bottom crossing (absent: shed/2)", "1",
        default=None, ge=1, le=63,
    )  # fmt: skip
    clearance_m: float = quantity(
        "Extra gap between crossing yarns", "m", default=0.0, ge=0.0, le=1e-4
    )
    arc_step_deg: float = quantity(
        "Largest angle of one polyline segment where a warp wraps a weft", "deg",
        default=10.0, ge=1.0, le=30.0,
    )  # fmt: skip
    voxel_size_m: float = quantity(
        "Voxel size of the fabric image", "m", default=8e-6, ge=1e-6, le=1e-4
    )
    stl_voxel_size_m: float = quantity(
        "Sampling step of the STL surface (coarser than the image keeps the file small)", "m",
        default=25e-6, ge=1e-6, le=2e-4,
    )  # fmt: skip

    def weave(self) -> WeaveParams:
        """The weave geometry of a generated fabric (:mod:`fiberform.fabric_geometry`)."""
        return WeaveParams(
            size_x_m=self.size_x_m, size_y_m=self.size_y_m, md_diameter_m=self.md_diameter_m,
            cd_top_diameter_m=self.cd_top_diameter_m, cd_bottom_diameter_m=self.cd_bottom_diameter_m,
            md_count_per_m=self.md_count_per_m, cd_count_per_m=self.cd_count_per_m, shed=self.shed,
            shed_step=self.shed_step, bottom_shift=self.bottom_shift, clearance_m=self.clearance_m,
            lower_side_z_m=self.lower_side_z_m, arc_step_deg=self.arc_step_deg,
        )  # fmt: skip

    @property
    def top_z_m(self) -> float:
        """Height of the generated fabric's top (lower side + weave thickness) [m]."""
        return self.lower_side_z_m + self.weave().thickness_m

    @model_validator(mode="after")
    def _check(self) -> FabricSection:
        if self.source != "generate" and self.import_file is None:
            raise scene_problem("import_file", f"required when source is {self.source}")
        if self.source == "generate" and self.import_file is not None:
            raise scene_problem(
                "import_file", "only used when source is voxels or stl", self.import_file
            )
        # a field the source does not use, given in the scene, configures nothing: refused
        for name in sorted(self.model_fields_set):
            sources = FABRIC_FIELD_SOURCES.get(name)
            if sources is not None and self.source not in sources:
                raise scene_problem(name, f"only used when source is {' or '.join(sources)} (this one: "
                                    f"{self.source})", getattr(self, name))
        return self


#: the fabric fields that act only with some sources (stage fabric, make_fabric): the weave's with a
#: generated fabric; the image's voxel size when one is made (generate, stl); the unit of an STL
WEAVE_FIELDS = ("md_diameter_m", "cd_top_diameter_m", "cd_bottom_diameter_m", "md_count_per_m",
                "cd_count_per_m", "shed", "shed_step", "bottom_shift", "clearance_m", "arc_step_deg",
                "stl_voxel_size_m")
FABRIC_FIELD_SOURCES: dict[str, tuple[str, ...]] = {
    **{name: ("generate",) for name in WEAVE_FIELDS},
    "voxel_size_m": ("generate", "stl"),
    "import_unit_m": ("stl",),
}
