/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "fiber_contact_fix.h"

#include <mpi.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "abi_guard.h"
#include "atom.h"
#include "comm.h"
#include "error.h"
#include "fix_fiber_beam.h"
#include "fix.h"
#include "force.h"
#include "modify.h"
#include "memory.h"
#include "update.h"

using namespace LAMMPS_NS;
using namespace FixConst;

FiberContactFix::FiberContactFix(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg) {
  comm_forward = 7;   // v(3), a0(3), mass share(1)
  comm_reverse = 12;  // fpre, fpost, tpre, tpost
  vector_flag = 1;
  size_vector = 6;  // 5 engine counters + the smallest separation of the last pass
  global_freq = 1;
  extvector = 0;
  nevery = 1;
  grow_arrays(atom->nmax);
  atom->add_callback(0);
  for (int i = 0; i < atom->nmax; ++i)
    for (int k = 0; k < 3; ++k) cpost_[i][k] = tpost_[i][k] = 0.0;
}

FiberContactFix::~FiberContactFix() {
  atom->delete_callback(id, 0);
  memory->destroy(cpost_);
  memory->destroy(tpost_);
  memory->destroy(vbuf_);
  memory->destroy(acc_);
  memory->destroy(share_);
  memory->destroy(fpre_);
  memory->destroy(fpost_);
  memory->destroy(tpre_);
  memory->destroy(tpost_b_);
}

int FiberContactFix::setmask() { return PRE_FORCE | POST_FORCE | FINAL_INTEGRATE | END_OF_STEP; }

void FiberContactFix::init() {
  fiberform::check_atom_layout(lmp);
  if (!engine_) error->all(FLERR, "fiber contact fix without an engine");
  engine_->init();
  reach_ = interaction_reach();
  beam_ = FixFiberBeam::find(lmp);
  if (implicit_beam() && !beam_->precedes(this))
    error->all(FLERR, "fiber contact (pair_style fiber/dlvo, fix wall/fiber/dlvo, fix wall/fiber/yarns): define it after fix "
                      "fiber/beam (its velocity landing follows the implicit solve)");
}

bool FiberContactFix::implicit_beam() const { return beam_ && beam_->implicit(); }

// Sub-integrates every interacting pair from the current state (a0 from f) and sums the averaged
// forces of all contact points into fpre_/fpost_/tpre_/tpost_b_ of the local atoms.
void FiberContactFix::subintegrate_all() {
  prepare(true);
  const int nall = atom->nlocal + atom->nghost;
  for (int i = 0; i < nall; ++i)
    for (int k = 0; k < 3; ++k) fpre_[i][k] = fpost_[i][k] = tpre_[i][k] = tpost_b_[i][k] = 0.0;
  const bool torques = atom->torque_flag;
  engine_->stats.min_h = std::numeric_limits<double>::infinity();
  accumulate(true, {vbuf_, acc_, share_}, {fpre_, fpost_, torques ? tpre_ : nullptr, torques ? tpost_b_ : nullptr});
  comm->reverse_comm_fix(this);
  sum_forces(fpost_);  // F_vel: the step's impulse / dt (explicit and implicit alike)
}

void FiberContactFix::sum_forces(double **src) {
  force_sum_[0] = force_sum_[1] = force_sum_[2] = 0.0;
  for (int i = 0; i < atom->nlocal; ++i)
    for (int k = 0; k < 3; ++k) force_sum_[k] += src[i][k];
  after_pass();
}

void FiberContactFix::solve_implicit() {
  for (int i = 0; i < atom->nlocal; ++i)
    for (int k = 0; k < 3; ++k) cpost_[i][k] = tpost_[i][k] = 0.0;
  subintegrate_all();
  const bool torques = atom->torque_flag;
  double **f = atom->f, **t = atom->torque;
  if (engine_->cfg.implicit_impulse) {
    // the impulse average m w(dt)/dt (momentum exact); torques from the same points' pre forces
    for (int i = 0; i < atom->nlocal; ++i)
      for (int k = 0; k < 3; ++k) {
        f[i][k] += fpost_[i][k];
        if (torques) t[i][k] += tpre_[i][k];
      }
    return;
  }
  const double c = 0.5 / beam_->beta_eff();  // F_pos = 2 m y / dt^2  ->  m y / (beta_eff dt^2)
  for (int i = 0; i < atom->nlocal; ++i)
    for (int k = 0; k < 3; ++k) {
      f[i][k] += c * fpre_[i][k];
      if (torques) t[i][k] += c * tpre_[i][k];
    }
}

double FiberContactFix::extend_cut_ghost() {
  // platform.md: ghosts are effectively shipped only within about half of the requested
  // distance for finite-radius atoms; request twice the reach.
  return 2.0 * reach_;
}

void FiberContactFix::grow_buffers() {
  const int nall = atom->nlocal + atom->nghost;
  if (nall <= nbuf_) return;
  nbuf_ = atom->nmax > nall ? atom->nmax : nall;
  memory->grow(vbuf_, nbuf_, 3, "fiber_contact:v");
  memory->grow(acc_, nbuf_, 3, "fiber_contact:acc");
  memory->grow(share_, nbuf_, "fiber_contact:share");
  memory->grow(fpre_, nbuf_, 3, "fiber_contact:fpre");
  memory->grow(fpost_, nbuf_, 3, "fiber_contact:fpost");
  memory->grow(tpre_, nbuf_, 3, "fiber_contact:tpre");
  memory->grow(tpost_b_, nbuf_, 3, "fiber_contact:tpost");
}

void FiberContactFix::prepare(bool with_acc) {
  grow_buffers();
  const int nlocal = atom->nlocal;
  double **v = atom->v, **f = atom->f;
  double *rmass = atom->rmass;
  engine_->compute_shares(share_);
  // implicit fibers, position landing: a0 from the external loads only (the internal force of a
  // stiff fiber at a contact node is mostly the unresolved elastic reaction to the last contact push)
  const bool external_only = with_acc && implicit_beam() && !engine_->cfg.implicit_impulse;
  for (int i = 0; i < nlocal; ++i) {
    const double *fint = external_only && beam_->is_node(i) ? beam_->internal_force(i) : nullptr;
    for (int k = 0; k < 3; ++k) {
      vbuf_[i][k] = v[i][k];
      acc_[i][k] = with_acc ? (f[i][k] - cpost_[i][k] - (fint ? fint[k] : 0.0)) / rmass[i] : 0.0;
    }
  }
  comm->forward_comm_fix(this);
}

void FiberContactFix::solve_step() {
  subintegrate_all();
  const bool torques = atom->torque_flag;
  double **f = atom->f;
  double **t = atom->torque;
  for (int i = 0; i < atom->nlocal; ++i) {
    for (int k = 0; k < 3; ++k) {
      f[i][k] += fpre_[i][k] - cpost_[i][k];  // replace last step's post part by the new pre part
      cpost_[i][k] = 2.0 * fpost_[i][k] - fpre_[i][k];
      if (torques) {
        t[i][k] += tpre_[i][k] - tpost_[i][k];
        tpost_[i][k] = tpre_[i][k];  // torques: no velocity correction (nodes carry no ODE spin)
      }
    }
  }
}

void FiberContactFix::setup_pre_force(int vflag) { pre_force(vflag); }

void FiberContactFix::pre_force(int) {
  if (in_newton_solve()) return;
  // integrator none: the force phase needs ghost mass shares and velocities
  if (!subintegrating()) prepare(false);
}

void FiberContactFix::setup(int vflag) {
  if (in_newton_solve()) return;
  if (subintegrating() && implicit_beam()) {
    solve_implicit();
    return;
  }
  if (!subintegrating()) {
    post_force(vflag);
    return;
  }
  // f holds every force but ours (our post part is not applied in setup)
  for (int i = 0; i < atom->nlocal; ++i)
    for (int k = 0; k < 3; ++k) cpost_[i][k] = tpost_[i][k] = 0.0;
  solve_step();
}

void FiberContactFix::end_of_step() {
  if (in_newton_solve()) return;
  if (!subintegrating() || implicit_beam()) return;
  solve_step();
}

/* Implicit fibers: right after fix fiber/beam's solve (this fix comes later in the fix list: init
   checks it), so that every end_of_step hook (settle checks, output) sees the landed velocities. */
void FiberContactFix::final_integrate() {
  if (in_newton_solve()) return;
  if (!subintegrating() || !implicit_beam()) return;
  // implicit: the constant force F = F_pos/(2 beta_eff) landed the points on the ODE end
  // positions but changed their velocities by gamma_eff dt F/m; land them on the ODE end velocities
  // as well (impulse F_vel dt): v += dt/m (F_vel - gamma_eff F), and take F out of the scheme's
  // acceleration history (else its impulse would be delivered again over the next steps).
  if (engine_->cfg.implicit_impulse) return;
  const double c = 0.5 / beam_->beta_eff(), g = beam_->gamma_eff();
  const double dt = update->dt;
  double **v = atom->v;
  for (int i = 0; i < atom->nlocal; ++i) {
    const double k = dt / atom->rmass[i];
    double F[3];
    for (int d = 0; d < 3; ++d) {
      F[d] = c * fpre_[i][d];
      v[i][d] += k * (fpost_[i][d] - g * F[d]);
    }
    beam_->remove_from_history(i, F);
  }
}

void FiberContactFix::post_force(int) {
  if (in_newton_solve()) return;
  double **f = atom->f;
  if (subintegrating() && implicit_beam()) {
    solve_implicit();
    return;
  }
  if (subintegrating()) {
    double **t = atom->torque;
    for (int i = 0; i < atom->nlocal; ++i)
      for (int k = 0; k < 3; ++k) {
        f[i][k] += cpost_[i][k];
        if (atom->torque_flag) t[i][k] += tpost_[i][k];
      }
    return;
  }
  if (!fix_applies_instantaneous()) return;
  const int nall = atom->nlocal + atom->nghost;
  grow_buffers();
  for (int i = 0; i < nall; ++i)
    for (int k = 0; k < 3; ++k) fpre_[i][k] = fpost_[i][k] = tpre_[i][k] = tpost_b_[i][k] = 0.0;
  const bool torques = atom->torque_flag;
  engine_->stats.min_h = std::numeric_limits<double>::infinity();
  accumulate(false, {vbuf_, nullptr, share_}, {fpre_, nullptr, torques ? tpre_ : nullptr, nullptr});
  comm->reverse_comm_fix(this);
  sum_forces(fpre_);
  double **t = atom->torque;
  for (int i = 0; i < atom->nlocal; ++i)
    for (int k = 0; k < 3; ++k) {
      f[i][k] += fpre_[i][k];
      if (torques) t[i][k] += tpre_[i][k];
    }
}

double FiberContactFix::compute_vector(int n) {
  const fiberform::EngineStats &s = engine_->stats;
  double loc = 0.0, glob = 0.0;
  switch (n) {
    case 0: loc = s.solves; break;
    case 1: loc = s.in_range; break;
    case 2: loc = s.rhs_evals; break;
    case 3: loc = s.failures; break;
    case 4: loc = s.cache_hits; break;
    case 5:  // smallest separation (m) of the last pass; 1 m when no pair was in range
      loc = s.min_h;
      MPI_Allreduce(&loc, &glob, 1, MPI_DOUBLE, MPI_MIN, world);
      return std::isfinite(glob) ? glob : 1.0;
  }
  MPI_Allreduce(&loc, &glob, 1, MPI_DOUBLE, MPI_SUM, world);
  return glob;
}

// ---- per-atom persistent state (the post part must follow its atom across ranks)
void FiberContactFix::grow_arrays(int nmax) {
  memory->grow(cpost_, nmax, 3, "fiber_contact:cpost");
  memory->grow(tpost_, nmax, 3, "fiber_contact:tpost");
}
void FiberContactFix::copy_arrays(int i, int j, int) {
  for (int k = 0; k < 3; ++k) {
    cpost_[j][k] = cpost_[i][k];
    tpost_[j][k] = tpost_[i][k];
  }
}
int FiberContactFix::pack_exchange(int i, double *buf) {
  for (int k = 0; k < 3; ++k) {
    buf[k] = cpost_[i][k];
    buf[3 + k] = tpost_[i][k];
  }
  return 6;
}
int FiberContactFix::unpack_exchange(int n, double *buf) {
  for (int k = 0; k < 3; ++k) {
    cpost_[n][k] = buf[k];
    tpost_[n][k] = buf[3 + k];
  }
  return 6;
}

// ---- ghost communication
int FiberContactFix::pack_comm(int n, int *list, double *buf, int, int *) {
  int m = 0;
  for (int q = 0; q < n; ++q) {
    const int j = list[q];
    for (int k = 0; k < 3; ++k) buf[m++] = vbuf_[j][k];
    for (int k = 0; k < 3; ++k) buf[m++] = acc_[j][k];
    buf[m++] = share_[j];
  }
  return comm_forward;
}
void FiberContactFix::unpack_comm(int n, int first, double *buf) {
  grow_buffers();
  int m = 0;
  for (int i = first; i < first + n; ++i) {
    for (int k = 0; k < 3; ++k) vbuf_[i][k] = buf[m++];
    for (int k = 0; k < 3; ++k) acc_[i][k] = buf[m++];
    share_[i] = buf[m++];
  }
}
int FiberContactFix::pack_reverse_comm(int n, int first, double *buf) {
  int m = 0;
  for (int i = first; i < first + n; ++i) {
    for (int k = 0; k < 3; ++k) buf[m++] = fpre_[i][k];
    for (int k = 0; k < 3; ++k) buf[m++] = fpost_[i][k];
    for (int k = 0; k < 3; ++k) buf[m++] = tpre_[i][k];
    for (int k = 0; k < 3; ++k) buf[m++] = tpost_b_[i][k];
  }
  return comm_reverse;
}
void FiberContactFix::unpack_reverse_comm(int n, int *list, double *buf) {
  int m = 0;
  for (int q = 0; q < n; ++q) {
    const int j = list[q];
    for (int k = 0; k < 3; ++k) fpre_[j][k] += buf[m++];
    for (int k = 0; k < 3; ++k) fpost_[j][k] += buf[m++];
    for (int k = 0; k < 3; ++k) tpre_[j][k] += buf[m++];
    for (int k = 0; k < 3; ++k) tpost_b_[j][k] += buf[m++];
  }
}
