/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/drag: fluid forces on the elements of fix fiber/beam fibers (Kettil 2016, sec. 2.3):
   drag per unit length eq. 2.14 with C_D of eq. 2.15 and Re of eq. 2.16 at each element centre,
   split equally to the element's two nodes; gravity and buoyancy on every node.

   Syntax (full page: docs/styles/fix_fiber_drag.md):
     fix ID group fiber/drag flow uniform ux uy uz | flow grid FILE  [keyword value ...]
       fluid_density rho      kg/m3 (default 998.2)
       viscosity mu           Pa s (default 1e-3)
       gravity gx gy gz       m/s2 (default 0 0 -9.81)
       drag yes|no            fluid drag on/off (default yes)
       implicit yes|no        with implicit fix fiber/beam: hand the drag's velocity Jacobian to the
                              Newton solve (linearly implicit drag; default yes) or lag it (no)

   The velocity field is a fiberform::physics::flow::FlowField (physics/flow_grid.h): a uniform
   vector or the frozen grid written by `fiberform flow`; a coupled field can replace it. */
#ifndef LMP_FIX_FIBER_DRAG_H
#define LMP_FIX_FIBER_DRAG_H

#include <memory>
#include <vector>

#include "fix.h"

namespace fiberform::physics::flow {
class FlowField;
}

namespace LAMMPS_NS {

class FixFiberDrag : public Fix {
 public:
  FixFiberDrag(class LAMMPS *lmp, int narg, char **arg);
  ~FixFiberDrag() override;
  int setmask() override;
  void init() override;
  void setup(int vflag) override;
  void post_force(int vflag) override;
  double compute_vector(int n) override;

  /// Replace the velocity field (e.g. by a coupled, time-varying one). Takes ownership.
  void set_flow(std::unique_ptr<fiberform::physics::flow::FlowField> flow);

  /// Drag force (N, xyz) this fix applied to local atom i in its last post_force (the node's halves
  /// of its elements' eq. 2.14 forces; zero for atoms that are not fiber nodes of the group, and zero
  /// with `drag no`). Valid until the atoms are next re-sorted or exchanged (the next step's
  /// neighbouring), i.e. for fixes at end_of_step of the same step. Gravity and buoyancy excluded.
  const double *node_drag(int i) const { return &node_drag_[3 * static_cast<std::size_t>(i)]; }
  /// Number of local atoms node_drag() covers (atom->nlocal at the last post_force).
  int node_drag_count() const { return static_cast<int>(node_drag_.size() / 3); }
  double fluid_density() const { return rho_f_; }  ///< kg/m3
  double viscosity() const { return mu_; }         ///< Pa s

 private:
  // drag on element i -> j into fe (N); jac (optional): its Jacobian df/du times the length (N s/m)
  double element_force(int i, int j, double fe[3], double *jac = nullptr) const;

  std::unique_ptr<fiberform::physics::flow::FlowField> flow_;
  double rho_f_ = 998.2, mu_ = 1.0e-3;
  double g_[3] = {0.0, 0.0, -9.81};
  bool drag_on_ = true;
  bool implicit_ = true;
  class FixFiberBeam *beam_ = nullptr;
  double sums_[7] = {0, 0, 0, 0, 0, 0, 0};  // drag xyz (N), gravity+buoyancy xyz (N), elements
  bool sums_valid_ = false;
  double local_[7] = {0, 0, 0, 0, 0, 0, 0};
  std::vector<double> node_drag_;  // 3 per local atom, see node_drag()
};

}  // namespace LAMMPS_NS

#endif
