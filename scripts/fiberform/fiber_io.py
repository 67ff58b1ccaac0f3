# SPDX-License-Identifier: GPL-3.0-or-later
"""Fiber chains on disk for ``fix fiber/beam``: the LIGGGHTS data file and the nodes file.

A fiber is a chain of ``n`` nodes with positions ``x`` (n, 3) in m, cross-section frames as unit
quaternions ``q`` (n, 4) ordered (w, x, y, z) with ``t_I = R(q) e_I`` (t3 the tangent), and section
radii ``radii`` (n, 4) = (a1, a2, b1, b2) in m (outer and inner semi-axes along t1 and t2,
thesis sec. 3.4).

Files (format: docs/styles/fix_fiber_beam.md):

* data file (``read_data``, ``atom_style sphere``): ``atom-ID type diameter density x y z``, one
  atom per node, the nodes of a fiber with consecutive IDs (node 0 first). The diameter is
  ``2 max(a1, a2)`` (the contact envelope); the mass is reset by fix fiber/beam from the section.
* nodes file (``fix fiber/beam ... nodes FILE``):
  ``atom-ID fiber-ID node-index node-count a1 a2 b1 b2 x0 y0 z0 q0w q0x q0y q0z [qw qx qy qz]``
  with the stress-free reference (x0, q0) and optionally a different initial frame q.

All numbers are written with ``repr`` (shortest round-trip text), so a reference written here and
the initial positions in the data file agree to the last bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .inputs import STAR, LiggghtsInput, Token, file_token

__all__ = [
    "DATA_NAME",
    "NODES_NAME",
    "Fiber",
    "fiber_preamble",
    "outer_half_axes",
    "write_nodes_subset",
    "quat_from_frames",
    "quat_rotate",
    "quat_to_frames",
    "read_nodes_file",
    "write_fibers_liggghts",
]

#: the generated fibers' data and nodes files (stage generate's folder; copied into the working
#: folders of the stages that run them)
DATA_NAME = "fibers.data"
NODES_NAME = "fibers.nodes"

Array = npt.NDArray[np.float64]


def outer_half_axes(cross_section: str, w: float, aspect: float = 0.25) -> tuple[float, float]:
    """Nominal outer semi-axes (a1, a2) [m] of a generated section (thesis sec. 3.4), before the
    per-node jitter: ``w`` is the thesis' w [m] (the outer radius of a circular section, half the
    scene's ``fibers.width_m``); circular a1 = a2 = w; collapsed ("rectangular") a1 = 0.8 w,
    a2 = a1 ``aspect`` (``fibers.thickness_m / fibers.width_m``; the thesis' 0.2 w for 1/4)."""
    if cross_section == "circular":
        return w, w
    return 0.8 * w, 0.8 * w * aspect


@dataclass
class Fiber:
    """One fiber: reference (stress-free) nodes; ``x_init``/``q_init`` optionally a different
    initial state (tests start deformed from a straight reference)."""

    x: Array  # (n, 3) m
    q: Array  # (n, 4) unit quaternions (w, x, y, z)
    radii: Array  # (n, 4) a1, a2, b1, b2 in m
    x_init: Array | None = None
    q_init: Array | None = None

    @property
    def n(self) -> int:
        return int(self.x.shape[0])


def quat_from_frames(t1: Array, t2: Array, t3: Array) -> Array:
    """Unit quaternions (w, x, y, z) of rotation matrices with columns t1, t2, t3 (each (n, 3))."""
    t1, t2, t3 = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (t1, t2, t3))
    m = np.stack([t1, t2, t3], axis=-1)  # (n, 3, 3), columns
    out = np.empty((m.shape[0], 4))
    for k, r in enumerate(m):
        tr = r[0, 0] + r[1, 1] + r[2, 2]
        if tr > 0:
            s = 2.0 * math.sqrt(tr + 1.0)
            q = (0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s)
        elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
            s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
            q = ((r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s)
        elif r[1, 1] > r[2, 2]:
            s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
            q = ((r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s)
        else:
            s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
            q = ((r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s)
        qa = np.array(q)
        out[k] = qa / np.linalg.norm(qa)
    return out


def quat_rotate(q: Array, v: Array) -> Array:
    """R(q) v for arrays of quaternions (n, 4) and vectors (n, 3) or (3,)."""
    q = np.atleast_2d(q)
    v = np.broadcast_to(np.asarray(v, dtype=float), (q.shape[0], 3))
    w, u = q[:, :1], q[:, 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_frames(q: Array) -> tuple[Array, Array, Array]:
    """(t1, t2, t3), each (n, 3), of quaternions (n, 4)."""
    e = np.eye(3)
    return quat_rotate(q, e[0]), quat_rotate(q, e[1]), quat_rotate(q, e[2])


def _r(x: float) -> str:
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"refusing to write a non-finite number {x!r}")
    return repr(x)


def write_fibers_liggghts(
    data_path: Path,
    nodes_path: Path,
    fibers: Sequence[Fiber],
    box_lo: Sequence[float],
    box_hi: Sequence[float],
    *,
    density_kg_m3: float = 1500.0,
    atom_type: int = 1,
    first_fiber_id: int = 1,
    title: str = "fiberform fibers (fix fiber/beam)",
) -> int:
    """Write the data file and nodes file; returns the number of atoms. Atom IDs start at 1."""
    data = [f"# {title}", ""]
    natoms = sum(f.n for f in fibers)
    data += [f"{natoms} atoms", "1 atom types", ""]
    for k, ax in enumerate("xyz"):
        data.append(f"{_r(box_lo[k])} {_r(box_hi[k])} {ax}lo {ax}hi")
    data += ["", "Atoms", ""]
    nodes = [
        "# fix fiber/beam nodes file: atom-ID fiber-ID node-index node-count a1 a2 b1 b2 "
        "x0 y0 z0 q0w q0x q0y q0z [qw qx qy qz]   (SI units)"
    ]
    tag = 0
    for fi, f in enumerate(fibers):
        if f.n < 2:
            raise ValueError("a fiber needs at least 2 nodes")
        xi = f.x if f.x_init is None else f.x_init
        qi = f.q if f.q_init is None else f.q_init
        for k in range(f.n):
            tag += 1
            a1, a2, b1, b2 = (float(v) for v in f.radii[k])
            diam = 2.0 * max(a1, a2)
            data.append(
                f"{tag} {atom_type} {_r(diam)} {_r(density_kg_m3)} "
                f"{_r(xi[k, 0])} {_r(xi[k, 1])} {_r(xi[k, 2])}"
            )
            vals = [a1, a2, b1, b2, *f.x[k], *f.q[k]]
            line = f"{tag} {first_fiber_id + fi} {k} {f.n} " + " ".join(_r(v) for v in vals)
            if f.q_init is not None:
                line += " " + " ".join(_r(v) for v in qi[k])
            nodes.append(line)
    Path(data_path).write_text("\n".join(data) + "\n")
    Path(nodes_path).write_text("\n".join(nodes) + "\n")
    return natoms


def read_nodes_file(path: Path) -> npt.NDArray[np.float64]:
    """The nodes file as an array (rows: atom-ID fiber-ID index count a1 a2 b1 b2 x0 y0 z0 q0...)."""
    rows = []
    for line in Path(path).read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            rows.append([float(v) for v in line.split()])
    width = max(len(r) for r in rows)
    return np.array([r + [math.nan] * (width - len(r)) for r in rows])


def fibers_in_nodes(path: Path) -> set[int]:
    """0-based indices of the fibers a nodes file lists (its fiber-ID column is 1-based)."""
    return {int(body[1]) - 1 for line in Path(path).read_text().splitlines()
            if (body := line.split("#", 1)[0].split())}


def write_nodes_subset(src: Path, dst: Path, fiber_ids: Sequence[int]) -> int:
    """Copy the nodes file ``src`` to ``dst`` keeping only the fibers whose 0-based index is in
    ``fiber_ids`` (the nodes file's fiber-ID column is 1-based), comments kept: the fibers left in
    a restart file after the lay-down removed some (fix fiber/beam wants every listed atom).
    Returns the number of node lines written."""
    keep = {int(k) + 1 for k in fiber_ids}
    out, count = [], 0
    for line in Path(src).read_text().splitlines():
        body = line.split("#", 1)[0].split()
        if body and int(body[1]) not in keep:
            continue
        count += bool(body)
        out.append(line)
    Path(dst).write_text("\n".join(out) + "\n")
    return count


def laydown_beam_options(ld: Any) -> tuple[object, ...]:
    """The fix fiber/beam keywords of a scene's laydown section (the lay-down and the press both
    integrate the fibers with them); ``anderson``, ``landing`` and ``split_memory`` only when
    not at their defaults, so that inputs without them stay as they were."""
    return ("inertia_scale", ld.inertia_scale, "stiffness_scale", ld.stiffness_scale,
            "damping", ld.damping_time_s, "integrator", ld.beam_integrator,
            "rho_inf", ld.rho_inf, "newton_tol", ld.newton_tolerance,
            "newton_max", ld.newton_max_iterations, "tangent_steps", ld.tangent_steps,
            *(("anderson", ld.anderson_depth) if ld.anderson_depth else ()),
            *(("landing", ld.newton_landing) if ld.newton_landing != "limit" else ()),
            *(("split_memory", ld.split_memory_steps) if ld.split_memory_steps else ()))


def fiber_preamble(s: LiggghtsInput, f: Any, newton: bool, *beam_options: object,
                   restart: Token | None = None, flat_decomposition: bool = False,
                   periodic_xy: bool = False) -> None:
    """The LIGGGHTS commands that load the generated fibers (DATA_NAME, NODES_NAME in the working
    folder) under fix fiber/beam with ID ``beam``; ``beam_options`` are appended to that fix.
    With ``restart`` (a restart file of an earlier run of the same input) the atoms, the box and
    the per-atom state of fix fiber/beam come from that file instead of DATA_NAME (units, atom
    style, boundary and newton are stored in it). ``flat_decomposition``: MPI ranks split the box
    in x and y only (a sheet is a thin layer: a split in z would leave it on one rank).
    ``periodic_xy``: ``boundary p p f`` (laydown.walls periodic) instead of ``f f f``; read_data
    maps nodes outside the box in x or y into it and keeps their image flags, so the unwrapped
    positions (dump ``xu yu zu``) continue the chains as written."""
    s.command("units", "si")
    if flat_decomposition:
        s.command("processors", STAR, STAR, 1)
    if restart is None:
        s.command("atom_style", "sphere")
    s.command("atom_modify", "map", "array", "sort", 0, 0.0)
    if restart is None:
        s.command("boundary", *(("p", "p", "f") if periodic_xy else ("f", "f", "f")))
        s.command("newton", "on" if newton else "off")
        s.command("communicate", "single", "vel", "yes")
        s.command("read_data", file_token(DATA_NAME))
    else:
        s.command("read_restart", restart)
        s.command("communicate", "single", "vel", "yes")
    s.command("neighbor", 0.1 * f.width_m, "bin")
    s.command("neigh_modify", "delay", 0)
    s.command("fix", "beam", "all", "fiber/beam", "nodes", file_token(NODES_NAME),
              "E", f.youngs_modulus_Pa, "G", f.shear_modulus_Pa, "density", f.density_kg_m3,
              *beam_options)
