/* SPDX-License-Identifier: GPL-3.0-or-later
   Waiting for MPI requests without keeping a core busy (plain MPI, C++17).

   Open MPI's blocking calls poll the network or shared memory in a busy loop. A rank that waits
   long (for the partner program in a coupled run, or in fiberdem for the rank that solves a
   contact cluster alone) then keeps a core busy; on machines whose virtual CPUs share physical
   cores that slows the rank doing the work (measured: docs/bench/machine.md). patient_wait polls
   MPI_Testall continuously for a short time (short waits stay fast), then sleeps between polls,
   the naps growing geometrically from nap_min_s to nap_max_s: a wait that ends during a nap is
   noticed at most one nap late. Used by the coupling layer's Channel and by fix fiber/beam. */
#ifndef FIBERFORM_COUPLING_PATIENT_WAIT_H
#define FIBERFORM_COUPLING_PATIENT_WAIT_H

#include <mpi.h>

namespace fiberform::coupling {

struct Patience {
  double spin_s = 0.0;        // poll without sleeping for this long first (s)
  double nap_min_s = 200e-6;  // first sleep between polls (s)
  double nap_max_s = 200e-6;  // longest sleep between polls (s); the naps double up to it
  double deadline_s = 0.0;    // give up at this steady-clock time (s; clock_s()); <= 0: never
};

/// Seconds on a monotonic clock (the clock of Patience::deadline_s).
double clock_s();

/// Wait until the n requests have completed (MPI_Testall, statuses ignored). Returns true then,
/// false if the deadline passed first (the requests are still pending).
bool patient_wait(MPI_Request *req, int n, const Patience &how);

}  // namespace fiberform::coupling

#endif
