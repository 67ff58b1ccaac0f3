/* SPDX-License-Identifier: GPL-3.0-or-later
   Fluid forces on a fiber element (Kettil 2016, section 2.3): drag per unit length, eq. 2.14-2.16,
   plus gravity and buoyancy. Pure functions, SI units, no LIGGGHTS dependency.

   Above Re = 400, where eq. 2.15 is no longer stated, C_D is CLAMPED to its value at Re = 400
   (about 1.12): the Newton regime of a circular cylinder, whose measured C_D stays near 1.0-1.2 up
   to Re ~ 1e5. Continuing the last branch instead would let C_D creep up as Re^0.04.
   The branches of eq. 2.15 are used as printed; they do not join continuously (C_D jumps by -2.7%
   at Re = 5 and +12% at Re = 40); see docs/models/drag.md. */
#ifndef FIBERFORM_PHYSICS_DRAG_H
#define FIBERFORM_PHYSICS_DRAG_H

#include <array>
#include <cmath>

namespace fiberform::physics::drag {

using Vec3 = std::array<double, 3>;

/// Largest Reynolds number at which eq. 2.15 is stated; C_D is held constant above it.
inline constexpr double kReMax = 400.0;

/// Reynolds number, eq. 2.16. rho: fluid density (kg/m3); speed: |v_rel| (m/s);
/// diameter: mean diameter of the cross-section (m); mu: dynamic viscosity (Pa s).
inline double reynolds(double rho, double speed, double diameter, double mu) {
  return rho * speed * diameter / mu;
}

/// Drag coefficient, eq. 2.15 (branches Re < 5, 5 <= Re < 40, 40 <= Re <= 400; clamped above 400).
/// Diverges like Re^-0.78 as Re -> 0; callers use drag_per_length(), which is finite there.
inline double drag_coefficient(double Re) {
  if (!(Re > 0.0)) return INFINITY;
  const double re = Re > kReMax ? kReMax : Re;
  const double base = 9.689 / std::pow(re, 0.78);
  if (re < 5.0) return base * (1.0 + 0.147 * std::pow(re, 0.82));
  if (re < 40.0) return base * (1.0 + 0.227 * std::sqrt(re));
  return base * (1.0 + 0.0838 * std::pow(re, 0.82));
}

/// Drag force per unit length on a fiber element, eq. 2.14: f = 0.5 rho C_D d |v_rel| v_rel (N/m).
/// v_rel = u_fluid - v_fiber at the element centre (m/s), so f points along the fluid's relative
/// motion. Zero when v_rel = 0 (the product C_D |v_rel| -> 0 like |v_rel|^0.22).
inline Vec3 drag_per_length(double rho, double mu, double diameter, const Vec3 &v_rel) {
  const double speed = std::sqrt(v_rel[0] * v_rel[0] + v_rel[1] * v_rel[1] + v_rel[2] * v_rel[2]);
  if (speed == 0.0 || diameter <= 0.0) return {0.0, 0.0, 0.0};
  const double cd = drag_coefficient(reynolds(rho, speed, diameter, mu));
  const double k = 0.5 * rho * cd * diameter * speed;
  return {k * v_rel[0], k * v_rel[1], k * v_rel[2]};
}

/// d ln C_D / d ln Re of eq. 2.15, C_D = 9.689 Re^-0.78 (1 + a Re^p) per branch:
/// -0.78 + a p Re^p / (1 + a Re^p); 0 above the clamp (C_D constant there).
inline double drag_coefficient_log_slope(double Re) {
  if (!(Re > 0.0)) return -0.78;
  if (Re > kReMax) return 0.0;
  double a, p;
  if (Re < 5.0) a = 0.147, p = 0.82;
  else if (Re < 40.0) a = 0.227, p = 0.5;
  else a = 0.0838, p = 0.82;
  const double t = a * std::pow(Re, p);
  return -0.78 + p * t / (1.0 + t);
}

/// Jacobian of eq. 2.14 with respect to the relative velocity, df/dv_rel (N s/m^2, per unit
/// length), as the symmetric 3x3 matrix xx yy zz xy xz yz. With f = k(s) u, s = |u|,
/// k = 0.5 rho C_D d s: df/du = k [I + (1 + dlnC_D/dlnRe) u u^T / s^2]. Positive definite
/// (dlnC_D/dlnRe > -1 in every branch). Zero at u = 0, where k -> 0 like s^0.22.
/// A fiber moving at v in a fluid at u_f feels f(u_f - v): -df/dv = df/du.
inline std::array<double, 6> drag_jacobian(double rho, double mu, double diameter, const Vec3 &v_rel) {
  const double s2 = v_rel[0] * v_rel[0] + v_rel[1] * v_rel[1] + v_rel[2] * v_rel[2];
  if (!(s2 > 0.0) || diameter <= 0.0) return {0, 0, 0, 0, 0, 0};
  const double s = std::sqrt(s2);
  const double Re = reynolds(rho, s, diameter, mu);
  const double k = 0.5 * rho * drag_coefficient(Re) * diameter * s;
  const double c = k * (1.0 + drag_coefficient_log_slope(Re)) / s2;
  return {k + c * v_rel[0] * v_rel[0], k + c * v_rel[1] * v_rel[1], k + c * v_rel[2] * v_rel[2],
          c * v_rel[0] * v_rel[1], c * v_rel[0] * v_rel[2], c * v_rel[1] * v_rel[2]};
}

/// Magnitude of eq. 2.14 for a relative speed (N/m).
inline double drag_per_length_magnitude(double rho, double mu, double diameter, double speed) {
  if (speed <= 0.0 || diameter <= 0.0) return 0.0;
  return 0.5 * rho * drag_coefficient(reynolds(rho, speed, diameter, mu)) * diameter * speed * speed;
}

/// Gravity plus buoyancy per unit length of a fiber with solid cross-section area (m2):
/// (rho_fiber - rho_fluid) * area * g (N/m), g the gravity vector (m/s2).
inline Vec3 gravity_buoyancy_per_length(double rho_fiber, double rho_fluid, double area, const Vec3 &g) {
  const double k = (rho_fiber - rho_fluid) * area;
  return {k * g[0], k * g[1], k * g[2]};
}

/// Relative speed at which eq. 2.14 balances a net body force per unit length `load` (N/m, >= 0):
/// the terminal slip speed of a straight fiber element. Bisection on the monotone part; the
/// discontinuities of eq. 2.15 can leave the drag curve non-monotone near Re = 5, in which case the
/// smallest root bracketed from below is returned. Returns 0 for load <= 0.
inline double balance_speed(double rho, double mu, double diameter, double load) {
  if (load <= 0.0) return 0.0;
  double lo = 0.0, hi = 1e-6;
  while (drag_per_length_magnitude(rho, mu, diameter, hi) < load) {
    lo = hi;
    hi *= 2.0;
    if (hi > 1e6) return INFINITY;
  }
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    if (drag_per_length_magnitude(rho, mu, diameter, mid) < load) lo = mid; else hi = mid;
    if (hi - lo <= 1e-15 * hi) break;
  }
  return 0.5 * (lo + hi);
}

}  // namespace fiberform::physics::drag

#endif
