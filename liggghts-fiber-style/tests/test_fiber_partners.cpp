/* SPDX-License-Identifier: GPL-3.0-or-later
   Unit tests of physics/fiber_partners.h: fiber-fiber contact inside the implicit step, by contact
   clusters solved in one Newton solve (physics/implicit_rod.h with Node::next and rank-one
   couplings), with real fibers (E = 10 GPa, 1500 kg/m3, 20 um wide).
   - FiberPartners: candidate pairs against closed-form distances, periodic images, clusters.
   - A fiber laid across two fibers that rest across two yarns (a stack), released at 50 mm/s onto
     them or at rest, load 2000 m/s^2 per mass (the lay-down's drag), background drag time 1 ms, at
     steps 1e-6 and 1e-5 s (and 1e-4 s from rest): it comes to rest, no pass-through (transient
     overlap < 5 % of the radius; at 1e-4 s: the centre lines stay apart), and statics: the contact force on the top fiber equals its load and
     each lower fiber's yarn reactions equal its own load plus its lever-rule share of the top fiber's
     (both to 1e-3:
     action = reaction across the fiber-fiber contacts).
   - Two free fibers crossing at right angles collide head-on at 50 mm/s in empty space (steps 1e-7
     to 1e-5 s): total momentum conserved (relative 1e-9), no pass-through.
   - Two tilted ribbons 50 nm apart: a Newton correction cut by the contact limiter lands them at
     the landing gap to 5 % of the starting gap (the limiter's gap gradient with sliding contact
     points).
   - Fiber-fiber friction (mu 0.5): a fiber resting across two clamped fibers under a lateral load of
     0.5 and 2 times mu times its weight creeps at the regularised law's closed-form speed (stuck)
     or slides as (a_x - mu acc) with the background drag, both to 2 %; action = reaction. */
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <vector>

#include "check.h"
#include "rod_fixtures.h"
#include "physics/fiber_partners.h"

using namespace fiberform::physics;
using beam::Vec3;
using fiberform::check::expect;

namespace {

using fiberform::testing::Fiber;
using fiberform::testing::make_fiber;

// The fibers' nodes one after the other in one node vector, as a cluster's (Node::next false at each
// fiber's last node), and the fibers' first nodes plus the end (off).
void cluster_nodes(const std::vector<Fiber *> &fibers, std::vector<rod::Node> &all, std::vector<int> &off) {
  all.clear();
  off = {0};
  for (const Fiber *f : fibers) {
    all.insert(all.end(), f->nodes.begin(), f->nodes.end());
    all.back().next = false;
    off.push_back(static_cast<int>(all.size()));
  }
}

// All fibers advanced by one step, cluster by cluster (what fix fiber/beam does on one rank).
struct Sim {
  std::vector<Fiber *> fibers;
  FiberPartners partners;
  ContactLaw law;
  std::vector<rod::NodeForceModel *> models;
  rod::Stepper stepper;
  rod::Options opt;
  int max_cluster = 0;
  bool step(double h, const rod::GenAlpha &g) {
    partners.clear();
    double vmax = 0, amax = 0;
    for (int i = 0; i < static_cast<int>(fibers.size()); ++i) {
      std::vector<FiberPartners::Point> pts;
      for (const rod::Node &nd : fibers[i]->nodes) {
        pts.push_back({nd.x, nd.v, nd.m, section_reach(nd)});
        vmax = std::max(vmax, norm(nd.v));
        amax = std::max(amax, norm(nd.F) / nd.m);
      }
      partners.add_fiber(i, pts);
    }
    partners.build({-1e-3, -1e-3, -1e-3}, {1e-3, 1e-3, 1e-3}, candidate_margin(law, h, vmax, amax));
    std::map<int, std::vector<int>> clusters;
    for (int i = 0; i < static_cast<int>(fibers.size()); ++i) clusters[partners.cluster(i)].push_back(i);
    for (const auto &kv : clusters) {
      std::vector<rod::Node> nodes;
      std::vector<rod::Element> els;
      std::vector<int> ids, off;
      for (int i : kv.second) {
        ids.push_back(i);
        off.push_back(static_cast<int>(nodes.size()));
        if (!nodes.empty()) els.emplace_back();
        nodes.insert(nodes.end(), fibers[i]->nodes.begin(), fibers[i]->nodes.end());
        nodes.back().next = false;
        els.insert(els.end(), fibers[i]->els.begin(), fibers[i]->els.end());
      }
      off.push_back(static_cast<int>(nodes.size()));
      max_cluster = std::max(max_cluster, static_cast<int>(ids.size()));
      for (rod::NodeForceModel *m : models) m->begin_cluster(ids, off);
      if (!stepper.step(nodes, els, h, g, opt, &models).ok) return false;
      for (std::size_t q = 0; q < ids.size(); ++q)
        for (int k = off[q]; k < off[q + 1]; ++k) fibers[ids[q]]->nodes[k - off[q]] = nodes[k];
    }
    return true;
  }
};

void test_pairs() {
  FiberPartners p;
  const double r = 10e-6;
  // A along x at z = 0 (nodes at x = -20, 20, 60 um); B along y at x = 20 um (nodes at y = -40, 0, 40 um),
  // z = 2r + 30 nm: they cross at a node of each
  std::vector<FiberPartners::Point> a, b, c;
  for (int k = 0; k < 3; ++k) a.push_back({{-20e-6 + 40e-6 * k, 0, 0}, {}, 1e-11, r});
  for (int k = 0; k < 3; ++k) b.push_back({{20e-6, -40e-6 + 40e-6 * k, 2 * r + 30e-9}, {}, 1e-11, r});
  // C far away, near the periodic boundary x = 1 mm: touches A's image across it
  for (int k = 0; k < 2; ++k) c.push_back({{1e-3 - 20e-6 + 0e-6, -10e-6 + 20e-6 * k, -2 * r - 20e-9}, {}, 1e-11, r});
  p.add_fiber(7, a);
  p.add_fiber(3, b);
  p.add_fiber(9, c);
  p.set_periods(1e-3, 0, 0);
  p.build({0, -1e-3, -1e-3}, {1e-3, 1e-3, 1e-3}, 50e-9);
  // A-B: elements 0 and 1 of A both end at x = 20 um; B's elements 0 and 1 meet at y = 0: the crossing
  // is at a node of each, so four element pairs, all at gap 30 nm; A-C across x = 1 mm: gap 20 nm
  int ab = 0, ac = 0;
  for (const FiberPartners::Pair &q : p.pairs()) {
    const int ia = p.fiber(q.a).id, ib = p.fiber(q.b).id;
    expect(ia < ib, "pair stored from the smaller fiber id", ia, ib);
    if (ia == 3 && ib == 7) ++ab;
    if (ia == 7 && ib == 9) {
      ++ac;
      expect(std::fabs(std::fabs(q.shift.x) - 1e-3) < 1e-12, "periodic shift of the pair", q.shift.x, 1e-3);
    }
  }
  expect(ab == 4, "element pairs at a crossing of two nodes", ab, 4);
  expect(ac >= 1, "pair across the periodic boundary", ac, 1);
  // one cluster named by the smallest id (3)
  for (int i = 0; i < p.fiber_count(); ++i)
    expect(p.fiber(p.cluster(i)).id == 3, "cluster named by its smallest fiber id", p.fiber(p.cluster(i)).id, 3);
  // far apart: no pairs, every fiber its own cluster
  FiberPartners q;
  q.add_fiber(1, a);
  std::vector<FiberPartners::Point> d = b;
  for (auto &pt : d) pt.x.z += 1e-6;  // gap 1.03 um > margin
  q.add_fiber(2, d);
  q.build({-1e-3, -1e-3, -1e-3}, {1e-3, 1e-3, 1e-3}, 50e-9);
  expect(q.pairs().empty(), "no pair beyond the margin", static_cast<double>(q.pairs().size()), 0);
  expect(q.cluster(0) != q.cluster(1), "separate clusters");
}

// ribbons: collapsed fibers (rectangular contact sections 2 r x 2 r/4) lying flat, which stack at
// their thickness 2 r/4, not at the 2 r of a circle
// sparse_from: the Stepper's threshold of the sparse capacitance LU; final: the nodes at the end
// reuse: the Stepper's reuse_analysis; reused: how often it reused an analysis
void test_stack(double h, double v0, double T = 0.02, bool ribbons = false, std::size_t sparse_from = 128,
                std::vector<Vec3> *final = nullptr, bool reuse = true, long *reused = nullptr) {
  const double R = 60e-6, d = 150e-6, L = 0.6e-3, acc = 2000.0, r = 10e-6;
  const double t = ribbons ? 0.25 * r : r;  // half-thickness: the centre line's height on a support
  StaticBodies yarns;
  for (double x : {-d, d}) yarns.add_segment({x, -1e-3, 0}, {x, 1e-3, 0}, R, x < 0 ? 0 : 1);
  yarns.build_bins(std::hypot(r, t) + 50e-9 + 2 * L / 12);
  auto fiber = [&](Vec3 c, bool along_y) {
    return ribbons ? fiberform::testing::make_ribbon(12, L, r, t, c, along_y) : make_fiber(12, L, r, 0.6 * r, c, along_y);
  };
  Fiber B1 = fiber({0, -d, R + t + 1e-9}, false);
  Fiber B2 = fiber({0, d, R + t + 1e-9}, false);
  Fiber A = fiber({5e-6, 0, R + 3 * t + 200e-9}, true);
  Sim sim;
  sim.law.steric.s1_damping = true;  // as the lay-down's newton contacts
  StaticContactModel on_yarns(yarns, sim.law, 0.0);
  ClusterContactModel between(sim.partners, sim.law);
  sim.models = {&on_yarns, &between};
  sim.fibers = {&A, &B1, &B2};
  for (Fiber *f : sim.fibers)
    for (rod::Node &nd : f->nodes) nd.F = {0, 0, -acc * nd.m};
  for (rod::Node &nd : A.nodes) nd.v = {0, 0, -v0};
  sim.opt.tau_drag = 1e-3;
  sim.stepper.sparse_from = sparse_from;
  sim.stepper.reuse_analysis = reuse;
  for (Fiber *f : sim.fibers) sim.stepper.initialise(f->nodes, f->els, sim.opt);
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  const int steps = static_cast<int>(std::lround(T / h));
  double gap_min = 1.0;
  bool ok = true;
  std::vector<rod::Node> all;
  std::vector<int> ids{0, 1, 2}, off;
  auto gather = [&]() { cluster_nodes(sim.fibers, all, off); };
  for (int s = 0; s < steps && ok; ++s) {
    ok = sim.step(h, g);
    gather();
    between.begin_cluster(ids, off);
    std::vector<Vec3> Fc(all.size());
    between.evaluate(all, Fc, nullptr);
    if (between.candidates() > 0) gap_min = std::min(gap_min, between.min_gap());
  }
  char what[200];
  std::snprintf(what, sizeof what, "stack, dt %g s, v0 %g m/s: every step converges", h, v0);
  expect(ok, what);
  if (!ok) return;
  gather();
  if (reused) *reused = sim.stepper.pattern_reused;
  if (final) {
    final->clear();
    for (const rod::Node &nd : all) final->push_back(nd.x);
  }
  between.begin_cluster(ids, off);
  std::vector<Vec3> Fc(all.size());
  between.evaluate(all, Fc, nullptr);
  Vec3 fa{};
  for (int k = off[0]; k < off[1]; ++k) fa = fa + Fc[static_cast<std::size_t>(k)];
  double vmax = 0.0;
  for (const rod::Node &nd : all) vmax = std::max(vmax, norm(nd.v));
  // as for the yarns (test_static_bodies): up to 10 us the transient overlap stays below 5 % of the
  // radius; at 1e-4 s the centre lines stay apart
  const double bound = h <= 1e-5 ? 0.05 * t : t;
  std::snprintf(what, sizeof what, "stack, dt %g s%s: no pass-through (smallest gap > -%g m)", h,
                ribbons ? ", ribbons" : "", bound);
  expect(gap_min > -bound, what, gap_min, -bound);
  std::snprintf(what, sizeof what, "stack, dt %g s: at rest after 20 ms (m/s)", h);
  expect(vmax < 1e-4, what, vmax, 1e-4);
  std::snprintf(what, sizeof what, "stack, dt %g s: contact force on the top fiber = its load", h);
  expect(std::fabs(fa.z / (acc * A.mass) - 1.0) < 1e-3, what, fa.z / (acc * A.mass), 1.0);
  // the top fiber may have slid along its axis (no friction): its load splits by the lever rule
  double yc = 0.0;
  for (const rod::Node &nd : A.nodes) yc += nd.m * nd.x.y / A.mass;
  for (Fiber *B : {&B1, &B2}) {
    std::vector<Vec3> Fy(B->nodes.size());
    on_yarns.evaluate(B->nodes, Fy, nullptr);
    Vec3 fy{};
    for (const Vec3 &q : Fy) fy = fy + q;
    // the supports of the top fiber: the lower fibers' centre lines (they may have moved too)
    const double yb = B->nodes[6].x.y, yo = (B == &B1 ? B2 : B1).nodes[6].x.y;
    const double want = acc * (B->mass + A.mass * std::fabs(yc - yo) / std::fabs(yb - yo));
    std::snprintf(what, sizeof what, "stack, dt %g s: yarn reactions on a lower fiber = its load + its lever-rule share of the top's", h);
    expect(std::fabs(fy.z / want - 1.0) < 1e-3, what, fy.z / want, 1.0);
  }
  // the heights of the centre lines: each fiber rests on its support at its half-thickness t (plus
  // the law's equilibrium gap, nanometres)
  for (Fiber *B : {&B1, &B2}) {
    const double zb = B->nodes[3].x.z - R;  // over the yarn at x = -d
    std::snprintf(what, sizeof what, "stack, dt %g s%s: a lower fiber's centre line at its half-thickness above the yarns", h,
                  ribbons ? ", ribbons" : "");
    expect(std::fabs(zb - t) < 0.05 * t, what, zb, t);
  }
  // A's nodes 3 and 9 lie over the lower fibers (y = -d, d), which A crosses near their node 6
  const double dz = A.nodes[3].x.z - B1.nodes[6].x.z, dz2 = A.nodes[9].x.z - B2.nodes[6].x.z;
  std::snprintf(what, sizeof what, "stack, dt %g s%s: the top fiber's centre line one thickness above the lower ones'", h,
                ribbons ? ", ribbons" : "");
  expect(std::fabs(dz - 2 * t) < 0.1 * t && std::fabs(dz2 - 2 * t) < 0.1 * t, what, dz, 2 * t);
  std::printf("stack dt %g s v0 %g m/s%s: smallest gap %.3g nm, top contact force / load %.6f, largest cluster %d, "
              "lower centre lines %.4g / %.4g um above the yarns, top centre line %.4g / %.4g um above theirs\n", h, v0,
              ribbons ? " ribbons" : "", 1e9 * gap_min, fa.z / (acc * A.mass), sim.max_cluster,
              1e6 * (B1.nodes[3].x.z - R), 1e6 * (B2.nodes[3].x.z - R), 1e6 * dz, 1e6 * dz2);
}

void test_free_collision(double h) {
  const double r = 10e-6, L = 0.4e-3, v = 0.025;
  Fiber A = make_fiber(8, L, r, 0.6 * r, {0, 0, r + 1e-6}, true);
  Fiber B = make_fiber(8, L, r, 0.6 * r, {5e-6, 0, -r - 1e-6}, false);
  for (rod::Node &nd : A.nodes) nd.v = {0, 0, -v};
  for (rod::Node &nd : B.nodes) nd.v = {0, 0, v};
  Sim sim;
  sim.law.steric.s1_damping = true;
  ClusterContactModel between(sim.partners, sim.law);
  sim.models = {&between};
  sim.fibers = {&A, &B};
  for (Fiber *f : sim.fibers) sim.stepper.initialise(f->nodes, f->els, sim.opt);
  auto momentum = [&]() {
    Vec3 p{};
    for (Fiber *f : sim.fibers)
      for (const rod::Node &nd : f->nodes) p = p + nd.m * nd.v;
    return p;
  };
  const Vec3 p0 = momentum();
  const double pscale = v * (A.mass + B.mass);
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  double gap_min = 1.0, dp = 0.0;
  bool ok = true;
  const int steps = static_cast<int>(std::lround(2e-4 / h));
  for (int s = 0; s < steps && ok; ++s) {
    ok = sim.step(h, g);
    dp = std::max(dp, norm(momentum() - p0) / pscale);
    gap_min = std::min(gap_min, A.nodes[4].x.z - B.nodes[4].x.z - 2 * r);  // both centres cross near there
  }
  char what[160];
  std::snprintf(what, sizeof what, "free collision, dt %g s: converges", h);
  expect(ok, what);
  std::snprintf(what, sizeof what, "free collision, dt %g s: momentum conserved (relative)", h);
  expect(dp < 1e-9, what, dp, 1e-9);
  std::snprintf(what, sizeof what, "free collision, dt %g s: no pass-through (m)", h);
  expect(gap_min > -0.05 * r, what, gap_min, -0.05 * r);
  std::printf("free collision dt %g s: momentum error %.2e, smallest centre gap %.3g nm\n", h, dp, 1e9 * gap_min);
}

// Fiber-fiber friction (ClusterContactModel with a Coulomb coefficient): a fiber A (along y) rests
// on two clamped fibers B1, B2 (along x, 0.25 mm apart), crossing each at an element's middle; load
// acc per mass downwards, background drag time tau. After it has come to rest a lateral load a_x per
// mass (along x: tangential at both contacts) is switched on. Closed forms of the regularised law
// (physics/friction.h): each contact carries f = m_A acc / 2 and, stuck, F_t = m_A a_x / 2, so A
// creeps at v = v_eps phi / sqrt(1 - phi^2), phi = a_x / (mu acc), v_eps = mu f / c_stick,
// c_stick = k m_eff / h (m_eff = 2 m_node: A's contact point at an element's middle, B clamped);
// sliding (a_x > mu acc) from rest, A moves x(T) = a' tau (T - tau (1 - exp(-T / tau))),
// a' = a_x - mu acc (the regularisation's share is below 1e-3 here).
void test_friction(double h, double phi) {
  const double r = 10e-6, L = 0.6e-3, d = 125e-6, acc = 2000.0, mu = 0.5, tau = 1e-3, k = 100.0;
  Fiber B1 = make_fiber(12, L, r, 0.6 * r, {0, -d, 0}, false);
  Fiber B2 = make_fiber(12, L, r, 0.6 * r, {0, d, 0}, false);
  for (Fiber *B : {&B1, &B2})
    for (rod::Node &nd : B->nodes) nd.fixed = true;
  // A's nodes at y = -0.3 mm + k 50 um: the supports y = -d, d lie at the middle of its elements 3, 8,
  // symmetric about its centre (equal loads, so both contacts creep alike and A does not turn)
  Fiber A = make_fiber(12, L, r, 0.6 * r, {5e-6, 0, 2 * r + 2e-9}, true);
  Sim sim;
  sim.law.steric.s1_damping = true;
  ClusterContactModel between(sim.partners, sim.law, mu, k);
  sim.models = {&between};
  sim.fibers = {&A, &B1, &B2};
  for (rod::Node &nd : A.nodes) nd.F = {0, 0, -acc * nd.m};
  sim.opt.tau_drag = tau;
  for (Fiber *f : sim.fibers) sim.stepper.initialise(f->nodes, f->els, sim.opt);
  const rod::GenAlpha g = rod::gen_alpha(0.5);
  bool ok = true;
  const int rest = static_cast<int>(std::lround(5e-3 / h));
  for (int s = 0; s < rest && ok; ++s) ok = sim.step(h, g);
  auto xc = [&]() {
    double x = 0.0;
    for (const rod::Node &nd : A.nodes) x += nd.m * nd.x.x / A.mass;
    return x;
  };
  const double ax = phi * mu * acc;
  for (rod::Node &nd : A.nodes) nd.F = {ax * nd.m, 0, -acc * nd.m};
  const double x0 = xc();
  char what[200];
  if (phi < 1.0) {
    // stuck: 1 ms to reach the creep, its speed over the next ms
    const int n1 = static_cast<int>(std::lround(1e-3 / h));
    for (int s = 0; s < n1 && ok; ++s) ok = sim.step(h, g);
    const double x1 = xc();
    for (int s = 0; s < n1 && ok; ++s) ok = sim.step(h, g);
    const double v = (xc() - x1) / 1e-3;
    const double m_node = A.nodes[1].m, f = 0.5 * A.mass * acc;
    const double v_eps = mu * f / (k * 2.0 * m_node / h);
    const double want = v_eps * phi / std::sqrt(1.0 - phi * phi);
    std::snprintf(what, sizeof what, "friction, dt %g s, load %.2f x mu f: converges", h, phi);
    expect(ok, what);
    std::snprintf(what, sizeof what, "friction, dt %g s, load %.2f x mu f: stuck, creeps at the regularised law's speed", h, phi);
    expect(std::fabs(v / want - 1.0) < 0.02, what, v, want);
    std::printf("friction dt %g s, load %.2f x mu f: creep %.4g m/s (closed form %.4g), moved %.3g um in 2 ms\n", h,
                phi, v, want, 1e6 * (xc() - x0));
  } else {
    const double T = 2e-4;
    const int n = static_cast<int>(std::lround(T / h));
    for (int s = 0; s < n && ok; ++s) ok = sim.step(h, g);
    const double a = ax - mu * acc;
    const double want = a * tau * (T - tau * (1.0 - std::exp(-T / tau)));
    const double x = xc() - x0;
    std::snprintf(what, sizeof what, "friction, dt %g s, load %.2f x mu f: converges", h, phi);
    expect(ok, what);
    std::snprintf(what, sizeof what, "friction, dt %g s, load %.2f x mu f: slides as (a_x - mu acc) with the drag", h, phi);
    expect(std::fabs(x / want - 1.0) < 0.02, what, x, want);
    std::printf("friction dt %g s, load %.2f x mu f: slid %.4g um in %.3g ms (closed form %.4g um)\n", h, phi, 1e6 * x,
                1e3 * T, 1e6 * want);
  }
  // action = reaction: the model's forces (normal and friction) sum to zero over the cluster
  std::vector<rod::Node> all;
  std::vector<int> ids{0, 1, 2}, off;
  cluster_nodes(sim.fibers, all, off);
  between.begin_cluster(ids, off);
  between.begin_step(all, 0.0, h);
  std::vector<Vec3> Fc(all.size());
  between.evaluate(all, Fc, nullptr);
  Vec3 sum{}, onA{};
  for (std::size_t q = 0; q < all.size(); ++q) sum = sum + Fc[q];
  for (int q = off[0]; q < off[1]; ++q) onA = onA + Fc[static_cast<std::size_t>(q)];
  expect(std::fabs(onA.z / (acc * A.mass) - 1.0) < 1e-3, "friction: the contacts carry A's weight", onA.z / (acc * A.mass), 1.0);
  std::snprintf(what, sizeof what, "friction, dt %g s: action = reaction (sum of the contact forces / load)", h);
  expect(norm(sum) < 1e-12 * acc * A.mass, what, norm(sum), 1e-12 * acc * A.mass);
}

}  // namespace

// The capacitance matrix of the cluster's couplings factored sparse (Eigen SparseLU, what piles of
// 128 couplings and more use) against the dense LU: the same stack to round-off grown over 2000
// steps (Newton stops at the same iterations unless a correction sits at the tolerance).
void test_sparse_capacitance() {
  std::vector<Vec3> xs, xd;
  test_stack(1e-5, 0.05, 0.02, false, 0, &xs);
  test_stack(1e-5, 0.05, 0.02, false, static_cast<std::size_t>(-1), &xd);
  double d = 0.0;
  for (std::size_t k = 0; k < xs.size(); ++k) d = std::max(d, norm(xs[k] - xd[k]));
  expect(xs.size() == xd.size() && !xs.empty(), "sparse capacitance: both runs give the stack");
  expect(d < 1e-15, "sparse capacitance: the same stack as the dense LU (m)", d, 1e-15);
  std::printf("sparse capacitance: stack after 20 ms, sparse vs dense LU: largest node difference %.3e m\n", d);
  // a repeated pattern factored on the previous analysis: the same factors, so the same stack bit
  // for bit as analysing every matrix afresh
  std::vector<Vec3> xf;
  long reused = 0, reused_off = 0;
  test_stack(1e-5, 0.05, 0.02, false, 0, &xs, true, &reused);
  test_stack(1e-5, 0.05, 0.02, false, 0, &xf, false, &reused_off);
  bool same = xs.size() == xf.size() && !xs.empty();
  for (std::size_t k = 0; same && k < xs.size(); ++k) same = xs[k].x == xf[k].x && xs[k].y == xf[k].y && xs[k].z == xf[k].z;
  expect(reused > 0 && reused_off == 0, "sparse capacitance: patterns repeat and their analysis is reused", static_cast<double>(reused), 0);
  expect(same, "sparse capacitance: reusing the analysis gives the stack bit for bit");
  std::printf("sparse capacitance: %ld of the factorisations reused the previous analysis\n", reused);
}

// The correction limiter of rectangles' fiber-fiber contacts (ClusterContactModel::limit) predicts a
// gap's change with the gap's gradient with the contact points sliding (gap_node_gradient): a
// correction that would carry two ribbons from 50 nm apart to deep inside each other, cut by the
// limiter's fraction, ends them at the landing gap 0 up to second order in the correction. Two
// ribbons (2 a1 x 2 a2 = 20 x 5 um) crossing at 60 degrees, the upper one rolled 30 degrees about its
// axis; 20 random corrections of the nodes of the crossing elements (each component up to 3 x 50 nm,
// so that the contact points slide and the normal turns, plus 50 nm towards each other on each
// side). The
// prediction at fixed contact points along the force's unit direction (before session 27) missed
// the landing by up to 37 % of the starting gap in this test, the sliding gradient by 0.64 %
// (measured); bound: 5 %.
void test_rect_limiter_prediction() {
  using fiberform::testing::make_ribbon;
  const double r = 10e-6, t = 0.25 * r, L = 0.6e-3, h0 = 50e-9;
  Fiber A = make_ribbon(12, L, r, t, {0, 0, 0}, false);  // along x, flat
  Fiber B = make_ribbon(12, L, r, t, {0, 0, 0}, true);   // along y, turned and lifted below
  // B: turned 30 degrees about z (crossing at 60 degrees) and rolled 30 degrees about its own axis t3,
  // its centre line crossing A's element 6 at x = 16 um (not at a node), then set 50 nm above A
  const beam::Quat turn = beam::qexp({0, 0, beam::kPi / 6});
  for (rod::Node &nd : B.nodes) {
    nd.x = beam::qrot(turn, nd.x) + Vec3{12e-6, 7e-6, 0};
    nd.q = beam::qmul(beam::qmul(turn, nd.q), beam::qexp({0, 0, beam::kPi / 6}));
  }
  FiberPartners partners;
  ContactLaw law;
  auto points = [](const Fiber &f) {
    std::vector<FiberPartners::Point> pts;
    for (const rod::Node &nd : f.nodes) pts.push_back({nd.x, nd.v, nd.m, section_reach(nd)});
    return pts;
  };
  std::vector<rod::Node> all;
  const std::vector<int> ids{0, 1};
  std::vector<int> off;
  ClusterContactModel between(partners, law);
  auto setup = [&]() {
    partners.clear();
    partners.add_fiber(0, points(A));
    partners.add_fiber(1, points(B));
    partners.build({-1e-3, -1e-3, -1e-3}, {1e-3, 1e-3, 1e-3}, 30e-6);
    cluster_nodes({&A, &B}, all, off);
    between.begin_cluster(ids, off);
    between.begin_step(all, 0.0, 1e-6);
  };
  auto gap = [&](const std::vector<rod::Node> &nodes) {
    std::vector<Vec3> F(nodes.size());
    between.evaluate(nodes, F, nullptr);
    return between.min_gap();
  };
  for (rod::Node &nd : B.nodes) nd.x.z += 10e-6;
  for (int it = 0; it < 5; ++it) {  // lowered onto A (the gap is linear in the height: n stays put)
    setup();
    const double lift = h0 - gap(all);
    for (rod::Node &nd : B.nodes) nd.x.z += lift;
  }
  setup();
  const double g0 = gap(all);
  expect(std::fabs(g0 - h0) < 1e-12, "ribbons set 50 nm apart", g0, h0);
  // the elements at the crossing: A's element 6 (x in 0..50 um), B's nearest to it
  std::uint64_t state = 12345;
  auto uniform = [&state]() {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    return static_cast<double>(state >> 11) / 9007199254740992.0 * 2.0 - 1.0;
  };
  double worst = 0.0;
  for (int draw = 0; draw < 20; ++draw) {
    std::vector<Vec3> dx(all.size());
    for (int k : {6, 7, off[1] + 5, off[1] + 6, off[1] + 7})
      dx[static_cast<std::size_t>(k)] = (3 * h0) * Vec3{uniform(), uniform(), uniform()};
    // push the pair together: A's nodes up, B's down by h0 each, on top of the random parts
    for (int k : {6, 7}) dx[static_cast<std::size_t>(k)].z += h0;
    for (int k : {off[1] + 5, off[1] + 6, off[1] + 7}) dx[static_cast<std::size_t>(k)].z -= h0;
    gap(all);
    const double frac = between.limit(all, dx);
    std::vector<rod::Node> moved = all;
    for (std::size_t k = 0; k < moved.size(); ++k) moved[k].x = moved[k].x + frac * dx[k];
    const double g1 = gap(moved);
    // a correction the limiter let through whole (frac 1) must not land deep; a cut one lands at 0
    if (frac < 1.0) worst = std::max(worst, std::fabs(g1) / h0);
    else worst = std::max(worst, std::max(0.0, -g1 - law.steric.cap()) / h0);
  }
  std::printf("rectangles' limiter: largest landing error %.3g of the starting gap (20 corrections)\n", worst);
  expect(worst < 0.05, "ribbons' limiter lands the correction at the landing gap (sliding gradient)", worst, 0.05);
}

int main() {
  test_pairs();
  for (double h : {1e-7, 1e-6, 1e-5}) test_free_collision(h);
  for (double h : {1e-6, 1e-5}) test_stack(h, 0.05);
  test_stack(1e-4, 0.0);
  for (double h : {1e-6, 1e-5}) test_stack(h, 0.05, 0.02, true);
  test_sparse_capacitance();
  test_rect_limiter_prediction();
  for (double h : {1e-6, 1e-5}) {
    test_friction(h, 0.5);
    test_friction(h, 2.0);
  }
  return fiberform::check::finish("test_fiber_partners");
}
