/* SPDX-License-Identifier: GPL-3.0-or-later
   The fluid mesh as the fibers see it in two-way coupling (docs/coupling/formulation.md): a uniform,
   axis-aligned grid of cuboid cells (a blockMesh box), recovered from the cell centres and bounding
   boxes the fluid solver sends in the handshake, in the solver's own cell order.

     - CellGrid::from_cells  checks that the cells tile a box as an nx x ny x nz grid of equal cuboids
                             and records which fluid cell sits at each grid position;
     - CellGrid::locate      the fluid cell containing a point (points outside the box: the nearest
                             boundary cell, so no force is ever dropped);
     - CellGrid::velocity_grid  the cell velocities as a RegularGrid with nodes at the cell centres,
                             for GridFlow (trilinear between centres, constant in the outer half
                             cells: the same FlowField as the frozen one-way flow);
     - spread_to_cells       the reaction kernel: each node force goes whole to the cell containing
                             the node. The sum over cells equals the sum over nodes to round-off.
   Pure header, SI units, no LIGGGHTS or MPI dependency. */
#ifndef FIBERFORM_PHYSICS_CELL_GRID_H
#define FIBERFORM_PHYSICS_CELL_GRID_H

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "flow_grid.h"

namespace fiberform::physics::flow {

struct CellGrid {
  std::array<std::int64_t, 3> n{0, 0, 0};
  Vec3 lo{0.0, 0.0, 0.0};       // lower corner of the box (m)
  Vec3 h{1.0, 1.0, 1.0};        // cell size (m)
  std::vector<std::int64_t> cell_at;  // grid position (C order, x slowest) -> fluid cell id
  RegularGrid lattice;                // the cell centres as a grid: n, origin lo + h/2, spacing h (no data)

  std::int64_t cells() const { return n[0] * n[1] * n[2]; }

  /// centres: 3 per cell (m); boxes: 6 per cell, lo xyz then hi xyz (m). Throws
  /// std::invalid_argument naming the first offending cell when they are not a uniform grid.
  static CellGrid from_cells(const std::vector<double> &centres, const std::vector<double> &boxes) {
    const std::size_t nc = centres.size() / 3;
    if (nc == 0 || centres.size() != 3 * nc || boxes.size() != 6 * nc)
      throw std::invalid_argument("cell grid: need 3 centre and 6 box values per cell, at least one cell");
    CellGrid g;
    Vec3 hi{0.0, 0.0, 0.0};
    for (int a = 0; a < 3; ++a) {
      g.lo[a] = boxes[a];
      hi[a] = boxes[3 + a];
      g.h[a] = boxes[3 + a] - boxes[a];
    }
    for (std::size_t c = 0; c < nc; ++c)
      for (int a = 0; a < 3; ++a) {
        g.lo[a] = std::min(g.lo[a], boxes[6 * c + a]);
        hi[a] = std::max(hi[a], boxes[6 * c + 3 + a]);
      }
    auto bad = [](std::size_t c, const std::string &why) {
      return std::invalid_argument("cell grid: cell " + std::to_string(c) + " " + why +
                                   ": the fluid mesh must be a uniform axis-aligned grid of equal "
                                   "cuboid cells (a blockMesh box) in this version");
    };
    for (int a = 0; a < 3; ++a) {
      if (!(g.h[a] > 0.0)) throw bad(0, "has a zero or negative extent");
      const double cnt = (hi[a] - g.lo[a]) / g.h[a];
      g.n[a] = static_cast<std::int64_t>(std::llround(cnt));
      if (g.n[a] < 1 || std::fabs(cnt - static_cast<double>(g.n[a])) > 1e-6)
        throw bad(0, "does not divide the box into whole cells");
    }
    if (static_cast<std::size_t>(g.cells()) != nc)
      throw std::invalid_argument("cell grid: " + std::to_string(nc) + " cells, but the box holds " +
                                  std::to_string(g.cells()) + " cells of the first cell's size: the "
                                  "fluid mesh must be a uniform axis-aligned grid (a blockMesh box)");
    g.cell_at.assign(nc, -1);
    for (std::size_t c = 0; c < nc; ++c) {
      std::int64_t idx[3];
      for (int a = 0; a < 3; ++a) {
        if (std::fabs(boxes[6 * c + 3 + a] - boxes[6 * c + a] - g.h[a]) > 1e-6 * g.h[a])
          throw bad(c, "differs in size from cell 0");
        const double s = (centres[3 * c + a] - g.lo[a]) / g.h[a] - 0.5;
        idx[a] = static_cast<std::int64_t>(std::llround(s));
        if (idx[a] < 0 || idx[a] >= g.n[a] || std::fabs(s - static_cast<double>(idx[a])) > 1e-6)
          throw bad(c, "has its centre off the grid");
      }
      const std::size_t pos = static_cast<std::size_t>((idx[0] * g.n[1] + idx[1]) * g.n[2] + idx[2]);
      if (g.cell_at[pos] >= 0) throw bad(c, "overlaps cell " + std::to_string(g.cell_at[pos]));
      g.cell_at[pos] = static_cast<std::int64_t>(c);
    }
    g.lattice.n = g.n;
    for (int a = 0; a < 3; ++a) {
      g.lattice.origin[a] = g.lo[a] + 0.5 * g.h[a];
      g.lattice.spacing[a] = g.h[a];
    }
    return g;
  }

  /// The fluid cell containing x (m); outside the box, the nearest boundary cell (clamped per axis).
  /// A point on a face between two cells goes to the upper one.
  std::int64_t locate(const Vec3 &x) const {
    std::int64_t idx[3];
    for (int a = 0; a < 3; ++a) {
      const double s = (x[a] - lo[a]) / h[a];
      if (!(s > 0.0)) idx[a] = 0;  // also NaN
      else if (s >= static_cast<double>(n[a])) idx[a] = n[a] - 1;
      else idx[a] = std::min<std::int64_t>(static_cast<std::int64_t>(s), n[a] - 1);
    }
    return cell_at[static_cast<std::size_t>((idx[0] * n[1] + idx[1]) * n[2] + idx[2])];
  }

  /// Cell velocities (3 per fluid cell, fluid cell order, m/s) as a RegularGrid with its nodes at
  /// the cell centres (origin lo + h/2, spacing h), for GridFlow.
  RegularGrid velocity_grid(const std::vector<double> &cell_u) const {
    if (cell_u.size() != static_cast<std::size_t>(3 * cells()))
      throw std::invalid_argument("cell grid: velocity array has " + std::to_string(cell_u.size()) +
                                  " values, expected 3 per cell (" + std::to_string(3 * cells()) + ")");
    RegularGrid r = lattice;
    r.data.resize(cell_u.size());
    for (std::size_t p = 0; p < cell_at.size(); ++p)
      for (int k = 0; k < 3; ++k)
        r.data[3 * p + k] = cell_u[3 * static_cast<std::size_t>(cell_at[p]) + k];
    return r;
  }
};

/// Reaction kernels (docs/coupling/formulation.md):
///   Cell       the whole force to the cell containing the point;
///   Trilinear  the force split over the (up to 8) cells around the point with the trilinear weights
///              of velocity_grid()'s interpolation (the kernel is the transpose of the interpolation;
///              clamped outside the centres' box like the interpolation).
/// Both conserve: the weights of a point sum to 1, so sum(out) changes by sum(f) up to round-off.
enum class Kernel { Cell, Trilinear };

/// out (3 per fluid cell, N) += the force f (N) of a point x (m) spread by the kernel.
inline void spread_to_cells(const CellGrid &g, const Vec3 &x, const Vec3 &f, std::vector<double> &out,
                            Kernel kernel = Kernel::Cell) {
  if (kernel == Kernel::Cell) {
    const auto c = static_cast<std::size_t>(g.locate(x));
    for (int k = 0; k < 3; ++k) out[3 * c + k] += f[k];
    return;
  }
  const Stencil st = trilinear_stencil(g.lattice, x);
  for (int s = 0; s < st.size; ++s) {
    const auto c = static_cast<std::size_t>(g.cell_at[st.node[static_cast<std::size_t>(s)]]);
    const double w = st.weight[static_cast<std::size_t>(s)];
    for (int k = 0; k < 3; ++k) out[3 * c + k] += w * f[k];
  }
}

}  // namespace fiberform::physics::flow

#endif
