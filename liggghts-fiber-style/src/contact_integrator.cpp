/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "contact_integrator.h"

#include <cvode/cvode.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include <cmath>
#include <stdexcept>

namespace fiberform {

using physics::cross;
using physics::dot;
using physics::norm;

struct ContactIntegrator::Rhs {
  const physics::PairLaw *law;
  PairGeometry g;
  Vec3 base;    // p2(0) - p1(0)
  Vec3 dv0;     // v2(0) - v1(0)
  Vec3 da0;     // a2 - a1
  double inv_m1, inv_m2;
  long evals = 0;

  // y = [y1(3) y2(3) w1(3) w2(3)]; writes accelerations of the deviations into acc[6].
  void accel(double t, const double *y, double *acc) {
    ++evals;
    const double *y1 = y, *y2 = y + 3, *w1 = y + 6, *w2 = y + 9;
    const Vec3 d{base.x + t * (dv0.x + 0.5 * t * da0.x) + y2[0] - y1[0],
                 base.y + t * (dv0.y + 0.5 * t * da0.y) + y2[1] - y1[1],
                 base.z + t * (dv0.z + 0.5 * t * da0.z) + y2[2] - y1[2]};
    const Vec3 vr{dv0.x + t * da0.x + w2[0] - w1[0], dv0.y + t * da0.y + w2[1] - w1[1],
                  dv0.z + t * da0.z + w2[2] - w1[2]};
    Vec3 n;
    double h;
    if (g.plane) {
      // point 1 above a plane through p2: separation along the fixed normal
      n = -1.0 * g.normal;  // direction from point 1 towards the plane
      h = -dot(d, g.normal) - g.offset;
    } else {
      const double r = norm(d);
      n = r > 0 ? (1.0 / r) * d : Vec3{1, 0, 0};
      h = r - g.offset;
    }
    const double u = dot(n, vr);  // dh/dt
    const double F = law->force(h, u);
    // repulsive F pushes 1 along -n, 2 along +n
    acc[0] = -F * n.x * inv_m1;
    acc[1] = -F * n.y * inv_m1;
    acc[2] = -F * n.z * inv_m1;
    acc[3] = F * n.x * inv_m2;
    acc[4] = F * n.y * inv_m2;
    acc[5] = F * n.z * inv_m2;
  }
};

namespace {
int cvode_rhs(realtype t, N_Vector y, N_Vector ydot, void *user) {
  auto *r = static_cast<ContactIntegrator::Rhs *>(user);
  const double *yy = N_VGetArrayPointer(y);
  double *yd = N_VGetArrayPointer(ydot);
  for (int k = 0; k < 6; ++k) yd[k] = yy[6 + k];
  r->accel(t, yy, yd + 6);
  for (int k = 6; k < 12; ++k)
    if (!std::isfinite(yd[k])) return 1;  // recoverable: CVODE retries with a smaller step
  return 0;
}
}  // namespace

ContactIntegrator::ContactIntegrator() {
  SUNContext ctx;
  if (SUNContext_Create(nullptr, &ctx) != 0) throw std::runtime_error("SUNContext_Create failed");
  sunctx_ = ctx;
}

ContactIntegrator::~ContactIntegrator() {
  if (cvode_) CVodeFree(&cvode_);
  if (nls_) SUNNonlinSolFree(static_cast<SUNNonlinearSolver>(nls_));
  if (y_) N_VDestroy(static_cast<N_Vector>(y_));
  if (abstol_) N_VDestroy(static_cast<N_Vector>(abstol_));
  if (sunctx_) {
    SUNContext ctx = static_cast<SUNContext>(sunctx_);
    SUNContext_Free(&ctx);
  }
}

void ContactIntegrator::configure(Method m, int nsub, double rtol, double atol) {
  method_ = m;
  nsub_ = nsub > 0 ? nsub : 1;
  rtol_ = rtol;
  atol_ = atol;
  abstol_dt_ = -1.0;
}

Vec3 ContactIntegrator::instantaneous_force(const physics::PairLaw &law, const PairGeometry &g,
                                            const PointState &s1, const PointState &s2) {
  Rhs r{&law, g, s2.p - s1.p, s2.v - s1.v, {0, 0, 0}, 1.0, 0.0};
  double y[12] = {0}, acc[6];
  r.accel(0.0, y, acc);
  return {acc[0], acc[1], acc[2]};  // inv_m1 = 1: acceleration == force
}

PairResult ContactIntegrator::solve(const physics::PairLaw &law, const PairGeometry &g, const PointState &s1,
                                    const PointState &s2, double dt) {
  Rhs r{&law, g, s2.p - s1.p, s2.v - s1.v, s2.a - s1.a, s1.inv_m, s2.inv_m};
  PairResult res = method_ == Method::Cvode ? solve_cvode(r, dt) : solve_substep(r, dt);
  res.rhs_evals = r.evals;
  return res;
}

namespace {
PairResult to_forces(const double *y, double dt, double inv_m1, double inv_m2) {
  PairResult res;
  const double cp = 2.0 / (dt * dt), cv = 1.0 / dt;
  auto f = [](const double *q, double c, double inv_m) {
    return inv_m > 0 ? Vec3{c * q[0] / inv_m, c * q[1] / inv_m, c * q[2] / inv_m} : Vec3{0, 0, 0};
  };
  res.fpos1 = f(y, cp, inv_m1);
  res.fpos2 = f(y + 3, cp, inv_m2);
  res.fvel1 = f(y + 6, cv, inv_m1);
  res.fvel2 = f(y + 9, cv, inv_m2);
  return res;
}
}  // namespace

PairResult ContactIntegrator::solve_cvode(Rhs &r, double dt) {
  SUNContext ctx = static_cast<SUNContext>(sunctx_);
  if (!y_) {
    y_ = N_VNew_Serial(12, ctx);
    abstol_ = N_VNew_Serial(12, ctx);
  }
  N_Vector y = static_cast<N_Vector>(y_);
  N_Vector atol = static_cast<N_Vector>(abstol_);
  N_VConst(0.0, y);
  if (abstol_dt_ != dt) {
    double *a = N_VGetArrayPointer(atol);
    for (int k = 0; k < 6; ++k) a[k] = atol_;
    for (int k = 6; k < 12; ++k) a[k] = atol_ / dt;
  }
  int flag;
  if (!cvode_) {
    cvode_ = CVodeCreate(CV_ADAMS, ctx);
    flag = CVodeInit(cvode_, cvode_rhs, 0.0, y);
    nls_ = SUNNonlinSol_FixedPoint(y, 0, ctx);
    flag |= CVodeSetNonlinearSolver(cvode_, static_cast<SUNNonlinearSolver>(nls_));
    flag |= CVodeSetMaxNumSteps(cvode_, 100000);
    flag |= CVodeSetMaxHnilWarns(cvode_, -1);
    if (flag != 0) throw std::runtime_error("CVODE set-up failed");
  } else {
    CVodeReInit(cvode_, 0.0, y);
  }
  if (abstol_dt_ != dt) {
    CVodeSVtolerances(cvode_, rtol_, atol);
    abstol_dt_ = dt;
  }
  CVodeSetUserData(cvode_, &r);
  CVodeSetStopTime(cvode_, dt);
  realtype t = 0.0;
  flag = CVode(cvode_, dt, y, &t, CV_NORMAL);
  PairResult res = to_forces(N_VGetArrayPointer(y), dt, r.inv_m1, r.inv_m2);
  res.ok = flag >= 0;
  return res;
}

PairResult ContactIntegrator::solve_substep(Rhs &r, double dt) {
  // velocity Verlet on the deviations, nsub_ fixed sub-steps
  double y[12] = {0}, acc[6];
  const double hstep = dt / nsub_;
  double t = 0.0;
  r.accel(t, y, acc);
  for (int s = 0; s < nsub_; ++s) {
    for (int k = 0; k < 6; ++k) {
      y[6 + k] += 0.5 * hstep * acc[k];
      y[k] += hstep * y[6 + k];
    }
    t += hstep;
    r.accel(t, y, acc);
    for (int k = 0; k < 6; ++k) y[6 + k] += 0.5 * hstep * acc[k];
  }
  bool ok = true;
  for (double q : y) ok = ok && std::isfinite(q);
  PairResult res = to_forces(y, dt, r.inv_m1, r.inv_m2);
  res.ok = ok;
  return res;
}

}  // namespace fiberform
