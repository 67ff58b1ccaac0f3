/* SPDX-License-Identifier: GPL-3.0-or-later
   A minimal 3-vector for the pure physics headers (beam, contact geometry). SI units are the
   caller's; nothing here allocates. */
#ifndef FIBERFORM_PHYSICS_VEC3_H
#define FIBERFORM_PHYSICS_VEC3_H

#include <cmath>

namespace fiberform::physics {

inline constexpr double kPi = 3.14159265358979323846;  // the one pi of the physics headers

struct Vec3 {
  double x = 0, y = 0, z = 0;
  double &operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};
inline Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 operator*(double s, Vec3 a) { return {s * a.x, s * a.y, s * a.z}; }
inline double dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double norm(Vec3 a) { return std::sqrt(dot(a, a)); }
inline Vec3 hadamard(Vec3 a, Vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }

// A 3 x 3 matrix held by its columns (the beam's gradients store columns: d(force)/d(e_j)).
struct Mat3 {
  Vec3 c[3];
};
inline Vec3 operator*(const Mat3 &A, Vec3 v) { return v.x * A.c[0] + v.y * A.c[1] + v.z * A.c[2]; }
inline Mat3 operator*(const Mat3 &A, const Mat3 &B) { return {{A * B.c[0], A * B.c[1], A * B.c[2]}}; }
inline Mat3 operator+(const Mat3 &A, const Mat3 &B) { return {{A.c[0] + B.c[0], A.c[1] + B.c[1], A.c[2] + B.c[2]}}; }
inline Mat3 operator-(const Mat3 &A, const Mat3 &B) { return {{A.c[0] - B.c[0], A.c[1] - B.c[1], A.c[2] - B.c[2]}}; }
inline Mat3 operator*(double s, const Mat3 &A) { return {{s * A.c[0], s * A.c[1], s * A.c[2]}}; }
inline Mat3 transpose(const Mat3 &A) {
  return {{{A.c[0].x, A.c[1].x, A.c[2].x}, {A.c[0].y, A.c[1].y, A.c[2].y}, {A.c[0].z, A.c[1].z, A.c[2].z}}};
}
inline Mat3 identity3() { return {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}; }
// [v]x: skew(v) u = v x u
inline Mat3 skew(Vec3 v) { return {{{0, v.z, -v.y}, {-v.z, 0, v.x}, {v.y, -v.x, 0}}}; }
// a b^T
inline Mat3 outer(Vec3 a, Vec3 b) { return {{b.x * a, b.y * a, b.z * a}}; }
// diag(d) A (each row i scaled by d_i) and A diag(d) (each column j scaled by d_j)
inline Mat3 diag_times(Vec3 d, const Mat3 &A) { return {{hadamard(d, A.c[0]), hadamard(d, A.c[1]), hadamard(d, A.c[2])}}; }
inline Mat3 times_diag(const Mat3 &A, Vec3 d) { return {{d.x * A.c[0], d.y * A.c[1], d.z * A.c[2]}}; }

}  // namespace fiberform::physics

#endif
