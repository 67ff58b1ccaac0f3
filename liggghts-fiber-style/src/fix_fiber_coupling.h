/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/coupling: the fiber side of two-way coupling with fiberPimpleFoam through the coupling
   layer (coupling/layer). It gives fix fiber/drag the fluid velocity of the coupled solver (the
   cell velocities as a FlowField) and sends back, every `interval` steps, the reaction of the drag
   on the fluid: minus each node's drag force, put whole into the fluid cell containing the node
   (physics/cell_grid.h), averaged over the interval.

   Syntax (full page: docs/styles/fix_fiber_coupling.md):
     fix ID group fiber/coupling drag DRAG_ID interval N [keyword value ...]
       drag DRAG_ID     the fix fiber/drag whose flow is replaced and whose drag is reflected
       interval N       fiber steps per exchange (>= 1); the fluid step is N x the fiber step
       reaction yes|no  send the reaction (default yes) or zeros (one-way through the layer)
       kernel cell|trilinear  reaction to the cell containing the node (default) or split over the
                        8 cells around it with the interpolation's trilinear weights
       timeout T        deadline of each blocking exchange, s (> 0, default 300)

   Needs fiberdem under one mpirun with fiberPimpleFoam -coupled (docs/coupling/launch.md). */
#ifndef LMP_FIX_FIBER_COUPLING_H
#define LMP_FIX_FIBER_COUPLING_H

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fix.h"
#include "physics/cell_grid.h"

namespace fiberform::coupling {
class Channel;
}

namespace LAMMPS_NS {

class FixFiberCoupling : public Fix {
 public:
  FixFiberCoupling(class LAMMPS *lmp, int narg, char **arg);
  ~FixFiberCoupling() override;
  int setmask() override;
  void init() override;
  void end_of_step() override;
  double compute_vector(int n) override;

 private:
  void handshake();
  void receive_velocity();  // leader receives, every rank gets the field, fix fiber/drag uses it
  void exchange();

  std::string drag_id_;
  class FixFiberDrag *drag_ = nullptr;
  std::int64_t interval_ = 0;
  bool reaction_ = true;
  fiberform::physics::flow::Kernel kernel_ = fiberform::physics::flow::Kernel::Cell;
  double timeout_ = 0.0;
  double dt_ = 0.0;          // fiber step of the handshake (s)
  bool connected_ = false;
  std::unique_ptr<fiberform::coupling::Channel> channel_;  // rank 0 only
  fiberform::physics::flow::CellGrid grid_;
  std::vector<double> volumes_;  // m3, fluid cell order
  std::vector<double> acc_;      // summed reaction of the current interval, N (3 per cell)
  std::int64_t steps_ = 0;       // steps accumulated in acc_
  double stats_[4] = {0, 0, 0, 0};  // exchanges, impulse given to the fluid xyz (N s)
  // wall time of this rank (s): coupling work (spreading, sums, messages, the new flow field)
  // and waiting for the fluid (the leader's receives: the fluid's step and its own exchange work)
  double work_s_ = 0.0, wait_s_ = 0.0;
};

}  // namespace LAMMPS_NS

#endif
