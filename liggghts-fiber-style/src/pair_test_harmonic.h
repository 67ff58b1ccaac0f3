/* SPDX-License-Identifier: GPL-3.0-or-later
   pair_style test/harmonic: harmonic repulsion between overlapping spheres.

   F = K * delta along the line of centres, delta = r_i + r_j - |x_i - x_j| > 0 (overlap, m),
   K in N/m. No damping, no friction: an elastic collision with a closed-form answer (contact time
   pi*sqrt(m_eff/K), velocities exchanged/reversed), used to test the driver, the style
   registration and parallel consistency, and as the simplest demo style. */
#ifndef LMP_PAIR_TEST_HARMONIC_H
#define LMP_PAIR_TEST_HARMONIC_H

#include "pair.h"

namespace LAMMPS_NS {

class PairTestHarmonic : public Pair {
 public:
  explicit PairTestHarmonic(class LAMMPS *lmp);
  ~PairTestHarmonic() override;
  void compute(int eflag, int vflag) override;
  void settings(int narg, char **arg) override;
  void coeff(int narg, char **arg) override;
  void init_style() override;
  double init_one(int i, int j) override;

 private:
  void allocate();
  double **stiffness_ = nullptr;  // K per type pair, N/m
  double max_radius_ = 0.0;       // largest sphere radius in the system, m
};

}  // namespace LAMMPS_NS

#endif
