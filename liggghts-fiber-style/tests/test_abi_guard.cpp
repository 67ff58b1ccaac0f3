/* SPDX-License-Identifier: GPL-3.0-or-later
   The ABI guard agrees with a real LIGGGHTS instance, and reports a mismatch when a probe's
   header-side address is wrong (so the guard can fail). */
#include <mpi.h>

#include <cstdio>
#include <iterator>
#include <string>

#include "abi_guard.h"
#include "domain.h"
#include "lammps.h"
#include "update.h"

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  char a0[] = "test", a1[] = "-screen", a2[] = "none", a3[] = "-log", a4[] = "none";
  char *args[] = {a0, a1, a2, a3, a4};
  auto *lmp = new LAMMPS_NS::LAMMPS(5, args, MPI_COMM_WORLD);
  int failures = 0;

  const std::string ok = fiberform::check_library_layout(lmp);
  if (!ok.empty()) {
    std::fprintf(stderr, "FAIL: guard reports a mismatch on a consistent build: %s\n", ok.c_str());
    ++failures;
  }
  // A deliberately wrong probe: the header side points at boxhi where the library reports boxlo.
  const fiberform::LayoutProbe wrong[] = {{"boxxlo", &lmp->domain->boxhi[0]}};
  const std::string bad = fiberform::compare_global_probes(lmp, std::begin(wrong), std::end(wrong));
  if (bad.empty() || bad.find("boxxlo") == std::string::npos) {
    std::fprintf(stderr, "FAIL: guard did not report a wrong probe\n");
    ++failures;
  }
  delete lmp;
  MPI_Finalize();
  std::printf("test_abi_guard: %s\n", failures ? "FAILED" : "ok");
  return failures ? 1 : 0;
}
