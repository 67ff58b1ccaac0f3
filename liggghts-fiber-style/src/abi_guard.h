/* SPDX-License-Identifier: GPL-3.0-or-later
   fiberform: start-up check that the LIGGGHTS headers we compiled against describe the same
   object layout as the shared library we run with. */
#ifndef FIBERFORM_ABI_GUARD_H
#define FIBERFORM_ABI_GUARD_H

#include <string>

namespace LAMMPS_NS {
class LAMMPS;
}

namespace fiberform {

// Compares addresses of fields computed from our headers with the addresses the library's own
// accessors (lammps_extract_global, Atom::extract) return. Returns an empty string when all
// agree, otherwise a description of the first mismatch.
std::string check_library_layout(LAMMPS_NS::LAMMPS *lmp);

// One probe: a global the library can report by name, and the address our headers compute for it.
struct LayoutProbe {
  const char *name;    // a name lammps_extract_global() knows, e.g. "dt"
  const void *header;  // the address computed from the headers, e.g. &lmp->update->dt
};
// The comparison behind check_library_layout(), exposed for unit tests.
std::string compare_global_probes(LAMMPS_NS::LAMMPS *lmp, const LayoutProbe *begin, const LayoutProbe *end);

// The per-atom part of the check, for styles to call from init(): once atoms exist, the arrays a
// style reads through the header (atom->x, v, f, radius, rmass, omega, ...) must be the ones the
// library reports. Calls error->all() with a clear message on mismatch.
void check_atom_layout(LAMMPS_NS::LAMMPS *lmp);

}  // namespace fiberform

#endif
