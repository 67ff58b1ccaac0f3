/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of the per-contact sub-integration (src/contact_integrator.*): free motion gives no
   force, internal forces conserve momentum exactly, an elastic collision resolved inside one
   fiber step conserves energy and reverses the relative velocity (closed form), CVODE and
   fixed sub-steps agree, and a wall (infinite mass) reflects a point. */
#include <cmath>
#include <cstdio>
#include <initializer_list>

#include "contact_integrator.h"

using namespace fiberform;
using namespace fiberform::physics;

static int failures = 0;
static void expect(bool ok, const char *what, double a = 0, double b = 0) {
  if (!ok) {
    std::fprintf(stderr, "FAIL: %s (%.17g vs %.17g)\n", what, a, b);
    ++failures;
  }
}

int main() {
  ContactLaw L;
  L.terms = kSteric;
  L.steric = {1e-9, 0.5e-9, 1e-9, 1e-8};
  L.steric.s2 = L.steric.s3 = L.steric.s4 = false;
  L.steric.s1_damping = false;  // conservative spring 2 mu (h_R - h)/t_R^2 B1(h)
  const double m = 1e-14, r = 7e-6, v0 = 0.05, dt = 1e-6;
  PairLaw pl;
  pl.setup(L, r, r, 1 / m, 1 / m, 0, 0);
  PairGeometry g;
  g.offset = 2 * r;
  ContactIntegrator cv, ss;
  cv.configure(ContactIntegrator::Method::Cvode, 0, 1e-8, 1e-15);
  ss.configure(ContactIntegrator::Method::Substep, 20000, 0, 0);

  // 1) far apart: exactly zero
  {
    PointState a{{0, 0, 0}, {v0, 0, 0}, {0, 0, 0}, 1 / m}, b{{2 * r + 1e-6, 0, 0}, {-v0, 0, 0}, {0, 0, 0}, 1 / m};
    const PairResult res = cv.solve(pl, g, a, b, dt);
    expect(res.fpos1.x == 0 && res.fvel1.x == 0 && res.fpos2.x == 0, "no force out of range");
  }
  // 2) head-on: gap 20 nm, approach 2*v0 = 0.1 m/s -> contact after 0.2 us, the collision lasts
  //    pi/omega with omega = sqrt(2 k/m) = sqrt(2)/t_R ... well inside dt = 1 us
  {
    PointState a{{0, 0, 0}, {v0, 0, 0}, {0, 0, 0}, 1 / m}, b{{2 * r + 20e-9, 0, 0}, {-v0, 0, 0}, {0, 0, 0}, 1 / m};
    for (ContactIntegrator *ig : {&cv, &ss}) {
      const PairResult res = ig->solve(pl, g, a, b, dt);
      // momentum: the internal forces cancel to round-off
      expect(std::fabs(res.fpos1.x + res.fpos2.x) <= 1e-12 * std::fabs(res.fpos1.x), "momentum (positions)", res.fpos1.x, res.fpos2.x);
      expect(std::fabs(res.fvel1.x + res.fvel2.x) <= 1e-12 * std::fabs(res.fvel1.x), "momentum (velocities)", res.fvel1.x, res.fvel2.x);
      // elastic: end velocities reversed, v_end = v0 + F_vel dt / m
      const double va = v0 + res.fvel1.x * dt / m, vb = -v0 + res.fvel2.x * dt / m;
      expect(std::fabs(va + v0) < 1e-5 * v0 && std::fabs(vb - v0) < 1e-5 * v0, "elastic: velocities reversed", va, vb);
      expect(std::fabs(0.5 * m * (va * va + vb * vb) / (m * v0 * v0) - 1) < 1e-5, "kinetic energy conserved");
    }
    const PairResult a1 = cv.solve(pl, g, a, b, dt), a2 = ss.solve(pl, g, a, b, dt);
    expect(std::fabs(a1.fpos1.x - a2.fpos1.x) < 1e-5 * std::fabs(a2.fpos1.x), "CVODE = fine sub-steps (position force)", a1.fpos1.x, a2.fpos1.x);
    // reuse of the memory block gives the same answer
    const PairResult a3 = cv.solve(pl, g, a, b, dt);
    expect(a3.fpos1.x == a1.fpos1.x && a3.fvel1.x == a1.fvel1.x, "reused CVODE memory is deterministic");
  }
  // 3) plane (infinite mass): a point hitting a wall at v0 leaves with -v0
  {
    PairLaw pw;
    pw.setup(L, r, INFINITY, 1 / m, 0.0, 0, 0);
    PairGeometry gw;
    gw.plane = true;
    gw.normal = {0, 0, 1};
    gw.offset = r;
    PointState a{{0, 0, r + 10e-9}, {0, 0, -v0}, {0, 0, 0}, 1 / m}, w{{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, 0.0};
    const PairResult res = cv.solve(pw, gw, a, w, dt);
    const double vz = -v0 + res.fvel1.z * dt / m;
    expect(std::fabs(vz - v0) < 1e-5 * v0, "wall reflects", vz, v0);
    expect(res.fpos2.z == 0 && res.fvel2.z == 0, "wall gets no force");
  }
  // 4) damped steric (all terms): no pass-through at 5 m/s head-on, resolved in one step
  {
    ContactLaw Ld;
    Ld.terms = kSteric | kVdw;
    PairLaw pd;
    pd.setup(Ld, r, r, 1 / m, 1 / m, 0, 0);
    const double v = 5.0;
    PointState a{{0, 0, 0}, {v, 0, 0}, {0, 0, 0}, 1 / m}, b{{2 * r + 20e-9, 0, 0}, {-v, 0, 0}, {0, 0, 0}, 1 / m};
    const PairResult res = cv.solve(pd, g, a, b, dt);
    const double xa = 0 + v * dt + 0.5 * res.fpos1.x / m * dt * dt;
    const double xb = 2 * r + 20e-9 - v * dt + 0.5 * res.fpos2.x / m * dt * dt;
    expect(res.ok && xb - xa > 0, "no pass-through at 5 m/s", xb - xa, 0);
    const double va = v + res.fvel1.x * dt / m, vb = -v + res.fvel2.x * dt / m;
    expect(0.5 * m * (va * va + vb * vb) <= m * v * v, "kinetic energy does not grow", va, vb);
  }
  std::printf("test_contact_integrator: %s\n", failures ? "FAILED" : "ok");
  return failures ? 1 : 0;
}
