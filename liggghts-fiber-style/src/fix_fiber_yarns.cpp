/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/yarns: see fix_fiber_yarns.h and docs/styles/fix_fiber_yarns.md. */
#include "fix_fiber_yarns.h"

#include "style_args.h"

#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <string>

#include "atom.h"
#include "atom_vec.h"
#include "comm.h"
#include "error.h"
#include "fix_fiber_beam.h"
#include "physics/settle.h"
#include "physics/contact_geometry.h"
#include "modify.h"
#include "update.h"

using namespace LAMMPS_NS;
using namespace FixConst;
namespace phys = fiberform::physics;


FixFiberYarns::~FixFiberYarns() { FixFiberBeam::release_force_model(lmp, model_.get()); }

FixFiberYarns::FixFiberYarns(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg) {
  vector_flag = 1;
  size_vector = 11;
  restart_global = 1;  // removal accounting and the settle counter survive a restart
  global_freq = 1;
  extvector = 0;
  law_.terms = phys::kSteric;
  int iarg = 3;
  while (iarg < narg) {
    const std::string kw = arg[iarg];
    auto need = [&](int n) {
      if (iarg + n >= narg)
        error->all(FLERR, fiberform::error_text("fix fiber/yarns: " + kw + " needs " + std::to_string(n) + " value(s)"));
    };
    auto val = [&](int k) { return fiberform::parse_finite(error, "fix fiber/yarns", kw, arg[iarg + k]); };
    if (kw == "yarns") {
      need(1);
      read_yarns(arg[iarg + 1]);
      iarg += 2;
    } else if (kw == "plane") {
      need(6);
      if (!bodies_.add_plane({val(1), val(2), val(3)}, {val(4), val(5), val(6)}))
        error->all(FLERR, "fix fiber/yarns: plane normal must not be zero");
      iarg += 7;
    } else if (kw == "remove_below") {
      need(1);
      remove_ = true;
      remove_z_ = val(1);
      iarg += 2;
    } else if (kw == "remove_every") {
      need(1);
      remove_every_ = static_cast<int>(val(1));
      if (remove_every_ < 1) error->all(FLERR, "fix fiber/yarns: remove_every must be >= 1");
      iarg += 2;
    } else if (kw == "settle") {
      need(2);
      settle_speed_ = val(1);
      nevery = static_cast<int>(val(2));
      if (!(settle_speed_ > 0.0) || nevery < 1) error->all(FLERR, "fix fiber/yarns: settle needs V > 0 and M >= 1");
      iarg += 3;
    } else if (kw == "implicit_force") {
      need(1);
      const std::string m = arg[iarg + 1];
      newton_kw_ = m == "newton";
      if (m == "impulse") impulse_kw_ = true;
      else if (m == "position") impulse_kw_ = false;
      else if (m != "newton") error->all(FLERR, "fix fiber/yarns: implicit_force must be newton, impulse or position");
      iarg += 2;
    } else if (kw == "integrator") {
      need(1);
      const std::string m = arg[iarg + 1];
      if (m == "cvode") use_cvode_ = true;
      else if (m == "substep") use_cvode_ = false;
      else error->all(FLERR, "fix fiber/yarns: integrator must be cvode or substep");
      iarg += 2;
    } else if (kw == "substeps") {
      need(1);
      substeps_ = static_cast<int>(val(1));
      if (substeps_ < 1) error->all(FLERR, "fix fiber/yarns: substeps must be >= 1");
      iarg += 2;
    } else if (kw == "settle_mass_fraction") {
      need(1);
      settle_fraction_ = val(1);
      if (!(settle_fraction_ > 0.0 && settle_fraction_ <= 1.0))
        error->all(FLERR, "fix fiber/yarns: settle_mass_fraction must be in (0, 1]");
      iarg += 2;
    } else if (kw == "settle_measure") {
      need(1);
      const std::string m = arg[iarg + 1];
      if (m == "node") settle_fiber_ = false;
      else if (m == "fiber") settle_fiber_ = true;
      else error->all(FLERR, "fix fiber/yarns: settle_measure must be node or fiber");
      iarg += 2;
    } else if (kw == "s1_damping") {
      need(1);
      const std::string m = arg[iarg + 1];
      if (m == "yes") s1_damping_kw_ = 1;
      else if (m == "no") s1_damping_kw_ = 0;
      else error->all(FLERR, "fix fiber/yarns: s1_damping must be yes or no");
      iarg += 2;
    } else if (kw == "friction") {
      need(1);
      mu_ = val(1);
      if (!(mu_ >= 0.0)) error->all(FLERR, "fix fiber/yarns: friction must be >= 0");
      iarg += 2;
    } else if (kw == "terms") {
      need(1);
      unsigned t = 0;
      std::stringstream ss(arg[iarg + 1]);
      std::string item;
      while (std::getline(ss, item, ',')) {
        if (item == "vdw") t |= phys::kVdw;
        else if (item == "es") t |= phys::kEs;
        else if (item == "steric") t |= phys::kSteric;
        else if (item != "none") error->all(FLERR, fiberform::error_text("fix fiber/yarns: terms: unknown term '" + item + "'"));
      }
      law_.terms = t;
      iarg += 2;
    } else if (kw == "hamaker") { need(1); law_.hamaker = val(1); iarg += 2; }
    else if (kw == "psi") { need(1); law_.psi_d = val(1); iarg += 2; }
    else if (kw == "ionic_strength") { need(1); law_.ionic_strength = val(1); iarg += 2; }
    else if (kw == "temperature") { need(1); law_.temperature = val(1); iarg += 2; }
    else if (kw == "eps_r") { need(1); law_.eps_r = val(1); iarg += 2; }
    else if (kw == "h0") { need(1); law_.h0 = law_.steric.h0 = val(1); iarg += 2; }
    else if (kw == "h_cut") { need(1); law_.h_cut = val(1); iarg += 2; }
    else if (kw == "h_R") { need(1); law_.steric.h_R = val(1); iarg += 2; }
    else if (kw == "h_S") { need(1); law_.steric.h_S = val(1); iarg += 2; }
    else if (kw == "t_R") { need(1); law_.steric.t_R = val(1); iarg += 2; }
    else {
      error->all(FLERR, fiberform::error_text("fix fiber/yarns: unknown keyword '" + kw + "'"));
    }
  }
  if (!(law_.steric.h_R > 0.0 && law_.steric.h_R < law_.h0))
    error->all(FLERR, "fix fiber/yarns: need 0 < h_R < h0");
  if (!(law_.h_cut > law_.h0)) error->all(FLERR, "fix fiber/yarns: need h_cut > h0");
  if (remove_) {
    force_reneighbor = 1;
    next_reneighbor = (update->ntimestep / remove_every_) * remove_every_ + remove_every_;
  }
  bodies_.build_bins(0.0);
}

void FixFiberYarns::read_yarns(const char *path) {
  std::ifstream in(path);
  if (!in) error->all(FLERR, fiberform::error_text(std::string("fix fiber/yarns: cannot open yarns file ") + path));
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
  if (bodies_.segments().empty()) error->all(FLERR, fiberform::error_text(std::string("fix fiber/yarns: no yarn segments in ") + path));
}

int FixFiberYarns::setmask() { return POST_FORCE | PRE_EXCHANGE | END_OF_STEP; }

void FixFiberYarns::end_of_step() {
  if (implicit_ && !impulse_ && !newton_ && land_.size() >= 6 * static_cast<size_t>(atom->nlocal)) {
    for (int i = 0; i < atom->nlocal; ++i) {
      for (int k = 0; k < 3; ++k) atom->v[i][k] += land_[6 * i + k];
      beam_->remove_from_history(i, &land_[6 * i + 3]);
    }
  }
  if (!(settle_speed_ > 0.0)) return;
  double vmax = 0.0;
  if (settle_fiber_) {
    // centre-of-mass velocity of each fiber: sums of m v and m by fiber ID over all ranks
    int idmax = -1, gidmax = -1;
    for (int i = 0; i < atom->nlocal; ++i)
      if ((atom->mask[i] & groupbit) && beam_->is_node(i)) idmax = std::max(idmax, beam_->fiber_id(i));
    MPI_Allreduce(&idmax, &gidmax, 1, MPI_INT, MPI_MAX, world);
    if (gidmax >= 0) {
      std::vector<double> loc(4 * static_cast<size_t>(gidmax + 1), 0.0), glob(loc.size());
      for (int i = 0; i < atom->nlocal; ++i) {
        if (!(atom->mask[i] & groupbit) || !beam_->is_node(i)) continue;
        double *row = &loc[4 * static_cast<size_t>(beam_->fiber_id(i))];
        const double m = atom->rmass[i];
        for (int k = 0; k < 3; ++k) row[k] += m * atom->v[i][k];
        row[3] += m;
      }
      MPI_Allreduce(loc.data(), glob.data(), static_cast<int>(loc.size()), MPI_DOUBLE, MPI_SUM, world);
      std::vector<double> speed, mass;
      for (size_t f = 0; f + 3 < glob.size(); f += 4)
        if (glob[f + 3] > 0.0) {
          speed.push_back(std::sqrt(glob[f] * glob[f] + glob[f + 1] * glob[f + 1] + glob[f + 2] * glob[f + 2]) /
                          glob[f + 3]);
          mass.push_back(glob[f + 3]);
        }
      vmax = fiberform::physics::mass_fraction_speed(speed, mass, settle_fraction_);
    }
    max_speed_ = vmax;
  } else {
    for (int i = 0; i < atom->nlocal; ++i) {
      if (!(atom->mask[i] & groupbit)) continue;
      const double *v = atom->v[i];
      vmax = std::max(vmax, v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    }
    MPI_Allreduce(&vmax, &max_speed_, 1, MPI_DOUBLE, MPI_MAX, world);
    max_speed_ = std::sqrt(max_speed_);
  }
  settled_checks_ = max_speed_ < settle_speed_ ? settled_checks_ + 1.0 : 0.0;
}

void FixFiberYarns::init() {
  if (settle_fraction_ < 1.0 && !settle_fiber_)
    error->all(FLERR, "fix fiber/yarns: settle_mass_fraction needs settle_measure fiber");
  beam_ = FixFiberBeam::find(lmp);
  if (!beam_) error->all(FLERR, "fix fiber/yarns: needs a fix fiber/beam (fiber topology and sections)");
  implicit_ = beam_->implicit();
  impulse_ = !implicit_ || impulse_kw_;
  newton_ = implicit_ && newton_kw_;
  // the PD form of eq. 2.35 inside the implicit step (docs/styles/fix_fiber_yarns.md)
  law_.steric.s1_damping = s1_damping_kw_ >= 0 ? s1_damping_kw_ == 1 : newton_;
  integ_.configure(use_cvode_ ? fiberform::ContactIntegrator::Method::Cvode : fiberform::ContactIntegrator::Method::Substep,
                   substeps_, 1e-6, 1e-13);
  beta_eff_ = implicit_ ? beam_->beta_eff() : 0.5;
  gamma_eff_ = implicit_ ? beam_->gamma_eff() : 1.0;  // explicit: stop the tangential motion over dt
  if (!atom->rmass_flag) error->all(FLERR, "fix fiber/yarns: needs per-atom mass (atom_style sphere)");
  if (!atom->map_style) error->all(FLERR, "fix fiber/yarns: needs atom_modify map array (element contact)");
  // bins must cover the elements: reach = largest fiber radius + longest element (local maxima)
  double loc[2] = {0.0, 0.0}, glob[2];
  for (int i = 0; i < atom->nlocal; ++i) {
    if (!(atom->mask[i] & groupbit) || !beam_->is_node(i)) continue;
    double rr[4];
    beam_->section_radii(i, rr);
    loc[0] = std::max(loc[0], std::max(rr[0], rr[1]));
    if (beam_->node_index(i) + 1 < beam_->node_count(i)) {
      const int j = atom->map(atom->tag[i] + 1);
      if (j >= 0) {
        double l2 = 0.0;
        for (int k = 0; k < 3; ++k) l2 += (atom->x[j][k] - atom->x[i][k]) * (atom->x[j][k] - atom->x[i][k]);
        loc[1] = std::max(loc[1], std::sqrt(l2));
      }
    }
  }
  MPI_Allreduce(loc, glob, 2, MPI_DOUBLE, MPI_MAX, world);
  bodies_.build_bins(glob[0] + law_.h_cut + glob[1]);
  if (newton_ && !model_) model_ = std::make_unique<phys::StaticContactModel>(bodies_, law_, mu_);
  beam_->use_force_model(model_.get(), newton_);
  // the contact force uses the other forces on the node: they must be summed before this fix
  bool after = newton_;  // (not with newton: the contacts act inside the fiber's solve)
  for (int k = 0; k < modify->nfix; ++k) {
    if (modify->fix[k] == this) after = true;
    else if (after && (modify->fmask[k] & POST_FORCE) && comm->me == 0)
      error->warning(FLERR, "fix fiber/yarns: define it after the fixes that add forces (its contact "
                            "sub-integration uses the node's other forces)");
  }
}

void FixFiberYarns::setup(int vflag) { post_force(vflag); }


/* Implicit fibers: the constant force fc lands the contact point on the sub-integrated end position;
   its velocity then changed by gamma_eff dt fc / m instead of the sub-integrated dt fv / m. Record the
   impulse that makes up the difference (split by the lever rule: the point's velocity changes by
   exactly that amount) and fc itself, to be taken out of the scheme's history after the implicit
   solve (end_of_step), as the contact styles do (fiber_contact_fix.h). */
void FixFiberYarns::land_velocity(int i, int j, double wi, double wj, const double n[3], double fc, double fv,
                                  double inv_m) {
  (void)inv_m;
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
double FixFiberYarns::travel(int i) const {
  const double *v = atom->v[i], *f = atom->f[i];
  const double dt = update->dt, m = atom->rmass[i];
  const double sp = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  const double ac = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) / m;
  return 2.0 * (sp * dt + 0.5 * ac * dt * dt);
}

/* The normal motion of one contact point against a static body over the step: the point (position p,
   velocity v, other forces per mass a, inverse mass inv_m) and the body's surface at gap h along the
   unit normal n (towards the point) as a plane pair of the contact integrator (CVODE or velocity-
   Verlet sub-steps, the same integrator and law as pair_style fiber/dlvo). Returns the normal
   components of the two averaged forces: fpos (2 m y / dt^2, eq. 2.22 with beta 1/2 minus m a) and
   fvel (m w / dt, the impulse). */
void FixFiberYarns::normal_solve(const double p[3], const double v[3], const double a[3], double inv_m,
                                 const double n[3], double h, double r1, double r2, double &fpos, double &fvel) {
  phys::PairLaw pl;
  pl.setup(law_, r1, r2, inv_m, 0.0, law_.effective_potential(r1), law_.effective_potential(r2));
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
   velocities): the impulse fvel, as before; implicit fibers: eq. 2.22 with the scheme's beta_eff,
   fpos / (2 beta_eff), plus the velocity landing recorded for end_of_step. */
double FixFiberYarns::applied_force(double fpos, double fvel) const {
  return implicit_ && !impulse_ ? fpos / (2.0 * beta_eff_) : fvel;
}

/* One node against a static body (plane or yarn), the other forces on the node held constant. */
void FixFiberYarns::apply_contact(int i, const double n[3], double h, double r1, double r2, double &gap_min) {
  double *v = atom->v[i], *f = atom->f[i];
  const double m = atom->rmass[i];
  const double dt = update->dt;
  const double u0 = v[0] * n[0] + v[1] * n[1] + v[2] * n[2];
  if (h + std::min(0.0, u0) * dt - std::fabs(u0) * dt >= law_.h_cut && h >= law_.h_cut) return;
  const double a[3] = {f[0] / m, f[1] / m, f[2] / m};
  const double inv_m = 1.0 / m;
  double fpos, fvel;
  normal_solve(atom->x[i], v, a, inv_m, n, h, r1, r2, fpos, fvel);
  const double fc = applied_force(fpos, fvel);
  for (int k = 0; k < 3; ++k) f[k] += fc * n[k];
  if (implicit_ && !impulse_) land_velocity(i, -1, 1.0, 0.0, n, fc, fvel, inv_m);
  if (mu_ > 0.0 && fc > 0.0) apply_friction(i, -1, 0.0, n, fc);
  gap_min = std::min(gap_min, h);
}

/* One element (nodes i, j) against a static body at the element point of parameter s (0: i, 1: j):
   the contact point's motion over the step with effective mass 1/m = (1-s)^2/m_i + s^2/m_j, the
   other forces on both nodes held constant; the average contact force is split by the lever rule
   ((1-s) to i, s to j: total force and torque about any point kept, thesis 2.4.2). */
void FixFiberYarns::apply_element_contact(int i, int j, double s, const double n[3], double h, double r1,
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
  if (h - 2.0 * std::fabs(u0) * dt >= law_.h_cut) return;
  const double inv_m = wi * wi / mi + wj * wj / mj;
  double fpos, fvel;
  normal_solve(p, v, a, inv_m, n, h, r1, r2, fpos, fvel);
  const double fc = applied_force(fpos, fvel);
  for (int k = 0; k < 3; ++k) {
    fi[k] += wi * fc * n[k];
    fj[k] += wj * fc * n[k];
  }
  if (implicit_ && !impulse_) land_velocity(i, j, wi, wj, n, fc, fvel, inv_m);
  if (mu_ > 0.0 && fc > 0.0) apply_friction(i, j, s, n, fc);
  gap_min = std::min(gap_min, h);
}

/* Coulomb friction at a contact point (element i-j at parameter s, or node i when j < 0) against a
   static body, at the velocity level: the tangential force that would stop the point's tangential
   motion over the next step (cancelling its other tangential forces) is applied if it is within
   mu * fn (stick), else mu * fn along it (slip). Split to the nodes by the lever rule. */
void FixFiberYarns::apply_friction(int i, int j, double s, const double n[3], double fn) {
  const double dt = update->dt;
  const double wi = j < 0 ? 1.0 : 1.0 - s, wj = j < 0 ? 0.0 : s;
  const double mi = atom->rmass[i], mj = j < 0 ? 1.0 : atom->rmass[j];
  const double *vi = atom->v[i], *fi = atom->f[i];
  const double *vj = j < 0 ? vi : atom->v[j], *fj = j < 0 ? fi : atom->f[j];
  const double inv_m = wi * wi / mi + (j < 0 ? 0.0 : wj * wj / mj);
  double vt[3], at[3], vn = 0.0, an = 0.0;
  for (int k = 0; k < 3; ++k) {
    vt[k] = wi * vi[k] + wj * vj[k];
    at[k] = wi * fi[k] / mi + (j < 0 ? 0.0 : wj * fj[k] / mj);
    vn += vt[k] * n[k];
    an += at[k] * n[k];
  }
  double ft[3], ft2 = 0.0;
  for (int k = 0; k < 3; ++k) {
    ft[k] = -((vt[k] - vn * n[k]) / (gamma_eff_ * dt) + (at[k] - an * n[k])) / inv_m;
    ft2 += ft[k] * ft[k];
  }
  const double lim = mu_ * fn;
  const double scale = ft2 > lim * lim ? lim / std::sqrt(ft2) : 1.0;
  for (int k = 0; k < 3; ++k) {
    atom->f[i][k] += wi * scale * ft[k];
    if (j >= 0) atom->f[j][k] += wj * scale * ft[k];
  }
}

/* Element i-j against the yarns: per yarn, the segment with the smallest separation between the
   element's centre line and the yarn's centre line (physics/static_bodies.h) acts. */
void FixFiberYarns::element_yarn_contacts(int i, int j, double r1, double &gap_min) {
  double **x = atom->x;
  double vmax2 = 0.0;
  for (int k = 0; k < 3; ++k) vmax2 = std::max(vmax2, std::max(atom->v[i][k] * atom->v[i][k], atom->v[j][k] * atom->v[j][k]));
  const double margin = law_.h_cut + 1e-3 * r1 + 4.0 * std::sqrt(3.0 * vmax2) * update->dt;
  phys::BodyHit hits[phys::StaticBodies::kMaxHits];
  const int nh = bodies_.element_hits({x[i][0], x[i][1], x[i][2]}, {x[j][0], x[j][1], x[j][2]}, r1, margin, hits);
  for (int b = 0; b < nh; ++b) {
    local_[0] += 1.0;
    const double n[3] = {hits[b].n.x, hits[b].n.y, hits[b].n.z};
    apply_element_contact(i, j, hits[b].s, n, hits[b].h, r1, hits[b].r2, gap_min);
  }
}

void FixFiberYarns::node_yarn_contacts(int i, double r1, double &gap_min) {
  double **x = atom->x;
  phys::BodyHit hits[phys::StaticBodies::kMaxHits];
  const int nh = bodies_.node_hits({x[i][0], x[i][1], x[i][2]}, r1, law_.h_cut + 1e-3 * r1 + travel(i), hits);
  for (int b = 0; b < nh; ++b) {
    local_[0] += 1.0;
    const double n[3] = {hits[b].n.x, hits[b].n.y, hits[b].n.z};
    apply_contact(i, n, hits[b].h, r1, hits[b].r2, gap_min);
  }
}

/* implicit_force newton: the contacts act inside the fibers' Newton solves (registered with fix
   fiber/beam); here only the diagnostics at the current state: contacts within h_cut (yarns,
   planes) and the smallest gap. Elements whose second node is a ghost are seen too. */
void FixFiberYarns::scan_contacts() {
  const int nlocal = atom->nlocal;
  double **x = atom->x;
  double gap_min = std::numeric_limits<double>::max();
  phys::BodyHit hits[phys::StaticBodies::kMaxHits];
  for (int i = 0; i < nlocal; ++i) {
    if (!(atom->mask[i] & groupbit) || !beam_->is_node(i)) continue;
    double rr[4];
    beam_->section_radii(i, rr);
    const double r1 = std::max(rr[0], rr[1]);
    const phys::Vec3 xi{x[i][0], x[i][1], x[i][2]};
    for (int p = 0; p < static_cast<int>(bodies_.planes().size()); ++p) {
      const double h = bodies_.plane_gap(p, xi, r1);
      gap_min = std::min(gap_min, h);
      if (h < law_.h_cut) local_[1] += 1.0;
    }
    if (bodies_.segments().empty()) continue;
    int nh = 0;
    if (beam_->node_count(i) > 1) {
      if (beam_->node_index(i) + 1 >= beam_->node_count(i)) continue;
      const int j = atom->map(atom->tag[i] + 1);
      if (j < 0) continue;  // not present here (fix fiber/beam's ghost cut-off covers an element)
      double rj[4];
      beam_->section_radii(j, rj);
      nh = bodies_.element_hits(xi, {x[j][0], x[j][1], x[j][2]}, std::max(r1, std::max(rj[0], rj[1])),
                                law_.h_cut, hits);
    } else {
      nh = bodies_.node_hits(xi, r1, law_.h_cut, hits);
    }
    for (int b = 0; b < nh; ++b) {
      local_[0] += 1.0;
      gap_min = std::min(gap_min, hits[b].h);
    }
  }
  local_[2] = -gap_min;
}

void FixFiberYarns::post_force(int) {
  const int nlocal = atom->nlocal;
  int *mask = atom->mask;
  double **x = atom->x;
  local_[0] = local_[1] = 0.0;
  sums_valid_ = false;
  if (newton_) {
    scan_contacts();
    // the yarns' and planes' total force on the fibers at the end of the last step (their
    // converged Newton states), summed over the fibers this rank solved
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
    // planes
    for (int p = 0; p < static_cast<int>(bodies_.planes().size()); ++p) {
      const double h = bodies_.plane_gap(p, {x[i][0], x[i][1], x[i][2]}, r1);
      if (h < law_.h_cut + 1e-3 * r1 + travel(i)) {
        local_[1] += 1.0;
        const phys::Vec3 &pn = bodies_.planes()[p].n;
        const double n[3] = {pn.x, pn.y, pn.z};
        apply_contact(i, n, h, r1, INFINITY, gap_min);
      }
    }
    if (bodies_.segments().empty()) continue;
    if (beam_->node_count(i) > 1) {
      // element to the next node (owned by this node); a fiber's elements cover its nodes
      if (beam_->node_index(i) + 1 >= beam_->node_count(i)) continue;
      int j = atom->map(atom->tag[i] + 1);
      if (j < 0 || j >= nlocal)
        fiberform::fail_one(lmp, FLERR, "fix fiber/yarns: the next node of an element is not owned by this rank "
                          "(the sub-integrated element contact runs on one rank only; implicit_force newton "
                          "runs on any number)");
      double rj[4];
      beam_->section_radii(j, rj);
      element_yarn_contacts(i, j, std::max(r1, std::max(rj[0], rj[1])), gap_min);
      continue;
    }
    node_yarn_contacts(i, r1, gap_min);
  }
  local_[2] = -gap_min;
}

/* Removal of whole fibers (all nodes) once any node is below remove_z_; as LAMMPS fix evaporate:
   on a forced re-neighbouring step, before atoms migrate. */
void FixFiberYarns::pre_exchange() {
  if (!remove_ || update->ntimestep < next_reneighbor) return;
  next_reneighbor = update->ntimestep + remove_every_;
  int nlocal = atom->nlocal;
  double **x = atom->x;
  std::vector<int> mine;
  for (int i = 0; i < nlocal; ++i)
    if ((atom->mask[i] & groupbit) && beam_->is_node(i) && x[i][2] < remove_z_) mine.push_back(beam_->fiber_id(i));
  std::sort(mine.begin(), mine.end());
  mine.erase(std::unique(mine.begin(), mine.end()), mine.end());
  int nmine = static_cast<int>(mine.size());
  const int nprocs = comm->nprocs;
  std::vector<int> counts(nprocs), displs(nprocs);
  MPI_Allgather(&nmine, 1, MPI_INT, counts.data(), 1, MPI_INT, world);
  int total = 0;
  for (int p = 0; p < nprocs; ++p) {
    displs[p] = total;
    total += counts[p];
  }
  if (total == 0) return;
  std::vector<int> all(total);
  MPI_Allgatherv(mine.data(), nmine, MPI_INT, all.data(), counts.data(), displs.data(), MPI_INT, world);
  std::set<int> gone(all.begin(), all.end());
  double mass = 0.0, nodes = 0.0;
  for (int i = nlocal - 1; i >= 0; --i) {
    if (!beam_->is_node(i) || !gone.count(beam_->fiber_id(i))) continue;
    mass += atom->rmass[i];
    nodes += 1.0;
    atom->avec->copy(nlocal - 1, i, 1);
    --nlocal;
  }
  atom->nlocal = nlocal;
  double loc[2] = {mass, nodes}, glob[2];
  MPI_Allreduce(loc, glob, 2, MPI_DOUBLE, MPI_SUM, world);
  removed_mass_ += glob[0];
  removed_nodes_ += glob[1];
  removed_fibers_ += static_cast<double>(gone.size());
  atom->natoms -= static_cast<bigint>(glob[1] + 0.5);
  if (atom->map_style) {
    atom->nghost = 0;
    atom->map_init();
    atom->map_set();
  }
  if (comm->me == 0) {
    std::string msg = "fix fiber/yarns: step " + std::to_string(update->ntimestep) + " removed fiber(s)";
    for (int id : gone) msg += " " + std::to_string(id);
    msg += "\n";
    if (screen) std::fputs(msg.c_str(), screen);
    if (logfile) std::fputs(msg.c_str(), logfile);
  }
}

/* Restart: the removal accounting (fibers, mass, nodes) and the settle counter, so that a resumed
   lay-down reports the same totals and stops at the same check as an uninterrupted one. */
void FixFiberYarns::write_restart(FILE *fp) {
  double list[5] = {removed_fibers_, removed_mass_, removed_nodes_, settled_checks_, max_speed_};
  if (comm->me == 0) {
    const int size = sizeof(list);
    std::fwrite(&size, sizeof(int), 1, fp);
    std::fwrite(list, sizeof(double), 5, fp);
  }
}

void FixFiberYarns::restart(char *buf) {
  const double *list = reinterpret_cast<double *>(buf);
  removed_fibers_ = list[0];
  removed_mass_ = list[1];
  removed_nodes_ = list[2];
  settled_checks_ = list[3];
  max_speed_ = list[4];
}

double FixFiberYarns::compute_vector(int n) {
  if (n == 0) return removed_fibers_;
  if (n == 1) return removed_mass_;
  if (n == 2) return removed_nodes_;
  if (n == 6) return settled_checks_;
  if (n == 7) return max_speed_;
  if (!sums_valid_) {
    MPI_Allreduce(local_, sums_, 2, MPI_DOUBLE, MPI_SUM, world);
    MPI_Allreduce(local_force_, force_, 3, MPI_DOUBLE, MPI_SUM, world);
    MPI_Allreduce(&local_[2], &sums_[2], 1, MPI_DOUBLE, MPI_MAX, world);
    sums_valid_ = true;
  }
  if (n == 5) return -sums_[2];
  if (n >= 8) return force_[n - 8];
  return sums_[n - 3];
}
