/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "fix_wall_fiber_dlvo.h"

#include "style_args.h"

#include <mpi.h>

#include <cmath>
#include <cstring>
#include <string>

#include "error.h"
#include "fix_fiber_beam.h"
#include "force.h"
#include "update.h"

using namespace LAMMPS_NS;

FixWallFiberDlvo::FixWallFiberDlvo(LAMMPS *lmp, int narg, char **arg)
    : FiberContactFix(lmp, narg, arg), own_engine_(new fiberform::ContactEngine(lmp)) {
  engine_ = own_engine_;
  const char *style = "fix wall/fiber/dlvo";
  if (narg < 10 || std::strcmp(arg[3], "plane") != 0)
    error->all(FLERR, "fix wall/fiber/dlvo: expected 'fix ID group wall/fiber/dlvo plane px py pz nx ny nz ...'");
  double v[6];
  for (int k = 0; k < 6; ++k) {
    char *end = nullptr;
    v[k] = std::strtod(arg[4 + k], &end);
    if (end == arg[4 + k] || *end || !std::isfinite(v[k]))
      error->all(FLERR, fiberform::error_text(std::string(style) + ": plane: '" + arg[4 + k] + "' is not a number"));
  }
  fiberform::Vec3 n{v[3], v[4], v[5]};
  const double nn = fiberform::physics::norm(n);
  if (!(nn > 0)) error->all(FLERR, "fix wall/fiber/dlvo: plane normal must not be zero");
  plane0_.point = {v[0], v[1], v[2]};
  plane0_.normal = (1.0 / nn) * n;
  plane0_.velocity = {0, 0, 0};
  fiberform::EngineConfig cfg;
  int iarg = 10;
  while (iarg < narg) {
    if (!std::strcmp(arg[iarg], "servo")) {
      // servo A u_max p_ref N t1 p1 ... tN pN
      if (iarg + 4 >= narg) error->all(FLERR, "fix wall/fiber/dlvo: servo needs A u_max p_ref N t1 p1 ... tN pN");
      area_ = force->numeric(FLERR, arg[iarg + 1]);
      u_max_ = force->numeric(FLERR, arg[iarg + 2]);
      p_ref_ = force->numeric(FLERR, arg[iarg + 3]);
      const int n = force->inumeric(FLERR, arg[iarg + 4]);
      if (!(area_ > 0) || !(u_max_ > 0) || !(p_ref_ > 0) || n < 1)
        error->all(FLERR, "fix wall/fiber/dlvo: servo needs A > 0 (m^2), u_max > 0 (m/s), p_ref > 0 (Pa), N >= 1");
      if (iarg + 4 + 2 * n >= narg)
        error->all(FLERR, "fix wall/fiber/dlvo: servo schedule needs N pairs t_k p_k (s, Pa)");
      for (int k = 0; k < n; ++k) {
        schedule_.t.push_back(force->numeric(FLERR, arg[iarg + 5 + 2 * k]));
        schedule_.p.push_back(force->numeric(FLERR, arg[iarg + 6 + 2 * k]));
      }
      if (!schedule_.valid()) error->all(FLERR, "fix wall/fiber/dlvo: servo schedule times must ascend strictly");
      iarg += 5 + 2 * n;
      continue;
    }
    if (!std::strcmp(arg[iarg], "stop")) {
      // stop D: the plate travels at most D (m) along its normal from where it starts
      if (iarg + 1 >= narg) error->all(FLERR, "fix wall/fiber/dlvo: stop needs a distance D >= 0 (m)");
      travel_max_ = force->numeric(FLERR, arg[iarg + 1]);
      if (!(travel_max_ >= 0)) error->all(FLERR, "fix wall/fiber/dlvo: stop needs a distance D >= 0 (m)");
      iarg += 2;
      continue;
    }
    if (!std::strcmp(arg[iarg], "velocity")) {
      if (iarg + 3 >= narg) error->all(FLERR, "fix wall/fiber/dlvo: velocity needs vx vy vz (m/s)");
      plane0_.velocity = {force->numeric(FLERR, arg[iarg + 1]), force->numeric(FLERR, arg[iarg + 2]),
                          force->numeric(FLERR, arg[iarg + 3])};
      iarg += 4;
      continue;
    }
    const int used = fiberform::parse_contact_keyword(lmp, style, cfg, iarg, narg, arg);
    if (used == 0)
      error->all(FLERR, fiberform::error_text(std::string(style) + ": unknown keyword '" + arg[iarg] +
                                              "' (see docs/styles/fix_wall_fiber_dlvo.md)"));
    iarg += used;
  }
  fiberform::validate_contact_config(lmp, style, cfg);
  own_engine_->cfg = cfg;
  if (area_ > 0 && fiberform::physics::dot(plane0_.velocity, plane0_.velocity) > 0)
    error->all(FLERR, "fix wall/fiber/dlvo: servo and velocity exclude each other (the servo sets the speed)");
  plane_ = plane0_;
  size_vector = 16;
}

FixWallFiberDlvo::~FixWallFiberDlvo() {
  FixFiberBeam::release_force_model(lmp, model_.get());
  delete own_engine_;
}

void FixWallFiberDlvo::init() {
  FiberContactFix::init();
  newton_ = implicit_beam() && engine_->cfg.implicit_newton;
  if (engine_->cfg.implicit_newton && !implicit_beam())
    error->all(FLERR, "fix wall/fiber/dlvo: implicit_force newton needs fix fiber/beam integrator implicit");
  if (newton_ && !model_) {
    bodies_.add_plane(plane0_.point, plane0_.normal, plane0_.velocity);
    newton_law_ = engine_->cfg.law;
    newton_law_.steric.s1_damping = true;  // the PD servo, as fix wall/fiber/yarns (docs/models/contact.md 8)
    model_ = std::make_unique<fiberform::physics::StaticContactModel>(bodies_, newton_law_, engine_->cfg.friction,
                                                                         engine_->cfg.friction_stick);
    model_->track_stiffness(area_ > 0);  // the servo's gain bound
  }
  if (beam_) beam_->use_force_model(model_.get(), newton_);
}

/* implicit_force newton: the plate's force at the end of the last step (the fibers' converged
   states), the servo's speed from it, and the plate's position at the end of this step, where the
   fibers are solved. */
void FixWallFiberDlvo::post_force(int vflag) {
  if (!newton_) {
    FiberContactFix::post_force(vflag);
    return;
  }
  double gap = 0.0;
  // this rank's contacts' stiffness, summed over the ranks with the force (reduce_force): every
  // rank's servo must see the same bound, or each rank would move its own copy of the plate
  const fiberform::Vec3 t = model_->take_total(gap, stiff_local_);
  force_sum_[0] = t.x;
  force_sum_[1] = t.y;
  force_sum_[2] = t.z;
  newton_gap_local_ = gap;  // reduced over ranks when output (compute_vector)
  after_pass();
  move_plane();
  bodies_.set_plane_point(0, plane_.point);
  bodies_.set_plane_velocity(0, plane_.velocity);
}

void FixWallFiberDlvo::setup(int vflag) {
  if (!moved_set_) {  // the plane starts moving at the fix's first run
    moved_ = update->ntimestep;
    moved_set_ = true;
  }
  FiberContactFix::setup(vflag);
}

double FixWallFiberDlvo::interaction_reach() {
  double max_len = 0, max_rad = 0;
  engine_->global_extents(max_len, max_rad);
  return 1.2 * max_len;  // the next node of every local atom must be present
}

void FixWallFiberDlvo::accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) {
  // the plane at the current time (the start of the sub-integrated step): moved once per step with
  // the velocity of the previous step (constant, or the servo's)
  move_plane();
  engine_->wall(plane_, groupbit, update->dt, subintegrate, nd, out);
}

/* Moves the plane to the current step with its velocity, no farther than `stop` allows; a plate
   at its stop has zero velocity (what the fibers' Newton solves and the outputs see). */
void FixWallFiberDlvo::move_plane() {
  if (update->ntimestep <= moved_) return;
  const double dt = static_cast<double>(update->ntimestep - moved_) * update->dt;
  moved_ = update->ntimestep;
  if (travel_max_ >= 0) {
    const double done = fiberform::physics::dot(plane_.point - plane0_.point, plane_.normal);
    const double un = fiberform::physics::dot(plane_.velocity, plane_.normal);
    if (done + un * dt >= travel_max_) {
      plane_.point = plane_.point + (travel_max_ - done) * plane_.normal;
      plane_.velocity = {0.0, 0.0, 0.0};
      at_stop_ = true;
      return;
    }
  }
  at_stop_ = false;
  plane_.point = plane_.point + dt * plane_.velocity;
}

/* After each pass: the total contact force on the fibers (all ranks), the plate pressure, and the
   servo's plate speed for the next step. */
void FixWallFiberDlvo::after_pass() {
  force_reduced_ = false;
  if (area_ <= 0) return;  // no servo: the force is reduced only when output (compute_vector)
  reduce_force();
  if (newton_) k_bound_ = fiberform::physics::press::stiffness_bound(k_bound_, stiff_ / area_, kStiffnessDecay);
  const double n[3] = {plane_.normal.x, plane_.normal.y, plane_.normal.z};
  pressure_ = fiberform::physics::press::plate_pressure(force_, n, area_);
  // the schedule's clock starts at the first contact (any force); before it the plate approaches
  // at the speed limit
  if (contact_step_ < 0 && (force_[0] != 0.0 || force_[1] != 0.0 || force_[2] != 0.0))
    contact_step_ = update->ntimestep;
  double u = u_max_;
  target_ = 0.0;
  if (contact_step_ >= 0) {
    target_ = schedule_.at((update->ntimestep - contact_step_) * update->dt);
    // k_bound_ stays 0 without implicit_force newton: then this is the plain proportional law
    const double m = adapt_.update(target_ - pressure_);
    u = fiberform::physics::press::servo_speed_bounded(target_, pressure_, p_ref_, u_max_, k_bound_, update->dt,
                                                       kServoSteps, m);
  }
  if (at_stop_ && u > 0.0) u = 0.0;  // resting on its stop: only a retreat moves it
  plane_.velocity = u * plane_.normal;
}

/* The contact force on the fibers and (implicit_force newton) the plate contacts' stiffness, summed
   over the ranks (collective; once per pass). */
void FixWallFiberDlvo::reduce_force() {
  if (force_reduced_) return;
  const double local[4] = {force_sum_[0], force_sum_[1], force_sum_[2], stiff_local_};
  double total[4];
  MPI_Allreduce(local, total, 4, MPI_DOUBLE, MPI_SUM, world);
  for (int k = 0; k < 3; ++k) force_[k] = total[k];
  stiff_ = total[3];
  force_reduced_ = true;
}

/* 1-5 engine counters, 6 smallest separation (m), 7-9 contact force on the fibers (N), 10 plate
   displacement along its normal since the fix's first run (m), 11 plate speed along its normal
   (m/s); servo only (else 0): 12 measured plate pressure (Pa), 13 target pressure (Pa), 14 time
   since the first contact (s; -1 before it); 15: 1 while the plate rests at its stop (keyword
   stop), else 0; 16: the servo's stiffness bound (Pa/m; implicit_force newton, else 0). */
double FixWallFiberDlvo::compute_vector(int n) {
  if (n == 5 && newton_) {
    double gap = 0.0;
    MPI_Allreduce(&newton_gap_local_, &gap, 1, MPI_DOUBLE, MPI_MIN, world);
    return std::isfinite(gap) ? gap : 1.0;
  }
  if (n <= 5) return FiberContactFix::compute_vector(n);
  if (n <= 8) reduce_force();
  const fiberform::Vec3 d = plane_.point - plane0_.point;
  switch (n) {
    case 6: case 7: case 8: return force_[n - 6];
    case 9: return fiberform::physics::dot(d, plane_.normal);
    case 10: return fiberform::physics::dot(plane_.velocity, plane_.normal);
    case 11: return pressure_;
    case 12: return target_;
    case 13: return contact_step_ < 0 ? -1.0 : (update->ntimestep - contact_step_) * update->dt;
    case 14: return at_stop_ ? 1.0 : 0.0;
    case 15: return k_bound_;
  }
  return 0.0;
}
