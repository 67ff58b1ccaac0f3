// SPDX-License-Identifier: GPL-3.0-or-later
// fiberform: the permeability solve's convergence criterion on a sliding window of flow rates.
//
// The air-permeability stage (docs/stages/permeability.md, "Convergence") counts a SIMPLE solve as
// converged when the outflow through the bottom, recorded after every iteration, varies over the
// last `window` iterations by at most `tolerance` of its mean: (max - min) <= tolerance * |mean|.
// The Python stage applies the same test to the recorded history afterwards
// (fiberform.porous_media.flow_rate_convergence); this header is the run-time copy used by
// the function object flowRateConvergence to stop the solver there. No OpenFOAM, no MPI.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace fiberform {

// A ring of the last `window` values of a scalar history.
class SlidingWindow {
 public:
  explicit SlidingWindow(std::size_t window) : values_(window, 0.0) {}

  void push(double v) {
    if (values_.empty()) return;
    values_[next_] = v;
    next_ = (next_ + 1) % values_.size();
    if (count_ < values_.size()) ++count_;
  }
  bool full() const { return !values_.empty() && count_ == values_.size(); }
  std::size_t size() const { return count_; }

  // (max - min) / |mean| of a full window; infinity while it is not full or the mean is zero.
  double relative_range() const {
    if (!full()) return INFINITY;
    const auto [lo, hi] = std::minmax_element(values_.begin(), values_.end());
    double sum = 0.0;
    for (double v : values_) sum += v;
    const double mean = sum / static_cast<double>(values_.size());
    if (!(std::fabs(mean) > 0.0) || !std::isfinite(mean)) return INFINITY;
    return (*hi - *lo) / std::fabs(mean);
  }

  // The criterion: a full window whose range is at most `tolerance` of its mean (tolerance >= 0).
  bool converged(double tolerance) const { return relative_range() <= tolerance; }

 private:
  std::vector<double> values_;
  std::size_t next_ = 0;
  std::size_t count_ = 0;
};

}  // namespace fiberform
