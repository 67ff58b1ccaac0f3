/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "fix_wall_fiber_dlvo.h"

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
      error->all(FLERR, (std::string(style) + ": plane: '" + arg[4 + k] + "' is not a number").c_str());
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
    if (!std::strcmp(arg[iarg], "velocity")) {
      if (iarg + 3 >= narg) error->all(FLERR, "fix wall/fiber/dlvo: velocity needs vx vy vz (m/s)");
      plane0_.velocity = {force->numeric(FLERR, arg[iarg + 1]), force->numeric(FLERR, arg[iarg + 2]),
                          force->numeric(FLERR, arg[iarg + 3])};
      iarg += 4;
      continue;
    }
    const int used = fiberform::parse_contact_keyword(lmp, style, cfg, iarg, narg, arg);
    if (used == 0)
      error->all(FLERR, (std::string(style) + ": unknown keyword '" + arg[iarg] +
                         "' (see docs/styles/fix_wall_fiber_dlvo.md)").c_str());
    iarg += used;
  }
  fiberform::validate_contact_config(lmp, style, cfg);
  own_engine_->cfg = cfg;
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
  const fiberform::Vec3 &vp = plane0_.velocity;
  if (newton_ && (vp.x != 0.0 || vp.y != 0.0 || vp.z != 0.0))
    error->all(FLERR, "fix wall/fiber/dlvo: implicit_force newton with a moving plate is not supported yet (a "
                      "free fiber pushed by the plate leaves it at 1.9x the plate speed; "
                      "docs/models/contact.md section 8): use implicit_force position or impulse");
  if (newton_ && !model_) {
    bodies_.add_plane(plane0_.point, plane0_.normal, plane0_.velocity);
    newton_law_ = engine_->cfg.law;
    newton_law_.steric.s1_damping = true;  // the PD servo, as fix fiber/yarns (docs/models/contact.md 8)
    model_ = std::make_unique<fiberform::physics::StaticContactModel>(bodies_, newton_law_, 0.0);
  }
  if (beam_) beam_->use_force_model(model_.get(), newton_);
}

/* implicit_force newton: the plate's position at the end of this step, where the fibers are solved */
void FixWallFiberDlvo::post_force(int vflag) {
  if (!newton_) {
    FiberContactFix::post_force(vflag);
    return;
  }
  const double t = (update->ntimestep - step0_) * update->dt;
  bodies_.set_plane_point(0, plane0_.point + t * plane0_.velocity);
}

void FixWallFiberDlvo::setup(int vflag) {
  if (!step0_set_) {
    step0_ = update->ntimestep;
    step0_set_ = true;
  }
  FiberContactFix::setup(vflag);
}

double FixWallFiberDlvo::interaction_reach() {
  double max_len = 0, max_rad = 0;
  engine_->global_extents(max_len, max_rad);
  return 1.2 * max_len;  // the next node of every local atom must be present
}

void FixWallFiberDlvo::accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) {
  // plane position at the current time (the start of the sub-integrated step)
  fiberform::Plane pl = plane0_;
  const double t = (update->ntimestep - step0_) * update->dt;
  pl.point = pl.point + t * pl.velocity;
  engine_->wall(pl, groupbit, update->dt, subintegrate, nd, out);
}
