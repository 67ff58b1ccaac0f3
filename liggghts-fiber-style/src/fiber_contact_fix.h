/* SPDX-License-Identifier: GPL-3.0-or-later
   Base of the fixes that apply sub-integrated fiber contact forces (the internal fix of
   pair_style fiber/dlvo, fix wall/fiber/dlvo and fix wall/fiber/yarns; the last one runs its own
   per-contact passes over the yarns and keeps only the configuration, init and hooks of this
   base). Not a style by itself.

   Why a fix: with velocity Verlet a pair style only ever sees x(t+dt) and the half-step velocity
   v(t+dt/2); the sub-integration of eq. 2.19-2.21 needs the state at the START of a fiber step
   (x, full-step v, and the other forces, i.e. the intrinsic acceleration a0). That state exists
   at end_of_step() of the previous step (and in setup()). There:
     1. a0 = (f - C_post)/m per node: every force except this fix's own contribution;
     2. each interacting pair of contact points is integrated over [t, t+dt] (CVODE or sub-steps);
     3. F_pos (eq. 2.22, beta = 1/2) is added to f now: the next initial_integrate (velocity
        Verlet: x += dt v + dt^2/2 f/m) then lands the points exactly on the ODE end positions;
     4. C_post = 2 F_vel - F_pos is stored per atom (migrates with the atom) and added in
        post_force() of the next step, so that the final half kick lands on the ODE end velocity:
        v(t+dt) = v + dt/2 (a0 + F_pos/m) + dt/2 (a0' + C_post/m) = v + dt F_vel/m + dt/2 (a0 + a0').
   With integrator none the engine instead adds the instantaneous force in the force phase.

   With the implicit integrator of fix fiber/beam (the default) nothing moves before
   final_integrate, so the state at the start of the step is at hand in post_force. There:
     1. a0 = f/m per node (every other force: the internal forces of the last converged state that
        fix fiber/beam put into f, drag, gravity, yarns, walls defined before this fix);
     2. each interacting pair is integrated over [t, t+dt] as above (deviation y from free motion);
     3. the averaged contact force of eq. 2.22 with the scheme's own beta (beta_eff of the
        generalized-alpha scheme, fix fiber/beam) and a(t0) = a0, minus m a0 (which the fiber
        equation already has): F = m y(dt) / (beta_eff dt^2) = F_pos / (2 beta_eff), added to f and
        held constant over the step by the implicit solve (a rigid point then lands exactly on the
        ODE end position);
     4. in final_integrate, right after the implicit solve (this fix must come after fix fiber/beam
        in the fix list; init checks it) and before any end_of_step hook reads velocities (settle
        checks, output), the velocity is landed on the ODE end velocity as
        well, v += dt/m (F_vel - gamma_eff F), and F is taken out of the generalized-alpha
        acceleration history (FixFiberBeam::remove_from_history). Without both, a collision shorter
        than the step changes the velocity by up to gamma/beta (1.9 at rho_inf 0.5) times the right
        amount and the scheme's memory delivers part of the impulse again in the next steps
        (measured: the 4.1.1 collision at dt = 1 us gained kinetic energy 3- to 9-fold). */
#ifndef FIBERFORM_FIBER_CONTACT_FIX_H
#define FIBERFORM_FIBER_CONTACT_FIX_H

#include "contact_engine.h"
#include "fix.h"

namespace LAMMPS_NS {

class FiberContactFix : public Fix {
 public:
  FiberContactFix(class LAMMPS *lmp, int narg, char **arg);
  ~FiberContactFix() override;
  int setmask() override;
  void init() override;
  void setup_pre_force(int) override;
  void setup(int) override;
  void pre_force(int) override;
  void post_force(int) override;
  void end_of_step() override;
  void final_integrate() override;
  // true when the contacts act inside the implicit fiber solves instead (fix wall/fiber/dlvo
  // implicit_force newton): the sub-integration hooks then do nothing
  virtual bool in_newton_solve() const { return false; }
  double extend_cut_ghost() override;

  void grow_arrays(int) override;
  void copy_arrays(int, int, int) override;
  int pack_exchange(int, double *) override;
  int unpack_exchange(int, double *) override;
  int pack_comm(int, int *, double *, int, int *) override;
  void unpack_comm(int, int, double *) override;
  int pack_reverse_comm(int, int, double *) override;
  void unpack_reverse_comm(int, int *, double *) override;
  double compute_vector(int) override;
  // Node data for the force phase (integrator none): velocities and mass shares, local + ghost.
  fiberform::NodeData node_data() const { return {vbuf_, nullptr, share_}; }

 protected:
  // The engine whose configuration applies; set by the derived class before init().
  fiberform::ContactEngine *engine_ = nullptr;
  // Adds contact forces of local elements into the sinks (local + ghost indices).
  virtual void accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) = 0;
  // Distance from a local atom to the farthest atom it may interact with through an element.
  virtual double interaction_reach() = 0;
  // Called after every pass over the contacts (forces summed over ranks is up to the caller):
  // force_sum_ then holds this rank's total contact force on its local atoms for the step (N).
  virtual void after_pass() {}
  double force_sum_[3] = {0.0, 0.0, 0.0};
  // integrator none: is the instantaneous force added by the fix (wall) or by a pair (false)?
  virtual bool fix_applies_instantaneous() const { return true; }
  bool subintegrating() const { return engine_->cfg.integrator != fiberform::IntegratorKind::None; }
  bool implicit_beam() const;
  LAMMPS_NS::FixFiberBeam *beam_ = nullptr;  // set in init()

 private:
  void prepare(bool with_acc);   // shares, velocities, a0 of locals, forward comm to ghosts
  void solve_step();             // steps 1-4 above
  void solve_implicit();         // the implicit variant (post_force)
  void subintegrate_all();       // shared by both: all pairs into the sink buffers
  void sum_forces(double **src);  // force_sum_ over local atoms, then after_pass()
  void grow_buffers();
  double **cpost_ = nullptr, **tpost_ = nullptr;  // per-atom, persistent (nmax)
  double **vbuf_ = nullptr, **acc_ = nullptr, *share_ = nullptr;  // nall
  double **fpre_ = nullptr, **fpost_ = nullptr, **tpre_ = nullptr, **tpost_b_ = nullptr;  // nall
  int nbuf_ = 0;
  double reach_ = 0.0;
};

}  // namespace LAMMPS_NS

#endif
