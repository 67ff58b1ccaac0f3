/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of physics/block_tridiag.h and physics/implicit_rod.h: the block solve against a
   dense elimination, the generalized-alpha parameters (Chung-Hulbert closed forms), exactness for
   constant acceleration and free isotropic spin, the spectral radius of the scheme on a linear
   oscillator at omega h >> 1, the statics of a clamped cantilever at a large step against
   F L^3 / (3 E I), and modified Newton across steps (a held rod::Tangent): the first bending
   frequency of a cantilever against Euler-Bernoulli, and an impact on a unilateral spring. */
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "check.h"
#include "physics/block_tridiag.h"
#include "physics/implicit_rod.h"

using namespace fiberform::physics;
using beam::Quat;
using beam::Vec3;

namespace {
using fiberform::check::expect;
std::mt19937_64 rng(7);
double uni(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); }

void test_block_solve() {
  const int n = 7, N = 6 * n;
  std::vector<double> A(N * N, 0.0), D(n * 36), L(n * 36, 0.0), U(n * 36, 0.0), x(N), b(N);
  for (int k = 0; k < n; ++k)
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) {
        const double d = uni(-1, 1) + (i == j ? 8.0 * (1 + i) : 0.0);
        D[k * 36 + i * 6 + j] = d;
        A[(6 * k + i) * N + 6 * k + j] = d;
        if (k > 0) {
          const double l = uni(-1, 1);
          L[k * 36 + i * 6 + j] = l;
          A[(6 * k + i) * N + 6 * (k - 1) + j] = l;
        }
        if (k + 1 < n) {
          const double u = uni(-1, 1);
          U[k * 36 + i * 6 + j] = u;
          A[(6 * k + i) * N + 6 * (k + 1) + j] = u;
        }
      }
  for (int i = 0; i < N; ++i) x[i] = uni(-1, 1);
  for (int i = 0; i < N; ++i) {
    b[i] = 0;
    for (int j = 0; j < N; ++j) b[i] += A[i * N + j] * x[j];
  }
  std::vector<int> piv(N);
  const bool ok = blocktri::solve(n, D.data(), L.data(), U.data(), b.data(), piv.data());
  expect(ok, "block solve succeeds");
  double err = 0;
  for (int i = 0; i < N; ++i) err = std::fmax(err, std::fabs(b[i] - x[i]));
  expect(err < 1e-12, "block-tridiagonal solve reproduces the solution", err, 0);
  // a pivot is needed inside a block: zero diagonal entry, non-zero below
  double M[36] = {0}, Mo[36];
  for (int i = 0; i < 36; ++i) M[i] = uni(-1, 1);
  M[0] = 0.0;
  for (int i = 0; i < 36; ++i) Mo[i] = M[i];
  double rhs[6], sol[6] = {1, -2, 3, -4, 5, -6};
  for (int i = 0; i < 6; ++i) {
    rhs[i] = 0;
    for (int j = 0; j < 6; ++j) rhs[i] += Mo[i * 6 + j] * sol[j];
  }
  int p6[6];
  expect(blocktri::lu6(M, p6), "lu6 with a zero leading entry");
  blocktri::lu6_solve(M, p6, rhs);
  double e6 = 0;
  for (int i = 0; i < 6; ++i) e6 = std::fmax(e6, std::fabs(rhs[i] - sol[i]));
  expect(e6 < 1e-10, "lu6 pivoting", e6, 0);
}

void test_parameters() {
  const rod::GenAlpha g1 = rod::gen_alpha(1.0);
  expect(std::fabs(g1.am - 0.5) < 1e-15 && std::fabs(g1.af - 0.5) < 1e-15, "rho 1: am = af = 1/2");
  expect(std::fabs(g1.gamma - 0.5) < 1e-15 && std::fabs(g1.beta - 0.25) < 1e-15, "rho 1: trapezoidal");
  const rod::GenAlpha g0 = rod::gen_alpha(0.0);
  expect(std::fabs(g0.am + 1.0) < 1e-15 && std::fabs(g0.af) < 1e-15, "rho 0: am = -1, af = 0");
  expect(std::fabs(g0.gamma - 1.5) < 1e-15 && std::fabs(g0.beta - 1.0) < 1e-15, "rho 0: gamma 3/2, beta 1");
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  expect(std::fabs(g.beta_eff() - g.beta * (1 - g.af) / (1 - g.am)) < 1e-15, "beta_eff");
}

rod::Node free_node(double m, Vec3 J) {
  rod::Node nd;
  nd.m = m;
  nd.J = J;
  nd.scale = 1e-5;
  return nd;
}

// One free node: constant force -> x exactly quadratic; isotropic spin exact.
void test_free_node() {
  rod::Stepper st;
  rod::Options opt;
  opt.tol = 1e-12;
  std::vector<rod::Element> none;
  for (double rho : {0.0, 0.5, 1.0}) {
    std::vector<rod::Node> nodes{free_node(2e-9, {1e-18, 1e-18, 1e-18})};
    nodes[0].v = {1e-3, -2e-3, 0.5e-3};
    nodes[0].F = {3e-9, 0, -6e-9};
    nodes[0].W = {0, 0, 200.0};
    st.initialise(nodes, none, opt);
    const rod::GenAlpha g = rod::gen_alpha(rho);
    const double h = 1e-4;
    const int steps = 50;
    for (int s = 0; s < steps; ++s) {
      const rod::Stats r = st.step(nodes, none, h, g, opt);
      expect(r.ok, "free node step converges");
    }
    const double t = h * steps;
    const Vec3 want{1e-3 * t + 0.5 * 1.5 * t * t, -2e-3 * t, 0.5e-3 * t - 0.5 * 3.0 * t * t};
    expect(beam::norm(nodes[0].x - want) < 1e-15, "constant force: exact quadratic", beam::norm(nodes[0].x - want), 0);
    const Vec3 vwant{1e-3 + 1.5 * t, -2e-3, 0.5e-3 - 3.0 * t};
    expect(beam::norm(nodes[0].v - vwant) < 1e-12, "constant force: exact velocity", beam::norm(nodes[0].v - vwant), 0);
    const Vec3 t1 = beam::qrot(nodes[0].q, {1, 0, 0});
    const double ang = std::atan2(t1.y, t1.x);
    const double want_ang = std::remainder(200.0 * t, 2 * beam::kPi);
    expect(std::fabs(ang - want_ang) < 1e-9, "isotropic free spin: exact angle", ang, want_ang);
  }
}

// Linear oscillator (one node on a spring along a chain of 2 nodes, the other clamped): after many
// steps at omega h = 1000 the amplitude decays by rho_inf per step (spectral radius).
void test_spectral_radius() {
  const double L = 5e-5, r = 10e-6;
  const beam::Section s = beam::hollow_ellipse(r, r, 0, 0);
  const beam::Stiffness C = beam::section_stiffness(s, 10e9, 4e9, 5.0 / 6.0);
  rod::Element el;
  el.ref = beam::element_reference({0, 0, 0}, {}, {0, 0, L}, {});
  el.C = C;
  const double m = 1500 * s.A * L / 2;
  const double omega = std::sqrt(C.CG.z / L / m);  // axial
  const double h = 1000.0 / omega;
  for (double rho : {0.0, 0.5, 0.8}) {
    std::vector<rod::Node> nodes{free_node(m, {1e-20, 1e-20, 1e-20}), free_node(m, {1e-20, 1e-20, 1e-20})};
    nodes[0].fixed = true;
    nodes[1].x = {0, 0, L * (1 + 1e-4)};
    // keep it axial: clamp rotations by big inertia? use a stiff element; only the axial mode is excited
    rod::Stepper st;
    rod::Options opt;
    opt.tol = 1e-10;
    st.initialise(nodes, {el}, opt);
    const rod::GenAlpha g = rod::gen_alpha(rho);
    const double amp_start = 1e-4 * L;
    double amp5 = 0, amp15 = 0;
    for (int k = 0; k < 16; ++k) {
      const rod::Stats res = st.step(nodes, {el}, h, g, opt);
      expect(res.ok, "oscillator step converges");
      const double amp = std::fabs(nodes[1].x.z - L) + std::fabs(nodes[1].v.z) / omega;
      if (k == 5) amp5 = amp;
      if (k == 15) amp15 = amp;
    }
    if (rho == 0.0) {
      // asymptotic annihilation: the mode is gone after a few steps
      expect(amp15 < 1e-8 * amp_start, "rho_inf 0 annihilates the unresolved mode", amp15 / amp_start, 0);
    } else {
      // at omega h -> infinity the amplification matrix has the double eigenvalue -rho_inf (a Jordan
      // block, Chung & Hulbert 1993), so the amplitude goes as k rho_inf^k: fit rho from steps 5..15
      const double ratio = std::pow(amp15 / amp5 * (6.0 / 16.0), 0.1);
      expect(std::fabs(ratio - rho) < 0.03, "spectral radius at omega h = 1000", ratio, rho);
    }
  }
}

// Clamped cantilever, tip load, real stiffness, h = 1e-4 s, background drag: tip deflection vs
// F L^3 / (3 E I) + F L / (k G A) within 1%.
void test_cantilever_statics() {
  const int ne = 16;
  const double L = 1e-3, r = 10e-6, E = 10e9, G = 4e9, rho = 1500, ks = 5.0 / 6.0;
  const beam::Section s = beam::hollow_ellipse(r, r, 0, 0);
  const beam::Stiffness C = beam::section_stiffness(s, E, G, ks);
  std::vector<rod::Element> els(ne);
  std::vector<rod::Node> nodes(ne + 1);
  const double le = L / ne;
  for (int k = 0; k <= ne; ++k) {
    nodes[k] = free_node(rho * s.A * le * (k == 0 || k == ne ? 0.5 : 1.0), {1, 1, 1});
    const double jl = rho * le * (k == 0 || k == ne ? 0.5 : 1.0);
    nodes[k].J = {jl * s.I1, jl * s.I2, jl * s.Ip};
    nodes[k].x = {0, 0, k * le};
    nodes[k].scale = r;
  }
  for (int k = 0; k < ne; ++k) {
    els[k].ref = beam::element_reference(nodes[k].x, nodes[k].q, nodes[k + 1].x, nodes[k + 1].q);
    els[k].C = C;
  }
  nodes[0].fixed = true;
  const double EI = E * s.I1;
  const double F = 3 * EI * 1e-3 * L / (L * L * L);  // 0.1 % of L
  nodes[ne].F = {0, F, 0};
  const double omega1 = 1.8751 * 1.8751 / (L * L) * std::sqrt(EI / (rho * s.A));
  rod::Options opt;
  opt.tau_drag = 1.0 / omega1;  // about critically damped first mode
  rod::Stepper st;
  st.initialise(nodes, els, opt);
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  const double h = 1e-4;
  long iters = 0;
  const int steps = static_cast<int>(400.0 / omega1 / h) + 1;
  for (int k = 0; k < steps; ++k) {
    const rod::Stats res = st.step(nodes, els, h, g, opt);
    expect(res.ok, "cantilever step converges");
    iters += res.iterations;
  }
  const double want = F * L * L * L / (3 * EI) + F * L / (ks * G * s.A);
  expect(std::fabs(nodes[ne].x.y / want - 1) < 0.01, "cantilever tip deflection at h = 1e-4 s", nodes[ne].x.y, want);
  std::printf("cantilever: %d steps, %.2f Newton iterations per step, tip %.6e m (closed form %.6e m)\n",
              steps, static_cast<double>(iters) / steps, nodes[ne].x.y, want);
}

// Euler-Bernoulli first mode of a clamped-free beam (beta1 L = 1.8751040687): shape phi(z) and slope.
void eb_mode1(double z, double L, double *phi, double *dphi) {
  const double b = 1.8751040687 / L, bl = 1.8751040687;
  const double sig = (std::cosh(bl) + std::cos(bl)) / (std::sinh(bl) + std::sin(bl));
  *phi = std::cosh(b * z) - std::cos(b * z) - sig * (std::sinh(b * z) - std::sin(b * z));
  *dphi = b * (std::sinh(b * z) + std::sin(b * z) - sig * (std::cosh(b * z) - std::cos(b * z)));
}

// Modified Newton across steps (rod::Tangent, docs/models/beam.md "Cost"): the cantilever of
// bench/fibers/run_implicit.py (r = 10 um, L = 0.5 mm, 16 elements, real stiffness) released from
// its first mode shape, 5 periods at 40 steps per period, solved with a held tangent
// (tangent_steps 50) and with a new tangent in every step:
// * the held run keeps the Euler-Bernoulli frequency (beta1 L = 1.8751) to 1 % (zero crossings
//   of the tip), and its trajectory equals the other one to 1e-4 of the amplitude (both solve the
//   same equations to the Newton tolerance);
// * it forms far fewer tangents (< 0.2 per step, against 1) for at most one more iteration per step;
// * a step of another size forms a new tangent.
void test_tangent_reuse() {
  const int ne = 16;
  const double L = 0.5e-3, r = 10e-6, E = 10e9, G = 4e9, rho = 1500, ks = 5.0 / 6.0;
  const beam::Section s = beam::hollow_ellipse(r, r, 0, 0);
  const beam::Stiffness C = beam::section_stiffness(s, E, G, ks);
  const double le = L / ne;
  std::vector<rod::Element> els(ne);
  std::vector<rod::Node> start(ne + 1);
  for (int k = 0; k <= ne; ++k) {
    const double w = (k == 0 || k == ne) ? 0.5 : 1.0;
    start[k] = free_node(rho * s.A * le * w, {rho * le * w * s.I1, rho * le * w * s.I2, rho * le * w * s.Ip});
    start[k].x = {0, 0, k * le};
    start[k].scale = r;
  }
  for (int k = 0; k < ne; ++k) {
    els[k].ref = beam::element_reference(start[k].x, start[k].q, start[k + 1].x, start[k + 1].q);
    els[k].C = C;
  }
  // bent into the first mode, tip amplitude 1e-3 L; frames follow the slope (rotation about t1)
  double phiL, dphiL;
  eb_mode1(L, L, &phiL, &dphiL);
  const double amp = 1e-3 * L / phiL;
  for (int k = 0; k <= ne; ++k) {
    double phi, dphi;
    eb_mode1(k * le, L, &phi, &dphi);
    start[k].x.y = amp * phi;
    start[k].q = beam::qexp({-std::atan(amp * dphi), 0, 0});
  }
  start[0].fixed = true;
  const double EI = E * s.I1;
  const double omega1 = 1.8751040687 * 1.8751040687 / (L * L) * std::sqrt(EI / (rho * s.A));
  const double period = 2 * beam::kPi / omega1, h = period / 40;
  const int steps = 200;
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  rod::Options opt;
  opt.tangent_steps = 50;
  std::vector<rod::Node> fresh = start, held = start;
  rod::Stepper st_fresh, st_held;
  rod::Tangent tangent;
  st_fresh.initialise(fresh, els, opt);
  st_held.initialise(held, els, opt);
  long it_fresh = 0, it_held = 0, tg_fresh = 0, tg_held = 0;
  bool ok = true;
  double diff = 0, prev_y = held[ne].x.y, t_prev = 0;
  std::vector<double> crossings;
  for (int k = 1; k <= steps; ++k) {
    const rod::Stats a = st_fresh.step(fresh, els, h, g, opt);
    const rod::Stats b = st_held.step(held, els, h, g, opt, nullptr, &tangent);
    ok = ok && a.ok && b.ok;
    it_fresh += a.iterations;
    it_held += b.iterations;
    tg_fresh += a.tangents;
    tg_held += b.tangents;
    for (int n = 0; n <= ne; ++n) diff = std::max(diff, beam::norm(fresh[n].x - held[n].x));
    const double y = held[ne].x.y, t = k * h;
    if ((prev_y > 0) != (y > 0)) crossings.push_back(t_prev + (t - t_prev) * prev_y / (prev_y - y));
    prev_y = y;
    t_prev = t;
  }
  expect(ok, "tangent reuse: every step converges");
  const double measured = 2.0 * (crossings.back() - crossings.front()) / (crossings.size() - 1);
  expect(crossings.size() >= 8 && std::fabs(measured / period - 1) < 0.01,
         "tangent reuse: first bending period within 1 % of Euler-Bernoulli", measured, period);
  expect(diff <= 1e-4 * 1e-3 * L, "tangent reuse: same trajectory as a new tangent per step", diff, 1e-4 * 1e-3 * L);
  const double tps = static_cast<double>(tg_held) / steps;
  expect(tg_fresh == steps && tps < 0.2, "tangent reuse: fewer than 0.2 tangents per step", tps, 0.2);
  expect(it_held <= it_fresh + steps, "tangent reuse: at most one more iteration per step",
         static_cast<double>(it_held) / steps, static_cast<double>(it_fresh) / steps);
  const rod::Stats c = st_held.step(held, els, 0.5 * h, g, opt, nullptr, &tangent);
  expect(c.ok && c.tangents >= 1, "tangent reuse: a new step size forms a new tangent", c.tangents, 1);
  std::printf("tangent reuse: %.2f / %.2f Newton iterations and %.3f / 1 tangents per step (held / new), "
              "period %.6e s (Euler-Bernoulli %.6e s), largest difference %.2e m\n",
              static_cast<double>(it_held) / steps, static_cast<double>(it_fresh) / steps, tps, measured, period, diff);
}

// A stiff unilateral contact spring as a NodeForceModel, saturating like the steric servo S1
// (physics/steric.h, without its damping): F = k c tanh(-z / c) upwards for z < 0.
class UnilateralSpring : public rod::NodeForceModel {
 public:
  UnilateralSpring(double k, double c) : k_(k), c_(c) {}
  void evaluate(const std::vector<rod::Node> &nodes, std::vector<Vec3> &F, rod::ForceJacobian *J) override {
    const double z = nodes[0].x.z;
    if (z >= 0.0) return;
    F[0].z += k_ * c_ * std::tanh(-z / c_);
    if (J) J->Kd[8] += -k_ / std::pow(std::cosh(z / c_), 2);
  }

 private:
  double k_, c_;
};

// Contact force weighting (rod::contact_force_weight, docs/models/contact.md section 10): one node
// of a log-cabin stack's top layer (tests/test_press_stack.py: 2.36e-10 kg) on a stiff unilateral
// spring of the steric servo's stiffness 2 m / t_R^2 (t_R = 1e-7 s, omega h = 141 at h = 1e-5 s),
// saturating at 2 nm (no damping: the servo's PD damping is left out to expose the scheme):
// * statics: pressed by a load P it rests with the spring force = P (the weighting keeps statics);
// * impact at v0 = 0.1 mm/s, 5 steps above the spring: the rebound speed. Alpha-averaged like the
//   internal forces (contact_at_end = false, printed), the force of the step that caught the node
//   kept pushing in the next one, after the contact had opened: rebound 2.37 v0 at rho_inf 0.5,
//   2.91 v0 at 0.8 (and at 0.8 the node pressed by P did not come to rest). Taken at the end of
//   the step: 1.25 v0 at 0.5 and 0.8, 1.00 at 0 (the remaining gain is the Newmark relation of
//   displacement and velocity, gamma / beta; in fiberdem the PD damping of S1 removes it).
void test_contact_weighting() {
  // a layer-3 node of the log-cabin stack (tests/test_press_stack.py) on the servo's stiffness 2 m / t_R^2
  const double m = 2.36e-10, h = 1e-5, t_R = 1e-7, k = 2.0 * m / (t_R * t_R), c = 2e-9, P = 0.5 * k * c, v0 = 1e-4;
  for (bool at_end : {true, false}) {
    for (double rho : {0.0, 0.5, 0.8}) {
      const rod::GenAlpha g = rod::gen_alpha(rho);
      rod::Options opt;
      opt.tol = 1e-12;
      opt.contact_at_end = at_end;
      std::vector<rod::Element> none;
      UnilateralSpring spring(k, c);
      std::vector<rod::NodeForceModel *> models{&spring};
      // statics
      std::vector<rod::Node> nodes{free_node(m, {1e-18, 1e-18, 1e-18})};
      nodes[0].x = {0, 0, -P / k};
      nodes[0].F = {0, 0, -P};
      rod::Stepper st;
      st.initialise(nodes, none, opt);
      bool ok = true;
      for (int s = 0; s < 200; ++s) ok = ok && st.step(nodes, none, h, g, opt, &models).ok;
      const double rest_v = std::fabs(nodes[0].v.z), rest_f = nodes[0].Fmodel.z;
      // impact: released 5 v0 h above the spring, moving down at v0
      nodes = {free_node(m, {1e-18, 1e-18, 1e-18})};
      nodes[0].x = {0, 0, 5.0 * v0 * h};
      nodes[0].v = {0, 0, -v0};
      st.initialise(nodes, none, opt);
      double vmax = 0.0;
      for (int s = 0; s < 30; ++s) {
        ok = ok && st.step(nodes, none, h, g, opt, &models).ok;
        vmax = std::max(vmax, nodes[0].v.z);
      }
      char what[160];
      std::snprintf(what, sizeof what, "contact weighting (rho_inf %.1f, %s): steps converge", rho, at_end ? "end" : "alpha");
      expect(ok, what);
      std::printf("contact weighting rho_inf %.1f, contact forces %s: at rest |v| %.1e m/s, spring force / load "
                  "%.9f; impact: rebound speed / v0 %.3f\n",
                  rho, at_end ? "at the end of the step" : "alpha-averaged", rest_v, rest_f / P, vmax / v0);
      if (!at_end) continue;  // the former weighting: printed only
      std::snprintf(what, sizeof what, "contact weighting (rho_inf %.1f): at rest under the load", rho);
      expect(rest_v < 1e-9 && std::fabs(rest_f / P - 1.0) < 1e-6, what, rest_f / P, 1.0);
      std::snprintf(what, sizeof what, "contact weighting (rho_inf %.1f): rebound at most 1.25 v0 (alpha-averaged: 2.4 v0)", rho);
      expect(vmax <= (rho > 0.0 ? 1.25 : 1.0) * v0 * (1.0 + 1e-3), what, vmax / v0, rho > 0.0 ? 1.25 : 1.0);
    }
  }
  expect(std::fabs(rod::contact_force_weight(rod::gen_alpha(0.5)) - 1.5) < 1e-15, "contact weight 1/(1 - af) at rho_inf 0.5",
         rod::contact_force_weight(rod::gen_alpha(0.5)), 1.5);
}

// Modified Newton across steps with a force model whose derivative jumps (the unilateral spring
// above): the impact of test_contact_weighting solved with a held tangent (tangent_steps 50) keeps
// its bounds (rebound at most 1.25 v0 at rho_inf 0.5, rest under the load with the spring force =
// load), forms no tangent in the free flight before the impact, and needs no more Newton
// iterations over the impact than with a new tangent in every step (the step that closes the
// contact starts on the held tangent of the flight and backtracks across the kink like a new one).
void test_tangent_reuse_contact() {
  const double m = 2.36e-10, h = 1e-5, t_R = 1e-7, k = 2.0 * m / (t_R * t_R), c = 2e-9, P = 0.5 * k * c, v0 = 1e-4;
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  rod::Options opt;
  opt.tol = 1e-12;
  opt.tangent_steps = 50;
  std::vector<rod::Element> none;
  UnilateralSpring spring(k, c);
  std::vector<rod::NodeForceModel *> models{&spring};
  bool ok = true;
  long iters[2] = {0, 0}, flight_tangents = 0;
  double vmax = 0.0;
  for (int held = 0; held < 2; ++held) {
    rod::Stepper st;
    rod::Tangent tangent;
    // impact: released 5 v0 h above the spring, moving down at v0
    std::vector<rod::Node> nodes{free_node(m, {1e-18, 1e-18, 1e-18})};
    nodes[0].x = {0, 0, 5.0 * v0 * h};
    nodes[0].v = {0, 0, -v0};
    st.initialise(nodes, none, opt);
    for (int s = 0; s < 30; ++s) {
      const rod::Stats r = st.step(nodes, none, h, g, opt, &models, held ? &tangent : nullptr);
      ok = ok && r.ok;
      iters[held] += r.iterations;
      if (held && s > 0 && s < 4) flight_tangents += r.tangents;
      if (held) vmax = std::max(vmax, nodes[0].v.z);
    }
    if (!held) continue;
    // statics: pressed by the load P
    nodes = {free_node(m, {1e-18, 1e-18, 1e-18})};
    nodes[0].x = {0, 0, -P / k};
    nodes[0].F = {0, 0, -P};
    st.initialise(nodes, none, opt);
    for (int s = 0; s < 200; ++s) ok = ok && st.step(nodes, none, h, g, opt, &models, &tangent).ok;
    expect(std::fabs(nodes[0].v.z) < 1e-9 && std::fabs(nodes[0].Fmodel.z / P - 1.0) < 1e-6,
           "tangent reuse with contact: at rest under the load", nodes[0].Fmodel.z / P, 1.0);
  }
  expect(ok, "tangent reuse with contact: steps converge");
  expect(flight_tangents == 0, "tangent reuse with contact: free flight keeps the tangent", flight_tangents, 0);
  expect(iters[1] <= iters[0], "tangent reuse with contact: no more iterations than new tangents", iters[1], iters[0]);
  expect(vmax <= 1.25 * v0 * (1.0 + 1e-3), "tangent reuse with contact: rebound at most 1.25 v0", vmax / v0, 1.25);
  std::printf("tangent reuse with contact: rebound speed / v0 %.3f; Newton iterations over the impact %ld (held) / "
              "%ld (new tangent every step)\n", vmax / v0, iters[1], iters[0]);
}


// Split memory (rod::remember_split, rod::merge_split, Stepper::step's first_depth):
// * the policy: one level deeper after a step none of whose sub-steps converged whole, not calm
//   when some failed, one level coarser after `relax_after` calm steps, nothing remembered with
//   relax_after 0; a cluster takes its deepest fiber's memory;
// * free flight under a constant force is exactly quadratic in time (test_free_node), so a step
//   started as 8 sub-steps lands on the closed form too;
// * the impact of test_contact_weighting made hard (v0 = 0.2 m/s, 4 Newton iterations per
//   attempt): a step that fails whole and is split gives to the bit the state of the step started
//   as two halves (each split further alike), and the started one does not pay the failed
//   attempt's iterations.
void test_split_memory() {
  using rod::SplitMemory;
  const auto same = [](SplitMemory a, int d, int c) { return a.depth == d && a.calm == c; };
  expect(same(rod::remember_split({0, 0}, 1, 0), 0, 0), "split memory: off with relax_after 0");
  expect(same(rod::remember_split({0, 4}, 1, 5), 1, 0) && same(rod::remember_split({2, 2}, 4, 5), 3, 0),
         "split memory: no sub-step converged whole: one level deeper");
  expect(same(rod::remember_split({2, 3}, 3, 5), 2, 0), "split memory: some sub-steps failed: not calm");
  expect(same(rod::remember_split({2, 3}, 0, 5), 2, 4), "split memory: a calm step is counted");
  expect(same(rod::remember_split({2, 4}, 0, 5), 1, 0), "split memory: one level coarser after 5 calm steps");
  expect(same(rod::remember_split({0, 4}, 0, 5), 0, 5), "split memory: whole steps stay whole");
  expect(same(rod::merge_split({1, 9}, {2, 7}), 2, 7) && same(rod::merge_split({2, 3}, {2, 7}), 2, 3),
         "split memory: a cluster takes the deepest, least calm memory");

  const rod::GenAlpha g = rod::gen_alpha(0.5);
  std::vector<rod::Element> none;
  {
    rod::Options opt;
    opt.tol = 1e-12;
    const double m = 2e-9, h = 1e-4, Fz = -3e-6;
    std::vector<rod::Node> nodes{free_node(m, {1e-18, 1e-18, 1e-18})};
    nodes[0].v = {1e-3, 0, 2e-3};
    nodes[0].F = {0, 0, Fz};
    rod::Stepper st;
    st.initialise(nodes, none, opt);
    const rod::Stats r = st.step(nodes, none, h, g, opt, nullptr, nullptr, 3);
    const double z = 2e-3 * h + 0.5 * Fz / m * h * h, vz = 2e-3 + Fz / m * h;
    expect(r.ok && r.splits == 7 && r.depth == 3, "split memory: started as 8 sub-steps", r.splits, 7);
    expect(std::fabs(nodes[0].x.z - z) < 1e-12 * std::fabs(z) + 1e-20 && std::fabs(nodes[0].x.x - 1e-3 * h) < 1e-20 &&
               std::fabs(nodes[0].v.z - vz) < 1e-12 * std::fabs(vz),
           "split memory: free flight in 8 sub-steps = closed form", nodes[0].x.z, z);
  }
  const double m = 2.36e-10, h = 1e-5, t_R = 1e-7, k = 2.0 * m / (t_R * t_R), c = 2e-9, v0 = 0.2;
  rod::Options opt;
  opt.tol = 1e-12;
  opt.max_iter = 4;
  UnilateralSpring spring(k, c);
  std::vector<rod::NodeForceModel *> models{&spring};
  std::vector<rod::Node> a{free_node(m, {1e-18, 1e-18, 1e-18})};
  a[0].x = {0, 0, 0.3 * v0 * h};
  a[0].v = {0, 0, -v0};
  rod::Stepper sa, sb;
  sa.initialise(a, none, opt);
  std::vector<rod::Node> b = a;
  const rod::Stats ra = sa.step(a, none, h, g, opt, &models);
  const rod::Stats rb = sb.step(b, none, h, g, opt, &models, nullptr, 1);
  double dx = 0, dv = 0;
  if (ra.ok && rb.ok) {
    dx = beam::norm(a[0].x - b[0].x);
    dv = beam::norm(a[0].v - b[0].v);
  }
  expect(ra.ok && ra.depth >= 1, "split memory: the hard impact step is split", ra.depth, 1);
  expect(rb.ok && dx == 0.0 && dv == 0.0, "split memory: the started step = the split one, to the bit", dx, 0.0);
  expect(ra.start_failed == 1 && rb.start_failed >= 0 && rb.start_failed <= 2,
         "split memory: failed sub-steps of the start level counted", static_cast<double>(ra.start_failed), 1);
  expect(rb.iterations + opt.max_iter <= ra.iterations, "split memory: without the failed attempt's iterations",
         static_cast<double>(rb.iterations), static_cast<double>(ra.iterations));
  std::printf("split memory: impact at %.2f m/s split to depth %d (%d sub-steps beyond one, %ld Newton iterations); "
              "started as two halves: %ld iterations, difference %.1e m\n",
              v0, ra.depth, ra.splits, ra.iterations, rb.iterations, dx);
}
}  // namespace

// The element tangent (analytic translation and rotation columns for elastic elements, finite
// rotation columns with damping) against central differences of the element forces mapped to the
// residual here: r = -(f_A, R_A^T t_A, f_B, R_B^T t_B), translations spatial, rotations body-frame
// right perturbations q -> q exp(e).
void test_element_tangent() {
  using namespace fiberform::physics;
  std::mt19937_64 gen(7);
  auto uni = [&](double a) { return std::uniform_real_distribution<double>(-a, a)(gen); };
  auto rv = [&](double a) { return beam::Vec3{uni(a), uni(a), uni(a)}; };
  const beam::Section sec = beam::hollow_ellipse(12e-6, 5e-6, 6e-6, 2e-6);
  auto residual = [](const beam::NodeState &A, const beam::NodeState &B, const rod::Element &el, double td,
                     double r[12]) {
    const beam::ElementForces f = beam::element_forces(A, B, el.ref, el.C, td);
    const beam::Vec3 parts[4] = {f.fA, beam::qrot_t(A.q, f.tA), f.fB, beam::qrot_t(B.q, f.tB)};
    for (int p = 0; p < 4; ++p)
      for (int c = 0; c < 3; ++c) r[3 * p + c] = -parts[p][c];
  };
  double worst[2] = {0, 0};
  for (int t = 0; t < 30; ++t) {
    const double td = t % 3 == 2 ? 1e-6 : 0.0;  // every third with damping (finite rotation columns)
    beam::NodeState A, B;
    A.q = beam::qnormalize({uni(1), uni(1), uni(1), uni(1)});
    B.q = beam::qmul(A.q, beam::qexp(rv(t < 10 ? 1e-3 : 0.8)));
    B.x = A.x + 5e-5 * (beam::Vec3{0, 0, 1} + rv(0.3));
    rod::Element el;
    el.ref = beam::element_reference(A.x, A.q, B.x, B.q);
    el.C = beam::section_stiffness(sec, 20e9, 3e9, 5.0 / 6.0);
    B.x = B.x + rv(1e-5);
    A.q = beam::qmul(beam::qexp(rv(0.4)), A.q);
    B.q = beam::qmul(beam::qexp(rv(0.4)), B.q);
    A.v = rv(1e-2); B.v = rv(1e-2); A.w = rv(100); B.w = rv(100);
    double r0[12], K[144];
    beam::ElementChordGradient g;
    rod::Stepper::element_residual(A, B, el, td, r0, &g);
    rod::Stepper::element_tangent(A, B, el, td, r0, g, K);
    double kmax = 0;
    for (double k : K) kmax = std::fmax(kmax, std::fabs(k) * (1.0));
    for (int c = 0; c < 12; ++c) {
      const int k = c % 6;
      const double h = k < 3 ? 1e-9 : 1e-6;
      beam::NodeState Ap = A, Am = A, Bp = B, Bm = B;
      beam::NodeState &P = c < 6 ? Ap : Bp, &M = c < 6 ? Am : Bm;
      if (k < 3) {
        P.x[k] += h;
        M.x[k] -= h;
      } else {
        beam::Vec3 e{};
        e[k - 3] = h;
        P.q = beam::qmul(P.q, beam::qexp(e));
        M.q = beam::qmul(M.q, beam::qexp(-1.0 * e));
      }
      double rp[12], rm[12];
      residual(Ap, Bp, el, td, rp);
      residual(Am, Bm, el, td, rm);
      // columns compared in their own units (force or torque per metre or per radian)
      double cmax = 0, err = 0;
      for (int r = 0; r < 12; ++r) {
        const double num = (rp[r] - rm[r]) / (2 * h);
        cmax = std::fmax(cmax, std::fabs(num));
        err = std::fmax(err, std::fabs(num - K[r * 12 + c]));
      }
      const double rel = err / (cmax + 1e-300);
      const int kind = td > 0 ? 1 : 0;
      worst[kind] = std::fmax(worst[kind], rel);
    }
  }
  // elastic: analytic columns (central differences here: 1e-8); damped: the rotation columns are
  // forward differences of step 1e-7 rad in the code (1e-6 relative)
  expect(worst[0] < 1e-6, "element tangent (elastic, analytic) = central differences", worst[0], 0);
  expect(worst[1] < 1e-5, "element tangent (damped) = central differences", worst[1], 0);
  std::printf("  element tangent: worst column error %.2e (elastic), %.2e (damped)\n", worst[0], worst[1]);
}

int main() {
  test_element_tangent();
  test_block_solve();
  test_parameters();
  test_free_node();
  test_spectral_radius();
  test_cantilever_statics();
  test_contact_weighting();
  test_tangent_reuse();
  test_tangent_reuse_contact();
  test_split_memory();
  return fiberform::check::finish("test_implicit_rod");
}
