/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "abi_guard.h"

#include <cstdio>
#include <iterator>

#include "atom.h"
#include "domain.h"
#include "error.h"
#include "lammps.h"
#include "library.h"
#include "update.h"

namespace fiberform {

namespace {
std::string mismatch(const char *what, const void *header, const void *library) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "%s: header-derived address %p, library reports %p", what, header,
                library);
  return buf;
}
}  // namespace

std::string compare_global_probes(LAMMPS_NS::LAMMPS *lmp, const LayoutProbe *begin,
                                  const LayoutProbe *end) {
  for (const LayoutProbe *p = begin; p != end; ++p) {
    const void *lib = lammps_extract_global(lmp, const_cast<char *>(p->name));
    if (lib != p->header) return mismatch(p->name, p->header, lib);
  }
  return {};
}

std::string check_library_layout(LAMMPS_NS::LAMMPS *lmp) {
  const LayoutProbe probes[] = {
      {"dt", &lmp->update->dt},
      {"boxxlo", &lmp->domain->boxlo[0]},
      {"boxzhi", &lmp->domain->boxhi[2]},
      {"natoms", &lmp->atom->natoms},
      {"nlocal", &lmp->atom->nlocal},
  };
  return compare_global_probes(lmp, std::begin(probes), std::end(probes));
}

void check_atom_layout(LAMMPS_NS::LAMMPS *lmp) {
  LAMMPS_NS::Atom *atom = lmp->atom;
  struct Probe {
    const char *name;
    const void *header;
  };
  const Probe probes[] = {
      {"x", atom->x},         {"v", atom->v},          {"f", atom->f},
      {"id", atom->tag},     {"type", atom->type},    {"mask", atom->mask},
      {"radius", atom->radius}, {"rmass", atom->rmass}, {"omega", atom->omega},
      {"torque", atom->torque},
  };
  for (const Probe &p : probes) {
    const void *lib = atom->extract(p.name);
    if (lib != p.header) {
      // LIGGGHTS' Error::all prints the message again after exit() has run static destructors:
      // keep it in a plain static buffer, never in a std::string.
      static char msg[512];
      std::snprintf(msg, sizeof msg,
                    "fiberform ABI guard: LIGGGHTS headers and library disagree on Atom::%s "
                    "(header-derived %p, library %p). Rebuild against the installed "
                    "libliggghts-dev; never define SUPERQUADRIC_ACTIVE_FLAG or "
                    "NONSPHERICAL_ACTIVE_FLAG.",
                    p.name, p.header, lib);
      lmp->error->all(FLERR, msg);
    }
  }
}

}  // namespace fiberform
