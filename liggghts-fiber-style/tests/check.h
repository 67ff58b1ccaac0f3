/* SPDX-License-Identifier: GPL-3.0-or-later
   The check helper shared by the ctest unit tests: expect() prints a failure with the value
   obtained and the value wanted, and counts it; a test's main() returns finish(). */
#ifndef FIBERFORM_TESTS_CHECK_H
#define FIBERFORM_TESTS_CHECK_H

#include <cmath>
#include <cstdio>

namespace fiberform::check {

inline int &failures() {
  static int n = 0;
  return n;
}

inline void expect(bool ok, const char *what, double got = NAN, double want = NAN) {
  if (!ok) {
    std::fprintf(stderr, "FAIL: %s (got %.12g, want %.12g)\n", what, got, want);
    ++failures();
  }
}

// exit status of a test program: 0 when every check passed
inline int finish(const char *name) {
  if (failures()) {
    std::fprintf(stderr, "%s: %d failure(s)\n", name, failures());
    return 1;
  }
  std::printf("%s: all checks passed\n", name);
  return 0;
}

}  // namespace fiberform::check

#endif
