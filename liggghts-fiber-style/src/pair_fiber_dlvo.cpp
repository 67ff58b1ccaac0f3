/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "pair_fiber_dlvo.h"

#include <cstring>
#include <string>

#include "abi_guard.h"
#include "atom.h"
#include "error.h"
#include "fiber_contact_fix.h"
#include "force.h"
#include "memory.h"
#include "modify.h"
#include "neigh_list.h"
#include "neigh_request.h"
#include "neighbor.h"
#include "style_args.h"
#include "update.h"

using namespace LAMMPS_NS;

namespace {
const char *kStepFixId = "FIBER_DLVO_STEP";
}

PairFiberDlvo::PairFiberDlvo(LAMMPS *lmp) : Pair(lmp), engine_(new fiberform::ContactEngine(lmp)) {
  single_enable = 0;
  restartinfo = 0;
}

PairFiberDlvo::~PairFiberDlvo() {
  if (allocated) {
    memory->destroy(setflag);
    memory->destroy(cutsq);
  }
  if (modify && modify->find_fix(kStepFixId) >= 0) modify->delete_fix(kStepFixId);
  delete engine_;
}

void PairFiberDlvo::allocate() {
  allocated = 1;
  const int n = atom->ntypes;
  memory->create(setflag, n + 1, n + 1, "pair:setflag");
  memory->create(cutsq, n + 1, n + 1, "pair:cutsq");
  for (int i = 1; i <= n; ++i)
    for (int j = i; j <= n; ++j) setflag[i][j] = 0;
}

void PairFiberDlvo::settings(int narg, char **arg) {
  fiberform::EngineConfig cfg;
  int iarg = 0;
  while (iarg < narg) {
    const int used = fiberform::parse_contact_keyword(lmp, "pair_style fiber/dlvo", cfg, iarg, narg, arg);
    if (used == 0)
      error->all(FLERR, fiberform::error_text(std::string("pair_style fiber/dlvo: unknown keyword '") + arg[iarg] +
                                              "' (see docs/styles/pair_fiber_dlvo.md)"));
    iarg += used;
  }
  fiberform::validate_contact_config(lmp, "pair_style fiber/dlvo", cfg);
  // fiber-fiber friction acts inside the clusters' Newton solve only (ClusterContactModel)
  if (cfg.friction != 0.0 && !cfg.implicit_newton)
    error->all(FLERR, "pair_style fiber/dlvo: friction between fibers needs implicit_force newton");
  if (cfg.friction_stick_set && !(cfg.friction > 0.0))
    error->all(FLERR, "pair_style fiber/dlvo: friction_stick acts with friction > 0 only");
  engine_->cfg = cfg;
  // the internal step fix exists from here on (so that thermo can name f_FIBER_DLVO_STEP[i])
  if (modify->find_fix(kStepFixId) < 0) {
    char id[] = "FIBER_DLVO_STEP", grp[] = "all", style[] = "fiber/dlvo/step";
    char *fixarg[3] = {id, grp, style};
    modify->add_fix(3, fixarg);
  }
}

void PairFiberDlvo::coeff(int narg, char **arg) {
  if (narg != 2) error->all(FLERR, "pair_coeff for fiber/dlvo: expected 'pair_coeff * *' (parameters are keywords of pair_style)");
  if (!allocated) allocate();
  int ilo, ihi, jlo, jhi;
  force->bounds(arg[0], atom->ntypes, ilo, ihi);
  force->bounds(arg[1], atom->ntypes, jlo, jhi);
  for (int i = ilo; i <= ihi; ++i)
    for (int j = (jlo > i ? jlo : i); j <= jhi; ++j) setflag[i][j] = 1;
}

void PairFiberDlvo::init_style() {
  fiberform::check_atom_layout(lmp);
  if (!force->newton_pair) error->all(FLERR, "pair_style fiber/dlvo requires 'newton on'");
  engine_->init();
  double max_len = 0, max_rad = 0;
  engine_->global_extents(max_len, max_rad);
  reach_ = engine_->reach(max_len, max_rad);
  const int irequest = neighbor->request(this);
  neighbor->requests[irequest]->half = 0;
  neighbor->requests[irequest]->full = 1;
  if (modify->find_fix(kStepFixId) < 0) error->all(FLERR, "pair_style fiber/dlvo: its internal fix FIBER_DLVO_STEP was deleted");
  step_fix_ = dynamic_cast<FiberContactFix *>(modify->fix[modify->find_fix(kStepFixId)]);
}

void PairFiberDlvo::init_list(int, NeighList *ptr) { list = ptr; }

double PairFiberDlvo::init_one(int i, int j) {
  if (setflag[i][j] == 0) error->all(FLERR, "pair_style fiber/dlvo: pair_coeff * * is missing");
  return reach_;
}

void PairFiberDlvo::compute(int eflag, int vflag) {
  if (eflag || vflag) ev_setup(eflag, vflag);
  else evflag = vflag_fdotr = 0;
  if (engine_->cfg.integrator != fiberform::IntegratorKind::None) return;  // the step fix applies them
  if (engine_->cfg.implicit_newton) return;  // inside the fibers' Newton solves (fix fiber/dlvo/step)
  // instantaneous forces (the classic explicit way); ghost contributions are summed by LIGGGHTS'
  // reverse communication (newton on)
  double **t = atom->torque_flag ? atom->torque : nullptr;
  engine_->pairs(list, update->dt, false, step_fix_->node_data(), {atom->f, nullptr, t, nullptr});
}
