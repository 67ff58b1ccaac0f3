/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/remove: see fix_fiber_remove.h and docs/styles/fix_fiber_remove.md. */
#include "fix_fiber_remove.h"

#include "style_args.h"

#include <mpi.h>

#include <algorithm>
#include <cstdio>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "atom.h"
#include "atom_vec.h"
#include "comm.h"
#include "error.h"
#include "fix_fiber_beam.h"
#include "update.h"

using namespace LAMMPS_NS;
using namespace FixConst;

FixFiberRemove::FixFiberRemove(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg) {
  vector_flag = 1;
  size_vector = 3;
  restart_global = 1;  // the removal accounting survives a restart
  global_freq = 1;
  extvector = 0;
  const char *style = "fix fiber/remove";
  bool have_z = false;
  int iarg = 3;
  while (iarg < narg) {
    const std::string kw = arg[iarg];
    if (iarg + 1 >= narg) error->all(FLERR, fiberform::error_text(std::string(style) + ": " + kw + " needs a value"));
    const double v = fiberform::parse_finite(error, style, kw, arg[iarg + 1]);
    if (kw == "below") {
      z_ = v;
      have_z = true;
    } else if (kw == "every") {
      every_ = static_cast<int>(fiberform::parse_count(error, style, kw, arg[iarg + 1], 1, 2000000000));
    } else {
      error->all(FLERR, fiberform::error_text(std::string(style) + ": unknown keyword '" + kw +
                                              "' (see docs/styles/fix_fiber_remove.md)"));
    }
    iarg += 2;
  }
  if (!have_z) error->all(FLERR, "fix fiber/remove: expected 'fix ID group fiber/remove below z [every N]'");
  force_reneighbor = 1;
  next_reneighbor = (update->ntimestep / every_) * every_ + every_;
}

int FixFiberRemove::setmask() { return PRE_EXCHANGE; }

void FixFiberRemove::init() {
  beam_ = FixFiberBeam::find(lmp);
  if (!beam_) error->all(FLERR, "fix fiber/remove: needs a fix fiber/beam (fiber IDs)");
  if (!atom->rmass_flag) error->all(FLERR, "fix fiber/remove: needs per-atom mass (atom_style sphere)");
}

/* Removal of whole fibers (all nodes) once any node is below z_; as LAMMPS fix evaporate: on a
   forced re-neighbouring step, before atoms migrate. The fibers to remove are gathered from every
   rank, so a fiber whose nodes sit on several ranks goes as a whole. */
void FixFiberRemove::pre_exchange() {
  if (update->ntimestep < next_reneighbor) return;
  next_reneighbor = update->ntimestep + every_;
  int nlocal = atom->nlocal;
  double **x = atom->x;
  std::vector<int> mine;
  for (int i = 0; i < nlocal; ++i)
    if ((atom->mask[i] & groupbit) && beam_->is_node(i) && x[i][2] < z_) mine.push_back(beam_->fiber_id(i));
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
  // (atom ID, mass) of every removed node, gathered and summed in atom-ID order: the removed mass
  // does not depend on how the nodes are spread over the ranks (bit for bit)
  std::vector<double> pairs;
  for (int i = nlocal - 1; i >= 0; --i) {
    if (!beam_->is_node(i) || !gone.count(beam_->fiber_id(i))) continue;
    pairs.push_back(static_cast<double>(atom->tag[i]));
    pairs.push_back(atom->rmass[i]);
    atom->avec->copy(nlocal - 1, i, 1);
    --nlocal;
  }
  atom->nlocal = nlocal;
  int npairs = static_cast<int>(pairs.size());
  MPI_Allgather(&npairs, 1, MPI_INT, counts.data(), 1, MPI_INT, world);
  total = 0;
  for (int p = 0; p < nprocs; ++p) {
    displs[p] = total;
    total += counts[p];
  }
  std::vector<double> every(static_cast<size_t>(total));
  MPI_Allgatherv(pairs.data(), npairs, MPI_DOUBLE, every.data(), counts.data(), displs.data(), MPI_DOUBLE, world);
  std::vector<std::pair<double, double>> by_id;
  for (size_t k = 0; k + 1 < every.size(); k += 2) by_id.emplace_back(every[k], every[k + 1]);
  std::sort(by_id.begin(), by_id.end());
  double mass = 0.0;
  for (const auto &tm : by_id) mass += tm.second;
  const double nodes = static_cast<double>(by_id.size());
  removed_mass_ += mass;
  removed_nodes_ += nodes;
  removed_fibers_ += static_cast<double>(gone.size());
  atom->natoms -= static_cast<bigint>(by_id.size());
  if (atom->map_style) {
    atom->nghost = 0;
    atom->map_init();
    atom->map_set();
  }
  if (comm->me == 0) {
    std::string msg = "fix fiber/remove: step " + std::to_string(update->ntimestep) + " removed fiber(s)";
    for (int id : gone) msg += " " + std::to_string(id);
    msg += "\n";
    if (screen) std::fputs(msg.c_str(), screen);
    if (logfile) std::fputs(msg.c_str(), logfile);
  }
}

/* Restart: the removal accounting, so that a resumed lay-down reports the same totals. */
void FixFiberRemove::write_restart(FILE *fp) {
  const double list[3] = {removed_fibers_, removed_mass_, removed_nodes_};
  fiberform::write_global_restart(lmp, fp, list, 3);
}

void FixFiberRemove::restart(char *buf) {
  const double *list = reinterpret_cast<double *>(buf);
  removed_fibers_ = list[0];
  removed_mass_ = list[1];
  removed_nodes_ = list[2];
}

/* 1 fibers removed, 2 their mass (kg), 3 their nodes: totals since the start (restart included). */
double FixFiberRemove::compute_vector(int n) {
  if (n == 0) return removed_fibers_;
  if (n == 1) return removed_mass_;
  return removed_nodes_;
}
