/* SPDX-License-Identifier: GPL-3.0-or-later
   fix wall/fiber/dlvo: the contact law of pair_style fiber/dlvo (extended DLVO + steric) between
   the contact points of fiber elements and an infinite plane: a wall (fixed) or a plate moving
   with a constant velocity, or a press plate driven by a pressure servo (physics/press_servo.h).
   The plane has infinite mass. Same integrators (cvode | substep N | none) and keywords as the pair
   style, plus Coulomb friction (`friction mu`; physics/friction.h, inside the Newton solve
   physics/static_bodies.h, as fix wall/fiber/yarns). Documentation: docs/styles/fix_wall_fiber_dlvo.md.

   fix ID group wall/fiber/dlvo plane px py pz nx ny nz [velocity vx vy vz]
       [servo A u_max p_ref N t1 p1 ... tN pN] [stop D] [keyword value ...] */
#ifndef LMP_FIX_WALL_FIBER_DLVO_H
#define LMP_FIX_WALL_FIBER_DLVO_H

#include <limits>
#include <memory>

#include "fiber_contact_fix.h"
#include "physics/press_servo.h"
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
  double compute_vector(int) override;

 protected:
  void accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) override;
  double interaction_reach() override;
  void after_pass() override;
  void move_plane();

 private:
  fiberform::ContactEngine *own_engine_;
  fiberform::Plane plane0_{};  // plane at the fix's first run
  fiberform::Plane plane_{};   // plane now (moved once per time step, move_plane)
  bigint moved_ = 0;           // the step plane_ was last moved to
  bool moved_set_ = false;
  // pressure servo (off when area_ == 0): area (m^2), speed limit (m/s), pressure band (Pa)
  double area_ = 0.0, u_max_ = 0.0, p_ref_ = 0.0;
  fiberform::physics::press::Schedule schedule_;
  double force_[3] = {0.0, 0.0, 0.0};  // contact force on the fibers, all ranks (N)
  bool force_reduced_ = false;         // force_ holds the sum of this pass's force_sum_
  void reduce_force();
  double pressure_ = 0.0, target_ = 0.0;
  bigint contact_step_ = -1;  // step of the first contact (servo clock), -1: none yet
  // implicit_force newton: this rank's smallest plate gap at the last step (m)
  double newton_gap_local_ = std::numeric_limits<double>::infinity();
  double travel_max_ = -1.0;     // keyword stop: largest travel along the normal (m); < 0: none
  bool at_stop_ = false;
  // implicit_force newton: the servo's gain bound (physics/press_servo.h): the plate contacts'
  // stiffness per area (Pa/m), peak-held with a decay per step; one step closes <= 1/kServoSteps
  double k_bound_ = 0.0;
  double stiff_local_ = 0.0;  // this rank's plate contacts' stiffness at the last step (N/m)
  double stiff_ = 0.0;        // ... summed over the ranks (reduce_force)
  fiberform::physics::press::GainAdapt adapt_;  // the gain's multiplier for soft sheets
  static constexpr double kStiffnessDecay = 0.99, kServoSteps = 4.0;
  // implicit_force newton: the plane as a static (moving) body of the fibers' Newton solves
  bool newton_ = false;
  fiberform::physics::StaticBodies bodies_;
  fiberform::physics::ContactLaw newton_law_;
  std::unique_ptr<fiberform::physics::StaticContactModel> model_;
};

}  // namespace LAMMPS_NS

#endif
