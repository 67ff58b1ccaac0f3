/* SPDX-License-Identifier: GPL-3.0-or-later
   The press plate's pressure servo (fix wall/fiber/dlvo `servo`, docs/models/press.md):
   a piecewise-linear target pressure p_t(t) and the plate speed that drives the measured contact
   pressure p towards it,

       u = clamp(u_max (p_t - p) / p_ref, -u_max, u_max)     (u > 0: towards the fibers),

   a proportional law on the plate VELOCITY, hence integral action on the plate POSITION: at rest
   (u = 0) the measured pressure equals the target exactly, whatever the sheet's stiffness. For a
   sheet of pressure-stiffness K = dp/dz (Pa/m) the pressure approaches its target with the time
   constant tau = p_ref / (u_max K); one plate step changes p by u_max K dt (p_t - p) / p_ref, so
   the discrete loop is monotone while u_max K dt / p_ref < 1. Pure functions, unit-tested in
   tests/test_press_servo.cpp. */
#ifndef FIBERFORM_PHYSICS_PRESS_SERVO_H
#define FIBERFORM_PHYSICS_PRESS_SERVO_H

#include <algorithm>
#include <cstddef>
#include <vector>

namespace fiberform::physics::press {

// A piecewise-linear schedule (t_k, p_k), t ascending; constant before the first and after the
// last point. Empty: zero everywhere.
struct Schedule {
  std::vector<double> t, p;

  double at(double time) const {
    if (t.empty()) return 0.0;
    if (time <= t.front()) return p.front();
    if (time >= t.back()) return p.back();
    const std::size_t k = static_cast<std::size_t>(std::upper_bound(t.begin(), t.end(), time) - t.begin());
    const double w = (time - t[k - 1]) / (t[k] - t[k - 1]);
    return p[k - 1] + w * (p[k] - p[k - 1]);
  }
  // true when the times ascend strictly (k > 0) and the sizes agree
  bool valid() const {
    if (t.size() != p.size()) return false;
    for (std::size_t k = 1; k < t.size(); ++k)
      if (!(t[k] > t[k - 1])) return false;
    return true;
  }
};

// The plate speed towards the fibers (m/s) for target p_t and measured p (Pa); p_ref > 0, u_max > 0.
inline double servo_speed(double p_target, double p, double p_ref, double u_max) {
  const double u = u_max * (p_target - p) / p_ref;
  return std::clamp(u, -u_max, u_max);
}

// The same law with its gain limited by a stiffness bound: K_bound (Pa/m) an upper bound of the
// sheet's pressure stiffness dp/dz seen by the plate (the plate contacts' own stiffness: the
// fibers are in series with it). With the gain g = min(u_max / p_ref, 1 / (n K_bound dt)) one step
// closes at most 1/n of the pressure error on a linear sheet, so the discrete loop is monotone
// for n >= 1 whatever the contact stiffness (without the bound, u_max K dt / p_ref > 1 gives a limit
// cycle: measured 0 <-> 15 Pa around a 4 Pa target on one fiber, docs/models/press.md).
inline double servo_speed_bounded(double p_target, double p, double p_ref, double u_max, double K_bound,
                                  double dt, double n, double m = 1.0) {
  double g = u_max / p_ref;
  if (K_bound > 0.0) g = std::min(g, m / (n * K_bound * dt));
  return std::clamp(g * (p_target - p), -u_max, u_max);
}

// The bound above uses the plate contacts' own stiffness, an UPPER bound of the sheet's: a soft
// sheet (fibers bending between crossings; measured on a log-cabin stack: 7000 x softer) would be
// approached with a time constant of thousands of steps. GainAdapt multiplies the bounded gain by
// m >= 1: m grows by `grow` per step while the pressure error keeps its sign and halves when the
// error changes sign (an overshoot), so the loop finds the sheet's own stiffness in a few tens of
// steps and backs off as soon as it rings. (Unit-tested on a soft linear sheet and on a stiff one.)
struct GainAdapt {
  double m = 1.0, prev_err = 0.0;
  double grow = 1.1, m_max = 1e6;

  double update(double err) {
    if (prev_err * err < 0.0)
      m = std::max(1.0, 0.5 * m);
    else if (err != 0.0)
      m = std::min(m_max, grow * m);
    prev_err = err;
    return m;
  }
};

// A peak-hold estimate of a stiffness bound that forgets at rate `decay` per step (0 < decay <= 1):
// max(now, decay * previous). Contacts that open for a step do not reset the bound at once.
inline double stiffness_bound(double previous, double now, double decay) {
  return std::max(now, decay * previous);
}

// The contact pressure on a plate of area A (m^2) with inward normal n from the total contact
// force F on the fibers (N): the plate pushes the fibers along +n in compression.
inline double plate_pressure(const double F[3], const double n[3], double area) {
  return (F[0] * n[0] + F[1] * n[1] + F[2] * n[2]) / area;
}

}  // namespace fiberform::physics::press

#endif
