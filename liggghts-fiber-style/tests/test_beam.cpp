/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of physics/beam.h: cross-section closed forms, exactness of the element forces as
   the gradient of the stored energy (finite differences, large rotations), objectivity, balance
   of momentum and angular momentum, dissipation of the damping term, the rotation integrator and
   the time-step formulas. */
#include <cmath>
#include <cstdio>
#include <random>

#include "check.h"
#include "physics/beam.h"

using namespace fiberform::physics::beam;

namespace {
using fiberform::check::expect;
bool rel_close(double a, double b, double tol) { return std::fabs(a - b) <= tol * std::fmax(std::fabs(b), 1e-300); }

std::mt19937_64 rng(12345);
double uni(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); }
Vec3 rvec(double s) { return {uni(-s, s), uni(-s, s), uni(-s, s)}; }
Quat rquat() { return qnormalize({uni(-1, 1), uni(-1, 1), uni(-1, 1), uni(-1, 1)}); }

void test_sections() {
  const double w = 15e-6;
  const Section c = hollow_ellipse(w, w, 0, 0);
  expect(rel_close(c.A, kPi * w * w, 1e-14), "solid circle area", c.A, kPi * w * w);
  expect(rel_close(c.I1, kPi * std::pow(w, 4) / 4, 1e-14), "solid circle I1");
  expect(rel_close(c.I2, kPi * std::pow(w, 4) / 4, 1e-14), "solid circle I2");
  expect(rel_close(c.J, kPi * std::pow(w, 4) / 2, 1e-14), "solid circle J = polar moment");
  const double b = 0.6 * w;
  const Section h = hollow_ellipse(w, w, b, b);
  expect(rel_close(h.J, kPi / 2 * (std::pow(w, 4) - std::pow(b, 4)), 1e-14), "hollow circle J");
  expect(rel_close(h.A, kPi * (w * w - b * b), 1e-14), "hollow circle area");
  // collapsed (thesis 'rectangular'): a1 = 0.8 w, a2 = 0.2 w
  const double a1 = 0.8 * w, a2 = 0.2 * w;
  const Section r = hollow_ellipse(a1, a2, 0, 0);
  expect(rel_close(r.I1, kPi / 4 * a1 * a2 * a2 * a2, 1e-14), "ellipse I1 = pi a1 a2^3/4");
  expect(rel_close(r.I2, kPi / 4 * a1 * a1 * a1 * a2, 1e-14), "ellipse I2 = pi a1^3 a2/4");
  expect(rel_close(r.I2 / r.I1, 16.0, 1e-12), "ellipse I2/I1 = (a1/a2)^2");
  expect(rel_close(r.J, kPi * std::pow(a1 * a2, 3) / (a1 * a1 + a2 * a2), 1e-14), "ellipse torsion");
  // similar hollow ellipse: J = (1 - k^4) J_outer (exact)
  const double k = 0.5;
  const Section hs = hollow_ellipse(a1, a2, k * a1, k * a2);
  expect(rel_close(hs.J, (1 - std::pow(k, 4)) * r.J, 1e-13), "similar hollow ellipse torsion");
  expect(section_valid(a1, a2, 0.1 * a1, 0.1 * a2) && !section_valid(a1, a2, a1, 0.1 * a2), "section_valid");
}

void test_quaternions() {
  for (int t = 0; t < 100; ++t) {
    const Vec3 th = rvec(1.5);
    const Vec3 back = qlog(qexp(th));
    expect(norm(back - th) < 1e-12, "log(exp(th)) = th", norm(back - th), 0);
    const Quat q = rquat();
    const Vec3 t1 = qrot(q, {1, 0, 0}), t2 = qrot(q, {0, 1, 0}), t3 = qrot(q, {0, 0, 1});
    const Quat p = quat_from_frame(t1, t2, t3);
    const double d = std::fabs(std::fabs(p.w * q.w + p.x * q.x + p.y * q.y + p.z * q.z) - 1.0);
    expect(d < 1e-12, "quat_from_frame inverts qrot", d, 0);
  }
  // left Jacobian: exp(th + e) ~ exp(J_l e) exp(th)
  for (int t = 0; t < 20; ++t) {
    const Vec3 th = rvec(1.2), e = rvec(1e-6);
    const Quat lhs = qexp(th + e);
    const Quat rhs = qmul(qexp(jl(th, e)), qexp(th));
    const Vec3 diff = qlog(qmul(qconj(rhs), lhs));
    expect(norm(diff) < 1e-11, "left Jacobian definition", norm(diff), 0);
    const Vec3 v = rvec(1.0);
    expect(norm(jl_inv(th, jl(th, v)) - v) < 1e-13, "J_l^-1 J_l = I");
    expect(norm(jl_inv_t(th, jl_t(th, v)) - v) < 1e-13, "J_l^-T J_l^T = I");
  }
}

// Perturbations for finite differences: translate node, or rotate its frame in space.
struct Config {
  NodeState A, B;
};
double energy(const Config &c, const ElementRef &r, const Stiffness &C) {
  return element_forces(c.A, c.B, r, C).energy;
}

void test_element_gradient() {
  const Section s = hollow_ellipse(12e-6, 5e-6, 6e-6, 2e-6);
  const Stiffness C = section_stiffness(s, 20e9, 3e9, 5.0 / 6.0);
  double worst_f = 0, worst_t = 0;
  for (int t = 0; t < 40; ++t) {
    // a curved, twisted reference with a large relative rotation (up to ~1.7 rad)
    Config ref;
    ref.A.x = rvec(1e-4);
    ref.A.q = rquat();
    ref.B.q = qmul(ref.A.q, qexp(rvec(1.0)));
    ref.B.x = ref.A.x + 5e-5 * (Vec3{0, 0, 1} + rvec(0.3));
    const ElementRef r = element_reference(ref.A.x, ref.A.q, ref.B.x, ref.B.q);
    // the reference itself is stress free
    const ElementForces f0 = element_forces(ref.A, ref.B, r, C);
    expect(norm(f0.fA) < 1e-18 * C.CG.z + 1e-15 && std::fabs(f0.energy) < 1e-30,
           "reference configuration is stress free", norm(f0.fA), 0);
    // a deformed state
    Config c = ref;
    c.B.x = c.B.x + rvec(1e-5);
    c.A.q = qmul(qexp(rvec(0.6)), c.A.q);
    c.B.q = qmul(qexp(rvec(0.6)), c.B.q);
    const ElementForces f = element_forces(c.A, c.B, r, C);
    const double h = 1e-9, hr = 1e-7;
    for (int node = 0; node < 2; ++node) {
      for (int k = 0; k < 3; ++k) {
        Vec3 e{};
        e[k] = 1.0;
        Config p = c, m = c;
        NodeState &pn = node ? p.B : p.A, &mn = node ? m.B : m.A;
        pn.x = pn.x + h * e;
        mn.x = mn.x - h * e;
        const double dUdx = (energy(p, r, C) - energy(m, r, C)) / (2 * h);
        const double fk = node ? f.fB[k] : f.fA[k];
        const double scale_f = norm(f.fA) + 1e-12;
        worst_f = std::fmax(worst_f, std::fabs(-dUdx - fk) / scale_f);
        Config pr = c, mr = c;
        NodeState &prn = node ? pr.B : pr.A, &mrn = node ? mr.B : mr.A;
        prn.q = qmul(qexp(hr * e), prn.q);
        mrn.q = qmul(qexp(-hr * e), mrn.q);
        const double dUdpsi = (energy(pr, r, C) - energy(mr, r, C)) / (2 * hr);
        const double tk = node ? f.tB[k] : f.tA[k];
        const double scale_t = norm(f.tA) + norm(f.tB) + 1e-18;
        worst_t = std::fmax(worst_t, std::fabs(-dUdpsi - tk) / scale_t);
      }
    }
    // balance of momentum and angular momentum
    const Vec3 sumf = f.fA + f.fB;
    const Vec3 summ = cross(c.A.x, f.fA) + cross(c.B.x, f.fB) + f.tA + f.tB;
    expect(norm(sumf) <= 1e-12 * norm(f.fA), "sum of forces = 0", norm(sumf), 0);
    expect(norm(summ) <= 1e-9 * (norm(f.tA) + norm(cross(c.B.x - c.A.x, f.fA))), "sum of moments = 0",
           norm(summ), 0);
    // objectivity: a rigid rotation + translation of the deformed state leaves U unchanged and
    // rotates the forces
    const Quat Q = rquat();
    const Vec3 shift = rvec(1e-3);
    Config g = c;
    g.A.x = qrot(Q, c.A.x) + shift;
    g.B.x = qrot(Q, c.B.x) + shift;
    g.A.q = qmul(Q, c.A.q);
    g.B.q = qmul(Q, c.B.q);
    const ElementForces fg = element_forces(g.A, g.B, r, C);
    expect(rel_close(fg.energy, f.energy, 1e-9), "energy objective", fg.energy, f.energy);
    expect(norm(fg.tB - qrot(Q, f.tB)) <= 1e-8 * norm(f.tB), "torque objective");
  }
  expect(worst_f < 1e-5, "F = -dU/dx (finite differences)", worst_f, 0);
  expect(worst_t < 1e-5, "T = -dU/dpsi (finite differences)", worst_t, 0);
  std::printf("  element gradient check: max rel. error force %.2e, torque %.2e\n", worst_f, worst_t);
}

// J_l coefficients a = (1 - cos f)/f^2 = 2 sin^2(f/2)/f^2, b = (f - sin f)/f^3, c = (1 - (f/2) cot(f/2))/f^2
// by series below 0.05 rad (truncation < 1e-16 relative) and the closed forms above, where they
// lose no digits to cancellation (c's closed form loses up to 1e-3 relative near f = 1e-3)
JacobianCoeffs reference_coeffs(double f) {
  const double f2 = f * f;
  const double a = f > 0 ? 2.0 * std::pow(std::sin(0.5 * f), 2) / f2 : 0.5;
  if (f < 0.05)
    return {a, 1.0 / 6.0 - f2 / 120.0 + f2 * f2 / 5040.0 - f2 * f2 * f2 / 362880.0,
            1.0 / 12.0 + f2 / 720.0 + f2 * f2 / 30240.0 + f2 * f2 * f2 / 1209600.0};
  return {a, (f - std::sin(f)) / (f2 * f), (1.0 - 0.5 * f / std::tan(0.5 * f)) / f2};
}

// relative_rotation: theta, the half rotation and the J_l coefficients at f and f/2 without trig,
// against qlog/qexp and reference_coeffs, from tiny to nearly pi, both signs of w
void test_relative_rotation() {
  double worst[3] = {0, 0, 0};
  const double angles[] = {0.0, 1e-9, 1e-5, 9.9e-4, 1.0e-3, 1.01e-3, 2.0e-3, 2.1e-3, 0.01, 0.3, 1.0, 2.0, 3.0, 3.14};
  for (double ang : angles)
    for (int t = 0; t < 8; ++t) {
      Vec3 axis = rvec(1.0);
      axis = (1.0 / norm(axis)) * axis;
      const Quat qA = rquat();
      Quat qB = qmul(qA, qexp(ang * axis));
      if (t % 2) qB = {-qB.w, -qB.x, -qB.y, -qB.z};  // the same rotation, w of the other sign
      const RelativeRotation r = relative_rotation(qA, qB);
      const Vec3 th = qlog(qmul(qconj(qA), qB));
      const Quat qm = qmul(qA, qexp(0.5 * th));  // the geodesic mid rotation (with sin/cos)
      expect(norm(r.th - th) <= 1e-15 * (1.0 + norm(th)), "relative_rotation theta = log(qA* qB)");
      const Quat hm = qmul(qA, r.half);
      const double dq = std::fabs(std::fabs(hm.w * qm.w + hm.x * qm.x + hm.y * qm.y + hm.z * qm.z) - 1.0);
      expect(dq < 1e-14, "relative_rotation half = exp(theta/2)", dq, 0);
      const double f = norm(th);
      const JacobianCoeffs got[2] = {r.k, r.k_half}, want[2] = {reference_coeffs(f), reference_coeffs(0.5 * f)};
      for (int h = 0; h < 2; ++h) {
        const double e[3] = {std::fabs(got[h].a - want[h].a) / want[h].a, std::fabs(got[h].b - want[h].b) / want[h].b,
                             std::fabs(got[h].c - want[h].c) / want[h].c};
        for (int i = 0; i < 3; ++i) worst[i] = std::fmax(worst[i], e[i]);
        // b = (f - sin f)/f^3 keeps the cancellation of its closed form (~1e-9 near f = 1e-3)
        expect(e[0] < 1e-13, "relative_rotation J_l coefficient a", e[0], ang);
        expect(e[1] < 1e-8, "relative_rotation J_l coefficient b", e[1], ang);
        expect(e[2] < 1e-7, "relative_rotation J_l coefficient c", e[2], ang);
      }
    }
  std::printf("  relative_rotation: worst rel. error of a %.2e, b %.2e, c %.2e\n", worst[0], worst[1], worst[2]);
}

// the chord derivatives of the forces (the implicit tangent's translational columns) against
// central differences of element_forces in x_B, elastic and with Kelvin-Voigt damping
void test_chord_gradient() {
  const Section s = hollow_ellipse(12e-6, 5e-6, 6e-6, 2e-6);
  const Stiffness C = section_stiffness(s, 20e9, 3e9, 5.0 / 6.0);
  double worst = 0;
  for (int t = 0; t < 40; ++t) {
    NodeState A, B;
    A.x = rvec(1e-4);
    A.q = rquat();
    B.q = qmul(A.q, qexp(rvec(1.0)));
    B.x = A.x + 5e-5 * (Vec3{0, 0, 1} + rvec(0.3));
    const ElementRef r = element_reference(A.x, A.q, B.x, B.q);
    B.x = B.x + rvec(1e-5);
    A.q = qmul(qexp(rvec(0.6)), A.q);
    B.q = qmul(qexp(rvec(0.6)), B.q);
    A.v = rvec(1e-2); B.v = rvec(1e-2); A.w = rvec(100); B.w = rvec(100);
    const double td = t % 2 ? 1e-6 : 0.0;
    ElementChordGradient g;
    const ElementForces f = element_forces(A, B, r, C, td, &g);
    const double h = 1e-10;
    const double sf = norm(f.fA) + 1e-300, st = norm(f.tA) + norm(f.tB) + 1e-300;
    for (int j = 0; j < 3; ++j) {
      NodeState Bp = B, Bm = B;
      Bp.x[j] += h;
      Bm.x[j] -= h;
      const ElementForces p = element_forces(A, Bp, r, C, td), m = element_forces(A, Bm, r, C, td);
      const double L = r.L0;  // forces change by ~ f / L per metre of chord
      const double ef = norm((1.0 / (2 * h)) * (p.fA - m.fA) - g.dfA[j]) * L / sf;
      const double efb = norm((1.0 / (2 * h)) * (p.fB - m.fB) + g.dfA[j]) * L / sf;
      const double eta = norm((1.0 / (2 * h)) * (p.tA - m.tA) - g.dtA[j]) * L / st;
      const double etb = norm((1.0 / (2 * h)) * (p.tB - m.tB) - g.dtB[j]) * L / st;
      worst = std::fmax(worst, std::fmax(std::fmax(ef, efb), std::fmax(eta, etb)));
    }
  }
  expect(worst < 1e-6, "chord gradient = d(forces)/d(x_B - x_A) (central differences)", worst, 0);
  std::printf("  chord gradient check: max rel. error %.2e\n", worst);
}

// the rotation columns (elastic element): d(forces)/d(body-frame right rotation of q_A, q_B)
// against central differences, from straight to strongly bent and twisted elements (relative
// rotations 1e-4 to ~2 rad, so both the series and the closed-form coefficient slopes are used)
void test_rotation_gradient() {
  const Section s = hollow_ellipse(12e-6, 5e-6, 6e-6, 2e-6);
  const Stiffness C = section_stiffness(s, 20e9, 3e9, 5.0 / 6.0);
  double worst = 0;
  for (int t = 0; t < 60; ++t) {
    const double bend = t < 20 ? 1e-4 : (t < 40 ? 0.03 : 1.0);
    NodeState A, B;
    A.x = rvec(1e-4);
    A.q = rquat();
    B.q = qmul(A.q, qexp(rvec(bend)));
    B.x = A.x + 5e-5 * (Vec3{0, 0, 1} + rvec(0.3));
    const ElementRef r = element_reference(A.x, A.q, B.x, B.q);
    B.x = B.x + rvec(1e-5);
    A.q = qmul(qexp(rvec(bend)), A.q);
    B.q = qmul(qexp(rvec(bend)), B.q);
    ElementChordGradient g;
    const ElementForces f = element_forces(A, B, r, C, 0.0, &g);
    expect(g.has_rot, "rotation gradient filled for an elastic element");
    const double h = 1e-6;
    const double sf = norm(f.fA) * r.L0 + norm(f.tA) + norm(f.tB) + 1e-300;  // torque scale
    for (int node = 0; node < 2; ++node)
      for (int j = 0; j < 3; ++j) {
        Vec3 e{};
        e[j] = h;
        NodeState Ap = A, Am = A, Bp = B, Bm = B;
        NodeState &P = node ? Bp : Ap, &Mn = node ? Bm : Am;
        P.q = qmul(P.q, qexp(e));
        Mn.q = qmul(Mn.q, qexp(-1.0 * e));
        const ElementForces p = element_forces(Ap, Bp, r, C), m = element_forces(Am, Bm, r, C);
        const Vec3 *dfA = node ? g.rB_dfA : g.rA_dfA, *dtA = node ? g.rB_dtA : g.rA_dtA, *dtB = node ? g.rB_dtB : g.rA_dtB;
        const double ef = norm((1.0 / (2 * h)) * (p.fA - m.fA) - dfA[j]) * r.L0 / sf;
        const double eta = norm((1.0 / (2 * h)) * (p.tA - m.tA) - dtA[j]) / sf;
        const double etb = norm((1.0 / (2 * h)) * (p.tB - m.tB) - dtB[j]) / sf;
        worst = std::fmax(worst, std::fmax(ef, std::fmax(eta, etb)));
      }
  }
  expect(worst < 1e-6, "rotation gradient = d(forces)/d(frame rotations) (central differences)", worst, 0);
  std::printf("  rotation gradient check: max rel. error %.2e\n", worst);
  // with damping the rotation columns are left to finite differences
  NodeState A, B;
  B.x = {0, 0, 5e-5};
  const ElementRef r = element_reference(A.x, A.q, B.x, B.q);
  ElementChordGradient g;
  element_forces(A, B, r, C, 1e-6, &g);
  expect(!g.has_rot, "no analytic rotation columns with damping");
}

// the matrix forms the gradients are built from (rotation_matrix, so3_matrix, skew, outer, the
// diagonal products) against the vector operations they replace, and the slopes from a relative
// rotation's sin/cos(f/2) against the slopes from std::sin/std::cos, on both sides of the series
void test_matrix_forms() {
  for (int t = 0; t < 50; ++t) {
    const Quat q = rquat();
    const Vec3 v = rvec(2.0), a = rvec(1.5), th = rvec(1.7);
    const Mat3 R = rotation_matrix(q);
    expect(norm(R * v - qrot(q, v)) < 1e-14 * norm(v), "rotation_matrix(q) v = qrot(q, v)");
    expect(norm(transpose(R) * v - qrot_t(q, v)) < 1e-14 * norm(v), "R^T v = qrot_t(q, v)");
    const Mat3 S = so3_matrix(th, 0.3, -0.7);
    expect(norm(S * v - apply_so3(th, 0.3, -0.7, v)) < 1e-14 * (1 + dot(th, th)) * norm(v), "so3_matrix = apply_so3");
    expect(norm(skew(a) * v - cross(a, v)) < 1e-15 * norm(a) * norm(v), "skew(a) v = a x v");
    expect(norm(outer(a, th) * v - dot(th, v) * a) < 1e-15 * norm(a) * norm(th) * norm(v), "outer(a, b) v = (b.v) a");
    const Mat3 M = so3_matrix(a, 0.2, 0.1);
    expect(norm(diag_times(th, M) * v - hadamard(th, M * v)) < 1e-14 * norm(th) * norm(v) * (1 + dot(a, a)),
           "diag(d) M v");
    expect(norm(times_diag(M, th) * v - M * hadamard(th, v)) < 1e-14 * norm(th) * norm(v) * (1 + dot(a, a)),
           "M diag(d) v");
    expect(norm((R * M) * v - R * (M * v)) < 1e-14 * norm(v) * (1 + dot(a, a)), "matrix product");
  }
  double worst = 0;
  for (double f : {1e-6, 1e-3, 0.049, 0.0500001, 0.2, 1.0, 2.0, 3.0, 3.14}) {
    const Quat qA = rquat();
    const Vec3 n = (1.0 / norm(rvec(1.0) + Vec3{0.1, 0, 0})) * (rvec(1.0) + Vec3{0.1, 0, 0});
    const RelativeRotation r = relative_rotation(qA, qmul(qA, qexp(f * (1.0 / norm(n)) * n)));
    const double g = norm(r.th);
    const JacobianCoeffs a = jacobian_coeff_slopes(g, r.sin_h, r.cos_h), b = jacobian_coeff_slopes(g);
    const double e[3] = {std::fabs(a.a - b.a) / std::fabs(b.a), std::fabs(a.b - b.b) / std::fabs(b.b),
                         std::fabs(a.c - b.c) / std::fabs(b.c)};
    for (double x : e) {
      worst = std::fmax(worst, x);
      expect(x < 1e-9, "slopes from sin/cos(f/2) = slopes from f", x, f);
    }
  }
  std::printf("  slopes from a relative rotation: worst rel. difference %.2e\n", worst);
}

// the coefficient slopes a'(f)/f, b'(f)/f, c'(f)/f against central differences of the
// coefficients (reference_coeffs), on both sides of the series threshold
void test_coefficient_slopes() {
  double worst = 0;
  for (double f : {1e-3, 0.02, 0.049, 0.051, 0.2, 1.0, 2.5}) {
    const double h = 1e-3 * f;  // truncation ~1e-6 relative; round-off ~1e-6 at f = 1e-3
    const JacobianCoeffs p = reference_coeffs(f + h), m = reference_coeffs(f - h), s = jacobian_coeff_slopes(f);
    const double num[3] = {(p.a - m.a) / (2 * h) / f, (p.b - m.b) / (2 * h) / f, (p.c - m.c) / (2 * h) / f};
    const double got[3] = {s.a, s.b, s.c};
    for (int i = 0; i < 3; ++i) {
      const double e = std::fabs(got[i] - num[i]) / std::fabs(got[i]);
      worst = std::fmax(worst, e);
      expect(e < 1e-5, "J_l coefficient slope", got[i], num[i]);
    }
  }
  std::printf("  coefficient slopes: worst rel. error %.2e\n", worst);
}

void test_damping() {
  const Section s = hollow_ellipse(10e-6, 10e-6, 0, 0);
  const Stiffness C = section_stiffness(s, 10e9, 4e9, 5.0 / 6.0);
  NodeState A, B;
  A.q = rquat();
  B.q = qmul(A.q, qexp(rvec(0.3)));
  B.x = qrot(A.q, {0, 0, 4e-5});
  const ElementRef r = element_reference(A.x, A.q, B.x, B.q);
  // rigid motion: v = V + W x x, w = W for both: no damping force
  const Vec3 V = rvec(1e-2), W = rvec(10.0);
  A.v = V + cross(W, A.x);
  B.v = V + cross(W, B.x);
  A.w = B.w = W;
  const ElementForces f = element_forces(A, B, r, C, 1e-6);
  expect(norm(f.fA) < 1e-12 * C.CG.z * 1e-6, "damping: rigid motion is not damped", norm(f.fA), 0);
  // random motion: power of the damping forces is -dissipation <= 0
  for (int t = 0; t < 20; ++t) {
    A.v = rvec(1e-2); B.v = rvec(1e-2); A.w = rvec(100); B.w = rvec(100);
    const ElementForces e = element_forces(A, B, r, C, 0.0);
    const ElementForces d = element_forces(A, B, r, C, 1e-6);
    const double power = dot(d.fA - e.fA, A.v) + dot(d.fB - e.fB, B.v) + dot(d.tA - e.tA, A.w) +
                         dot(d.tB - e.tB, B.w);
    expect(d.dissipation >= 0 && rel_close(-power, d.dissipation, 1e-9), "damping power = -dissipation",
           -power, d.dissipation);
  }
}

void test_rotation_integrator() {
  // torque-free anisotropic rotor: energy and |L| conserved to O(h^2), spatial L conserved exactly
  const Vec3 J{1.0, 2.0, 3.0};
  Quat q = rquat();
  Vec3 Lb{0.3, 1.0, 0.2};
  const Vec3 Ls0 = qrot(q, Lb);
  auto ke = [&](Vec3 L) { return 0.5 * (L.x * L.x / J.x + L.y * L.y / J.y + L.z * L.z / J.z); };
  const double E0 = ke(Lb);
  double worst = 0;
  for (int n = 0; n < 20000; ++n) {
    free_rotation(1e-3, J, q, Lb);
    worst = std::fmax(worst, std::fabs(ke(Lb) / E0 - 1));
  }
  const Vec3 Ls = qrot(q, Lb);
  expect(norm(Ls - Ls0) < 1e-10, "free rotor: spatial angular momentum conserved", norm(Ls - Ls0), 0);
  expect(worst < 1e-5, "free rotor: energy bounded", worst, 0);
  // isotropic rotor: exact rotation angle
  Quat qi{};
  Vec3 Li{0, 0, 2.0};
  free_rotation(0.5, {1, 1, 1}, qi, Li);
  expect(std::fabs(norm(qlog(qi)) - 1.0) < 1e-14, "isotropic rotor: angle = h |L| / J");
}

void test_critical_steps() {
  const double w = 10e-6, L = 50e-6, rho = 1500, E = 10e9, G = 4e9;
  const Section s = hollow_ellipse(w, w, 0, 0);
  const Stiffness C = section_stiffness(s, E, G, 5.0 / 6.0);
  const CriticalSteps c = critical_steps(s, C, L, rho, 1.0, 0.0);
  expect(rel_close(c.axial, L / std::sqrt(E / rho), 1e-12), "axial step = L / c", c.axial, L / std::sqrt(E / rho));
  // the shear-rotation cutoff approaches 2 sqrt(rho I / (k G A)) for long elements
  const CriticalSteps lng = critical_steps(s, C, 1e3 * L, rho, 1.0, 0.0);
  const double cut = 2 * std::sqrt(rho * s.I2 / (C.CG.x));
  expect(rel_close(lng.shear, cut, 1e-5), "shear-rotation cutoff", lng.shear, cut);
  // damping lowers the stable step
  expect(critical_steps(s, C, L, rho, 1.0, 1e-8).min() < c.min(), "damping lowers the step");
  // inertia scaling raises the bending/torsion/shear steps by sqrt(s)
  const CriticalSteps sc = critical_steps(s, C, L, rho, 100.0, 0.0);
  expect(rel_close(sc.torsion, 10 * c.torsion, 1e-12), "inertia scale 100 -> torsion step x10");
}
}  // namespace

int main() {
  test_sections();
  test_quaternions();
  test_element_gradient();
  test_relative_rotation();
  test_chord_gradient();
  test_coefficient_slopes();
  test_rotation_gradient();
  test_matrix_forms();
  test_damping();
  test_rotation_integrator();
  test_critical_steps();
  return fiberform::check::finish("test_beam");
}
