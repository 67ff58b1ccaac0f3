/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/beam: see fix_fiber_beam.h, docs/styles/fix_fiber_beam.md and docs/models/beam.md. */
#include "fix_fiber_beam.h"

#include "style_args.h"

#include <mpi.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <algorithm>
#include <map>
#include <sstream>
#include <vector>

#include "abi_guard.h"
#include "patient_wait.h"
#include "atom.h"
#include "comm.h"
#include "domain.h"
#include "error.h"
#include "force.h"
#include "group.h"
#include "memory.h"
#include "modify.h"
#include "physics/beam.h"
#include "physics/implicit_rod.h"
#include "update.h"

using namespace LAMMPS_NS;
using namespace FixConst;

namespace bm = fiberform::physics::beam;
namespace rod = fiberform::physics::rod;

// The factored tangent of every fiber (or contact cluster, keyed by its fiber IDs) solved on this
// rank, for modified Newton across steps (rod::Tangent, keyword tangent_steps), and the work
// arrays of implicit_step (kept so that a step does not allocate them anew).
namespace LAMMPS_NS {
struct FiberTangents {
  struct Entry {
    rod::Tangent tangent;
    bigint used = -1;  // the last step it was solved in
  };
  std::map<std::vector<int>, Entry> map;
  std::vector<rod::Node> nodes, fnodes;
  std::vector<rod::Element> elems, felems;
  std::vector<bm::Vec3> starts;
  std::vector<std::vector<double>> back;  // return records, per source rank
  std::vector<double> brecv;
  std::vector<int> ids, offsets;
  std::vector<const double *> recs;
};
}  // namespace LAMMPS_NS

namespace {

constexpr int kRecordCols = 19;  // id fiber node count a1 a2 b1 b2 x0 y0 z0 q0(4) q(4)
constexpr int kDynamicComm = 10;  // q(4) v(3) omega(3)

bm::Vec3 vec(const double *p) { return {p[0], p[1], p[2]}; }
bm::Quat quat(const double *p) { return {p[0], p[1], p[2], p[3]}; }
void put(double *p, bm::Vec3 v) { p[0] = v.x; p[1] = v.y; p[2] = v.z; }
void add(double *p, bm::Vec3 v) { p[0] += v.x; p[1] += v.y; p[2] += v.z; }

void say(LAMMPS *lmp, const std::string &s) {
  if (lmp->comm->me != 0) return;
  if (lmp->screen) std::fputs(s.c_str(), lmp->screen);
  if (lmp->logfile) std::fputs(s.c_str(), lmp->logfile);
}

}  // namespace

/* ---------------------------------------------------------------------- */

FixFiberBeam::FixFiberBeam(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg) {
  if (narg < 3) error->all(FLERR, "fix fiber/beam: missing arguments");
  time_integrate = 1;
  restart_global = 1;
  restart_peratom = 1;
  // per-atom output f_ID[1..7]: fiber ID, node index, node count, qw, qx, qy, qz
  peratom_flag = 1;
  size_peratom_cols = 7;
  peratom_freq = 1;
  scalar_flag = 1;
  extscalar = 1;
  vector_flag = 1;
  size_vector = 22;
  extvector = 0;
  global_freq = 1;
  comm_forward = NSTATIC > kDynamicComm ? NSTATIC : kDynamicComm;

  bool haveE = false, haveG = false, haveRho = false;
  auto need = [&](int iarg, int n, const char *kw) {
    if (iarg + n >= narg) {
      const std::string m = std::string("fix fiber/beam: keyword '") + kw + "' needs " + std::to_string(n) +
                            " value(s)";
      error->all(FLERR, fiberform::error_text(m));
    }
  };
  auto positive = [&](double v, const char *kw, bool allow_zero) {
    if (!std::isfinite(v) || v < 0 || (!allow_zero && v == 0)) {
      const std::string m = std::string("fix fiber/beam: keyword '") + kw + "' must be a finite number " +
                            (allow_zero ? ">= 0" : "> 0");
      error->all(FLERR, fiberform::error_text(m));
    }
    return v;
  };
  // the integer value of keyword kw at arg[iarg + 1], which must lie in [lo, hi]
  auto integer_in = [&](int iarg, const char *kw, int lo, int hi) {
    need(iarg, 1, kw);
    const int v = force->inumeric(FLERR, arg[iarg + 1]);
    if (v < lo || v > hi) {
      const std::string m = std::string("fix fiber/beam: keyword '") + kw + "' must be an integer in [" +
                            std::to_string(lo) + ", " + std::to_string(hi) + "]";
      error->all(FLERR, fiberform::error_text(m));
    }
    return v;
  };
  // keyword kw at arg[iarg + 1] takes one of two words: true for yes, false for no
  auto one_of = [&](int iarg, const char *kw, const char *yes, const char *no) {
    need(iarg, 1, kw);
    if (std::strcmp(arg[iarg + 1], yes) == 0) return true;
    if (std::strcmp(arg[iarg + 1], no) == 0) return false;
    const std::string m = std::string("fix fiber/beam: keyword '") + kw + "' takes '" + yes + "' or '" + no + "'";
    error->all(FLERR, fiberform::error_text(m));
    return false;
  };
  for (int iarg = 3; iarg < narg;) {
    const char *kw = arg[iarg];
    if (std::strcmp(kw, "nodes") == 0) {
      need(iarg, 1, kw);
      nodes_path_ = arg[iarg + 1];
      iarg += 2;
    } else if (std::strcmp(kw, "E") == 0) {
      need(iarg, 1, kw);
      E_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, false);
      haveE = true;
      iarg += 2;
    } else if (std::strcmp(kw, "G") == 0) {
      need(iarg, 1, kw);
      G_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, false);
      haveG = true;
      iarg += 2;
    } else if (std::strcmp(kw, "density") == 0) {
      need(iarg, 1, kw);
      rho_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, false);
      haveRho = true;
      iarg += 2;
    } else if (std::strcmp(kw, "shear_factor") == 0) {
      need(iarg, 1, kw);
      kshear_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, false);
      iarg += 2;
    } else if (std::strcmp(kw, "damping") == 0) {
      need(iarg, 1, kw);
      t_damp_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, true);
      iarg += 2;
    } else if (std::strcmp(kw, "drag") == 0) {
      need(iarg, 1, kw);
      tau_drag_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, true);
      iarg += 2;
    } else if (std::strcmp(kw, "stiffness_scale") == 0) {
      need(iarg, 1, kw);
      stiff_scale_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, false);
      iarg += 2;
    } else if (std::strcmp(kw, "inertia_scale") == 0) {
      need(iarg, 1, kw);
      inertia_scale_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, false);
      iarg += 2;
    } else if (std::strcmp(kw, "torque") == 0) {
      need(iarg, 4, kw);
      const int ig = group->find(arg[iarg + 1]);
      if (ig < 0) error->all(FLERR, "fix fiber/beam: keyword 'torque': unknown group");
      torque_groupbit_ = group->bitmask[ig];
      for (int k = 0; k < 3; ++k) torque_[k] = force->numeric(FLERR, arg[iarg + 2 + k]);
      iarg += 5;
    } else if (std::strcmp(kw, "integrator") == 0) {
      implicit_ = one_of(iarg, kw, "implicit", "explicit");
      iarg += 2;
    } else if (std::strcmp(kw, "rho_inf") == 0) {
      need(iarg, 1, kw);
      rho_inf_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, true);
      if (rho_inf_ > 1.0) error->all(FLERR, "fix fiber/beam: keyword 'rho_inf' must be in [0, 1]");
      iarg += 2;
    } else if (std::strcmp(kw, "contact_weighting") == 0) {
      contact_at_end_ = one_of(iarg, kw, "end", "alpha");
      iarg += 2;
    } else if (std::strcmp(kw, "newton_tol") == 0) {
      need(iarg, 1, kw);
      newton_tol_ = positive(force->numeric(FLERR, arg[iarg + 1]), kw, false);
      iarg += 2;
    } else if (std::strcmp(kw, "newton_max") == 0) {
      newton_max_ = integer_in(iarg, kw, 1, 1000);
      iarg += 2;
    } else if (std::strcmp(kw, "tangent_steps") == 0) {
      tangent_steps_ = integer_in(iarg, kw, 1, 100000);
      iarg += 2;
    } else if (std::strcmp(kw, "anderson") == 0) {
      anderson_ = integer_in(iarg, kw, 0, rod::Stepper::kMaxAnderson);
      iarg += 2;
    } else if (std::strcmp(kw, "landing") == 0) {
      land_predict_ = one_of(iarg, kw, "predict", "limit");
      iarg += 2;
    } else if (std::strcmp(kw, "max_split") == 0) {
      max_split_ = integer_in(iarg, kw, 0, 20);
      iarg += 2;
    } else if (std::strcmp(kw, "split_memory") == 0) {
      split_memory_ = integer_in(iarg, kw, 0, 1000000);
      iarg += 2;
    } else if (std::strcmp(kw, "clamp") == 0) {
      need(iarg, 1, kw);
      const int ig = group->find(arg[iarg + 1]);
      if (ig < 0) error->all(FLERR, "fix fiber/beam: keyword 'clamp': unknown group");
      clamp_groupbit_ = group->bitmask[ig];
      iarg += 2;
    } else if (std::strcmp(kw, "dt_check") == 0) {
      dt_check_error_ = one_of(iarg, kw, "error", "warn");
      iarg += 2;
    } else {
      const std::string m = std::string("fix fiber/beam: unknown keyword '") + kw +
                            "' (expected nodes, E, G, density, shear_factor, damping, drag, "
                            "stiffness_scale, inertia_scale, torque, dt_check, integrator, rho_inf, "
                            "newton_tol, newton_max, tangent_steps, anderson, landing, max_split, split_memory, clamp)";
      error->all(FLERR, fiberform::error_text(m));
    }
  }
  if (!haveE || !haveG || !haveRho)
    error->all(FLERR, "fix fiber/beam: keywords E (Pa), G (Pa) and density (kg/m3) are required");
  if (!atom->radius_flag || !atom->rmass_flag || !atom->omega_flag || !atom->torque_flag)
    error->all(FLERR, "fix fiber/beam requires atom_style sphere (radius, rmass, omega, torque)");
  if (atom->map_style == 0)
    error->all(FLERR, "fix fiber/beam requires 'atom_modify map array' (nodes are found by atom ID)");

  grow_arrays(atom->nmax);
  atom->add_callback(0);
  atom->add_callback(1);
  for (int i = 0; i < atom->nmax; ++i) set_arrays(i);

  if (!nodes_path_.empty()) read_nodes_file(nodes_path_.c_str());
}

FixFiberBeam::~FixFiberBeam() {
  atom->delete_callback(id, 0);
  atom->delete_callback(id, 1);
  memory->destroy(node_);
  memory->destroy(acc_);
}

int FixFiberBeam::setmask() {
  return INITIAL_INTEGRATE | PRE_NEIGHBOR | PRE_FORCE | POST_FORCE | FINAL_INTEGRATE;
}

FixFiberBeam *FixFiberBeam::find(LAMMPS *lmp) {
  for (int i = 0; i < lmp->modify->nfix; ++i)
    if (std::strcmp(lmp->modify->fix[i]->style, "fiber/beam") == 0)
      return dynamic_cast<FixFiberBeam *>(lmp->modify->fix[i]);
  return nullptr;
}

bool FixFiberBeam::precedes(const Fix *other) const {
  for (int k = 0; k < modify->nfix; ++k) {
    if (modify->fix[k] == this) return true;
    if (modify->fix[k] == other) return false;
  }
  return false;
}

void FixFiberBeam::frame(int i, double t1[3], double t2[3], double t3[3]) const {
  const bm::Quat q = quat(&node_[i][QW]);
  put(t1, bm::qrot(q, {1, 0, 0}));
  put(t2, bm::qrot(q, {0, 1, 0}));
  put(t3, bm::qrot(q, {0, 0, 1}));
}

double FixFiberBeam::beta_eff() const { return implicit_ ? rod::gen_alpha(rho_inf_).beta_eff() : 0.5; }
double FixFiberBeam::gamma_eff() const { return implicit_ ? rod::gen_alpha(rho_inf_).gamma_eff() : 0.5; }
void FixFiberBeam::add_velocity_jacobian(int i, const double *D) {
  if (!implicit_ || i < 0 || i >= atom->nlocal) return;
  for (int k = 0; k < 6; ++k) node_[i][DJ0 + k] += D[k];
}

void FixFiberBeam::use_force_model(rod::NodeForceModel *m, bool on) {
  if (!m) return;
  const bool present = std::find(models_.begin(), models_.end(), m) != models_.end();
  if (on && !present) models_.push_back(m);
  if (!on && present) models_.erase(std::remove(models_.begin(), models_.end(), m), models_.end());
}
void FixFiberBeam::release_force_model(LAMMPS *lmp, rod::NodeForceModel *m) {
  if (FixFiberBeam *beam = find(lmp)) beam->use_force_model(m, false);
}
void FixFiberBeam::remove_from_history(int i, const double *F) {
  if (!implicit_ || i < 0 || i >= atom->nlocal || !is_node(i)) return;
  const rod::GenAlpha g = rod::gen_alpha(rho_inf_);
  const double k = 1.0 / atom->rmass[i], ka = k * (1.0 - g.af) / (1.0 - g.am);
  for (int d = 0; d < 3; ++d) {
    node_[i][VDX + d] -= k * F[d];
    node_[i][AX + d] -= ka * F[d];
  }
}

void FixFiberBeam::section_radii(int i, double r[4]) const {
  for (int k = 0; k < 4; ++k) r[k] = node_[i][A1 + k];
}

void FixFiberBeam::element_radii(int i, int j, double r[4]) const {
  bm::element_radii(&node_[i][A1], &node_[j][A1], r);
}

double FixFiberBeam::contact_reach(int i) const {
  return contact_rect(i) ? std::hypot(node_[i][A1], node_[i][A2]) : contact_radius(i);
}

/* ---------------------------------------------------------------------- 
   nodes file: one line per node,
     atom-ID fiber-ID node-index node-count a1 a2 b1 b2 x0 y0 z0 q0w q0x q0y q0z [qw qx qy qz]
   '#' starts a comment. Read on rank 0, broadcast, assigned to the owned atoms by ID.
------------------------------------------------------------------------- */

void FixFiberBeam::read_nodes_file(const char *path) {
  std::vector<double> rec;
  int status = 0;
  std::string why;
  if (comm->me == 0) {
    std::ifstream in(path);
    if (!in) {
      status = 1;
      why = std::string("cannot open nodes file ") + path;
    }
    std::string line;
    int lineno = 0;
    std::map<long, size_t> row_of_tag;
    while (status == 0 && std::getline(in, line)) {
      ++lineno;
      const auto hash = line.find('#');
      if (hash != std::string::npos) line.erase(hash);
      std::istringstream ss(line);
      std::vector<double> vals;
      double v;
      while (ss >> v) vals.push_back(v);
      if (!ss.eof()) {
        status = 1;
        why = "nodes file line " + std::to_string(lineno) + ": not a number";
        break;
      }
      if (vals.empty()) continue;
      if (vals.size() != 15 && vals.size() != 19) {
        status = 1;
        why = "nodes file line " + std::to_string(lineno) + ": expected 15 or 19 values, got " +
              std::to_string(vals.size());
        break;
      }
      if (vals.size() == 15) vals.insert(vals.end(), vals.begin() + 11, vals.begin() + 15);
      bool ok = vals[0] >= 1 && vals[1] >= 0 && vals[2] >= 0 && vals[3] >= 2 && vals[2] < vals[3] &&
                bm::section_valid(vals[4], vals[5], vals[6], vals[7]);
      for (double x : vals) ok = ok && std::isfinite(x);
      if (!ok) {
        status = 1;
        why = "nodes file line " + std::to_string(lineno) +
              ": need atom-ID >= 1, fiber-ID >= 0, 0 <= node-index < node-count, node-count >= 2, "
              "0 <= b < a for the section radii, finite values";
        break;
      }
      row_of_tag[static_cast<long>(vals[0])] = rec.size() / kRecordCols;
      rec.insert(rec.end(), vals.begin(), vals.end());
    }
    // topology check and the longest element (ghost reach)
    const size_t nrow = rec.size() / kRecordCols;
    for (size_t r = 0; status == 0 && r < nrow; ++r) {
      const double *a = &rec[r * kRecordCols];
      if (a[2] + 1 >= a[3]) continue;
      const auto it = row_of_tag.find(static_cast<long>(a[0]) + 1);
      const double *b = it == row_of_tag.end() ? nullptr : &rec[it->second * kRecordCols];
      if (!b || b[1] != a[1] || b[2] != a[2] + 1 || b[3] != a[3]) {
        status = 1;
        why = "nodes file: node after atom " + std::to_string(static_cast<long>(a[0])) +
              " must be atom ID+1 with the same fiber ID, node index+1 and node count";
        break;
      }
      double d[3] = {b[8] - a[8], b[9] - a[9], b[10] - a[10]};
      domain->minimum_image(d);
      max_elem_len_ = std::fmax(max_elem_len_, std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
    }
  }
  MPI_Bcast(&status, 1, MPI_INT, 0, world);
  if (status) {
    const std::string m = "fix fiber/beam: " + why;
    fiberform::fail_one(lmp, FLERR, fiberform::error_text(m));
  }
  long n = static_cast<long>(rec.size());
  MPI_Bcast(&n, 1, MPI_LONG, 0, world);
  rec.resize(n);
  MPI_Bcast(rec.data(), static_cast<int>(n), MPI_DOUBLE, 0, world);
  MPI_Bcast(&max_elem_len_, 1, MPI_DOUBLE, 0, world);

  const int nrow = static_cast<int>(n / kRecordCols);
  int assigned = 0;
  for (int r = 0; r < nrow; ++r) {
    const double *a = &rec[static_cast<size_t>(r) * kRecordCols];
    const long tag = static_cast<long>(a[0]);
    if (tag > atom->map_tag_max) continue;
    const int i = atom->map(static_cast<int>(tag));
    if (i < 0 || i >= atom->nlocal) continue;
    double *p = node_[i];
    p[FID] = a[1];
    p[IDX] = a[2];
    p[CNT] = a[3];
    for (int k = 0; k < 4; ++k) p[A1 + k] = a[4 + k];
    for (int k = 0; k < 3; ++k) p[X0 + k] = a[8 + k];
    const bm::Quat q0 = bm::qnormalize(quat(a + 11)), q = bm::qnormalize(quat(a + 15));
    p[Q0W] = q0.w; p[Q0X] = q0.x; p[Q0Y] = q0.y; p[Q0Z] = q0.z;
    p[QW] = q.w; p[QX] = q.x; p[QY] = q.y; p[QZ] = q.z;
    p[HASREF] = 0;
    ++assigned;
  }
  int total = 0;
  MPI_Allreduce(&assigned, &total, 1, MPI_INT, MPI_SUM, world);
  if (total != nrow) {
    const std::string m = "fix fiber/beam: nodes file lists " + std::to_string(nrow) + " nodes but only " +
                          std::to_string(total) + " of those atom IDs exist";
    error->all(FLERR, fiberform::error_text(m));
  }
  ref_done_ = 0;
}

/* ---------------------------------------------------------------------- */

void FixFiberBeam::init() {
  fiberform::check_atom_layout(lmp);
  dtv_ = update->dt;
  dtf_ = 0.5 * update->dt * force->ftm2v;
  // nobody else may integrate our nodes
  for (int f = 0; f < modify->nfix; ++f) {
    Fix *other = modify->fix[f];
    if (other == this || !other->time_integrate) continue;
    int overlap = 0, any = 0;
    for (int i = 0; i < atom->nlocal; ++i)
      if ((atom->mask[i] & groupbit) && (atom->mask[i] & other->groupbit)) overlap = 1;
    MPI_Allreduce(&overlap, &any, 1, MPI_INT, MPI_MAX, world);
    if (any) {
      const std::string m = std::string("fix fiber/beam integrates its nodes itself; fix ") + other->id +
                            " (" + other->style + ") also integrates some of them. Apply it to a group "
                            "without fiber nodes.";
      error->all(FLERR, fiberform::error_text(m));
    }
  }
}

double FixFiberBeam::extend_cut_ghost() {
  // ghosts must reach one element; LIGGGHTS effectively halves this request (platform.md)
  return 2.0 * 1.05 * max_elem_len_;
}

void FixFiberBeam::reset_dt() {
  dtv_ = update->dt;
  dtf_ = 0.5 * update->dt * force->ftm2v;
}

/* ----------------------------------------------------------------------
   element section: radii averaged over the two nodes
------------------------------------------------------------------------- */

void FixFiberBeam::element_section(int i, int j, double *area, double inertia[3], double stiff[6]) const {
  double r[4];
  element_radii(i, j, r);
  const bm::Section s = bm::hollow_ellipse(r[0], r[1], r[2], r[3]);
  const bm::Stiffness C = bm::section_stiffness(s, E_, G_, kshear_, stiff_scale_);
  *area = s.A;
  inertia[0] = s.I1;
  inertia[1] = s.I2;
  inertia[2] = s.Ip;
  stiff[0] = C.CG.x; stiff[1] = C.CG.y; stiff[2] = C.CG.z;
  stiff[3] = C.CK.x; stiff[4] = C.CK.y; stiff[5] = C.CK.z;
}

static int neighbour_node(LAMMPS *lmp, int i, int dtag) {
  const long t = static_cast<long>(lmp->atom->tag[i]) + dtag;
  if (t < 1 || t > lmp->atom->map_tag_max) return -1;
  const int j = lmp->atom->map(static_cast<int>(t));
  if (j < 0) return -1;
  return lmp->domain->closest_image(i, j);
}

int FixFiberBeam::neighbour(int i, int dtag) const { return neighbour_node(lmp, i, dtag); }

static void missing_neighbour(LAMMPS *lmp, int i, int dtag) {
  static char buf[512];  // static POD: LIGGGHTS' Error prints the message again at exit
  std::snprintf(buf, sizeof buf,
                "fix fiber/beam: node %d needs atom %d, which is neither owned nor a ghost "
                "on this rank. The ghost cut-off must cover one element (check the nodes file and the "
                "atom IDs, or raise it with 'communicate single cutoff')",
                lmp->atom->tag[i], lmp->atom->tag[i] + dtag);
  fiberform::fail_one(lmp, FLERR, buf);
}

/* ---------------------------------------------------------------------- 
   stress-free reference (from the nodes file's x0, q0), node mass and rotary inertia
------------------------------------------------------------------------- */

void FixFiberBeam::compute_reference() {
  const int nlocal = atom->nlocal;
  int bad = 0;
  for (int i = 0; i < nlocal; ++i) {
    if (!(atom->mask[i] & groupbit)) continue;
    if (!is_node(i)) {
      ++bad;
      continue;
    }
    double *p = node_[i];
    double mass = 0, inert[3] = {0, 0, 0};
    for (int side = 0; side < 2; ++side) {
      const int dtag = side == 0 ? -1 : +1;
      if (side == 0 && p[IDX] < 0.5) continue;
      if (side == 1 && p[IDX] + 1 >= p[CNT]) continue;
      const int j = neighbour_node(lmp, i, dtag);
      if (j < 0) missing_neighbour(lmp, i, dtag);
      const int a = side == 0 ? j : i, b = side == 0 ? i : j;
      double d0[3] = {node_[b][X0] - node_[a][X0], node_[b][Y0] - node_[a][Y0], node_[b][Z0] - node_[a][Z0]};
      domain->minimum_image(d0);
      const double len0 = std::sqrt(d0[0] * d0[0] + d0[1] * d0[1] + d0[2] * d0[2]);
      if (!(len0 > 0)) fiberform::fail_one(lmp, FLERR, "fix fiber/beam: two consecutive nodes share the same reference position");
      double area, I[3], C[6];
      element_section(a, b, &area, I, C);
      mass += 0.5 * rho_ * area * len0;
      for (int k = 0; k < 3; ++k) inert[k] += 0.5 * inertia_scale_ * rho_ * I[k] * len0;
      if (side == 1) {
        const bm::Vec3 xa = vec(&node_[a][X0]);
        const bm::ElementRef r =
            bm::element_reference(xa, quat(&node_[a][Q0W]), xa + vec(d0), quat(&node_[b][Q0W]));
        p[HASREF] = 1;
        p[L0] = r.L0;
        put(&p[G0X], r.gamma0);
        put(&p[K0X], r.kappa0);
        for (int k = 0; k < 6; ++k) p[CGX + k] = C[k];
      }
    }
    atom->rmass[i] = mass;
    p[JB1] = inert[0];
    p[JB2] = inert[1];
    p[JB3] = inert[2];
  }
  int badall = 0;
  MPI_Allreduce(&bad, &badall, 1, MPI_INT, MPI_SUM, world);
  if (badall) {
    const std::string m = "fix fiber/beam: " + std::to_string(badall) +
                          " atoms of the fix group have no entry in the nodes file";
    error->all(FLERR, fiberform::error_text(m));
  }
  ref_done_ = 1;
}

void FixFiberBeam::compute_critical_steps(bool print) {
  double dt[4] = {INFINITY, INFINITY, INFINITY, INFINITY};
  bigint counts[2] = {0, 0}, all[2];
  for (int i = 0; i < atom->nlocal; ++i) {
    if (!(atom->mask[i] & groupbit) || !is_node(i)) continue;
    ++counts[0];
    if (node_[i][IDX] < 0.5) ++counts[1];
    if (node_[i][HASREF] < 0.5) continue;
    const int j = neighbour_node(lmp, i, +1);
    if (j < 0) missing_neighbour(lmp, i, +1);
    double r[4];
    element_radii(i, j, r);
    const bm::Section s = bm::hollow_ellipse(r[0], r[1], r[2], r[3]);
    const bm::Stiffness C{vec(&node_[i][CGX]), vec(&node_[i][CKX])};
    const bm::CriticalSteps c = bm::critical_steps(s, C, node_[i][L0], rho_, inertia_scale_, t_damp_);
    dt[0] = std::fmin(dt[0], c.axial);
    dt[1] = std::fmin(dt[1], c.shear);
    dt[2] = std::fmin(dt[2], c.bending);
    dt[3] = std::fmin(dt[3], c.torsion);
  }
  double dtall[4];
  MPI_Allreduce(dt, dtall, 4, MPI_DOUBLE, MPI_MIN, world);
  MPI_Allreduce(counts, all, 2, MPI_LMP_BIGINT, MPI_SUM, world);
  nnodes_ = all[0];
  nfibers_ = all[1];
  double mn = INFINITY;
  const char *names[4] = {"axial", "shear", "bending", "torsion"};
  int which = 0;
  for (int k = 0; k < 4; ++k) {
    dt_crit_[k] = dtall[k];
    if (dtall[k] < mn) {
      mn = dtall[k];
      which = k;
    }
  }
  dt_crit_[4] = mn;
  if (print) {
    char buf[1024];
    std::snprintf(buf, sizeof buf,
                  "fix fiber/beam: %ld fibers, %ld nodes; E %g Pa, G %g Pa, density %g kg/m3, shear_factor %g\n"
                  "  options: stiffness_scale %g, inertia_scale %g, damping %g s, drag %g s\n"
                  "  critical time step (velocity Verlet, element bound): axial %.4g s, shear %.4g s, "
                  "bending %.4g s, torsion %.4g s\n"
                  "  timestep %.4g s = %.3f x critical (%s)\n"
                  "  integrator %s",
                  static_cast<long>(nfibers_), static_cast<long>(nnodes_), E_, G_, rho_, kshear_, stiff_scale_,
                  inertia_scale_, t_damp_, tau_drag_, dtall[0], dtall[1], dtall[2], dtall[3], update->dt,
                  update->dt / mn, names[which], implicit_ ? "implicit" : "explicit (velocity Verlet)");
    say(lmp, buf);
    if (implicit_) {
      const rod::GenAlpha g = rod::gen_alpha(rho_inf_);
      std::snprintf(buf, sizeof buf,
                    " (generalized-alpha on SO(3): rho_inf %g, alpha_m %.4g, alpha_f %.4g, gamma %.4g, beta %.4g; "
                    "Newton tolerance %g, at most %d iterations, up to %d halvings)\n",
                    rho_inf_, g.am, g.af, g.gamma, g.beta, newton_tol_, newton_max_, max_split_);
    } else {
      std::snprintf(buf, sizeof buf, "\n");
    }
    say(lmp, buf);
  }
  if (update->dt > mn && !implicit_) {
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "fix fiber/beam: timestep %.4g s exceeds the critical step %.4g s of the %s mode. "
                  "Reduce the timestep, or trade accuracy for speed with stiffness_scale (axial/shear) or "
                  "inertia_scale (rotary inertia), see docs/styles/fix_fiber_beam.md",
                  update->dt, mn, names[which]);
    if (dt_check_error_) error->all(FLERR, fiberform::error_text(buf));
    else error->warning(FLERR, fiberform::error_text(buf));
  }
}

/* ---------------------------------------------------------------------- */

void FixFiberBeam::setup_pre_neighbor() { pre_neighbor(); }

void FixFiberBeam::pre_neighbor() {
  comm_mode_ = 1;
  comm->forward_comm_fix(this);
  comm_mode_ = 0;
  owners_valid_ = false;  // atoms may have migrated
  // Held tangents are dropped whenever atoms may migrate, on every rank alike: a fiber whose owner
  // changed would otherwise start on a new tangent on one decomposition and on the held one on
  // another, and runs on 1 and 2 ranks would differ at the level of the Newton tolerance.
  if (tangents_) tangents_->map.clear();
}

void FixFiberBeam::setup_pre_force(int vflag) { pre_force(vflag); }

void FixFiberBeam::pre_force(int) {
  comm_mode_ = 0;
  comm->forward_comm_fix(this);
}

void FixFiberBeam::setup(int vflag) {
  if (!ref_done_) {
    pre_neighbor();
    compute_reference();
  }
  pre_neighbor();  // ship the element data to the ghosts
  pre_force(vflag);
  compute_critical_steps(true);
  if (implicit_) {
    // internal forces of the initial state (later ones come from the converged implicit steps;
    // a node whose scheme state is already set, by an earlier run or a restart file, keeps them,
    // so that a resumed run repeats the uninterrupted one)
    internal_forces_local();
    for (int i = 0; i < atom->nlocal; ++i) {
      if (!(atom->mask[i] & groupbit) || !is_node(i)) continue;
      if (node_[i][ACCOK] > 0.5) continue;
      for (int k = 0; k < 3; ++k) {
        node_[i][FIX + k] = acc_[i][k] + acc_[i][6 + k];
        node_[i][TIX + k] = acc_[i][3 + k] + acc_[i][9 + k];
      }
      for (int k = 0; k < 6; ++k) node_[i][DJ0 + k] = 0.0;
    }
  }
  post_force(vflag);
}

/* ----------------------------------------------------------------------
   element forces at the current state into acc_: per local atom the force/torque of the element
   to the previous node (columns 0-5) and to the next node (6-11); element energies summed
------------------------------------------------------------------------- */

void FixFiberBeam::internal_forces_local() {
  const int nlocal = atom->nlocal;
  if (nmax_acc_ < atom->nmax) {
    nmax_acc_ = atom->nmax;
    memory->destroy(acc_);
    memory->create(acc_, nmax_acc_, 12, "fiber/beam:acc");
  }
  double **x = atom->x, **v = atom->v, **omega = atom->omega;
  int *mask = atom->mask;
  energy_local_ = 0;
  dissipation_local_ = 0;
  for (int i = 0; i < nlocal; ++i)
    for (int k = 0; k < 12; ++k) acc_[i][k] = 0.0;

  auto state = [&](int i) {
    bm::NodeState s;
    s.x = vec(x[i]);
    s.q = quat(&node_[i][QW]);
    s.v = vec(v[i]);
    s.w = vec(omega[i]);
    return s;
  };
  auto element = [&](int a, int b) {
    const double *p = node_[a];
    bm::ElementRef r;
    r.L0 = p[L0];
    r.gamma0 = vec(&p[G0X]);
    r.kappa0 = vec(&p[K0X]);
    const bm::Stiffness C{vec(&p[CGX]), vec(&p[CKX])};
    return bm::element_forces(state(a), state(b), r, C, t_damp_);
  };

  for (int i = 0; i < nlocal; ++i) {
    if (!(mask[i] & groupbit) || !is_node(i)) continue;
    // element to the next node: computed once per rank that owns at least one end
    if (node_[i][IDX] + 1 < node_[i][CNT]) {
      const int j = neighbour_node(lmp, i, +1);
      if (j < 0) missing_neighbour(lmp, i, +1);
      if (node_[i][HASREF] < 0.5) fiberform::fail_one(lmp, FLERR, "fix fiber/beam: element without reference");
      const bm::ElementForces e = element(i, j);
      add(&acc_[i][6], e.fA);
      add(&acc_[i][9], e.tA);
      if (j < nlocal) {
        add(&acc_[j][0], e.fB);
        add(&acc_[j][3], e.tB);
        energy_local_ += e.energy;
        dissipation_local_ += e.dissipation;
      } else {
        energy_local_ += 0.5 * e.energy;
        dissipation_local_ += 0.5 * e.dissipation;
      }
    }
    // element from a previous node that is a ghost here
    if (node_[i][IDX] > 0.5) {
      const int j = neighbour_node(lmp, i, -1);
      if (j < 0) missing_neighbour(lmp, i, -1);
      if (j >= nlocal) {
        if (node_[j][HASREF] < 0.5) fiberform::fail_one(lmp, FLERR, "fix fiber/beam: ghost element without reference");
        const bm::ElementForces e = element(j, i);
        add(&acc_[i][0], e.fB);
        add(&acc_[i][3], e.tB);
        energy_local_ += 0.5 * e.energy;
        dissipation_local_ += 0.5 * e.dissipation;
      }
    }
  }
}

/* ----------------------------------------------------------------------
   explicit: the element forces, background drag and external torque go into f / torque.
   implicit: f / torque receive the internal forces of the current (converged) state, so that the
   fixes after this one (contact, yarns) see every non-contact force in f, exactly as with the
   explicit integrator; final_integrate takes them out again (external = f - internal) and solves.
------------------------------------------------------------------------- */

void FixFiberBeam::post_force(int) {
  const int nlocal = atom->nlocal;
  double **v = atom->v, **omega = atom->omega;
  double **f = atom->f, **torque = atom->torque;
  int *mask = atom->mask;
  if (implicit_) {
    for (int i = 0; i < nlocal; ++i) {
      if (!(mask[i] & groupbit) || !is_node(i)) continue;
      // the velocity Jacobians of this step's external forces are added by the fixes after this
      // one (fix fiber/drag checks that it comes later); a setup() before the step must not count
      for (int k = 0; k < 6; ++k) node_[i][DJ0 + k] = 0.0;
      for (int k = 0; k < 3; ++k) {
        f[i][k] += node_[i][FIX + k];
        torque[i][k] += node_[i][TIX + k];
      }
      if (torque_groupbit_ && (mask[i] & torque_groupbit_))
        for (int k = 0; k < 3; ++k) torque[i][k] += torque_[k];
    }
    return;
  }
  internal_forces_local();
  // sum in a fixed order (previous element, then next) so results do not depend on the
  // decomposition; then background drag and the external torque
  for (int i = 0; i < nlocal; ++i) {
    if (!(mask[i] & groupbit) || !is_node(i)) continue;
    for (int k = 0; k < 3; ++k) {
      f[i][k] += acc_[i][k] + acc_[i][6 + k];
      torque[i][k] += acc_[i][3 + k] + acc_[i][9 + k];
    }
    if (tau_drag_ > 0) {
      const double c = 1.0 / tau_drag_;
      for (int k = 0; k < 3; ++k) f[i][k] -= c * atom->rmass[i] * v[i][k];
      const bm::Quat q = quat(&node_[i][QW]);
      const bm::Vec3 wb = bm::qrot_t(q, vec(omega[i]));
      const bm::Vec3 tb{-c * node_[i][JB1] * wb.x, -c * node_[i][JB2] * wb.y, -c * node_[i][JB3] * wb.z};
      add(torque[i], bm::qrot(q, tb));
    }
    if (torque_groupbit_ && (mask[i] & torque_groupbit_))
      for (int k = 0; k < 3; ++k) torque[i][k] += torque_[k];
  }
}

/* ----------------------------------------------------------------------
   explicit: velocity Verlet; rotation: body-frame angular momentum, half kick with the torque,
   free-rotor splitting (physics/beam.h free_rotation), half kick.
   implicit: nothing moves here; the whole step is done in final_integrate.
   Clamped nodes (keyword clamp) never move.
------------------------------------------------------------------------- */

void FixFiberBeam::initial_integrate(int) {
  if (implicit_) return;
  double **x = atom->x, **v = atom->v, **f = atom->f, **omega = atom->omega, **torque = atom->torque;
  double *rmass = atom->rmass;
  int *mask = atom->mask;
  for (int i = 0; i < atom->nlocal; ++i) {
    if (!(mask[i] & groupbit) || !is_node(i)) continue;
    if (clamp_groupbit_ && (mask[i] & clamp_groupbit_)) {
      for (int k = 0; k < 3; ++k) v[i][k] = omega[i][k] = 0.0;
      continue;
    }
    const double dtfm = dtf_ / rmass[i];
    for (int k = 0; k < 3; ++k) {
      v[i][k] += dtfm * f[i][k];
      x[i][k] += dtv_ * v[i][k];
    }
    double *p = node_[i];
    bm::Quat q = quat(&p[QW]);
    const bm::Vec3 J{p[JB1], p[JB2], p[JB3]};
    bm::Vec3 Lb = bm::hadamard(J, bm::qrot_t(q, vec(omega[i]))) + dtf_ * bm::qrot_t(q, vec(torque[i]));
    bm::free_rotation(dtv_, J, q, Lb);
    p[QW] = q.w; p[QX] = q.x; p[QY] = q.y; p[QZ] = q.z;
    put(omega[i], bm::qrot(q, {Lb.x / J.x, Lb.y / J.y, Lb.z / J.z}));
  }
}

void FixFiberBeam::final_integrate() {
  if (implicit_) {
    implicit_step();
    return;
  }
  double **v = atom->v, **f = atom->f, **omega = atom->omega, **torque = atom->torque;
  double *rmass = atom->rmass;
  int *mask = atom->mask;
  for (int i = 0; i < atom->nlocal; ++i) {
    if (!(mask[i] & groupbit) || !is_node(i)) continue;
    if (clamp_groupbit_ && (mask[i] & clamp_groupbit_)) {
      for (int k = 0; k < 3; ++k) v[i][k] = omega[i][k] = 0.0;
      continue;
    }
    const double dtfm = dtf_ / rmass[i];
    for (int k = 0; k < 3; ++k) v[i][k] += dtfm * f[i][k];
    const double *p = node_[i];
    const bm::Quat q = quat(&p[QW]);
    const bm::Vec3 J{p[JB1], p[JB2], p[JB3]};
    const bm::Vec3 Lb = bm::hadamard(J, bm::qrot_t(q, vec(omega[i]))) + dtf_ * bm::qrot_t(q, vec(torque[i]));
    put(omega[i], bm::qrot(q, {Lb.x / J.x, Lb.y / J.y, Lb.z / J.z}));
  }
}

/* ----------------------------------------------------------------------
   implicit step. Each fiber is solved in one place: the rank that owns its node 0 (the "owner").
   Every rank sends the records of its fiber nodes to the owners (MPI_Alltoallv), the owners run
   the generalized-alpha Newton solve (physics/implicit_rod.h) on whole fibers in node order (so the
   result does not depend on the decomposition), and send the new states back. No ghost reach
   beyond one element is needed; the cost is two all-to-all exchanges per step.
------------------------------------------------------------------------- */

namespace {
// send record layout
enum SendCol {
  S_TAG = 0, S_FID, S_IDX, S_CNT, S_X, S_Q = S_X + 3, S_V = S_Q + 4, S_W = S_V + 3, S_ACC = S_W + 3,
  S_M = S_ACC + 12, S_J, S_F = S_J + 3, S_T = S_F + 3, S_D = S_T + 3, S_FIXED = S_D + 6, S_ACCOK, S_SCALE,
  S_RECT, S_HASREF = S_RECT + 2, S_L0, S_G0, S_K0 = S_G0 + 3, S_CG = S_K0 + 3, S_CK = S_CG + 3, S_SRC = S_CK + 3, S_SPLIT, S_N = S_SPLIT + 2
};
// return record layout
enum RecvCol { R_TAG = 0, R_DX, R_Q = R_DX + 3, R_V = R_Q + 4, R_W = R_V + 3, R_ACC = R_W + 3, R_FI = R_ACC + 12,
  R_TI = R_FI + 3, R_SPLIT = R_TI + 3, R_N = R_SPLIT + 2 };
}  // namespace

/* ----------------------------------------------------------------------
   The return exchange's first collective. A rank without a fiber or cluster to solve waits here
   for the ranks that solve theirs: once a sheet forms it is one contact cluster, solved by one
   rank, and the others wait for most of the step. Polling would keep their cores busy, which on
   virtual CPUs that share a physical core slows the solving rank (docs/bench/machine.md), so they
   sleep between polls (coupling/layer/patient_wait.h): 50 us of polling first (short waits stay
   fast), then naps of 10 us doubling up to 0.5 % of the last step period (at most 1 ms), so a
   rank that waits for a sleeping one is late by at most that (docs/bench/laydown.md, "The waiting
   rank sleeps"). The data exchanged are the same.
------------------------------------------------------------------------- */

void FixFiberBeam::wait_for_solvers(MPI_Request *req) {
  const double now = fiberform::coupling::clock_s();
  if (last_return_s_ > 0.0) step_period_s_ = now - last_return_s_;
  last_return_s_ = now;
  fiberform::coupling::Patience how;
  how.spin_s = 50e-6;
  how.nap_min_s = 10e-6;
  how.nap_max_s = std::clamp(0.005 * step_period_s_, 10e-6, 1e-3);
  fiberform::coupling::patient_wait(req, 1, how);
}

void FixFiberBeam::update_owners() {
  int maxfid = -1;
  for (int i = 0; i < atom->nlocal; ++i)
    if ((atom->mask[i] & groupbit) && is_node(i)) maxfid = std::max(maxfid, fiber_id(i));
  int gmax = -1;
  MPI_Allreduce(&maxfid, &gmax, 1, MPI_INT, MPI_MAX, world);
  std::vector<int> mine(static_cast<size_t>(gmax + 1), -1);
  for (int i = 0; i < atom->nlocal; ++i)
    if ((atom->mask[i] & groupbit) && is_node(i) && node_index(i) == 0) mine[fiber_id(i)] = comm->me;
  owner_.assign(mine.size(), -1);
  if (!mine.empty())
    MPI_Allreduce(mine.data(), owner_.data(), static_cast<int>(mine.size()), MPI_INT, MPI_MAX, world);
  owners_valid_ = true;
}

void FixFiberBeam::implicit_step() {
  if (!owners_valid_) update_owners();
  const int nlocal = atom->nlocal, nprocs = comm->nprocs;
  double **x = atom->x, **v = atom->v, **f = atom->f, **omega = atom->omega, **torque = atom->torque;
  int *mask = atom->mask;
  const double dt = update->dt;

  // ---- pack node records per destination
  scount_.assign(nprocs, 0);
  std::vector<int> dest(static_cast<size_t>(nlocal), -1);
  for (int i = 0; i < nlocal; ++i) {
    if (!(mask[i] & groupbit) || !is_node(i)) continue;
    const int fid = fiber_id(i);
    const int o = fid < static_cast<int>(owner_.size()) ? owner_[fid] : -1;
    const int c = fid < static_cast<int>(cluster_.size()) ? cluster_[fid] : fid;  // solved with its cluster
    const int oc = c >= 0 && c < static_cast<int>(owner_.size()) ? owner_[c] : -1;
    if (o < 0) {
      static char buf[256];
      std::snprintf(buf, sizeof buf, "fix fiber/beam: node %d of fiber %d has no owner (node 0 of the fiber is "
                    "missing: fibers must be deleted whole)", atom->tag[i], fid);
      fiberform::fail_one(lmp, FLERR, buf);
    }
    dest[i] = oc >= 0 ? oc : o;
    scount_[dest[i]] += S_N;
  }
  sdispl_.assign(nprocs, 0);
  for (int r = 1; r < nprocs; ++r) sdispl_[r] = sdispl_[r - 1] + scount_[r - 1];
  sendbuf_.assign(static_cast<size_t>(sdispl_[nprocs - 1] + scount_[nprocs - 1]), 0.0);
  {
    std::vector<int> fill(sdispl_);
    for (int i = 0; i < nlocal; ++i) {
      if (dest[i] < 0) continue;
      double *b = &sendbuf_[fill[dest[i]]];
      fill[dest[i]] += S_N;
      const double *p = node_[i];
      b[S_TAG] = atom->tag[i];
      b[S_FID] = p[FID];
      b[S_IDX] = p[IDX];
      b[S_CNT] = p[CNT];
      for (int k = 0; k < 3; ++k) {
        b[S_X + k] = x[i][k];
        b[S_V + k] = v[i][k];
        b[S_F + k] = f[i][k] - p[FIX + k];
        b[S_T + k] = torque[i][k] - p[TIX + k];
        b[S_J + k] = p[JB1 + k];
        b[S_G0 + k] = p[G0X + k];
        b[S_K0 + k] = p[K0X + k];
        b[S_CG + k] = p[CGX + k];
        b[S_CK + k] = p[CKX + k];
      }
      for (int k = 0; k < 4; ++k) b[S_Q + k] = p[QW + k];
      const bm::Vec3 Wb = bm::qrot_t(quat(&p[QW]), vec(omega[i]));
      b[S_W] = Wb.x; b[S_W + 1] = Wb.y; b[S_W + 2] = Wb.z;
      for (int k = 0; k < 12; ++k) b[S_ACC + k] = p[AX + k];
      for (int k = 0; k < 6; ++k) b[S_D + k] = p[DJ0 + k];
      b[S_M] = atom->rmass[i];
      b[S_FIXED] = (clamp_groupbit_ && (mask[i] & clamp_groupbit_)) ? 1.0 : 0.0;
      b[S_ACCOK] = p[ACCOK];
      b[S_SCALE] = contact_radius(i);
      b[S_RECT] = contact_rect(i) ? p[A1] : 0.0;
      b[S_RECT + 1] = contact_rect(i) ? p[A2] : 0.0;
      b[S_HASREF] = p[HASREF];
      b[S_L0] = p[L0];
      b[S_SRC] = comm->me;
      b[S_SPLIT] = p[SPLD];
      b[S_SPLIT + 1] = p[SPLN];
    }
  }
  if (nprocs == 1) {
    // one rank: the records are already where they are solved (the same bytes as the exchange)
    std::swap(recvbuf_, sendbuf_);
  } else {
    rcount_.assign(nprocs, 0);
    MPI_Alltoall(scount_.data(), 1, MPI_INT, rcount_.data(), 1, MPI_INT, world);
    rdispl_.assign(nprocs, 0);
    for (int r = 1; r < nprocs; ++r) rdispl_[r] = rdispl_[r - 1] + rcount_[r - 1];
    recvbuf_.assign(static_cast<size_t>(rdispl_[nprocs - 1] + rcount_[nprocs - 1]), 0.0);
    MPI_Alltoallv(sendbuf_.data(), scount_.data(), sdispl_.data(), MPI_DOUBLE, recvbuf_.data(), rcount_.data(),
                  rdispl_.data(), MPI_DOUBLE, world);
  }

  // ---- group the received records by fiber, in node order
  const size_t nrec = recvbuf_.size() / S_N;
  std::map<int, std::vector<const double *>> fibers;
  for (size_t r = 0; r < nrec; ++r) {
    const double *b = &recvbuf_[r * S_N];
    auto &vecf = fibers[static_cast<int>(b[S_FID])];
    if (vecf.empty()) vecf.assign(static_cast<size_t>(b[S_CNT]), nullptr);
    const int idx = static_cast<int>(b[S_IDX]);
    if (idx < 0 || idx >= static_cast<int>(vecf.size())) fiberform::fail_one(lmp, FLERR, "fix fiber/beam: bad node index");
    vecf[idx] = b;
  }
  const rod::GenAlpha ga = rod::gen_alpha(rho_inf_);
  rod::Options opt;
  opt.tol = newton_tol_;
  opt.max_iter = newton_max_;
  opt.max_split = max_split_;
  opt.t_damp = t_damp_;
  opt.tau_drag = tau_drag_;
  opt.contact_at_end = contact_at_end_;
  opt.tangent_steps = tangent_steps_;
  opt.anderson = anderson_;
  opt.land_predict = land_predict_;
  if (!stepper_) stepper_ = std::make_unique<rod::Stepper>();
  if (!tangents_) tangents_ = std::make_unique<FiberTangents>();
  rod::Stepper &stepper = *stepper_;
  std::vector<rod::Node> &nodes = tangents_->nodes, &fnodes = tangents_->fnodes;
  std::vector<rod::Element> &elems = tangents_->elems, &felems = tangents_->felems;
  std::vector<bm::Vec3> &starts = tangents_->starts;
  // return records, per source rank
  std::vector<std::vector<double>> &back = tangents_->back;
  back.resize(static_cast<size_t>(nprocs));
  for (std::vector<double> &b : back) b.clear();
  energy_local_ = 0;
  dissipation_local_ = 0;
  for (int k = 0; k < 5; ++k) stat_local_[k] = 0;
  start_depth_local_ = 0;
  // fibers solved together (contact clusters, set_clusters), each in ascending fiber ID
  std::map<int, std::vector<int>> clusters;
  for (const auto &kv : fibers) {
    const int fid = kv.first;
    clusters[fid < static_cast<int>(cluster_.size()) && cluster_[fid] >= 0 ? cluster_[fid] : fid].push_back(fid);
  }
  std::vector<int> &ids = tangents_->ids, &offsets = tangents_->offsets;
  std::vector<const double *> &recs = tangents_->recs;  // the record of every node of the cluster, in node order
  for (const auto &cl : clusters) {
    nodes.clear();
    elems.clear();
    ids.clear();
    offsets.clear();
    recs.clear();
    for (const int fid : cl.second) {
      const std::vector<const double *> &rec = fibers[fid];
      const size_t n = rec.size();
      for (size_t k = 0; k < n; ++k)
        if (!rec[k]) {
          static char buf[256];
          std::snprintf(buf, sizeof buf, "fix fiber/beam: fiber %d: node %d did not reach the fiber's owner rank "
                        "(fibers must be deleted whole)", fid, static_cast<int>(k));
          fiberform::fail_one(lmp, FLERR, buf);
        }
      fnodes.assign(n, rod::Node{});
      felems.assign(n > 0 ? n - 1 : 0, rod::Element{});
      bool need_init = false;
      for (size_t k = 0; k < n; ++k) {
        const double *b = rec[k];
        rod::Node &nd = fnodes[k];
        nd.x = {b[S_X], b[S_X + 1], b[S_X + 2]};
        if (k > 0) {  // unwrap periodic images: each node next to the previous one
          double d[3] = {nd.x.x - rec[k - 1][S_X], nd.x.y - rec[k - 1][S_X + 1], nd.x.z - rec[k - 1][S_X + 2]};
          domain->minimum_image(d);
          nd.x = fnodes[k - 1].x + bm::Vec3{d[0], d[1], d[2]};
        }
        nd.q = {b[S_Q], b[S_Q + 1], b[S_Q + 2], b[S_Q + 3]};
        nd.v = {b[S_V], b[S_V + 1], b[S_V + 2]};
        nd.W = {b[S_W], b[S_W + 1], b[S_W + 2]};
        nd.ax = {b[S_ACC], b[S_ACC + 1], b[S_ACC + 2]};
        nd.aw = {b[S_ACC + 3], b[S_ACC + 4], b[S_ACC + 5]};
        nd.vdx = {b[S_ACC + 6], b[S_ACC + 7], b[S_ACC + 8]};
        nd.vdw = {b[S_ACC + 9], b[S_ACC + 10], b[S_ACC + 11]};
        nd.m = b[S_M];
        nd.J = {b[S_J], b[S_J + 1], b[S_J + 2]};
        nd.F = {b[S_F], b[S_F + 1], b[S_F + 2]};
        nd.T = {b[S_T], b[S_T + 1], b[S_T + 2]};
        for (int c = 0; c < 6; ++c) nd.D[c] = b[S_D + c];
        nd.fixed = b[S_FIXED] > 0.5;
        nd.scale = b[S_SCALE];
        nd.radius = b[S_SCALE];
        nd.rect[0] = b[S_RECT];
        nd.rect[1] = b[S_RECT + 1];
        if (b[S_ACCOK] < 0.5) need_init = true;
        if (k + 1 < n) {
          if (b[S_HASREF] < 0.5) fiberform::fail_one(lmp, FLERR, "fix fiber/beam: element without reference");
          rod::Element &el = felems[k];
          el.ref.L0 = b[S_L0];
          el.ref.gamma0 = {b[S_G0], b[S_G0 + 1], b[S_G0 + 2]};
          el.ref.kappa0 = {b[S_K0], b[S_K0 + 1], b[S_K0 + 2]};
          el.C.CG = {b[S_CG], b[S_CG + 1], b[S_CG + 2]};
          el.C.CK = {b[S_CK], b[S_CK + 1], b[S_CK + 2]};
        }
      }
      // consistent initial accelerations only when the step resolves every mode (physics/implicit_rod.h)
      if (need_init) stepper.initialise(fnodes, felems, opt, dt < dt_crit_[4]);
      if (!fnodes.empty()) fnodes.back().next = false;  // the fiber ends here
      ids.push_back(fid);
      offsets.push_back(static_cast<int>(nodes.size()));
      if (!nodes.empty()) elems.emplace_back();  // no element between two fibers
      nodes.insert(nodes.end(), fnodes.begin(), fnodes.end());
      elems.insert(elems.end(), felems.begin(), felems.end());
      recs.insert(recs.end(), rec.begin(), rec.end());
    }
    offsets.push_back(static_cast<int>(nodes.size()));
    const size_t n = nodes.size();
    starts.resize(n);
    for (size_t k = 0; k < n; ++k) starts[k] = nodes[k].x;
    for (rod::NodeForceModel *m : models_) m->begin_cluster(ids, offsets);
    // the fiber's (cluster's) held tangent; none kept with tangent_steps 1
    rod::Tangent *held = nullptr;
    if (tangent_steps_ > 1) {
      FiberTangents::Entry &entry = tangents_->map[ids];
      entry.used = update->ntimestep;
      held = &entry.tangent;
    }
    // split memory: the cluster starts at its deepest fiber's remembered depth (physics/implicit_rod.h)
    rod::SplitMemory mem;
    if (split_memory_ > 0) {
      mem = {static_cast<int>(recs[0][S_SPLIT]), static_cast<int>(recs[0][S_SPLIT + 1])};
      for (size_t f = 1; f + 1 < offsets.size(); ++f) {
        const double *b0 = recs[static_cast<size_t>(offsets[f])];
        mem = rod::merge_split(mem, {static_cast<int>(b0[S_SPLIT]), static_cast<int>(b0[S_SPLIT + 1])});
      }
      mem.depth = std::min(mem.depth, max_split_);
      start_depth_local_ = std::max(start_depth_local_, static_cast<double>(mem.depth));
    }
    const rod::Stats st = stepper.step(nodes, elems, dt, ga, opt, &models_, held, mem.depth);
    const rod::SplitMemory next = rod::remember_split(mem, st.start_failed, split_memory_);
    if (!st.ok) {
      double amax = 0, vmax = 0;
      int kmax = 0;
      for (size_t k = 0; k < n; ++k) {
        const double a = bm::norm(nodes[k].F) / nodes[k].m;
        if (a > amax) amax = a, kmax = static_cast<int>(k);
        vmax = std::max(vmax, bm::norm(nodes[k].v));
      }
      const size_t f = static_cast<size_t>(std::upper_bound(offsets.begin(), offsets.end(), kmax) - offsets.begin()) - 1;
      static char buf[768];
      std::snprintf(buf, sizeof buf,
                    "fix fiber/beam: the implicit step of fiber %d (solved with %d fiber(s) in contact) did not "
                    "converge at step %ld, even split into 2^%d sub-steps (newton_tol %g, newton_max %d); largest "
                    "external force per mass %.3g m/s2 (fiber %d node %d), largest node speed %.3g m/s. Look for an "
                    "excessive external force (contact, drag) on this fiber, or reduce the timestep; see "
                    "docs/styles/fix_fiber_beam.md",
                    ids.front(), static_cast<int>(ids.size()), static_cast<long>(update->ntimestep), max_split_,
                    newton_tol_, newton_max_, amax, ids[f], kmax - offsets[f], vmax);
      fiberform::fail_one(lmp, FLERR, buf);
    }
    energy_local_ += st.energy;
    dissipation_local_ += st.dissipation;
    stat_local_[0] += st.iterations * static_cast<double>(ids.size());  // per fiber: each took part in all
    stat_local_[1] += static_cast<double>(ids.size());
    stat_local_[2] += st.splits;
    stat_local_[3] = std::max(stat_local_[3], static_cast<double>(st.iterations));
    stat_local_[4] += st.tangents * static_cast<double>(ids.size());
    stat_run_[0] += st.iterations * static_cast<double>(ids.size());
    stat_run_[1] += static_cast<double>(ids.size());
    stat_run_[2] += st.tangents * static_cast<double>(ids.size());
    stat_run_[3] += st.limited * static_cast<double>(ids.size());
    for (size_t k = 0; k < n; ++k) {
      const double *b = recs[k];
      const rod::Node &nd = nodes[k];
      std::vector<double> &out = back[static_cast<size_t>(b[S_SRC])];
      const size_t o = out.size();
      out.resize(o + R_N);
      double *r = &out[o];
      r[R_TAG] = b[S_TAG];
      const bm::Vec3 w = bm::qrot(nd.q, nd.W);
      for (int c = 0; c < 3; ++c) {
        // displacement from the unwrapped start, so that the owning rank keeps its periodic image
        r[R_DX + c] = nd.x[c] - starts[k][c];
        r[R_V + c] = nd.v[c];
        r[R_W + c] = w[c];
        r[R_FI + c] = nd.Fint[c];
        r[R_TI + c] = nd.Tint[c];
      }
      r[R_Q] = nd.q.w; r[R_Q + 1] = nd.q.x; r[R_Q + 2] = nd.q.y; r[R_Q + 3] = nd.q.z;
      const bm::Vec3 acc[4] = {nd.ax, nd.aw, nd.vdx, nd.vdw};
      for (int a = 0; a < 4; ++a)
        for (int c = 0; c < 3; ++c) r[R_ACC + 3 * a + c] = acc[a][c];
      r[R_SPLIT] = next.depth;
      r[R_SPLIT + 1] = next.calm;
    }
  }
  cluster_.clear();  // set again before every step
  // tangents of fibers (clusters) not solved in this step are dropped
  for (auto it = tangents_->map.begin(); it != tangents_->map.end();)
    it = it->second.used == update->ntimestep ? std::next(it) : tangents_->map.erase(it);
  // ---- return the new states (one rank: they are here already)
  std::vector<double> &brecv = tangents_->brecv;
  if (nprocs == 1) {
    brecv.swap(back[0]);
  } else {
    std::vector<int> bcount(nprocs), bdispl(nprocs, 0), rc(nprocs), rd(nprocs, 0);
    for (int r = 0; r < nprocs; ++r) bcount[r] = static_cast<int>(back[r].size());
    for (int r = 1; r < nprocs; ++r) bdispl[r] = bdispl[r - 1] + bcount[r - 1];
    std::vector<double> bsend(static_cast<size_t>(bdispl[nprocs - 1] + bcount[nprocs - 1]));
    for (int r = 0; r < nprocs; ++r) std::copy(back[r].begin(), back[r].end(), bsend.begin() + bdispl[r]);
    MPI_Request req;
    MPI_Ialltoall(bcount.data(), 1, MPI_INT, rc.data(), 1, MPI_INT, world, &req);
    wait_for_solvers(&req);
    for (int r = 1; r < nprocs; ++r) rd[r] = rd[r - 1] + rc[r - 1];
    brecv.resize(static_cast<size_t>(rd[nprocs - 1] + rc[nprocs - 1]));
    MPI_Alltoallv(bsend.data(), bcount.data(), bdispl.data(), MPI_DOUBLE, brecv.data(), rc.data(), rd.data(),
                  MPI_DOUBLE, world);
  }
  for (size_t o = 0; o + R_N <= brecv.size(); o += R_N) {
    const double *r = &brecv[o];
    const int i = atom->map(static_cast<int>(r[R_TAG]));
    if (i < 0 || i >= nlocal) fiberform::fail_one(lmp, FLERR, "fix fiber/beam: returned node is not owned here");
    double *p = node_[i];
    for (int c = 0; c < 3; ++c) {
      x[i][c] += r[R_DX + c];
      v[i][c] = r[R_V + c];
      omega[i][c] = r[R_W + c];
      p[FIX + c] = r[R_FI + c];
      p[TIX + c] = r[R_TI + c];
    }
    for (int c = 0; c < 4; ++c) p[QW + c] = r[R_Q + c];
    for (int c = 0; c < 12; ++c) p[AX + c] = r[R_ACC + c];
    p[ACCOK] = 1.0;
    for (int c = 0; c < 6; ++c) p[DJ0 + c] = 0.0;
    p[SPLD] = r[R_SPLIT];
    p[SPLN] = r[R_SPLIT + 1];
  }
}

/* ----------------------------------------------------------------------
   global output: scalar = elastic energy (J). vector (1-based in f_ID[n]):
   1 elastic energy, 2 translational kinetic energy, 3 rotational kinetic energy (with the node
   inertia of this fix), 4 total, 5 damping power (W), 6 critical step (min), 7-10 critical steps
   axial, shear, bending, torsion, 11 stiffness_scale, 12 inertia_scale, 13 damping time,
   14 mean Newton iterations per fiber in the last step, 15 largest Newton iterations of a fiber in
   the last step, 16 sub-step splits in the last step (implicit), 17 rho_inf (-1: explicit),
   18 mean tangent formations (factorisations) per fiber in the last step, 19 and 20 mean Newton
   iterations and tangent formations per fiber and step since the fix was created, 21 mean Newton
   iterations per fiber and step whose correction a contact model's limiter shortened (landings,
   docs/models/contact.md section 8), since the fix was created, 22 deepest start depth of a fiber
   or cluster in the last step (split memory: the step started as 2^depth sub-steps)
------------------------------------------------------------------------- */

double FixFiberBeam::compute_scalar() {
  double all = 0;
  MPI_Allreduce(&energy_local_, &all, 1, MPI_DOUBLE, MPI_SUM, world);
  return all;
}

double FixFiberBeam::compute_vector(int n) {
  if (n == 0) return compute_scalar();
  if (n == 1 || n == 2 || n == 3) {
    double ke[3] = {0, 0, 0}, all[3];
    ke[0] = energy_local_;
    for (int i = 0; i < atom->nlocal; ++i) {
      if (!(atom->mask[i] & groupbit) || !is_node(i)) continue;
      const double *vi = atom->v[i];
      ke[1] += 0.5 * atom->rmass[i] * (vi[0] * vi[0] + vi[1] * vi[1] + vi[2] * vi[2]);
      const bm::Vec3 wb = bm::qrot_t(quat(&node_[i][QW]), vec(atom->omega[i]));
      ke[2] += 0.5 * (node_[i][JB1] * wb.x * wb.x + node_[i][JB2] * wb.y * wb.y + node_[i][JB3] * wb.z * wb.z);
    }
    MPI_Allreduce(ke, all, 3, MPI_DOUBLE, MPI_SUM, world);
    if (n == 3) return all[0] + all[1] + all[2];
    return all[n];
  }
  if (n == 4) {
    double all = 0;
    MPI_Allreduce(&dissipation_local_, &all, 1, MPI_DOUBLE, MPI_SUM, world);
    return all;
  }
  if (n == 5) return dt_crit_[4];
  if (n >= 6 && n <= 9) return dt_crit_[n - 6];
  if (n == 10) return stiff_scale_;
  if (n == 11) return inertia_scale_;
  if (n == 12) return t_damp_;
  if ((n >= 13 && n <= 15) || n == 17) {
    // Newton iterations per fiber in the last step, largest per fiber, sub-step splits in the last
    // step, tangent formations per fiber in the last step
    double loc[4] = {stat_local_[0], stat_local_[1], stat_local_[2], stat_local_[4]}, all[4];
    MPI_Allreduce(loc, all, 4, MPI_DOUBLE, MPI_SUM, world);
    if (n == 13) return all[1] > 0 ? all[0] / all[1] : 0.0;
    if (n == 17) return all[1] > 0 ? all[3] / all[1] : 0.0;
    if (n == 15) return all[2];
    double mx = stat_local_[3], gmx = 0;
    MPI_Allreduce(&mx, &gmx, 1, MPI_DOUBLE, MPI_MAX, world);
    return gmx;
  }
  if (n == 16) return implicit_ ? rho_inf_ : -1.0;
  if (n == 21) {
    double gmx = 0;
    MPI_Allreduce(&start_depth_local_, &gmx, 1, MPI_DOUBLE, MPI_MAX, world);
    return gmx;
  }
  if (n == 18 || n == 19 || n == 20) {
    double all[4];
    MPI_Allreduce(stat_run_, all, 4, MPI_DOUBLE, MPI_SUM, world);
    return all[1] > 0 ? all[n == 18 ? 0 : (n == 19 ? 2 : 3)] / all[1] : 0.0;
  }
  return 0.0;
}

int FixFiberBeam::modify_param(int narg, char **arg) {
  if (narg >= 2 && std::strcmp(arg[0], "damping") == 0) {
    t_damp_ = force->numeric(FLERR, arg[1]);
    if (!(t_damp_ >= 0)) error->all(FLERR, "fix_modify fiber/beam damping: must be >= 0");
    return 2;
  }
  if (narg >= 2 && std::strcmp(arg[0], "drag") == 0) {
    tau_drag_ = force->numeric(FLERR, arg[1]);
    if (!(tau_drag_ >= 0)) error->all(FLERR, "fix_modify fiber/beam drag: must be >= 0");
    return 2;
  }
  if (narg >= 2 && std::strcmp(arg[0], "torque") == 0) {
    if (narg < 5) error->all(FLERR, "fix_modify fiber/beam torque: expected group Tx Ty Tz");
    const int ig = group->find(arg[1]);
    if (ig < 0) error->all(FLERR, "fix_modify fiber/beam torque: unknown group");
    torque_groupbit_ = group->bitmask[ig];
    for (int k = 0; k < 3; ++k) torque_[k] = force->numeric(FLERR, arg[2 + k]);
    return 5;
  }
  return 0;
}

/* ---------------------------------------------------------------------- 
   per-atom state that moves with atoms
------------------------------------------------------------------------- */

void FixFiberBeam::grow_arrays(int nmax) {
  memory->grow(node_, nmax, NCOL, "fiber/beam:node");
  array_atom = node_;
}

void FixFiberBeam::copy_arrays(int i, int j, int) {
  for (int k = 0; k < NCOL; ++k) node_[j][k] = node_[i][k];
}

void FixFiberBeam::set_arrays(int i) {
  for (int k = 0; k < NCOL; ++k) node_[i][k] = 0.0;
  node_[i][FID] = -1.0;
  node_[i][QW] = node_[i][Q0W] = 1.0;
  node_[i][JB1] = node_[i][JB2] = node_[i][JB3] = 1.0;
}

int FixFiberBeam::pack_exchange(int i, double *buf) {
  for (int k = 0; k < NCOL; ++k) buf[k] = node_[i][k];
  return NCOL;
}

int FixFiberBeam::unpack_exchange(int nlocal, double *buf) {
  for (int k = 0; k < NCOL; ++k) node_[nlocal][k] = buf[k];
  return NCOL;
}

int FixFiberBeam::pack_restart(int i, double *buf) {
  buf[0] = NCOL + 1;
  for (int k = 0; k < NCOL; ++k) buf[k + 1] = node_[i][k];
  return NCOL + 1;
}

void FixFiberBeam::unpack_restart(int nlocal, int nth) {
  double **extra = atom->extra;
  int m = 0;
  for (int k = 0; k < nth; ++k) m += static_cast<int>(extra[nlocal][m]);
  // restart files written before the split memory columns (SPLD, SPLN) hold fewer: those start at 0
  const int stored = static_cast<int>(extra[nlocal][m]) - 1;
  ++m;
  for (int k = 0; k < NCOL; ++k) node_[nlocal][k] = k < stored ? extra[nlocal][m++] : 0.0;
}

int FixFiberBeam::size_restart(int) { return NCOL + 1; }
int FixFiberBeam::maxsize_restart() { return NCOL + 1; }

void FixFiberBeam::write_restart(FILE *fp) {
  const double list[2] = {static_cast<double>(ref_done_), max_elem_len_};
  fiberform::write_global_restart(lmp, fp, list, 2);
}

void FixFiberBeam::restart(char *buf) {
  const double *list = reinterpret_cast<double *>(buf);
  ref_done_ = static_cast<int>(list[0]);
  max_elem_len_ = std::fmax(max_elem_len_, list[1]);
}

int FixFiberBeam::pack_comm(int n, int *list, double *buf, int, int *) {
  int m = 0;
  if (comm_mode_ == 1) {
    for (int ii = 0; ii < n; ++ii) {
      const int j = list[ii];
      for (int k = 0; k < NSTATIC; ++k) buf[m++] = node_[j][k];
    }
  } else {
    double **v = atom->v, **omega = atom->omega;
    for (int ii = 0; ii < n; ++ii) {
      const int j = list[ii];
      for (int k = 0; k < 4; ++k) buf[m++] = node_[j][QW + k];
      for (int k = 0; k < 3; ++k) buf[m++] = v[j][k];
      for (int k = 0; k < 3; ++k) buf[m++] = omega[j][k];
    }
  }
  // LIGGGHTS 3.8 (LAMMPS 2013 convention): pack_comm returns the number of values PER ATOM
  return comm_mode_ == 1 ? static_cast<int>(NSTATIC) : kDynamicComm;
}

void FixFiberBeam::unpack_comm(int n, int first, double *buf) {
  int m = 0;
  const int last = first + n;
  if (comm_mode_ == 1) {
    for (int i = first; i < last; ++i)
      for (int k = 0; k < NSTATIC; ++k) node_[i][k] = buf[m++];
  } else {
    double **v = atom->v, **omega = atom->omega;
    for (int i = first; i < last; ++i) {
      for (int k = 0; k < 4; ++k) node_[i][QW + k] = buf[m++];
      for (int k = 0; k < 3; ++k) v[i][k] = buf[m++];
      for (int k = 0; k < 3; ++k) omega[i][k] = buf[m++];
    }
  }
}

double FixFiberBeam::memory_usage() {
  return static_cast<double>(atom->nmax) * NCOL * sizeof(double) + static_cast<double>(nmax_acc_) * 12 * sizeof(double);
}
