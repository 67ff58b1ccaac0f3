// SPDX-License-Identifier: GPL-3.0-or-later
// Unit test of fiberform::SlidingWindow (the permeability solve's stop criterion).
#include <cmath>
#include <cstdio>

#include "window_convergence.h"

static int failures = 0;
#define CHECK(c)                                                  \
  do {                                                            \
    if (!(c)) {                                                   \
      std::printf("FAIL %s:%d: %s\n", __FILE__, __LINE__, #c);    \
      ++failures;                                                 \
    }                                                             \
  } while (0)

int main() {
  using fiberform::SlidingWindow;
  // not full: never converged
  SlidingWindow w(4);
  w.push(1.0);
  w.push(1.0);
  w.push(1.0);
  CHECK(!w.full());
  CHECK(!w.converged(1.0));
  w.push(1.0);
  CHECK(w.full());
  CHECK(w.relative_range() == 0.0);
  CHECK(w.converged(0.0));
  // window 10, 11, 9, 10: range 2, mean 10 -> 0.2
  SlidingWindow v(4);
  for (double x : {100.0, 10.0, 11.0, 9.0, 10.0}) v.push(x);  // the 100 has left the window
  CHECK(std::fabs(v.relative_range() - 0.2) < 1e-15);
  CHECK(v.converged(0.2));
  CHECK(!v.converged(0.19));
  // a negative flow rate (outflow counted negative): |mean|
  SlidingWindow n(2);
  n.push(-10.0);
  n.push(-11.0);
  CHECK(std::fabs(n.relative_range() - 1.0 / 10.5) < 1e-15);
  // zero mean: not converged, whatever the tolerance
  SlidingWindow z(2);
  z.push(-1.0);
  z.push(1.0);
  CHECK(!z.converged(1e300));
  // window 0: never full
  SlidingWindow e(0);
  e.push(1.0);
  CHECK(!e.full());
  if (failures == 0) std::printf("test_window_convergence: all passed\n");
  return failures == 0 ? 0 : 1;
}
