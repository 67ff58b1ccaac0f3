/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of physics/settle.h (the lay-down's settle measure) against hand-computed values: the
   largest speed at fraction 1; a light fast fine ignored at 0.99 but not at 1; a sheet sinking as a
   whole stays at its sinking speed at any fraction; ties and the exact-fraction edge. */
#include <vector>

#include "check.h"
#include "physics/settle.h"

using fiberform::check::expect;
using fiberform::physics::mass_fraction_speed;

int main() {
  // 99 fibers of 1 ug at rest-ish (1e-4 m/s), one fine of 0.2 ug fluttering at 5e-2 m/s
  std::vector<double> v(99, 1e-4), m(99, 1e-9);
  v.push_back(5e-2);
  m.push_back(0.2e-9);
  expect(mass_fraction_speed(v, m, 1.0) == 5e-2, "fraction 1: the largest speed", mass_fraction_speed(v, m, 1.0), 5e-2);
  // the fine carries 0.2 / 99.2 = 0.2 % of the mass: ignored at 0.99
  expect(mass_fraction_speed(v, m, 0.99) == 1e-4, "fraction 0.99 ignores the fine", mass_fraction_speed(v, m, 0.99), 1e-4);
  // but not at 0.999 (the slow ones carry 99.8 %)
  expect(mass_fraction_speed(v, m, 0.999) == 5e-2, "fraction 0.999 keeps it", mass_fraction_speed(v, m, 0.999), 5e-2);
  // a sheet sinking as a whole at 3e-3 m/s: that speed at any fraction
  std::vector<double> s(50, 3e-3), ms(50, 2e-9);
  for (double q : {0.5, 0.9, 0.99, 1.0})
    expect(mass_fraction_speed(s, ms, q) == 3e-3, "uniform sinking", mass_fraction_speed(s, ms, q), 3e-3);
  // exact edge: masses 1, 1, 2 at speeds 3, 1, 2; sorted 1 (1), 2 (2), 3 (1): cumulative 1/4, 3/4, 1
  std::vector<double> v3{3.0, 1.0, 2.0}, m3{1.0, 1.0, 2.0};
  expect(mass_fraction_speed(v3, m3, 0.25) == 1.0, "q = 0.25", mass_fraction_speed(v3, m3, 0.25), 1.0);
  expect(mass_fraction_speed(v3, m3, 0.5) == 2.0, "q = 0.5", mass_fraction_speed(v3, m3, 0.5), 2.0);
  expect(mass_fraction_speed(v3, m3, 0.75) == 2.0, "q = 0.75", mass_fraction_speed(v3, m3, 0.75), 2.0);
  expect(mass_fraction_speed(v3, m3, 0.76) == 3.0, "q = 0.76", mass_fraction_speed(v3, m3, 0.76), 3.0);
  expect(mass_fraction_speed({}, {}, 0.9) == 0.0, "empty", 0, 0);
  return fiberform::check::finish("test_settle");
}
