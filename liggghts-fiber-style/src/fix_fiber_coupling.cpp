/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/coupling: see fix_fiber_coupling.h and docs/styles/fix_fiber_coupling.md. */
#include "fix_fiber_coupling.h"

#include <mpi.h>

#include <cstring>
#include <stdexcept>
#include <string>

#include "atom.h"
#include "comm.h"
#include "coupling_layer.h"
#include "error.h"
#include "fix_fiber_drag.h"
#include "modify.h"
#include "style_args.h"
#include "update.h"

using namespace LAMMPS_NS;
using namespace FixConst;
namespace cpl = fiberform::coupling;
namespace flow = fiberform::physics::flow;

namespace {
constexpr const char *kSelf = "fiberdem";
constexpr const char *kPartner = "fiberPimpleFoam";
}  // namespace

FixFiberCoupling::FixFiberCoupling(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg) {
  vector_flag = 1;
  size_vector = 6;
  global_freq = 1;
  extvector = 0;
  timeout_ = cpl::kDefaultTimeout;
  int iarg = 3;
  while (iarg < narg) {
    const std::string kw = arg[iarg];
    if (iarg + 1 >= narg)
      error->all(FLERR, fiberform::error_text("fix fiber/coupling: " + kw + " needs a value"));
    const std::string val = arg[iarg + 1];
    if (kw == "drag") {
      drag_id_ = val;
    } else if (kw == "interval") {
      const double v = fiberform::parse_finite(error, "fix fiber/coupling", "interval", arg[iarg + 1]);
      if (!(v >= 1.0 && v <= 1e9) || v != static_cast<double>(static_cast<std::int64_t>(v)))
        error->all(FLERR, fiberform::error_text("fix fiber/coupling: interval must be a whole number of "
                                                "fiber steps in [1, 1e9], got '" + val + "'"));
      interval_ = static_cast<std::int64_t>(v);
    } else if (kw == "reaction") {
      if (val != "yes" && val != "no") error->all(FLERR, "fix fiber/coupling: reaction: expected yes or no");
      reaction_ = val == "yes";
    } else if (kw == "kernel") {
      if (val != "cell" && val != "trilinear")
        error->all(FLERR, "fix fiber/coupling: kernel: expected cell or trilinear");
      kernel_ = val == "cell" ? flow::Kernel::Cell : flow::Kernel::Trilinear;
    } else if (kw == "timeout") {
      timeout_ = fiberform::parse_finite(error, "fix fiber/coupling", "timeout", arg[iarg + 1]);
      if (!(timeout_ > 0.0 && timeout_ <= 1e6))
        error->all(FLERR, "fix fiber/coupling: timeout must be in (0, 1e6] s");
    } else {
      error->all(FLERR, fiberform::error_text("fix fiber/coupling: unknown keyword '" + kw +
                                              "' (drag, interval, reaction, kernel, timeout)"));
    }
    iarg += 2;
  }
  if (drag_id_.empty()) error->all(FLERR, "fix fiber/coupling: the keyword 'drag DRAG_ID' is required");
  if (interval_ < 1) error->all(FLERR, "fix fiber/coupling: the keyword 'interval N' is required");

  const cpl::Session &s = cpl::session();
  if (!s.started)
    error->all(FLERR, "fix fiber/coupling: the coupling layer was not started: run the input with "
                      "fiberdem (not liggghts with the preload shim)");
  if (s.inter == MPI_COMM_NULL)
    error->all(FLERR, fiberform::error_text(
                          "fix fiber/coupling: no coupling partner: fiberdem was started alone. Start "
                          "both programs under one mpirun: mpirun -np A fiberdem -in IN : -np B "
                          "fiberPimpleFoam -coupled -case DIR (docs/coupling/launch.md)"));
}

FixFiberCoupling::~FixFiberCoupling() {
  if (channel_) {
    if (steps_ > 0 && screen)
      std::fprintf(screen, "fix fiber/coupling: the last %lld step(s) after the last exchange were not "
                           "sent to the fluid (run lengths that are multiples of interval avoid this)\n",
                   static_cast<long long>(steps_));
    if (screen)  // bench/coupling reads this line
      std::fprintf(screen, "fix fiber/coupling: %lld exchanges, wall time (s, rank 0): coupling work "
                           "%.6g, waiting for the fluid %.6g\n",
                   static_cast<long long>(stats_[0]), work_s_, wait_s_);
    channel_->send(cpl::Kind::Finish);
  }
}

int FixFiberCoupling::setmask() { return END_OF_STEP; }

void FixFiberCoupling::init() {
  const int idrag = modify->find_fix(drag_id_.c_str());
  if (idrag < 0)
    error->all(FLERR, fiberform::error_text("fix fiber/coupling: drag: no fix with ID '" + drag_id_ + "'"));
  if (std::strcmp(modify->fix[idrag]->style, "fiber/drag") != 0)
    error->all(FLERR, fiberform::error_text("fix fiber/coupling: drag: fix '" + drag_id_ +
                                            "' is not a fix fiber/drag"));
  drag_ = static_cast<FixFiberDrag *>(modify->fix[idrag]);
  if (!atom->rmass_flag || atom->map_style == 0)
    error->all(FLERR, "fix fiber/coupling: needs atom_style sphere and 'atom_modify map array'");
  if (!connected_) {
    handshake();
    connected_ = true;
  } else if (update->dt != dt_) {
    error->all(FLERR, "fix fiber/coupling: the timestep changed during a coupled run (the fluid step "
                      "is fixed at the handshake)");
  }
}

void FixFiberCoupling::handshake() {
  dt_ = update->dt;
  const bool leader = comm->me == 0;
  std::vector<double> mesh_payload;
  if (leader) {
    channel_ = std::make_unique<cpl::Channel>(cpl::session().inter, timeout_, kSelf, kPartner);
    cpl::exchange_hello(*channel_, cpl::Role::Fibers, comm->nprocs);
    cpl::Config cfg;
    cfg.interval = interval_;
    cfg.dt = dt_;
    cfg.rho = drag_->fluid_density();
    cfg.mu = drag_->viscosity();
    cfg.reaction = reaction_;
    channel_->send(cpl::Kind::Config, cpl::encode(cfg));
    channel_->recv(mesh_payload, {cpl::Kind::Mesh}, "waiting for the fluid mesh (start-up handshake)");
    const cpl::Mesh mesh = cpl::decode_mesh(mesh_payload);
    if (mesh.size() == 0) channel_->fail("malformed or empty Mesh message from the fluid");
    try {
      (void)flow::CellGrid::from_cells(mesh.centres, mesh.boxes);
    } catch (const std::exception &e) {
      channel_->fail(e.what());
    }
  }
  long long n = static_cast<long long>(mesh_payload.size());
  MPI_Bcast(&n, 1, MPI_LONG_LONG, 0, world);
  mesh_payload.resize(static_cast<std::size_t>(n));
  MPI_Bcast(mesh_payload.data(), static_cast<int>(n), MPI_DOUBLE, 0, world);
  const cpl::Mesh mesh = cpl::decode_mesh(mesh_payload);
  grid_ = flow::CellGrid::from_cells(mesh.centres, mesh.boxes);  // checked on the leader above
  volumes_ = mesh.volumes;
  acc_.assign(3 * mesh.size(), 0.0);
  if (leader && screen)
    std::fprintf(screen, "fix fiber/coupling: connected to the fluid: %lld x %lld x %lld cells, "
                         "exchange every %lld steps (fluid step %g s), reaction %s\n",
                 static_cast<long long>(grid_.n[0]), static_cast<long long>(grid_.n[1]),
                 static_cast<long long>(grid_.n[2]), static_cast<long long>(interval_),
                 static_cast<double>(interval_) * dt_, reaction_ ? "yes" : "no");
  receive_velocity();
}

void FixFiberCoupling::receive_velocity() {
  std::vector<double> u(acc_.size(), 0.0);
  if (comm->me == 0) {
    std::vector<double> p;
    const double t0 = MPI_Wtime();
    channel_->recv(p, {cpl::Kind::Velocity}, "waiting for the fluid velocity");
    wait_s_ += MPI_Wtime() - t0;
    if (p.size() != u.size())
      channel_->fail("Velocity message has " + std::to_string(p.size()) + " values, expected " +
                     std::to_string(u.size()));
    u.swap(p);
  }
  MPI_Bcast(u.data(), static_cast<int>(u.size()), MPI_DOUBLE, 0, world);
  drag_->set_flow(std::make_unique<flow::GridFlow>(grid_.velocity_grid(u)));
}

void FixFiberCoupling::end_of_step() {
  const double t0 = MPI_Wtime(), waited = wait_s_;
  const int nlocal = atom->nlocal;
  if (drag_->node_drag_count() != nlocal)
    fiberform::fail_one(lmp, FLERR, "fix fiber/coupling: fix fiber/drag has no drag forces of this step "
                                    "(define fix fiber/drag with the same atoms; it must run every step)");
  double **x = atom->x;
  int *mask = atom->mask;
  for (int i = 0; i < nlocal; ++i) {
    if (!(mask[i] & groupbit)) continue;
    const double *f = drag_->node_drag(i);
    if (f[0] == 0.0 && f[1] == 0.0 && f[2] == 0.0) continue;
    flow::spread_to_cells(grid_, {x[i][0], x[i][1], x[i][2]}, {-f[0], -f[1], -f[2]}, acc_, kernel_);
  }
  if (++steps_ >= interval_) exchange();
  work_s_ += (MPI_Wtime() - t0) - (wait_s_ - waited);  // the wait inside exchange() apart
}

void FixFiberCoupling::exchange() {
  std::vector<double> total(acc_.size(), 0.0);
  MPI_Allreduce(acc_.data(), total.data(), static_cast<int>(acc_.size()), MPI_DOUBLE, MPI_SUM, world);
  const double inv = 1.0 / static_cast<double>(steps_);
  for (std::size_t c = 0; c < total.size(); ++c) total[c] = reaction_ ? total[c] * inv : 0.0;
  // impulse given to the fluid over this interval: mean force x interval time
  for (std::size_t c = 0; c < total.size(); ++c)
    stats_[1 + c % 3] += total[c] * static_cast<double>(steps_) * dt_;
  stats_[0] += 1.0;
  if (comm->me == 0) channel_->send(cpl::Kind::Reaction, total);
  std::fill(acc_.begin(), acc_.end(), 0.0);
  steps_ = 0;
  receive_velocity();
}

double FixFiberCoupling::compute_vector(int n) {
  if (n == 4) return work_s_;
  if (n == 5) return wait_s_;
  return stats_[n];
}
