/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/yarns: static bodies for fix fiber/beam fibers during lay-down (Kettil 2016 sec. 3.1):
   fabric yarns as chains of cylinders (polylines with a radius) and planes, both of infinite mass,
   acting on every fiber element (yarns; closest points of the centre lines, lever rule) and node
   (planes) through the fiber/dlvo contact law (physics/contact_law.h, read-only), optional friction,
   sub-integrated over the step; and removal of whole fibers that reach a height (the bottom).

   Syntax (full page: docs/styles/fix_fiber_yarns.md):
     fix ID group fiber/yarns [yarns FILE] [plane px py pz nx ny nz] ... [keyword value ...]
       remove_below z      remove every fiber any node of which is below z (m)
       remove_every N      check for removal every N steps (default 100)
       settle V M          every M steps: count consecutive checks with max node speed < V (m/s)
       settle_measure node|fiber   node speeds (default) or fiber centre-of-mass speeds
       settle_mass_fraction q      with fiber: the speed below which fibers carrying q of the mass
                                   move (default 1: every fiber; physics/settle.h)
       integrator cvode|substep   contact sub-integration (default cvode, as pair_style fiber/dlvo)
       implicit_force newton|impulse|position  with implicit fibers: newton (default) = the contact
                           law acts inside each fiber's Newton solve (physics/static_bodies.h, any
                           number of ranks); impulse/position = sub-integrated averaged forces
       s1_damping yes|no   PD form of the steric servo S1 (default yes with newton, else no)
       substeps N          velocity-Verlet sub-steps per step for `integrator substep` (default 100)
       friction mu         Coulomb friction coefficient against yarns and planes (default 0)
       terms LIST          comma list of vdw, es, steric (default steric)
       hamaker A | psi V | ionic_strength I | temperature T | eps_r e | h0 h | h_cut h |
       h_R h | h_S h | t_R t      as in pair_style fiber/dlvo */
#ifndef LMP_FIX_FIBER_YARNS_H
#define LMP_FIX_FIBER_YARNS_H

#include <array>
#include <memory>
#include <vector>

#include "fix.h"
#include "contact_integrator.h"
#include "physics/contact_law.h"
#include "physics/static_bodies.h"

namespace LAMMPS_NS {

class FixFiberYarns : public Fix {
 public:
  FixFiberYarns(class LAMMPS *lmp, int narg, char **arg);
  ~FixFiberYarns() override;
  int setmask() override;
  void init() override;
  void setup(int vflag) override;
  void post_force(int vflag) override;
  void pre_exchange() override;
  void end_of_step() override;
  double compute_vector(int n) override;
  void write_restart(FILE *fp) override;
  void restart(char *buf) override;

 private:
  void apply_contact(int i, const double n[3], double h, double r1, double r2, double &gap_min);
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
  void land_velocity(int i, int j, double wi, double wj, const double n[3], double fc, double fv, double inv_m);

  fiberform::physics::StaticBodies bodies_;  // yarn segments (binned) and planes
  std::unique_ptr<fiberform::physics::StaticContactModel> model_;  // implicit_force newton
  fiberform::physics::ContactLaw law_;
  int substeps_ = 100;
  double mu_ = 0.0;                 // Coulomb friction coefficient against yarns and planes
  bool remove_ = false;
  double remove_z_ = 0.0;
  int remove_every_ = 100;
  class FixFiberBeam *beam_ = nullptr;
  double settle_speed_ = -1.0;  // < 0: no settle check
  bool settle_fiber_ = false;   // settle on fiber centre-of-mass speeds instead of node speeds
  double settle_fraction_ = 1.0;  // settle_measure fiber: speed below which this mass fraction moves
  double settled_checks_ = 0, max_speed_ = 0;
  double removed_fibers_ = 0, removed_mass_ = 0, removed_nodes_ = 0;
  double local_[3] = {0, 0, 0};  // yarn contacts, plane contacts, -min gap
  double sums_[3] = {0, 0, 0};
  // implicit_force newton: the yarns' and planes' total contact force on the fibers at the end of
  // the last step (N); this rank's share and the sum over ranks (vector 9-11)
  double local_force_[3] = {0, 0, 0}, force_[3] = {0, 0, 0};
  bool sums_valid_ = false;
  bool implicit_ = false;           // fix fiber/beam integrates implicitly (set in init)
  double beta_eff_ = 0.5, gamma_eff_ = 1.0;  // its effective Newmark coefficients
  fiberform::ContactIntegrator integ_;  // one CVODE memory / sub-stepper for all contacts
  bool use_cvode_ = true;
  bool impulse_ = true;             // apply the impulse average (explicit, or implicit default)
  bool impulse_kw_ = true;          // keyword implicit_force impulse|position
  bool newton_kw_ = true;           // keyword implicit_force newton (the default)
  bool newton_ = false;             // contacts inside the implicit solve (set in init)
  int s1_damping_kw_ = -1;          // -1: default (yes with newton)
  double failures_ = 0;
  std::vector<double> land_;        // implicit: per local atom velocity correction (3), force (3)
};

}  // namespace LAMMPS_NS

#endif
