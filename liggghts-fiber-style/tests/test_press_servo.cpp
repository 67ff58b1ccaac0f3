/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of physics/press_servo.h: the piecewise-linear schedule against hand values, the
   servo's clamp and sign, and the closed loop against a linear spring sheet p = K (z0 - z): the
   pressure reaches the target without overshoot and settles at it exactly (integral action), with
   the time constant p_ref / (u_max K) of the continuous loop (exp(-1) after tau within 1 %). */
#include <cmath>

#include "check.h"
#include "physics/press_servo.h"

using namespace fiberform::physics::press;
using fiberform::check::expect;

namespace {

void test_schedule() {
  Schedule s{{0.0, 1e-3, 3e-3, 4e-3}, {0.0, 1e4, 1e4, 0.0}};
  expect(s.valid(), "ascending schedule is valid");
  expect(s.at(-1.0) == 0.0, "before the first point: first value", s.at(-1.0), 0.0);
  expect(std::fabs(s.at(0.5e-3) - 5e3) < 1e-9, "ramp midpoint", s.at(0.5e-3), 5e3);
  expect(std::fabs(s.at(2e-3) - 1e4) < 1e-9, "hold", s.at(2e-3), 1e4);
  expect(std::fabs(s.at(3.25e-3) - 7.5e3) < 1e-9, "unload quarter", s.at(3.25e-3), 7.5e3);
  expect(s.at(9.0) == 0.0, "after the last point: last value", s.at(9.0), 0.0);
  Schedule bad{{0.0, 0.0}, {1.0, 2.0}};
  expect(!bad.valid(), "repeated time is invalid");
  expect(Schedule{}.at(1.0) == 0.0, "empty schedule is zero", 0, 0);
}

void test_speed() {
  expect(servo_speed(1e4, 0.0, 1e3, 2e-3) == 2e-3, "far below target: full speed in", 0, 0);
  expect(servo_speed(0.0, 1e4, 1e3, 2e-3) == -2e-3, "far above target: full speed out", 0, 0);
  const double u = servo_speed(1e4, 9.5e3, 1e3, 2e-3);
  expect(std::fabs(u - 1e-3) < 1e-15, "proportional band", u, 1e-3);
  const double F[3] = {1.0, 2.0, -3.0}, n[3] = {0.0, 0.0, -1.0};
  expect(std::fabs(plate_pressure(F, n, 1e-6) - 3e6) < 1e-6, "pressure from the force on the fibers",
         plate_pressure(F, n, 1e-6), 3e6);
}

void test_closed_loop() {
  // sheet spring: p = K max(0, z0 - z) with the plate at z moving down at speed u
  const double K = 1e10, z0 = 1e-4, pt = 2e4, pref = 2e3, umax = 1e-3, dt = 1e-7;
  const double tau = pref / (umax * K);  // 0.2 ms inside the proportional band
  double z = z0 + 5e-6, t = 0.0, pmax = 0.0, p = 0.0;
  double t_band = -1.0;  // when the loop enters the proportional band
  double p_at_tau = -1.0;
  for (int k = 0; k < 200000; ++k) {
    p = K * std::max(0.0, z0 - z);
    pmax = std::max(pmax, p);
    if (t_band < 0 && pt - p < pref) t_band = t;
    if (t_band >= 0 && p_at_tau < 0 && t >= t_band + tau) p_at_tau = p;
    z -= servo_speed(pt, p, pref, umax) * dt;
    t += dt;
  }
  expect(pmax <= pt * (1 + 1e-12), "no overshoot", pmax, pt);
  expect(std::fabs(p - pt) < 1e-6 * pt, "settles at the target", p, pt);
  // inside the band: pt - p = pref exp(-(t - t_band)/tau)
  const double want = pt - pref * std::exp(-1.0);
  expect(std::fabs(p_at_tau - want) < 0.01 * pref, "time constant p_ref/(u_max K)", p_at_tau, want);
}

// A contact far stiffer than the band allows (u_max K dt / p_ref = 250): the plain law cycles
// between full speed in and out; the bounded law (K_bound = K) settles monotonically, closing 1/n
// of the error per step.
void test_bounded_loop_on_a_stiff_contact() {
  const double K = 1e12, z0 = 1e-4, pt = 20.0, pref = 2.0, umax = 5e-3, dt = 1e-6, n = 4.0;
  auto run = [&](bool bounded, double &pmax, double &spread_late) {
    double z = z0 - 1e-12, p = 0.0, lo = 1e300, hi = -1e300;
    pmax = 0.0;
    for (int k = 0; k < 2000; ++k) {
      p = K * std::max(0.0, z0 - z);
      pmax = std::max(pmax, p);
      if (k >= 1500) {
        lo = std::min(lo, p);
        hi = std::max(hi, p);
      }
      const double u = bounded ? servo_speed_bounded(pt, p, pref, umax, K, dt, n) : servo_speed(pt, p, pref, umax);
      z -= u * dt;
    }
    spread_late = hi - lo;
    return p;
  };
  double pmax = 0.0, spread = 0.0;
  run(false, pmax, spread);
  expect(spread > pt, "plain law on a stiff contact: a limit cycle (the reason for the bound)", spread, pt);
  const double p = run(true, pmax, spread);
  // to the round-off of z (ulp(1e-4 m) x K = 1.4e-8 Pa)
  expect(std::fabs(p - pt) < 1e-6 * pt, "bounded law settles at the target", p, pt);
  expect(pmax <= pt * (1 + 1e-12), "bounded law: no overshoot", pmax, pt);
  expect(spread < 1e-6 * pt, "bounded law: at rest", spread, 0.0);
  // one step from rest closes exactly 1/n of the error on a linear contact
  const double u = servo_speed_bounded(pt, 0.0, pref, umax, K, dt, n);
  expect(std::fabs(K * u * dt - pt / n) < 1e-12 * pt, "one step closes 1/n of the error", K * u * dt, pt / n);
  expect(stiffness_bound(10.0, 1.0, 0.5) == 5.0 && stiffness_bound(1.0, 10.0, 0.5) == 10.0,
         "peak-hold stiffness bound", 0, 0);
}

// The adaptive multiplier on a sheet 7000 x softer than its bound (K_bound = 7000 K): without it
// the time constant is 4 x 7000 steps; with it the error falls below 1e-3 within 600 steps (250 at
// the speed limit), and on
// a sheet AS stiff as its bound it never overshoots by more than a few per cent before settling.
void test_adaptive_gain() {
  const double pt = 2.5, pref = 2.5, umax = 1e-4, dt = 1e-5, n = 4.0, z0 = 1e-3;
  auto run = [&](double K, double K_bound, bool adapt, int steps, double &pmax) {
    GainAdapt a;
    double z = z0, p = 0.0;
    pmax = 0.0;
    for (int k = 0; k < steps; ++k) {
      p = K * std::max(0.0, z0 - z);
      pmax = std::max(pmax, p);
      const double m = adapt ? a.update(pt - p) : 1.0;
      z -= servo_speed_bounded(pt, p, pref, umax, K_bound, dt, n, m) * dt;
    }
    return p;
  };
  double pmax = 0.0;
  const double K = 1e8;  // Pa/m: 25 nm of travel for the target (250 steps at u_max)
  const double slow = run(K, 7000 * K, false, 300, pmax);
  expect(pt - slow > 0.9 * pt, "bounded gain on a soft sheet: barely moved in 300 steps", slow, pt);
  const double fast = run(K, 7000 * K, true, 600, pmax);
  expect(std::fabs(fast - pt) < 1e-3 * pt, "adaptive gain: at the target within 600 steps", fast, pt);
  const double stiff = run(K, K, true, 2000, pmax);
  expect(std::fabs(stiff - pt) < 1e-6 * pt, "adaptive gain on a stiff sheet: settles", stiff, pt);
  expect(pmax < 1.5 * pt, "adaptive gain on a stiff sheet: bounded overshoot", pmax, pt);
}

}  // namespace

int main() {
  test_schedule();
  test_speed();
  test_closed_loop();
  test_bounded_loop_on_a_stiff_contact();
  test_adaptive_gain();
  return fiberform::check::finish("test_press_servo");
}
