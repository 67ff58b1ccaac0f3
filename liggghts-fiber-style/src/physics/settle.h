/* SPDX-License-Identifier: GPL-3.0-or-later
   Settle criterion of the lay-down (fix fiber/settle, docs/stages/laydown.md "Settling"):
   the speed below which a given fraction of the fiber mass moves. Pure function, SI units.

   With fraction 1 it is the largest speed (every fiber must be slower than the threshold). With a
   fraction q < 1 the fibers carrying the fastest (1 - q) of the mass are ignored, so a few light
   fines fluttering in the flow do not keep a large sheet running, while a sheet that still sinks
   as a whole (most of its mass moving) is not counted as settled. */
#ifndef FIBERFORM_PHYSICS_SETTLE_H
#define FIBERFORM_PHYSICS_SETTLE_H

#include <algorithm>
#include <numeric>
#include <vector>

namespace fiberform::physics {

// The smallest speed v such that the bodies with speed <= v carry at least `fraction` of the total
// mass (masses > 0; fraction in (0, 1]). Empty input or zero total mass: 0.
inline double mass_fraction_speed(const std::vector<double> &speed, const std::vector<double> &mass,
                                  double fraction) {
  const size_t n = std::min(speed.size(), mass.size());
  std::vector<size_t> order(n);
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return speed[a] < speed[b]; });
  double total = 0.0;
  for (size_t i = 0; i < n; ++i) total += mass[i];
  if (!(total > 0.0)) return 0.0;
  if (fraction >= 1.0) return n ? speed[order.back()] : 0.0;
  double acc = 0.0;
  for (size_t k : order) {
    acc += mass[k];
    if (acc >= fraction * total) return speed[k];
  }
  return speed[order.back()];
}

}  // namespace fiberform::physics

#endif
