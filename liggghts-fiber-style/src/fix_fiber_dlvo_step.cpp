/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "fix_fiber_dlvo_step.h"

#include "error.h"
#include "force.h"
#include "pair_fiber_dlvo.h"
#include "update.h"

using namespace LAMMPS_NS;

FixFiberDlvoStep::FixFiberDlvoStep(LAMMPS *lmp, int narg, char **arg) : FiberContactFix(lmp, narg, arg) {
  if (narg != 3) error->all(FLERR, "fix fiber/dlvo/step is internal (created by pair_style fiber/dlvo)");
  find_pair();
}

void FixFiberDlvoStep::find_pair() {
  pair_ = dynamic_cast<PairFiberDlvo *>(force->pair);
  if (!pair_) error->all(FLERR, "fix fiber/dlvo/step needs pair_style fiber/dlvo (it is internal to it)");
  engine_ = &pair_->engine();
}

void FixFiberDlvoStep::init() {
  find_pair();
  FiberContactFix::init();
}

double FixFiberDlvoStep::interaction_reach() { return pair_->reach(); }

void FixFiberDlvoStep::accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) {
  engine_->pairs(pair_->neigh_list(), update->dt, subintegrate, nd, out);
}
