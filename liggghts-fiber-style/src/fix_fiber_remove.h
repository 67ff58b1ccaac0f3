/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/remove: removes whole fix fiber/beam fibers (all their nodes, on every rank) once any
   node of the fiber is below a height, checked every N steps, with mass accounting (fibers, mass,
   nodes removed; kept in restart files). Documentation: docs/styles/fix_fiber_remove.md.

     fix ID group fiber/remove below z [every N]

   Each removal prints `fix fiber/remove: step S removed fiber(s) ID ...` (IDs of fix fiber/beam,
   0-based) to the screen and log. */
#ifndef LMP_FIX_FIBER_REMOVE_H
#define LMP_FIX_FIBER_REMOVE_H

#include "fix.h"

namespace LAMMPS_NS {

class FixFiberRemove : public Fix {
 public:
  FixFiberRemove(class LAMMPS *lmp, int narg, char **arg);
  int setmask() override;
  void init() override;
  void pre_exchange() override;
  double compute_vector(int n) override;
  void write_restart(FILE *fp) override;
  void restart(char *buf) override;

 private:
  double z_ = 0.0;       // removal height (m)
  int every_ = 100;      // steps between checks
  class FixFiberBeam *beam_ = nullptr;
  double removed_fibers_ = 0, removed_mass_ = 0, removed_nodes_ = 0;  // totals, all ranks (1, kg, 1)
};

}  // namespace LAMMPS_NS

#endif
