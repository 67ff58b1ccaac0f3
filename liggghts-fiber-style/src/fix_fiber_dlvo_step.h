/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/dlvo/step: INTERNAL fix created by pair_style fiber/dlvo (ID FIBER_DLVO_STEP, group
   all); never written in input scripts. It runs the per-contact sub-integration of the pair style
   at the start of each fiber step and applies the averaged forces (see fiber_contact_fix.h). */
#ifndef LMP_FIX_FIBER_DLVO_STEP_H
#define LMP_FIX_FIBER_DLVO_STEP_H

#include "fiber_contact_fix.h"

namespace LAMMPS_NS {

class FixFiberDlvoStep : public FiberContactFix {
 public:
  FixFiberDlvoStep(class LAMMPS *lmp, int narg, char **arg);
  void init() override;

 protected:
  void accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) override;
  double interaction_reach() override;
  bool fix_applies_instantaneous() const override { return false; }

 private:
  class PairFiberDlvo *pair_ = nullptr;
  void find_pair();
};

}  // namespace LAMMPS_NS

#endif
