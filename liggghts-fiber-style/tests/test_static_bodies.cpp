/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of physics/static_bodies.h: the element/node/plane contact geometry against closed
   forms, and the contact of real fibers (E = 10 GPa, 1500 kg/m3) with static bodies inside the
   implicit step (StaticContactModel): a fiber dropped across two yarns at steps from 1e-6 to 1e-4 s
   comes to rest without passing through them (transient overlap < 5 % of the fiber radius up to
   1e-5 s, centre line outside the yarn at 1e-4 s) and the two contact forces equal the support
   reactions of a beam on two supports (statics); Coulomb friction on a plane holds below mu N and
   slides at (F_t - mu N)/M above it. The rectangular contact section of a collapsed fiber against
   the closed forms of a rectangle (extent along a direction; gaps to a yarn and a plane). The
   per-step candidate lists of the yarn search give exactly the full lookup's hits. A moving plane
   met where it is at the end of each sub-step of a split step. */
#include <cmath>
#include <cstdio>
#include <vector>

#include "check.h"
#include "rod_fixtures.h"
#include "physics/static_bodies.h"

using namespace fiberform::physics;
using beam::Vec3;

namespace {
using fiberform::check::expect;

void test_geometry() {
  StaticBodies b;
  const double R = 50e-6, r = 10e-6;
  // yarn along y through x = 20 um, z = 0; element along x at height z
  b.add_segment({20e-6, -1e-3, 0}, {20e-6, 1e-3, 0}, R, 0);
  b.add_segment({20e-6, 1e-3, 0}, {20e-6, 2e-3, 0}, R, 0);  // same yarn: one hit only
  b.build_bins(r + 1e-6 + 200e-6);
  const double z = R + r + 3e-9;
  BodyHit hits[StaticBodies::kMaxHits];
  const int nh = b.element_hits({-80e-6, 0, z}, {120e-6, 0, z}, r, 1e-6, hits);
  expect(nh == 1, "one hit per yarn", nh, 1);
  expect(std::fabs(hits[0].h - 3e-9) < 1e-15, "element gap = z - R - r", hits[0].h, 3e-9);
  expect(std::fabs(hits[0].s - 0.5) < 1e-12, "element parameter at the crossing", hits[0].s, 0.5);
  expect(std::fabs(hits[0].n.z - 1.0) < 1e-12, "normal towards the fiber", hits[0].n.z, 1.0);
  // node 30 um beyond the yarn's end along its axis: distance to the end cap point
  const int nn = b.node_hits({20e-6, 2e-3 + 30e-6, R}, r, 1e-4, hits);
  const double want = std::sqrt(30e-6 * 30e-6 + R * R) - R - r;
  expect(nn == 1 && std::fabs(hits[0].h - want) < 1e-15, "node gap beyond the segment end", hits[0].h, want);
  // far element: no hit
  expect(b.element_hits({-80e-6, 0, 1e-3}, {120e-6, 0, 1e-3}, r, 1e-6, hits) == 0, "no hit far away");
  expect(b.add_plane({0, 0, -1e-4}, {0, 0, 2}), "plane accepted");
  expect(!b.add_plane({0, 0, 0}, {0, 0, 0}), "zero normal refused");
  expect(std::fabs(b.plane_gap(0, {5, 5, 2e-4}, r) - (3e-4 - r)) < 1e-15, "plane gap");
}

// The rectangular contact section of a collapsed fiber (2 a1 x 2 a2): its extent from the centre
// line along a direction, against the closed forms of a rectangle.
void test_rect_sections() {
  using fiberform::testing::Fiber;
  using fiberform::testing::make_fiber;
  const double a1 = 12e-6, a2 = 3e-6, s2 = std::sqrt(0.5);
  const Vec3 ax{1, 0, 0}, up{0, 0, 1};
  // thickness axis t2 = z (flat): a2 up, a1 sideways, the corner direction at most the half-diagonal
  expect(std::fabs(rect_extent(ax, up, a1, a2, {0, 0, 1}) - a2) < 1e-18, "rect: face along t2", rect_extent(ax, up, a1, a2, {0, 0, 1}), a2);
  expect(std::fabs(rect_extent(ax, up, a1, a2, {0, -1, 0}) - a1) < 1e-18, "rect: face along t1", rect_extent(ax, up, a1, a2, {0, -1, 0}), a1);
  // at 45 degrees the line leaves through the thin face: a2 / sin 45
  expect(std::fabs(rect_extent(ax, up, a1, a2, {0, s2, s2}) - a2 / s2) < 1e-17, "rect: 45 degrees", rect_extent(ax, up, a1, a2, {0, s2, s2}), a2 / s2);
  // through the corner exactly: hypot(a1, a2)
  const double hd = std::hypot(a1, a2);
  expect(std::fabs(rect_extent(ax, up, a1, a2, {0, a1 / hd, a2 / hd}) - hd) < 1e-17, "rect: corner", rect_extent(ax, up, a1, a2, {0, a1 / hd, a2 / hd}), hd);
  // an axial part of n is dropped; t2 not normal to the axis is made so
  expect(std::fabs(rect_extent(ax, {0.3, 0, 2}, a1, a2, {s2, 0, s2}) - a2) < 1e-18, "rect: axial parts dropped", rect_extent(ax, {0.3, 0, 2}, a1, a2, {s2, 0, s2}), a2);
  expect(std::fabs(rect_extent(ax, up, a1, a2, {1, 0, 0}) - a2) < 1e-18, "rect: along the axis: the smaller half-side");
  // its gradient with respect to n against central differences, on either face (generic frame)
  for (const Vec3 n0 : {Vec3{0.3, 0.2, 0.9}, Vec3{0.2, 0.95, 0.1}}) {
    const Vec3 axg = (1.0 / norm(Vec3{1, 0.2, -0.1})) * Vec3{1, 0.2, -0.1}, t2g{0.1, 0.3, 1.0};
    const Vec3 n = (1.0 / norm(n0)) * n0;
    Vec3 g;
    rect_extent(axg, t2g, a1, a2, n, &g);
    const double dh = 1e-7;
    double worst = 0.0;
    for (int i = 0; i < 3; ++i) {
      Vec3 dp, dm;
      dp[i] = dh;
      dm[i] = -dh;
      const double fd = (rect_extent(axg, t2g, a1, a2, n + dp) - rect_extent(axg, t2g, a1, a2, n + dm)) / (2 * dh);
      worst = std::max(worst, std::fabs(fd - g[i]));
    }
    expect(worst < 1e-6 * norm(g) + 1e-15, "rect: extent gradient = central differences", worst, 0.0);
  }
  // nodes: a fiber along x with t1 vertical lies on its edge (make_fiber's frame), turned about its
  // axis (make_ribbon) it lies flat; circles keep their radius
  Fiber edge = make_fiber(2, 40e-6, a1, 0.6 * a1, {0, 0, 0});
  for (rod::Node &nd : edge.nodes) {
    nd.rect[0] = a1;
    nd.rect[1] = a2;
  }
  Fiber flat = fiberform::testing::make_ribbon(2, 40e-6, a1, a2, {0, 0, 0});
  Fiber circ = make_fiber(2, 40e-6, a1, 0.6 * a1, {0, 0, 0});
  const Vec3 z{0, 0, 1};
  expect(std::fabs(element_extent(edge.nodes[0], edge.nodes[1], z) - a1) < 1e-17, "ribbon on its edge: a1 up", element_extent(edge.nodes[0], edge.nodes[1], z), a1);
  expect(std::fabs(element_extent(flat.nodes[0], flat.nodes[1], z) - a2) < 1e-17, "flat ribbon: a2 up", element_extent(flat.nodes[0], flat.nodes[1], z), a2);
  expect(std::fabs(node_extent(flat.nodes[1], z) - a2) < 1e-17, "flat ribbon node: a2 up", node_extent(flat.nodes[1], z), a2);
  expect(element_extent(circ.nodes[0], circ.nodes[1], z) == a1 && section_reach(circ.nodes[0]) == a1 &&
             law_radius(circ.nodes[0]) == a1, "circle: the radius");
  expect(std::fabs(section_reach(flat.nodes[0]) - hd) < 1e-18 && law_radius(flat.nodes[0]) == a2,
         "ribbon: reach = half-diagonal, law radius = half-thickness");
  // on a yarn across it and on a plane: the gap from the face, not from the circle of a1
  StaticBodies b;
  const double R = 50e-6;
  b.add_segment({0, -1e-3, -R - a2 - 5e-9}, {0, 1e-3, -R - a2 - 5e-9}, R, 0);
  b.build_bins(hd + 1e-6 + 40e-6);
  expect(b.add_plane({0, 0, -a2 - 7e-9}, {0, 0, 1}), "plane accepted");
  const ContactLaw law;
  StaticContactModel model(b, law, 0.0);
  std::vector<Vec3> F(flat.nodes.size());
  model.evaluate(flat.nodes, F, nullptr);
  expect(std::fabs(model.min_gap() - 5e-9) < 1e-15, "flat ribbon on a yarn: gap from its face", model.min_gap(), 5e-9);
  StaticBodies pl;
  expect(pl.add_plane({0, 0, -a2 - 7e-9}, {0, 0, 1}), "plane accepted");
  StaticContactModel on_plane(pl, law, 0.0);
  on_plane.evaluate(flat.nodes, F, nullptr);
  expect(std::fabs(on_plane.min_gap() - 7e-9) < 1e-15, "flat ribbon on a plane: gap from its face", on_plane.min_gap(), 7e-9);
}

// A moving plane inside a split step (rod::NodeForceModel::begin_whole_step): its point is where it
// is at the whole step's end, so a sub-step [t0, t0 + h] of a step of length H meets it v (H - t0 - h)
// back along its motion. A plate 20 nm above a fiber moving down at 20 mm/s (the press), step 1 us:
// the first half-step sees the gap 10 nm larger than the whole step, the same gap as a plane put
// there (closed form of the motion), the second half-step the whole step's gap.
void test_moving_plane_in_sub_steps() {
  using fiberform::testing::make_fiber;
  const double r = 10e-6, H = 1e-6, u = 0.02, g0 = 20e-9;
  fiberform::testing::Fiber f = make_fiber(4, 80e-6, r, 0.6 * r, {0, 0, 0});
  StaticBodies moving, placed;
  moving.add_plane({0, 0, r + g0}, {0, 0, -1}, {0, 0, -u});
  placed.add_plane({0, 0, r + g0 + 0.5 * H * u}, {0, 0, -1});
  const ContactLaw law;
  StaticContactModel m(moving, law, 0.0), p(placed, law, 0.0);
  std::vector<Vec3> F(f.nodes.size());
  m.begin_whole_step(H);
  m.begin_step(f.nodes, 0.0, 0.5 * H);
  m.evaluate(f.nodes, F, nullptr);
  p.begin_whole_step(H);
  p.begin_step(f.nodes, 0.0, 0.5 * H);
  p.evaluate(f.nodes, F, nullptr);
  expect(std::fabs(m.min_gap() - (g0 + 0.5 * H * u)) < 1e-15 && std::fabs(m.min_gap() - p.min_gap()) < 1e-15,
         "moving plane: the first half-step meets it half a step back", m.min_gap(), g0 + 0.5 * H * u);
  m.begin_step(f.nodes, 0.5 * H, 0.5 * H);
  m.evaluate(f.nodes, F, nullptr);
  expect(std::fabs(m.min_gap() - g0) < 1e-15, "moving plane: the second half-step at the step's end", m.min_gap(), g0);
  m.begin_whole_step(H);
  m.begin_step(f.nodes, 0.0, H);
  m.evaluate(f.nodes, F, nullptr);
  expect(std::fabs(m.min_gap() - g0) < 1e-15, "moving plane: the whole step at its end", m.min_gap(), g0);
}

using fiberform::testing::Fiber;
using fiberform::testing::make_fiber;

// every node of f loaded by acc (m/s^2) per mass downward (-z) and falling at speed (m/s)
void load_falling(Fiber &f, double acc, double speed) {
  for (rod::Node &nd : f.nodes) {
    nd.F = {0, 0, -acc * nd.m};
    nd.v = {0, 0, -speed};
  }
}

// A fiber of radius r across two parallel yarns (along y at x = +-d, radius R), released 200 nm above
// them at 50 mm/s with a load of 2000 m/s^2 per mass (the drag of the lay-down's flow on such
// fibers), background drag time 1 ms: no pass-through, rest, two equal contact forces = the load.
void test_drop_on_yarns(double h, double r) {
  const double R = 60e-6, d = 150e-6, L = 0.6e-3, acc = 2000.0;
  StaticBodies b;
  for (double x : {-d, d}) b.add_segment({x, -1e-3, 0}, {x, 1e-3, 0}, R, x < 0 ? 0 : 1);
  const int ne = 12;
  Fiber f = make_fiber(ne, L, r, 0.6 * r, Vec3{0, 0, R + r + 200e-9});
  b.build_bins(r + 50e-9 + 2 * L / ne);
  ContactLaw law;  // vdW + electrostatics + steric, cellulose in 1 mM water (contact_law.h)
  law.steric.s1_damping = true;  // as fix wall/fiber/yarns with implicit_force newton
  StaticContactModel model(b, law, 0.0);
  std::vector<rod::NodeForceModel *> models{&model};
  load_falling(f, acc, 0.05);
  rod::Options opt;
  opt.tau_drag = 1e-3;
  rod::Stepper st;
  st.initialise(f.nodes, f.els, opt);
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  const double T = 0.02;  // 20 background-drag times
  const int steps = static_cast<int>(std::lround(T / h));
  double gap_min = 1.0;
  long iters = 0;
  int splits = 0;
  bool ok = true;
  for (int s = 0; s < steps && ok; ++s) {
    const rod::Stats res = st.step(f.nodes, f.els, h, g, opt, &models);
    ok = res.ok;
    iters += res.iterations;
    splits += res.splits;
    // gap at the converged state, yarn by yarn
    std::vector<Vec3> Fc(f.nodes.size());
    model.evaluate(f.nodes, Fc, nullptr);
    gap_min = std::min(gap_min, model.min_gap());
  }
  char what[160];
  std::snprintf(what, sizeof what, "drop on yarns, h = %g s, r = %g m: every step converges", h, r);
  expect(ok, what);
  // no pass-through: the centre line never reaches the yarn (gap > -r); up to 10 us the transient
  // overlap of the impact stays below 5 % of the radius
  const double bound = h <= 1e-5 ? 0.05 * r : r;
  std::snprintf(what, sizeof what, "drop on yarns, h = %g s, r = %g m: no pass-through (gap > -%g m)", h, r,
                bound);
  expect(gap_min > -bound, what, gap_min, -bound);
  double vmax = 0, fz = 0, fleft = 0, want_left = 0;
  for (const rod::Node &nd : f.nodes) {
    vmax = std::max(vmax, beam::norm(nd.v));
    fz += nd.Fmodel.z;
    if (nd.x.x < 0) fleft += nd.Fmodel.z;
    // a beam on two supports is statically determinate: moments about the right yarn's axis
    want_left += acc * nd.m * (d - nd.x.x) / (2.0 * d);
  }
  const double load = acc * f.mass;
  std::snprintf(what, sizeof what, "drop on yarns, h = %g s, r = %g m: at rest", h, r);
  expect(vmax < 1e-4, what, vmax, 1e-4);
  std::snprintf(what, sizeof what, "drop on yarns, h = %g s, r = %g m: contact forces carry the load", h, r);
  expect(std::fabs(fz / load - 1.0) < 1e-3, what, fz, load);
  std::snprintf(what, sizeof what, "drop on yarns, h = %g s, r = %g m: support reactions from statics", h, r);
  expect(std::fabs(fleft / want_left - 1.0) < 1e-3, what, fleft, want_left);
  std::printf("drop on yarns h %.0e s r %.0e m: %d steps, %.2f Newton iterations/step, %d splits, "
              "smallest gap %.3e m, final speed %.2e m/s, contact/load %.6f\n",
              h, r, steps, static_cast<double>(iters) / steps, splits, gap_min, vmax, fz / load);
}

// The landing predictor (rod::Options::land_predict): a fiber falling at 0.3 m/s onto five yarns
// whose gaps differ (200-360 nm) covers 3 um per step of 10 us, so the first correction of the impact
// step carries all five contacts from outside to deep inside. The limiter alone lands one of them per
// iteration; the predictor lands them together. Both reach the same rest (statics of the load) with
// no pass-through; the predictor takes fewer iterations for the impact and linearises contacts.
struct LandingRun {
  long impact_iters = 0, limited = 0, predicted = 0;
  double gap_min = 1.0, fz = 0.0;
  bool ok = true;
  std::vector<Vec3> x;
};
LandingRun drop_on_five_yarns(bool predict) {
  const double R = 60e-6, d = 110e-6, r = 12e-6, L = 0.6e-3, acc = 2000.0, h = 1e-5;
  StaticBodies b;
  for (int k = 0; k < 5; ++k) {
    const double x = (k - 2) * d, z = -40e-9 * k;  // gaps 200, 240, ..., 360 nm
    b.add_segment({x, -1e-3, z}, {x, 1e-3, z}, R, k);
  }
  Fiber f = make_fiber(24, L, r, 0.6 * r, Vec3{0, 0, R + r + 200e-9});
  b.build_bins(r + 50e-9 + 2 * L / 24);
  ContactLaw law;
  law.steric.s1_damping = true;
  StaticContactModel model(b, law, 0.0);
  std::vector<rod::NodeForceModel *> models{&model};
  load_falling(f, acc, 0.3);
  rod::Options opt;
  opt.tau_drag = 1e-3;
  opt.land_predict = predict;
  rod::Stepper st;
  st.initialise(f.nodes, f.els, opt);
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  LandingRun out;
  for (int s = 0; s < 2000 && out.ok; ++s) {  // 20 ms: 20 drag times
    const rod::Stats res = st.step(f.nodes, f.els, h, g, opt, &models);
    out.ok = res.ok;
    if (s < 3) out.impact_iters += res.iterations;
    out.limited += res.limited;
    out.predicted += res.predicted;
    std::vector<Vec3> Fc(f.nodes.size());
    model.evaluate(f.nodes, Fc, nullptr);
    out.gap_min = std::min(out.gap_min, model.min_gap());
  }
  for (const rod::Node &nd : f.nodes) {
    out.fz += nd.Fmodel.z / (acc * f.mass);
    out.x.push_back(nd.x);
  }
  return out;
}

void test_landing_predictor() {
  const double r = 12e-6;
  const LandingRun lim = drop_on_five_yarns(false), pre = drop_on_five_yarns(true);
  expect(lim.ok && pre.ok, "landing on five yarns: every step converges with and without the predictor");
  expect(lim.predicted == 0, "landing on five yarns: no predicted contacts without the predictor", lim.predicted, 0);
  expect(pre.predicted >= 4, "landing on five yarns: the predictor linearises the landing contacts",
         pre.predicted, 4);
  expect(pre.impact_iters < lim.impact_iters, "landing on five yarns: fewer Newton iterations for the impact",
         pre.impact_iters, lim.impact_iters);
  expect(lim.gap_min > -0.05 * r && pre.gap_min > -0.05 * r, "landing on five yarns: no pass-through",
         std::min(lim.gap_min, pre.gap_min), -0.05 * r);
  expect(std::fabs(lim.fz - 1.0) < 1e-3 && std::fabs(pre.fz - 1.0) < 1e-3,
         "landing on five yarns: the contacts carry the load at rest", pre.fz, lim.fz);
  // the same rest on the yarns: heights of the nodes (the fiber also slides slowly along x, down the
  // slope of the yarns' heights, frictionless: a neutral motion that the impact's transients set)
  double dx = 0.0;
  for (std::size_t k = 0; k < pre.x.size(); ++k) dx = std::max(dx, std::fabs(pre.x[k].z - lim.x[k].z));
  expect(dx < 1e-4 * r, "landing on five yarns: the same rest heights with and without the predictor", dx,
         1e-4 * r);
  std::printf("landing on five yarns: impact (3 steps) %ld iterations with the predictor, %ld without; limited "
              "iterations %ld / %ld, predicted contacts %ld; smallest gap %.3e / %.3e m; rest heights differ "
              "by %.2e m\n",
              pre.impact_iters, lim.impact_iters, pre.limited, lim.limited, pre.predicted, pre.gap_min,
              lim.gap_min, dx);
}

// A fiber lying on a plane (normal +z) under a normal load a_n and a tangential load a_t along x:
// friction mu holds it for a_t < mu a_n and lets it accelerate at a_t - mu a_n above.
void test_friction(double at_over_an, double stick = StaticContactModel::kStick) {
  const double r = 10e-6, L = 0.4e-3, an = 2000.0, mu = 0.5, h = 1e-5;
  StaticBodies b;
  b.add_plane({0, 0, 0}, {0, 0, 1});
  Fiber f = make_fiber(8, L, r, 0.6 * r, Vec3{0, 0, r + 0.4e-9});
  ContactLaw law;
  StaticContactModel model(b, law, mu, stick);
  std::vector<rod::NodeForceModel *> models{&model};
  for (rod::Node &nd : f.nodes) nd.F = {at_over_an * an * nd.m, 0, -an * nd.m};
  rod::Options opt;
  rod::Stepper st;
  st.initialise(f.nodes, f.els, opt);
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  // settle normally first (no tangential load), then apply it for T
  std::vector<Vec3> Ft(f.nodes.size());
  for (std::size_t k = 0; k < f.nodes.size(); ++k) {
    Ft[k] = f.nodes[k].F;
    f.nodes[k].F.x = 0;
  }
  bool ok = true;
  for (int s = 0; s < 200 && ok; ++s) ok = st.step(f.nodes, f.els, h, g, opt, &models).ok;
  const double x0 = f.nodes[4].x.x;
  for (std::size_t k = 0; k < f.nodes.size(); ++k) f.nodes[k].F = Ft[k];
  const double T = 2e-3;
  const int steps = static_cast<int>(std::lround(T / h));
  for (int s = 0; s < steps && ok; ++s) ok = st.step(f.nodes, f.els, h, g, opt, &models).ok;
  expect(ok, "friction: every step converges");
  const double dx = f.nodes[4].x.x - x0;
  if (at_over_an < mu) {
    // regularised stick: creep at F_t / c_stick = a_t h / stick per contact point
    const double creep = at_over_an * an * h / stick * T;
    char what[160];
    std::snprintf(what, sizeof what, "friction holds below mu N, stick factor %g: creeps at F_t / c_stick (2 ms, m)",
                  stick);
    expect(std::fabs(dx) < 2.0 * creep && std::fabs(dx) > 0.5 * creep, what, dx, creep);
  } else {
    const double want = 0.5 * (at_over_an - mu) * an * T * T;
    expect(std::fabs(dx / want - 1.0) < 0.02, "friction: slides at (F_t - mu N)/M", dx, want);
  }
  std::printf("friction F_t/N = %.2f, mu = %.2f, stick factor %g: displacement %.4e m after %.0e s\n", at_over_an,
              mu, stick, dx, T);
}

// gap_node_gradient: the gradient of a gap between two elements' centre lines with respect to the
// four node positions, the closest points moving with the nodes, against central differences of the
// gap with the closest points recomputed. Rectangles (a1 16 um, a2 4 um): crossing ribbons whose
// centre-line direction leaves a face at an angle (both parameters inside), a pair with one
// parameter at an end, a near-parallel pair (10 degrees); a ribbon element against a yarn segment
// (static: its two rows unused). The extents are taken about the elements' chords at the base
// positions in the differences (gap_node_gradient leaves out the chords' turning, as the force
// models do); the full difference is then compared with the gradient before this term
// (the lever weights times the unit gradient at fixed points). Circles: the weights times n.
void test_gap_gradient() {
  const double a1 = 16e-6, a2 = 4e-6, R = 50e-6;
  const Vec3 t2[4] = {{0.1, 0.05, 1.0}, {0.05, 0.1, 1.0}, {-0.2, 0.1, 1.0}, {-0.1, 0.2, 1.0}};
  // the gap with the element axes held at `axA`, `axB` (unit; zero: each element's own chord)
  auto gap = [&](const Vec3 x[4], bool rect, bool yarn, Vec3 axA, Vec3 axB, Vec3 *grad, double *sp = nullptr,
                 double *tp = nullptr) {
    double s, t;
    closest_params_segment_segment(x[0], x[1], x[2], x[3], s, t);
    if (sp) *sp = s;
    if (tp) *tp = t;
    const Vec3 d = lerp(x[0], x[1], s) - lerp(x[2], x[3], t);
    const double dist = norm(d);
    const Vec3 n = (1.0 / dist) * d;
    auto extent = [&](int i, Vec3 ax, Vec3 *de) {
      if (!rect) {
        *de = Vec3{0, 0, 0};
        return 10e-6;
      }
      const Vec3 a = norm(ax) > 0 ? ax : (1.0 / norm(x[i + 1] - x[i])) * (x[i + 1] - x[i]);
      return rect_extent(a, t2[i] + t2[i + 1], a1, a2, n, de);
    };
    Vec3 deA, deB;
    const double eA = extent(0, axA, &deA);
    double eB = R;
    deB = Vec3{0, 0, 0};
    if (!yarn) eB = extent(2, axB, &deB);
    if (grad) gap_node_gradient(x[0], x[1], x[2], x[3], s, t, d, gap_gradient(n, dist, deA + deB), grad);
    return dist - eA - eB;
  };
  struct Case {
    const char *name;
    Vec3 x[4];
    bool rect, yarn;
  };
  const Case cases[] = {
      {"ribbons crossing, tilted", {{-30e-6, -2e-6, 14e-6}, {32e-6, 3e-6, 11e-6}, {1e-6, -28e-6, 0}, {-4e-6, 33e-6, 3e-6}}, true, false},
      {"ribbons, one end", {{12e-6, -2e-6, 13e-6}, {60e-6, 3e-6, 16e-6}, {1e-6, -28e-6, 0}, {-4e-6, 33e-6, 3e-6}}, true, false},
      {"ribbons near-parallel", {{-30e-6, 1e-6, 9e-6}, {30e-6, 3e-6, 10e-6}, {-29e-6, -5e-6, 0}, {29e-6, 6e-6, 1e-6}}, true, false},
      {"ribbon on a yarn", {{-30e-6, -2e-6, 58e-6}, {32e-6, 3e-6, 55e-6}, {1e-6, -300e-6, 0}, {-4e-6, 330e-6, 3e-6}}, true, true},
      {"circles crossing", {{-30e-6, -2e-6, 24e-6}, {32e-6, 3e-6, 21e-6}, {1e-6, -28e-6, 0}, {-4e-6, 33e-6, 3e-6}}, false, false},
  };
  for (const Case &c : cases) {
    const Vec3 axA = (1.0 / norm(c.x[1] - c.x[0])) * (c.x[1] - c.x[0]);
    const Vec3 axB = (1.0 / norm(c.x[3] - c.x[2])) * (c.x[3] - c.x[2]);
    Vec3 g[4];
    double s, t;
    gap(c.x, c.rect, c.yarn, axA, axB, g, &s, &t);
    const int rows = c.yarn ? 2 : 4;
    const double eps = 1e-11;
    double worst = 0.0, scale = 0.0, worst_full = 0.0, worst_old = 0.0;
    // the gradient before: the weights times the unit gradient at fixed points
    Vec3 old[4];
    {
      const Vec3 d = lerp(c.x[0], c.x[1], s) - lerp(c.x[2], c.x[3], t);
      const double dist = norm(d);
      const Vec3 n = (1.0 / dist) * d;
      Vec3 deA{0, 0, 0}, deB{0, 0, 0};
      if (c.rect) rect_extent(axA, t2[0] + t2[1], a1, a2, n, &deA);
      if (c.rect && !c.yarn) rect_extent(axB, t2[2] + t2[3], a1, a2, n, &deB);
      const Vec3 u = gap_gradient_dir(n, dist, deA + deB);
      const double w[4] = {1.0 - s, s, -(1.0 - t), -t};
      for (int k = 0; k < 4; ++k) old[k] = w[k] * u;
    }
    for (int k = 0; k < rows; ++k)
      for (int i = 0; i < 3; ++i) {
        Vec3 xp[4] = {c.x[0], c.x[1], c.x[2], c.x[3]}, xm[4] = {c.x[0], c.x[1], c.x[2], c.x[3]};
        xp[k][i] += eps;
        xm[k][i] -= eps;
        const double fd = (gap(xp, c.rect, c.yarn, axA, axB, nullptr) - gap(xm, c.rect, c.yarn, axA, axB, nullptr)) / (2 * eps);
        const double fd_full = (gap(xp, c.rect, c.yarn, Vec3{}, Vec3{}, nullptr) - gap(xm, c.rect, c.yarn, Vec3{}, Vec3{}, nullptr)) / (2 * eps);
        worst = std::max(worst, std::fabs(fd - g[k][i]));
        worst_full = std::max(worst_full, std::fabs(fd_full - g[k][i]));
        worst_old = std::max(worst_old, std::fabs(fd_full - old[k][i]));
        scale = std::max(scale, std::fabs(g[k][i]));
      }
    std::printf("gap gradient, %s (s %.3f, t %.3f): |grad| %.3f, central differences %.1e (chords held), %.1e "
                "(chords turning; the weights times the unit gradient: %.1e)\n",
                c.name, s, t, scale, worst, worst_full, worst_old);
    expect(worst < 1e-4 * scale, "gap gradient = central differences (chords held)", worst, 0.0);
    if (!c.rect) {
      const Vec3 d = lerp(c.x[0], c.x[1], s) - lerp(c.x[2], c.x[3], t);
      const Vec3 n = (1.0 / norm(d)) * d;
      const double w[4] = {1.0 - s, s, -(1.0 - t), -t};
      double dev = 0.0;
      for (int k = 0; k < 4; ++k) dev = std::max(dev, norm(g[k] - w[k] * n));
      expect(dev < 1e-12, "circles: the lever weights times n", dev, 0.0);
    }
    if (c.rect && !c.yarn && s > 0 && s < 1 && t > 0 && t < 1)
      expect(worst_full < 0.2 * worst_old, "the moving contact points are most of the gradient's error", worst_full, worst_old);
    if (c.rect && s > kSlideFade && s < 1 - kSlideFade && t > kSlideFade && t < 1 - kSlideFade) {
      // the fade (the contact models' kSlideFade): exact farther inside than the fade; continuous
      // where a point reaches an end (the same positions with s taken just inside and at 0)
      const Vec3 d = lerp(c.x[0], c.x[1], s) - lerp(c.x[2], c.x[3], t);
      Vec3 gf[4], g0[4], gi[4];
      const Vec3 gd = g[0] + g[1];  // any vector: the function is linear in gd
      gap_node_gradient(c.x[0], c.x[1], c.x[2], c.x[3], s, t, d, gd, gf, kSlideFade);
      gap_node_gradient(c.x[0], c.x[1], c.x[2], c.x[3], s, t, d, gd, g0);
      double dev = 0.0, jump = 0.0;
      for (int k = 0; k < 4; ++k) dev = std::max(dev, norm(gf[k] - g0[k]));
      gap_node_gradient(c.x[0], c.x[1], c.x[2], c.x[3], 1e-9, t, d, gd, gi, kSlideFade);
      gap_node_gradient(c.x[0], c.x[1], c.x[2], c.x[3], 0.0, t, d, gd, g0, kSlideFade);
      for (int k = 0; k < 4; ++k) jump = std::max(jump, norm(gi[k] - g0[k]));
      expect(dev == 0.0, "fade: exact farther inside", dev, 0.0);
      expect(jump < 1e-6 * scale, "fade: continuous where a contact point reaches an end", jump, 0.0);
    }
    Vec3 sum{0, 0, 0};
    for (int k = 0; k < 4; ++k) sum = sum + g[k];
    if (!c.yarn) expect(norm(sum) < 1e-12 * scale, "action = reaction: the gradients sum to zero", norm(sum), 0.0);
  }
}

}  // namespace

// A small LCG: the tests' own numbers, no library generator's sequence (uniform in [0, 1)).
struct Lcg {
  unsigned long seed;
  double operator()() {
    seed = seed * 6364136223846793005UL + 1442695040888963407UL;
    return static_cast<double>(seed >> 11) * (1.0 / 9007199254740992.0);
  }
};

// `yarns` random yarns of 6 segments each in an L x L x 0.2 mm box, radii R x [0.5, 1.5)
void add_tangle(StaticBodies &b, Lcg &uni, int yarns, double L, double R) {
  for (int y = 0; y < yarns; ++y) {
    Vec3 a{uni() * L, uni() * L, uni() * 0.2e-3};
    for (int k = 0; k < 6; ++k) {
      const Vec3 d{(uni() - 0.5) * 200e-6, (uni() - 0.5) * 200e-6, (uni() - 0.5) * 60e-6};
      b.add_segment(a, a + d, R * (0.5 + uni()), y);
      a = a + d;
    }
  }
}

// StaticBodies::Candidates (the per-step short list of StaticContactModel): element_hits over a
// list made at (a0, b0) equals the full bin lookup, hit for hit and bit for bit, for elements moved
// by up to 1.5 skin in random directions (beyond 0.999 skin the list is not complete and the lookup
// is used), in a tangle of random yarn segments; a list of stale bins is not used.
void test_candidates() {
  StaticBodies b;
  Lcg uni{12345};
  const double L = 1e-3;
  add_tangle(b, uni, 40, L, 50e-6);
  const double r = 10e-6, margin = r + 1e-6, skin = r;
  b.build_bins(r + margin + 200e-6);
  int used = 0, fell_back = 0, hits_seen = 0, mismatches = 0;
  for (int e = 0; e < 3000; ++e) {
    const Vec3 a0{uni() * L, uni() * L, uni() * 0.2e-3};
    const Vec3 b0 = a0 + Vec3{(uni() - 0.5) * 100e-6, (uni() - 0.5) * 100e-6, (uni() - 0.5) * 40e-6};
    StaticBodies::Candidates c;
    b.element_candidates(a0, b0, r, margin, skin, c);
    for (int m = 0; m < 4; ++m) {
      auto move = [&]() {
        const Vec3 d{uni() - 0.5, uni() - 0.5, uni() - 0.5};
        return (1.5 * skin * uni() / std::max(1e-12, beam::norm(d))) * d;
      };
      const Vec3 a = a0 + move(), bb = b0 + move();
      BodyHit full[StaticBodies::kMaxHits], listed[StaticBodies::kMaxHits];
      const int nf = b.element_hits(a, bb, r, margin, full);
      const int nl = b.element_hits(a, bb, r, margin, listed, &c);
      (b.complete(c, a, bb, r, margin) ? used : fell_back) += 1;
      hits_seen += nf;
      bool same = nf == nl;
      for (int q = 0; same && q < nf; ++q)
        same = full[q].seg == listed[q].seg && full[q].h == listed[q].h && full[q].s == listed[q].s &&
               full[q].t == listed[q].t && full[q].n.x == listed[q].n.x && full[q].n.y == listed[q].n.y &&
               full[q].n.z == listed[q].n.z;
      mismatches += same ? 0 : 1;
    }
  }
  expect(mismatches == 0, "candidate list: the same hits as the full lookup", mismatches, 0);
  expect(used > 2000 && fell_back > 1000, "candidate list: both paths taken", used, fell_back);
  expect(hits_seen > 1000, "candidate list: elements near yarns", hits_seen, 1000);
  // rebuilt bins: the list is stale
  StaticBodies::Candidates c;
  const Vec3 a0{0.5e-3, 0.5e-3, 0.1e-3}, b0{0.55e-3, 0.5e-3, 0.1e-3};
  b.element_candidates(a0, b0, r, margin, skin, c);
  expect(b.complete(c, a0, b0, r, margin), "candidate list complete where it was made");
  expect(!b.complete(c, a0, b0, r, 2 * margin), "candidate list: another margin is not covered");
  // within (StaticContactModel keeps a list for the next steps): half the skin, per end
  const Vec3 nudge{0.4 * skin, 0.0, 0.0}, shove{0.6 * skin, 0.0, 0.0};
  expect(b.within(c, a0 + nudge, b0, r, margin, 0.5), "kept list: ends moved 0.4 skin");
  expect(!b.within(c, a0, b0 + shove, r, margin, 0.5), "kept list: an end moved 0.6 skin is made again");
  expect(b.complete(c, a0, b0 + shove, r, margin), "... though still complete for this iterate");
  b.build_bins(r + margin + 200e-6);
  expect(!b.complete(c, a0, b0, r, margin), "candidate list stale after the bins are rebuilt");
  expect(!b.within(c, a0, b0, r, margin, 0.5), "kept list stale after the bins are rebuilt");
}

// StaticBodies::build_bins stores the bins as one array over their box, or, when one segment lies
// far from the others, as a hash map: in a tangle of random yarn segments, every element's hits
// (element_segment_hits) are those of a brute-force test of every segment, in the order of the
// segment ids, with the dense bins; with a segment 1 m away added (hash map) the hits are the same
// bit for bit, and so are the node lookups (node_hits).
void test_bins_dense_and_map() {
  StaticBodies b;
  Lcg uni{777};
  const double L = 1e-3, R = 40e-6;
  add_tangle(b, uni, 30, L, R);
  const double r = 10e-6, margin = r + 1e-6, reach = r + margin + 150e-6;  // elements up to 100 um
  b.build_bins(reach);
  expect(b.dense_bins(), "bins of a compact tangle: one array");
  std::vector<Vec3> ends;
  for (int e = 0; e < 2000; ++e) {
    const Vec3 a0{uni() * L, uni() * L, uni() * 0.2e-3};
    ends.push_back(a0);
    ends.push_back(a0 + Vec3{(uni() - 0.5) * 100e-6, (uni() - 0.5) * 100e-6, (uni() - 0.5) * 40e-6});
  }
  std::vector<std::vector<BodyHit>> dense(ends.size() / 2);
  std::vector<std::vector<BodyHit>> node_dense(ends.size());
  int missing = 0, extra = 0, seen = 0;
  for (std::size_t e = 0; e < dense.size(); ++e) {
    const Vec3 xa = ends[2 * e], xb = ends[2 * e + 1];
    b.element_segment_hits(xa, xb, r, margin, -1, dense[e]);
    std::vector<int> want;  // every segment closer than margin, by brute force
    const auto &segs = b.segments();
    for (std::size_t id = 0; id < segs.size(); ++id) {
      double se, ty;
      closest_params_segment_segment(xa, xb, segs[id].a, segs[id].b, se, ty);
      const double dist = beam::norm(lerp(xa, xb, se) - lerp(segs[id].a, segs[id].b, ty));
      if (dist - segs[id].radius - r < margin && dist > 0.0) want.push_back(static_cast<int>(id));
    }
    std::vector<int> got;
    for (const BodyHit &h : dense[e]) got.push_back(h.seg);
    seen += static_cast<int>(got.size());
    if (got != want) (got.size() < want.size() ? missing : extra) += 1;
  }
  expect(missing == 0 && extra == 0, "dense bins: the hits of every segment within margin, in id order",
         missing, extra);
  expect(seen > 500, "dense bins: elements near yarns", seen, 500);
  for (std::size_t k = 0; k < ends.size(); ++k) {
    BodyHit out[StaticBodies::kMaxHits];
    const int n = b.node_hits(ends[k], r, margin, out);
    node_dense[k].assign(out, out + n);
  }
  b.add_segment({1.0, 1.0, 1.0}, {1.0 + 100e-6, 1.0, 1.0}, R, 99);  // 1 m away
  b.build_bins(reach);
  expect(!b.dense_bins(), "bins with a far segment: the hash map");
  int differ = 0;
  auto same = [](const BodyHit &p, const BodyHit &q) {
    return p.seg == q.seg && p.h == q.h && p.s == q.s && p.t == q.t && p.n.x == q.n.x && p.n.y == q.n.y &&
           p.n.z == q.n.z && p.r2 == q.r2;
  };
  for (std::size_t e = 0; e < dense.size(); ++e) {
    std::vector<BodyHit> hits;
    b.element_segment_hits(ends[2 * e], ends[2 * e + 1], r, margin, -1, hits);
    bool eq = hits.size() == dense[e].size();
    for (std::size_t q = 0; eq && q < hits.size(); ++q) eq = same(hits[q], dense[e][q]);
    differ += eq ? 0 : 1;
  }
  for (std::size_t k = 0; k < ends.size(); ++k) {
    BodyHit out[StaticBodies::kMaxHits];
    const int n = b.node_hits(ends[k], r, margin, out);
    bool eq = static_cast<std::size_t>(n) == node_dense[k].size();
    for (int q = 0; eq && q < n; ++q) eq = same(out[q], node_dense[k][static_cast<std::size_t>(q)]);
    differ += eq ? 0 : 1;
  }
  expect(differ == 0, "hash-map bins: the same hits as the dense bins, bit for bit", differ, 0);
}

int main() {
  test_geometry();
  test_bins_dense_and_map();
  test_candidates();
  test_rect_sections();
  test_gap_gradient();
  test_moving_plane_in_sub_steps();
  // lay-down fibers (r 5-12 um) from 1 us to 100 us; a 100 um thick fiber at 1 us
  for (double h : {1e-6, 5e-6, 1e-5, 1e-4})
    for (double r : {5e-6, 12e-6}) test_drop_on_yarns(h, r);
  test_drop_on_yarns(1e-6, 50e-6);
  test_landing_predictor();
  test_friction(0.3);
  test_friction(0.3, 10.0);  // keyword friction_stick: a softer stick creeps faster
  test_friction(0.8);
  test_friction(0.8, 10.0);  // ... and slides alike
  return fiberform::check::finish("test_static_bodies");
}
