/* SPDX-License-Identifier: GPL-3.0-or-later
   Fluid velocity seen by the fibers: an abstract FlowField (velocity at a point and a time) with
   two implementations,
     - UniformFlow: one constant vector (tests, free fall),
     - GridFlow:    a frozen steady field on a regular grid, trilinearly interpolated (one-way
                    coupling as in Kettil 2016 section 3.2, the flow read once at start-up).
   A coupled, time-varying field (the OpenFOAM solver of coupling/) implements the same interface.

   Grid convention: values live at the nodes x_ijk = origin + (i, j, k) * spacing,
   0 <= i < nx etc., stored in C order with the three components interleaved:
   data[((i * ny + j) * nz + k) * 3 + c]. Outside the grid box the position is clamped to the box
   (constant extrapolation of the boundary values). Trilinear interpolation reproduces every field
   that is linear (indeed multilinear) in x, y, z exactly inside the box.

   The binary companion file written by `fiberform flow` (flow.grid, little-endian) is read by
   read_flow_grid():
     8 bytes  magic "FFGRID1\n"
     3 int64  nx ny nz
     6 double origin[3] spacing[3]           (m)
     nx*ny*nz*3 double velocity, order above (m/s)
   Pure header, no LIGGGHTS dependency. */
#ifndef FIBERFORM_PHYSICS_FLOW_GRID_H
#define FIBERFORM_PHYSICS_FLOW_GRID_H

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace fiberform::physics::flow {

using Vec3 = std::array<double, 3>;

/// Source of the fluid velocity at a point x (m) and time t (s), in m/s.
class FlowField {
 public:
  virtual ~FlowField() = default;
  virtual Vec3 velocity(const Vec3 &x, double t) const = 0;
};

/// The same velocity everywhere and always.
class UniformFlow final : public FlowField {
 public:
  explicit UniformFlow(const Vec3 &u) : u_(u) {}
  Vec3 velocity(const Vec3 &, double) const override { return u_; }

 private:
  Vec3 u_;
};

/// Vector samples on a regular grid (see the file comment for the layout).
struct RegularGrid {
  std::array<std::int64_t, 3> n{0, 0, 0};
  Vec3 origin{0.0, 0.0, 0.0};
  Vec3 spacing{1.0, 1.0, 1.0};
  std::vector<double> data;  // n[0]*n[1]*n[2]*3 values

  std::size_t index(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return static_cast<std::size_t>(((i * n[1] + j) * n[2] + k) * 3);
  }
  void validate() const {
    for (int a = 0; a < 3; ++a) {
      if (n[a] < 1) throw std::invalid_argument("flow grid: every dimension needs >= 1 node");
      if (!(spacing[a] > 0.0)) throw std::invalid_argument("flow grid: spacing must be > 0");
    }
    if (data.size() != static_cast<std::size_t>(n[0] * n[1] * n[2] * 3))
      throw std::invalid_argument("flow grid: data size does not match nx*ny*nz*3");
  }
};

/// The trilinear stencil of a point: up to 8 grid nodes (flat node number (i * ny + j) * nz + k) with
/// weights > 0 that sum to 1 (to round-off); positions outside the box are clamped onto it.
struct Stencil {
  std::array<std::size_t, 8> node{};
  std::array<double, 8> weight{};
  int size = 0;
};

inline Stencil trilinear_stencil(const RegularGrid &g, const Vec3 &x) {
  std::int64_t i0[3];
  double w[3];
  for (int a = 0; a < 3; ++a) {
    const double s = (x[a] - g.origin[a]) / g.spacing[a];
    const std::int64_t last = g.n[a] - 1;
    if (last == 0 || !(s > 0.0)) {  // also catches NaN
      i0[a] = 0;
      w[a] = 0.0;
    } else if (s >= static_cast<double>(last)) {
      i0[a] = last - 1;
      w[a] = 1.0;
    } else {
      i0[a] = static_cast<std::int64_t>(std::floor(s));
      if (i0[a] > last - 1) i0[a] = last - 1;
      w[a] = s - static_cast<double>(i0[a]);
    }
  }
  Stencil st;
  for (int di = 0; di < 2; ++di) {
    const double wi = di ? w[0] : 1.0 - w[0];
    if (wi == 0.0) continue;
    for (int dj = 0; dj < 2; ++dj) {
      const double wj = dj ? w[1] : 1.0 - w[1];
      if (wj == 0.0) continue;
      for (int dk = 0; dk < 2; ++dk) {
        const double wk = dk ? w[2] : 1.0 - w[2];
        if (wk == 0.0) continue;
        st.node[static_cast<std::size_t>(st.size)] = g.index(i0[0] + di, i0[1] + dj, i0[2] + dk) / 3;
        st.weight[static_cast<std::size_t>(st.size)] = wi * wj * wk;
        ++st.size;
      }
    }
  }
  return st;
}

/// Trilinear interpolation of a RegularGrid; positions outside the box are clamped onto it.
inline Vec3 interpolate(const RegularGrid &g, const Vec3 &x) {
  const Stencil st = trilinear_stencil(g, x);
  Vec3 out{0.0, 0.0, 0.0};
  for (int s = 0; s < st.size; ++s) {
    const std::size_t idx = 3 * st.node[static_cast<std::size_t>(s)];
    const double wt = st.weight[static_cast<std::size_t>(s)];
    out[0] += wt * g.data[idx];
    out[1] += wt * g.data[idx + 1];
    out[2] += wt * g.data[idx + 2];
  }
  return out;
}

/// A frozen (steady) field on a regular grid: velocity(x, t) ignores t.
class GridFlow final : public FlowField {
 public:
  explicit GridFlow(RegularGrid grid) : grid_(std::move(grid)) { grid_.validate(); }
  Vec3 velocity(const Vec3 &x, double) const override { return interpolate(grid_, x); }
  const RegularGrid &grid() const { return grid_; }

 private:
  RegularGrid grid_;
};

/// Parse the binary companion file (format in the file comment) from a stream; ``path`` names it
/// in the messages. Throws std::runtime_error.
inline RegularGrid read_flow_grid(std::istream &in, const std::string &path) {
  char magic[8];
  in.read(magic, 8);
  if (!in || std::memcmp(magic, "FFGRID1\n", 8) != 0)
    throw std::runtime_error(path + ": not a fiberform flow grid (bad magic)");
  RegularGrid g;
  in.read(reinterpret_cast<char *>(g.n.data()), sizeof(std::int64_t) * 3);
  in.read(reinterpret_cast<char *>(g.origin.data()), sizeof(double) * 3);
  in.read(reinterpret_cast<char *>(g.spacing.data()), sizeof(double) * 3);
  if (!in) throw std::runtime_error(path + ": truncated header");
  for (int a = 0; a < 3; ++a)
    if (g.n[a] < 1 || g.n[a] > (1 << 20)) throw std::runtime_error(path + ": bad grid dimensions");
  g.data.resize(static_cast<std::size_t>(g.n[0] * g.n[1] * g.n[2] * 3));
  in.read(reinterpret_cast<char *>(g.data.data()),
          static_cast<std::streamsize>(g.data.size() * sizeof(double)));
  if (!in) throw std::runtime_error(path + ": truncated data");
  g.validate();
  return g;
}

/// Read the binary companion file. Throws std::runtime_error.
inline RegularGrid read_flow_grid(const std::string &path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open flow grid file " + path);
  return read_flow_grid(in, path);
}

/// Write the binary companion file (used by tests; the Python flow stage writes the same format).
inline void write_flow_grid(const std::string &path, const RegularGrid &g) {
  g.validate();
  std::ofstream out(path, std::ios::binary);
  if (!out) throw std::runtime_error("cannot write flow grid file " + path);
  out.write("FFGRID1\n", 8);
  out.write(reinterpret_cast<const char *>(g.n.data()), sizeof(std::int64_t) * 3);
  out.write(reinterpret_cast<const char *>(g.origin.data()), sizeof(double) * 3);
  out.write(reinterpret_cast<const char *>(g.spacing.data()), sizeof(double) * 3);
  out.write(reinterpret_cast<const char *>(g.data.data()),
            static_cast<std::streamsize>(g.data.size() * sizeof(double)));
  if (!out) throw std::runtime_error("error writing flow grid file " + path);
}

}  // namespace fiberform::physics::flow

#endif
