/* SPDX-License-Identifier: GPL-3.0-or-later
   Steric repulsion between two contact points, thesis (Kettil 2016) eq. 2.34-2.39, with bell
   functions B1..B4 designed here (the thesis' appendix with its own forms is not available; the
   design and its stability argument are in docs/models/contact.md section 3). Pure functions, SI.

   Variables: h surface separation (m); u = dh/dt (m/s, > 0 when the points SEPARATE, < 0 when they
   approach); mu = 1/(1/m1 + 1/m2) reduced mass (kg; m2 = inf allowed); h_min = -(r1 + r2)
   (plane: -r1). Positive force = repulsive. ONE sign convention for all four terms.

     F_S1 = max(0, B1(h) 2 mu (e(h) - c t_R u) / t_R^2)    eq. 2.35: PD servo towards h_R
            e(h) = h_cap tanh((h_R - h)/h_cap)              saturated position error (C-inf),
                                                            ~ h_R - h near h_R, never above h_cap;
            c = 1 (s1_damping yes) or 0 (pure spring)       never attractive (clipped at 0)
     F_S2 = +[u < 0] B2(h) mu u^2 / h_S                     eq. 2.36: brakes APPROACH in the contact
                                                            range (speed decays as exp(-dist/h_S))
     F_S3 = +[u < 0] B3(h) mu u^2 / (|h_min|/1000)          eq. 2.37: brakes approach in the deepest
                                                            half: no pass-through
     F_S4 = -[u > 0] B4(h) mu u^2 / h_S4                    eq. 2.38: brakes SEPARATION in the deep
                                                            steric zone only (h < 0, fully below -h_D):
                                                            caps the push-out speed from any overlap at
                                                            u_t = sqrt(2 h_cap h_S4)/t_R; shallow
                                                            rebounds are left to the DLVO well

   Bells, with the C1 smooth step S(x) = 0 (x <= 0), x^2 (3 - 2x) (0 < x < 1), 1 (x >= 1):
     B1(h) = 1 - S(h / h_R)                         1 for h <= 0, 0 for h >= h_R
     B4(h) = 1 - S((h + h_D) / h_D)                 1 for h <= -h_D, 0 for h >= 0
     B2(h) = 1 - S((h - h_R)/(h0 - h_R))            1 for h <= h_R, 0 for h >= h0
     B3(h) = S((h_min/2 - h)/(|h_min|/2))           0 for h >= h_min/2, 1 at h_min
   [u < 0] u^2 and [u > 0] u^2 are C1 in u, so every term is C1 in (h, u) except S1 at its clip. */
#ifndef FIBERFORM_PHYSICS_STERIC_H
#define FIBERFORM_PHYSICS_STERIC_H

#include <cmath>

namespace fiberform::physics {

inline double smooth_step(double x) {
  if (x <= 0.0) return 0.0;
  if (x >= 1.0) return 1.0;
  return x * x * (3.0 - 2.0 * x);
}

struct StericParams {
  double h0;    // DLVO cut-in separation (m); S2 ends there
  double h_R;   // target separation of the S1 servo (m), 0 < h_R < h0
  double h_S;   // brake length of S2 and S4 (m)
  double t_R;   // servo time of S1 (s)
  double h_cap = 0.0;  // saturation of the S1 position error (m); 0 = h_R
  double h_D = 6e-9;   // depth below which the separation brake S4 is fully on (m)
  double h_S4 = 1e-9;  // brake length of S4 (m)
  bool s1 = true, s2 = true, s3 = true, s4 = true;
  bool s1_damping = false;  // the -t_R u term of S1 (off: a conservative, saturated spring)
  double cap() const { return h_cap > 0.0 ? h_cap : h_R; }
};

inline double bell1(const StericParams &p, double h) { return 1.0 - smooth_step(h / p.h_R); }
inline double bell2(const StericParams &p, double h) {
  return 1.0 - smooth_step((h - p.h_R) / (p.h0 - p.h_R));
}
inline double bell3(double h, double rsum) { return smooth_step((-0.5 * rsum - h) / (0.5 * rsum)); }
inline double bell4(const StericParams &p, double h) { return 1.0 - smooth_step((h + p.h_D) / p.h_D); }
// saturated position error of the servo
inline double servo_error(const StericParams &p, double h) {
  const double c = p.cap();
  return c * std::tanh((p.h_R - h) / c);
}

struct StericTerms {
  double s1, s2, s3, s4;
  double total() const { return s1 + s2 + s3 + s4; }
};

// mu: reduced mass (kg); rsum: r1 + r2 (m), |h_min|.
inline StericTerms steric_terms(const StericParams &p, double h, double u, double mu, double rsum) {
  StericTerms t{0, 0, 0, 0};
  if (h >= p.h0) return t;
  const double u2 = u * u;
  if (u < 0.0) {
    if (p.s2) t.s2 = bell2(p, h) * mu * u2 / p.h_S;
    if (p.s3 && h < -0.5 * rsum) t.s3 = bell3(h, rsum) * mu * u2 / (rsum * 1e-3);
  }
  if (h >= p.h_R) return t;
  if (p.s1) {
    const double damp = p.s1_damping ? p.t_R * u : 0.0;
    const double v = bell1(p, h) * 2.0 * mu * (servo_error(p, h) - damp) / (p.t_R * p.t_R);
    t.s1 = v > 0.0 ? v : 0.0;
  }
  if (p.s4 && u > 0.0 && h < 0.0) t.s4 = -bell4(p, h) * mu * u2 / p.h_S4;
  return t;
}

inline double steric_force(const StericParams &p, double h, double u, double mu, double rsum) {
  return steric_terms(p, h, u, mu, rsum).total();
}

}  // namespace fiberform::physics

#endif
