/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit test of physics/contact_geometry.h (thesis sec. 2.4.2-2.4.3) and of the two small laws
   that had none: regularized_friction_secant (physics/friction.h) and servo_error
   (physics/steric.h). Each function is checked against an independent computation: closest
   points against a dense search over the segments, the rectangle's surface distance against
   walking along the direction until the point leaves the rectangle, the node loads against the
   force and moment of the force at its point, the rest against their closed forms. */
#include <cmath>
#include <random>

#include "check.h"
#include "physics/contact_geometry.h"
#include "physics/friction.h"
#include "physics/steric.h"

using namespace fiberform;
using namespace fiberform::physics;
using fiberform::check::expect;

namespace {

double dist(Vec3 a, Vec3 b) { return norm(a - b); }

// the smallest distance between two segments by a dense search over both parameters, refined
// around the best grid point (independent of the normal equations)
double brute_segment_segment(Vec3 p1, Vec3 q1, Vec3 p2, Vec3 q2) {
  double best = INFINITY, bs = 0, bt = 0;
  const int n = 400;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j) {
      const double s = double(i) / n, t = double(j) / n;
      const double d = dist(lerp(p1, q1, s), lerp(p2, q2, t));
      if (d < best) best = d, bs = s, bt = t;
    }
  for (double w = 1.0 / n; w > 1e-12; w *= 0.5) {  // pattern search in (s, t)
    bool moved = true;
    while (moved) {
      moved = false;
      for (int k = 0; k < 8; ++k) {
        const double ds = w * std::cos(k * M_PI / 4), dt = w * std::sin(k * M_PI / 4);
        const double s = std::fmin(1.0, std::fmax(0.0, bs + ds)), t = std::fmin(1.0, std::fmax(0.0, bt + dt));
        const double d = dist(lerp(p1, q1, s), lerp(p2, q2, t));
        if (d < best - 1e-16) best = d, bs = s, bt = t, moved = true;
      }
    }
  }
  return best;
}

// distance from the centre along the unit direction u (normal to the axis) to the surface of the
// rectangle width x thickness (e_w, e_t), by bisection on "inside" (independent of the formula)
double walk_out(Vec3 e_w, Vec3 e_t, double width, double thickness, Vec3 u) {
  auto inside = [&](double r) {
    const Vec3 p = r * u;
    return std::fabs(dot(p, e_w)) <= 0.5 * width && std::fabs(dot(p, e_t)) <= 0.5 * thickness;
  };
  double lo = 0.0, hi = width + thickness;
  for (int k = 0; k < 200; ++k) {
    const double mid = 0.5 * (lo + hi);
    (inside(mid) ? lo : hi) = mid;
  }
  return lo;
}

}  // namespace

int main() {
  std::mt19937_64 rng(20261129);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  auto rvec = [&] { return Vec3{U(rng), U(rng), U(rng)}; };

  // points along an element: fractions (k + 1/2)/n, the closest one by projection
  expect(point_fraction(0, 4) == 0.125 && point_fraction(3, 4) == 0.875, "point fractions (k + 1/2)/n");
  {
    const Vec3 xa{0, 0, 0}, xb{1, 0, 0};
    expect(closest_point_index(xa, xb, 4, {0.3, 2, 0}) == 1, "closest point: t = 0.3 of 4 points -> 1");
    expect(closest_point_index(xa, xb, 4, {-5, 0, 0}) == 0, "closest point: before the element -> 0");
    expect(closest_point_index(xa, xb, 4, {7, 1, 1}) == 3, "closest point: beyond the element -> n - 1");
  }

  // closest point of a segment to a point: against a dense search
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3 a = rvec(), b = rvec(), p = 2.0 * rvec();
    const double t = closest_param_point_segment(a, b, p);
    double best = INFINITY;
    for (int i = 0; i <= 100000; ++i) best = std::fmin(best, dist(lerp(a, b, i / 100000.0), p));
    const double got = dist(lerp(a, b, t), p);
    expect(t >= 0.0 && t <= 1.0 && got <= best + 1e-9, "closest point on a segment: no point closer", got, best);
  }

  // closest points of two segments: against the dense search, including parallel ones
  for (int trial = 0; trial < 60; ++trial) {
    Vec3 p1 = rvec(), q1 = rvec(), p2 = rvec(), q2 = rvec();
    if (trial % 10 == 0) q2 = p2 + 0.7 * (q1 - p1);  // parallel
    double s = -1, t = -1;
    closest_params_segment_segment(p1, q1, p2, q2, s, t);
    const double got = dist(lerp(p1, q1, s), lerp(p2, q2, t)), want = brute_segment_segment(p1, q1, p2, q2);
    expect(s >= 0 && s <= 1 && t >= 0 && t <= 1 && std::fabs(got - want) <= 1e-9,
           "closest points of two segments: the smallest distance", got, want);
  }

  // the rectangle's surface distance along a direction: against walking out of it
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3 axis = (1.0 / norm(rvec() + Vec3{0, 0, 0.1})) * (rvec() + Vec3{0, 0, 0.1});
    const Vec3 axis_u = (1.0 / norm(axis)) * axis;
    const Vec3 e_t = rect_thickness_dir(axis_u, rvec());
    const Vec3 e_w = cross(e_t, axis_u);
    Vec3 u = rvec();
    u = u - dot(u, axis_u) * axis_u;
    u = (1.0 / norm(u)) * u;
    const double w = 30e-6, th = 7.5e-6;
    const double got = rect_surface_distance(axis_u, e_t, w, th, u), want = walk_out(e_w, e_t, w, th, u);
    expect(std::fabs(got - want) <= 1e-12 * w, "rectangle: distance to the surface along u", got, want);
    expect(std::fabs(norm(e_t) - 1.0) < 1e-12 && std::fabs(dot(e_t, axis_u)) < 1e-12,
           "thickness direction: unit and normal to the axis", norm(e_t), 1.0);
  }
  {
    // the reference direction made normal to the axis; along the axis it falls back to x's part
    const Vec3 t = rect_thickness_dir({1, 0, 0}, {1, 0, 1});
    expect(std::fabs(t.x) < 1e-15 && std::fabs(t.z - 1.0) < 1e-15, "thickness direction: up's part normal to x", t.z, 1.0);
    const Vec3 f = rect_thickness_dir({0, 0, 1}, {0, 0, 1});
    expect(std::fabs(f.x - 1.0) < 1e-15, "thickness direction: axis along up -> x", f.x, 1.0);
  }

  // force transfer to the nodes (thesis 2.4.2): the total force and the moment of the force at its
  // point (centre-line point at fraction s plus the offset) are preserved
  for (int trial = 0; trial < 100; ++trial) {
    const Vec3 xa = rvec(), xb = rvec(), F = rvec(), r_off = 1e-2 * rvec();
    const double s = 0.5 * (U(rng) + 1.0);
    const NodeLoads L = transfer_to_nodes(s, F, r_off);
    const Vec3 sum = L.fa + L.fb;
    const Vec3 point = lerp(xa, xb, s) + r_off;
    const Vec3 moment = cross(xa, L.fa) + cross(xb, L.fb) + L.ta + L.tb;  // about the origin
    const Vec3 want = cross(point, F);
    expect(dist(sum, F) < 1e-15, "node loads: the total force", norm(sum - F), 0.0);
    expect(dist(moment, want) < 1e-14, "node loads: the moment of the force at its point", norm(moment - want), 0.0);
    expect(dist(L.ta, L.tb) == 0.0, "node loads: the offset's moment split equally", norm(L.ta - L.tb), 0.0);
  }

  // lever-rule inverse mass: w1^2/m1 + w2^2/m2; a clamped node (infinite mass) adds nothing
  expect(std::fabs(lever_inverse_mass(0.25, 2.0, 0.75, 3.0) - (0.0625 / 2.0 + 0.5625 / 3.0)) < 1e-16,
         "lever inverse mass", lever_inverse_mass(0.25, 2.0, 0.75, 3.0), 0.0625 / 2.0 + 0.5625 / 3.0);
  expect(lever_inverse_mass(0.5, 2.0) == 0.125, "lever inverse mass against a static body", lever_inverse_mass(0.5, 2.0), 0.125);

  // regularised Coulomb friction's secant: c = mu f / sqrt(vt^2 + v_eps^2), v_eps = mu f / c_stick,
  // c_stick = stick / (inv_m h): at rest the stick damping, fast sliding mu f / |vt|
  {
    const double mu = 0.5, f = 2e-6, inv_m = 1.0 / 3e-9, stick = 100.0, h = 1e-6;
    const double c_stick = stick / (inv_m * h);
    expect(std::fabs(regularized_friction_secant(mu, f, 0.0, inv_m, stick, h) / c_stick - 1.0) < 1e-14,
           "friction secant at rest: the stick damping", regularized_friction_secant(mu, f, 0.0, inv_m, stick, h), c_stick);
    const double vt = 1e3 * mu * f / c_stick;  // far in slip: the force is mu f within 1e-6
    const double c = regularized_friction_secant(mu, f, vt * vt, inv_m, stick, h);
    expect(std::fabs(c * vt / (mu * f) - 1.0) < 1e-6, "friction secant in slip: force mu f", c * vt, mu * f);
    expect(regularized_friction_secant(mu, -f, 0.0, inv_m, stick, h) == 0.0 &&
           regularized_friction_secant(0.0, f, 0.0, inv_m, stick, h) == 0.0,
           "friction secant: none without compression or a coefficient");
  }

  // the steric servo's saturated error: cap tanh((h_R - h)/cap): linear near h_R, at most cap
  {
    StericParams p{1e-9, 0.5e-9, 1e-9, 1e-8};  // h0, h_R, h_S, t_R
    p.h_cap = 0.2e-9;
    const double c = p.cap();
    expect(c == 0.2e-9, "servo cap: h_cap when given", c, 0.2e-9);
    expect(servo_error(p, p.h_R) == 0.0, "servo error at h_R");
    const double dh = 1e-6 * c;
    expect(std::fabs(servo_error(p, p.h_R - dh) / dh - 1.0) < 1e-9, "servo error: slope 1 at h_R",
           servo_error(p, p.h_R - dh) / dh, 1.0);
    expect(std::fabs(servo_error(p, p.h_R - 1e3 * c) - c) < 1e-12 * c, "servo error saturates at the cap",
           servo_error(p, p.h_R - 1e3 * c), c);
  }

  return fiberform::check::finish("test_contact_geometry");
}
