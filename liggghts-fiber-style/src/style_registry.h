/* SPDX-License-Identifier: GPL-3.0-or-later
   fiberform: the list of the project's LIGGGHTS styles and their run-time registration. */
#ifndef FIBERFORM_STYLE_REGISTRY_H
#define FIBERFORM_STYLE_REGISTRY_H

#include <cstdio>

namespace LAMMPS_NS {
class LAMMPS;
class Pair;
class Fix;
class Compute;
}  // namespace LAMMPS_NS

namespace fiberform {

enum class StyleKind { Pair, Fix, Compute };

struct StyleEntry {
  StyleKind kind;
  const char *name;         // the name used in input scripts, e.g. "fiber/dlvo"
  const char *description;  // one line for `fiberdem -h`
  LAMMPS_NS::Pair *(*make_pair)(LAMMPS_NS::LAMMPS *);
  LAMMPS_NS::Fix *(*make_fix)(LAMMPS_NS::LAMMPS *, int, char **);
  LAMMPS_NS::Compute *(*make_compute)(LAMMPS_NS::LAMMPS *, int, int, char **);
};

// All styles of the project, in the order `fiberdem -h` lists them.
const StyleEntry *style_begin();
const StyleEntry *style_end();

// Inserts every style into the LIGGGHTS instance's style maps. A name that LIGGGHTS already
// knows is an error (returns false and names it on stderr): we never shadow a stock style.
bool register_styles(LAMMPS_NS::LAMMPS *lmp);

// Prints "kind  name  description" lines.
void print_style_list(std::FILE *out);

}  // namespace fiberform

#endif
