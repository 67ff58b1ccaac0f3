/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of the extended-DLVO and steric force laws (src/physics/dlvo.h, steric.h,
   contact_law.h, contact_geometry.h) against independent evaluations of the thesis formulas
   (written out again here in long double, in the printed form), published values and closed forms. */
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <limits>

#include "physics/contact_geometry.h"
#include "physics/contact_law.h"
#include "physics/dlvo.h"
#include "physics/steric.h"

using namespace fiberform::physics;
typedef long double ld;

static int failures = 0;
static void expect(bool ok, const char *what, double a = 0, double b = 0) {
  if (!ok) {
    std::fprintf(stderr, "FAIL: %s (%.17g vs %.17g)\n", what, a, b);
    ++failures;
  }
}
static bool rel_close(double a, double b, double tol) {
  return std::fabs(a - b) <= tol * std::fmax(std::fabs(a), std::fabs(b));
}

int main() {
  const double A = 8.0e-21, r1 = 7e-6, r2 = 5e-6;
  const double hs[] = {0.5e-9, 1e-9, 2e-9, 5e-9, 1e-8, 3e-8, 1e-7};

  // ---- eq. 2.25 against the formula as printed
  for (double h : hs) {
    const ld ref = -(ld)A / (6.0L * h * h) * ((ld)r1 * r2 / ((ld)r1 + r2));
    expect(rel_close(vdw_force(A, r1, r2, h), (double)ref, 1e-14), "eq 2.25", vdw_force(A, r1, r2, h), (double)ref);
  }
  // ---- eq. 2.23 differentiated: analytic force and slope against central differences of the
  //      printed energy (long double), and the Derjaguin limit for h << r
  auto V = [&](ld h, ld a1, ld a2) {
    return -(ld)A / 6.0L *
           (2 * a1 * a2 / (h * (h + 2 * a1 + 2 * a2)) + 2 * a1 * a2 / ((h + 2 * a1) * (h + 2 * a2)) +
            std::log(h * (h + 2 * a1 + 2 * a2) / ((h + 2 * a1) * (h + 2 * a2))));
  };
  for (double h : {2e-9, 1e-8, 1e-7, 1e-6, 5e-6}) {
    const ld dh = h * 1e-5L;
    const ld F = -(V(h + dh, r1, r2) - V(h - dh, r1, r2)) / (2 * dh);
    const ld F2 = -(V(h + 2 * dh, r1, r2) - V(h - 2 * dh, r1, r2)) / (4 * dh);
    const ld Fp = -(V(h + dh, r1, r2) - 2 * V(h, r1, r2) + V(h - dh, r1, r2)) / (dh * dh);
    const ForceAndSlope fs = hamaker_force(A, r1, r2, h);
    expect(rel_close(fs.force, (double)F, 1e-7), "eq 2.23 force = -dV/dh", fs.force, (double)F);
    (void)F2;
    expect(rel_close(fs.slope, (double)Fp, 1e-4), "eq 2.23 slope", fs.slope, (double)Fp);
  }
  expect(rel_close(hamaker_force(A, r1, r2, 1e-10).force, vdw_force(A, r1, r2, 1e-10), 1e-4), "2.23 -> 2.25 for h << r");
  // sphere-plane limit of the full expression = very large partner radius
  expect(rel_close(hamaker_force(A, r1, INFINITY, 3e-8).force, hamaker_force(A, r1, 1e3, 3e-8).force, 1e-6),
         "Hamaker sphere-plane limit");

  // ---- Debye length: 1 mM 1:1 electrolyte in water at 25 C is 9.6 nm (Israelachvili eq. 14.37:
  //      1/kappa = 0.304 nm / sqrt(M))
  const double kappa = inverse_debye_length(1.0, 298.15, 78.5);
  expect(std::fabs(1.0 / kappa - 0.304e-9 / std::sqrt(1e-3)) < 0.01 * 9.6e-9, "Debye length 1 mM", 1 / kappa, 9.61e-9);
  expect(rel_close(inverse_debye_length(100.0, 298.15, 78.5), 10.0 * kappa, 1e-12), "kappa ~ sqrt(I)");

  // ---- eq. 2.29 round trip to 1e-10, over potentials and curvatures
  for (double y : {-8.0, -2.0, -0.9, -0.1, 0.01, 0.5, 1.0, 3.0, 10.0})
    for (double kr : {0.1, 1.0, 30.0, 700.0, (double)INFINITY}) {
      const double s = reduced_charge_from_potential(y, kr);
      const ld sref = 2.0L * std::sinh((ld)y / 2) + (std::isinf(kr) ? 0.0L : 4.0L / kr * std::tanh((ld)y / 4));
      expect(rel_close(s, (double)sref, 1e-14), "eq 2.29 forward", s, (double)sref);
      const double yb = potential_from_reduced_charge(s, kr);
      expect(std::fabs(yb - y) <= 1e-10 * std::fabs(y), "eq 2.29 round trip", yb, y);
    }

  // ---- eq. 2.28 (Ohshima, tanh^2) and its limits
  for (double y : {-3.0, -1.0, 0.2, 2.0})
    for (double kr : {0.5, 5.0, 50.0}) {
      const ld t = std::tanh((ld)y / 4), g = (2 * (ld)kr + 1) / (((ld)kr + 1) * ((ld)kr + 1));
      const ld ref = 8 * t / (1 + std::sqrt(1 - g * t * t));
      expect(rel_close(effective_surface_potential(y, kr), (double)ref, 1e-14), "eq 2.28");
      expect(rel_close(effective_surface_potential(-y, kr), -effective_surface_potential(y, kr), 1e-15), "eq 2.28 odd");
    }
  expect(rel_close(effective_surface_potential(1e-4, 3.0), 1e-4, 1e-6), "eq 2.28 low-potential limit Y = y");
  expect(rel_close(effective_surface_potential(2.0, INFINITY), 4 * std::tanh(0.5), 1e-14), "eq 2.28 plate limit");

  // ---- eq. 2.27 against the printed formula
  {
    const double T = 298.15, eps = 78.5 * constants::eps0, kT_e = constants::kB * T / constants::e;
    const ElectrostaticParams p{eps, kT_e, kappa};
    const double Y1 = 0.9, Y2 = -0.7;
    for (double h : hs) {
      const ld R = (ld)h + r1 + r2;
      const ld ref = 4 * (ld)constants::pi * eps * (ld)kT_e * kT_e * Y1 * Y2 * (ld)r1 * r2 / (R * R) * (1 + kappa * R) *
                     std::exp(-(ld)kappa * (R - r1 - r2));
      const ForceAndSlope f = electrostatic_force(p, Y1, Y2, r1, r2, h);
      expect(rel_close(f.force, (double)ref, 1e-12), "eq 2.27", f.force, (double)ref);
      const double dh = h * 1e-6;
      const double num = (electrostatic_force(p, Y1, Y2, r1, r2, h + dh).force -
                          electrostatic_force(p, Y1, Y2, r1, r2, h - dh).force) / (2 * dh);
      expect(rel_close(f.slope, num, 1e-6), "eq 2.27 slope", f.slope, num);
    }
    // plane limit
    expect(rel_close(electrostatic_force(p, Y1, Y2, r1, INFINITY, 2e-9).force,
                     electrostatic_force(p, Y1, Y2, r1, 1e4, 2e-9).force, 1e-6), "eq 2.27 sphere-plane limit");
  }

  // ---- spline extension (eq. 2.30-2.33): zero for h <= 0, C1 at h0/2 and h0, for both terms
  {
    ContactLaw L;
    L.terms = kVdw | kEs;
    PairLaw pl;
    pl.setup(L, r1, r2, 1 / 1e-14, 1 / 2e-14, L.effective_potential(r1), L.effective_potential(r2));
    const double h0 = L.h0;
    auto jump = [](double a, double b) { return std::fabs(a - b) / std::fmax(std::fabs(a), std::fabs(b)); };
    for (int term = 0; term < 2; ++term) {
      const Spline &s = term == 0 ? pl.spl_vdw : pl.spl_es;
      const ForceAndSlope at0 = term == 0 ? ForceAndSlope{vdw_force(A, r1, r2, h0), vdw_force_slope(A, r1, r2, h0)}
                                          : electrostatic_force(pl.es, pl.Y1, pl.Y2, r1, r2, h0);
      // value and slope of the two spline pieces at h0/2 (evaluated from each formula directly)
      const double hm = 0.5 * h0;
      const double left_v = s.a * hm * hm, right_v = (s.b * hm + s.c) * hm + s.d;
      const double left_s = 2 * s.a * hm, right_s = 2 * s.b * hm + s.c;
      expect(jump(left_v, right_v) < 1e-9, "spline value continuous at h0/2", left_v, right_v);
      expect(jump(left_s, right_s) < 1e-9, "spline slope continuous at h0/2", left_s, right_s);
      const double end_v = (s.b * h0 + s.c) * h0 + s.d, end_s = 2 * s.b * h0 + s.c;
      expect(jump(end_v, at0.force) < 1e-9, "spline value = formula at h0", end_v, at0.force);
      expect(jump(end_s, at0.slope) < 1e-9, "spline slope = formula at h0", end_s, at0.slope);
      expect(spline_value(s, 0.0) == 0.0 && spline_value(s, -1e-9) == 0.0, "spline zero for h <= 0");
    }
    // the law as a whole is continuous across h0 (value)
    const double below = pl.force(h0 * (1 - 1e-12), 0.0), above = pl.force(h0, 0.0);
    expect(jump(below, above) < 1e-9, "extended DLVO continuous at h0", below, above);
  }

  // ---- steric: bells confined to their ranges, C1 smooth step, signs by purpose
  {
    StericParams p{1e-9, 0.5e-9, 1e-9, 1e-8};
    const double mu = 1e-14, rsum = 14e-6;
    expect(bell1(p, -1e-9) == 1.0 && bell1(p, p.h_R) == 0.0 && bell1(p, 0.9e-9) == 0.0, "B1 support (-inf, h_R)");
    expect(bell2(p, p.h_R) == 1.0 && bell2(p, -1e-9) == 1.0 && bell2(p, p.h0) == 0.0 && bell2(p, 0.75e-9) > 0,
           "B2 support (-inf, h0)");
    expect(bell3(-0.4 * rsum, rsum) == 0.0 && bell3(-rsum, rsum) == 1.0 && bell3(-0.75 * rsum, rsum) > 0,
           "B3 support (h_min, h_min/2)");
    expect(bell4(p, -p.h_D) == 1.0 && bell4(p, 0.0) == 0.0, "B4 support (-inf, 0)");
    for (double x : {0.0, 1.0}) {
      const double e = 1e-7;
      expect(std::fabs(smooth_step(x + e) - smooth_step(x - e)) < 1e-6, "smooth step continuous");
      expect(std::fabs((smooth_step(x + e) - smooth_step(x)) / e) < 1e-6 + 6 * e, "smooth step C1 at ends");
    }
    // S1 at rest just inside h_R: 2 mu e(h) / t_R^2 with e ~ h_R - h; saturated at h_cap deep inside
    const double h = 0.45e-9;
    expect(rel_close(steric_terms(p, h, 0.0, mu, rsum).s1, 2 * mu * p.h_R * std::tanh((p.h_R - h) / p.h_R) / (p.t_R * p.t_R) * bell1(p, h), 1e-14),
           "S1 servo value");
    const double deep = steric_terms(p, -0.5 * rsum, 0.0, mu, rsum).s1;
    expect(deep <= 2 * mu * p.h_R / (p.t_R * p.t_R) && deep > 0.99 * 2 * mu * p.h_R / (p.t_R * p.t_R), "S1 saturated at h_cap");
    StericParams pd = p;
    pd.s1_damping = true;  // PD servo: the damping term can cancel the push but never attract
    expect(steric_terms(pd, h, 10.0, mu, rsum).s1 == 0.0 && steric_terms(p, h, 10.0, mu, rsum).s1 > 0, "S1 never attracts");
    expect(steric_terms(p, h, -1.0, mu, rsum).s2 > 0 && steric_terms(p, h, 1.0, mu, rsum).s2 == 0, "S2 brakes approach only");
    expect(steric_terms(p, -0.9 * rsum, -1.0, mu, rsum).s3 > 0 && steric_terms(p, -0.9 * rsum, 1.0, mu, rsum).s3 == 0 &&
               steric_terms(p, -1e-9, -1.0, mu, rsum).s3 == 0, "S3 brakes approach in the deepest half only");
    expect(steric_terms(p, -1e-8, 1.0, mu, rsum).s4 < 0 && steric_terms(p, 0.25e-9, 1.0, mu, rsum).s4 == 0 &&
               steric_terms(p, -1e-8, -1.0, mu, rsum).s4 == 0, "S4 brakes separation in the deep steric zone only");
    expect(steric_terms(p, 2e-9, -1.0, mu, rsum).total() == 0.0, "steric zero for h >= h0");
    // C1 of the bells at the ends of their supports
    for (double x : {0.0, p.h_R}) {
      const double e = 1e-15;
      expect(std::fabs(bell1(p, x + e) - bell1(p, x - e)) < 1e-5, "B1 continuous");
    }
  }

  // ---- points per element: point-pair forces summed along two long parallel cylinders match the
  //      parallel-cylinder result at the matching gap (and are within 5 % at 2x / 0.5x that gap)
  {
    const double R = 7e-6, h_match = 1e-9, Le = 2e-5;
    const int n = points_per_element(Le, R, R, h_match);
    const double spacing = Le / n;
    for (double h : {h_match, 2 * h_match}) {
      // fiber 2 at centre distance 2R + h; sum over all points of fiber 2 acting on one point of
      // fiber 1 (closest point only would be the thesis rule; the sum shows the continuum limit)
      const double Fcyl = parallel_cylinders_vdw_per_length(A, R, R, h) * spacing;
      const double Fpt = vdw_force(A, R, R, h);
      const double ratio = Fpt / Fcyl;
      if (h == h_match) expect(std::fabs(ratio - 1) < 0.5 / n + 0.02, "points/element matches parallel cylinders", ratio, 1);
      else expect(ratio > 1.0 && ratio < 1.5, "closest-point sum vs cylinders at 2 h_match", ratio, std::sqrt(2.0));
    }
  }

  std::printf("test_dlvo: %s\n", failures ? "FAILED" : "ok");
  return failures ? 1 : 0;
}
