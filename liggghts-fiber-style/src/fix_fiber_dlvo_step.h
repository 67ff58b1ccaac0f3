/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/dlvo/step: INTERNAL fix created by pair_style fiber/dlvo (ID FIBER_DLVO_STEP, group
   all); never written in input scripts. It runs the per-contact sub-integration of the pair style
   at the start of each fiber step and applies the averaged forces (see fiber_contact_fix.h).
   With `implicit_force newton` (implicit fix fiber/beam) it instead gathers the start-of-step state
   of every fiber node on every rank in post_force, finds the fibers that may touch during the step
   and has fix fiber/beam solve each such cluster in one Newton solve with the contacts inside
   (physics/fiber_partners.h, docs/models/contact.md section 9). */
#ifndef LMP_FIX_FIBER_DLVO_STEP_H
#define LMP_FIX_FIBER_DLVO_STEP_H

#include <memory>
#include <vector>

#include "fiber_contact_fix.h"
#include "physics/fiber_partners.h"

namespace LAMMPS_NS {

class FixFiberDlvoStep : public FiberContactFix {
 public:
  FixFiberDlvoStep(class LAMMPS *lmp, int narg, char **arg);
  ~FixFiberDlvoStep() override;
  void init() override;
  void post_force(int vflag) override;
  bool in_newton_solve() const override { return newton_; }
  double compute_vector(int n) override;

 protected:
  void accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) override;
  double interaction_reach() override;
  bool fix_applies_instantaneous() const override { return false; }

 private:
  class PairFiberDlvo *pair_ = nullptr;
  void find_pair();
  void gather_partners();
  bool newton_ = false;
  fiberform::physics::ContactLaw newton_law_;
  fiberform::physics::FiberPartners partners_;
  std::unique_ptr<fiberform::physics::ClusterContactModel> model_;
  std::vector<double> mine_, all_;
};

}  // namespace LAMMPS_NS

#endif
