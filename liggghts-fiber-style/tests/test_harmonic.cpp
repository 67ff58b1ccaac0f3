/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit test of the harmonic contact law against its closed form. */
#include <cmath>
#include <cstdio>

#include "physics/harmonic.h"

int main() {
  using fiberform::physics::harmonic_contact;
  int failures = 0;
  auto expect = [&](bool ok, const char *what) {
    if (!ok) {
      std::fprintf(stderr, "FAIL: %s\n", what);
      ++failures;
    }
  };
  const double K = 250.0, rs = 2e-5;
  expect(harmonic_contact(K, rs, 3e-5).force == 0.0, "no force when apart");
  expect(harmonic_contact(K, rs, rs).force == 0.0, "no force at touching");
  const auto c = harmonic_contact(K, rs, 1.5e-5);
  expect(std::fabs(c.force - K * 0.5e-5) < 1e-15, "force = K*overlap");
  expect(std::fabs(c.energy - 0.5 * K * 0.25e-10) < 1e-20, "energy = K*overlap^2/2");
  // energy is the integral of force: -dE/dr = F (central difference)
  const double h = 1e-9, r = 1.2e-5;
  const double dEdr = (harmonic_contact(K, rs, r + h).energy - harmonic_contact(K, rs, r - h).energy) / (2 * h);
  expect(std::fabs(-dEdr - harmonic_contact(K, rs, r).force) < 1e-9, "F = -dE/dr");
  std::printf("test_harmonic: %s\n", failures ? "FAILED" : "ok");
  return failures ? 1 : 0;
}
