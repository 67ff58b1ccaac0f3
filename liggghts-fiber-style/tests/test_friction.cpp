/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of physics/friction.h (Coulomb friction of an averaged contact point on a static body)
   against hand-computed values: a point of 2 ug sliding at 1 mm/s along x on a plane z = 0 with a
   tangential load of 1 nN along y; step 1 us, gamma 1.
   - stick (limit large): the force that stops the tangential motion over the step,
     F = -m (v_t / dt + a_t) = -(2e-9 kg)(1e-3 / 1e-6, 0.5) = (-2e-6, -1e-9) N; the normal parts of
     v and a are ignored;
   - applied over the step it leaves no tangential velocity: v_t + dt (a_t + F/m) = 0;
   - slip (limit mu fn = 1e-7 N < |F|): the factor scales F to the limit, along F;
   - limit 0: factor 0 (no friction). */
#include <cmath>

#include "check.h"
#include "physics/friction.h"

using fiberform::check::expect;
using fiberform::physics::coulomb_stick_slip;

int main() {
  const double m = 2e-9, dt = 1e-6;
  const double v[3] = {1e-3, 0.0, -4e-3};   // normal part -4 mm/s: ignored
  const double a[3] = {0.0, 0.5, -9.81};    // 1 nN / 2 ug along y; gravity along the normal: ignored
  const double n[3] = {0.0, 0.0, 1.0};
  double ft[3];
  const double c = coulomb_stick_slip(v, a, n, 1.0 / m, dt, 1.0, ft);
  expect(c == 1.0, "stick: factor 1", c, 1.0);
  expect(std::fabs(ft[0] + 2e-6) < 1e-18, "stick force x = -m v_x / dt", ft[0], -2e-6);
  expect(std::fabs(ft[1] + 1e-9) < 1e-21, "stick force y = -m a_y", ft[1], -1e-9);
  expect(ft[2] == 0.0, "no normal part", ft[2], 0.0);
  for (int k = 0; k < 2; ++k) {
    const double vt = v[k] + dt * (a[k] + ft[k] / m);
    expect(std::fabs(vt) < 1e-15, "stick: the tangential velocity after the step is 0", vt, 0.0);
  }
  const double lim = 1e-7;
  const double cs = coulomb_stick_slip(v, a, n, 1.0 / m, dt, lim, ft);
  const double mag = cs * std::sqrt(ft[0] * ft[0] + ft[1] * ft[1]);
  expect(std::fabs(mag - lim) < 1e-12 * lim, "slip: |F| = mu fn", mag, lim);
  const double want = lim / std::sqrt(2e-6 * 2e-6 + 1e-9 * 1e-9);
  expect(std::fabs(cs - want) < 1e-12 * want, "slip: factor mu fn / |F_stick|", cs, want);
  const double c0 = coulomb_stick_slip(v, a, n, 1.0 / m, dt, 0.0, ft);
  expect(c0 == 0.0, "limit 0: no friction", c0, 0.0);
  return fiberform::check::finish("test_friction");
}
