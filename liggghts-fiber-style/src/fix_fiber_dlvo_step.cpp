/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "fix_fiber_dlvo_step.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>

#include "atom.h"
#include "comm.h"
#include "domain.h"
#include "error.h"
#include "fix_fiber_beam.h"
#include "force.h"
#include "modify.h"
#include "pair_fiber_dlvo.h"
#include "update.h"

using namespace LAMMPS_NS;
namespace phys = fiberform::physics;

FixFiberDlvoStep::FixFiberDlvoStep(LAMMPS *lmp, int narg, char **arg) : FiberContactFix(lmp, narg, arg) {
  if (narg != 3) error->all(FLERR, "fix fiber/dlvo/step is internal (created by pair_style fiber/dlvo)");
  find_pair();
}

FixFiberDlvoStep::~FixFiberDlvoStep() { FixFiberBeam::release_force_model(lmp, model_.get()); }

void FixFiberDlvoStep::find_pair() {
  pair_ = dynamic_cast<PairFiberDlvo *>(force->pair);
  if (!pair_) error->all(FLERR, "fix fiber/dlvo/step needs pair_style fiber/dlvo (it is internal to it)");
  engine_ = &pair_->engine();
}

void FixFiberDlvoStep::init() {
  find_pair();
  FiberContactFix::init();
  const fiberform::EngineConfig &cfg = engine_->cfg;
  newton_ = implicit_beam() && cfg.implicit_newton;
  if (cfg.implicit_newton && !implicit_beam())
    error->all(FLERR, "pair_style fiber/dlvo: implicit_force newton needs fix fiber/beam integrator implicit");
  if (newton_ && (cfg.self_contact || cfg.frozen_groupbit || cfg.section != fiberform::Section::Circle))
    error->all(FLERR, "pair_style fiber/dlvo: implicit_force newton supports circular sections (the larger "
                      "half-axis of fix fiber/beam's section), no self_contact (keyword self) and no frozen group yet");
  // newton: the candidate margin of the fiber pairs takes every node's force per mass from f at
  // post_force, so the drag and gravity of fix fiber/drag must be in it: that fix comes first
  bool after = false;
  for (int k = 0; k < modify->nfix && newton_; ++k) {
    if (modify->fix[k] == this) after = true;
    else if (after && !std::strcmp(modify->fix[k]->style, "fiber/drag"))
      error->all(FLERR, "pair_style fiber/dlvo implicit_force newton: define fix fiber/drag before pair_style "
                        "fiber/dlvo (the fiber pairs' candidate margin needs the drag in the node forces)");
  }
  if (newton_ && !model_) {
    newton_law_ = cfg.law;
    newton_law_.steric.s1_damping = true;  // the PD servo, as the static bodies (docs/models/contact.md 8)
    model_ = std::make_unique<phys::ClusterContactModel>(partners_, newton_law_, cfg.friction, cfg.friction_stick);
  }
  if (beam_) beam_->use_force_model(model_.get(), newton_);
}

double FixFiberDlvoStep::interaction_reach() { return pair_->reach(); }

void FixFiberDlvoStep::accumulate(bool subintegrate, const fiberform::NodeData &nd, const fiberform::NodeSinks &out) {
  engine_->pairs(pair_->neigh_list(), update->dt, subintegrate, nd, out);
}

void FixFiberDlvoStep::post_force(int vflag) {
  if (!newton_) {
    FiberContactFix::post_force(vflag);
    return;
  }
  gather_partners();
}

/* implicit_force newton: the start-of-step state of every fiber node, on every rank (nothing has
   moved yet: the implicit step runs in final_integrate). Cost O(all nodes) per rank and step: the
   simple, decomposition-independent choice; docs/models/contact.md section 9 states the limit. */
namespace {
enum GatherCol { G_FID = 0, G_IDX, G_X, G_V = G_X + 3, G_M = G_V + 3, G_R, G_A, G_N };
}

void FixFiberDlvoStep::gather_partners() {
  mine_.clear();
  for (int i = 0; i < atom->nlocal; ++i) {
    if (!beam_->is_node(i)) continue;
    const double rec[G_N] = {static_cast<double>(beam_->fiber_id(i)), static_cast<double>(beam_->node_index(i)),
                             atom->x[i][0], atom->x[i][1], atom->x[i][2], atom->v[i][0], atom->v[i][1],
                             atom->v[i][2], atom->rmass[i], beam_->contact_reach(i),
                             std::sqrt(atom->f[i][0] * atom->f[i][0] + atom->f[i][1] * atom->f[i][1] +
                                       atom->f[i][2] * atom->f[i][2]) / atom->rmass[i]};
    mine_.insert(mine_.end(), rec, rec + G_N);
  }
  const int nprocs = comm->nprocs;
  int n = static_cast<int>(mine_.size());
  std::vector<int> counts(static_cast<size_t>(nprocs)), displs(static_cast<size_t>(nprocs), 0);
  MPI_Allgather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, world);
  for (int r = 1; r < nprocs; ++r) displs[r] = displs[r - 1] + counts[r - 1];
  all_.resize(static_cast<size_t>(displs[nprocs - 1] + counts[nprocs - 1]));
  MPI_Allgatherv(mine_.data(), n, MPI_DOUBLE, all_.data(), counts.data(), displs.data(), MPI_DOUBLE, world);

  // fibers by id, nodes in order (the same on every rank whatever the decomposition)
  std::map<int, std::map<int, const double *>> fibers;
  for (size_t o = 0; o + G_N <= all_.size(); o += G_N)
    fibers[static_cast<int>(all_[o + G_FID])][static_cast<int>(all_[o + G_IDX])] = &all_[o];
  partners_.clear();
  const double L[3] = {domain->xperiodic ? domain->xprd : 0.0, domain->yperiodic ? domain->yprd : 0.0,
                       domain->zperiodic ? domain->zprd : 0.0};
  partners_.set_periods(L[0], L[1], L[2]);
  double vmax = 0.0, amax = 0.0;
  std::vector<phys::FiberPartners::Point> pts;
  for (const auto &f : fibers) {
    pts.clear();
    for (const auto &nd : f.second) {
      const double *b = nd.second;
      phys::FiberPartners::Point p;
      p.x = {b[G_X], b[G_X + 1], b[G_X + 2]};
      if (!pts.empty()) {  // unwrap: each node next to the previous one (as fix fiber/beam does)
        double d[3] = {p.x.x - pts.back().x.x, p.x.y - pts.back().x.y, p.x.z - pts.back().x.z};
        domain->minimum_image(d);
        p.x = pts.back().x + phys::Vec3{d[0], d[1], d[2]};
      }
      p.v = {b[G_V], b[G_V + 1], b[G_V + 2]};
      p.m = b[G_M];
      p.radius = b[G_R];
      vmax = std::max(vmax, phys::norm(p.v));
      amax = std::max(amax, b[G_A]);
      pts.push_back(p);
    }
    partners_.add_fiber(f.first, pts);
  }
  const phys::Vec3 lo{domain->boxlo[0], domain->boxlo[1], domain->boxlo[2]};
  const phys::Vec3 hi{domain->boxhi[0], domain->boxhi[1], domain->boxhi[2]};
  // every force but the contacts' is in f here (this fix comes last: it is created by pair_style)
  partners_.build(lo, hi, phys::candidate_margin(newton_law_, update->dt, vmax, amax));
  int maxid = -1;
  for (int i = 0; i < partners_.fiber_count(); ++i) maxid = std::max(maxid, partners_.fiber(i).id);
  std::vector<int> cluster(static_cast<size_t>(maxid + 1), -1);
  for (int i = 0; i < partners_.fiber_count(); ++i)
    cluster[partners_.fiber(i).id] = partners_.fiber(partners_.cluster(i)).id;
  beam_->set_clusters(std::move(cluster));
}

double FixFiberDlvoStep::compute_vector(int n) {
  if (!newton_) return FiberContactFix::compute_vector(n);
  if (n == 5) {  // smallest surface gap of the candidate pairs at the start of the step (m)
    const double g = partners_.fiber_count() ? partners_.min_gap() : 1.0;
    return std::isfinite(g) ? g : 1.0;  // the gather is global: every rank has the same value
  }
  return 0.0;  // no sub-integration in newton mode
}
