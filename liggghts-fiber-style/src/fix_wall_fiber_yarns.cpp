/* SPDX-License-Identifier: GPL-3.0-or-later
   fix wall/fiber/yarns: see fix_wall_fiber_yarns.h and docs/styles/fix_wall_fiber_yarns.md. */
#include "fix_wall_fiber_yarns.h"

#include "style_args.h"

#include <mpi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>

#include "atom.h"
#include "comm.h"
#include "domain.h"
#include "error.h"
#include "fix_fiber_beam.h"
#include "modify.h"
#include "physics/contact_geometry.h"
#include "physics/friction.h"
#include "update.h"

using namespace LAMMPS_NS;
using namespace FixConst;
namespace phys = fiberform::physics;

namespace {
constexpr const char *kStyle = "fix wall/fiber/yarns";
}

FixWallFiberYarns::~FixWallFiberYarns() { FixFiberBeam::release_force_model(lmp, model_.get()); }

FixWallFiberYarns::FixWallFiberYarns(LAMMPS *lmp, int narg, char **arg)
    : FiberContactFix(lmp, narg, arg), own_engine_(new fiberform::ContactEngine(lmp)) {
  engine_ = own_engine_.get();
  size_vector = 6;
  fiberform::EngineConfig cfg;
  cfg.law.terms = phys::kSteric;  // the yarns' default terms
  cfg.implicit_newton = true;     // the yarns' default with implicit fibers
  cfg.implicit_impulse = true;    // (explicit fibers: always the impulse)
  int iarg = 3;
  bool have_yarns = false;
  while (iarg < narg) {
    const std::string kw = arg[iarg];
    if (kw == "yarns") {
      if (iarg + 1 >= narg) error->all(FLERR, "fix wall/fiber/yarns: yarns needs a file name");
      read_yarns(arg[iarg + 1]);
      have_yarns = true;
      iarg += 2;
      continue;
    }
    if (kw == "section" || kw == "up" || kw == "points" || kw == "self" || kw == "frozen")
      error->all(FLERR, fiberform::error_text(std::string(kStyle) + ": keyword '" + kw +
                                              "' is one of the fiber-fiber styles, not of the yarns"));
    if (kw == "s1_damping") s1_damping_kw_ = iarg + 1 < narg && !std::strcmp(arg[iarg + 1], "yes") ? 1 : 0;
    const int used = fiberform::parse_contact_keyword(lmp, kStyle, cfg, iarg, narg, arg);
    if (used == 0)
      error->all(FLERR, fiberform::error_text(std::string(kStyle) + ": unknown keyword '" + kw +
                                              "' (see docs/styles/fix_wall_fiber_yarns.md)"));
    iarg += used;
  }
  if (!have_yarns) error->all(FLERR, "fix wall/fiber/yarns: expected 'fix ID group wall/fiber/yarns yarns FILE ...'");
  if (cfg.integrator == fiberform::IntegratorKind::None)
    error->all(FLERR, "fix wall/fiber/yarns: integrator must be cvode or substep N");
  fiberform::validate_contact_config(lmp, kStyle, cfg);
  own_engine_->cfg = cfg;
  bodies_.build_bins(0.0);
}

void FixWallFiberYarns::read_yarns(const char *path) {
  std::istringstream in(fiberform::read_file_everywhere(lmp, std::string(kStyle) + ": yarns file", path));
  std::string line;
  int prev_yarn = -1;
  std::array<double, 3> prev{0, 0, 0};
  double prev_r = 0.0;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    int yarn;
    std::array<double, 3> p;
    double r;
    if (!(ls >> yarn)) continue;
    if (!(ls >> p[0] >> p[1] >> p[2] >> r) || !(r > 0.0))
      error->all(FLERR, fiberform::error_text(std::string(path) + ":" + std::to_string(lineno) +
                                              ": expected 'yarn-index x y z radius' with radius > 0"));
    if (yarn == prev_yarn) bodies_.add_segment({prev[0], prev[1], prev[2]}, {p[0], p[1], p[2]}, 0.5 * (prev_r + r), yarn);
    prev_yarn = yarn;
    prev = p;
    prev_r = r;
  }
  if (bodies_.segments().empty())
    error->all(FLERR, fiberform::error_text(std::string(kStyle) + ": no yarn segments in " + path));
}

int FixWallFiberYarns::setmask() { return POST_FORCE | END_OF_STEP; }

/* implicit_force position: land the velocities recorded in post_force (land_velocity), every step. */
void FixWallFiberYarns::end_of_step() {
  if (!(implicit_ && !impulse_ && !newton_) || land_.size() < 6 * static_cast<size_t>(atom->nlocal)) return;
  for (int i = 0; i < atom->nlocal; ++i) {
    for (int k = 0; k < 3; ++k) atom->v[i][k] += land_[6 * i + k];
    beam_->remove_from_history(i, &land_[6 * i + 3]);
  }
}

void FixWallFiberYarns::init() {
  FiberContactFix::init();
  if (!beam_) error->all(FLERR, "fix wall/fiber/yarns: needs a fix fiber/beam (fiber topology and sections)");
  const fiberform::EngineConfig &cfg = engine_->cfg;
  implicit_ = beam_->implicit();
  impulse_ = !implicit_ || cfg.implicit_impulse;
  newton_ = implicit_ && cfg.implicit_newton;
  // the PD form of eq. 2.35 inside the implicit step (docs/styles/fix_wall_fiber_yarns.md)
  own_engine_->cfg.law.steric.s1_damping = s1_damping_kw_ >= 0 ? s1_damping_kw_ == 1 : newton_;
  integ_.configure(cfg.integrator == fiberform::IntegratorKind::Cvode ? fiberform::ContactIntegrator::Method::Cvode
                                                                      : fiberform::ContactIntegrator::Method::Substep,
                   cfg.nsub, cfg.rtol, cfg.atol);
  beta_eff_ = implicit_ ? beam_->beta_eff() : 0.5;
  gamma_eff_ = implicit_ ? beam_->gamma_eff() : 1.0;  // explicit: stop the tangential motion over dt
  // bins must cover the elements: reach = largest fiber radius + longest element (local maxima)
  double loc[2] = {0.0, 0.0}, glob[2];
  for (int i = 0; i < atom->nlocal; ++i) {
    if (!(atom->mask[i] & groupbit) || !beam_->is_node(i)) continue;
    double rr[4];
    beam_->section_radii(i, rr);
    loc[0] = std::max(loc[0], std::max(rr[0], rr[1]));
    if (beam_->node_index(i) + 1 < beam_->node_count(i)) {
      const int j = beam_->neighbour(i, +1);
      if (j >= 0) {
        double d[3] = {atom->x[j][0] - atom->x[i][0], atom->x[j][1] - atom->x[i][1], atom->x[j][2] - atom->x[i][2]};
        domain->minimum_image(d);  // periodic x/y: at init no ghost image may exist yet
        double l2 = 0.0;
        for (int k = 0; k < 3; ++k) l2 += d[k] * d[k];
        loc[1] = std::max(loc[1], std::sqrt(l2));
      }
    }
  }
  MPI_Allreduce(loc, glob, 2, MPI_DOUBLE, MPI_MAX, world);
  bodies_.build_bins(glob[0] + law().h_cut + glob[1]);
  if (newton_ && !model_) model_ = std::make_unique<phys::StaticContactModel>(bodies_, law(), cfg.friction, cfg.friction_stick);
  beam_->use_force_model(model_.get(), newton_);
  // the contact force uses the other forces on the node: they must be summed before this fix (not
  // with newton: the contacts act inside the fiber's solve)
  bool after = false;
  for (int k = 0; k < modify->nfix && !newton_; ++k) {
    if (modify->fix[k] == this) after = true;
    else if (after && (modify->fmask[k] & POST_FORCE) && comm->me == 0)
      error->warning(FLERR, "fix wall/fiber/yarns: define it after the fixes that add forces (its contact "
                            "sub-integration uses the node's other forces)");
  }
}

void FixWallFiberYarns::setup(int vflag) { post_force(vflag); }

/* Implicit fibers: the constant force fc lands the contact point on the sub-integrated end position;
   its velocity then changed by gamma_eff dt fc / m instead of the sub-integrated dt fv / m. Record the
   impulse that makes up the difference (split by the lever rule: the point's velocity changes by
   exactly that amount) and fc itself, to be taken out of the scheme's history after the implicit
   solve (end_of_step), as the contact styles do (fiber_contact_fix.h). */
void FixWallFiberYarns::land_velocity(int i, int j, double wi, double wj, const double n[3], double fc, double fv) {
  const double J = update->dt * (fv - gamma_eff_ * fc);
  for (int k = 0; k < 3; ++k) {
    land_[6 * i + k] += wi * J * n[k] / atom->rmass[i];
    land_[6 * i + 3 + k] += wi * fc * n[k];
    if (j >= 0) {
      land_[6 * j + k] += wj * J * n[k] / atom->rmass[j];
      land_[6 * j + 3 + k] += wj * fc * n[k];
    }
  }
}

/* Distance node i may travel in one step (speed and the other forces held): contacts closer than the
   law's range plus this are sub-integrated, so that a large step cannot jump over the range. */
double FixWallFiberYarns::travel(int i) const {
  const double *v = atom->v[i], *f = atom->f[i];
  const double dt = update->dt, m = atom->rmass[i];
  const double sp = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  const double ac = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) / m;
  return 2.0 * (sp * dt + 0.5 * ac * dt * dt);
}

/* The normal motion of one contact point against a yarn over the step: the point (position p,
   velocity v, other forces per mass a, inverse mass inv_m) and the yarn's surface at gap h along the
   unit normal n (towards the point) as a plane pair of the contact integrator (CVODE or velocity-
   Verlet sub-steps, the same integrator and law as pair_style fiber/dlvo). Returns the normal
   components of the two averaged forces: fpos (2 m y / dt^2, eq. 2.22 with beta 1/2 minus m a) and
   fvel (m w / dt, the impulse). */
void FixWallFiberYarns::normal_solve(const double p[3], const double v[3], const double a[3], double inv_m,
                                     const double n[3], double h, double r1, double r2, double &fpos,
                                     double &fvel) {
  const phys::ContactLaw &L = law();
  phys::PairLaw pl;
  pl.setup(L, r1, r2, inv_m, 0.0, L.effective_potential(r1), L.effective_potential(r2));
  fiberform::PairGeometry g;
  g.plane = true;
  g.normal = {n[0], n[1], n[2]};
  g.offset = std::isfinite(r2) ? r1 + r2 : r1;
  fiberform::PointState s1, s2;
  s1.p = {p[0], p[1], p[2]};
  s1.v = {v[0], v[1], v[2]};
  s1.a = {a[0], a[1], a[2]};
  s1.inv_m = inv_m;
  const double back = h + g.offset;
  s2.p = {p[0] - back * n[0], p[1] - back * n[1], p[2] - back * n[2]};
  s2.inv_m = 0.0;
  const fiberform::PairResult r = integ_.solve(pl, g, s1, s2, update->dt);
  if (!r.ok) ++failures_;
  fpos = r.fpos1.x * n[0] + r.fpos1.y * n[1] + r.fpos1.z * n[2];
  fvel = r.fvel1.x * n[0] + r.fvel1.y * n[1] + r.fvel1.z * n[2];
}

/* The force applied over the step from the two averages: explicit fibers (velocity Verlet, half-step
   velocities): the impulse fvel; implicit fibers: eq. 2.22 with the scheme's beta_eff,
   fpos / (2 beta_eff), plus the velocity landing recorded for end_of_step. */
double FixWallFiberYarns::applied_force(double fpos, double fvel) const {
  return implicit_ && !impulse_ ? fpos / (2.0 * beta_eff_) : fvel;
}

/* One node (a single-node fiber) against a yarn, the other forces on the node held constant. */
void FixWallFiberYarns::apply_node_contact(int i, const double n[3], double h, double r1, double r2,
                                           double &gap_min) {
  double *v = atom->v[i], *f = atom->f[i];
  const double m = atom->rmass[i];
  const double dt = update->dt;
  const double u0 = v[0] * n[0] + v[1] * n[1] + v[2] * n[2];
  if (h + std::min(0.0, u0) * dt - std::fabs(u0) * dt >= law().h_cut && h >= law().h_cut) return;
  const double a[3] = {f[0] / m, f[1] / m, f[2] / m};
  const double inv_m = 1.0 / m;
  double fpos, fvel;
  normal_solve(atom->x[i], v, a, inv_m, n, h, r1, r2, fpos, fvel);
  const double fc = applied_force(fpos, fvel);
  for (int k = 0; k < 3; ++k) f[k] += fc * n[k];
  if (implicit_ && !impulse_) land_velocity(i, -1, 1.0, 0.0, n, fc, fvel);
  if (engine_->cfg.friction > 0.0 && fc > 0.0) apply_friction(i, -1, 0.0, n, fc);
  gap_min = std::min(gap_min, h);
}

/* One element (nodes i, j) against a yarn at the element point of parameter s (0: i, 1: j): the
   contact point's motion over the step with effective mass 1/m = (1-s)^2/m_i + s^2/m_j, the other
   forces on both nodes held constant; the average contact force is split by the lever rule
   ((1-s) to i, s to j: total force and torque about any point kept, thesis 2.4.2). */
void FixWallFiberYarns::apply_element_contact(int i, int j, double s, const double n[3], double h, double r1,
                                              double r2, double &gap_min) {
  double *vi = atom->v[i], *vj = atom->v[j], *fi = atom->f[i], *fj = atom->f[j];
  const double mi = atom->rmass[i], mj = atom->rmass[j];
  const double wi = 1.0 - s, wj = s;
  const double dt = update->dt;
  double u0 = 0.0, p[3], v[3], a[3];
  for (int k = 0; k < 3; ++k) {
    p[k] = wi * atom->x[i][k] + wj * atom->x[j][k];
    v[k] = wi * vi[k] + wj * vj[k];
    a[k] = wi * fi[k] / mi + wj * fj[k] / mj;
    u0 += v[k] * n[k];
  }
  if (h - 2.0 * std::fabs(u0) * dt >= law().h_cut) return;
  const double inv_m = phys::lever_inverse_mass(wi, mi, wj, mj);
  double fpos, fvel;
  normal_solve(p, v, a, inv_m, n, h, r1, r2, fpos, fvel);
  const double fc = applied_force(fpos, fvel);
  for (int k = 0; k < 3; ++k) {
    fi[k] += wi * fc * n[k];
    fj[k] += wj * fc * n[k];
  }
  if (implicit_ && !impulse_) land_velocity(i, j, wi, wj, n, fc, fvel);
  if (engine_->cfg.friction > 0.0 && fc > 0.0) apply_friction(i, j, s, n, fc);
  gap_min = std::min(gap_min, h);
}

/* Coulomb friction at a contact point (element i-j at parameter s, or node i when j < 0) against a
   yarn (physics/friction.h), split to the nodes by the lever rule. */
void FixWallFiberYarns::apply_friction(int i, int j, double s, const double n[3], double fn) {
  const double dt = update->dt;
  const double wi = j < 0 ? 1.0 : 1.0 - s, wj = j < 0 ? 0.0 : s;
  const double mi = atom->rmass[i], mj = j < 0 ? 1.0 : atom->rmass[j];
  const double *vi = atom->v[i], *fi = atom->f[i];
  const double *vj = j < 0 ? vi : atom->v[j], *fj = j < 0 ? fi : atom->f[j];
  const double inv_m = j < 0 ? phys::lever_inverse_mass(wi, mi) : phys::lever_inverse_mass(wi, mi, wj, mj);
  double vt[3], at[3], ft[3];
  for (int k = 0; k < 3; ++k) {
    vt[k] = wi * vi[k] + wj * vj[k];
    at[k] = wi * fi[k] / mi + (j < 0 ? 0.0 : wj * fj[k] / mj);
  }
  const double scale = phys::coulomb_stick_slip(vt, at, n, inv_m, gamma_eff_ * dt, engine_->cfg.friction * fn, ft);
  for (int k = 0; k < 3; ++k) {
    atom->f[i][k] += wi * scale * ft[k];
    if (j >= 0) atom->f[j][k] += wj * scale * ft[k];
  }
}

/* Element i-j against the yarns: per yarn, the segment with the smallest separation between the
   element's centre line and the yarn's centre line (physics/static_bodies.h) acts. */
void FixWallFiberYarns::element_yarn_contacts(int i, int j, double r1, double &gap_min) {
  double **x = atom->x;
  double vmax2 = 0.0;
  for (int k = 0; k < 3; ++k) vmax2 = std::max(vmax2, std::max(atom->v[i][k] * atom->v[i][k], atom->v[j][k] * atom->v[j][k]));
  const double margin = law().h_cut + 1e-3 * r1 + 4.0 * std::sqrt(3.0 * vmax2) * update->dt;
  phys::BodyHit hits[phys::StaticBodies::kMaxHits];
  const int nh = bodies_.element_hits({x[i][0], x[i][1], x[i][2]}, {x[j][0], x[j][1], x[j][2]}, r1, margin, hits);
  for (int b = 0; b < nh; ++b) {
    local_[0] += 1.0;
    const double n[3] = {hits[b].n.x, hits[b].n.y, hits[b].n.z};
    apply_element_contact(i, j, hits[b].s, n, hits[b].h, r1, hits[b].r2, gap_min);
  }
}

void FixWallFiberYarns::node_yarn_contacts(int i, double r1, double &gap_min) {
  double **x = atom->x;
  phys::BodyHit hits[phys::StaticBodies::kMaxHits];
  const int nh = bodies_.node_hits({x[i][0], x[i][1], x[i][2]}, r1, law().h_cut + 1e-3 * r1 + travel(i), hits);
  for (int b = 0; b < nh; ++b) {
    local_[0] += 1.0;
    const double n[3] = {hits[b].n.x, hits[b].n.y, hits[b].n.z};
    apply_node_contact(i, n, hits[b].h, r1, hits[b].r2, gap_min);
  }
}

/* implicit_force newton: the contacts act inside the fibers' Newton solves (registered with fix
   fiber/beam); here only the diagnostics at the current state: contacts within h_cut and the
   smallest gap. Elements whose second node is a ghost are seen too. */
void FixWallFiberYarns::scan_contacts() {
  const int nlocal = atom->nlocal;
  double **x = atom->x;
  double gap_min = std::numeric_limits<double>::max();
  phys::BodyHit hits[phys::StaticBodies::kMaxHits];
  // the contact section of node k as the Newton solve sees it (fix fiber/beam: circle or rectangle)
  auto section = [&](int k) {
    phys::rod::Node nd;
    nd.x = {x[k][0], x[k][1], x[k][2]};
    const double *q = beam_->quaternion(k);
    nd.q = {q[0], q[1], q[2], q[3]};
    nd.radius = beam_->contact_radius(k);
    if (beam_->contact_rect(k)) {
      double rr[4];
      beam_->section_radii(k, rr);
      nd.rect[0] = rr[0];
      nd.rect[1] = rr[1];
    }
    return nd;
  };
  for (int i = 0; i < nlocal; ++i) {
    if (!(atom->mask[i] & groupbit) || !beam_->is_node(i)) continue;
    const phys::rod::Node a = section(i);
    int nh = 0;
    if (beam_->node_count(i) > 1) {
      if (beam_->node_index(i) + 1 >= beam_->node_count(i)) continue;
      const int j = beam_->neighbour(i, +1);  // periodic x/y: the image next to node i
      if (j < 0) continue;  // not present here (fix fiber/beam's ghost cut-off covers an element)
      const phys::rod::Node b = section(j);
      const double r = phys::element_reach(a, b);
      nh = bodies_.element_hits(a.x, b.x, r, law().h_cut + r, hits);
      for (int k = 0; k < nh; ++k) hits[k].h += r - phys::element_extent(a, b, hits[k].n);
    } else {
      const double r = phys::section_reach(a);
      nh = bodies_.node_hits(a.x, r, law().h_cut + r, hits);
      for (int k = 0; k < nh; ++k) hits[k].h += r - phys::node_extent(a, hits[k].n);
    }
    for (int b = 0; b < nh; ++b) {
      if (hits[b].h >= law().h_cut) continue;
      local_[0] += 1.0;
      gap_min = std::min(gap_min, hits[b].h);
    }
  }
  local_[1] = -gap_min;
}

void FixWallFiberYarns::post_force(int) {
  const int nlocal = atom->nlocal;
  int *mask = atom->mask;
  local_[0] = 0.0;
  sums_valid_ = false;
  if (newton_) {
    scan_contacts();
    // the yarns' total force on the fibers at the end of the last step (their converged Newton
    // states), summed over the fibers this rank solved
    double gap = 0.0;
    const phys::Vec3 t = model_->take_total(gap);
    local_force_[0] = t.x;
    local_force_[1] = t.y;
    local_force_[2] = t.z;
    return;
  }
  double gap_min = std::numeric_limits<double>::max();
  if (implicit_ && !impulse_) land_.assign(6 * static_cast<size_t>(nlocal), 0.0);
  for (int i = 0; i < nlocal; ++i) {
    if (!(mask[i] & groupbit) || !beam_->is_node(i)) continue;
    double rr[4];
    beam_->section_radii(i, rr);
    const double r1 = std::max(rr[0], rr[1]);
    if (beam_->node_count(i) > 1) {
      // element to the next node (owned by this node); a fiber's elements cover its nodes
      if (beam_->node_index(i) + 1 >= beam_->node_count(i)) continue;
      const int j = beam_->neighbour(i, +1);  // periodic x/y: the image next to node i
      if (j < 0 || j >= nlocal)
        fiberform::fail_one(lmp, FLERR, "fix wall/fiber/yarns: the next node of an element is not owned by this "
                          "rank (implicit_force impulse|position runs the element contact on one rank only and "
                          "without periodic x/y; implicit_force newton runs on any number and with periodic x/y)");
      double rj[4];
      beam_->section_radii(j, rj);
      element_yarn_contacts(i, j, std::max(r1, std::max(rj[0], rj[1])), gap_min);
      continue;
    }
    node_yarn_contacts(i, r1, gap_min);
  }
  local_[1] = -gap_min;
}

/* 1 contact points within range of a yarn (last step, all ranks), 2 failed sub-integrations (this
   run, all ranks), 3 smallest gap element-yarn (m; < 0: overlap), 4-6 the yarns' contact force on
   the fibers (N; implicit_force newton, else 0). */
double FixWallFiberYarns::compute_vector(int n) {
  if (n == 1) {
    double all = 0.0;
    MPI_Allreduce(&failures_, &all, 1, MPI_DOUBLE, MPI_SUM, world);
    return all;
  }
  if (!sums_valid_) {
    MPI_Allreduce(&local_[0], &sums_[0], 1, MPI_DOUBLE, MPI_SUM, world);
    MPI_Allreduce(&local_[1], &sums_[1], 1, MPI_DOUBLE, MPI_MAX, world);
    MPI_Allreduce(local_force_, force_, 3, MPI_DOUBLE, MPI_SUM, world);
    sums_valid_ = true;
  }
  if (n == 0) return sums_[0];
  if (n == 2) return -sums_[1];
  return force_[n - 3];
}
