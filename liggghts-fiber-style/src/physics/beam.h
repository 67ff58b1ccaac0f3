/* SPDX-License-Identifier: GPL-3.0-or-later
   Geometrically exact (Simo-Reissner / Cosserat) rod element: pure functions, SI units.

   Used by fix fiber/beam (fix_fiber_beam.cpp); unit-tested in tests/test_beam.cpp.
   The formulation is documented in docs/models/beam.md. Summary:

   * A fiber is a chain of nodes; node k carries a position x_k and a unit quaternion q_k whose
     rotation matrix R_k maps the body basis (e1, e2, e3) to the cross-section frame
     (t1, t2, t3) (thesis eq. 2.7, Lambda = R). t3 is the fiber tangent, t1/t2 principal axes.
   * Element A-B (reference length L0). Relative rotation vector theta = log(q_A^* q_B)
     (R_A^T R_B = exp(theta^)); mid-element rotation R_m = R_A exp(theta^/2) (geodesic midpoint).
     Strains (thesis eq. 2.10, one-point quadrature):
         Gamma = R_m^T (x_B - x_A) / L0 - e3 - Gamma0      (shear 1, shear 2, axial)
         kappa = theta / L0 - kappa0                       (bending 1, bending 2, twist)
     Gamma0, kappa0 are the strains of the stress-free (generated, possibly curved) reference.
   * Stored energy (thesis eq. 2.13), C = diag(GA1, GA2, EA, EI1, EI2, GJ):
         U = L0/2 * (Gamma . C_G Gamma + kappa . C_K kappa)
   * Nodal forces and torques are the EXACT negative variations of U (with spatial virtual
     rotations delta R = alpha^ R), using the left Jacobian J_l of SO(3):
         n = R_m C_G Gamma,  F_A = +n,  F_B = -n
         m = R_A J_l(theta)^-T C_K kappa              (bending/torsion couple)
         u = d x n,  P u = 1/2 R_A J_l(theta)^-T J_l(theta/2)^T R_A^T u
         T_A = u - P u + m,  T_B = P u - m
     so the discrete system is conservative (energy test) and objective (no force under rigid
     rotation). Small-rotation limit: T_A = T_B = d x n / 2 +- m (the familiar linear element).
   * Optional Kelvin-Voigt material damping (stiffness proportional, time constant t_d):
     N_d = t_d C_G dGamma/dt, M_d = t_d C_K dkappa/dt with the objective strain rates
     dGamma/dt = R_m^T (v_B - v_A - w_m x d) / L0, dkappa/dt = R_m^T (w_B - w_A) / L0, w_m = mean.
     It dissipates only deformation; rigid motion is undamped.

   Sources: J.C. Simo, L. Vu-Quoc, Comput. Methods Appl. Mech. Eng. 58 (1986) 79-116 and 66 (1988)
   125-161 (finite-strain rod); T.D. Barfoot, State Estimation for Robotics (2017) ch. 7 (SO(3)
   Jacobians); A. Dullweber, B. Leimkuhler, R. McLachlan, J. Chem. Phys. 107 (1997) 5840 (symplectic
   splitting for rigid-body rotation); T. Belytschko, W.K. Liu, B. Moran, Nonlinear Finite Elements
   (2000) sec. 6.3 (element eigenvalue bound for the critical time step). */
#ifndef FIBERFORM_PHYSICS_BEAM_H
#define FIBERFORM_PHYSICS_BEAM_H

#include <algorithm>
#include <cmath>

#include "vec3.h"

namespace fiberform::physics::beam {

using physics::kPi;

// ------------------------------------------------------------------------------------------
// small vector / quaternion algebra
// ------------------------------------------------------------------------------------------
using physics::Vec3;
using physics::cross;
using physics::dot;
using physics::hadamard;
using physics::norm;
using physics::operator+;
using physics::operator-;
using physics::operator*;
using physics::Mat3;

struct Quat {
  double w = 1, x = 0, y = 0, z = 0;
};
inline Quat qmul(Quat a, Quat b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}
inline Quat qconj(Quat a) { return {a.w, -a.x, -a.y, -a.z}; }
inline Quat qnormalize(Quat a) {
  const double n = std::sqrt(a.w * a.w + a.x * a.x + a.y * a.y + a.z * a.z);
  return {a.w / n, a.x / n, a.y / n, a.z / n};
}
// rotate a body vector into space: R(q) v
inline Vec3 qrot(Quat q, Vec3 v) {
  const Vec3 u{q.x, q.y, q.z};
  const Vec3 t = 2.0 * cross(u, v);
  return v + q.w * t + cross(u, t);
}
// space -> body: R(q)^T v
inline Vec3 qrot_t(Quat q, Vec3 v) { return qrot(qconj(q), v); }
// the rotation matrix R(q) (columns R e_j; the same map as qrot to rounding)
inline Mat3 rotation_matrix(Quat q) {
  const double xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z, xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
  const double wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  return {{{1 - 2 * (yy + zz), 2 * (xy + wz), 2 * (xz - wy)},
           {2 * (xy - wz), 1 - 2 * (xx + zz), 2 * (yz + wx)},
           {2 * (xz + wy), 2 * (yz - wx), 1 - 2 * (xx + yy)}}};
}

// exp: rotation vector -> unit quaternion
inline Quat qexp(Vec3 th) {
  const double a = norm(th);
  const double h = 0.5 * a;
  // sin(h)/a with a series below 1e-4 (error < 1e-18)
  const double s = a < 1e-4 ? 0.5 - a * a / 48.0 : std::sin(h) / a;
  return {std::cos(h), s * th.x, s * th.y, s * th.z};
}
// log: unit quaternion -> rotation vector of angle in [0, pi] (shortest rotation)
inline Vec3 qlog(Quat q) {
  if (q.w < 0) q = {-q.w, -q.x, -q.y, -q.z};
  const Vec3 v{q.x, q.y, q.z};
  const double s = norm(v);
  if (s < 1e-8) {
    // angle = 2 atan2(s, w) ~ 2 s / w (1 - s^2/(3 w^2))
    const double f = 2.0 / q.w * (1.0 - s * s / (3.0 * q.w * q.w));
    return f * v;
  }
  const double ang = 2.0 * std::atan2(s, q.w);
  return (ang / s) * v;
}
// unit quaternion from the columns of a rotation matrix given as three orthonormal vectors
inline Quat quat_from_frame(Vec3 t1, Vec3 t2, Vec3 t3) {
  const double m00 = t1.x, m10 = t1.y, m20 = t1.z;
  const double m01 = t2.x, m11 = t2.y, m21 = t2.z;
  const double m02 = t3.x, m12 = t3.y, m22 = t3.z;
  const double tr = m00 + m11 + m22;
  Quat q;
  if (tr > 0) {
    const double s = 2.0 * std::sqrt(tr + 1.0);
    q = {0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s};
  } else if (m00 > m11 && m00 > m22) {
    const double s = 2.0 * std::sqrt(1.0 + m00 - m11 - m22);
    q = {(m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s};
  } else if (m11 > m22) {
    const double s = 2.0 * std::sqrt(1.0 + m11 - m00 - m22);
    q = {(m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s};
  } else {
    const double s = 2.0 * std::sqrt(1.0 + m22 - m00 - m11);
    q = {(m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s};
  }
  return qnormalize(q);
}

// SO(3) left Jacobian J_l(th) v and the products with its inverse / transposes.
// J_l = I + a th^ + b th^2, a = (1 - cos f)/f^2, b = (f - sin f)/f^3, f = |th|.
// J_l^-1 = I - th^/2 + c th^2, c = (1 - f sin f / (2 (1 - cos f))) / f^2.
struct JacobianCoeffs {
  double a, b, c;
};
inline JacobianCoeffs jacobian_coeffs(double f) {
  if (f < 1e-3) {
    const double f2 = f * f;
    return {0.5 - f2 / 24.0, 1.0 / 6.0 - f2 / 120.0, 1.0 / 12.0 + f2 / 720.0};
  }
  const double f2 = f * f;
  return {(1.0 - std::cos(f)) / f2, (f - std::sin(f)) / (f2 * f),
          (1.0 - f * std::sin(f) / (2.0 * (1.0 - std::cos(f)))) / f2};
}
// M v for M = I + s1 th^ + s2 th^2 (th^ v = th x v)
inline Vec3 apply_so3(Vec3 th, double s1, double s2, Vec3 v) {
  const Vec3 tv = cross(th, v);
  return v + s1 * tv + s2 * cross(th, tv);
}
// the same operator as a matrix: I + s1 th^ + s2 th^2 (th^2 = th th^T - |th|^2 I)
inline Mat3 so3_matrix(Vec3 th, double s1, double s2) {
  return identity3() + s1 * skew(th) + s2 * (outer(th, th) - dot(th, th) * identity3());
}
// transposes flip the sign of the odd term
inline Vec3 jl(Vec3 th, Vec3 v) { const auto k = jacobian_coeffs(norm(th)); return apply_so3(th, k.a, k.b, v); }
inline Vec3 jl_t(Vec3 th, Vec3 v) { const auto k = jacobian_coeffs(norm(th)); return apply_so3(th, -k.a, k.b, v); }
inline Vec3 jl_inv(Vec3 th, Vec3 v) { const auto k = jacobian_coeffs(norm(th)); return apply_so3(th, -0.5, k.c, v); }
inline Vec3 jl_inv_t(Vec3 th, Vec3 v) { const auto k = jacobian_coeffs(norm(th)); return apply_so3(th, 0.5, k.c, v); }

// ------------------------------------------------------------------------------------------
// cross-section (thesis sec. 3.4): hollow ellipse, outer semi-axes a1 (along t1), a2 (along t2),
// inner semi-axes b1, b2 (b = 0: solid). Circular: a1 = a2 = w; collapsed: a1 = 0.8 w, a2 = 0.2 w.
// ------------------------------------------------------------------------------------------
struct Section {
  double A;   // area, m^2
  double I1;  // second moment about the t1 axis (bending that moves the fiber along t2), m^4
  double I2;  // second moment about the t2 axis, m^4
  double J;   // St-Venant torsion constant, m^4
  double Ip;  // polar second moment I1 + I2 (torsional rotary inertia per density), m^4
};
// J of a solid ellipse: pi a^3 b^3 / (a^2 + b^2) (exact). Hollow: J_outer - J_inner, which is
// exact for similar ellipses (b1/a1 = b2/a2, including the hollow circle) and an approximation
// otherwise (documented in docs/models/beam.md).
inline double ellipse_torsion(double a, double b) {
  if (a <= 0 || b <= 0) return 0.0;
  return kPi * a * a * a * b * b * b / (a * a + b * b);
}
// The area of the hollow elliptical section (m^2): outer half-axes a1, a2, inner b1, b2.
inline double hollow_ellipse_area(double a1, double a2, double b1, double b2) { return kPi * (a1 * a2 - b1 * b2); }
// An element's section radii a1, a2, b1, b2 (m): those of its two nodes averaged.
inline void element_radii(const double ri[4], const double rj[4], double r[4]) {
  for (int k = 0; k < 4; ++k) r[k] = 0.5 * (ri[k] + rj[k]);
}
inline Section hollow_ellipse(double a1, double a2, double b1, double b2) {
  Section s{};
  s.A = hollow_ellipse_area(a1, a2, b1, b2);
  s.I1 = 0.25 * kPi * (a1 * a2 * a2 * a2 - b1 * b2 * b2 * b2);
  s.I2 = 0.25 * kPi * (a1 * a1 * a1 * a2 - b1 * b1 * b1 * b2);
  s.J = ellipse_torsion(a1, a2) - ellipse_torsion(b1, b2);
  s.Ip = s.I1 + s.I2;
  return s;
}
inline bool section_valid(double a1, double a2, double b1, double b2) {
  return a1 > 0 && a2 > 0 && b1 >= 0 && b2 >= 0 && b1 < a1 && b2 < a2 && std::isfinite(a1 * a2 * b1 * b2);
}

// Elasticity tensor diagonal of eq. 2.13: (GA1, GA2, EA) and (EI1, EI2, GJ).
struct Stiffness {
  Vec3 CG;  // GA1, GA2, EA (N)
  Vec3 CK;  // EI1, EI2, GJ (N m^2)
};
// kshear: shear correction factor (Timoshenko); stiff_scale multiplies EA, GA1, GA2 only.
inline Stiffness section_stiffness(const Section &s, double E, double G, double kshear,
                                   double stiff_scale = 1.0) {
  return {{stiff_scale * kshear * G * s.A, stiff_scale * kshear * G * s.A, stiff_scale * E * s.A},
          {E * s.I1, E * s.I2, G * s.J}};
}

// ------------------------------------------------------------------------------------------
// element
// ------------------------------------------------------------------------------------------
struct ElementRef {
  double L0 = 0;  // reference length, m
  Vec3 gamma0;    // reference (material) strain Gamma0
  Vec3 kappa0;    // reference curvature/twist kappa0, 1/m
};
struct ElementForces {
  Vec3 fA, fB;  // forces on the nodes, N
  Vec3 tA, tB;  // torques on the nodes (space frame), N m
  double energy = 0;  // stored energy, J
  double dissipation = 0;  // damping power (>= 0), W
};

// Derivatives of an element's nodal forces and torques (space frame) with respect to the chord
// d = x_B - x_A, the only way the translations enter them: column j is d(.)/d d_j. Since
// f_B = -f_A, its derivative is minus dfA. Used for the translational columns of the implicit
// element tangent (physics/implicit_rod.h), unit-tested against finite differences.
struct ElementChordGradient {
  Vec3 dfA[3], dtA[3], dtB[3];
  // Derivatives with respect to body-frame right rotations of the nodes' frames, q_A -> q_A exp(e_j)
  // (rotA) and q_B -> q_B exp(e_j) (rotB), of f_A, t_A, t_B (space frame; f_B = -f_A). Filled
  // when the element is elastic (t_damp = 0; with damping has_rot is false).
  bool has_rot = false;
  Vec3 rA_dfA[3], rA_dtA[3], rA_dtB[3];
  Vec3 rB_dfA[3], rB_dtA[3], rB_dtB[3];
};

struct NodeState {
  Vec3 x;  // position
  Quat q;  // frame
  Vec3 v;  // velocity (damping only)
  Vec3 w;  // angular velocity, space frame (damping only)
};

// The relative rotation of an element and every SO(3) quantity its forces need, from one atan2
// and square roots. With q = q_A^* q_B = (cos(f/2), sin(f/2) n) (sign chosen so that w >= 0):
// theta = log(q) (as qlog), exp(theta/2) = sqrt(q) = (c, v / (2c)) with c = sqrt((1 + w)/2), and
// the coefficients of J_l at f and at f/2 from cos f = 1 - 2 s^2, sin f = 2 s w, cos(f/2) = w,
// sin(f/2) = s (s = |v|): the same values as qexp(theta/2) and jacobian_coeffs(f),
// jacobian_coeffs(f/2) to rounding (tests/test_beam.cpp), without their six sin/cos calls.
struct RelativeRotation {
  Vec3 th;               // theta, |theta| = f in [0, pi]
  Quat half;             // exp(theta/2): the mid rotation is q_A half
  JacobianCoeffs k;      // of J_l(theta)
  JacobianCoeffs k_half; // of J_l(theta/2)
  double sin_h = 0, cos_h = 1;  // sin(f/2), cos(f/2) (the relative quaternion's |v| and w)
};
inline RelativeRotation relative_rotation(Quat qA, Quat qB) {
  Quat q = qmul(qconj(qA), qB);
  if (q.w < 0) q = {-q.w, -q.x, -q.y, -q.z};
  RelativeRotation r;
  r.th = qlog(q);
  const Vec3 v{q.x, q.y, q.z};
  const double s = norm(v), w = q.w;
  r.sin_h = s;
  r.cos_h = w;
  const double c = std::sqrt(0.5 * (1.0 + w));  // cos(f/4), w >= 0: c >= 1/sqrt(2)
  r.half = {c, 0.5 / c * q.x, 0.5 / c * q.y, 0.5 / c * q.z};
  const double f = norm(r.th);
  if (f < 1e-3) {
    r.k = jacobian_coeffs(f);  // series: no trig either
  } else {
    const double f2 = f * f;
    r.k = {2.0 * s * s / f2, (f - 2.0 * s * w) / (f2 * f), (1.0 - 0.5 * f * w / s) / f2};
  }
  const double g = 0.5 * f;
  if (g < 1e-3) {
    r.k_half = jacobian_coeffs(g);
  } else {
    const double g2 = g * g, one_minus_w = s * s / (1.0 + w);  // 1 - cos g without cancellation
    r.k_half = {one_minus_w / g2, (g - s) / (g2 * g), (1.0 - 0.5 * g * s / one_minus_w) / g2};
  }
  return r;
}

// J_l(theta)^-T v, J_l(theta)^-1 v and J_l(theta/2)^T v with the coefficients of a RelativeRotation
// (the same operators as jl_inv_t, jl_inv and jl_t(theta/2, v), without recomputing them)
inline Vec3 jl_inv_t(const RelativeRotation &r, Vec3 v) { return apply_so3(r.th, 0.5, r.k.c, v); }
inline Vec3 jl_inv(const RelativeRotation &r, Vec3 v) { return apply_so3(r.th, -0.5, r.k.c, v); }
inline Vec3 jl_half_t(const RelativeRotation &r, Vec3 v) {
  return apply_so3(0.5 * r.th, -r.k_half.a, r.k_half.b, v);
}

// a'(f)/f, b'(f)/f, c'(f)/f of the J_l coefficients (JacobianCoeffs), by series below 0.05 rad
// (truncation < 1e-12 relative) and closed forms above (cancellation < 1e-11 relative there):
// a = (1 - cos f)/f^2, b = (f - sin f)/f^3, c = (1 - g)/f^2 with g = (f/2) cot(f/2). The closed
// forms take sin(f/2) and cos(f/2) (sin f = 2 sh ch, 1 - cos f = 2 sh^2): a relative rotation
// has them without trigonometric calls (RelativeRotation).
inline JacobianCoeffs jacobian_coeff_slopes(double f, double sh, double ch) {
  const double f2 = f * f;
  if (f < 0.05)
    return {-1.0 / 12.0 + f2 / 180.0 - f2 * f2 / 6720.0, -1.0 / 60.0 + f2 / 1260.0 - f2 * f2 / 60480.0,
            1.0 / 360.0 + f2 / 7560.0 + f2 * f2 / 201600.0};
  const double sf = 2.0 * sh * ch, one_minus_cf = 2.0 * sh * sh, f3 = f2 * f, f4 = f2 * f2;
  const double cot = ch / sh;  // cot(f/2)
  const double g = 0.5 * f * cot, dg = 0.5 * cot - 0.25 * f / (sh * sh);
  const double c = (1.0 - g) / f2;
  return {sf / f3 - 2.0 * one_minus_cf / f4, one_minus_cf / f4 - 3.0 * (f - sf) / (f4 * f), -dg / f3 - 2.0 * c / f2};
}
inline JacobianCoeffs jacobian_coeff_slopes(double f) {
  return jacobian_coeff_slopes(f, std::sin(0.5 * f), std::cos(0.5 * f));
}

// Reference strains of an element from its stress-free configuration.
inline ElementRef element_reference(Vec3 xA, Quat qA, Vec3 xB, Quat qB) {
  ElementRef r;
  const RelativeRotation rr = relative_rotation(qA, qB);
  const Quat qm = qmul(qA, rr.half);  // mid rotation
  const Vec3 d = xB - xA;
  r.L0 = norm(d);
  r.gamma0 = (1.0 / r.L0) * qrot_t(qm, d) - Vec3{0, 0, 1};
  r.kappa0 = (1.0 / r.L0) * rr.th;
  return r;
}

// The matrices both gradients share: R_A, R_m, J_l^-T(theta), J_l^T(theta/2), W and P = R_A W R_A^T.
struct ElementGradientFrames {
  Mat3 RA, Rm, Jt, Jh, W, P;
};
inline ElementGradientFrames element_gradient_frames(Quat qA, Quat qm, const RelativeRotation &rr) {
  ElementGradientFrames F;
  F.RA = rotation_matrix(qA);
  F.Rm = rotation_matrix(qm);
  F.Jt = so3_matrix(rr.th, 0.5, rr.k.c);
  F.Jh = so3_matrix(0.5 * rr.th, -rr.k_half.a, rr.k_half.b);
  F.W = 0.5 * (F.Jt * F.Jh);
  F.P = F.RA * F.W * transpose(F.RA);
  return F;
}

// The rotation columns of ElementChordGradient (elastic element). With the body-frame right
// rotation e of node A (B), theta changes by -J_l(theta)^-1 e (J_l(theta)^-T e), the mid frame by
// the body rotation psi = H^T e + J_l(theta/2)^T dtheta/2 (J_l(theta/2)^T dtheta/2), H = exp(theta/2),
// and R_A (for A) by R_A e^. Then dGamma = (R_m^T d x psi)/L0, dn = R_m (psi x N + C_G dGamma),
// dkappa = dtheta/L0, m = R_A J_l^-T M and P u = R_A W R_A^T u (W = J_l^-T(theta) J_l^T(theta/2)/2) by
// the product rule with the directional derivatives of the J_l operators (coefficient slopes from
// jacobian_coeff_slopes). Every step is linear in e, so the three columns of each node are formed
// at once as 3 x 3 matrices (D_theta, Psi, then the forces'); with the chord columns done alike,
// an element's forces and gradients take half the time of the column-by-column form
// (docs/models/beam.md). Tested against central differences of element_forces (test_beam.cpp).
inline void element_rotation_gradient(const ElementGradientFrames &F, const RelativeRotation &rr, Vec3 d, Vec3 N,
                                      Vec3 M, Vec3 u, const ElementRef &ref, const Stiffness &C,
                                      ElementChordGradient *g) {
  const Vec3 &th = rr.th;
  const double f = norm(th);
  const Vec3 th2 = 0.5 * th;
  // slopes at f from sin/cos(f/2); at f/2 from sin/cos(f/4), the half rotation's |v| and w
  const double sq = norm(Vec3{rr.half.x, rr.half.y, rr.half.z});
  const JacobianCoeffs sl = jacobian_coeff_slopes(f, rr.sin_h, rr.cos_h);
  const JacobianCoeffs slh = jacobian_coeff_slopes(0.5 * f, sq, rr.half.w);
  const double iL0 = 1.0 / ref.L0;
  const Mat3 &Jt = F.Jt, &Jh = F.Jh, &RA = F.RA, &Rm = F.Rm, &W = F.W, &P = F.P;
  const Mat3 Jinv = so3_matrix(th, -0.5, rr.k.c);  // J_l^-1(theta)
  // eta -> dJ(eta) v, the directional derivatives of J_l^-T(theta) v and J_l^T(theta/2) v in theta
  auto dJt = [&](Vec3 v) {
    const Vec3 tv = cross(th, v);
    return -0.5 * skew(v) + sl.c * outer(cross(th, tv), th) - rr.k.c * (skew(tv) + skew(th) * skew(v));
  };
  auto dJh = [&](Vec3 v) {
    const Vec3 tv = cross(th2, v);
    return 0.5 * rr.k_half.a * skew(v) - 0.25 * slh.a * outer(tv, th) + 0.25 * slh.b * outer(cross(th2, tv), th) -
           0.5 * rr.k_half.b * (skew(tv) + skew(th2) * skew(v));
  };
  const Vec3 bd{dot(Rm.c[0], d), dot(Rm.c[1], d), dot(Rm.c[2], d)};  // R_m^T d
  const Vec3 wA{dot(RA.c[0], u), dot(RA.c[1], u), dot(RA.c[2], u)};  // R_A^T u
  const Vec3 JtM = Jt * M;
  const Vec3 Jhw = Jh * wA;
  const Vec3 Ww = W * wA;
  // dn = Qn psi; dm = RKm dtheta (+ node A's frame term); dPu = P du + RKp dtheta (+ node A's)
  const Mat3 Qn = Rm * (iL0 * diag_times(C.CG, skew(bd)) - skew(N));
  const Mat3 RKm = RA * (dJt(M) + iL0 * times_diag(Jt, C.CK));
  const Mat3 RKp = RA * (0.5 * (dJt(Jhw) + Jt * dJh(wA)));
  const Mat3 sd = skew(d);
  for (int node = 0; node < 2; ++node) {
    const Mat3 Dth = node == 0 ? -1.0 * Jinv : Jt;
    const Mat3 hD = 0.5 * (Jh * Dth);
    const Mat3 Psi = node == 0 ? transpose(rotation_matrix(rr.half)) + hD : hD;
    const Mat3 Dn = Qn * Psi;
    const Mat3 Du = sd * Dn;
    Mat3 Dm = RKm * Dth;
    Mat3 DPu = P * Du + RKp * Dth;
    if (node == 0) {
      Dm = Dm - RA * skew(JtM);
      DPu = DPu + RA * (W * skew(wA) - skew(Ww));
    }
    Vec3 *dfA = node == 0 ? g->rA_dfA : g->rB_dfA;
    Vec3 *dtA = node == 0 ? g->rA_dtA : g->rB_dtA;
    Vec3 *dtB = node == 0 ? g->rA_dtB : g->rB_dtB;
    for (int j = 0; j < 3; ++j) {
      dfA[j] = Dn.c[j];
      dtA[j] = Du.c[j] - DPu.c[j] + Dm.c[j];
      dtB[j] = DPu.c[j] - Dm.c[j];
    }
  }
}

// Forces of one element. t_damp = 0: elastic only (velocities unused). grad (optional): their
// derivatives with respect to the chord x_B - x_A (ElementChordGradient).
inline ElementForces element_forces(const NodeState &A, const NodeState &B, const ElementRef &ref,
                                    const Stiffness &C, double t_damp = 0.0, ElementChordGradient *grad = nullptr) {
  ElementForces out;
  const RelativeRotation rr = relative_rotation(A.q, B.q);
  const Vec3 &th = rr.th;
  const Quat qm = qmul(A.q, rr.half);
  const Vec3 d = B.x - A.x;
  const double L0 = ref.L0;
  const Vec3 gamma = (1.0 / L0) * qrot_t(qm, d) - Vec3{0, 0, 1} - ref.gamma0;
  const Vec3 kappa = (1.0 / L0) * th - ref.kappa0;
  const Vec3 N = hadamard(C.CG, gamma);
  const Vec3 M = hadamard(C.CK, kappa);
  out.energy = 0.5 * L0 * (dot(N, gamma) + dot(M, kappa));

  // P u = 1/2 R_A J_l(th)^-T J_l(th/2)^T R_A^T u
  auto P = [&](Vec3 u) { return qrot(A.q, 0.5 * jl_inv_t(rr, jl_half_t(rr, qrot_t(A.q, u)))); };
  const Vec3 n = qrot(qm, N);
  const Vec3 m = qrot(A.q, jl_inv_t(rr, M));
  const Vec3 u = cross(d, n);
  const Vec3 Pu = P(u);
  out.fA = n;
  out.fB = -1.0 * n;
  out.tA = u - Pu + m;
  out.tB = Pu - m;

  Vec3 wm, nd;
  if (t_damp > 0.0) {
    wm = 0.5 * (A.w + B.w);
    const Vec3 gdot = (1.0 / L0) * qrot_t(qm, B.v - A.v - cross(wm, d));
    const Vec3 kdot = (1.0 / L0) * qrot_t(qm, B.w - A.w);
    const Vec3 Nd = t_damp * hadamard(C.CG, gdot);
    const Vec3 Md = t_damp * hadamard(C.CK, kdot);
    nd = qrot(qm, Nd);
    const Vec3 md = qrot(qm, Md);
    const Vec3 half = 0.5 * cross(d, nd);
    out.fA = out.fA + nd;
    out.fB = out.fB - nd;
    out.tA = out.tA + md + half;
    out.tB = out.tB - md + half;
    out.dissipation = L0 * (dot(Nd, gdot) + dot(Md, kdot));
  }
  if (grad) {
    // dn = R_m C_G R_m^T e / L0; du = e x n + d x dn; damping: dnd = -t_d/L0 R_m C_G R_m^T (w_m x e),
    // dhalf = (e x nd + d x dnd)/2; the couple m does not depend on d. Linear in e: the three
    // columns at once as matrices (e x v = -v^ e).
    const ElementGradientFrames F = element_gradient_frames(A.q, qm, rr);
    const Mat3 sd = skew(d);
    const Mat3 Dn = (1.0 / L0) * (F.Rm * diag_times(C.CG, transpose(F.Rm)));
    const Mat3 Du = sd * Dn - skew(n);
    const Mat3 DPu = F.P * Du;
    Mat3 DfA = Dn, DtA = Du - DPu, DtB = DPu;
    if (t_damp > 0.0) {
      const Mat3 Dnd = (-t_damp / L0) * (F.Rm * diag_times(C.CG, transpose(F.Rm) * skew(wm)));
      const Mat3 Dhalf = 0.5 * (sd * Dnd - skew(nd));
      DfA = DfA + Dnd;
      DtA = DtA + Dhalf;
      DtB = DtB + Dhalf;
    }
    for (int j = 0; j < 3; ++j) {
      grad->dfA[j] = DfA.c[j];
      grad->dtA[j] = DtA.c[j];
      grad->dtB[j] = DtB.c[j];
    }
    grad->has_rot = !(t_damp > 0.0);
    if (grad->has_rot) element_rotation_gradient(F, rr, d, N, M, u, ref, C, grad);
  }
  return out;
}

// ------------------------------------------------------------------------------------------
// explicit time-step limits (velocity Verlet: dt < 2/omega) from the exact eigenvalues of one
// straight element with lumped half masses / half rotary inertias at its two nodes; the global
// maximum frequency is bounded by the largest element frequency (element eigenvalue theorem).
// ------------------------------------------------------------------------------------------
struct CriticalSteps {
  double axial, shear, bending, torsion;  // s
  double min() const { return std::min(std::min(axial, shear), std::min(bending, torsion)); }
};
// Stiffness C is the (possibly scaled) element stiffness; rho A and rho*inertia_scale*I give the
// masses. t_damp: stiffness-proportional damping time (reduces the stable step).
inline double stable_step(double omega2, double t_damp) {
  if (!(omega2 > 0)) return INFINITY;
  const double om = std::sqrt(omega2);
  const double xi = 0.5 * t_damp * om;
  return 2.0 / om * (std::sqrt(1.0 + xi * xi) - xi);
}
inline CriticalSteps critical_steps(const Section &s, const Stiffness &C, double L, double rho,
                                    double inertia_scale, double t_damp) {
  const double mA = rho * s.A;  // mass per length
  const double j1 = inertia_scale * rho * s.I1, j2 = inertia_scale * rho * s.I2,
               jp = inertia_scale * rho * s.Ip;
  const double L2 = L * L;
  CriticalSteps c;
  c.axial = stable_step(4.0 * C.CG.z / (mA * L2), t_damp);
  // shear along t1 couples to rotation about t2 and vice versa (rank-one stiffness: add)
  const double w_s1 = 4.0 * C.CG.x / (mA * L2) + C.CG.x / j2;
  const double w_s2 = 4.0 * C.CG.y / (mA * L2) + C.CG.y / j1;
  c.shear = stable_step(std::max(w_s1, w_s2), t_damp);
  c.bending = stable_step(std::max(4.0 * C.CK.x / (j1 * L2), 4.0 * C.CK.y / (j2 * L2)), t_damp);
  c.torsion = stable_step(4.0 * C.CK.z / (jp * L2), t_damp);
  return c;
}

// ------------------------------------------------------------------------------------------
// rotation integrator: free rigid-body rotation with body inertia J = (J1, J2, J3) over a step h,
// symmetric splitting R1(h/2) R2(h/2) R3(h) R2(h/2) R1(h/2) (Dullweber-Leimkuhler-McLachlan).
// Lb is the body-frame angular momentum; q is updated by body-fixed rotations.
// ------------------------------------------------------------------------------------------
inline void rotate_body_axis(int k, double h, const Vec3 &J, Quat &q, Vec3 &Lb) {
  const double phi = h * Lb[k] / J[k];
  const double c = std::cos(phi), s = std::sin(phi);
  // Lb' = Rk(phi)^T Lb (angular momentum seen from the rotated body)
  const int i = (k + 1) % 3, j = (k + 2) % 3;
  const double li = Lb[i], lj = Lb[j];
  Lb[i] = c * li + s * lj;
  Lb[j] = -s * li + c * lj;
  Quat r{std::cos(0.5 * phi), 0, 0, 0};
  const double sh = std::sin(0.5 * phi);
  if (k == 0) r.x = sh;
  else if (k == 1) r.y = sh;
  else r.z = sh;
  q = qmul(q, r);
}
inline void free_rotation(double h, const Vec3 &J, Quat &q, Vec3 &Lb) {
  if (J.x == J.y && J.y == J.z) {
    // isotropic: one exact rotation about the (constant) angular velocity
    q = qmul(q, qexp((h / J.x) * Lb));
  } else {
    rotate_body_axis(0, 0.5 * h, J, q, Lb);
    rotate_body_axis(1, 0.5 * h, J, q, Lb);
    rotate_body_axis(2, h, J, q, Lb);
    rotate_body_axis(1, 0.5 * h, J, q, Lb);
    rotate_body_axis(0, 0.5 * h, J, q, Lb);
  }
  q = qnormalize(q);
}

}  // namespace fiberform::physics::beam

#endif
