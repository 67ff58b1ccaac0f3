/* SPDX-License-Identifier: GPL-3.0-or-later
   Fiber-fiber contact INSIDE the implicit step (docs/models/contact.md section 9): contact clusters.

   Fibers whose elements may touch during a step are solved together in one Newton solve (a
   "cluster"; physics/implicit_rod.h solves several fibers at once when Node::next separates them).
   The contact of two elements of different fibers of a cluster is the fiber/dlvo law
   (physics/contact_law.h) at the END-of-step state of both, at the closest points of their centre
   lines (parameters s, t): gap h = |d| - r_A - r_B, d = x_A(s) - x_B(t), n = d / |d| (r: the
   section's extent along n, physics/static_bodies.h element_extent: a circle's radius or a
   collapsed fiber's rectangle, the thesis' rule of moving the points to the surfaces), rate
   u = n . (v_A(s) - v_B(t)), reduced mass of the two contact points (lever rule:
   1/m_point = (1-s)^2/m_a + s^2/m_b). The force f(h, u) n acts on A's nodes with weights (1-s, s) and
   -f n on B's with (1-t, t): action equals reaction exactly, at every Newton iterate. Its tangent is
   the rank-one term of ForceJacobian::Coupling (the rotation of n and the motion of s, t are left
   out, as for the static bodies), which the Stepper solves by the Woodbury identity.

   Friction (optional; the thesis' law has none: coefficient 0, the default). With a coefficient
   mu > 0 a compressive contact (f > 0) also carries the regularised Coulomb friction of the static
   bodies (physics/friction.h regularized_friction_secant, the same law and stick factor):
   -c v_t on A's contact point and +c v_t on B's, v_t the tangential part (normal to n) of their
   relative velocity v_A(s) - v_B(t), c its secant coefficient at the pair's reduced mass
   (1/m = 1/m_A + 1/m_B, each by the lever rule). Action equals reaction; its tangent is two more
   rank-one couplings, along two unit vectors normal to n, with dF/du = -c.

   Why clusters. Solving each fiber alone against its partners' predicted motion (tried first) is a
   Jacobi iteration on a stiff coupling: a fiber resting on another that rests on yarns overshoots
   and the pair was driven through the yarns at steps of 1e-5 s (docs/models/contact.md section 9).

   FiberPartners holds the start-of-step state of every fiber (all ranks hold all of it: fix
   fiber/dlvo/step gathers it), finds the candidate element pairs (surfaces closer than a margin that
   covers the motion over the step), and joins fibers connected by candidate pairs into clusters
   (union-find; a cluster is named by its smallest fiber id). Pairs are detected with periodic
   images: each carries the shift added to B's unwrapped coordinates. Candidates use the nodes'
   `radius` (fix fiber/beam contact_reach: a circle's radius, a rectangle's half-diagonal).
   Self-contact of a fiber and single-node fibers are not modelled here.

   Pure classes, SI units, no LIGGGHTS dependency; tests/test_fiber_partners.cpp. */
#ifndef FIBERFORM_PHYSICS_FIBER_PARTNERS_H
#define FIBERFORM_PHYSICS_FIBER_PARTNERS_H

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <utility>
#include <vector>

#include "static_bodies.h"

namespace fiberform::physics {

// Surface distance (m) below which two elements are candidates of a step of h (s): the law's range
// plus twice the largest motion of two points over the step, from the largest node speed vmax (m/s)
// and acceleration amax (m/s^2) at its start, plus 10 nm.
inline double candidate_margin(const ContactLaw &law, double h, double vmax, double amax) {
  return law.h_cut + 2.0 * (2.0 * h * vmax + h * h * amax) + 10e-9;
}

class FiberPartners {
 public:
  struct Point {
    Vec3 x, v;          // position (m), velocity (m/s) at the start of the step
    double m = 0;       // node mass (kg)
    double radius = 0;  // the section's reach (m): a circle's radius, a rectangle's half-diagonal
  };
  struct Fiber {
    int id;
    std::vector<Point> pts;
  };
  // candidate pair: element k of fiber a (index into fibers) and element j of fiber b, b's
  // coordinates shifted by `shift` (periodic image); fibers[a].id < fibers[b].id
  struct Pair {
    int a, k, b, j;
    Vec3 shift;
  };

  void clear() {
    fibers_.clear();
    pairs_.clear();
    by_cluster_.clear();
    bodies_.clear_segments();
  }
  // periodic box lengths per axis (0: not periodic)
  void set_periods(double lx, double ly, double lz) { period_ = {lx, ly, lz}; }
  // one fiber's nodes in order, positions unwrapped (each node next to the previous one)
  void add_fiber(int id, const std::vector<Point> &pts) { fibers_.push_back({id, pts}); }

  // Candidate pairs and clusters. lo/hi: the box; margin: surface distance below which two
  // elements are candidates (m; the law's range plus the relative motion over the step).
  void build(Vec3 lo, Vec3 hi, double margin) {
    bodies_.clear_segments();
    seg_.clear();
    pairs_.clear();
    by_cluster_.clear();
    double lmax = 0.0, rmax = 0.0;
    for (const Fiber &f : fibers_) {
      for (std::size_t k = 0; k < f.pts.size(); ++k) {
        rmax = std::max(rmax, f.pts[k].radius);
        if (k + 1 < f.pts.size()) lmax = std::max(lmax, norm(f.pts[k + 1].x - f.pts[k].x));
      }
    }
    const double reach = lmax + 2.0 * rmax + margin;
    // Periodic axes: every element is binned at the image whose midpoint lies in the box (shift w),
    // plus the images across a side when that midpoint is within `reach` of it; each element is
    // then queried at its own in-box image. Two elements within the margin have midpoints within
    // `reach` of each other, so the image of the other next to the queried one is binned: the
    // pairs are complete with about (1 + 4 reach / L) copies per element instead of nine.
    const double per[3] = {period_.x, period_.y, period_.z};
    auto in_box_shift = [&](Vec3 m) {
      Vec3 w{};
      for (int c = 0; c < 3; ++c)
        if (per[c] > 0.0) w[c] = -std::floor((m[c] - lo[c]) / per[c]) * per[c];
      return w;
    };
    for (int fi = 0; fi < static_cast<int>(fibers_.size()); ++fi) {
      const Fiber &f = fibers_[static_cast<std::size_t>(fi)];
      for (int k = 0; k + 1 < static_cast<int>(f.pts.size()); ++k) {
        const Vec3 a = f.pts[static_cast<std::size_t>(k)].x, b = f.pts[static_cast<std::size_t>(k + 1)].x;
        const double r = std::max(f.pts[static_cast<std::size_t>(k)].radius, f.pts[static_cast<std::size_t>(k + 1)].radius);
        const Vec3 w = in_box_shift(0.5 * (a + b));
        const Vec3 m = 0.5 * (a + b) + w;
        int lo_im[3], hi_im[3];
        for (int c = 0; c < 3; ++c) {
          lo_im[c] = (per[c] > 0.0 && hi[c] - m[c] < reach) ? -1 : 0;  // its image below the lower side
          hi_im[c] = (per[c] > 0.0 && m[c] - lo[c] < reach) ? 1 : 0;   // its image above the upper side
        }
        for (int ix = lo_im[0]; ix <= hi_im[0]; ++ix)
          for (int iy = lo_im[1]; iy <= hi_im[1]; ++iy)
            for (int iz = lo_im[2]; iz <= hi_im[2]; ++iz) {
              const Vec3 sh = w + Vec3{ix * per[0], iy * per[1], iz * per[2]};
              bodies_.add_segment(a + sh, b + sh, r, fi);
              seg_.push_back({fi, k, sh});
            }
      }
    }
    bodies_.build_bins(reach);
    // pairs, each once (from the fiber of smaller id, unshifted)
    std::vector<BodyHit> hits;
    min_gap_ = std::numeric_limits<double>::infinity();
    parent_.resize(fibers_.size());
    std::iota(parent_.begin(), parent_.end(), 0);
    for (int fa = 0; fa < static_cast<int>(fibers_.size()); ++fa) {
      const Fiber &f = fibers_[static_cast<std::size_t>(fa)];
      for (int k = 0; k + 1 < static_cast<int>(f.pts.size()); ++k) {
        const Point &p = f.pts[static_cast<std::size_t>(k)], &q = f.pts[static_cast<std::size_t>(k + 1)];
        hits.clear();
        const Vec3 w = in_box_shift(0.5 * (p.x + q.x));  // the element at its in-box image
        bodies_.element_segment_hits(p.x + w, q.x + w, std::max(p.radius, q.radius), margin, fa, hits);
        for (const BodyHit &g : hits) {
          const SegRef &sr = seg_[static_cast<std::size_t>(g.seg)];
          if (fibers_[static_cast<std::size_t>(sr.fiber)].id < f.id) continue;
          min_gap_ = std::min(min_gap_, g.h);
          pairs_.push_back({fa, k, sr.fiber, sr.k, sr.shift - w});  // b's shift in a's frame
          unite(fa, sr.fiber);
        }
      }
    }
    for (std::size_t q = 0; q < pairs_.size(); ++q) by_cluster_[cluster(pairs_[q].a)].push_back(static_cast<int>(q));
  }

  int fiber_count() const { return static_cast<int>(fibers_.size()); }
  const Fiber &fiber(int index) const { return fibers_[static_cast<std::size_t>(index)]; }
  // the cluster of fiber `index`: the index of its fiber of smallest id
  int cluster(int index) {
    int r = index;
    while (parent_[static_cast<std::size_t>(r)] != r) r = parent_[static_cast<std::size_t>(r)];
    while (parent_[static_cast<std::size_t>(index)] != r) {
      const int nx = parent_[static_cast<std::size_t>(index)];
      parent_[static_cast<std::size_t>(index)] = r;
      index = nx;
    }
    return r;
  }
  const std::vector<Pair> &pairs() const { return pairs_; }
  // smallest surface gap of the candidate pairs at build time (m; +infinity without pairs)
  double min_gap() const { return min_gap_; }
  // the pairs of the cluster named by fiber index c (empty if none)
  const std::vector<int> &cluster_pairs(int c) const {
    static const std::vector<int> none;
    auto it = by_cluster_.find(c);
    return it == by_cluster_.end() ? none : it->second;
  }

 private:
  struct SegRef {
    int fiber;   // index into fibers_
    int k;       // first node of the element
    Vec3 shift;  // periodic image shift (m)
  };
  // union by smallest fiber id: the root is always the member of smallest id
  void unite(int a, int b) {
    a = cluster(a);
    b = cluster(b);
    if (a == b) return;
    if (fibers_[static_cast<std::size_t>(b)].id < fibers_[static_cast<std::size_t>(a)].id) std::swap(a, b);
    parent_[static_cast<std::size_t>(b)] = a;
  }

  std::vector<Fiber> fibers_;
  std::vector<SegRef> seg_;
  std::vector<Pair> pairs_;
  double min_gap_ = std::numeric_limits<double>::infinity();
  std::vector<int> parent_;
  std::map<int, std::vector<int>> by_cluster_;
  StaticBodies bodies_;
  Vec3 period_;
};

// The fiber-fiber contacts of one cluster inside its implicit step (see the file comment).
class ClusterContactModel : public rod::NodeForceModel {
 public:
  // friction: Coulomb coefficient of fiber-fiber contacts (0: none, the thesis' law); stick: the
  // stick damping factor of its regularisation (c_stick = stick m / h, as BodyContactModel)
  ClusterContactModel(const FiberPartners &partners, const ContactLaw &law, double friction = 0.0,
                      double stick = BodyContactModel::kStick)
      : partners_(partners), law_(law), mu_(friction), stick_(stick) {}

  // fibers: ids of the cluster's fibers in node-vector order, offsets: their first nodes
  void begin_cluster(const std::vector<int> &fibers, const std::vector<int> &offsets) override {
    local_.clear();
    if (fibers.empty()) return;
    std::map<int, int> first;  // fiber id -> first node
    for (std::size_t q = 0; q < fibers.size(); ++q) first[fibers[q]] = offsets[q];
    // the cluster's pairs are filed under its fiber of smallest id
    int c = -1;
    for (int i = 0; i < partners_.fiber_count() && c < 0; ++i)
      if (partners_.fiber(i).id == fibers.front()) c = i;
    if (c < 0) return;
    for (int q : partners_.cluster_pairs(c)) {
      const FiberPartners::Pair &p = partners_.pairs()[static_cast<std::size_t>(q)];
      auto ia = first.find(partners_.fiber(p.a).id), ib = first.find(partners_.fiber(p.b).id);
      if (ia == first.end() || ib == first.end()) continue;
      local_.push_back({ia->second + p.k, ib->second + p.j, p.shift});
    }
  }
  void begin_fiber(int) override { local_.clear(); }
  void begin_step(const std::vector<rod::Node> &start, double, double h) override {
    h_ = h;
    frames_.take(start);
  }

  void evaluate(const std::vector<rod::Node> &nodes, std::vector<Vec3> &F, rod::ForceJacobian *J) override {
    near_.clear();
    slide_.clear();
    contacts_ = 0;
    min_gap_ = std::numeric_limits<double>::max();
    for (const Local &lp : local_) {
      const int idx[4] = {lp.a, lp.a + 1, lp.b, lp.b + 1};
      const rod::Node &A0 = nodes[static_cast<std::size_t>(idx[0])], &A1 = nodes[static_cast<std::size_t>(idx[1])];
      const rod::Node &B0 = nodes[static_cast<std::size_t>(idx[2])], &B1 = nodes[static_cast<std::size_t>(idx[3])];
      double s, t;
      closest_params_segment_segment(A0.x, A1.x, B0.x + lp.shift, B1.x + lp.shift, s, t);
      const Vec3 d = lerp(A0.x, A1.x, s) - (lerp(B0.x, B1.x, t) + lp.shift);
      const double dist = norm(d);
      if (!(dist > 0.0)) continue;
      Vec3 n = (1.0 / dist) * d;
      double h = dist;
      const double w[4] = {1.0 - s, s, -(1.0 - t), -t};
      Near nr{{idx[0], idx[1], idx[2], idx[3]}, {w[0], w[1], w[2], w[3]}, n, h, -1};  // n, h set below
      if (rect_section(A0) || rect_section(A1) || rect_section(B0) || rect_section(B1)) {
        // rectangles (frames held over the step); the force along the gap's gradient
        Vec3 deA, deB;
        auto t2 = [&](int i) { return frames_.t2_of(nodes, static_cast<std::size_t>(idx[i])); };
        h = h - element_extent(A0, A1, t2(0), t2(1), n, &deA) - element_extent(B0, B1, t2(2), t2(3), n, &deB);
        // the limiter predicts the gap's change with the gap's gradient, contact points sliding
        // (docs/models/contact.md section 9, session 27); the force keeps the direction below
        nr.slide = static_cast<int>(slide_.size());
        slide_.emplace_back();
        gap_node_gradient(A0.x, A1.x, B0.x + lp.shift, B1.x + lp.shift, s, t, d,
                          gap_gradient(n, dist, deA + deB), slide_.back().g, kSlideFade);
        n = gap_gradient_dir(n, dist, deA + deB);
      } else {
        h = h - element_extent(A0, A1, n) - element_extent(B0, B1, n);  // circles: (dist - r_A) - r_B
      }
      nr.n = n;
      nr.h = h;
      near_.push_back(nr);
      min_gap_ = std::min(min_gap_, h);
      if (h >= law_.h_cut) continue;
      ++contacts_;
      const Vec3 vrel = lerp(A0.v, A1.v, s) - lerp(B0.v, B1.v, t);
      const double u = dot(n, vrel);
      const PairLaw pl = pair_law(A0, A1, B0, B1, w);
      const double f = pl.force(h, u);
      for (int i = 0; i < 4; ++i) F[static_cast<std::size_t>(idx[i])] = F[static_cast<std::size_t>(idx[i])] + (w[i] * f) * n;
      double cf = 0.0;  // friction's secant coefficient (N s/m)
      if (mu_ > 0.0 && f > 0.0) {
        const Vec3 vt = vrel - u * n;
        const auto [inv_mA, inv_mB] = point_inverse_masses(A0, A1, B0, B1, w);
        cf = regularized_friction_secant(mu_, f, dot(vt, vt), inv_mA + inv_mB, stick_, h_);
        for (int i = 0; i < 4; ++i) F[static_cast<std::size_t>(idx[i])] = F[static_cast<std::size_t>(idx[i])] - (w[i] * cf) * vt;
      }
      if (!J) continue;
      rod::ForceJacobian::Coupling c;
      for (int i = 0; i < 4; ++i) {
        c.node[i] = idx[i];
        c.w[i] = w[i];
      }
      c.n = n;
      c.dFdh = pair_law_dh(law_, pl, h, u);
      c.dFdu = pair_law_du(pl, h, u);
      J->couplings.push_back(c);
      if (cf > 0.0) {  // friction: -cf (I - n n^T) on the relative velocity, two tangential columns
        Vec3 t1, t2;
        tangent_basis(n, t1, t2);
        c.dFdh = 0.0;
        c.dFdu = -cf;
        c.n = t1;
        J->couplings.push_back(c);
        c.n = t2;
        J->couplings.push_back(c);
      }
    }
  }

  double limit(const std::vector<rod::Node> &, const std::vector<Vec3> &dx) const override {
    double frac = 1.0;
    for (const Near &c : near_) {
      double dh = 0.0;
      if (c.slide >= 0) {
        const Vec3 *g = slide_[static_cast<std::size_t>(c.slide)].g;
        for (int i = 0; i < 4; ++i) dh += dot(g[i], dx[static_cast<std::size_t>(c.node[i])]);
      } else {
        Vec3 d;
        for (int i = 0; i < 4; ++i) d = d + c.w[i] * dx[static_cast<std::size_t>(c.node[i])];
        dh = dot(c.n, d);
      }
      frac = std::min(frac, BodyContactModel::landing_fraction(law_, c.h, dh));
    }
    return frac;
  }
  // the landing predictor's contacts (rod::NodeForceModel::landings): the force f n with the
  // signed lever weights, the law and rate as in evaluate
  void landings(const std::vector<rod::Node> &nodes, const std::vector<Vec3> &dx,
                std::vector<rod::Landing> &out) const override {
    for (std::size_t q = 0; q < near_.size(); ++q) {
      const Near &c = near_[q];
      Vec3 d, v;
      for (int i = 0; i < 4; ++i) {
        d = d + c.w[i] * dx[static_cast<std::size_t>(c.node[i])];
        v = v + c.w[i] * nodes[static_cast<std::size_t>(c.node[i])].v;
      }
      if (!BodyContactModel::lands_deep(law_, c.h, dot(c.n, d))) continue;
      const rod::Node *p[4];
      for (int i = 0; i < 4; ++i) p[i] = &nodes[static_cast<std::size_t>(c.node[i])];
      const double u = dot(c.n, v);
      const PairLaw pl = pair_law(*p[0], *p[1], *p[2], *p[3], c.w);
      rod::Landing L;
      for (int i = 0; i < 4; ++i) {
        L.node[i] = c.node[i];
        L.g[i] = c.w[i] * c.n;
      }
      L.h = c.h;
      L.phi = pl.force(c.h, u);
      L.phi0 = pl.force(0.0, u);
      L.dphidh0 = pair_law_dh(law_, pl, 0.0, u);
      L.dphidu0 = pair_law_du(pl, 0.0, u);
      L.owner = this;
      L.index = static_cast<int>(q);
      out.push_back(L);
    }
  }

  // the inverse effective masses (1/kg) of two elements' contact points (signed lever weights w)
  static std::pair<double, double> point_inverse_masses(const rod::Node &A0, const rod::Node &A1, const rod::Node &B0,
                                                        const rod::Node &B1, const double w[4]) {
    return {lever_inverse_mass(w[0], rod::contact_mass(A0), w[1], rod::contact_mass(A1)),
            lever_inverse_mass(w[2], rod::contact_mass(B0), w[3], rod::contact_mass(B1))};
  }
  // the law of two elements' contact points (signed lever weights w: reduced mass of each side)
  PairLaw pair_law(const rod::Node &A0, const rod::Node &A1, const rod::Node &B0, const rod::Node &B1,
                   const double w[4]) const {
    const auto [inv_mA, inv_mB] = point_inverse_masses(A0, A1, B0, B1, w);
    PairLaw pl;
    const double rA = element_law_radius(A0, A1), rB = element_law_radius(B0, B1);
    pl.setup(law_, rA, rB, inv_mA, inv_mB, law_.effective_potential(rA), law_.effective_potential(rB));
    return pl;
  }

  int contacts() const { return contacts_; }   // pairs below h_cut at the last evaluation
  double min_gap() const { return min_gap_; }  // smallest gap of the candidate pairs (m)
  std::size_t candidates() const { return local_.size(); }

 private:
  struct Local {
    int a, b;  // first nodes of the two elements in the node vector
    Vec3 shift;
  };
  struct Near {
    int node[4];
    double w[4];
    Vec3 n;
    double h;
    int slide;  // rectangles: index in slide_ (the limiter predicts dh = sum g[i] . dx[i]); circles -1
  };
  struct Slide {
    Vec3 g[4];  // dh/dx of the four nodes, contact points sliding (gap_node_gradient)
  };
  // two unit vectors that make (t1, t2, n) orthonormal (n: unit)
  static void tangent_basis(Vec3 n, Vec3 &t1, Vec3 &t2) {
    const Vec3 e = std::fabs(n.x) < 0.6 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
    t1 = e - dot(e, n) * n;
    t1 = (1.0 / norm(t1)) * t1;
    t2 = cross(n, t1);
  }

  const FiberPartners &partners_;
  const ContactLaw &law_;
  double mu_ = 0.0, stick_ = BodyContactModel::kStick, h_ = 0.0;
  SectionFrames frames_;  // the rectangles' frames at the start of the step
  std::vector<Local> local_;
  std::vector<Near> near_;
  std::vector<Slide> slide_;
  int contacts_ = 0;
  double min_gap_ = 0.0;
};

}  // namespace fiberform::physics

#endif
