/* SPDX-License-Identifier: GPL-3.0-or-later
   Coulomb friction of a sub-integrated (averaged) contact point against a body of known motion, at
   the velocity level (fix wall/fiber/yarns and fix wall/fiber/dlvo, averaged contacts;
   docs/models/contact.md). Pure function, SI units.

   The tangential force that would stop the point's tangential motion relative to the body over the
   next step (cancelling its other tangential forces) is applied if it is within mu * fn (stick),
   else mu * fn along it (slip). Inside the implicit step (implicit_force newton) the Coulomb law
   acts regularised (regularized_friction_secant) through BodyContactModel (physics/static_bodies.h)
   and ClusterContactModel (physics/fiber_partners.h) instead. */
#ifndef FIBERFORM_PHYSICS_FRICTION_H
#define FIBERFORM_PHYSICS_FRICTION_H

#include <cmath>

namespace fiberform::physics {

// v: the point's velocity relative to the body (m/s), a: its other forces per mass (m/s^2), n: unit
// normal of the contact, inv_m: the point's inverse effective mass (1/kg), gamma_dt: the scheme's
// gamma_eff times the step (s; explicit: dt), limit: mu * fn (N, >= 0). Writes the stick force (N)
// to ft and returns the factor in [0, 1] that scales it to the applied force (1: stick).
inline double coulomb_stick_slip(const double v[3], const double a[3], const double n[3], double inv_m,
                               double gamma_dt, double limit, double ft[3]) {
  double vn = 0.0, an = 0.0;
  for (int k = 0; k < 3; ++k) {
    vn += v[k] * n[k];
    an += a[k] * n[k];
  }
  double ft2 = 0.0;
  for (int k = 0; k < 3; ++k) {
    ft[k] = -((v[k] - vn * n[k]) / gamma_dt + (a[k] - an * n[k])) / inv_m;
    ft2 += ft[k] * ft[k];
  }
  return ft2 > limit * limit ? limit / std::sqrt(ft2) : 1.0;
}

// Inside the implicit step (implicit_force newton): Coulomb friction regularised at the velocity
// scale where it stops the contact point within a step. The secant coefficient (N s/m) of
// f_t = -c v_t: c = mu f / sqrt(|v_t|^2 + v_eps^2), v_eps = mu f / c_stick, c_stick = stick m / h
// (mu: coefficient, f: compressive normal force (N), vt2: |v_t|^2 (m^2/s^2), inv_m: the contact's
// reduced inverse mass (1/kg), stick: the stick damping factor, h: the step (s)). A stuck point
// creeps at |f_t| / c_stick. 0 without friction, without a compressive force or without a step.
// Shared by the static bodies (BodyContactModel) and the fiber-fiber clusters (ClusterContactModel).
inline double regularized_friction_secant(double mu, double f, double vt2, double inv_m, double stick, double h) {
  if (!(mu > 0.0 && f > 0.0 && h > 0.0 && inv_m > 0.0)) return 0.0;
  const double c_stick = stick / (inv_m * h);
  const double v_eps = mu * f / c_stick;
  return mu * f / std::sqrt(vt2 + v_eps * v_eps);
}

}  // namespace fiberform::physics

#endif
