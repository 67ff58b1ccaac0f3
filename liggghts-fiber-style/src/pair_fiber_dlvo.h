/* SPDX-License-Identifier: GPL-3.0-or-later
   pair_style fiber/dlvo: fiber-fiber interaction by extended DLVO plus steric repulsion between
   contact points on fiber elements, sub-integrated per contact over the fiber time step with
   SUNDIALS CVODE (Kettil 2016, sections 2.4 and 4.1). Documentation: docs/styles/pair_fiber_dlvo.md.

   The pair style owns the parameters, the neighbour list (a plain FULL list whose cut-off covers two
   element lengths, two radii and the force range) and, for integrator none, the instantaneous
   forces. In every mode it creates the internal fix fiber/dlvo/step (ID FIBER_DLVO_STEP;
   docs/styles/fix_fiber_dlvo_step.md), which does the sub-integration at the start of each fiber
   step (cvode/substep; see fiber_contact_fix.h for why) or, with implicit_force newton, puts the
   fiber-fiber contacts into the fibers' Newton solves. */
#ifndef LMP_PAIR_FIBER_DLVO_H
#define LMP_PAIR_FIBER_DLVO_H

#include "contact_engine.h"
#include "pair.h"

namespace LAMMPS_NS {

class PairFiberDlvo : public Pair {
 public:
  explicit PairFiberDlvo(class LAMMPS *lmp);
  ~PairFiberDlvo() override;
  void compute(int eflag, int vflag) override;
  void settings(int narg, char **arg) override;
  void coeff(int narg, char **arg) override;
  void init_style() override;
  double init_one(int i, int j) override;
  void init_list(int id, class NeighList *ptr) override;

  fiberform::ContactEngine &engine() { return *engine_; }
  class NeighList *neigh_list() { return list; }
  double reach() const { return reach_; }

 private:
  void allocate();
  fiberform::ContactEngine *engine_;
  class FiberContactFix *step_fix_ = nullptr;
  double reach_ = 0.0;
};

}  // namespace LAMMPS_NS

#endif
