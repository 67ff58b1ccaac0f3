/* SPDX-License-Identifier: GPL-3.0-or-later
   The exchange grid of two-way coupling on a fluid mesh that is not a uniform box (the flow stage's
   mesh: graded in z, the yarn cells removed). docs/coupling/formulation.md, "Exchange grid".

   The fibers always see a uniform grid of cuboid "exchange cells" (their uniform-grid code,
   physics/cell_grid.h, is unchanged). The fluid solver maps between that grid and its own cells
   with a map written by the lay-down stage (scripts/fiberform/coupling_map.py):
     - sampling:  U at an exchange cell's centre = sum over <= 8 fluid cells of w U_cell (the
                  trilinear weights of the flow stage's resampling onto flow.grid; removed cells
                  count as U = 0, so inside a yarn U = 0);
     - reaction:  the force of an exchange cell goes whole to ONE fluid cell: the one containing the
                  exchange cell's centre, or the nearest fluid cell when the centre is in a yarn.
                  Every force reaches exactly one cell: the total is conserved to round-off.

   Binary file (little-endian), written by fiberform, read by fiberPimpleFoam -coupled:
     8 bytes  magic "FFXMAP1\n"
     3 int64  nx ny nz                      exchange cells
     6 double origin[3] spacing[3]          centre of cell (0,0,0) and cell size (m)
     1 int64  fluid cells of the mesh the map was made for
     n x (8 int64 fluid cell or -1, 8 double weight)   sampling stencil per exchange cell
     n int64  receiving fluid cell per exchange cell
   Exchange cells in C order (x slowest), as flow.grid's nodes. No MPI, OpenFOAM or LIGGGHTS. */
#ifndef FIBERFORM_COUPLING_EXCHANGE_MAP_H
#define FIBERFORM_COUPLING_EXCHANGE_MAP_H

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "coupling_layer.h"

namespace fiberform::coupling {

struct ExchangeMap {
  static constexpr int kStencil = 8;
  std::array<std::int64_t, 3> n{0, 0, 0};
  std::array<double, 3> origin{0.0, 0.0, 0.0};   // centre of exchange cell (0, 0, 0) (m)
  std::array<double, 3> spacing{1.0, 1.0, 1.0};  // exchange cell size (m)
  std::int64_t fluid_cells = 0;
  std::vector<std::int64_t> stencil_cell;  // kStencil per exchange cell, -1: none
  std::vector<double> stencil_weight;      // kStencil per exchange cell
  std::vector<std::int64_t> target;        // receiving fluid cell per exchange cell

  std::size_t size() const { return target.size(); }

  /// The exchange cells as the Mesh message describes cells: centres, boxes, volumes (m, m3).
  Mesh mesh() const {
    Mesh m;
    const double vol = spacing[0] * spacing[1] * spacing[2];
    for (std::int64_t i = 0; i < n[0]; ++i)
      for (std::int64_t j = 0; j < n[1]; ++j)
        for (std::int64_t k = 0; k < n[2]; ++k) {
          const std::array<double, 3> c{origin[0] + static_cast<double>(i) * spacing[0],
                                        origin[1] + static_cast<double>(j) * spacing[1],
                                        origin[2] + static_cast<double>(k) * spacing[2]};
          for (int a = 0; a < 3; ++a) m.centres.push_back(c[a]);
          for (int a = 0; a < 3; ++a) m.boxes.push_back(c[a] - 0.5 * spacing[a]);
          for (int a = 0; a < 3; ++a) m.boxes.push_back(c[a] + 0.5 * spacing[a]);
          m.volumes.push_back(vol);
        }
    return m;
  }

  /// Velocities at the exchange cell centres (3 per exchange cell) from the fluid cell velocities
  /// u_fluid (3 per fluid cell, m/s).
  std::vector<double> sample(const std::vector<double> &u_fluid) const {
    if (u_fluid.size() != static_cast<std::size_t>(3 * fluid_cells))
      throw std::invalid_argument("exchange map: " + std::to_string(u_fluid.size() / 3) +
                                  " fluid cell velocities, the map was made for " +
                                  std::to_string(fluid_cells) + " cells");
    std::vector<double> out(3 * size(), 0.0);
    for (std::size_t e = 0; e < size(); ++e)
      for (int s = 0; s < kStencil; ++s) {
        const std::int64_t c = stencil_cell[kStencil * e + static_cast<std::size_t>(s)];
        if (c < 0) continue;
        const double w = stencil_weight[kStencil * e + static_cast<std::size_t>(s)];
        for (int a = 0; a < 3; ++a) out[3 * e + static_cast<std::size_t>(a)] += w * u_fluid[3 * static_cast<std::size_t>(c) + static_cast<std::size_t>(a)];
      }
    return out;
  }

  /// The force per fluid cell (3 per fluid cell, N) from the force per exchange cell (3 each, N):
  /// each exchange cell's force goes whole to its target cell (conservative to round-off).
  std::vector<double> gather(const std::vector<double> &f_exchange) const {
    if (f_exchange.size() != 3 * size())
      throw std::invalid_argument("exchange map: " + std::to_string(f_exchange.size()) +
                                  " reaction values, expected 3 per exchange cell (" +
                                  std::to_string(3 * size()) + ")");
    std::vector<double> out(static_cast<std::size_t>(3 * fluid_cells), 0.0);
    for (std::size_t e = 0; e < size(); ++e)
      for (int a = 0; a < 3; ++a)
        out[3 * static_cast<std::size_t>(target[e]) + static_cast<std::size_t>(a)] += f_exchange[3 * e + static_cast<std::size_t>(a)];
    return out;
  }
};

/// Read and check an exchange map file (format in the file comment). Throws std::runtime_error
/// naming the file and the first problem.
inline ExchangeMap read_exchange_map(const std::string &path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open exchange map " + path);
  auto bad = [&path](const std::string &why) {
    return std::runtime_error("exchange map " + path + ": " + why);
  };
  char magic[8];
  in.read(magic, 8);
  if (!in || std::memcmp(magic, "FFXMAP1\n", 8) != 0) throw bad("not a fiberform exchange map");
  ExchangeMap m;
  in.read(reinterpret_cast<char *>(m.n.data()), 3 * sizeof(std::int64_t));
  in.read(reinterpret_cast<char *>(m.origin.data()), 3 * sizeof(double));
  in.read(reinterpret_cast<char *>(m.spacing.data()), 3 * sizeof(double));
  in.read(reinterpret_cast<char *>(&m.fluid_cells), sizeof(std::int64_t));
  if (!in) throw bad("truncated header");
  for (int a = 0; a < 3; ++a) {
    if (m.n[a] < 1 || m.n[a] > 100000) throw bad("cell count out of [1, 1e5]");
    if (!(m.spacing[a] > 0.0) || !std::isfinite(m.spacing[a]) || !std::isfinite(m.origin[a]))
      throw bad("spacing must be finite and > 0, origin finite");
  }
  if (m.fluid_cells < 1) throw bad("no fluid cells");
  const auto ne = static_cast<std::size_t>(m.n[0] * m.n[1] * m.n[2]);
  m.stencil_cell.resize(ExchangeMap::kStencil * ne);
  m.stencil_weight.resize(ExchangeMap::kStencil * ne);
  m.target.resize(ne);
  std::array<std::int64_t, ExchangeMap::kStencil> cells{};
  std::array<double, ExchangeMap::kStencil> weights{};
  for (std::size_t e = 0; e < ne; ++e) {
    in.read(reinterpret_cast<char *>(cells.data()), sizeof(cells));
    in.read(reinterpret_cast<char *>(weights.data()), sizeof(weights));
    for (int s = 0; s < ExchangeMap::kStencil; ++s) {
      const auto k = ExchangeMap::kStencil * e + static_cast<std::size_t>(s);
      m.stencil_cell[k] = cells[static_cast<std::size_t>(s)];
      m.stencil_weight[k] = weights[static_cast<std::size_t>(s)];
      if (m.stencil_cell[k] < -1 || m.stencil_cell[k] >= m.fluid_cells ||
          !(m.stencil_weight[k] >= 0.0 && m.stencil_weight[k] <= 1.0))
        throw bad("stencil of exchange cell " + std::to_string(e) + ": cell out of range or weight "
                  "outside [0, 1]");
    }
  }
  in.read(reinterpret_cast<char *>(m.target.data()), static_cast<std::streamsize>(ne * sizeof(std::int64_t)));
  if (!in) throw bad("truncated (expected " + std::to_string(ne) + " exchange cells)");
  for (std::size_t e = 0; e < ne; ++e)
    if (m.target[e] < 0 || m.target[e] >= m.fluid_cells)
      throw bad("receiving cell of exchange cell " + std::to_string(e) + " out of range");
  if (in.peek() != std::char_traits<char>::eof()) throw bad("trailing data");
  return m;
}

}  // namespace fiberform::coupling

#endif
