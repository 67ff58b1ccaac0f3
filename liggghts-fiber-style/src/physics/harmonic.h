/* SPDX-License-Identifier: GPL-3.0-or-later
   Harmonic contact between two spheres: pure function, SI units. */
#ifndef FIBERFORM_PHYSICS_HARMONIC_H
#define FIBERFORM_PHYSICS_HARMONIC_H

namespace fiberform::physics {

struct HarmonicContact {
  double force;   // N, repulsive (>= 0), along the line of centres
  double energy;  // J, 0.5*K*delta^2
};

// K: stiffness (N/m); radius_sum: r_i + r_j (m); distance: |x_i - x_j| (m).
inline HarmonicContact harmonic_contact(double K, double radius_sum, double distance) {
  const double overlap = radius_sum - distance;
  if (overlap <= 0.0 || distance <= 0.0) return {0.0, 0.0};
  return {K * overlap, 0.5 * K * overlap * overlap};
}

}  // namespace fiberform::physics

#endif
