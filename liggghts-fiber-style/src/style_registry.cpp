/* SPDX-License-Identifier: GPL-3.0-or-later
   fiberform: THE registrar. Every style of the project is listed here, once, with one line of
   description; `fiberdem -h` prints this list. To add a style: include its header and add a row. */
#include "style_registry.h"

#include <cstring>

#include "force.h"
#include "lammps.h"
#include "modify.h"
#include "modify_access.h"

// ---- style headers (one class per style, one file pair per class) ----
#include "pair_test_harmonic.h"
#include "pair_fiber_dlvo.h"
#include "fix_fiber_dlvo_step.h"
#include "fix_wall_fiber_dlvo.h"
#include "fix_fiber_beam.h"
#include "fix_fiber_drag.h"
#include "fix_fiber_coupling.h"
#include "fix_wall_fiber_yarns.h"
#include "fix_fiber_remove.h"
#include "fix_fiber_settle.h"

namespace fiberform {
namespace {

template <class T>
LAMMPS_NS::Pair *make_pair(LAMMPS_NS::LAMMPS *lmp) { return new T(lmp); }
template <class T>
LAMMPS_NS::Fix *make_fix(LAMMPS_NS::LAMMPS *lmp, int narg, char **arg) { return new T(lmp, narg, arg); }
template <class T>
LAMMPS_NS::Compute *make_compute(LAMMPS_NS::LAMMPS *lmp, int iarg, int narg, char **arg) {
  return new T(lmp, iarg, narg, arg);
}

const StyleEntry kStyles[] = {
    {StyleKind::Pair, "test/harmonic",
     "harmonic repulsion F = K*overlap between spheres (test and demo style)",
     &make_pair<LAMMPS_NS::PairTestHarmonic>, nullptr, nullptr},
    {StyleKind::Pair, "fiber/dlvo",
     "fiber-fiber extended DLVO + steric contact, sub-integrated per contact (CVODE)",
     &make_pair<LAMMPS_NS::PairFiberDlvo>, nullptr, nullptr},
    {StyleKind::Fix, "wall/fiber/dlvo",
     "the fiber/dlvo law against a plane wall or moving plate (infinite mass)",
     nullptr, &make_fix<LAMMPS_NS::FixWallFiberDlvo>, nullptr},
    {StyleKind::Fix, "fiber/dlvo/step",
     "internal: sub-integration step of pair fiber/dlvo (created automatically)",
     nullptr, &make_fix<LAMMPS_NS::FixFiberDlvoStep>, nullptr},
    {StyleKind::Fix, "fiber/beam",
     "flexible fibers: geometrically exact beam chains (thesis eq. 2.13); integrates each fiber implicitly "
     "(generalized-alpha, Newton) or explicitly",
     nullptr, &make_fix<LAMMPS_NS::FixFiberBeam>, nullptr},
    {StyleKind::Fix, "fiber/drag",
     "fluid drag (thesis eq. 2.14-2.16), gravity and buoyancy on fiber/beam elements; uniform or grid flow",
     nullptr, &make_fix<LAMMPS_NS::FixFiberDrag>, nullptr},
    {StyleKind::Fix, "fiber/coupling",
     "two-way coupling with fiberPimpleFoam -coupled (MPMD): coupled flow for fiber/drag, drag reaction "
     "sent to the fluid cells every N steps",
     nullptr, &make_fix<LAMMPS_NS::FixFiberCoupling>, nullptr},
    {StyleKind::Fix, "wall/fiber/yarns",
     "the fiber/dlvo law against static yarn chains (infinite mass) for fiber/beam elements: inside each "
     "implicit fiber solve, or sub-integrated (CVODE or sub-steps); Coulomb friction",
     nullptr, &make_fix<LAMMPS_NS::FixWallFiberYarns>, nullptr},
    {StyleKind::Fix, "fiber/remove",
     "removes whole fiber/beam fibers with a node below a height every N steps; removed count and mass",
     nullptr, &make_fix<LAMMPS_NS::FixFiberRemove>, nullptr},
    {StyleKind::Fix, "fiber/settle",
     "settle check: counts consecutive checks with the node or fiber (mass-fraction) speed below V",
     nullptr, &make_fix<LAMMPS_NS::FixFiberSettle>, nullptr},
};

const char *kind_name(StyleKind k) {
  switch (k) {
    case StyleKind::Pair: return "pair_style";
    case StyleKind::Fix: return "fix";
    case StyleKind::Compute: return "compute";
  }
  return "?";
}

}  // namespace

const StyleEntry *style_begin() { return kStyles; }
const StyleEntry *style_end() { return kStyles + sizeof(kStyles) / sizeof(kStyles[0]); }

bool register_styles(LAMMPS_NS::LAMMPS *lmp) {
  auto &pairs = *lmp->force->pair_map;
  auto &fixes = fix_map(lmp->modify);
  auto &computes = compute_map(lmp->modify);
  bool ok = true;
  for (const StyleEntry *s = style_begin(); s != style_end(); ++s) {
    bool clash = false;
    switch (s->kind) {
      case StyleKind::Pair:
        clash = pairs.count(s->name) != 0;
        if (!clash) pairs[s->name] = s->make_pair;
        break;
      case StyleKind::Fix:
        clash = fixes.count(s->name) != 0;
        if (!clash) fixes[s->name] = s->make_fix;
        break;
      case StyleKind::Compute:
        clash = computes.count(s->name) != 0;
        if (!clash) computes[s->name] = s->make_compute;
        break;
    }
    if (clash) {
      std::fprintf(stderr, "fiberdem: %s %s already exists in LIGGGHTS; refusing to shadow it\n",
                   kind_name(s->kind), s->name);
      ok = false;
    }
  }
  return ok;
}

void print_style_list(std::FILE *out) {
  for (const StyleEntry *s = style_begin(); s != style_end(); ++s)
    std::fprintf(out, "  %-11s %-24s %s\n", kind_name(s->kind), s->name, s->description);
}

}  // namespace fiberform
