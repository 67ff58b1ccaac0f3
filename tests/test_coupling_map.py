# SPDX-License-Identifier: GPL-3.0-or-later
"""The exchange map of two-way coupling on the flow stage's mesh (fiberform.coupling_map, issue 13),
without binaries: a lattice graded in z with removed (yarn) cells, the fluid cells listed in a
shuffled order as an OpenFOAM mesh after subsetMesh lists them.

- frozen-flow equivalence: the map's sampling of the fluid cell velocities equals the flow stage's
  own resampling onto flow.grid (fiberform.stages.flow.sample_grid; both use
  fiberform.lattice.trilinear_stencil) to 1e-12 relative, and both equal scipy's
  RegularGridInterpolator (linear, points clamped to the lattice's box: an independent
  implementation) to 1e-12 relative, velocity and fluid-weighted pressure;
- reaction: every exchange cell hands its force to one fluid cell, the one whose lattice box
  contains the exchange cell's centre (checked by brute force over the boxes), or, for a centre in a
  removed cell, the fluid cell with the nearest centre; the sum over fluid cells equals the sum over
  exchange cells to round-off;
- the scene section `coupling`: ranges, fields only allowed with two_way, interval dividing a check."""

from __future__ import annotations

import dataclasses
import struct
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.interpolate import RegularGridInterpolator

from fiberform.coupling_map import ExchangeGrid, exchange_map, write_exchange_map
from fiberform.errors import SceneError
from fiberform.scene import parse_scene
from fiberform.stages.laydown import Laydown
from fiberform.openfoam_case import CaseResult
from fiberform.stages.flow import FlowSetup, sample_grid

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_scene_fields_reach_input import BASE  # noqa: E402


def graded_lattice() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """x, y centres (uniform 50 um), z faces graded below and above a uniform zone, and faces z."""
    h = 50e-6
    lx = (np.arange(8) + 0.5) * h
    ly = (np.arange(6) + 0.5) * h
    below = 2e-4 * np.cumsum(1.0 / 1.15 ** np.arange(4))[::-1]  # shrinking towards the zone
    zf = np.concatenate([[0.0], np.cumsum(np.concatenate([np.diff(np.concatenate([[0.0], below[::-1]])),
                                                          np.full(6, h), h * 1.2 ** np.arange(1, 5)]))])
    return lx, ly, 0.5 * (zf[:-1] + zf[1:]), zf


def test_map_sampling_equals_flow_grid_and_reaction_is_conservative(tmp_path: Path) -> None:
    rng = np.random.default_rng(13)
    lx, ly, lz, zf = graded_lattice()
    shape = (len(lx), len(ly), len(lz))
    fluid = np.ones(shape, dtype=bool)
    k0 = int(np.searchsorted(lz, zf[4]))  # the uniform zone: remove a "yarn" of cells
    fluid[2:5, :, k0 + 1:k0 + 4] = False
    fluid[6, 1:3, k0:k0 + 2] = False
    U = rng.normal(size=shape + (3,))
    U[~fluid] = 0.0
    ijk = np.argwhere(fluid)
    perm = rng.permutation(len(ijk))  # the mesh's own cell order
    ijk = ijk[perm]
    C = np.stack([lx[ijk[:, 0]], ly[ijk[:, 1]], lz[ijk[:, 2]]], axis=1)
    Ucells = U[ijk[:, 0], ijk[:, 1], ijk[:, 2]]

    top = float(zf[-1])
    s = FlowSetup(size_x_m=8 * 50e-6, size_y_m=6 * 50e-6, fabric_lo_z_m=float(zf[4]),
                  fabric_hi_z_m=float(zf[10]), top_z_m=top, cell_size_m=50e-6,
                  max_cell_height_m=2e-4, delta_p_Pa=1.0, density_kg_m3=1000.0,
                  viscosity_Pa_s=1e-3, sample_spacing_m=70e-6)  # fmt: skip
    res = CaseResult(lattice_x=lx, lattice_y=ly, lattice_z=lz, U=U, p=np.zeros(shape), fluid=fluid,
                     solid_fraction=np.zeros(shape, np.float32), q_top_m3_s=0.0, q_bottom_m3_s=0.0,
                     iterations=0, converged=True, fluid_cells=len(C), lattice_cells=U.size // 3,
                     wall_times_s={}, final_residuals={})  # fmt: skip
    pres = rng.normal(size=shape)
    pres[~fluid] = np.nan
    res = dataclasses.replace(res, p=pres)
    g, Ug, pg = sample_grid(res, s)
    grid = ExchangeGrid(g.origin, g.spacing, g.shape)

    # the resampling against scipy's trilinear interpolation (clamped to the lattice centres' box)
    axes = (lx, ly, lz)
    Q = np.stack(np.meshgrid(*(np.clip(g.axis(a), axes[a][0], axes[a][-1]) for a in range(3)),
                             indexing="ij"), axis=-1).reshape(-1, 3)
    U_ref = np.stack([RegularGridInterpolator(axes, U[..., c])(Q) for c in range(3)], axis=1)
    assert np.max(np.abs(Ug.reshape(-1, 3) - U_ref)) <= 1e-12 * np.max(np.abs(U_ref))
    wf = RegularGridInterpolator(axes, fluid.astype(float))(Q)
    wet = wf > 0
    assert 0 < np.count_nonzero(~wet) < wet.size  # nodes inside the removed cells too
    p_ref = RegularGridInterpolator(axes, np.where(fluid, pres, 0.0))(Q)[wet] / wf[wet]
    assert np.max(np.abs(pg.reshape(-1)[wet] - p_ref)) <= 1e-12 * np.max(np.abs(p_ref))
    assert np.all(np.isnan(pg.reshape(-1)[~wet]))
    cells, weights, target = exchange_map(grid, (lx, ly, lz), C)

    # frozen-flow equivalence: sum of w U_cell over the stencil = the flow stage's flow.grid values
    sampled = np.einsum("es,esc->ec", weights, np.where(cells[..., None] >= 0, Ucells[cells], 0.0))
    want = Ug.reshape(-1, 3)
    assert np.max(np.abs(sampled - want)) <= 1e-12 * np.max(np.abs(want))

    # reaction: the receiving cell's box contains the centre, else it is the nearest fluid cell
    P = grid.centres()
    xf = np.arange(9) * 50e-6
    yf = np.arange(7) * 50e-6
    in_yarn = 0
    for e, p in enumerate(P):
        box = [int(np.clip(np.searchsorted(f, p[a], side="right") - 1, 0, len(f) - 2))
               for a, f in enumerate((xf, yf, zf))]
        if fluid[tuple(box)]:
            c = target[e]
            assert tuple(ijk[c]) == tuple(box), (e, p)
        else:
            in_yarn += 1
            d = np.linalg.norm(C - p, axis=1)
            assert d[target[e]] == d.min()
    assert in_yarn > 0  # the test covers centres in removed cells
    F = rng.normal(size=(len(P), 3))
    out = np.zeros((len(C), 3))
    np.add.at(out, target, F)
    np.testing.assert_allclose(out.sum(axis=0), F.sum(axis=0), rtol=0, atol=1e-13 * np.abs(F).sum())

    # the file has the documented layout (coupling/layer/exchange_map.h)
    path = tmp_path / "map"
    write_exchange_map(path, grid, len(C), cells, weights, target)
    raw = path.read_bytes()
    assert raw[:8] == b"FFXMAP1\n"
    assert struct.unpack("<3q", raw[8:32]) == g.shape
    assert len(raw) == 88 + len(P) * (8 * 8 + 8 * 8) + 8 * len(P)
    assert not (tmp_path / "map.tmp").exists()


def test_coupling_section_validation() -> None:
    """coupling fields: ranges, only-with-two_way, and the interval that must divide a check."""
    def scene(coupling: dict[str, object]):  # type: ignore[no-untyped-def]
        data = yaml.safe_load(yaml.safe_dump(BASE))
        data["coupling"] = coupling
        return parse_scene(data, "c.yaml")

    for bad, field in (({"interval": 5}, "coupling.interval"),
                       ({"mode": "one_way", "reaction": "off"}, "coupling.reaction"),
                       ({"mode": "two_way", "interval": 0}, "coupling.interval"),
                       ({"mode": "two_way", "timeout_s": 0.0}, "coupling.timeout_s"),
                       ({"mode": "two_way", "fluid_ranks": 0}, "coupling.fluid_ranks"),
                       ({"mode": "two_way", "fluid_ranks": 1.5}, "coupling.fluid_ranks"),
                       ({"mode": "one_way", "fluid_ranks": 2}, "coupling.fluid_ranks"),
                       ({"mode": "three_way"}, "coupling.mode")):
        with pytest.raises(SceneError) as err:
            scene(bad)
        assert any(field in p for p in err.value.problems), err.value.problems
    assert scene({"mode": "one_way"}).coupling.mode == "one_way"
    assert scene({"mode": "two_way", "fluid_ranks": 3}).coupling.fluid_ranks == 3
    # 5000 steps per check (5e-4 s / 1e-7 s): 300 does not divide them, 250 does
    problems = Laydown().check_scene(scene({"mode": "two_way", "interval": 300}))
    assert any("coupling.interval = 300" in p for p in problems), problems
    assert not Laydown().check_scene(scene({"mode": "two_way", "interval": 250}))
