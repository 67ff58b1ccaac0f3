/* SPDX-License-Identifier: GPL-3.0-or-later
   Waiting for MPI requests without keeping a core busy: see patient_wait.h. */
#include "patient_wait.h"

#include <algorithm>
#include <chrono>
#include <thread>

namespace fiberform::coupling {

double clock_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

bool patient_wait(MPI_Request *req, int n, const Patience &how) {
  const double start = clock_s();
  double nap = std::max(how.nap_min_s, 1e-6);
  for (;;) {
    int done = 0;
    MPI_Testall(n, req, &done, MPI_STATUSES_IGNORE);
    if (done) return true;
    const double now = clock_s();
    if (how.deadline_s > 0.0 && now > how.deadline_s) return false;
    if (now - start < how.spin_s) continue;
    std::this_thread::sleep_for(std::chrono::duration<double>(nap));
    nap = std::min(2.0 * nap, std::max(how.nap_max_s, how.nap_min_s));
  }
}

}  // namespace fiberform::coupling
