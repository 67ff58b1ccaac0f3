/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit test of coupling/layer/patient_wait.h on one rank (MPI_COMM_SELF): a receive that no message
   answers is waited for until the deadline and no longer complete (false), and the process sleeps
   meanwhile (its CPU time stays far below the wall time: a polling loop would use all of it); once
   the message is sent the same request completes (true) with the data; a request that has already
   completed returns at once, also with a deadline in the past. */
#include <mpi.h>

#include <ctime>

#include "check.h"
#include "patient_wait.h"

namespace cpl = fiberform::coupling;
using fiberform::check::expect;

namespace {

double cpu_s() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

}  // namespace

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  double got = 0.0;
  MPI_Request req;
  MPI_Irecv(&got, 1, MPI_DOUBLE, 0, 11, MPI_COMM_SELF, &req);

  // nobody sends: naps of 1-4 ms until the deadline 80 ms on
  cpl::Patience how;
  how.spin_s = 0.0;
  how.nap_min_s = 1e-3;
  how.nap_max_s = 4e-3;
  const double t0 = cpl::clock_s(), c0 = cpu_s();
  how.deadline_s = t0 + 0.08;
  const bool done = cpl::patient_wait(&req, 1, how);
  const double wall = cpl::clock_s() - t0, cpu = cpu_s() - c0;
  expect(!done, "no message: the wait ends at the deadline, the request pending");
  expect(wall >= 0.08, "no message: waited until the deadline (s)", wall, 0.08);
  expect(cpu < 0.25 * wall, "the wait sleeps: its CPU time is a small part of the wall time (s)", cpu, 0.25 * wall);

  // the message arrives (a send to self completes eagerly): the same request completes
  const double value = 42.5;
  MPI_Send(&value, 1, MPI_DOUBLE, 0, 11, MPI_COMM_SELF);
  how.deadline_s = cpl::clock_s() + 5.0;
  expect(cpl::patient_wait(&req, 1, how), "after the send the request completes");
  expect(got == value, "the message's value arrived", got, value);

  // a completed (null) request: true at once, even with a deadline already passed
  how.deadline_s = cpl::clock_s() - 1.0;
  expect(cpl::patient_wait(&req, 1, how), "a completed request returns true at once");

  // spinning first: a spin phase longer than the deadline ends at the deadline too
  MPI_Irecv(&got, 1, MPI_DOUBLE, 0, 12, MPI_COMM_SELF, &req);
  how.spin_s = 1.0;
  const double t1 = cpl::clock_s();
  how.deadline_s = t1 + 0.02;
  expect(!cpl::patient_wait(&req, 1, how), "spinning: the wait ends at the deadline");
  expect(cpl::clock_s() - t1 < 0.9, "spinning: the deadline ends the spin phase (s)", cpl::clock_s() - t1, 0.9);
  MPI_Cancel(&req);
  MPI_Wait(&req, MPI_STATUS_IGNORE);

  MPI_Finalize();
  return fiberform::check::finish("test_patient_wait");
}
