/* SPDX-License-Identifier: GPL-3.0-or-later
   fiberdem: the fiberform DEM driver. It is LIGGGHTS (Debian's libliggghts) with the project's
   styles registered at start-up. It accepts the same command-line flags as `liggghts`
   (-in, -var, -log, -echo, -screen, ...) and runs under mpirun.

   fiberdem -h         lists the project's styles (one line each) and the flags
   fiberdem --version  prints the fiberform and LIGGGHTS versions */
#include <mpi.h>

#include <cstdio>
#include <cstring>
#include <string>

#include "abi_guard.h"
#include "coupling_layer.h"
#include "input.h"
#include "lammps.h"
#include "style_registry.h"
#include "universe.h"

namespace {

// Set once the driver ends normally; until then a call of MPI_Finalize in a coupled run is an error
// exit of LIGGGHTS (see MPI_Finalize below).
bool g_normal_end = false;

void print_help() {
  std::printf(
      "fiberdem %s: LIGGGHTS with the fiberform styles registered\n\n"
      "Usage: fiberdem [liggghts flags] -in INPUT\n"
      "  -in FILE, -var NAME VALUE, -log FILE|none, -echo none|screen|log|both, -screen FILE|none\n"
      "  (all flags of `liggghts -h` are accepted and passed on)\n"
      "  -h, --help       this list\n"
      "  --version        fiberform and LIGGGHTS versions\n\n"
      "fiberform styles:\n",
      FIBERFORM_VERSION);
  fiberform::print_style_list(stdout);
  std::printf("\nUnits: the styles are written for `units si` (m, kg, s, N).\n");
}

bool has_flag(int argc, char **argv, const char *a, const char *b = nullptr) {
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], a) == 0 || (b && std::strcmp(argv[i], b) == 0)) return true;
  return false;
}

}  // namespace

// LIGGGHTS ends an input or run error on all ranks (Error::all) with MPI_Finalize() and exit(1). In a
// coupled MPMD run the partner program is still running, and MPI_Finalize then waits for it (Open
// MPI's finalize synchronises the whole job) until the partner's own timeout aborts the job: an error
// of the fibers' side took the coupling timeout to end both programs, and under load mpirun was seen
// to hang in that state. This definition takes precedence over Open MPI's for libliggghts (the
// executable's symbols come first; the MPI profiling interface PMPI_* reaches the library): in a
// coupled run that has not ended normally it aborts the whole job at once, status kAbortStatus.
extern "C" int MPI_Finalize() {
  const auto &s = fiberform::coupling::session();
  if (s.started && s.partner_size > 0 && !g_normal_end) {
    std::fprintf(stderr, "fiberdem: coupling error: the fibers' side of the coupled run ended with an "
                 "error (message above): aborting both programs (status %d)\n",
                 fiberform::coupling::kAbortStatus);
    std::fflush(stderr);
    return PMPI_Abort(MPI_COMM_WORLD, fiberform::coupling::kAbortStatus);
  }
  return PMPI_Finalize();
}

int main(int argc, char **argv) {
  // Line-buffered screen output: LIGGGHTS prints its errors to the screen and aborts without a
  // flush, so through a pipe or into a file (the stages' logs) a block-buffered stdout lost them.
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  MPI_Init(&argc, &argv);
  // First collective on MPI_COMM_WORLD: split by MPI_APPNUM (a coupled MPMD run with
  // fiberPimpleFoam -coupled, docs/coupling/launch.md); alone, `local` holds every rank of the world.
  const MPI_Comm local = fiberform::coupling::start_world().local;
  int rank = 0;
  MPI_Comm_rank(local, &rank);

  if (has_flag(argc, argv, "-h", "--help") || has_flag(argc, argv, "-help")) {
    if (rank == 0) print_help();
    g_normal_end = true;
    MPI_Finalize();
    return 0;
  }

  const bool version_only = has_flag(argc, argv, "--version");
  std::string quiet[] = {"fiberdem", "-screen", "none", "-log", "none"};
  char *quiet_argv[5];
  for (int i = 0; i < 5; ++i) quiet_argv[i] = quiet[i].data();

  auto *lmp = version_only ? new LAMMPS_NS::LAMMPS(5, quiet_argv, local)
                           : new LAMMPS_NS::LAMMPS(argc, argv, local);

  const std::string abi = fiberform::check_library_layout(lmp);
  if (!abi.empty()) {
    if (rank == 0)
      std::fprintf(stderr,
                   "fiberdem: ABI guard: the LIGGGHTS headers this driver was compiled with do not "
                   "match the installed libliggghts (%s). Reinstall libliggghts-dev for the same "
                   "version as liggghts and rebuild (make setup).\n",
                   abi.c_str());
    MPI_Abort(MPI_COMM_WORLD, 3);
  }

  if (version_only) {
    if (rank == 0)
      std::printf("fiberdem %s\nLIGGGHTS %s\n", FIBERFORM_VERSION, lmp->universe->version);
    delete lmp;
    g_normal_end = true;
    MPI_Finalize();
    return 0;
  }

  if (!fiberform::register_styles(lmp)) MPI_Abort(MPI_COMM_WORLD, 3);

  lmp->input->file();
  delete lmp;
  g_normal_end = true;
  MPI_Finalize();
  return 0;
}
