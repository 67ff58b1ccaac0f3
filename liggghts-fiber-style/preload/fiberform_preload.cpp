/* SPDX-License-Identifier: GPL-3.0-or-later
   libfiberform_preload.so: lets the STOCK `liggghts` binary use the fiberform styles.

     LD_PRELOAD=build/lib/libfiberform_preload.so liggghts -in in.script

   The stock main() constructs LAMMPS and then calls Input::file() through the dynamic linker.
   This library defines that same symbol, so the preloaded definition is the one bound: it registers
   the project's styles on the instance (once), runs the ABI guard, and forwards to the real
   Input::file() found with dlsym(RTLD_NEXT). Nothing else of LIGGGHTS is touched. */
#include <dlfcn.h>
#include <mpi.h>

#include <cstdio>
#include <string>

#include "abi_guard.h"
#include "input.h"
#include "lammps.h"
#include "style_registry.h"

namespace {
using InputFileFn = void (*)(LAMMPS_NS::Input *);
LAMMPS_NS::LAMMPS *g_registered = nullptr;
}  // namespace

namespace LAMMPS_NS {

// Same signature as the library's Input::file(); `lmp` is the protected Pointers member.
void Input::file() {
  static InputFileFn real = reinterpret_cast<InputFileFn>(dlsym(RTLD_NEXT, "_ZN9LAMMPS_NS5Input4fileEv"));
  if (!real) {
    std::fprintf(stderr, "fiberform_preload: cannot find LIGGGHTS' Input::file(): %s\n", dlerror());
    MPI_Abort(MPI_COMM_WORLD, 3);
  }
  if (g_registered != lmp) {
    const std::string abi = fiberform::check_library_layout(lmp);
    if (!abi.empty()) {
      std::fprintf(stderr, "fiberform_preload: ABI guard: %s\n", abi.c_str());
      MPI_Abort(MPI_COMM_WORLD, 3);
    }
    if (!fiberform::register_styles(lmp)) MPI_Abort(MPI_COMM_WORLD, 3);
    g_registered = lmp;
  }
  real(this);
}

}  // namespace LAMMPS_NS
