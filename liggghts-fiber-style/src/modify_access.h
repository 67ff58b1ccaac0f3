/* SPDX-License-Identifier: GPL-3.0-or-later
   fiberform: access to LIGGGHTS' private style maps without patching LIGGGHTS.

   Modify::fix_map and Modify::compute_map are private. The C++ rule that access checks do not
   apply to the template arguments of an explicit instantiation ([temp.explicit]/12 in C++17)
   lets a header name a pointer-to-member of a private field; a friend function defined inside the
   instantiated template hands that pointer out. Force::pair_map is public and needs no trick. */
#ifndef FIBERFORM_MODIFY_ACCESS_H
#define FIBERFORM_MODIFY_ACCESS_H

#include <map>
#include <string>

#include "lammps.h"
#include "modify.h"

namespace fiberform {
namespace detail {

using FixCreatorFn = LAMMPS_NS::Fix *(*)(LAMMPS_NS::LAMMPS *, int, char **);
using ComputeCreatorFn = LAMMPS_NS::Compute *(*)(LAMMPS_NS::LAMMPS *, int, int, char **);
using FixMap = std::map<std::string, FixCreatorFn>;
using ComputeMap = std::map<std::string, ComputeCreatorFn>;

// A tag type per member; `get(Tag)` is declared here and defined by the instantiation below.
struct FixMapTag {
  using type = FixMap *LAMMPS_NS::Modify::*;
  friend type get(FixMapTag);
};
struct ComputeMapTag {
  using type = ComputeMap *LAMMPS_NS::Modify::*;
  friend type get(ComputeMapTag);
};

template <typename Tag, typename Tag::type Member>
struct MemberThief {
  friend typename Tag::type get(Tag) { return Member; }
};

template struct MemberThief<FixMapTag, &LAMMPS_NS::Modify::fix_map>;
template struct MemberThief<ComputeMapTag, &LAMMPS_NS::Modify::compute_map>;

}  // namespace detail

inline detail::FixMap &fix_map(LAMMPS_NS::Modify *modify) {
  return *(modify->*get(detail::FixMapTag{}));
}
inline detail::ComputeMap &compute_map(LAMMPS_NS::Modify *modify) {
  return *(modify->*get(detail::ComputeMapTag{}));
}

}  // namespace fiberform

#endif
