/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "pair_test_harmonic.h"

#include <mpi.h>

#include <cmath>

#include "abi_guard.h"
#include "atom.h"
#include "error.h"
#include "force.h"
#include "memory.h"
#include "neigh_list.h"
#include "neighbor.h"
#include "physics/harmonic.h"

using namespace LAMMPS_NS;

PairTestHarmonic::PairTestHarmonic(LAMMPS *lmp) : Pair(lmp) {}

PairTestHarmonic::~PairTestHarmonic() {
  if (allocated) {
    memory->destroy(setflag);
    memory->destroy(cutsq);
    memory->destroy(stiffness_);
  }
}

void PairTestHarmonic::allocate() {
  allocated = 1;
  const int n = atom->ntypes;
  memory->create(setflag, n + 1, n + 1, "pair:setflag");
  memory->create(cutsq, n + 1, n + 1, "pair:cutsq");
  memory->create(stiffness_, n + 1, n + 1, "pair:stiffness");
  for (int i = 1; i <= n; ++i)
    for (int j = i; j <= n; ++j) setflag[i][j] = 0;
}

void PairTestHarmonic::settings(int narg, char ** /*arg*/) {
  if (narg != 0) error->all(FLERR, "pair_style test/harmonic takes no arguments");
}

void PairTestHarmonic::coeff(int narg, char **arg) {
  if (narg != 3) error->all(FLERR, "pair_coeff for test/harmonic: expected 'pair_coeff I J K' (K in N/m)");
  if (!allocated) allocate();
  int ilo, ihi, jlo, jhi;
  force->bounds(arg[0], atom->ntypes, ilo, ihi);
  force->bounds(arg[1], atom->ntypes, jlo, jhi);
  const double k = force->numeric(FLERR, arg[2]);
  if (!(k > 0.0) || !std::isfinite(k))
    error->all(FLERR, "pair_coeff for test/harmonic: K (N/m) must be a finite number > 0");
  int count = 0;
  for (int i = ilo; i <= ihi; ++i)
    for (int j = (jlo > i ? jlo : i); j <= jhi; ++j) {
      stiffness_[i][j] = k;
      setflag[i][j] = 1;
      ++count;
    }
  if (count == 0) error->all(FLERR, "Incorrect args for pair coefficients");
}

void PairTestHarmonic::init_style() {
  if (!atom->radius_flag || !atom->rmass_flag)
    error->all(FLERR, "pair_style test/harmonic requires atom_style sphere (radius and mass per atom)");
  fiberform::check_atom_layout(lmp);
  double local = 0.0;
  for (int i = 0; i < atom->nlocal; ++i) local = std::fmax(local, atom->radius[i]);
  MPI_Allreduce(&local, &max_radius_, 1, MPI_DOUBLE, MPI_MAX, world);
  neighbor->request(this);
}

double PairTestHarmonic::init_one(int i, int j) {
  if (setflag[i][j] == 0) error->all(FLERR, "test/harmonic: all pair coeffs are not set");
  stiffness_[j][i] = stiffness_[i][j];
  return 2.0 * max_radius_;  // contact can only exist below the sum of the two largest radii
}

void PairTestHarmonic::compute(int eflag, int vflag) {
  if (eflag || vflag) ev_setup(eflag, vflag);
  else evflag = vflag_fdotr = 0;

  double **x = atom->x;
  double **f = atom->f;
  double *radius = atom->radius;
  int *type = atom->type;
  const int nlocal = atom->nlocal;
  const int newton_pair = force->newton_pair;

  for (int ii = 0; ii < list->inum; ++ii) {
    const int i = list->ilist[ii];
    const int *jlist = list->firstneigh[i];
    for (int jj = 0; jj < list->numneigh[i]; ++jj) {
      const int j = jlist[jj] & NEIGHMASK;
      const double dx = x[i][0] - x[j][0], dy = x[i][1] - x[j][1], dz = x[i][2] - x[j][2];
      const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
      const fiberform::physics::HarmonicContact c =
          fiberform::physics::harmonic_contact(stiffness_[type[i]][type[j]], radius[i] + radius[j], r);
      if (c.force == 0.0) continue;
      const double fpair = c.force / r;  // force on i along (x_i - x_j), divided by r
      f[i][0] += dx * fpair;
      f[i][1] += dy * fpair;
      f[i][2] += dz * fpair;
      if (newton_pair || j < nlocal) {
        f[j][0] -= dx * fpair;
        f[j][1] -= dy * fpair;
        f[j][2] -= dz * fpair;
      }
      if (evflag) ev_tally(i, j, nlocal, newton_pair, c.energy, 0.0, fpair, dx, dy, dz);
    }
  }
  if (vflag_fdotr) virial_fdotr_compute();
}
