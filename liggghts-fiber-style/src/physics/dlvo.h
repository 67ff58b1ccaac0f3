/* SPDX-License-Identifier: GPL-3.0-or-later
   Extended DLVO force laws between two contact points (spheres of radii r1, r2), thesis
   (Kettil 2016) section 2.4.5. Pure functions, SI units. Sign convention: a positive force is
   REPULSIVE (pushes the surfaces apart); h is the surface separation (m).

   - van der Waals, eq. 2.25 (Derjaguin limit) and the full Hamaker sphere-sphere expression
     eq. 2.23 differentiated analytically (valid when h is not small against the radii);
   - electrostatic, eq. 2.27 with Ohshima's effective surface potential eq. 2.28 and the
     charge-potential relation eq. 2.29 solved by a bracketed Newton iteration;
   - the extension below h0, eq. 2.30-2.33: g(h) = 0 (h <= 0), a h^2 (0 <= h < h0/2),
     b h^2 + c h + d (h0/2 <= h < h0), value and slope matched at h0/2 and h0.
   A partner radius of +infinity (plane wall) is accepted everywhere (sphere-plane limits). */
#ifndef FIBERFORM_PHYSICS_DLVO_H
#define FIBERFORM_PHYSICS_DLVO_H

#include <cmath>
#include <limits>

#include "vec3.h"

namespace fiberform::physics {

namespace constants {
inline constexpr double e = 1.602176634e-19;      // elementary charge, C
inline constexpr double kB = 1.380649e-23;        // Boltzmann constant, J/K
inline constexpr double NA = 6.02214076e23;       // Avogadro constant, 1/mol
inline constexpr double eps0 = 8.8541878128e-12;  // vacuum permittivity, F/m
inline constexpr double pi = kPi;
}  // namespace constants

// r1*r2/(r1+r2), with r2 = +inf giving r1 (sphere-plane).
inline double reduced_radius(double r1, double r2) {
  if (std::isinf(r2)) return r1;
  if (std::isinf(r1)) return r2;
  return r1 * r2 / (r1 + r2);
}

// ---------------------------------------------------------------- van der Waals
// eq. 2.25: F = -A R_eff / (6 h^2); dF/dh = A R_eff / (3 h^3).
inline double vdw_force(double A, double r1, double r2, double h) {
  return -A * reduced_radius(r1, r2) / (6.0 * h * h);
}
inline double vdw_force_slope(double A, double r1, double r2, double h) {
  return A * reduced_radius(r1, r2) / (3.0 * h * h * h);
}

// F = -dV/dh of eq. 2.23 (the Hamaker energy of two spheres; tests/test_dlvo.cpp differentiates
// its own copy of V numerically) and its slope dF/dh, analytic. For r2 = inf the sphere-plane limit
// F = -A r1 / 6 * [1/h^2 - 1/(h+2r1)^2] - ... is used (Hamaker sphere-plate, V = -A/6[r/h + r/(h+2r)
// + ln(h/(h+2r))]).
struct ForceAndSlope {
  double force;
  double slope;
};
inline ForceAndSlope hamaker_force(double A, double r1, double r2, double h) {
  if (std::isinf(r2) || std::isinf(r1)) {
    const double r = std::isinf(r2) ? r1 : r2;
    // V = -A/6 [ r/h + r/(h+2r) + ln(h/(h+2r)) ]
    const double q = h + 2 * r;
    const double dV = -A / 6.0 * (-r / (h * h) - r / (q * q) + 1.0 / h - 1.0 / q);
    const double d2V = -A / 6.0 * (2 * r / (h * h * h) + 2 * r / (q * q * q) - 1.0 / (h * h) + 1.0 / (q * q));
    return {-dV, -d2V};
  }
  const double K = 2 * r1 * r2, a = 2 * r1, b = 2 * r2, c = a + b;
  // T(u) = K/u with u quadratic in h; T' = -K u'/u^2; T'' = -K (u u'' - 2 u'^2)/u^3, u'' = 2.
  auto t_derivs = [K](double u, double up, double &d1, double &d2) {
    d1 = -K * up / (u * u);
    d2 = -K * (2.0 * u - 2.0 * up * up) / (u * u * u);
  };
  double t1, t1p, t2, t2p;
  t_derivs(h * (h + c), 2 * h + c, t1, t1p);
  t_derivs((h + a) * (h + b), 2 * h + a + b, t2, t2p);
  const double t3 = 1.0 / h + 1.0 / (h + c) - 1.0 / (h + a) - 1.0 / (h + b);
  const double t3p = -1.0 / (h * h) - 1.0 / ((h + c) * (h + c)) + 1.0 / ((h + a) * (h + a)) +
                     1.0 / ((h + b) * (h + b));
  // V = -A/6 (T1+T2+T3)  =>  F = -V' = A/6 (T1'+T2'+T3'), F' = A/6 (T1''+T2''+T3'')
  return {A / 6.0 * (t1 + t2 + t3), A / 6.0 * (t1p + t2p + t3p)};
}

// ---------------------------------------------------------------- electrolyte
// Inverse Debye length kappa (1/m) of a symmetric z:z electrolyte of ionic strength I (mol/m^3;
// 1 mM = 1 mol/m^3), absolute temperature T (K), relative permittivity eps_r:
//   kappa^2 = 2 NA e^2 I / (eps_r eps0 kB T).   (I = z^2 c for a z:z salt of concentration c.)
inline double inverse_debye_length(double ionic_strength, double temperature, double eps_r) {
  using namespace constants;
  return std::sqrt(2.0 * NA * e * e * ionic_strength / (eps_r * eps0 * kB * temperature));
}

// Reduced potential y = z e psi / (kB T).
inline double reduced_potential(double psi, double z, double temperature) {
  return z * constants::e * psi / (constants::kB * temperature);
}

// eq. 2.29 (Ohshima, Healy & White): reduced surface charge of a sphere of radius r,
//   s = z e sigma / (eps kappa kB T) = 2 sinh(y/2) + 4/(kappa r) tanh(y/4).
inline double reduced_charge_from_potential(double y, double kappa_r) {
  const double curv = std::isinf(kappa_r) ? 0.0 : 4.0 / kappa_r;
  return 2.0 * std::sinh(0.5 * y) + curv * std::tanh(0.25 * y);
}
inline double reduced_charge(double sigma, double z, double kappa, double temperature, double eps_r) {
  using namespace constants;
  return z * e * sigma / (eps_r * eps0 * kappa * kB * temperature);
}

// Inverse of eq. 2.29: y such that reduced_charge_from_potential(y, kappa_r) = s. The function is
// odd and strictly increasing, so y lies in [0, 2 asinh(s/2)] for s >= 0 (the tanh term is >= 0);
// Newton steps are kept inside that bracket (bisection fallback), converging to machine precision.
inline double potential_from_reduced_charge(double s, double kappa_r) {
  if (s == 0.0) return 0.0;
  const double sign = s < 0 ? -1.0 : 1.0;
  s = std::fabs(s);
  double lo = 0.0, hi = 2.0 * std::asinh(0.5 * s);
  const double curv = std::isinf(kappa_r) ? 0.0 : 4.0 / kappa_r;
  double y = hi;
  for (int it = 0; it < 200; ++it) {
    const double f = reduced_charge_from_potential(y, kappa_r) - s;
    if (f > 0) hi = y; else lo = y;
    const double th = std::tanh(0.25 * y);
    const double df = std::cosh(0.5 * y) + curv * 0.25 * (1.0 - th * th);
    double ynew = y - f / df;
    if (!(ynew > lo && ynew < hi)) ynew = 0.5 * (lo + hi);
    if (std::fabs(ynew - y) <= 1e-15 * std::fabs(ynew) || hi - lo <= 1e-15 * hi) { y = ynew; break; }
    y = ynew;
  }
  return sign * y;
}

// eq. 2.28 (Ohshima): effective reduced surface potential of a sphere, kappa_r = kappa*r:
//   Y = 8 tanh(y/4) / (1 + sqrt(1 - (2 kr + 1)/(kr + 1)^2 tanh^2(y/4))).
// The thesis prints tanh without the square; Ohshima's original (and the symmetry Y(-y) = -Y(y))
// has tanh^2, which is used here. Limits: Y -> y for small y; Y -> 4 tanh(y/4) for kr -> inf.
inline double effective_surface_potential(double y, double kappa_r) {
  const double t = std::tanh(0.25 * y);
  const double g = std::isinf(kappa_r) ? 0.0 : (2.0 * kappa_r + 1.0) / ((kappa_r + 1.0) * (kappa_r + 1.0));
  return 8.0 * t / (1.0 + std::sqrt(1.0 - g * t * t));
}

// eq. 2.27 (Bell, Levine & McCartney): electrostatic force between spheres, repulsive positive,
//   F = 4 pi eps (kB T/(z e))^2 Y1 Y2 r1 r2/R^2 (1 + kappa R) exp(-kappa h),  R = h + r1 + r2.
// For r2 = inf (plane): r2 (1 + kappa R)/R^2 -> kappa, F = 4 pi eps (kT/ze)^2 Y1 Y2 kappa r1 e^{-kh}.
struct ElectrostaticParams {
  double eps;    // permittivity of the liquid, F/m (eps_r*eps0)
  double kT_e;   // kB T / (z e), V
  double kappa;  // 1/m
};
inline ForceAndSlope electrostatic_force(const ElectrostaticParams &p, double Y1, double Y2, double r1,
                                         double r2, double h) {
  const double pref = 4.0 * constants::pi * p.eps * p.kT_e * p.kT_e * Y1 * Y2;
  const double ex = std::exp(-p.kappa * h);
  if (std::isinf(r2) || std::isinf(r1)) {
    const double r = std::isinf(r2) ? r1 : r2;
    const double F = pref * p.kappa * r * ex;
    return {F, -p.kappa * F};
  }
  const double R = h + r1 + r2;
  const double g = r1 * r2 * (1.0 + p.kappa * R) / (R * R);
  const double gp = r1 * r2 * (p.kappa / (R * R) - 2.0 * (1.0 + p.kappa * R) / (R * R * R));
  return {pref * g * ex, pref * ex * (gp - p.kappa * g)};
}

// ---------------------------------------------------------------- extension below h0 (eq. 2.32)
// Coefficients from the four conditions of eq. 2.33 (value F0 and slope S0 of the formula at h0;
// g continuous with continuous slope at h0/2; g(0) = g'(0) = 0 holds by construction):
//   a = 2 F0/h0^2 - S0/(2 h0)     b = 3 S0/(2 h0) - 2 F0/h0^2
//   c = 4 F0/h0 - 2 S0            d = S0 h0/2 - F0
struct Spline {
  double a, b, c, d, h0;
};
inline Spline make_spline(double F0, double S0, double h0) {
  return {2.0 * F0 / (h0 * h0) - S0 / (2.0 * h0), 1.5 * S0 / h0 - 2.0 * F0 / (h0 * h0),
          4.0 * F0 / h0 - 2.0 * S0, 0.5 * S0 * h0 - F0, h0};
}
// g(h) for h < h0 (0 for h <= 0).
inline double spline_value(const Spline &s, double h) {
  if (h <= 0.0) return 0.0;
  if (h < 0.5 * s.h0) return s.a * h * h;
  return (s.b * h + s.c) * h + s.d;
}
inline double spline_slope(const Spline &s, double h) {
  if (h <= 0.0) return 0.0;
  if (h < 0.5 * s.h0) return 2.0 * s.a * h;
  return 2.0 * s.b * h + s.c;
}

}  // namespace fiberform::physics

#endif
