/* SPDX-License-Identifier: GPL-3.0-or-later
   Contact-point geometry on fiber elements (thesis section 2.4.3-2.4.4). An element is the
   straight segment between two consecutive fiber nodes xa -> xb. It carries n contact points at
   the fractions s_k = (k + 1/2)/n, k = 0..n-1 (uniform along the centre line). Pure functions. */
#ifndef FIBERFORM_PHYSICS_CONTACT_GEOMETRY_H
#define FIBERFORM_PHYSICS_CONTACT_GEOMETRY_H

#include <cmath>
#include <limits>

#include "dlvo.h"
#include "vec3.h"

namespace fiberform::physics {


inline double point_fraction(int k, int n) { return (k + 0.5) / n; }
inline Vec3 lerp(Vec3 a, Vec3 b, double s) { return a + s * (b - a); }

// Index of the contact point of an element (xa -> xb, n points) closest to p.
inline int closest_point_index(Vec3 xa, Vec3 xb, int n, Vec3 p) {
  const Vec3 e = xb - xa;
  const double L2 = dot(e, e);
  double t = L2 > 0 ? dot(p - xa, e) / L2 : 0.5;
  int k = static_cast<int>(std::floor(t * n));
  if (k < 0) k = 0;
  if (k > n - 1) k = n - 1;
  return k;
}

// Parameter in [0, 1] of the point of segment a-b closest to p.
inline double closest_param_point_segment(Vec3 a, Vec3 b, Vec3 p) {
  const Vec3 d = b - a;
  const double dd = dot(d, d);
  if (dd <= 0.0) return 0.0;
  const double t = dot(p - a, d) / dd;
  return t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
}

// Closest points of segments p1-q1 (parameter s) and p2-q2 (parameter t), both clamped to [0, 1]
// (the standard clamped solution of the 2 x 2 normal equations; parallel segments: s = 0).
inline void closest_params_segment_segment(Vec3 p1, Vec3 q1, Vec3 p2, Vec3 q2, double &s, double &t) {
  const Vec3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r);
  auto clamp01 = [](double v) { return v < 0.0 ? 0.0 : (v > 1.0 ? 1.0 : v); };
  if (a <= 0.0 && e <= 0.0) { s = t = 0.0; return; }
  if (a <= 0.0) { s = 0.0; t = clamp01(f / e); return; }
  const double c = dot(d1, r);
  if (e <= 0.0) { t = 0.0; s = clamp01(-c / a); return; }
  const double b = dot(d1, d2);
  const double denom = a * e - b * b;
  s = denom > 1e-14 * a * e ? clamp01((b * f - c * e) / denom) : 0.0;
  t = (b * s + f) / e;
  if (t < 0.0) { t = 0.0; s = clamp01(-c / a); }
  else if (t > 1.0) { t = 1.0; s = clamp01((b - c) / a); }
}

// ---- rectangular cross-sections (thesis 2.4.3): points are moved from the centre line towards
// the partner along the line between the two centres until they reach the element surface.
// The element is a prism with width w along e_w and thickness t along e_t (both orthogonal to
// the axis). Returns the distance from the centre line point to the surface along unit dir u.
inline double rect_surface_distance(Vec3 axis_unit, Vec3 e_t, double width, double thickness, Vec3 u) {
  const Vec3 e_w = cross(e_t, axis_unit);
  const double cw = std::fabs(dot(u, e_w)), ct = std::fabs(dot(u, e_t));
  const double big = 1e300;
  const double dw = cw > 0 ? 0.5 * width / cw : big;
  const double dt = ct > 0 ? 0.5 * thickness / ct : big;
  return dw < dt ? dw : dt;
}

// Thickness direction of a flat (rectangular) element: the reference direction `up` (default
// global z) made orthogonal to the axis; falls back to x if the axis is parallel to `up`.
inline Vec3 rect_thickness_dir(Vec3 axis_unit, Vec3 up) {
  Vec3 t = up - dot(up, axis_unit) * axis_unit;
  double n = norm(t);
  if (n < 1e-8) {
    const Vec3 x{1, 0, 0};
    t = x - dot(x, axis_unit) * axis_unit;
    n = norm(t);
  }
  return (1.0 / n) * t;
}

// Extent of a rectangular section 2 a1 x 2 a2 (a1 along t1, a2 along t2; t1, t2, axis a right-handed
// frame) from the centre line along the unit direction n (m): where the line from the centre along
// n's part normal to the axis leaves the rectangle (the thesis' rule above, used by the contacts
// inside the implicit step, docs/models/contact.md section 9). t2 need not be unit or normal to the
// axis (it is made so, by rect_thickness_dir). n's axial part
// is dropped (contacts at an element's end); n along the axis gives min(a1, a2). Between min(a1, a2)
// (a face) and hypot(a1, a2) (a corner).
// de_dn (optional): the gradient of the extent with respect to n (m per unit change of n), on the
// active face (the one the line leaves through), 0 when n is along the axis.
inline double rect_extent(Vec3 axis_unit, Vec3 t2, double a1, double a2, Vec3 n, Vec3 *de_dn = nullptr) {
  if (de_dn) *de_dn = Vec3{0, 0, 0};
  Vec3 u = n - dot(n, axis_unit) * axis_unit;
  const double lu = norm(u);
  if (!(lu > 1e-9)) return a1 < a2 ? a1 : a2;
  u = (1.0 / lu) * u;
  const Vec3 e_t = rect_thickness_dir(axis_unit, norm(t2) > 0.0 ? t2 : Vec3{0, 0, 1});
  const double e = rect_surface_distance(axis_unit, e_t, 2.0 * a1, 2.0 * a2, u);
  if (de_dn) {
    // e = a / |c| on the active face (c = u.f, f its normal): de/du = -e/c f, and u = P n / |P n|
    // (P the projection normal to the axis): de/dn = (de/du - (de/du . u) u) / |P n|
    const Vec3 e_w = cross(e_t, axis_unit);
    const double cw = dot(u, e_w), ct = dot(u, e_t);
    const bool thin = std::fabs(ct) > 0.0 && (std::fabs(cw) == 0.0 || a2 / std::fabs(ct) <= a1 / std::fabs(cw));
    const Vec3 f = thin ? e_t : e_w;
    const double c = thin ? ct : cw;
    const Vec3 g = (-e / c) * f;
    *de_dn = (1.0 / lu) * (g - dot(g, u) * u);
  }
  return e;
}

// ---- force transfer to the nodes (thesis 2.4.2). A force F acting at the centre-line point of
// fraction s plus an offset r_off (surface point - centre-line point) becomes node forces
// (1-s)F, sF (force and moment about any point preserved for the centre-line part) and the
// moment r_off x F of the off-centre-line part, split equally between the two nodes.
struct NodeLoads {
  Vec3 fa, fb, ta, tb;
};

// The inverse effective mass (1/kg) of a contact point carried by two nodes with lever weights w1,
// w2 and masses m1, m2 (the point moves with w1 v1 + w2 v2 and a force F on it loads the nodes with
// w1 F, w2 F, so its acceleration is (w1^2 / m1 + w2^2 / m2) F); a clamped node or a static body
// has an infinite mass (adds 0). The reduced mass of a contact is 1 / the sum of its two points'.
inline double lever_inverse_mass(double w1, double m1, double w2 = 0.0,
                                 double m2 = std::numeric_limits<double>::infinity()) {
  return w1 * w1 / m1 + w2 * w2 / m2;
}
inline NodeLoads transfer_to_nodes(double s, Vec3 F, Vec3 r_off) {
  const Vec3 t = 0.5 * cross(r_off, F);
  return {(1.0 - s) * F, s * F, t, t};
}

// Force per unit length between two parallel cylinders (radii R1, R2, surface gap h) from the
// van der Waals interaction (Israelachvili, Intermolecular and Surface Forces, table 13.1):
//   F/L = -A / (8 sqrt(2) h^(5/2)) * sqrt(R1 R2 / (R1 + R2)).
inline double parallel_cylinders_vdw_per_length(double A, double R1, double R2, double h) {
  return -A / (8.0 * std::sqrt(2.0) * std::pow(h, 2.5)) * std::sqrt(reduced_radius(R1, R2));
}

// Number of contact points per element length Le such that point-pair van der Waals forces
// (eq. 2.25, spacing Le/n) sum to the parallel-cylinder result at the matching gap h_match:
//   A R/(6 h^2) / spacing = A sqrt(R)/(8 sqrt2 h^2.5)  =>  spacing = (4 sqrt2 / 3) sqrt(R h).
inline int points_per_element(double Le, double R1, double R2, double h_match) {
  const double R = reduced_radius(R1, R2);
  const double spacing = 4.0 * std::sqrt(2.0) / 3.0 * std::sqrt(R * h_match);
  int n = static_cast<int>(std::lround(Le / spacing));
  return n < 1 ? 1 : n;
}

}  // namespace fiberform::physics

#endif
