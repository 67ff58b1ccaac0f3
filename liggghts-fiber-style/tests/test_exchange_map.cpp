/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit test of the exchange map of two-way coupling on a non-uniform fluid mesh
   (coupling/layer/exchange_map.h): a map written in the documented binary format is read back;
   gather() hands every exchange cell's force to its receiving cell and conserves the total to
   round-off; sample() with weights that sum to 1 over fluid cells reproduces a uniform velocity and
   gives 0 where every stencil cell is removed (-1); the exchange cells form a uniform grid the
   fibers accept (CellGrid::from_cells); a truncated file and an out-of-range cell are refused. */
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "check.h"
#include "exchange_map.h"
#include "physics/cell_grid.h"

namespace cpl = fiberform::coupling;
using fiberform::check::expect;

namespace {

void write_map(const std::string &path, const cpl::ExchangeMap &m, bool truncate = false) {
  std::ofstream out(path, std::ios::binary);
  out.write("FFXMAP1\n", 8);
  out.write(reinterpret_cast<const char *>(m.n.data()), 3 * sizeof(std::int64_t));
  out.write(reinterpret_cast<const char *>(m.origin.data()), 3 * sizeof(double));
  out.write(reinterpret_cast<const char *>(m.spacing.data()), 3 * sizeof(double));
  out.write(reinterpret_cast<const char *>(&m.fluid_cells), sizeof(std::int64_t));
  for (std::size_t e = 0; e < m.size(); ++e) {
    out.write(reinterpret_cast<const char *>(&m.stencil_cell[8 * e]), 8 * sizeof(std::int64_t));
    out.write(reinterpret_cast<const char *>(&m.stencil_weight[8 * e]), 8 * sizeof(double));
  }
  const std::size_t nt = truncate ? m.size() - 1 : m.size();
  out.write(reinterpret_cast<const char *>(m.target.data()), static_cast<std::streamsize>(nt * sizeof(std::int64_t)));
}

bool refused(const std::string &path) {
  try {
    (void)cpl::read_exchange_map(path);
  } catch (const std::runtime_error &) {
    return true;
  }
  return false;
}

}  // namespace

int main() {
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::uniform_int_distribution<std::int64_t> cell(0, 36);
  cpl::ExchangeMap m;
  m.n = {3, 4, 5};
  m.origin = {0.5e-4, 0.5e-4, 0.5e-4};
  m.spacing = {1e-4, 1e-4, 1e-4};
  m.fluid_cells = 37;
  const std::size_t ne = 60;
  for (std::size_t e = 0; e < ne; ++e) {
    // exchange cells 0..9 lie in a yarn: no fluid cell in their stencil
    const int used = e < 10 ? 0 : 1 + static_cast<int>(e % 8);
    double sum = 0.0;
    std::vector<double> w(8, 0.0);
    for (int s = 0; s < used; ++s) sum += (w[static_cast<std::size_t>(s)] = 0.1 + 0.5 * (1.0 + uni(rng)));
    for (int s = 0; s < 8; ++s) {
      m.stencil_cell.push_back(s < used ? cell(rng) : -1);
      m.stencil_weight.push_back(s < used ? w[static_cast<std::size_t>(s)] / sum : 0.0);
    }
    m.target.push_back(cell(rng));
  }
  const std::string path = "test_exchange_map.bin";
  write_map(path, m);
  const cpl::ExchangeMap r = cpl::read_exchange_map(path);
  expect(r.size() == ne && r.fluid_cells == 37 && r.target == m.target && r.stencil_cell == m.stencil_cell,
         "map read back");

  // gather conserves the total force and puts each force in its target
  std::vector<double> f(3 * ne);
  double total[3] = {0, 0, 0}, scale = 0.0;
  for (std::size_t i = 0; i < f.size(); ++i) {
    f[i] = uni(rng);
    total[i % 3] += f[i];
    scale += std::fabs(f[i]);
  }
  const std::vector<double> g = r.gather(f);
  double got[3] = {0, 0, 0};
  for (std::size_t i = 0; i < g.size(); ++i) got[i % 3] += g[i];
  for (int k = 0; k < 3; ++k)
    expect(std::fabs(got[k] - total[k]) <= 1e-14 * scale, "gather: sum over fluid cells = sum sent", got[k], total[k]);
  std::vector<double> one(3 * ne, 0.0);
  one[3 * 17 + 1] = 2.5;
  expect(r.gather(one)[3 * static_cast<std::size_t>(m.target[17]) + 1] == 2.5, "gather: force to the target cell");

  // sample: uniform fluid velocity reproduced where the stencil has fluid cells, 0 in yarns
  std::vector<double> u(3 * 37);
  for (std::size_t c = 0; c < 37; ++c) {
    u[3 * c] = 0.1;
    u[3 * c + 1] = -0.2;
    u[3 * c + 2] = -3.0;
  }
  const std::vector<double> s = r.sample(u);
  double worst = 0.0, in_yarn = 0.0;
  for (std::size_t e = 0; e < ne; ++e)
    for (int k = 0; k < 3; ++k) {
      const double v = s[3 * e + static_cast<std::size_t>(k)];
      if (e < 10) in_yarn = std::max(in_yarn, std::fabs(v));
      else worst = std::max(worst, std::fabs(v - u[static_cast<std::size_t>(k)]));
    }
  expect(worst < 1e-15 * 3.0 * 4, "sample: uniform field reproduced", worst, 0.0);
  expect(in_yarn == 0.0, "sample: zero inside a yarn", in_yarn, 0.0);

  // the exchange cells are a uniform grid for the fibers
  const cpl::Mesh mesh = r.mesh();
  const auto cg = fiberform::physics::flow::CellGrid::from_cells(mesh.centres, mesh.boxes);
  expect(cg.n[0] == 3 && cg.n[1] == 4 && cg.n[2] == 5, "exchange cells form a 3 x 4 x 5 grid");
  expect(std::fabs(cg.lattice.origin[2] - 0.5e-4) < 1e-18, "lattice origin = exchange origin", cg.lattice.origin[2], 0.5e-4);

  // bad files
  write_map(path, m, true);
  expect(refused(path), "truncated map refused");
  cpl::ExchangeMap b = m;
  b.target[5] = 37;
  write_map(path, b);
  expect(refused(path), "receiving cell out of range refused");
  std::remove(path.c_str());
  return fiberform::check::finish("test_exchange_map");
}
