/* SPDX-License-Identifier: GPL-3.0-or-later
   Sub-integration of one pair of contact points over one fiber time step (thesis eq. 2.19-2.21)
   and conversion to averaged forces (eq. 2.22, made consistent with velocity Verlet).

   The ODE is written for the DEVIATION of each point from its free motion
   p_free(t) = p0 + v0 t + a0 t^2/2 (a0: intrinsic acceleration = gravity, drag, beam forces, ...,
   constant over the step as in the thesis):  y' = w,  w' = F_contact / m.
   Tolerances then act on the contact-induced motion itself (nm and below), not on absolute
   positions (0.1 mm), and a pair that never comes into range stays exactly at y = w = 0.
   Outputs, per point, the two averaged contact forces used by the step fix:
     F_pos = 2 m y(dt) / dt^2   (eq. 2.22 with beta = 1/2, minus m a0: the position update of
                                 velocity Verlet then lands exactly on the ODE end position)
     F_vel =   m w(dt) / dt     (the impulse: used to land on the ODE end velocity as well)
   Methods: CVODE (Adams-Moulton, fixed-point iteration, one memory block reused through
   CVodeReInit), or fixed velocity-Verlet sub-steps. */
#ifndef FIBERFORM_CONTACT_INTEGRATOR_H
#define FIBERFORM_CONTACT_INTEGRATOR_H

#include "physics/contact_geometry.h"
#include "physics/contact_law.h"

namespace fiberform {

using physics::Vec3;

struct PointState {
  Vec3 p;        // position at t0 (m)
  Vec3 v;        // velocity at t0 (m/s)
  Vec3 a;        // intrinsic acceleration (m/s^2), constant over the step
  double inv_m;  // 1/mass (1/kg); 0 = infinite mass (frozen body, wall, driven plate)
};

struct PairGeometry {
  double offset = 0.0;  // h = |p2 - p1| - offset (sum of radii; 0 when points sit on surfaces)
  bool plane = false;   // partner is a plane through p2 with unit normal `normal` (towards point 1):
  Vec3 normal{0, 0, 1}; //   h = normal . (p1 - p2) - offset
};

struct PairResult {
  Vec3 fpos1, fvel1, fpos2, fvel2;  // averaged contact forces on point 1 and 2 (N)
  long rhs_evals = 0;
  bool ok = true;
};

class ContactIntegrator {
 public:
  enum class Method { Cvode, Substep };
  ContactIntegrator();
  ~ContactIntegrator();
  ContactIntegrator(const ContactIntegrator &) = delete;
  ContactIntegrator &operator=(const ContactIntegrator &) = delete;

  // rtol: relative tolerance; atol: absolute tolerance of the deviation y (m); the velocity
  // deviation w gets atol/dt. nsub: sub-steps of the Substep method.
  void configure(Method m, int nsub, double rtol, double atol);
  PairResult solve(const physics::PairLaw &law, const PairGeometry &g, const PointState &s1,
                   const PointState &s2, double dt);

  // Instantaneous contact force on point 1 (the force on point 2 is its negative).
  static Vec3 instantaneous_force(const physics::PairLaw &law, const PairGeometry &g, const PointState &s1,
                                  const PointState &s2);

  struct Rhs;  // right-hand-side data (public for the C callback)

 private:
  PairResult solve_cvode(Rhs &r, double dt);
  PairResult solve_substep(Rhs &r, double dt);
  Method method_ = Method::Cvode;
  int nsub_ = 100;
  double rtol_ = 1e-6, atol_ = 1e-13;
  void *sunctx_ = nullptr;  // SUNContext
  void *y_ = nullptr;       // N_Vector (12)
  void *abstol_ = nullptr;  // N_Vector (12)
  void *nls_ = nullptr;     // SUNNonlinearSolver (fixed point)
  void *cvode_ = nullptr;   // CVODE memory, created once
  double abstol_dt_ = -1.0; // dt for which abstol_ was filled
};

}  // namespace fiberform

#endif
