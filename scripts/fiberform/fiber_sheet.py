# SPDX-License-Identifier: GPL-3.0-or-later
"""Shared machinery of the stages that simulate the sheet of fibers on the fabric in LIGGGHTS
(``laydown``, ``press``): the contact commands (yarns, side planes, fiber-fiber pair style), the
yarn file, the sheet's geometric measures (gaps, clearances, thickness, thickness above the
fabric, solid fraction) and its pictures. Stages import this module, never each other
(docs/stages/pipeline.md).

Periodic lateral boundaries (``laydown.walls: periodic``): the box [0, Lx] x [0, Ly] is periodic
in x and y (:func:`lateral_period`); the yarns are tiled over the box's neighbouring images
(:func:`tile_yarns`); the node dump holds the unwrapped positions ``xu yu zu``, so the chains
are continuous and may reach up to a fiber length out of the box; consumers that clip to the box
take the chains' images that reach into it (:func:`periodic_images`), node measures wrap the
nodes into the box (:func:`wrap_points`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .fabric_geometry import segment_closest_differences, segment_distances
from .fiber_io import quat_rotate
from .inputs import STAR, LiggghtsInput, Token, dump_format, file_token, fix_ref, ident_list
from .products import (
    FIBERS_H5, Chain, Yarns, read_fiber_outer_axes, read_sheet_chains, read_yarns, sheet_chains,
)
from .scene import FluidSection, Scene

Array = npt.NDArray[np.float64]

# fix wall/gran material (stock Hertz model): soft enough for the fiber time step, frictionless as
# the yarns; one atom type
WALL_GRAN_MATERIAL: tuple[tuple[str, str, tuple[object, ...]], ...] = (
    ("wallmat1", "youngsModulus", ("peratomtype", 1.0e7)),
    ("wallmat2", "poissonsRatio", ("peratomtype", 0.3)),
    ("wallmat3", "coefficientRestitution", ("peratomtypepair", 1, 0.5)),
    ("wallmat4", "coefficientFriction", ("peratomtypepair", 1, 0.0)),
)


def contact_integrator_words(ld: Any) -> list[object]:
    """The yarn/wall contact integrator keywords of fix wall/fiber/yarns and fix wall/fiber/dlvo
    (the contact keywords of pair_style fiber/dlvo): `integrator cvode` or `integrator substep N`."""
    if ld.contact_integrator == "cvode":
        return ["integrator", "cvode"]
    return ["integrator", "substep", ld.contact_substeps]


def law_words(scene: Scene, *, steric_cap_m: float | None = None) -> list[object]:
    """The contact law's parameters from the scene, the same for every body the fibers touch
    (fibers: pair_style fiber/dlvo; yarns, side planes, press plate: the fixes): the fluid's
    temperature (kT and the Debye length) and the contact section's Hamaker constant, ionic
    strength, surface potential and cut-off; an absent one keeps the law's default
    (docs/models/contact.md). ``steric_cap_m``: the steric servo's saturation h_cap (m; the press
    stage's ``press.steric_cap_m``), absent: the law's default."""
    fl = scene.fluid or FluidSection()
    out: list[object] = ["temperature", fl.temperature_K]
    c = scene.contact
    if c is not None:
        for word, value in (("hamaker", c.hamaker_J), ("ionic_strength", c.ionic_strength_mol_m3),
                            ("psi", c.surface_potential_V), ("h_cut", c.cutoff_m)):
            if value is not None:
                out += [word, value]
    if steric_cap_m is not None:
        out += ["h_cap", steric_cap_m]
    return out


def static_body_words(scene: Scene, *, steric_cap_m: float | None = None) -> list[object]:
    """The keywords that make yarns (and the ``fiber_yarns`` side planes) act as the laydown
    section sets them: law terms and parameters (:func:`law_words`), integrator, implicit_force
    mode, Coulomb friction (and its stick damping inside the Newton solve); ``steric_cap_m`` as
    in :func:`law_words`."""
    ld = scene.laydown
    assert ld is not None
    newton = ld.yarn_contact_mode == "newton"
    words: list[object] = ["terms", ident_list(ld.terms), *law_words(scene, steric_cap_m=steric_cap_m),
                           *contact_integrator_words(ld),
                           "implicit_force", "newton" if newton else "impulse",
                           "friction", ld.friction_coefficient]
    if newton and ld.friction_coefficient > 0.0:
        words += ["friction_stick", ld.friction_stick]
    return words


def pair_options(scene: Scene, mode: str = "averaged", *, steric_cap_m: float | None = None) -> list[object]:
    """pair_style fiber/dlvo keywords from the scene's contact section; mode: laydown.fiber_contact
    (newton: the contacts inside the fibers' Newton solves, no sub-integration keywords); with
    ``laydown.fiber_friction_coefficient`` > 0 the fiber-fiber friction and its stick factor;
    ``steric_cap_m`` as in :func:`law_words`."""
    c = scene.contact
    assert c is not None
    out: list[object]
    if mode == "newton":
        out = ["implicit_force", "newton"]
    else:
        out = ["integrator", c.integrator]
        if c.integrator == "substep":
            out.append(c.substeps)
    out += ["terms", ident_list(c.terms), *law_words(scene, steric_cap_m=steric_cap_m)]
    if c.points_per_element is not None and mode != "newton":
        out += ["points", c.points_per_element]
    ld = scene.laydown
    if ld is not None and ld.fiber_friction_coefficient > 0.0:  # (validated: fiber_contact newton)
        out += ["friction", ld.fiber_friction_coefficient, "friction_stick", ld.friction_stick]
    return out


def side_planes(scene: Scene) -> list[tuple[float, ...]]:
    """The four vertical side planes of the domain: point x, y, z and inward normal."""
    dom = scene.domain
    assert dom is not None
    lo, hi = dom.lo_m, dom.hi_m
    return [
        (lo[0], 0.0, 0.0, 1.0, 0.0, 0.0), (hi[0], 0.0, 0.0, -1.0, 0.0, 0.0),
        (0.0, lo[1], 0.0, 0.0, 1.0, 0.0), (0.0, hi[1], 0.0, 0.0, -1.0, 0.0),
    ]


#: IDs of the generated fixes: the yarns (fix wall/fiber/yarns) and the side planes
YARNS_FIX = "yarns"
SIDE_WALL_IDS = ("wall0", "wall1", "wall2", "wall3")


def lateral_period(scene: Scene) -> tuple[float, float] | None:
    """(Lx, Ly), m: the periods of the box in x and y with ``laydown.walls: periodic`` (the
    domain's x and y extent, which is the fabric piece, from 0); None with side planes."""
    ld, dom = scene.laydown, scene.domain
    if ld is None or ld.walls != "periodic" or dom is None:
        return None
    return (dom.hi_m[0] - dom.lo_m[0], dom.hi_m[1] - dom.lo_m[1])


def contact_commands(s: LiggghtsInput, scene: Scene, yarns_file: str, *,
                     steric_cap_m: float | None = None) -> None:
    """The sheet's contacts, as the laydown section sets them: the four side planes (``walls``;
    ``fiber_yarns``: fix wall/fiber/dlvo acting as the yarns do; ``periodic``: none), fix
    wall/fiber/yarns on the yarns of ``yarns_file`` (periodic: the tiled yarns, :func:`write_yarns`)
    and, with a contact section, pair_style fiber/dlvo between fibers; ``steric_cap_m`` (the
    press's) reaches every one of them (:func:`law_words`)."""
    ld = scene.laydown
    assert ld is not None
    planes = side_planes(scene)
    if ld.walls == "periodic":  # boundary p p f (fiber_preamble): no side planes
        pass
    elif ld.walls == "fiber_yarns":  # the yarns' law, mode and friction (docs/stages/laydown.md)
        for k, p in enumerate(planes):
            s.command("fix", SIDE_WALL_IDS[k], "all", "wall/fiber/dlvo", "plane", *p,
                      *static_body_words(scene, steric_cap_m=steric_cap_m))
    elif ld.walls == "wall_gran":  # stock LIGGGHTS granular walls (comparison option)
        for name, style, value in WALL_GRAN_MATERIAL:
            s.command("fix", name, "all", "property/global", style, *value)
        for k, p in enumerate(planes):
            axis = "xplane" if p[3] != 0.0 else "yplane"
            s.command("fix", SIDE_WALL_IDS[k], "all", "wall/gran", "model", "hertz", "tangential",
                      "no_history", "primitive", "type", 1, axis, p[0] if p[3] != 0.0 else p[1])
    else:  # the contact styles' own wall fix, one per plane
        for k, p in enumerate(planes):
            s.command("fix", SIDE_WALL_IDS[k], "all", "wall/fiber/dlvo", "plane", *p, "terms",
                      ident_list(ld.terms), *law_words(scene, steric_cap_m=steric_cap_m),
                      *contact_integrator_words(ld))
    s.command("fix", YARNS_FIX, "all", "wall/fiber/yarns", "yarns", file_token(yarns_file),
              *static_body_words(scene, steric_cap_m=steric_cap_m))
    c = scene.contact
    if c is not None and c.model == "fiber_dlvo":  # fiber-fiber contact (thesis sec. 2.4)
        s.command("pair_style", "fiber/dlvo", *pair_options(scene, ld.fiber_contact_mode, steric_cap_m=steric_cap_m))
        s.command("pair_coeff", STAR, STAR)


def static_force_refs(scene: Scene) -> list[tuple[str, int]]:
    """(fix ID, vector index) of the x components of the static bodies' contact force on the
    fibers (N; implicit_force newton): the yarns and, with ``walls: fiber_yarns``, the side planes
    (y, z: the next two indices)."""
    ld = scene.laydown
    assert ld is not None
    sides = [(w, 7) for w in SIDE_WALL_IDS] if ld.walls == "fiber_yarns" else []
    return [(YARNS_FIX, 4), *sides]


def write_yarns(path: Path, fabric_h5: Path, period: tuple[float, float] | None = None) -> Yarns:
    """The fabric's yarn centrelines as fix wall/fiber/yarns reads them: ``yarn x y z radius``; returns
    the yarns written: those of fabric.h5 (products.read_yarns) or, with ``period`` (Lx, Ly) in m
    (:func:`lateral_period`), the yarns tiled over the periodic box and its neighbours
    (:func:`tile_yarns`)."""
    yarns = contact_yarns(read_yarns(fabric_h5), period)
    pts, offs, rad = yarns.points, yarns.offsets, yarns.radius
    with open(path, "w") as fh:
        fh.write("# yarn-index x y z radius (m), from fabric.h5 /yarns"
                 + (" tiled over the periodic box and its 8 neighbours\n" if period is not None else "\n"))
        for k in range(len(rad)):
            for p in pts[offs[k]:offs[k + 1]]:
                fh.write(f"{k} {float(p[0])!r} {float(p[1])!r} {float(p[2])!r} {float(rad[k])!r}\n")
    return yarns


def contact_yarns(yarns: Yarns, period: tuple[float, float] | None) -> Yarns:
    """The yarns as fix wall/fiber/yarns has them (:func:`write_yarns`): ``yarns`` themselves, or
    with ``period`` (Lx, Ly; :func:`lateral_period`) tiled over the periodic box and its neighbours
    (:func:`tile_yarns`)."""
    return yarns if period is None else tile_yarns(yarns, period)


def tile_yarns(yarns: Yarns, period: tuple[float, float]) -> Yarns:
    """The yarns of a generated fabric of whole weave repeats (fabric.size_x_m, size_y_m =
    ``period`` (Lx, Ly), m, the box from 0) tiled over the box and its 8 neighbouring periodic
    images, m. A yarn runs along x (a warp) or y (a weft), whichever its centre line spans more;
    the yarns whose centre line lies across in [0, L) (the other axis) are the box's own, the others
    (the generator's yarns reaching into the piece from outside) are their images and dropped.
    Each own yarn is cut at 0 and L along its direction (points interpolated on its polyline) and
    its three copies shifted by -L, 0, +L along it are joined into ONE chain over [-L, 2L] (fix
    wall/fiber/yarns takes the closest segment per yarn, so a joint is no second contact); that
    chain is repeated at -L, 0, +L across (distinct yarn indices). Raises ValueError if a yarn does
    not cover [0, L] with increasing coordinates or its ends at 0 and L differ by more than
    1e-9 L (the fabric is not periodic: not whole weave repeats)."""
    pts, offs, rad = yarns.points, yarns.offsets, yarns.radius
    out_pts: list[Array] = []
    out_rad: list[float] = []
    for k in range(len(rad)):
        p = pts[offs[k]:offs[k + 1]]
        span = np.ptp(p[:, :2], axis=0)
        a = 0 if span[0] >= span[1] else 1  # along the yarn
        b = 1 - a  # across
        if not 0.0 <= float(np.mean(p[:, b])) < period[b]:
            continue  # an image of one of the box's yarns
        s, length = p[:, a], period[a]
        if np.any(np.diff(s) <= 0.0) or s[0] > 0.0 or s[-1] < length:
            raise ValueError(f"yarn {k}: its centre line does not run across the periodic box "
                             f"[0, {length!r}] m along {'xy'[a]} with increasing coordinates")
        ends = np.array([[np.interp(v, s, p[:, j]) for j in range(3)] for v in (0.0, length)])
        ends[0, a], ends[1, a] = 0.0, length
        piece = np.vstack([ends[:1], p[(s > 0.0) & (s < length)], ends[1:]])
        along = np.zeros(3)
        along[a] = length
        if float(np.max(np.abs(piece[-1] - along - piece[0]))) > 1e-9 * length:
            raise ValueError(f"yarn {k}: its ends at {'xy'[a]} = 0 and {length!r} m differ: the "
                             "fabric is not periodic (not whole weave repeats)")
        chain = np.vstack([piece[:-1] - along, piece[:-1], piece + along])
        across = np.zeros(3)
        across[b] = period[b]
        for shift in (-1.0, 0.0, 1.0):
            out_pts.append(chain + shift * across)
            out_rad.append(float(rad[k]))
    counts = [len(c) for c in out_pts]
    return Yarns(np.vstack(out_pts) if out_pts else np.zeros((0, 3)),
                 np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
                 np.array(out_rad, dtype=np.float64))


def periodic_images(x: Array, offsets: npt.NDArray[Any], period: Sequence[float], margin: float = 0.0
                    ) -> tuple[Array, npt.NDArray[np.int64], npt.NDArray[np.int64], Array]:
    """The copies of the chains (nodes ``x`` (n, 3), m; chain k owns x[offsets[k]:offsets[k+1]])
    shifted by whole periods in x and y that reach into the box [0, Lx] x [0, Ly] grown by
    ``margin`` (m): for the consumers that clip a periodic sheet (unwrapped chains, up to a fiber
    length out of the box) to the box. ``period`` (Lx, Ly), m; 0 for an axis that is not periodic
    (no shifts along it). A chain inside the box gives itself; one across a side gives itself and
    the image on the other side. Returns (the copies' nodes, their offsets, the chain each copy
    is of, each copy's shift (c, 3), m), copies by chain, then by shift in x, then y."""
    out: list[Array] = []
    src: list[int] = []
    shifts: list[Array] = []
    for k in range(len(offsets) - 1):
        c = x[offsets[k]:offsets[k + 1]]
        if len(c) == 0:
            continue
        ranges = []
        for axis in (0, 1):
            length = float(period[axis])
            if length <= 0.0:
                ranges.append([0])
                continue
            lo, hi = float(c[:, axis].min()), float(c[:, axis].max())
            ranges.append(list(range(math.ceil((-margin - hi) / length),
                                     math.floor((length + margin - lo) / length) + 1)))
        for i in ranges[0]:
            for j in ranges[1]:
                d = np.array([i * float(period[0]), j * float(period[1]), 0.0])
                out.append(c + d)
                src.append(k)
                shifts.append(d)
    counts = [len(c) for c in out]
    return (np.vstack(out) if out else np.zeros((0, 3)),
            np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            np.array(src, dtype=np.int64), np.array(shifts).reshape(-1, 3))


def wrap_points(x: Array, period: Sequence[float] | None) -> Array:
    """The points ``x`` (n, 3), m, mapped into the periodic box [0, Lx) x [0, Ly) (each on its
    own: for node measures against :func:`tile_yarns`); unchanged without ``period``."""
    if period is None:
        return x
    out = np.array(x, dtype=np.float64, copy=True)
    for axis in (0, 1):
        if period[axis] > 0.0:
            out[:, axis] = np.mod(out[:, axis], period[axis])
    return out


def wrap_chains(x: Array, offsets: npt.NDArray[Any], period: Sequence[float] | None) -> Array:
    """The chains (nodes ``x`` (n, 3), m, by ``offsets``) each shifted by whole periods so that its
    first node lies in the box [0, Lx) x [0, Ly) (a chain stays continuous: for element measures
    against :func:`tile_yarns`, whose yarns cover one period around the box); unchanged without
    ``period``."""
    if period is None:
        return x
    out = np.array(x, dtype=np.float64, copy=True)
    for lo, hi in zip(offsets[:-1], offsets[1:]):
        if hi <= lo:
            continue
        for axis in (0, 1):
            if period[axis] > 0.0:
                out[lo:hi, axis] -= math.floor(out[lo, axis] / period[axis]) * period[axis]
    return out


def yarn_distances(x: Array, pts: Array, offs: Array, rad: Array) -> Array:
    """For each point of x (n, 3): min over yarns of (distance to the centreline - radius), m."""
    a, b, r = _yarn_segments(pts, offs, rad)
    out = np.full(len(x), np.inf)
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    for i, p in enumerate(x):
        t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        dist = np.linalg.norm(p - (a + t[:, None] * d), axis=1) - r
        out[i] = float(dist.min())
    return out


def _yarn_segments(pts: Array, offs: Array, rad: Array) -> tuple[Array, Array, Array]:
    a = np.vstack([pts[offs[k]:offs[k + 1] - 1] for k in range(len(rad))])
    b = np.vstack([pts[offs[k] + 1:offs[k + 1]] for k in range(len(rad))])
    r = np.concatenate([np.full(offs[k + 1] - offs[k] - 1, rad[k]) for k in range(len(rad))])
    return a, b, r


def _near_pairs(m1: Array, m2: Array | None, reach: float,
                period: Sequence[float] | None = None) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Index pairs (i, j) of points ``m1`` (n, 3) and ``m2`` (m, 3) at most ``reach`` apart (m),
    from a k-d tree (scipy.spatial.cKDTree); ``m2`` None: pairs i < j within ``m1``. ``period``
    (Lx, Ly): x and y periodic (minimal image), z not."""
    from scipy.spatial import cKDTree

    pts = [np.asarray(m1, dtype=np.float64)] + ([] if m2 is None else [np.asarray(m2, dtype=np.float64)])
    box = None
    if period is not None and (period[0] > 0.0 or period[1] > 0.0):
        allp = np.vstack(pts)
        lo, span = allp.min(axis=0), np.ptp(allp, axis=0)
        big = 4.0 * (float(span.max()) + reach) + 1.0  # a period no pair reaches across
        size = np.array([period[0] if period[0] > 0.0 else big, period[1] if period[1] > 0.0 else big, big])
        periodic = np.array([period[0] > 0.0, period[1] > 0.0, False])
        pts = [np.where(periodic, np.mod(q, size), q - lo) for q in pts]
        pts = [np.minimum(q, np.nextafter(size, 0.0)) for q in pts]  # mod may round up to size
        box = size
    t1 = cKDTree(pts[0], boxsize=box)
    if m2 is None:
        pairs = t1.query_pairs(reach, output_type="ndarray").astype(np.int64)
        return pairs[:, 0], pairs[:, 1]
    t2 = cKDTree(pts[1], boxsize=box)
    d = t1.sparse_distance_matrix(t2, reach, output_type="ndarray")
    return d["i"].astype(np.int64), d["j"].astype(np.int64)


def _shift_to_nearest(mid_i: Array, mid_j: Array, period: Sequence[float] | None) -> Array:
    """(n, 3): the whole-period shifts in x and y that bring points ``mid_j`` to their images
    closest to ``mid_i`` (rows pairwise); zeros without ``period`` (and along an axis of period 0)."""
    out = np.zeros_like(mid_j)
    if period is None:
        return out
    diff = mid_j - mid_i
    for axis in (0, 1):
        if period[axis] > 0.0:
            out[:, axis] = -np.round(diff[:, axis] / period[axis]) * period[axis]
    return out


def _growing_search(start: float, limit: float, pairs_min: Callable[[float], float]) -> float:
    """The smallest value over pairs of a k-d tree search with a growing radius: ``pairs_min(c)``
    returns the smallest value over the pairs close enough to hold any pair of value <= c (the
    caller's reach: its length bound + c), or inf; that is the minimum over all pairs once it is
    <= c. c starts at ``start`` and grows 4-fold up to ``limit`` (a reach that holds every pair)."""
    c = start
    while True:
        best = pairs_min(c)
        if best <= c or c >= limit:
            return best
        c = min(4.0 * c, limit)


def element_clearance(x: Array, offsets: Array, pts: Array, offs: Array, rad: Array,
                      node_radius: Array | None = None) -> float:
    """Smallest (distance between a fiber element's centre line and a yarn segment's centre line -
    yarn radius) over all elements and yarn segments, m (< 0: a fiber centre line inside a yarn).
    ``node_radius`` (one per node of ``x``, m): each element's radius (its first node's) is taken
    off too, so the result is the smallest surface gap (< 0: a fiber reaching into a yarn by that
    much), element by element. Candidate pairs from a k-d tree of the segments' midpoints
    (:func:`_near_pairs`), with a search radius that grows until the smallest value is certain; the
    result equals the minimum over all pairs."""
    ends = [(offsets[k], offsets[k + 1]) for k in range(len(offsets) - 1)]
    idx = np.concatenate([np.arange(lo, hi - 1) for lo, hi in ends if hi - lo > 1] or
                         [np.zeros(0, dtype=np.int64)]).astype(np.int64)
    if len(idx) == 0:
        return math.inf
    a, b, r = _yarn_segments(pts, offs, rad)
    if len(r) == 0:
        return math.inf
    pe, qe = x[idx], x[idx + 1]
    re = np.zeros(len(idx)) if node_radius is None else np.asarray(node_radius, dtype=np.float64)[idx]
    me, ms = 0.5 * (pe + qe), 0.5 * (a + b)
    half = 0.5 * float(np.max(np.linalg.norm(qe - pe, axis=1))) + 0.5 * float(np.max(np.linalg.norm(b - a, axis=1)))
    # midpoints of a pair of value c lie within bound + c
    bound = half + float(np.max(r)) + float(np.max(re))
    allp = np.vstack([pe, qe, a, b])
    limit = float(np.linalg.norm(np.ptp(allp, axis=0))) + 1e-9

    def pairs_min(c: float) -> float:
        i, j = _near_pairs(me, ms, bound + max(c, 0.0))
        if len(i) == 0:
            return math.inf
        out = math.inf
        for k in np.array_split(np.arange(len(i)), max(1, len(i) // 200_000)):
            out = min(out, float(np.min(segment_distances(pe[i[k]], qe[i[k]], a[j[k]], b[j[k]])
                                        - r[j[k]] - re[i[k]])))
        return out

    return _growing_search(max(float(np.max(r)), 1e-9), limit, pairs_min)


def rect_extent(axis: Array, t2: Array, a1: Array, a2: Array, n: Array) -> Array:
    """Extent (m) of rectangular sections 2 ``a1`` x 2 ``a2`` from their centre line along the
    directions ``n``: where the line from the centre along n's part normal to the ``axis`` leaves
    the rectangle (thesis sec. 2.4.3: contact points moved along the line between the centre lines
    to the surfaces). Vectors (..., 3) and half-sides (...,) broadcast; ``axis`` unit; ``n`` unit
    (or zero); ``t2`` the direction of a2, not necessarily unit or normal to the axis: made normal
    to it and unit (a zero t2: z; a normal part of norm < 1e-8: x instead), a1 along
    t2 x axis. n's axial part is dropped; n along the axis (or zero) gives min(a1, a2). Between
    min(a1, a2) (a face) and hypot(a1, a2) (a corner). The C++ twin: contact_geometry.h
    ``rect_extent`` (with ``rect_thickness_dir``, ``rect_surface_distance``)."""
    axis, t2, n = (np.asarray(v, dtype=np.float64) for v in (axis, t2, n))
    a1, a2 = np.asarray(a1, dtype=np.float64), np.asarray(a2, dtype=np.float64)

    def normal_part(v: Array) -> Array:  # v minus its part along the axis
        return v - np.sum(v * axis, axis=-1, keepdims=True) * axis

    u = normal_part(n)
    lu = np.linalg.norm(u, axis=-1, keepdims=True)
    t2 = np.where(np.linalg.norm(t2, axis=-1, keepdims=True) > 0.0, t2, np.array([0.0, 0.0, 1.0]))
    e_t = normal_part(t2)  # contact_geometry.h rect_thickness_dir
    e_t = np.where(np.linalg.norm(e_t, axis=-1, keepdims=True) < 1e-8, normal_part(np.array([1.0, 0.0, 0.0])), e_t)
    e_t = e_t / np.linalg.norm(e_t, axis=-1, keepdims=True)
    e_w = np.cross(e_t, axis)
    u = u / np.where(lu > 1e-9, lu, 1.0)
    face = lu[..., 0] > 1e-9
    cw, ct = np.abs(np.sum(u * e_w, axis=-1)), np.abs(np.sum(u * e_t, axis=-1))
    with np.errstate(divide="ignore"):
        dw = np.where(cw > 0.0, a1 / np.where(cw > 0.0, cw, 1.0), math.inf)
        dt = np.where(ct > 0.0, a2 / np.where(ct > 0.0, ct, 1.0), math.inf)
    return np.asarray(np.where(face, np.minimum(dw, dt), np.minimum(a1, a2)))


def node_extents(axes: Array, q: Array, n: Array) -> Array:
    """Extent (m) of each node's contact section from its centre along the unit direction ``n``,
    in the node's own frame (axis t3 = R(q) e3, t2 = R(q) e2): a1 for a circle (``axes`` (n, 2)
    = a1, a2 with a1 == a2), the rectangle's :func:`rect_extent` for a collapsed fiber. The C++
    twin: static_bodies.h ``node_extent`` (planes: side walls, the press plate)."""
    axes = np.asarray(axes, dtype=np.float64)
    rect = axes[:, 0] != axes[:, 1]
    ext = rect_extent(quat_rotate(q, np.array([0.0, 0.0, 1.0])), quat_rotate(q, np.array([0.0, 1.0, 0.0])),
                      axes[:, 0], axes[:, 1], np.broadcast_to(np.asarray(n, dtype=np.float64), (len(axes), 3)))
    return np.asarray(np.where(rect, ext, axes[:, 0]))


def fiber_fiber_gap(x: Array, offsets: Array, radius: Array, axes: Array | None = None,
                    q: Array | None = None, period: Sequence[float] | None = None) -> float:
    """Smallest surface gap between elements of DIFFERENT fibers, m: |d| - e_A(n) - e_B(n), d the
    closest point of element A's centre line minus that of B's (parameters clamped to [0, 1]),
    n = d / |d|, e the element's section extent along n. Sections as the fibers' contacts inside
    the implicit step (physics/static_bodies.h ``element_extent``): without ``axes`` or for nodes
    with a1 == a2 a circle, the element's extent the larger of its nodes' ``radius`` (m, one per
    row of x); ``axes`` (n, 2): the nodes' outer half-axes (a1, a2), m (fibers.h5 radii); a node
    with a1 != a2 is a collapsed fiber's rectangle 2 a1 x 2 a2, a1 along the node frame's t1 and
    a2 along t2 = R(q) e2 (``q`` (n, 4): the nodes' unit quaternions w, x, y, z, from the dump,
    :func:`frame_quaternions`; required then). An element with a rectangular node is a rectangle
    about its chord with the larger a1 and a2 of its rectangular nodes and t2 the sum of its nodes'
    (:func:`rect_extent`); touching centre lines (|d| = 0) take min(a1, a2). The contact law keeps
    the gap above about -10 nm; below minus the radius (thickness) a centre line is inside another
    fiber (a pass-through). ``period`` (Lx, Ly), m (periodic x/y, unwrapped chains): each pair of
    elements at the image of B whose midpoint is closest to A's (exact for elements shorter than
    half a period). inf with fewer than two fibers.

    Candidate pairs come from a k-d tree of the element midpoints (:func:`_near_pairs`) with a
    search radius that grows until the smallest gap is certain (a pair of gap g has its
    midpoints within the two half-lengths + the two largest extents + g), so the result equals
    the minimum over all pairs at a cost that grows with the pairs in reach, not with their
    square (a thesis-scale sheet's 200 snapshots: 3500 elements each)."""
    owner = np.concatenate([np.full(max(0, hi - lo - 1), k) for k, (lo, hi) in
                            enumerate(zip(offsets[:-1], offsets[1:]))] or [np.zeros(0)]).astype(np.int64)
    idx = np.concatenate([np.arange(lo, hi - 1) for lo, hi in zip(offsets[:-1], offsets[1:])
                          if hi - lo > 1] or [np.zeros(0, dtype=np.int64)]).astype(np.int64)
    if len(idx) < 2 or len(np.unique(owner)) < 2:
        return math.inf
    r_el = np.maximum(radius[idx], radius[idx + 1])
    rect = (np.zeros((len(x), 2)) if axes is None
            else np.where((axes[:, 0] != axes[:, 1])[:, None], axes, 0.0))  # fix fiber/beam contact_rect
    is_rect = (rect[idx, 0] > 0.0) | (rect[idx + 1, 0] > 0.0)
    if np.any(is_rect) and q is None:
        raise ValueError("fiber_fiber_gap: rectangular sections need the node quaternions q")
    p0, p1 = x[idx], x[idx + 1]
    mid = 0.5 * (p0 + p1)
    a1, a2 = np.maximum(rect[idx, 0], rect[idx + 1, 0]), np.maximum(rect[idx, 1], rect[idx + 1, 1])
    chord = p1 - p0
    length = np.linalg.norm(chord, axis=1)
    hi_e = np.where(is_rect, np.hypot(a1, a2), r_el)  # the largest extent (a corner's; circles: r)
    axis = t2 = np.zeros_like(chord)
    if np.any(is_rect):
        assert q is not None
        e2 = np.array([0.0, 1.0, 0.0])
        t2 = quat_rotate(q[idx], e2) + quat_rotate(q[idx + 1], e2)
        axis = chord / np.where(length > 0.0, length, 1.0)[:, None]
        # a zero-length element: the frame of its (first) rectangular node (static_bodies.h node_extent)
        node = np.where(rect[idx, 0] > 0.0, idx, idx + 1)
        axis = np.where((length > 0.0)[:, None], axis, quat_rotate(q[node], np.array([0.0, 0.0, 1.0])))
        t2 = np.where((length > 0.0)[:, None], t2, quat_rotate(q[node], e2))

    def extent(k: npt.NDArray[np.int64], n: Array) -> Array:
        if not np.any(is_rect[k]):
            return r_el[k]
        return np.where(is_rect[k], rect_extent(axis[k], t2[k], a1[k], a2[k], n), r_el[k])

    bound = float(np.max(length)) + 2.0 * float(np.max(hi_e))
    if period is None:
        limit = float(np.linalg.norm(np.ptp(np.vstack([p0, p1]), axis=0))) + 1e-9
    else:
        limit = float(np.hypot(period[0], period[1])) + float(np.ptp(np.concatenate([p0[:, 2], p1[:, 2]]))) + 1e-9

    def pairs_min(c: float) -> float:
        i, j = _near_pairs(mid, None, bound + max(c, 0.0), period)
        keep = owner[i] != owner[j]
        i, j = i[keep], j[keep]
        if len(i) == 0:
            return math.inf
        out = math.inf
        for k in np.array_split(np.arange(len(i)), max(1, len(i) // 200_000)):
            ik, jk = i[k], j[k]
            sh = _shift_to_nearest(mid[ik], mid[jk], period)
            d = segment_closest_differences(p0[ik], p1[ik], p0[jk] + sh, p1[jk] + sh)
            dist = np.linalg.norm(d, axis=-1)
            n = d / np.where(dist > 0.0, dist, 1.0)[:, None]
            out = min(out, float(np.min(dist - extent(ik, n) - extent(jk, n))))
        return out

    return _growing_search(max(2.0 * float(np.max(hi_e)), 1e-9), limit, pairs_min)


#: the dump columns of fix fiber/beam's node quaternions (per-atom f_beam[4..7]: qw qx qy qz)
QUAT_COLUMNS = ("f_beam[4]", "f_beam[5]", "f_beam[6]", "f_beam[7]")


#: the dump columns of the node positions: as LIGGGHTS keeps them (in the box in periodic
#: directions) and unwrapped (periodic x/y: continuous chains)
POSITION_COLUMNS = ("x", "y", "z")
UNWRAPPED_COLUMNS = ("xu", "yu", "zu")


def node_dump_columns(f: Any, periodic: bool = False) -> tuple[list[object], Token]:
    """The columns of the stages' node dump (``dump ... custom``) and its ``dump_modify format``:
    id, mass, position (m; ``periodic`` (x/y): the unwrapped :data:`UNWRAPPED_COLUMNS`, so that
    the chains are continuous), velocity (m/s), fiber ID and node index (f_beam[1], f_beam[2]) and,
    for collapsed fibers (``fibers.cross_section`` rectangular), the node quaternions
    :data:`QUAT_COLUMNS` (the sections' orientation, for :func:`fiber_fiber_gap`)."""
    pos = UNWRAPPED_COLUMNS if periodic else POSITION_COLUMNS
    cols: list[object] = ["id", "mass", *pos, "vx", "vy", "vz", fix_ref("beam", 1), fix_ref("beam", 2)]
    if f.cross_section != "circular":
        cols += [fix_ref("beam", k) for k in range(4, 8)]
    return cols, dump_format(["int"] + ["float"] * (len(cols) - 1))


def position_columns(columns: Mapping[str, Any]) -> tuple[str, str, str]:
    """The position columns of a dump frame: the unwrapped ones if the dump has them (periodic
    x/y), else x y z."""
    return UNWRAPPED_COLUMNS if all(c in columns for c in UNWRAPPED_COLUMNS) else POSITION_COLUMNS


def frame_positions(columns: Mapping[str, Any]) -> Array:
    """Node positions (n, 3), m, of a dump frame in its row order (:func:`position_columns`)."""
    return np.stack([np.asarray(columns[c], dtype=np.float64) for c in position_columns(columns)], axis=1)


def _frame_order(columns: Mapping[str, Any]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """(fiber IDs 0-based, the order by fiber then node) of a dump frame's rows."""
    fid = np.rint(np.asarray(columns["f_beam[1]"])).astype(np.int64) - 1
    return fid, np.lexsort((np.rint(np.asarray(columns["f_beam[2]"])), fid))


def frame_quaternions(columns: Mapping[str, Any]) -> Array | None:
    """The node quaternions (n, 4: w, x, y, z) of a dump frame in the order of
    :func:`frame_fibers`; None if the dump has no :data:`QUAT_COLUMNS` (circular fibers)."""
    if not all(c in columns for c in QUAT_COLUMNS):
        return None
    _, order = _frame_order(columns)
    return np.stack([np.asarray(columns[c], dtype=np.float64)[order] for c in QUAT_COLUMNS], axis=1)


def frame_fibers(columns: Mapping[str, Any]) -> tuple[Array, Array, Array]:
    """Node positions of a dump frame ordered by fiber then node (unwrapped when the dump has
    ``xu yu zu``: :func:`position_columns`), with the fiber IDs (0-based) and the offsets of each
    fiber's nodes."""
    fid, order = _frame_order(columns)
    x = np.stack([np.asarray(columns[c])[order] for c in position_columns(columns)], axis=1)
    fids = fid[order]
    present, counts = np.unique(fids, return_counts=True)
    return x, present, np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def fiber_com_speeds(columns: Mapping[str, Any]) -> tuple[Array, Array]:
    """(mass kg, centre-of-mass speed m/s) of each fiber of a dump frame (ascending fiber ID)."""
    fid = np.rint(np.asarray(columns["f_beam[1]"])).astype(np.int64)
    m = np.asarray(columns["mass"], dtype=float)
    _, inv = np.unique(fid, return_inverse=True)
    msum = np.bincount(inv, weights=m)
    v = np.stack([np.bincount(inv, weights=m * np.asarray(columns[c])) for c in ("vx", "vy", "vz")], 1)
    return msum, np.linalg.norm(v / msum[:, None], axis=1)


def mass_fraction_speed(mass: Array, speed: Array, fraction: float = 1.0) -> float:
    """The speed below which the bodies carrying ``fraction`` of the mass move (m/s): the largest
    speed at fraction 1. The lay-down's settle measure of fix fiber/settle ``mass_fraction``
    (the C++ twin, physics/settle.h, decides the run; this one reports it)."""
    if fraction >= 1.0:
        return float(np.max(speed))
    order = np.argsort(speed, kind="stable")
    cum = np.cumsum(mass[order])
    k = min(int(np.searchsorted(cum, fraction * cum[-1])), len(order) - 1)
    return float(speed[order[k]])


def solid_fraction_profile(x: Array, offsets: Array, radius: Array, edges: Array,
                           area: float, samples: int = 4) -> Array:
    """Solid fraction of the fibers per height bin (``edges`` ascending, m): fiber volume in the
    bin / (bin height x ``area``). Each element is cut into ``samples`` pieces treated as
    horizontal cylinders of the element's radius (the larger of its nodes' ``radius``): a piece of
    length l at height z_c holds dV/dz = 2 l sqrt(r^2 - (z - z_c)^2), integrated over each bin
    exactly (inclined elements: their pieces follow the slope)."""
    out = np.zeros(len(edges) - 1)
    for lo, hi in zip(offsets[:-1], offsets[1:]):
        if hi - lo < 2:
            continue
        a, b = x[lo:hi - 1], x[lo + 1:hi]
        r = np.maximum(radius[lo:hi - 1], radius[lo + 1:hi])
        length = np.linalg.norm(b - a, axis=1) / samples
        for q in range(samples):
            zc = a[:, 2] + (q + 0.5) / samples * (b[:, 2] - a[:, 2])
            # volume of a horizontal cylinder below height z: l * (r^2 acos(-u) + r u sqrt(...)),
            # u = (z - zc) / r clipped to [-1, 1]; the bin's share is the difference at its edges
            u = np.clip((edges[None, :] - zc[:, None]) / r[:, None], -1.0, 1.0)
            below = length[:, None] * r[:, None] ** 2 * (np.arccos(-u) + u * np.sqrt(1.0 - u * u))
            out += np.sum(np.diff(below, axis=1), axis=0)
    return out / (np.diff(edges) * area)


def sheet_thickness(z: Array, diameter: float) -> float:
    """Thickness estimate of the sheet: the 5-95 % range of node heights plus one fiber diameter
    (robust against single fibers hanging in openings or lying on top)."""
    if len(z) == 0:
        return 0.0
    return float(np.percentile(z, 95) - np.percentile(z, 5) + diameter)


def upper_surfaces(chains: Sequence[Chain]) -> Array:
    """Height of the fibers' upper surface above each node, m: the node's z plus half its fiber's
    thickness (:attr:`Chain.thickness`: the diameter of a circular section, the thickness of a
    collapsed one, which lies flat), fiber by fiber (:func:`fiberform.products.sheet_chains`)."""
    parts = [c.points[:, 2] + 0.5 * c.thickness for c in chains]
    return np.concatenate(parts) if parts else np.zeros(0)


def thickness_above_fabric(z_top_of_material: Array, fabric_top_z: float, percentile: float = 95.0) -> float:
    """Thickness of the sheet above its fabric, m, as the experiments measure a sheet on top of
    its fabric (thesis Table 4.1: sheet 1, nearly bare, 0 um): the ``percentile`` of the heights
    of the fibers' upper surfaces (``z_top_of_material``, one per node: :func:`upper_surfaces`)
    minus the fabric top ``fabric_top_z`` (the highest yarn surface, m), clipped at 0 (a sheet
    sunk into the fabric's openings is 0 um thick above it; so is a sheet without fibers).

    Why the 95th percentile: like a caliper plate, which rests on the highest points of the sheet,
    but not on a single outlier: one fiber lying on top of the others, or bent up, owns a few % of
    the nodes and does not set it; the maximum (100) would. Fibers hanging into the fabric's
    openings lie below the fabric top and do not count (unlike the 5-95 % span of
    :func:`sheet_thickness`). Each node is one sample (node-weighted, not length-weighted)."""
    if len(z_top_of_material) == 0:
        return 0.0
    return max(0.0, float(np.percentile(z_top_of_material, percentile)) - fabric_top_z)


def _cross_section(scene: Scene) -> str:
    assert scene.fibers is not None
    return scene.fibers.cross_section


def sheet_thickness_above_fabric(scene: Scene, x: Array, offsets: npt.NDArray[np.int64],
                                 fiber_id: npt.NDArray[np.int64], fabric_top_z: float) -> float:
    """:func:`thickness_above_fabric` (95th percentile, m) of a sheet given as its ``/sheet``
    arrays (node positions, offsets, fiber IDs into fibers.h5), with the sections of the scene's
    ``fibers.h5`` (``fibers.cross_section``): for the stages' collect, before the product exists."""
    axes = read_fiber_outer_axes(scene.output_path / FIBERS_H5, fiber_id)
    return thickness_above_fabric(upper_surfaces(sheet_chains(x, offsets, axes, _cross_section(scene))),
                                  fabric_top_z)


def product_thickness_above_fabric(scene: Scene, sheet_h5: Path, fabric_top_z: float) -> float:
    """:func:`thickness_above_fabric` (95th percentile, m) of the ``/sheet`` of a ``laydown.h5`` or
    ``press.h5``, with the sections of the scene's ``fibers.h5`` (``fibers.cross_section``): from
    stored products only, so also for products written before the metric existed."""
    chains = read_sheet_chains(sheet_h5, scene.output_path / FIBERS_H5, _cross_section(scene))
    return thickness_above_fabric(upper_surfaces(chains), fabric_top_z)


def write_sheet_vtu(path: Path, x: Array, fiber: Array, offsets: Array) -> None:
    from pyevtk.hl import polyLinesToVTK

    base = path.parent / "sheet_tmp"
    counts = np.diff(offsets).astype(np.int64)
    polyLinesToVTK(str(base), np.ascontiguousarray(x[:, 0]), np.ascontiguousarray(x[:, 1]),
                   np.ascontiguousarray(x[:, 2]), pointsPerLine=counts,
                   pointData={"fiber_id": np.ascontiguousarray(fiber.astype(np.float64))})
    Path(str(base) + ".vtu").replace(path)


def write_sheet_png(path: Path, x: Array, offsets: npt.NDArray[Any], pts: Array, offs: Array, rad: Array,
                    title: str, box: tuple[list[float], list[float]], plate_z: float | None = None,
                    period: Sequence[float] | None = None) -> None:
    """Side (x-z) and top (x-y) views of the sheet on the fabric (yarns in grey); ``plate_z``: a
    press plate's height, drawn dashed in the side view; ``period`` (Lx, Ly), m (periodic x/y,
    unwrapped chains): every image of a fiber that reaches into the box is drawn, in its fiber's
    colour (:func:`periodic_images`). Both views clip at the box's x (and y) range."""
    colour_of = None
    if period is not None:
        x, offsets, colour_of, _ = periodic_images(x, offsets, period)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 5))
    for k in range(len(rad)):
        p = pts[offs[k]:offs[k + 1]]
        lw = max(0.5, 2 * rad[k] / (box[1][0] - box[0][0]) * 300)
        ax1.plot(p[:, 0] * 1e3, p[:, 2] * 1e3, color="0.75", lw=lw, solid_capstyle="round", zorder=1)
        ax2.plot(p[:, 0] * 1e3, p[:, 1] * 1e3, color="0.8", lw=lw, solid_capstyle="round", zorder=1)
    cmap = plt.get_cmap("tab20")
    for k in range(len(offsets) - 1):
        p = x[offsets[k]:offsets[k + 1]]
        colour = cmap((k if colour_of is None else int(colour_of[k])) % 20)
        ax1.plot(p[:, 0] * 1e3, p[:, 2] * 1e3, color=colour, lw=1.5, zorder=2)
        ax2.plot(p[:, 0] * 1e3, p[:, 1] * 1e3, color=colour, lw=1.5, zorder=2)
    ax1.set(xlabel="x (mm)", ylabel="z (mm)", title="side view (x-z), fabric in grey",
            xlim=(box[0][0] * 1e3, box[1][0] * 1e3))
    ax2.set(xlabel="x (mm)", ylabel="y (mm)", title="top view (x-y)", aspect="equal",
            xlim=(box[0][0] * 1e3, box[1][0] * 1e3), ylim=(box[0][1] * 1e3, box[1][1] * 1e3))
    if len(x):
        zlo = min(float(pts[:, 2].min()), float(x[:, 2].min()))
        zhi = max(float(pts[:, 2].max()), float(x[:, 2].max()))
        if plate_z is not None:
            zhi = max(zhi, plate_z)
        pad = 0.1 * (zhi - zlo + 1e-4)
        ax1.set_ylim((zlo - pad) * 1e3, (zhi + pad) * 1e3)
    if plate_z is not None:
        ax1.axhline(plate_z * 1e3, color="k", ls="--", lw=1, label="plate")
        ax1.legend(loc="upper right")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
