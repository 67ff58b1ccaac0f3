/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit test of the regular-grid flow field: trilinear interpolation is exact for linear (and
   multilinear) fields, clamps outside the box, and the binary companion file round-trips. */
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <string>

#include "physics/flow_grid.h"

namespace fl = fiberform::physics::flow;

static int failures = 0;
static void expect(bool ok, const char *what) {
  if (!ok) {
    std::fprintf(stderr, "FAIL: %s\n", what);
    ++failures;
  }
}

// A linear field plus a trilinear term (x*y*z), both reproduced exactly by trilinear interpolation.
static fl::Vec3 field(const fl::Vec3 &x) {
  return {0.3 + 2.0 * x[0] - 1.5 * x[1] + 0.25 * x[2],
          -1.0 + 0.5 * x[0] + 4.0 * x[2],
          0.01 - 3.0 * x[1] + 7.0 * x[0] * x[1] * x[2] * 1e6};
}

int main() {
  fl::RegularGrid g;
  g.n = {7, 5, 9};
  g.origin = {1e-4, -2e-4, 3e-4};
  g.spacing = {5e-5, 7e-5, 4e-5};
  g.data.resize(7 * 5 * 9 * 3);
  for (int i = 0; i < 7; ++i)
    for (int j = 0; j < 5; ++j)
      for (int k = 0; k < 9; ++k) {
        const fl::Vec3 x{g.origin[0] + i * g.spacing[0], g.origin[1] + j * g.spacing[1],
                         g.origin[2] + k * g.spacing[2]};
        const auto u = field(x);
        for (int c = 0; c < 3; ++c) g.data[g.index(i, j, k) + c] = u[c];
      }
  std::unique_ptr<fl::FlowField> flow = std::make_unique<fl::GridFlow>(g);

  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> ux(0.0, 1.0);
  double worst = 0.0;
  for (int s = 0; s < 20000; ++s) {
    fl::Vec3 x;
    for (int a = 0; a < 3; ++a) x[a] = g.origin[a] + ux(rng) * (g.n[a] - 1) * g.spacing[a];
    const auto got = flow->velocity(x, 0.0);
    const auto want = field(x);
    for (int c = 0; c < 3; ++c) worst = std::fmax(worst, std::fabs(got[c] - want[c]));
  }
  expect(worst < 1e-12, "exact for linear/trilinear fields inside the box");
  std::printf("test_flow_grid: max interpolation error %.3e\n", worst);

  // Exact at nodes, including the last node of every axis.
  const fl::Vec3 corner{g.origin[0] + 6 * g.spacing[0], g.origin[1] + 4 * g.spacing[1],
                        g.origin[2] + 8 * g.spacing[2]};
  const auto uc = flow->velocity(corner, 1.0);
  const auto wc = field(corner);
  expect(std::fabs(uc[0] - wc[0]) < 1e-12 && std::fabs(uc[2] - wc[2]) < 1e-12, "exact at last node");

  // Clamped outside: a point below and left of the box sees the value at the projected point.
  const fl::Vec3 outside{g.origin[0] - 1.0, g.origin[1] + 2.5 * g.spacing[1], g.origin[2] + 100.0};
  const fl::Vec3 projected{g.origin[0], g.origin[1] + 2.5 * g.spacing[1], corner[2]};
  const auto uo = flow->velocity(outside, 0.0);
  const auto wp = field(projected);
  expect(std::fabs(uo[0] - wp[0]) < 1e-12 && std::fabs(uo[1] - wp[1]) < 1e-12 &&
             std::fabs(uo[2] - wp[2]) < 1e-12,
         "clamped outside the box");

  // Time is ignored by the frozen field; the uniform field is uniform.
  const fl::Vec3 x0{2e-4, -1e-4, 4e-4};
  expect(flow->velocity(x0, 0.0) == flow->velocity(x0, 123.0), "frozen field ignores time");
  fl::UniformFlow uni({0.0, 0.0, -0.01});
  expect(uni.velocity(x0, 5.0)[2] == -0.01, "uniform flow");

  // Binary companion file round trip.
  const char *tmpdir = std::getenv("TMPDIR");
  const std::string path = std::string(tmpdir ? tmpdir : "/tmp") + "/test_flow_grid.grid";
  fl::write_flow_grid(path, g);
  const auto back = fl::read_flow_grid(path);
  expect(back.n == g.n && back.origin == g.origin && back.spacing == g.spacing && back.data == g.data,
         "binary round trip");
  std::remove(path.c_str());

  // Bad grids are refused.
  bool threw = false;
  try {
    fl::RegularGrid bad = g;
    bad.data.pop_back();
    fl::GridFlow f(bad);
  } catch (const std::invalid_argument &) {
    threw = true;
  }
  expect(threw, "size mismatch refused");

  std::printf("test_flow_grid: %s\n", failures ? "FAILED" : "ok");
  return failures ? 1 : 0;
}
