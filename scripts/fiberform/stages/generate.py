# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``generate``: fibers from measured (or parametric) distributions, placed in the box.

Thesis sec. 3.4 (Kettil 2016): for each fiber a length L, a width w and per-node curvature
parameters alpha are sampled; node positions follow the recursion of eq. 3.4-3.9; cross-section
frames have t3 along the mean direction of the adjacent elements, t1 random for the first node
and rotated about t3 by a random angle in [-twist_max_rad, twist_max_rad] from node to node;
sections are hollow ellipses (circular a1 = a2 = w; collapsed a1 = 0.8 w, a2 = 0.2 w, with a small
random variation per node). Fibers are placed at random positions and orientations in the domain
without intersecting the fibers already placed, until the target mass (or count) is reached.

Products in ``<output_dir>/fibers/``: ``fibers.h5`` (datasets with units + provenance),
``fibers.data`` (LIGGGHTS ``read_data``), ``fibers.nodes`` (``fix fiber/beam ... nodes``) and
``in.fibers`` (a LIGGGHTS input that loads them, for ``fiberdem -in in.fibers``).
Page: docs/stages/generate.md.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from ..errors import ConfigError, StageError
from ..fabric_geometry import segment_distances
from ..fiber_io import (
    DATA_NAME, NODES_NAME, Fiber, fiber_preamble, outer_half_axes, quat_from_frames,
    write_fibers_liggghts,
)  # fmt: skip
from ..fiber_sheet import lateral_period
from ..inputs import LiggghtsInput
from ..provenance import file_hash, write_dataset
from ..scene.fibers import DISTRIBUTION_RANGES
from ._stage import Stage, StageContext

__all__ = [
    "FiberShape",
    "Generate",
    "Sampler",
    "fiber_mass",
    "fiber_shape",
    "generate_fibers",
    "segments_intersect",
]

Array = npt.NDArray[np.float64]
H5_NAME = "fibers.h5"
INPUT_NAME = "in.fibers"
#: time step written into in.fibers, which runs 0 steps (LIGGGHTS wants one); the lay-down and
#: press set their own
LOAD_TIMESTEP_S = 1.0e-7

# ------------------------------------------------------------------------------------------------
# shape (eq. 3.4-3.9) and frames


@dataclass
class FiberShape:
    """Parameters of one fiber shape. ``width_m`` is the thesis' w (the outer radius of a
    circular section); ``alpha`` has shape (n+1,) (same for both directions) or (2, n+1)."""

    length_m: float
    width_m: float
    alpha: Array
    segments: int
    cross_section: str = "circular"  # or "collapsed"
    wall_fraction: float = 1.0  # wall thickness / outer radius; 1 = solid
    twist_max_rad: float = 0.1
    radius_jitter: float = 0.02
    aspect: float = 0.25  # a2 / a1 of the collapsed section (thesis 0.2/0.8)


def random_rotation(rng: np.random.Generator) -> Array:
    """A uniformly random rotation matrix (columns e1, e2, e3)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def node_positions(length: float, alpha: Array, n: int, e: Array, c: Array) -> Array:
    """Eq. 3.4-3.9: n elements of length L/n, curvature parameters alpha (2, n+1)."""
    L = length
    LE = L / n  # eq. 3.5
    a = L * (1.0 - alpha[:, 0])  # eq. 3.7, the same amplitudes for all nodes
    q = np.empty((2, n + 1))
    q[:, 0] = math.pi / (L * alpha[:, 0])  # eq. 3.8
    for i in range(1, n + 1):  # eq. 3.9
        q[:, i] = 0.75 * q[:, i - 1] + 0.25 * math.pi / (L * alpha[:, i])
    p = np.empty((n + 1, 3))
    p[0] = c
    for i in range(n):  # eq. 3.4 and 3.6, node i+1 (0-based) uses q[:, i+1]
        xp = float((p[i] - c) @ e[:, 0]) + LE
        yp = a[0] * math.sin(q[0, i + 1] * xp)
        zp = a[1] * math.sin(q[1, i + 1] * xp)
        target = c + xp * e[:, 0] + yp * e[:, 1] + zp * e[:, 2]
        d = target - p[i]
        p[i + 1] = p[i] + LE * d / np.linalg.norm(d)
    return p


def node_frames(p: Array, twist_max: float, rng: np.random.Generator) -> Array:
    """Sec. 3.4 frames as quaternions (n+1, 4): t3 = mean element direction (end nodes: their
    element), t1 random for the first node, then carried to the next node (projected onto the
    new cross-section plane) and rotated about t3 by a uniform angle in [-twist_max, twist_max]."""
    d = np.diff(p, axis=0)
    d /= np.linalg.norm(d, axis=1)[:, None]
    t3 = np.empty_like(p)
    t3[0], t3[-1] = d[0], d[-1]
    if len(d) > 1:
        m = d[:-1] + d[1:]
        t3[1:-1] = m / np.linalg.norm(m, axis=1)[:, None]
    t1 = np.empty_like(p)
    r = rng.normal(size=3)
    r -= (r @ t3[0]) * t3[0]
    t1[0] = r / np.linalg.norm(r)
    for i in range(1, len(p)):
        v = t1[i - 1] - (t1[i - 1] @ t3[i]) * t3[i]
        nv = np.linalg.norm(v)
        if nv < 1e-8:  # t3 turned by ~90 degrees in one element: pick any perpendicular
            v = np.cross(t3[i], [1.0, 0.0, 0.0])
            if np.linalg.norm(v) < 1e-3:
                v = np.cross(t3[i], [0.0, 1.0, 0.0])
            nv = np.linalg.norm(v)
        v /= nv
        ang = rng.uniform(-twist_max, twist_max)
        t1[i] = math.cos(ang) * v + math.sin(ang) * np.cross(t3[i], v)
    t2 = np.cross(t3, t1)
    return quat_from_frames(t1, t2, t3)


def section_radii(shape: FiberShape, rng: np.random.Generator) -> Array:
    """(n+1, 4) radii a1, a2, b1, b2 with a small random variation per node."""
    n1 = shape.segments + 1
    w = shape.width_m
    # collapsed ("rectangular" in the thesis): a1 = 0.8 w, a2 = 0.2 w by default
    a = np.array(outer_half_axes(shape.cross_section, w, shape.aspect))
    jit = 1.0 + rng.uniform(-shape.radius_jitter, shape.radius_jitter, size=(n1, 1))
    outer = a[None, :] * jit
    inner = outer * (1.0 - shape.wall_fraction)
    return np.hstack([outer, inner])


def fiber_shape(shape: FiberShape, rng: np.random.Generator,
                center: Array | None = None, e: Array | None = None) -> Fiber:
    """One fiber in its stress-free generated shape, first node at ``center`` (default 0)."""
    n = shape.segments
    alpha = np.asarray(shape.alpha, dtype=float)
    if alpha.ndim == 1:
        alpha = np.vstack([alpha, alpha])
    if alpha.shape != (2, n + 1):
        raise ValueError(f"alpha must have shape (2, {n + 1}) or ({n + 1},)")
    if not np.all((alpha > 0) & (alpha <= 1)):
        raise ValueError("curvature parameters alpha must lie in (0, 1]")
    e = random_rotation(rng) if e is None else e
    c = np.zeros(3) if center is None else np.asarray(center, dtype=float)
    p = node_positions(shape.length_m, alpha, n, e, c)
    q = node_frames(p, shape.twist_max_rad, rng)
    return Fiber(x=p, q=q, radii=section_radii(shape, rng))


def fiber_mass(f: Fiber, density: float) -> float:
    """Mass as fix fiber/beam assigns it: density * sum over elements of A(mean radii) * length."""
    r = 0.5 * (f.radii[1:] + f.radii[:-1])
    area = math.pi * (r[:, 0] * r[:, 1] - r[:, 2] * r[:, 3])
    le = np.linalg.norm(np.diff(f.x, axis=0), axis=1)
    return float(density * np.sum(area * le))


# ------------------------------------------------------------------------------------------------
# sampling


class Sampler:
    """A distribution given as ``{"kind": ..., ...}`` (see docs/stages/generate.md):
    fixed (value), uniform (low, high), normal (mean, sd), lognormal (mean, sd of the variable),
    data (values from a CSV column, sampled uniformly). ``min``/``max`` truncate (resampling)."""

    def __init__(self, spec: Mapping[str, Any], data: Mapping[str, Array] | None = None,
                 name: str = "") -> None:
        self.spec = dict(spec)
        self.kind = self.spec.get("kind", "fixed")
        self.lo = self.spec.get("min")
        self.hi = self.spec.get("max")
        self.values: Array | None = None
        if self.kind == "data":
            col = self.spec.get("column", name)
            if data is None or col not in data:
                raise StageError(f"{name}: kind 'data' needs a data_csv with a column {col!r}")
            self.values = np.asarray(data[col], dtype=float)
            if self.values.size == 0:
                raise StageError(f"{name}: the data column {col!r} is empty")

    def _raw(self, rng: np.random.Generator, size: int) -> Array:
        s = self.spec
        if self.kind == "fixed":
            return np.full(size, float(s["value"]))
        if self.kind == "uniform":
            return rng.uniform(float(s["low"]), float(s["high"]), size)
        if self.kind == "normal":
            return rng.normal(float(s["mean"]), float(s["sd"]), size)
        if self.kind == "lognormal":
            m, sd = float(s["mean"]), float(s["sd"])
            sig2 = math.log(1.0 + (sd / m) ** 2)
            return rng.lognormal(math.log(m) - 0.5 * sig2, math.sqrt(sig2), size)
        if self.kind == "data":
            assert self.values is not None
            return rng.choice(self.values, size=size, replace=True)
        raise StageError(f"unknown distribution kind {self.kind!r}")

    def sample(self, rng: np.random.Generator, size: int = 1) -> Array:
        out = self._raw(rng, size)
        for _ in range(1000):
            bad = np.zeros(size, dtype=bool)
            if self.lo is not None:
                bad |= out < self.lo
            if self.hi is not None:
                bad |= out > self.hi
            if not bad.any():
                return out
            out[bad] = self._raw(rng, int(bad.sum()))
        raise StageError(f"distribution {self.spec} rarely falls inside [min, max]")

    def cdf(self, x: Array) -> Array:
        """The (truncated) CDF, for tests."""
        from scipy import stats

        s = self.spec
        if self.kind == "uniform":
            base = stats.uniform(float(s["low"]), float(s["high"]) - float(s["low"]))
        elif self.kind == "normal":
            base = stats.norm(float(s["mean"]), float(s["sd"]))
        elif self.kind == "lognormal":
            m, sd = float(s["mean"]), float(s["sd"])
            sig2 = math.log(1.0 + (sd / m) ** 2)
            base = stats.lognorm(math.sqrt(sig2), scale=math.exp(math.log(m) - 0.5 * sig2))
        else:
            raise ValueError(f"no analytic cdf for kind {self.kind!r}")
        lo = base.cdf(self.lo) if self.lo is not None else 0.0
        hi = base.cdf(self.hi) if self.hi is not None else 1.0
        return np.clip((base.cdf(x) - lo) / (hi - lo), 0.0, 1.0)


def read_csv_columns(path: Path) -> dict[str, Array]:
    """Numeric columns of a CSV file with a header row."""
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise StageError(f"cannot read data_csv {path}: {exc.strerror}") from None
    if not rows:
        raise StageError(f"data_csv {path} has no rows")
    out: dict[str, Array] = {}
    for key in rows[0]:
        try:
            out[key.strip()] = np.array([float(r[key]) for r in rows if r[key] not in ("", None)])
        except ValueError:
            continue
    return out


# ------------------------------------------------------------------------------------------------
# placement without intersection


def segments_intersect(fa: Fiber, fb: Fiber, gap: float = 0.0) -> bool:
    """True if any element capsule of ``fa`` overlaps one of ``fb`` (radius max(a1, a2))."""
    ra = np.max(0.5 * (fa.radii[1:, :2] + fa.radii[:-1, :2]), axis=1)
    rb = np.max(0.5 * (fb.radii[1:, :2] + fb.radii[:-1, :2]), axis=1)
    ia, ib = np.meshgrid(np.arange(len(ra)), np.arange(len(rb)), indexing="ij")
    ia, ib = ia.ravel(), ib.ravel()
    d = segment_distances(fa.x[ia], fa.x[ia + 1], fb.x[ib], fb.x[ib + 1])
    return bool(np.any(d < ra[ia] + rb[ib] + gap))


class _Grid:
    """Uniform grid of element capsules for the intersection checks. The capsules live in arrays
    that grow by doubling, so a check costs the capsules near it, not all placed ones."""

    def __init__(self, cell: float) -> None:
        self.cell = cell
        self.cells: dict[tuple[int, int, int], list[int]] = {}
        self.n = 0
        self.p0 = np.empty((64, 3))
        self.p1 = np.empty((64, 3))
        self.r = np.empty(64)

    def _keys(self, a: Array, b: Array, r: float) -> set[tuple[int, int, int]]:
        lo = np.floor((np.minimum(a, b) - r) / self.cell).astype(int)
        hi = np.floor((np.maximum(a, b) + r) / self.cell).astype(int)
        return {(i, j, k) for i in range(lo[0], hi[0] + 1) for j in range(lo[1], hi[1] + 1)
                for k in range(lo[2], hi[2] + 1)}

    def collides(self, f: Fiber) -> bool:
        rad = np.max(0.5 * (f.radii[1:, :2] + f.radii[:-1, :2]), axis=1)
        for k in range(f.n - 1):
            near: set[int] = set()
            for key in self._keys(f.x[k], f.x[k + 1], rad[k]):
                near.update(self.cells.get(key, ()))
            if not near:
                continue
            idx = np.fromiter(near, dtype=int)
            d = segment_distances(np.repeat(f.x[k:k + 1], len(idx), 0),
                                  np.repeat(f.x[k + 1:k + 2], len(idx), 0), self.p0[idx], self.p1[idx])
            if np.any(d < rad[k] + self.r[idx]):
                return True
        return False

    def add(self, f: Fiber) -> None:
        rad = np.max(0.5 * (f.radii[1:, :2] + f.radii[:-1, :2]), axis=1)
        need = self.n + f.n - 1
        if need > len(self.r):
            cap = max(need, 2 * len(self.r))
            self.p0 = np.resize(self.p0, (cap, 3))
            self.p1 = np.resize(self.p1, (cap, 3))
            self.r = np.resize(self.r, cap)
        for k in range(f.n - 1):
            sid = self.n
            self.p0[sid], self.p1[sid], self.r[sid] = f.x[k], f.x[k + 1], rad[k]
            self.n += 1
            for key in self._keys(f.x[k], f.x[k + 1], rad[k]):
                self.cells.setdefault(key, []).append(sid)


@dataclass
class GeneratedFiber:
    fiber: Fiber
    length_m: float
    width_m: float  # the scene's width (full width)
    alpha: Array  # (2, n+1)
    fine: bool
    mass_kg: float


def generate_fibers(
    *,
    rng: np.random.Generator,
    box_lo: Array,
    box_hi: Array,
    density: float,
    length: Sampler,
    width: Sampler,
    curvature: Sampler,
    segments: int | None,
    element_length_m: float | None = None,
    cross_section: str = "circular",
    aspect: float = 0.25,
    wall_fraction: float = 1.0,
    twist_max_rad: float = 0.1,
    radius_jitter: float = 0.02,
    fines_fraction: float = 0.0,
    fines_length: Sampler | None = None,
    target_mass_kg: float | None = None,
    count: int | None = None,
    max_attempts: int = 1000,
    period: tuple[float, float] | None = None,
) -> list[GeneratedFiber]:
    """Sample, shape and place fibers until the target mass (or count) is reached. Widths are
    full widths (the scene's width_m); the thesis' w (outer radius of a circular section) is
    width / 2. ``period`` (Lx, Ly), m (``laydown.walls: periodic``): in x and y the centre of a
    fiber's bounding box is uniform over the placement box and the fiber may cross its sides
    (no side of a periodic sheet is thinner than its middle); intersections are checked against
    the placed fibers' periodic images too. Without it every fiber lies inside the placement box."""
    if (target_mass_kg is None) == (count is None):
        raise ValueError("give exactly one of target_mass_kg and count")
    if (segments is None) == (element_length_m is None):
        raise ValueError("give exactly one of segments and element_length_m")
    box_lo, box_hi = np.asarray(box_lo, float), np.asarray(box_hi, float)
    out: list[GeneratedFiber] = []
    total = 0.0
    grid: _Grid | None = None
    while (count is not None and len(out) < count) or (target_mass_kg is not None and total < target_mass_kg):
        fine = fines_fraction > 0 and rng.uniform() < fines_fraction
        L = float((fines_length if fine and fines_length is not None else length).sample(rng)[0])
        w = float(width.sample(rng)[0])
        if segments is not None:
            n = segments
        else:
            assert element_length_m is not None
            n = max(2, round(L / element_length_m))
        alpha = curvature.sample(rng, 2 * (n + 1)).reshape(2, n + 1)
        shape = FiberShape(length_m=L, width_m=0.5 * w, alpha=alpha, segments=n,
                           cross_section="circular" if cross_section == "circular" else "collapsed",
                           wall_fraction=wall_fraction, twist_max_rad=twist_max_rad,
                           radius_jitter=radius_jitter, aspect=aspect)
        # orientations whose bounding box does not fit the placement box are redrawn (a thin
        # placement box thus gives nearly horizontal fibers)
        for _ in range(max_attempts):
            base = fiber_shape(shape, rng)
            rmax = float(np.max(base.radii[:, :2]))
            lo, hi = base.x.min(axis=0) - rmax, base.x.max(axis=0) + rmax
            room = (box_hi - box_lo) - (hi - lo)
            if period is not None:  # x, y: only the period bounds the fiber's extent
                room[:2] = np.array(period) - (hi - lo)[:2]
            if np.all(room > 0):
                break
        if np.any(room <= 0):
            raise StageError(
                f"a fiber of length {L:.3g} m does not fit into the domain "
                f"({(box_hi - box_lo).tolist()} m); enlarge domain.hi_m - domain.lo_m")
        if grid is None:
            grid = _Grid(cell=max(4 * rmax, 2 * L / n))
        placed = None
        images = [np.zeros(3)] if period is None else [
            np.array([i * period[0], j * period[1], 0.0]) for i in (-1, 0, 1) for j in (-1, 0, 1)]
        for _ in range(max_attempts):
            u = rng.uniform(0.0, 1.0, 3)
            shift = box_lo - lo + u * room
            if period is not None:  # the bounding box's centre uniform over the placement box
                shift[:2] = box_lo[:2] - 0.5 * (lo + hi)[:2] + u[:2] * (box_hi - box_lo)[:2]
            cand = Fiber(x=base.x + shift, q=base.q, radii=base.radii)
            if not any(grid.collides(Fiber(x=cand.x + d, q=cand.q, radii=cand.radii)) for d in images):
                placed = cand
                break
        if placed is None:
            raise StageError(
                f"could not place fiber {len(out) + 1} without intersections after {max_attempts} "
                f"attempts ({total:.3g} kg placed); the domain is too full for the target mass")
        grid.add(placed)
        m = fiber_mass(placed, density)
        total += m
        out.append(GeneratedFiber(placed, L, w, alpha, fine, m))
    return out


# ------------------------------------------------------------------------------------------------
# the stage


def _sampler_spec(section: Any, name: str, fallback: float | None) -> dict[str, Any]:
    spec = getattr(section, name, None) if section is not None else None
    if spec is None:
        if fallback is None:
            raise StageError(f"fiber_generation.{name}: required")
        return {"kind": "fixed", "value": fallback}
    return spec.model_dump(exclude_none=True) if hasattr(spec, "model_dump") else dict(spec)


def build_input(scene: Any, dt: float) -> str:
    """A LIGGGHTS input that loads the generated fibers (``fiberdem -in in.fibers``)."""
    s = LiggghtsInput()
    s.comment("Generated by fiberform stage generate: loads the fibers and runs 0 steps.")
    fiber_preamble(s, scene.fibers, newton=False, periodic_xy=lateral_period(scene) is not None)
    s.command("timestep", dt)
    s.command("thermo_style", "custom", "step", "atoms")
    s.command("run", 0)
    return s.render()


class Generate(Stage):
    """Fiber generation (thesis sec. 3.4)."""

    name = "generate"
    summary = "generate fibers (thesis sec. 3.4) from distributions and place them in the domain"
    folder = "fibers"
    requires = ("domain", "fibers")
    uses = ("seed", "domain", "fibers", "fiber_generation")
    products = (H5_NAME, DATA_NAME, NODES_NAME, INPUT_NAME)
    code_version = 2

    def preflight(self, ctx: StageContext) -> None:
        """The measured values of ``fiber_generation.data_csv`` (kind data), before anything is
        written: the file, the columns the distributions name and their values' ranges
        (fiberform.scene.fibers.DISTRIBUTION_RANGES); ConfigError (exit status 2) naming the field."""
        g = getattr(ctx.scene, "fiber_generation", None)
        if g is None:
            return
        specs = {key: getattr(g, key) for key in DISTRIBUTION_RANGES}
        wanted = {key: spec.column or key for key, spec in specs.items() if spec is not None and spec.kind == "data"}
        if not wanted:
            return
        path = ctx.scene_path.parent / g.data_csv
        try:
            data = read_csv_columns(path)
        except StageError as exc:
            raise ConfigError(f"fiber_generation.data_csv: {exc}") from None
        for key, col in wanted.items():
            allowed = DISTRIBUTION_RANGES[key]
            values = data.get(col)
            if values is None or values.size == 0:
                raise ConfigError(f"fiber_generation.{key}: kind data reads column {col!r} of {path}, which "
                                  f"{'is empty' if values is not None else 'has no such column'} (columns: "
                                  f"{', '.join(sorted(data)) or 'none'})")
            bad = values[~allowed.contains(values)]
            if bad.size:
                raise ConfigError(f"fiber_generation.{key}: column {col!r} of {path} holds {bad.size} value(s) "
                                  f"outside {allowed}, e.g. {bad[0]:g}")

    def metrics(self, ctx: StageContext) -> dict[str, float]:
        with h5py.File(self.product_paths(ctx)[0], "r") as h5:
            mass = np.asarray(h5["fibers/mass"][...], dtype=np.float64)
            fine = np.asarray(h5["fibers/is_fine"][...], dtype=bool)
        return {"fibers": float(len(mass)), "fines": float(np.count_nonzero(fine)),
                "fiber_mass_kg": float(np.sum(mass))}

    def input_hashes(self, ctx: StageContext) -> dict[str, str]:
        h = super().input_hashes(ctx)
        g = getattr(ctx.scene, "fiber_generation", None)
        if g is not None and getattr(g, "data_csv", None):
            p = ctx.scene_path.parent / g.data_csv
            if p.is_file():
                h["data_csv"] = file_hash(p)
        if lateral_period(ctx.scene) is not None:  # laydown.walls periodic: periodic placement
            h["lateral"] = "periodic"
        return h

    def produce(self, ctx: StageContext, h5: h5py.File, tmp: Mapping[str, Path],
                hashes: Mapping[str, str]) -> None:
        scene = ctx.scene
        f = scene.fibers
        g = getattr(scene, "fiber_generation", None)
        data = None
        if g is not None and g.data_csv:
            data = read_csv_columns(ctx.scene_path.parent / g.data_csv)
        length = Sampler(_sampler_spec(g, "length_m", f.length_m), data, "length_m")
        width = Sampler(_sampler_spec(g, "width_m", f.width_m), data, "width_m")
        curv = Sampler(_sampler_spec(g, "curvature_alpha", 1.0), data, "curvature_alpha")
        fines = None
        if g is not None and g.fines_length_m is not None:
            fines = Sampler(g.fines_length_m.model_dump(exclude_none=True), data, "fines_length_m")
        aspect = 0.25
        if f.cross_section == "rectangular" and f.thickness_m is not None:
            aspect = f.thickness_m / f.width_m
        rng = np.random.default_rng(scene.seed)
        fibers = generate_fibers(
            rng=rng,
            box_lo=np.array(g.placement_lo_m if g is not None and g.placement_lo_m else scene.domain.lo_m),
            box_hi=np.array(g.placement_hi_m if g is not None and g.placement_hi_m else scene.domain.hi_m),
            density=f.density_kg_m3, length=length, width=width, curvature=curv,
            segments=f.segments,
            element_length_m=g.element_length_m if g is not None else None,
            cross_section=f.cross_section, aspect=aspect,
            wall_fraction=g.wall_fraction if g is not None else 1.0,
            twist_max_rad=g.twist_max_rad if g is not None else 0.1,
            radius_jitter=g.radius_jitter if g is not None else 0.02,
            fines_fraction=g.fines_fraction if g is not None else 0.0, fines_length=fines,
            target_mass_kg=f.target_mass_kg, count=f.count,
            max_attempts=g.max_attempts if g is not None else 1000,
            period=lateral_period(scene),
        )
        write_fibers_liggghts(tmp[DATA_NAME], tmp[NODES_NAME], [gf.fiber for gf in fibers],
                              scene.domain.lo_m, scene.domain.hi_m, density_kg_m3=f.density_kg_m3)
        tmp[INPUT_NAME].write_text(build_input(scene, LOAD_TIMESTEP_S))

        grp = h5.create_group("fibers")
        counts = np.array([gf.fiber.n for gf in fibers])
        write_dataset(grp, "offsets", np.concatenate([[0], np.cumsum(counts)]), "1",
                      "node offsets: fiber k owns nodes offsets[k]:offsets[k+1]")
        write_dataset(grp, "x", np.vstack([gf.fiber.x for gf in fibers]), "m",
                      "node positions (stress-free reference = initial state)")
        write_dataset(grp, "q", np.vstack([gf.fiber.q for gf in fibers]), "1",
                      "cross-section frames as unit quaternions (w, x, y, z), t_I = R(q) e_I")
        write_dataset(grp, "radii", np.vstack([gf.fiber.radii for gf in fibers]), "m",
                      "section semi-axes a1, a2 (outer), b1, b2 (inner) per node")
        write_dataset(grp, "alpha", np.hstack([gf.alpha for gf in fibers]).T, "1",
                      "curvature parameters alpha_1, alpha_2 per node (eq. 3.7-3.9)")
        write_dataset(grp, "length", np.array([gf.length_m for gf in fibers]), "m", "sampled length")
        write_dataset(grp, "width", np.array([gf.width_m for gf in fibers]), "m",
                      "sampled (full) width")
        write_dataset(grp, "mass", np.array([gf.mass_kg for gf in fibers]), "kg", "fiber mass")
        write_dataset(grp, "is_fine", np.array([gf.fine for gf in fibers]), "1",
                      "true for fines (short fibers)")
        grp.attrs["total_mass_kg"] = float(sum(gf.mass_kg for gf in fibers))
        grp.attrs["count"] = len(fibers)
