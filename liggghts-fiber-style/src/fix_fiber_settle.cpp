/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/settle: see fix_fiber_settle.h and docs/styles/fix_fiber_settle.md. */
#include "fix_fiber_settle.h"

#include "style_args.h"

#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "atom.h"
#include "comm.h"
#include "error.h"
#include "fix_fiber_beam.h"
#include "physics/settle.h"

using namespace LAMMPS_NS;
using namespace FixConst;

FixFiberSettle::FixFiberSettle(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg) {
  vector_flag = 1;
  size_vector = 2;
  restart_global = 1;  // the count of consecutive settled checks survives a restart
  global_freq = 1;
  extvector = 0;
  const char *style = "fix fiber/settle";
  if (narg < 5) error->all(FLERR, "fix fiber/settle: expected 'fix ID group fiber/settle V M [keyword value ...]'");
  speed_ = fiberform::parse_finite(error, style, "V", arg[3]);
  if (!(speed_ > 0.0)) error->all(FLERR, "fix fiber/settle: needs V > 0 (m/s)");
  nevery = static_cast<int>(fiberform::parse_count(error, style, "M", arg[4], 1, 2000000000));
  int iarg = 5;
  while (iarg < narg) {
    const std::string kw = arg[iarg];
    if (iarg + 1 >= narg) error->all(FLERR, fiberform::error_text(std::string(style) + ": " + kw + " needs a value"));
    const std::string val = arg[iarg + 1];
    if (kw == "measure") {
      if (val == "node") by_fiber_ = false;
      else if (val == "fiber") by_fiber_ = true;
      else error->all(FLERR, "fix fiber/settle: measure must be node or fiber");
    } else if (kw == "mass_fraction") {
      fraction_ = fiberform::parse_finite(error, style, kw, arg[iarg + 1]);
      if (!(fraction_ > 0.0 && fraction_ <= 1.0)) error->all(FLERR, "fix fiber/settle: mass_fraction must be in (0, 1]");
    } else {
      error->all(FLERR, fiberform::error_text(std::string(style) + ": unknown keyword '" + kw +
                                              "' (see docs/styles/fix_fiber_settle.md)"));
    }
    iarg += 2;
  }
  if (fraction_ < 1.0 && !by_fiber_) error->all(FLERR, "fix fiber/settle: mass_fraction needs measure fiber");
}

int FixFiberSettle::setmask() { return END_OF_STEP; }

void FixFiberSettle::init() {
  beam_ = FixFiberBeam::find(lmp);
  if (by_fiber_ && !beam_) error->all(FLERR, "fix fiber/settle: measure fiber needs a fix fiber/beam (fiber IDs)");
  if (by_fiber_ && !atom->rmass_flag) error->all(FLERR, "fix fiber/settle: needs per-atom mass (atom_style sphere)");
}

/* Centre-of-mass velocity of each fiber (sums of m v and m by fiber ID over all ranks), then the
   speed below which fraction_ of the fiber mass moves (physics/settle.h). */
double FixFiberSettle::measure_fibers() const {
  int idmax = -1, gidmax = -1;
  for (int i = 0; i < atom->nlocal; ++i)
    if ((atom->mask[i] & groupbit) && beam_->is_node(i)) idmax = std::max(idmax, beam_->fiber_id(i));
  MPI_Allreduce(&idmax, &gidmax, 1, MPI_INT, MPI_MAX, world);
  if (gidmax < 0) return 0.0;
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
  return fiberform::physics::mass_fraction_speed(speed, mass, fraction_);
}

void FixFiberSettle::end_of_step() {
  if (by_fiber_) {
    measured_ = measure_fibers();
  } else {
    double vmax = 0.0;
    for (int i = 0; i < atom->nlocal; ++i) {
      if (!(atom->mask[i] & groupbit)) continue;
      const double *v = atom->v[i];
      vmax = std::max(vmax, v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    }
    MPI_Allreduce(&vmax, &measured_, 1, MPI_DOUBLE, MPI_MAX, world);
    measured_ = std::sqrt(measured_);
  }
  settled_checks_ = measured_ < speed_ ? settled_checks_ + 1.0 : 0.0;
}

/* Restart: the settle counter and the last measured speed, so that a resumed lay-down stops at the
   same check as an uninterrupted one. */
void FixFiberSettle::write_restart(FILE *fp) {
  const double list[2] = {settled_checks_, measured_};
  fiberform::write_global_restart(lmp, fp, list, 2);
}

void FixFiberSettle::restart(char *buf) {
  const double *list = reinterpret_cast<double *>(buf);
  settled_checks_ = list[0];
  measured_ = list[1];
}

/* 1 consecutive checks below V, 2 the speed measured at the last check (m/s). */
double FixFiberSettle::compute_vector(int n) { return n == 0 ? settled_checks_ : measured_; }
