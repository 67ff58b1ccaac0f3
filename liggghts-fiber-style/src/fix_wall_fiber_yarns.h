/* SPDX-License-Identifier: GPL-3.0-or-later
   fix wall/fiber/yarns: fabric yarns as static bodies for fix fiber/beam fibers (Kettil 2016 sec.
   3.1): chains of cylinders (polylines with a radius) of infinite mass acting on every fiber
   element (closest points of the centre lines, lever rule; single-node fibers: the node) through
   the fiber/dlvo contact law (physics/contact_law.h), with optional Coulomb friction. The contact
   keywords (law, integrator, implicit_force, friction) are those of pair_style fiber/dlvo and fix
   wall/fiber/dlvo (contact_args.cpp), so yarns, planes, plates and fibers share one law and one
   keyword parser. Documentation: docs/styles/fix_wall_fiber_yarns.md.

     fix ID group wall/fiber/yarns yarns FILE [keyword value ...]

   implicit_force newton (the default with implicit fibers): the law acts inside each fiber's Newton
   solve (physics/static_bodies.h StaticContactModel, any number of ranks); impulse | position
   (explicit fibers: always the impulse): each contact point is sub-integrated over the step
   (cvode | substep N) and its averaged force is handed to the step (both nodes of an element on
   the rank of its first node). */
#ifndef LMP_FIX_WALL_FIBER_YARNS_H
#define LMP_FIX_WALL_FIBER_YARNS_H

#include <memory>
#include <vector>

#include "contact_integrator.h"
#include "fiber_contact_fix.h"
#include "physics/static_bodies.h"

namespace LAMMPS_NS {

class FixWallFiberYarns : public FiberContactFix {
 public:
  FixWallFiberYarns(class LAMMPS *lmp, int narg, char **arg);
  ~FixWallFiberYarns() override;
  int setmask() override;
  void init() override;
  void setup(int vflag) override;
  void post_force(int vflag) override;
  void end_of_step() override;
  bool in_newton_solve() const override { return newton_; }
  double compute_vector(int n) override;

 protected:
  // the yarns' own contact passes (below) replace the base's engine passes
  void accumulate(bool, const fiberform::NodeData &, const fiberform::NodeSinks &) override {}
  double interaction_reach() override { return 0.0; }  // fix fiber/beam's ghost cut-off covers an element

 private:
  void apply_node_contact(int i, const double n[3], double h, double r1, double r2, double &gap_min);
  void apply_element_contact(int i, int j, double s, const double n[3], double h, double r1, double r2,
                             double &gap_min);
  void element_yarn_contacts(int i, int j, double r1, double &gap_min);
  void node_yarn_contacts(int i, double r1, double &gap_min);
  void read_yarns(const char *path);
  void scan_contacts();
  void apply_friction(int i, int j, double s, const double n[3], double fn);
  void normal_solve(const double p[3], const double v[3], const double a[3], double inv_m, const double n[3],
                    double h, double r1, double r2, double &fpos, double &fvel);
  double applied_force(double fpos, double fvel) const;
  double travel(int i) const;
  void land_velocity(int i, int j, double wi, double wj, const double n[3], double fc, double fv);
  const fiberform::physics::ContactLaw &law() const { return engine_->cfg.law; }

  std::unique_ptr<fiberform::ContactEngine> own_engine_;  // holds the parsed configuration
  fiberform::physics::StaticBodies bodies_;  // yarn segments (binned)
  std::unique_ptr<fiberform::physics::StaticContactModel> model_;  // implicit_force newton
  double local_[2] = {0, 0};  // contacts in range, -smallest gap (this rank)
  double sums_[2] = {0, 0};
  // the yarns' total contact force on the fibers at the end of the last step (N; implicit_force
  // newton): this rank's share and the sum over ranks
  double local_force_[3] = {0, 0, 0}, force_[3] = {0, 0, 0};
  bool sums_valid_ = false;
  bool implicit_ = false;           // fix fiber/beam integrates implicitly (set in init)
  double beta_eff_ = 0.5, gamma_eff_ = 1.0;  // its effective Newmark coefficients
  fiberform::ContactIntegrator integ_;  // one CVODE memory / sub-stepper for all contacts
  bool impulse_ = true;             // apply the impulse average (explicit, or implicit_force impulse)
  bool newton_ = false;             // contacts inside the implicit solve (set in init)
  int s1_damping_kw_ = -1;          // -1: default (yes with newton)
  double failures_ = 0;
  std::vector<double> land_;        // implicit position: per local atom velocity correction (3), force (3)
};

}  // namespace LAMMPS_NS

#endif
