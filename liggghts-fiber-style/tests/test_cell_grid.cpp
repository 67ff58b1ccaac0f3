/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit test of the coupling's view of the fluid mesh (physics/cell_grid.h): a uniform grid given as
   shuffled cell centres and boxes is recovered; locate() agrees with a brute-force search of the
   boxes (inside) and of the nearest box (outside); the spreading kernel conserves the total force to
   round-off and puts each force in the box that contains its point (the trilinear kernel conserves
   too and is the transpose of the interpolation); the cell velocities become a
   GridFlow that returns each cell's value at its centre and is exact for linear fields between
   centres; a non-uniform mesh is refused. */
#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <stdexcept>
#include <vector>

#include "check.h"
#include "physics/cell_grid.h"

namespace fl = fiberform::physics::flow;
using fiberform::check::expect;

namespace {

struct Mesh {
  std::vector<double> centres, boxes;
};

// nx x ny x nz cells of size h from lo, listed in a shuffled order (as an unstructured mesh may).
Mesh make_mesh(const int n[3], const double lo[3], const double h[3], std::mt19937_64 &rng) {
  std::vector<int> order(static_cast<std::size_t>(n[0] * n[1] * n[2]));
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), rng);
  Mesh m;
  for (int p : order) {
    const int ijk[3] = {p / (n[1] * n[2]), (p / n[2]) % n[1], p % n[2]};
    for (int a = 0; a < 3; ++a) m.centres.push_back(lo[a] + (ijk[a] + 0.5) * h[a]);
    for (int a = 0; a < 3; ++a) m.boxes.push_back(lo[a] + ijk[a] * h[a]);
    for (int a = 0; a < 3; ++a) m.boxes.push_back(lo[a] + (ijk[a] + 1) * h[a]);
  }
  return m;
}

// distance from x to the box of cell c (0 inside)
double box_distance(const Mesh &m, std::size_t c, const fl::Vec3 &x) {
  double d2 = 0.0;
  for (int a = 0; a < 3; ++a) {
    const double below = m.boxes[6 * c + a] - x[a], above = x[a] - m.boxes[6 * c + 3 + a];
    const double d = std::max({below, above, 0.0});
    d2 += d * d;
  }
  return std::sqrt(d2);
}

}  // namespace

int main() {
  std::mt19937_64 rng(2026);
  const int n[3] = {5, 3, 7};
  const double lo[3] = {-1e-3, 2e-4, 0.0}, h[3] = {2e-4, 1e-4, 5e-5};
  const Mesh m = make_mesh(n, lo, h, rng);
  const std::size_t nc = m.centres.size() / 3;
  const fl::CellGrid g = fl::CellGrid::from_cells(m.centres, m.boxes);
  expect(g.n[0] == 5 && g.n[1] == 3 && g.n[2] == 7, "grid dimensions recovered");
  expect(std::fabs(g.h[2] - 5e-5) < 1e-18, "cell size recovered", g.h[2], 5e-5);

  // locate(): inside points against the boxes; outside points against the nearest box
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  int wrong_in = 0, wrong_out = 0;
  std::vector<fl::Vec3> pts;
  for (int s = 0; s < 4000; ++s) {
    const bool outside = s % 4 == 0;
    fl::Vec3 x;
    for (int a = 0; a < 3; ++a) {
      const double span = n[a] * h[a];
      x[a] = lo[a] + (outside ? -0.5 + 2.0 * u01(rng) : u01(rng)) * span;
    }
    pts.push_back(x);
    const auto c = static_cast<std::size_t>(g.locate(x));
    const double dc = box_distance(m, c, x);
    double best = INFINITY;
    for (std::size_t k = 0; k < nc; ++k) best = std::min(best, box_distance(m, k, x));
    if (!outside && dc != 0.0) ++wrong_in;
    if (outside && dc > best + 1e-15) ++wrong_out;
  }
  expect(wrong_in == 0, "inside points lie in the box of their cell", wrong_in, 0);
  expect(wrong_out == 0, "outside points go to the nearest cell", wrong_out, 0);

  // spread_to_cells(): total conserved, each cell holds the forces of the points in its box
  std::vector<double> out(3 * nc, 0.0);
  std::normal_distribution<double> nf(0.0, 1e-6);
  double total[3] = {0, 0, 0}, scale = 0.0;
  std::vector<fl::Vec3> forces;
  for (const auto &x : pts) {
    const fl::Vec3 f{nf(rng), nf(rng), nf(rng)};
    forces.push_back(f);
    fl::spread_to_cells(g, x, f, out);
    for (int k = 0; k < 3; ++k) {
      total[k] += f[k];
      scale += std::fabs(f[k]);
    }
  }
  double spread_total[3] = {0, 0, 0};
  for (std::size_t c = 0; c < nc; ++c)
    for (int k = 0; k < 3; ++k) spread_total[k] += out[3 * c + k];
  for (int k = 0; k < 3; ++k)
    expect(std::fabs(spread_total[k] - total[k]) <= 1e-14 * scale, "sum over cells = sum of forces",
           spread_total[k], total[k]);
  // brute force for the inside points of one cell in the middle
  const std::size_t probe = static_cast<std::size_t>(g.cell_at[static_cast<std::size_t>((2 * 3 + 1) * 7 + 3)]);
  double want = 0.0;
  for (std::size_t s = 0; s < pts.size(); ++s) {
    const bool in = box_distance(m, probe, pts[s]) == 0.0;
    if (in) want += forces[s][0];
  }
  expect(std::fabs(out[3 * probe] - want) <= 1e-14 * scale, "a cell holds the forces of its points",
         out[3 * probe], want);

  // velocity_grid(): a linear field sampled at the centres
  auto lin = [](const fl::Vec3 &x) -> fl::Vec3 {
    return {0.1 + 30.0 * x[0] - 7.0 * x[2], -0.2 + 11.0 * x[1], 5.0 * x[0] + 2.0 * x[1]};
  };
  std::vector<double> cu(3 * nc);
  for (std::size_t c = 0; c < nc; ++c) {
    const auto v = lin({m.centres[3 * c], m.centres[3 * c + 1], m.centres[3 * c + 2]});
    for (int k = 0; k < 3; ++k) cu[3 * c + k] = v[k];
  }
  const fl::GridFlow flow(g.velocity_grid(cu));
  double worst_centre = 0.0, worst_between = 0.0;
  for (std::size_t c = 0; c < nc; ++c) {
    const auto v = flow.velocity({m.centres[3 * c], m.centres[3 * c + 1], m.centres[3 * c + 2]}, 0.0);
    for (int k = 0; k < 3; ++k) worst_centre = std::max(worst_centre, std::fabs(v[k] - cu[3 * c + k]));
  }
  for (int s = 0; s < 2000; ++s) {
    fl::Vec3 x;
    for (int a = 0; a < 3; ++a) x[a] = lo[a] + (0.5 + u01(rng) * (n[a] - 1)) * h[a];
    const auto v = flow.velocity(x, 0.0), w = lin(x);
    for (int k = 0; k < 3; ++k) worst_between = std::max(worst_between, std::fabs(v[k] - w[k]));
  }
  expect(worst_centre < 1e-15, "each cell's value at its centre", worst_centre, 0.0);
  expect(worst_between < 1e-13, "linear fields exact between centres", worst_between, 0.0);

  // trilinear kernel: conserving, and the transpose of the interpolation: for any cell field u,
  // sum over cells of (spread f)_c . u_c = f . u(x) (u interpolated at x)
  {
    std::vector<double> tri(3 * nc, 0.0);
    double tri_total[3] = {0, 0, 0}, worst_adjoint = 0.0;
    for (std::size_t s = 0; s < pts.size(); ++s) {
      std::vector<double> one(3 * nc, 0.0);
      fl::spread_to_cells(g, pts[s], forces[s], one, fl::Kernel::Trilinear);
      double lhs = 0.0;
      for (std::size_t c = 0; c < 3 * nc; ++c) {
        tri[c] += one[c];
        lhs += one[c] * cu[c];
      }
      const auto u = flow.velocity(pts[s], 0.0);
      const double rhs = forces[s][0] * u[0] + forces[s][1] * u[1] + forces[s][2] * u[2];
      const double mag = std::fabs(forces[s][0] * u[0]) + std::fabs(forces[s][1] * u[1]) +
                         std::fabs(forces[s][2] * u[2]) + 1e-300;
      worst_adjoint = std::max(worst_adjoint, std::fabs(lhs - rhs) / mag);
    }
    for (std::size_t c = 0; c < nc; ++c)
      for (int k = 0; k < 3; ++k) tri_total[k] += tri[3 * c + k];
    for (int k = 0; k < 3; ++k)
      expect(std::fabs(tri_total[k] - total[k]) <= 1e-14 * scale, "trilinear: sum over cells = sum of forces",
             tri_total[k], total[k]);
    expect(worst_adjoint < 1e-12, "trilinear spreading is the transpose of the interpolation", worst_adjoint, 0.0);
  }

  // a stretched cell is refused
  Mesh bad = m;
  bad.boxes[3] += 0.5 * h[0];
  bool threw = false;
  try {
    (void)fl::CellGrid::from_cells(bad.centres, bad.boxes);
  } catch (const std::invalid_argument &) {
    threw = true;
  }
  expect(threw, "non-uniform mesh refused");
  return fiberform::check::finish("test_cell_grid");
}
