/* SPDX-License-Identifier: GPL-3.0-or-later
   Steric repulsion between two contact points, thesis (Kettil 2016) eq. 2.34-2.39, with bell
   functions B1..B4 designed here (the thesis' appendix with its own forms is not available; the
   design and its stability argument are in docs/models/contact.md). Pure functions, SI units.

   Variables: h surface separation (m); u = dh/dt (m/s, > 0 when the points SEPARATE);
   mu = 1/(1/m1 + 1/m2) reduced mass (kg; m2 = inf allowed); h_min = -(r1 + r2).
   Sign convention: positive force = repulsive.

     F_S1 =  max(0, B1(h) * 2 mu (h_R - h - t_R u) / t_R^2)   servo: reach h_R in t_R
     F_S2 = -B2(h) * mu u|u| / h_S                              quadratic brake inside the overlap,
                                                                B2 -> inf at h_min: no pass-through
     F_S3 = -B3(h,u) * mu u|u| / (|h_min|/1000)                 strong brake on SEPARATION in deep
                                                                overlap (u > 0 only)
     F_S4 = -B4(h,u) * mu u|u| / h_S                            mild brake on separation between
                                                                h_R and h0 (u > 0 only)
   Note on signs: the thesis writes the S1 bracket as (h_R - h - t_R v~) and S2-S4 as +v~|v~|;
   one sign convention for v~ cannot make both the S1 target ("reach h_R in t_R") and the S2
   purpose ("prevent passing through") come out right, so u = dh/dt is used and the signs are
   chosen by the stated purposes.

   Bell functions, with the C1 smooth step S(x) = 0 (x <= 0), x^2 (3 - 2x) (0 < x < 1), 1 (x >= 1):
     B1(h)   = 1 - S(h / h_R)                         1 for h <= 0, 0 for h >= h_R
     B2(h)   = S(-h / h_S) * (r1 + r2) / (h - h_min)  0 for h >= 0, ~1 at h = -h_S, grows as
                                                      (r1+r2)/(h - h_min) towards h_min
     B3(h,u) = [u > 0] S(-h / h_S)                    deep-overlap band, separating only
     B4(h,u) = [u > 0] S(h / h_R) (1 - S((h - h_R)/(h0 - h_R)))   between h_R and h0, separating
   The factor [u > 0] multiplies u|u| = u^2, so F_S3, F_S4 stay C1 in u. */
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
  double h0;    // DLVO cut-in separation (m); B4 ends there
  double h_R;   // target separation of the S1 servo (m), 0 < h_R < h0
  double h_S;   // brake length of S2 and S4 (m)
  double t_R;   // servo time of S1 (s)
  bool s1 = true, s2 = true, s3 = true, s4 = true;
  bool s1_damping = true;  // the -t_R u term of S1 (off: a conservative spring)
};

inline double bell1(const StericParams &p, double h) { return 1.0 - smooth_step(h / p.h_R); }
inline double bell2(const StericParams &p, double h, double rsum) {
  if (h >= 0.0) return 0.0;
  const double d = h + rsum;  // distance to h_min
  const double floor_d = 1e-9 * rsum;
  return smooth_step(-h / p.h_S) * rsum / (d > floor_d ? d : floor_d);
}
inline double bell3(const StericParams &p, double h, double u) {
  return u > 0.0 ? smooth_step(-h / p.h_S) : 0.0;
}
inline double bell4(const StericParams &p, double h, double u) {
  if (u <= 0.0) return 0.0;
  return smooth_step(h / p.h_R) * (1.0 - smooth_step((h - p.h_R) / (p.h0 - p.h_R)));
}

struct StericTerms {
  double s1, s2, s3, s4;
  double total() const { return s1 + s2 + s3 + s4; }
};

// mu: reduced mass (kg); rsum: r1 + r2 (m).
inline StericTerms steric_terms(const StericParams &p, double h, double u, double mu, double rsum) {
  StericTerms t{0, 0, 0, 0};
  if (h >= p.h0) return t;
  if (p.s1) {
    const double damp = p.s1_damping ? p.t_R * u : 0.0;
    const double v = bell1(p, h) * 2.0 * mu * (p.h_R - h - damp) / (p.t_R * p.t_R);
    t.s1 = v > 0.0 ? v : 0.0;
  }
  const double uu = u * std::fabs(u);
  if (p.s2) t.s2 = -bell2(p, h, rsum) * mu * uu / p.h_S;
  if (p.s3) t.s3 = -bell3(p, h, u) * mu * uu / (rsum / 1000.0);
  if (p.s4) t.s4 = -bell4(p, h, u) * mu * uu / p.h_S;
  return t;
}

inline double steric_force(const StericParams &p, double h, double u, double mu, double rsum) {
  return steric_terms(p, h, u, mu, rsum).total();
}

}  // namespace fiberform::physics

#endif
