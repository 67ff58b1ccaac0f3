/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/settle: the settle check of the lay-down. Every M steps it measures the fibers' speed
   (the largest node speed, or the speed below which a given fraction of the fiber mass moves, by
   fiber centre-of-mass speeds: physics/settle.h) and counts the consecutive checks below V; an
   input script ends the run when the count reaches its criterion (`if` on f_ID[1]). The count
   survives a restart. Documentation: docs/styles/fix_fiber_settle.md.

     fix ID group fiber/settle V M [measure node|fiber] [mass_fraction q] */
#ifndef LMP_FIX_FIBER_SETTLE_H
#define LMP_FIX_FIBER_SETTLE_H

#include "fix.h"

namespace LAMMPS_NS {

class FixFiberSettle : public Fix {
 public:
  FixFiberSettle(class LAMMPS *lmp, int narg, char **arg);
  int setmask() override;
  void init() override;
  void end_of_step() override;
  double compute_vector(int n) override;
  void write_restart(FILE *fp) override;
  void restart(char *buf) override;

 private:
  double measure_fibers() const;  // collective: the mass-fraction speed of the fibers' COM speeds
  double speed_ = 0.0;            // threshold V (m/s)
  bool by_fiber_ = false;         // fiber centre-of-mass speeds instead of node speeds
  double fraction_ = 1.0;         // mass fraction q of physics/settle.h (measure fiber)
  class FixFiberBeam *beam_ = nullptr;
  double settled_checks_ = 0, measured_ = 0;
};

}  // namespace LAMMPS_NS

#endif
