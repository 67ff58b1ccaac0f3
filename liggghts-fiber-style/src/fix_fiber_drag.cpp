/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/drag: see fix_fiber_drag.h and docs/styles/fix_fiber_drag.md. */
#include "fix_fiber_drag.h"

#include "style_args.h"

#include <mpi.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>

#include "atom.h"
#include "comm.h"
#include "domain.h"
#include "error.h"
#include "modify.h"
#include "fix_fiber_beam.h"
#include "physics/beam.h"
#include "physics/drag.h"
#include "physics/flow_grid.h"
#include "update.h"

using namespace LAMMPS_NS;
using namespace FixConst;
namespace drag = fiberform::physics::drag;
namespace flow = fiberform::physics::flow;

FixFiberDrag::FixFiberDrag(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg) {
  vector_flag = 1;
  size_vector = 7;
  global_freq = 1;
  extvector = 0;
  int iarg = 3;
  while (iarg < narg) {
    const std::string kw = arg[iarg];
    auto need = [&](int n) {
      if (iarg + n >= narg)
        error->all(FLERR, fiberform::error_text("fix fiber/drag: " + kw + " needs " + std::to_string(n) + " value(s)"));
    };
    if (kw == "flow") {
      need(1);
      const std::string kind = arg[iarg + 1];
      if (kind == "uniform") {
        need(4);
        flow::Vec3 u{fiberform::parse_finite(error, "fix fiber/drag", "flow uniform", arg[iarg + 2]), fiberform::parse_finite(error, "fix fiber/drag", "flow uniform", arg[iarg + 3]),
                     fiberform::parse_finite(error, "fix fiber/drag", "flow uniform", arg[iarg + 4])};
        flow_ = std::make_unique<flow::UniformFlow>(u);
        iarg += 5;
      } else if (kind == "grid") {
        need(2);
        // read on rank 0 and broadcast, parsed on every rank (a bad file fails all of them alike)
        std::istringstream bytes(fiberform::read_file_everywhere(lmp, "fix fiber/drag: flow grid", arg[iarg + 2]));
        try {
          flow_ = std::make_unique<flow::GridFlow>(flow::read_flow_grid(bytes, arg[iarg + 2]));
        } catch (const std::exception &e) {
          error->all(FLERR, fiberform::error_text(std::string("fix fiber/drag: flow grid: ") + e.what()));
        }
        iarg += 3;
      } else {
        error->all(FLERR, fiberform::error_text("fix fiber/drag: flow: expected 'uniform ux uy uz' or 'grid FILE', got '" +
                                  kind + "'"));
      }
    } else if (kw == "fluid_density") {
      need(1);
      rho_f_ = fiberform::parse_finite(error, "fix fiber/drag", "fluid_density", arg[iarg + 1]);
      if (!(rho_f_ >= 0.0)) error->all(FLERR, "fix fiber/drag: fluid_density must be >= 0");
      iarg += 2;
    } else if (kw == "viscosity") {
      need(1);
      mu_ = fiberform::parse_finite(error, "fix fiber/drag", "viscosity", arg[iarg + 1]);
      if (!(mu_ > 0.0)) error->all(FLERR, "fix fiber/drag: viscosity must be > 0");
      iarg += 2;
    } else if (kw == "gravity") {
      need(3);
      for (int k = 0; k < 3; ++k) g_[k] = fiberform::parse_finite(error, "fix fiber/drag", "gravity", arg[iarg + 1 + k]);
      iarg += 4;
    } else if (kw == "implicit") {
      need(1);
      const std::string v = arg[iarg + 1];
      if (v != "yes" && v != "no") error->all(FLERR, "fix fiber/drag: implicit: expected yes or no");
      implicit_ = v == "yes";
      iarg += 2;
    } else if (kw == "drag") {
      need(1);
      const std::string v = arg[iarg + 1];
      if (v != "yes" && v != "no") error->all(FLERR, "fix fiber/drag: drag: expected yes or no");
      drag_on_ = v == "yes";
      iarg += 2;
    } else {
      error->all(FLERR, fiberform::error_text("fix fiber/drag: unknown keyword '" + kw +
                                "' (flow, fluid_density, viscosity, gravity, drag, implicit)"));
    }
  }
  if (!flow_) error->all(FLERR, "fix fiber/drag: the keyword 'flow uniform ux uy uz' or 'flow grid FILE' is required");
}

FixFiberDrag::~FixFiberDrag() = default;

int FixFiberDrag::setmask() { return POST_FORCE; }

void FixFiberDrag::set_flow(std::unique_ptr<flow::FlowField> f) { flow_ = std::move(f); }

void FixFiberDrag::init() {
  beam_ = FixFiberBeam::find(lmp);
  if (!beam_) error->all(FLERR, "fix fiber/drag: needs a fix fiber/beam (fiber topology and sections)");
  if (!atom->rmass_flag) error->all(FLERR, "fix fiber/drag: needs per-atom mass (atom_style sphere)");
  if (atom->map_style == 0) error->all(FLERR, "fix fiber/drag: needs 'atom_modify map array'");
  if (beam_->implicit() && !beam_->precedes(this))
    error->all(FLERR, "fix fiber/drag: define it after fix fiber/beam (the implicit step takes the drag's "
                      "velocity Jacobian of the current step)");
}

void FixFiberDrag::setup(int vflag) { post_force(vflag); }

/* Drag on the element i -> j (eq. 2.14 at the centre, mean diameter), returned in fe (N, the
   whole element); the return value is the element's displaced (wall) volume (m3). */
double FixFiberDrag::element_force(int i, int j, double fe[3], double *jac) const {
  double **x = atom->x, **v = atom->v;
  double r[4];
  beam_->element_radii(i, j, r);
  const double d = r[0] + r[1];  // mean of the two outer diameters 2 a1, 2 a2
  const double area = fiberform::physics::beam::hollow_ellipse_area(r[0], r[1], r[2], r[3]);
  double e[3], c[3], vc[3];
  for (int k = 0; k < 3; ++k) {
    e[k] = x[j][k] - x[i][k];
    c[k] = 0.5 * (x[i][k] + x[j][k]);
    vc[k] = 0.5 * (v[i][k] + v[j][k]);
  }
  const double len = std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
  fe[0] = fe[1] = fe[2] = 0.0;
  if (drag_on_) {
    domain->remap(c);  // periodic x/y: the element centre's image in the box (the flow grid's)
    const flow::Vec3 u = flow_->velocity({c[0], c[1], c[2]}, update->get_cur_time());
    const drag::Vec3 vrel{u[0] - vc[0], u[1] - vc[1], u[2] - vc[2]};
    const drag::Vec3 f = drag::drag_per_length(rho_f_, mu_, d, vrel);
    for (int k = 0; k < 3; ++k) fe[k] = f[k] * len;
    if (jac) {
      const auto J = drag::drag_jacobian(rho_f_, mu_, d, vrel);
      for (int k = 0; k < 6; ++k) jac[k] = J[k] * len;
    }
  } else if (jac) {
    for (int k = 0; k < 6; ++k) jac[k] = 0.0;
  }
  return area * len;
}

void FixFiberDrag::post_force(int) {
  const int nlocal = atom->nlocal;
  int *mask = atom->mask;
  double **f = atom->f;
  double *rmass = atom->rmass;
  for (double &s : local_) s = 0.0;
  node_drag_.assign(3 * static_cast<std::size_t>(nlocal), 0.0);
  // implicit fibers: each node also gets the row-sum-lumped velocity Jacobian of its drag,
  // D_i = sum over its elements of (len/2) df/du (the node's half of the element force changes by
  // -(len/2) df/du dv when both nodes move together), so fix fiber/beam treats drag linearly
  // implicitly: stable at any step (the relaxation time m/(dF/dv) of a 10 um fiber is ~3e-5 s)
  const bool jacobian = implicit_ && drag_on_ && beam_->implicit();
  for (int i = 0; i < nlocal; ++i) {
    if (!(mask[i] & groupbit) || !beam_->is_node(i)) continue;
    const int idx = beam_->node_index(i), cnt = beam_->node_count(i);
    double volume = 0.0, fi[3] = {0.0, 0.0, 0.0}, Di[6] = {0, 0, 0, 0, 0, 0};
    // every element is evaluated by the owners of both of its nodes, each keeping its half:
    // no reverse communication, and both halves are bit-identical
    for (int side = 0; side < 2; ++side) {
      if ((side == 0 && idx == 0) || (side == 1 && idx == cnt - 1)) continue;
      const int j = beam_->neighbour(i, side == 0 ? -1 : 1);  // periodic x/y: the image next to node i
      if (j < 0)
        fiberform::fail_one(lmp, FLERR, "fix fiber/drag: the neighbour node of an element is not on this rank or was lost (a node left the box: check the boundary and the lost-atoms warning), or the ghost cut-off is too short");
      double fe[3], je[6];
      const double ve = side == 0 ? element_force(j, i, fe, jacobian ? je : nullptr)
                                  : element_force(i, j, fe, jacobian ? je : nullptr);
      volume += 0.5 * ve;
      for (int k = 0; k < 3; ++k) fi[k] += 0.5 * fe[k];
      if (jacobian)
        for (int k = 0; k < 6; ++k) Di[k] += 0.5 * je[k];
      if (side == 1) {
        local_[6] += 1.0;
        for (int k = 0; k < 3; ++k) local_[k] += fe[k];
      }
    }
    for (int k = 0; k < 3; ++k) {
      const double body = (rmass[i] - rho_f_ * volume) * g_[k];
      node_drag_[3 * static_cast<std::size_t>(i) + k] = fi[k];
      f[i][k] += fi[k] + body;
      local_[3 + k] += body;
    }
    if (jacobian) beam_->add_velocity_jacobian(i, Di);
  }
  sums_valid_ = false;
}

double FixFiberDrag::compute_vector(int n) {
  if (!sums_valid_) {
    MPI_Allreduce(local_, sums_, 7, MPI_DOUBLE, MPI_SUM, world);
    sums_valid_ = true;
  }
  return sums_[n];
}
