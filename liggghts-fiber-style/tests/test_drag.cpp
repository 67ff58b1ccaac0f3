/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit test of the drag law (Kettil 2016 eq. 2.14-2.16) against numbers computed independently
   with 40-digit decimal arithmetic (Python's decimal module, a separate implementation). */
#include <cmath>
#include <cstdio>

#include "physics/drag.h"

namespace dr = fiberform::physics::drag;

static int failures = 0;
static void expect_rel(double got, double want, double tol, const char *what) {
  const double err = std::fabs(got - want) / std::fabs(want);
  if (!(err <= tol)) {
    std::fprintf(stderr, "FAIL: %s: got %.15e want %.15e (rel err %.2e)\n", what, got, want, err);
    ++failures;
  }
}
static void expect(bool ok, const char *what) {
  if (!ok) {
    std::fprintf(stderr, "FAIL: %s\n", what);
    ++failures;
  }
}

int main() {
  // C_D in each branch of eq. 2.15, at both sides of the branch limits, and clamped above 400.
  struct { double re, cd; const char *what; } table[] = {
      {0.01, 3.529709942659486e+02, "C_D(0.01), branch Re<5"},
      {1.0, 1.111328300000000e+01, "C_D(1)"},
      {4.999, 4.280510648006070e+00, "C_D(4.999)"},
      {5.0, 4.162601731121384e+00, "C_D(5), branch [5,40)"},
      {20.0, 1.887071241859552e+00, "C_D(20)"},
      {39.99, 1.328446379069083e+00, "C_D(39.99)"},
      {40.0, 1.486380166791890e+00, "C_D(40), branch [40,400]"},
      {100.0, 1.243021640033715e+00, "C_D(100)"},
      {400.0, 1.122328318065613e+00, "C_D(400)"},
      {1000.0, 1.122328318065613e+00, "C_D(1000) clamped to C_D(400)"},
  };
  for (const auto &row : table) expect_rel(dr::drag_coefficient(row.re), row.cd, 1e-13, row.what);
  expect(dr::drag_coefficient(1e5) == dr::drag_coefficient(400.0), "clamp far above 400");
  expect(std::isinf(dr::drag_coefficient(0.0)), "C_D(0) diverges");

  // Re, eq. 2.16.
  expect_rel(dr::reynolds(998.2, 0.1, 30e-6, 1.002e-3), 998.2 * 0.1 * 30e-6 / 1.002e-3, 1e-15, "Re");

  // Force per unit length, eq. 2.14, for an oblique relative velocity (Re = 1.637).
  const dr::Vec3 v{0.01, -0.02, 0.05};
  const auto f = dr::drag_per_length(998.2, 1.002e-3, 30e-6, v);
  expect_rel(f[0], 6.601395782038322e-05, 1e-13, "f_x");
  expect_rel(f[1], -1.320279156407664e-04, 1e-13, "f_y");
  expect_rel(f[2], 3.300697891019161e-04, 1e-13, "f_z");
  const auto f0 = dr::drag_per_length(998.2, 1.002e-3, 30e-6, {0.0, 0.0, 0.0});
  expect(f0[0] == 0.0 && f0[1] == 0.0 && f0[2] == 0.0, "no drag without relative velocity");
  // Odd in v_rel.
  const auto fm = dr::drag_per_length(998.2, 1.002e-3, 30e-6, {-0.01, 0.02, -0.05});
  expect(fm[0] == -f[0] && fm[1] == -f[1] && fm[2] == -f[2], "f(-v) = -f(v)");

  // Gravity + buoyancy, and the slip speed where eq. 2.14 balances them:
  // d = 30 um, rho_fiber 1500, water 998.2 kg/m3, mu 1.002e-3 Pa s, g = 9.81 m/s2.
  const double d = 30e-6, area = M_PI * d * d / 4.0;
  const auto w = dr::gravity_buoyancy_per_length(1500.0, 998.2, area, {0.0, 0.0, -9.81});
  expect_rel(-w[2], 3.479621897010380e-06, 1e-13, "net weight per length");
  const double u = dr::balance_speed(998.2, 1.002e-3, d, -w[2]);
  expect_rel(u, 1.420695405704801e-03, 1e-10, "balance speed");
  expect_rel(dr::drag_per_length_magnitude(998.2, 1.002e-3, d, u), -w[2], 1e-10, "balance");

  // Jacobian of eq. 2.14 vs central differences of drag_per_length, all three Re branches, a few
  // directions; positive definite (a symmetric matrix with a positive smallest eigenvalue).
  for (double speed : {1e-3, 0.2, 1.5, 30.0}) {  // d = 30 um in water: Re 0.03, 6, 45, 900
    for (const dr::Vec3 dir : {dr::Vec3{1, 0, 0}, dr::Vec3{0.6, -0.8, 0}, dr::Vec3{0.48, 0.6, -0.64}}) {
      const dr::Vec3 u{speed * dir[0], speed * dir[1], speed * dir[2]};
      const auto J = dr::drag_jacobian(998.2, 1.002e-3, d, u);
      const double full[3][3] = {{J[0], J[3], J[4]}, {J[3], J[1], J[5]}, {J[4], J[5], J[2]}};
      double scale = 0.0;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) scale = std::fmax(scale, std::fabs(full[r][c]));
      double err = 0.0;
      for (int c = 0; c < 3; ++c) {
        const double h = 1e-6 * speed;
        dr::Vec3 up = u, um = u;
        up[c] += h;
        um[c] -= h;
        const auto fp = dr::drag_per_length(998.2, 1.002e-3, d, up);
        const auto fm = dr::drag_per_length(998.2, 1.002e-3, d, um);
        for (int r = 0; r < 3; ++r) err = std::fmax(err, std::fabs((fp[r] - fm[r]) / (2 * h) - full[r][c]));
      }
      if (!(err <= 1e-6 * scale)) {
        std::fprintf(stderr, "FAIL: drag Jacobian vs finite differences at %g m/s: %g (scale %g)\n", speed, err, scale);
        ++failures;
      }
      // positive definite: leading principal minors
      const double m1 = full[0][0], m2 = full[0][0] * full[1][1] - full[0][1] * full[1][0];
      const double m3 = full[0][0] * (full[1][1] * full[2][2] - full[1][2] * full[2][1]) -
                        full[0][1] * (full[1][0] * full[2][2] - full[1][2] * full[2][0]) +
                        full[0][2] * (full[1][0] * full[2][1] - full[1][1] * full[2][0]);
      if (!(m1 > 0 && m2 > 0 && m3 > 0)) {
        std::fprintf(stderr, "FAIL: drag Jacobian not positive definite at %g m/s\n", speed);
        ++failures;
      }
    }
  }
  const auto J0 = dr::drag_jacobian(998.2, 1.002e-3, d, {0.0, 0.0, 0.0});
  if (J0[0] != 0.0 || J0[1] != 0.0 || J0[2] != 0.0) {
    std::fprintf(stderr, "FAIL: drag Jacobian at zero relative velocity\n");
    ++failures;
  }

  std::printf("test_drag: %s\n", failures ? "FAILED" : "ok");
  return failures ? 1 : 0;
}
