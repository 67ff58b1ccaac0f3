/* SPDX-License-Identifier: GPL-3.0-or-later
   fix wall/fiber/dlvo: the contact law of pair_style fiber/dlvo (extended DLVO + steric) between
   the contact points of fiber elements and an infinite plane: a wall (fixed) or a plate moving
   with a constant velocity. The plane has infinite mass. Same integrators (cvode | substep N |
   none) and keywords as the pair style. Documentation: docs/styles/fix_wall_fiber_dlvo.md.

   fix ID group wall/fiber/dlvo plane px py pz nx ny nz [velocity vx vy vz] [keyword value ...] */
#ifndef LMP_FIX_WALL_FIBER_DLVO_H
#define LMP_FIX_WALL_FIBER_DLVO_H

#include <memory>

#include "fiber_contact_fix.h"
#include "physics/static_bodies.h"

namespace LAMMPS_NS {

class FixWallFiberDlvo : public FiberContactFix {
 public:
  FixWallFiberDlvo(class LAMMPS *lmp, int narg, char **arg);
  ~FixWallFiberDlvo() override;
  void init() override;
  void setup(int) override;
  void post_force(int) override;
  bool in_newton_solve() const override { return newton_; }

 protected:
  void accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) override;
  double interaction_reach() override;

 private:
  fiberform::ContactEngine *own_engine_;
  fiberform::Plane plane0_{};  // plane at the time step time0_
  bigint step0_ = 0;
  bool step0_set_ = false;
  // implicit_force newton: the plane as a static (moving) body of the fibers' Newton solves
  bool newton_ = false;
  fiberform::physics::StaticBodies bodies_;
  fiberform::physics::ContactLaw newton_law_;
  std::unique_ptr<fiberform::physics::StaticContactModel> model_;
};

}  // namespace LAMMPS_NS

#endif
