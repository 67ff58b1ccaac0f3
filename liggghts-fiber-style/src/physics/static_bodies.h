/* SPDX-License-Identifier: GPL-3.0-or-later
   Static bodies of the lay-down and pressing (thesis sec. 3.1): fabric yarns as chains of cylinders
   (polyline segments with a radius) and planes, all of infinite mass; their contact geometry with
   fiber elements and nodes; and StaticContactModel, the contact of one fiber with these bodies as
   a force model INSIDE the implicit fiber step (physics/implicit_rod.h, NodeForceModel).
   Pure classes, SI units, no LIGGGHTS dependency. Used by fix wall/fiber/yarns (both integrators) and fix wall/fiber/dlvo (implicit_force newton);
   unit-tested in tests/test_static_bodies.cpp; documented in docs/models/contact.md
   ("Static bodies in the implicit step") and docs/styles/fix_wall_fiber_yarns.md.

   Geometry: an element (straight segment xa-xb of fiber radius r) against a yarn acts at the closest
   points of the two centre lines, per yarn the segment with the smallest gap h = |d| - r - R
   (d from the yarn axis to the element point, n = d/|d| the normal towards the fiber); a node
   (single-node fiber) likewise with the closest point of each yarn's centre line; a node against a
   plane (point p, unit normal n towards the fibers) at h = n.(x - p) - r. A collapsed fiber's
   section is the thesis' rectangle (rod::Node::rect): r is then its extent along n (rect_extent,
   the helpers below), found among the hits of its largest extent.

   The implicit model: at the fiber's end-of-step state x_{n+1}, v_{n+1} (every Newton iterate) the
   contact point of parameter s (lever weights w_a = 1 - s, w_b = s) carries the normal force of the
   fiber/dlvo law, F(h, u) n with u = n.v_point (physics/contact_law.h, the same law and parameters as
   pair_style fiber/dlvo; reduced mass = the point's effective mass 1/(w_a^2/m_a + w_b^2/m_b)), and
   optionally Coulomb friction regularised at the velocity scale where it stops the point within a
   step (f_t = -mu F v_t / sqrt(|v_t|^2 + v_eps^2), v_eps = mu F / c_stick, c_stick = k m / h with the
   stick factor k, keyword friction_stick, default kStick = 100).
   Tangent: dF/dh n n^T (position) and dF/du n n^T (velocity), central differences of the scalar law,
   the geometric stiffness of the rotating normal left out (it is F/|d| against dF/dh); friction by its
   secant coefficient. The correction limiter keeps one Newton iteration from moving a contact gap
   from outside to more than the servo's linear range h_cap below contact (h = 0), or from that deep
   to beyond h_R + h_cap (the law saturates there: a full correction would jump between the
   saturated force and no force): the whole correction is scaled so that the gap lands on h = 0. */
#ifndef FIBERFORM_PHYSICS_STATIC_BODIES_H
#define FIBERFORM_PHYSICS_STATIC_BODIES_H

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <vector>

#include "contact_geometry.h"
#include "contact_law.h"
#include "friction.h"
#include "implicit_rod.h"
#include "vec3.h"

namespace fiberform::physics {

// dF/dh and dF/du of a contact's law pl (set up from law) at (h, u) by central differences: the
// iteration matrix's derivatives of the contacts inside the implicit step (bodies here, fiber-fiber
// pairs in fiber_partners.h)
inline double pair_law_dh(const ContactLaw &law, const PairLaw &pl, double h, double u) {
  const double dh = 1e-3 * law.steric.h_R;
  return (pl.force(h + dh, u) - pl.force(h - dh, u)) / (2.0 * dh);
}
inline double pair_law_du(const PairLaw &pl, double h, double u) {
  const double du = 1e-6 + 1e-4 * std::fabs(u);
  return (pl.force(h, u + du) - pl.force(h, u - du)) / (2.0 * du);
}

// One contact candidate: element parameter s (0 for a node), unit normal from the body to the fiber,
// surface gap h (m), radius of the body (inf for a plane).
struct BodyHit {
  double s = 0.0;
  Vec3 n;
  double h = 0.0;
  double r2 = 0.0;
  Vec3 vb;  // velocity of the body (m/s): a moving plate; 0 for yarns
  int seg = -1;     // segment of the body (element_segment_hits)
  double t = 0.0;   // parameter of the contact point on that segment
};

// ---- contact sections of the implicit step's nodes (rod::Node::radius, rod::Node::rect): a circle,
// or a collapsed fiber's rectangle 2 a1 x 2 a2 (thesis sec. 2.4.3: contact points moved along the
// line between the centres to the surface; contact_geometry.h rect_extent). Shared by the body
// contacts here and the fiber-fiber contacts (physics/fiber_partners.h).
inline bool rect_section(const rod::Node &a) { return a.rect[0] > 0.0 && a.rect[1] > 0.0; }
// largest distance of a node's section surface from its centre line (m): the candidate searches'
inline double section_reach(const rod::Node &a) {
  return rect_section(a) ? std::hypot(a.rect[0], a.rect[1]) : a.radius;
}
inline double element_reach(const rod::Node &a, const rod::Node &b) {
  return std::max(section_reach(a), section_reach(b));
}
// the radius of the contact law's terms (m): the circle's, or a rectangle's smaller half-side (as
// pair fiber/dlvo `section rect` outside the Newton solve)
inline double law_radius(const rod::Node &a) { return rect_section(a) ? std::min(a.rect[0], a.rect[1]) : a.radius; }
inline double element_law_radius(const rod::Node &a, const rod::Node &b) {
  return std::max(law_radius(a), law_radius(b));
}
// The section frames t2 = R(q) e2 and t3 = R(q) e3 of nodes: from their rotations, or held by a
// contact model over a step (SectionFrames: the contacts then depend on the positions only, as a
// circle's do: the tangent has no contact-rotation terms. Together with gap_gradient_dir this took
// case A rectangular's piled-up ribbons from 135 to 121 Newton iterations per fiber and step,
// measured; circles need about 20, docs/bench/laydown.md).
inline Vec3 frame_t2(const rod::Node &a) { return beam::qrot(a.q, Vec3{0, 1, 0}); }
inline Vec3 frame_t3(const rod::Node &a) { return beam::qrot(a.q, Vec3{0, 0, 1}); }
struct SectionFrames {
  std::vector<Vec3> t2, t3;
  bool any = false;
  // the held frames for `nodes` (the step's node vector), else (a model evaluated outside a step)
  // the nodes' own
  bool held(const std::vector<rod::Node> &nodes) const { return any && t2.size() == nodes.size(); }
  Vec3 t2_of(const std::vector<rod::Node> &nodes, std::size_t k) const { return held(nodes) ? t2[k] : frame_t2(nodes[k]); }
  Vec3 t3_of(const std::vector<rod::Node> &nodes, std::size_t k) const { return held(nodes) ? t3[k] : frame_t3(nodes[k]); }
  // the frames of the rectangles among `start` (the nodes at the start of a step)
  void take(const std::vector<rod::Node> &start) {
    any = false;
    for (const rod::Node &a : start) any = any || rect_section(a);
    if (!any) return;
    t2.resize(start.size());
    t3.resize(start.size());
    for (std::size_t k = 0; k < start.size(); ++k) {
      t2[k] = frame_t2(start[k]);
      t3[k] = frame_t3(start[k]);
    }
  }
};
// extent of a node's section from its centre along the unit direction n (m), in the node's frame
// (t2, axis t3): single-node fibers and planes
inline double node_extent(const rod::Node &a, Vec3 t2, Vec3 t3, Vec3 n) {
  if (!rect_section(a)) return a.radius;
  return rect_extent(t3, t2, a.rect[0], a.rect[1], n);
}
inline double node_extent(const rod::Node &a, Vec3 n) { return node_extent(a, frame_t2(a), frame_t3(a), n); }
// extent of element a-b's section along n (m): circles the larger radius; a rectangle about the
// chord with the larger half-sides of the two nodes and t2 the sum of theirs (t2a, t2b)
// (de_dn: its gradient with respect to n, rect_extent; 0 for circles)
inline double element_extent(const rod::Node &a, const rod::Node &b, Vec3 t2a, Vec3 t2b, Vec3 n,
                             Vec3 *de_dn = nullptr) {
  if (de_dn) *de_dn = Vec3{0, 0, 0};
  if (!rect_section(a) && !rect_section(b)) return std::max(a.radius, b.radius);
  const Vec3 d = b.x - a.x;
  const double len = norm(d);
  if (!(len > 0.0)) return rect_section(a) ? node_extent(a, t2a, frame_t3(a), n) : node_extent(b, t2b, frame_t3(b), n);
  return rect_extent((1.0 / len) * d, t2a + t2b, std::max(a.rect[0], b.rect[0]), std::max(a.rect[1], b.rect[1]), n,
                     de_dn);
}
inline double element_extent(const rod::Node &a, const rod::Node &b, Vec3 n, Vec3 *de_dn = nullptr) {
  if (!rect_section(a) && !rect_section(b)) {
    if (de_dn) *de_dn = Vec3{0, 0, 0};
    return std::max(a.radius, b.radius);
  }
  return element_extent(a, b, frame_t2(a), frame_t2(b), n, de_dn);
}
// The direction of steepest increase of a gap h = |d| - e(n) (n = d/|d|, e the extents' sum along
// n, de_dn its gradient): grad h = n - (I - n n^T) de_dn / |d|, as a unit vector. A rectangle's
// contact force acts along it (for a circle it is n): so the force is the gradient of the gap's
// potential and the rank-one tangent along it is consistent (see SectionFrames for what both
// choices measured).
// gap_gradient: the gradient itself, dh/dd at fixed contact points (m/m); gap_gradient_dir its direction.
inline Vec3 gap_gradient(Vec3 n, double dist, Vec3 de_dn) { return n - (1.0 / dist) * (de_dn - dot(de_dn, n) * n); }
inline Vec3 gap_gradient_dir(Vec3 n, double dist, Vec3 de_dn) {
  const Vec3 g = gap_gradient(n, dist, de_dn);
  const double lg = norm(g);
  return lg > 0.0 ? (1.0 / lg) * g : n;
}
// The fade of gap_node_gradient in the fiber-yarn contacts of rectangles (StaticContactModel): the
// last 5 % of an element's or a yarn segment's length before an end.
inline constexpr double kSlideFade = 0.05;
// The gradient of a gap h(d) between the centre lines of two elements a0-a1 and b0-b1 with respect
// to the four node positions (grad: a0, a1, b0, b1; m/m), d = a(s) - b(t) between their closest
// points (closest_params_segment_segment) and gd = dh/dd at fixed s and t (gap_gradient). The
// closest points move with the nodes: the conditions d.(a1 - a0) = 0 and d.(b1 - b0) = 0,
// differentiated, give ds and dt for the parameters strictly inside (0, 1) (one at an end, or
// s = 0 of a parallel pair, stays put). For a circle (gd = n, normal to both elements at
// interior points) those terms vanish and grad = the lever weights (1-s, s, -(1-t), -t) times n;
// for a rectangle's gap h = |d| - e(n) they do not: n turns as the contact points slide, and the
// gradient jumps where a point reaches an end and stops sliding. `fade` (a fraction of the
// parameter range) makes it continuous there: a parameter's sliding terms are blended in over its
// last `fade` before an end (the gradient is exact farther inside; fade 0: exact everywhere).
// A static partner (a yarn segment b0-b1): grad[0], grad[1].
inline void gap_node_gradient(Vec3 a0, Vec3 a1, Vec3 b0, Vec3 b1, double s, double t, Vec3 d, Vec3 gd,
                              Vec3 grad[4], double fade = 0.0) {
  const double w[4] = {1.0 - s, s, -(1.0 - t), -t};
  for (int k = 0; k < 4; ++k) grad[k] = w[k] * gd;
  // the weight of each parameter's sliding terms: 0 at an end, 1 from `fade` inside
  auto ramp = [fade](double p) {
    if (!(p > 0.0 && p < 1.0)) return 0.0;
    const double m = std::min(p, 1.0 - p);
    return fade > 0.0 && m < fade ? m / fade : 1.0;
  };
  const double ps = ramp(s), pt = ramp(t);
  if (ps == 0.0 && pt == 0.0) return;
  const Vec3 eA = a1 - a0, eB = b1 - b0;
  const double A = dot(eA, eA), B = dot(eB, eB), C = dot(eA, eB);
  // A ds - C dt = r1, C ds - B dt = r2 with r1 = -(dd_w.eA + d.deA), r2 = -(dd_w.eB + d.deB)
  // (dd_w: d's change at fixed s and t); r1 = sum_k R1[k].dx_k, r2 likewise
  const Vec3 R1[4] = {d - (1.0 - s) * eA, (-s) * eA - d, (1.0 - t) * eA, t * eA};
  const Vec3 R2[4] = {(-(1.0 - s)) * eB, (-s) * eB, (1.0 - t) * eB + d, t * eB - d};
  // dh = gd.dd_w + (gd.eA) ds - (gd.eB) dt, with ds = s1 r1 + s2 r2, dt = t1 r1 + t2 r2 for each
  // set of sliding parameters: both (weight ps pt), s only (ps (1 - pt)), t only ((1 - ps) pt)
  const double cs = dot(gd, eA), ct = -dot(gd, eB);
  double c1 = 0.0, c2 = 0.0;
  const double D = A * B - C * C;
  if (ps * pt > 0.0 && D > 0.0) {
    c1 += ps * pt * (cs * B + ct * C) / D;
    c2 += ps * pt * (-cs * C - ct * A) / D;
  }
  if (ps * (1.0 - pt) > 0.0 && A > 0.0) c1 += ps * (1.0 - pt) * cs / A;
  if ((1.0 - ps) * pt > 0.0 && B > 0.0) c2 += (1.0 - ps) * pt * (-ct / B);
  for (int k = 0; k < 4; ++k) grad[k] = grad[k] + c1 * R1[k] + c2 * R2[k];
}

// A read-only run of segment ids (a bin's list, or a Candidates list).
struct IdSpan {
  const int *p = nullptr;
  std::size_t n = 0;
  const int *begin() const { return p; }
  const int *end() const { return p + n; }
  bool empty() const { return n == 0; }
};

class StaticBodies {
 public:
  static constexpr int kMaxHits = 8;  // yarns acting on one element at once
  static constexpr double kDenseCells = 1 << 22;  // dense bins up to this many cells (or 8 x the entries)
  struct Segment {
    Vec3 a, b, c;  // ends and centre (m)
    double radius = 0, half = 0;
    int yarn = 0;
  };
  struct Plane {
    Vec3 p, n;  // a point and the unit normal towards the fibers
    Vec3 v;     // velocity (m/s): a plate moving as a rigid body; p is its position at the time
                // the fibers are solved for (the end of the step)
  };
  // A reusable short list of element_segment_hits' candidates for one element (StaticContactModel
  // builds one per element at the start of each step attempt, element_candidates): the segments of
  // the bin of the element's midpoint that lie within margin + skin of the element as it was then,
  // in the bin's order. While the midpoint stays in that bin, the bins are not rebuilt, r and margin
  // are the same and neither end has moved by skin or more, every segment within margin of the
  // element is on the list (the distance of two segments changes by at most the largest move of
  // an end), so the hits found over it are those of the full lookup, in the same order.
  struct Candidates {
    bool valid = false;
    long key = 0;           // bin of the midpoint
    bool in_bin = false;    // the bin exists (else: no segment near)
    unsigned long generation = 0;  // of the bins
    Vec3 a0, b0;            // the element's ends when the list was made (m)
    double r = 0.0, margin = 0.0, skin = 0.0;
    std::vector<int> ids;
  };

  void clear_segments() {
    segs_.clear();
    reset_bins();
    bins_valid_ = false;
  }
  void add_segment(Vec3 a, Vec3 b, double radius, int yarn) {
    Segment s;
    s.a = a;
    s.b = b;
    s.c = 0.5 * (a + b);
    s.half = 0.5 * norm(b - a);
    s.radius = radius;
    s.yarn = yarn;
    segs_.push_back(s);
    bins_valid_ = false;
  }
  // false if n is zero
  bool add_plane(Vec3 p, Vec3 n, Vec3 v = Vec3{}) {
    const double nn = norm(n);
    if (!(nn > 0.0)) return false;
    planes_.push_back({p, (1.0 / nn) * n, v});
    return true;
  }
  // moves plane k (a plate) to point p
  void set_plane_point(int k, Vec3 p) { planes_[static_cast<std::size_t>(k)].p = p; }
  void set_plane_velocity(int k, Vec3 v) { planes_[static_cast<std::size_t>(k)].v = v; }
  const std::vector<Segment> &segments() const { return segs_; }
  const std::vector<Plane> &planes() const { return planes_; }

  // Bins of segment capsules reaching `reach` (m) beyond each yarn surface: a point's bin then holds
  // every segment whose surface is within `reach` of it, in the order of the segments' ids.
  // Stored as one array over the bounding box of the bins in use (two counting passes, no
  // allocation once the arrays have grown: fix fiber/dlvo/step rebuilds the fiber bins every step,
  // where the hash map of bins took a fifth of a formed sheet's run time); a box of more cells than
  // kDenseCells or 8 x the entries (a segment far from the others) falls back to a hash map of the
  // bins in use. Both give the same lists.
  void build_bins(double reach) {
    reach_ = std::max(reach, reach_);
    reset_bins();
    bins_valid_ = true;
    ++generation_;
    if (segs_.empty()) return;
    double rmax = 0.0, lmax = 0.0;
    for (int k = 0; k < 3; ++k) lo_[k] = std::numeric_limits<double>::max();
    for (const Segment &s : segs_) {
      rmax = std::max(rmax, s.radius);
      lmax = std::max(lmax, 2.0 * s.half);
      for (int k = 0; k < 3; ++k) lo_[k] = std::min(lo_[k], std::min(s.a[k], s.b[k]));
    }
    size_ = std::max(rmax, lmax);
    const double r = std::max(rmax, reach_);
    for (int k = 0; k < 3; ++k) lo_[k] -= 2.0 * size_;
    // each segment's range of bins, and the box of all of them
    ranges_.resize(segs_.size());
    int glo[3], ghi[3];
    for (int k = 0; k < 3; ++k) {
      glo[k] = std::numeric_limits<int>::max();
      ghi[k] = std::numeric_limits<int>::min();
    }
    double entries = 0.0;
    for (std::size_t id = 0; id < segs_.size(); ++id) {
      const Segment &s = segs_[id];
      BinRange &g = ranges_[id];
      double n = 1.0;
      for (int k = 0; k < 3; ++k) {
        g.lo[k] = static_cast<int>(std::floor((std::min(s.a[k], s.b[k]) - s.radius - r - lo_[k]) / size_));
        g.hi[k] = static_cast<int>(std::floor((std::max(s.a[k], s.b[k]) + s.radius + r - lo_[k]) / size_));
        glo[k] = std::min(glo[k], g.lo[k]);
        ghi[k] = std::max(ghi[k], g.hi[k]);
        n *= g.hi[k] - g.lo[k] + 1;
      }
      entries += n;
    }
    double cells = 1.0;
    for (int k = 0; k < 3; ++k) cells *= static_cast<double>(ghi[k]) - glo[k] + 1.0;
    dense_ = cells <= std::max(kDenseCells, 8.0 * entries);
    if (dense_) {
      for (int k = 0; k < 3; ++k) {
        g0_[k] = glo[k];
        gn_[k] = ghi[k] - glo[k] + 1;
      }
      const std::size_t nc = static_cast<std::size_t>(cells);
      start_.assign(nc + 1, 0);
      for (const BinRange &g : ranges_)
        for (int a = g.lo[0]; a <= g.hi[0]; ++a)
          for (int b = g.lo[1]; b <= g.hi[1]; ++b)
            for (int c = g.lo[2]; c <= g.hi[2]; ++c) ++start_[dense_index(a, b, c) + 1];
      for (std::size_t i = 0; i < nc; ++i) start_[i + 1] += start_[i];
      items_.resize(static_cast<std::size_t>(start_[nc]));
      fill_.assign(start_.begin(), start_.end() - 1);
      for (std::size_t id = 0; id < ranges_.size(); ++id) {
        const BinRange &g = ranges_[id];
        for (int a = g.lo[0]; a <= g.hi[0]; ++a)
          for (int b = g.lo[1]; b <= g.hi[1]; ++b)
            for (int c = g.lo[2]; c <= g.hi[2]; ++c)
              items_[static_cast<std::size_t>(fill_[dense_index(a, b, c)]++)] = static_cast<int>(id);
      }
      return;
    }
    for (std::size_t id = 0; id < ranges_.size(); ++id) {
      const BinRange &g = ranges_[id];
      for (int a = g.lo[0]; a <= g.hi[0]; ++a)
        for (int b = g.lo[1]; b <= g.hi[1]; ++b)
          for (int c = g.lo[2]; c <= g.hi[2]; ++c) {
            std::vector<int> &bin = bins_[key(a, b, c)];
            if (bin.empty()) ++bins_used_;
            bin.push_back(static_cast<int>(id));
          }
    }
  }
  double reach() const { return reach_; }
  // whether the last build_bins stored the bins as one array over their box (else a hash map)
  bool dense_bins() const { return dense_; }

  // Yarns near element xa-xb of radius r: per yarn the closest segment, when h < margin.
  // The element must be shorter than reach() - r - margin for the lookup at its midpoint to be complete.
  // With `cand` (element_candidates of this element, earlier in the step): over its list where it
  // is still complete (Candidates), else the full lookup; the same hits either way.
  int element_hits(Vec3 xa, Vec3 xb, double r, double margin, BodyHit out[kMaxHits],
                   const Candidates *cand = nullptr) const {
    scratch_.clear();
    if (cand && complete(*cand, xa, xb, r, margin)) {
      if (cand->in_bin) hits_among(IdSpan{cand->ids.data(), cand->ids.size()}, xa, xb, r, margin, -1, scratch_);
    } else {
      element_segment_hits(xa, xb, r, margin, -1, scratch_);
    }
    int yarn[kMaxHits];
    int nhit = 0;
    for (const BodyHit &g : scratch_) insert(out, yarn, nhit, segs_[static_cast<std::size_t>(g.seg)].yarn, g);
    return nhit;
  }
  // Every segment near element xa-xb of radius r (h < margin), except those of body `skip`, with the
  // segment id and the parameter t of the contact point on it; appended to out. Same completeness
  // condition as element_hits.
  void element_segment_hits(Vec3 xa, Vec3 xb, double r, double margin, int skip, std::vector<BodyHit> &out) const {
    const IdSpan cand = lookup(0.5 * (xa + xb));
    if (!cand.empty()) hits_among(cand, xa, xb, r, margin, skip, out);
  }
  // The Candidates of element xa-xb for element_hits(..., r, margin, ..., &c) while its ends stay
  // within skin (m) of where they are now.
  void element_candidates(Vec3 xa, Vec3 xb, double r, double margin, double skin, Candidates &c) const {
    c.ids.clear();
    c.valid = bins_valid_ && !segs_.empty() && skin > 0.0;
    if (!c.valid) return;
    c.key = bin_key(0.5 * (xa + xb));
    c.generation = generation_;
    c.a0 = xa;
    c.b0 = xb;
    c.r = r;
    c.margin = margin;
    c.skin = skin;
    const IdSpan bin = lookup(0.5 * (xa + xb));
    c.in_bin = !bin.empty();
    if (!c.in_bin) return;
    // hits_among's tests with margin + skin (also a segment through the element's axis: dist 0)
    const Vec3 mid = 0.5 * (xa + xb);
    const double half_e = 0.5 * norm(xb - xa), wide = margin + skin;
    for (int id : bin) {
      const Segment &sg = segs_[static_cast<std::size_t>(id)];
      double se, ty;
      Vec3 d;
      if (near_pair(sg, xa, xb, mid, half_e, r, wide, se, ty, d) && norm(d) - sg.radius - r < wide)
        c.ids.push_back(id);
    }
  }
  // c still holds every segment within margin of element xa-xb of radius r (see Candidates); the
  // ends' moves are compared with 0.999 skin, a margin far above the rounding of the distances
  bool complete(const Candidates &c, Vec3 xa, Vec3 xb, double r, double margin) const {
    return within(c, xa, xb, r, margin, 0.999);
  }
  // c may serve element xa-xb of radius r with `margin` for another step (StaticContactModel keeps
  // the lists between steps): complete, and neither end has moved by `frac` x skin since it was made
  bool within(const Candidates &c, Vec3 xa, Vec3 xb, double r, double margin, double frac) const {
    if (!c.valid || !bins_valid_ || c.generation != generation_ || c.r != r || c.margin != margin) return false;
    const double lim = frac * c.skin;
    const Vec3 da = xa - c.a0, db = xb - c.b0;
    if (!(dot(da, da) < lim * lim && dot(db, db) < lim * lim)) return false;
    return bin_key(0.5 * (xa + xb)) == c.key;
  }

 private:
  // Element xa-xb (midpoint mid, half length half_e, radius r) and segment sg: false when their
  // bounding spheres stay more than margin apart; else true with the closest points' parameters
  // se (element), ty (segment) and the separation d (element point - segment point).
  static bool near_pair(const Segment &sg, Vec3 xa, Vec3 xb, Vec3 mid, double half_e, double r, double margin,
                        double &se, double &ty, Vec3 &d) {
    const Vec3 dc = mid - sg.c;
    const double reach = half_e + sg.half + sg.radius + r + margin;
    if (dot(dc, dc) > reach * reach) return false;
    closest_params_segment_segment(xa, xb, sg.a, sg.b, se, ty);
    d = lerp(xa, xb, se) - lerp(sg.a, sg.b, ty);
    return true;
  }
  // element_segment_hits over the segments ids (a bin's list, or a Candidates list)
  void hits_among(IdSpan ids, Vec3 xa, Vec3 xb, double r, double margin, int skip, std::vector<BodyHit> &out) const {
    const Vec3 mid = 0.5 * (xa + xb);
    const double half_e = 0.5 * norm(xb - xa);
    for (int id : ids) {
      const Segment &sg = segs_[id];
      if (sg.yarn == skip) continue;
      double se, ty;
      Vec3 d;
      if (!near_pair(sg, xa, xb, mid, half_e, r, margin, se, ty, d)) continue;
      const double dist = norm(d);
      const double h = dist - sg.radius - r;
      if (h >= margin || !(dist > 0.0)) continue;
      BodyHit hit{se, (1.0 / dist) * d, h, sg.radius, Vec3{}};
      hit.seg = id;
      hit.t = ty;
      out.push_back(hit);
    }
  }

 public:
  // Yarns near a node at x of radius r (single-node fibers).
  int node_hits(Vec3 x, double r, double margin, BodyHit out[kMaxHits]) const {
    const IdSpan cand = lookup(x);
    if (cand.empty()) return 0;
    int yarn[kMaxHits];
    int nhit = 0;
    for (int id : cand) {
      const Segment &sg = segs_[id];
      const Vec3 d = x - lerp(sg.a, sg.b, closest_param_point_segment(sg.a, sg.b, x));
      const double dist = norm(d);
      const double h = dist - sg.radius - r;
      if (h >= margin || !(dist > 0.0)) continue;
      insert(out, yarn, nhit, sg.yarn, 0.0, (1.0 / dist) * d, h, sg.radius);
    }
    return nhit;
  }
  // Gap of a node (radius r) to plane k.
  double plane_gap(int k, Vec3 x, double r) const { return dot(x - planes_[k].p, planes_[k].n) - r; }

 private:
  // Empties the bins but keeps their storage (fix fiber/dlvo/step rebuilds the fiber bins every
  // step: no allocation then); bins left empty for long are dropped when they outnumber the used.
  void reset_bins() {
    if (bins_.size() > 2 * bins_used_ + 1024) {
      bins_.clear();
    } else {
      for (auto &kv : bins_) kv.second.clear();
    }
    bins_used_ = 0;
    dense_ = false;
  }
  static long key(int ix, int iy, int iz) { return (static_cast<long>(ix) * 4096 + iy) * 4096 + iz; }
  void bin_of(Vec3 p, int b[3]) const {
    for (int k = 0; k < 3; ++k) b[k] = static_cast<int>(std::floor((p[k] - lo_[k]) / size_));
  }
  long bin_key(Vec3 p) const {
    int b[3];
    bin_of(p, b);
    return key(b[0], b[1], b[2]);
  }
  std::size_t dense_index(int a, int b, int c) const {
    return (static_cast<std::size_t>(a - g0_[0]) * static_cast<std::size_t>(gn_[1]) +
            static_cast<std::size_t>(b - g0_[1])) * static_cast<std::size_t>(gn_[2]) +
           static_cast<std::size_t>(c - g0_[2]);
  }
  // the ids of p's bin (empty: no segment near p)
  IdSpan lookup(Vec3 p) const {
    if (segs_.empty() || !bins_valid_) return {};
    int b[3];
    bin_of(p, b);
    if (dense_) {
      for (int k = 0; k < 3; ++k)
        if (b[k] < g0_[k] || b[k] >= g0_[k] + gn_[k]) return {};
      const std::size_t i = dense_index(b[0], b[1], b[2]);
      const std::size_t first = static_cast<std::size_t>(start_[i]);
      return {items_.data() + first, static_cast<std::size_t>(start_[i + 1]) - first};
    }
    auto it = bins_.find(key(b[0], b[1], b[2]));
    return it == bins_.end() ? IdSpan{} : IdSpan{it->second.data(), it->second.size()};
  }
  // keep the smallest gap per yarn
  static void insert(BodyHit out[kMaxHits], int yarn[kMaxHits], int &nhit, int y, double s, Vec3 n, double h,
                     double r2) {
    insert(out, yarn, nhit, y, BodyHit{s, n, h, r2, Vec3{}, -1, 0.0});
  }
  // the nearest hit of each yarn (with its segment and parameter on it)
  static void insert(BodyHit out[kMaxHits], int yarn[kMaxHits], int &nhit, int y, const BodyHit &hit) {
    int slot = -1;
    for (int b = 0; b < nhit; ++b)
      if (yarn[b] == y) slot = b;
    if (slot < 0) {
      if (nhit == kMaxHits) return;
      slot = nhit++;
      yarn[slot] = y;
      out[slot].h = std::numeric_limits<double>::max();
    }
    if (hit.h < out[slot].h) out[slot] = hit;
  }

  std::vector<Segment> segs_;
  std::vector<Plane> planes_;
  struct BinRange {
    int lo[3], hi[3];
  };
  std::vector<BinRange> ranges_;  // each segment's bins (build_bins)
  // dense bins: the box g0_ .. g0_ + gn_ - 1 (bin indices), bin i holds items_[start_[i] .. start_[i + 1])
  bool dense_ = false;
  int g0_[3] = {0, 0, 0}, gn_[3] = {0, 0, 0};
  std::vector<long> start_, fill_;
  std::vector<int> items_;
  std::unordered_map<long, std::vector<int>> bins_;  // else the bins in use
  mutable std::vector<BodyHit> scratch_;  // element_hits
  bool bins_valid_ = false;
  unsigned long generation_ = 0;  // bins built so far (Candidates made before a rebuild are stale)
  std::size_t bins_used_ = 0;  // non-empty bins of the last build
  double size_ = 1.0, lo_[3] = {0, 0, 0}, reach_ = 0.0;
};

// Contact of one fiber with bodies of known motion inside its implicit step (the part of
// StaticContactModel that a model of other bodies of known motion would share): the fiber/dlvo law
// at each contact point (gap h, unit normal n from the body to the fiber, velocity relative to the
// body's), its tangent, and the correction limiter.
class BodyContactModel : public rod::NodeForceModel {
 public:
  static constexpr double kStick = 100.0;  // default stick damping factor: c_stick = kStick m / h

  // friction: Coulomb coefficient; stick: the stick damping factor (c_stick = stick m / h, > 0)
  BodyContactModel(const ContactLaw &law, double friction, double stick = kStick)
      : law_(law), mu_(friction), stick_(stick) {}

  void begin_whole_step(double H) override { whole_ = H; }
  void begin_step(const std::vector<rod::Node> &start, double t0, double h) override {
    h_ = h;
    // a sub-step ends lag_ before the whole step: a moving plane (its point is where it is at the
    // whole step's end, StaticBodies::Plane) is met where it is at the sub-step's end
    lag_ = whole_ > 0.0 ? std::max(0.0, whole_ - (t0 + h)) : 0.0;
    frames_.take(start);
  }

  double limit(const std::vector<rod::Node> &, const std::vector<Vec3> &dx) const override {
    // landing gap 0: there the servo S1 has its full bell (B1(0) = 1) and stiffness; at h_R both
    // vanish (B1(h_R) = B1'(h_R) = 0) and the next iterate would not see the contact
    double frac = 1.0;
    for (const Near &c : near_) {
      frac = std::min(frac, landing_fraction(law_, c.h, near_dh(c, dx)));
    }
    return frac;
  }
  // the landing predictor's contacts (rod::NodeForceModel::landings; its force along g_i = the
  // lever weights times n, or the rectangle's gap gradient, times 1/|dh/dd| as in act_exact)
  void landings(const std::vector<rod::Node> &, const std::vector<Vec3> &dx,
                std::vector<rod::Landing> &out) const override {
    for (std::size_t i = 0; i < near_.size(); ++i) {
      const Near &c = near_[i];
      if (!lands_deep(law_, c.h, near_dh(c, dx))) continue;
      const PairLaw pl = body_law(c.r1, c.r2, c.inv_m);
      rod::Landing L;
      L.node[0] = c.a;
      L.node[1] = c.b;
      L.g[0] = c.exact ? c.ga : c.wa * c.n;
      L.g[1] = c.exact ? c.gb : c.wb * c.n;
      L.h = c.h;
      L.phi = c.fscale * pl.force(c.h, c.u);
      L.phi0 = c.fscale * pl.force(0.0, c.u);
      L.dphidh0 = c.fscale * law_dh(pl, 0.0, c.u);
      L.dphidu0 = c.fscale * law_du(pl, 0.0, c.u);
      L.owner = this;
      L.index = static_cast<int>(i);
      out.push_back(L);
    }
  }
  // the first case of the limiter (landing_fraction): from outside to deeper than the servo's
  // linear range below the landing gap 0
  static bool lands_deep(const ContactLaw &law, double h, double dh) {
    const double cap = law.steric.cap();
    return h > 1e-3 * cap && h + dh < -cap;
  }
  // The part in (0, 1] of a gap change dh from h that the correction limiter accepts (file comment).
  static double landing_fraction(const ContactLaw &law, double h, double dh) {
    const double hR = law.steric.h_R, cap = law.steric.cap(), land = 0.0;
    const double h1 = h + dh;
    // (a gap already at the landing point is let through: cutting there would stall the iteration)
    if (lands_deep(law, h, dh)) return (h - land) / (h - h1);
    if (h < land - cap && h1 > hR + cap) return (land - h) / (h1 - h);
    // leaving the servo's range from inside it: stop at its edge (else the next iterate sees no
    // force, falls back in, and the iteration cycles between the two)
    const double edge = hR + cap;
    if (h < edge - 0.1 * cap && h1 > edge) return (edge - h) / (h1 - h);
    return 1.0;
  }

  int contacts() const { return contacts_; }    // gaps below h_cut at the last evaluation
  double min_gap() const { return min_gap_; }   // smallest gap at the last evaluation (m)

  // The total contact force on the fibers solved since the last take_total(): the sum over the
  // fibers (or clusters) of the model's forces at each one's LAST evaluation (N), the converged
  // end-of-step state. The smallest gap over them likewise (m; +infinity when none was near).
  void begin_fiber(int) override { commit(); }
  void begin_cluster(const std::vector<int> &, const std::vector<int> &) override { commit(); }
  Vec3 take_total(double &min_gap) {
    double stiffness = 0.0;
    return take_total(min_gap, stiffness);
  }
  // ... and the summed normal contact stiffness -dF/dh of those contacts (N/m; with
  // track_stiffness(true) only, else 0): an upper bound of the stiffness the bodies feel through
  // the fibers (the fibers are in series with it); the press servo limits its gain with it.
  Vec3 take_total(double &min_gap, double &stiffness) {
    commit();
    const Vec3 t = total_;
    min_gap = total_min_gap_;
    stiffness = total_stiff_;
    total_ = {0, 0, 0};
    total_min_gap_ = std::numeric_limits<double>::infinity();
    total_stiff_ = 0.0;
    return t;
  }
  void track_stiffness(bool on) { track_stiff_ = on; }

 protected:
  void reset() {
    near_.clear();
    contacts_ = 0;
    min_gap_ = std::numeric_limits<double>::max();
    eval_sum_ = {0, 0, 0};
    eval_stiff_ = 0.0;
    evaluated_ = true;
  }
  void commit() {
    if (!evaluated_) return;
    total_ = total_ + eval_sum_;
    total_stiff_ += eval_stiff_;
    if (!near_.empty()) total_min_gap_ = std::min(total_min_gap_, min_gap_);
    eval_sum_ = {0, 0, 0};
    eval_stiff_ = 0.0;
    evaluated_ = false;
  }

  // one contact point: element a-b (b < 0: node a) at the hit
  // (grad: the gap's gradient with respect to the positions of nodes a and b, gap_node_gradient,
  // for an element of a rectangle; else the lever weights times hit.n. hit.n is the direction of
  // the friction's normal either way.)
  void act(const std::vector<rod::Node> &nodes, std::vector<Vec3> &F, rod::ForceJacobian *J, int a, int b,
           const BodyHit &hit, const Vec3 *grad = nullptr, double fscale = 1.0) {
    if (grad && b >= 0) {
      act_exact(nodes, F, J, a, b, hit, grad[0], grad[1], fscale);
      return;
    }
    const double wa = b < 0 ? 1.0 : 1.0 - hit.s, wb = b < 0 ? 0.0 : hit.s;
    const rod::Node &A = nodes[static_cast<std::size_t>(a)];
    const rod::Node *B = b < 0 ? nullptr : &nodes[static_cast<std::size_t>(b)];
    const Vec3 v = (B ? wa * A.v + wb * B->v : A.v) - hit.vb;  // relative to the body
    const double inv_m = B ? lever_inverse_mass(wa, rod::contact_mass(A), wb, rod::contact_mass(*B))
                           : lever_inverse_mass(wa, rod::contact_mass(A));
    const double r1 = B ? element_law_radius(A, *B) : law_radius(A);
    const double u = dot(hit.n, v);
    near_.push_back({a, b, wa, wb, hit.n, hit.h, false, Vec3{}, Vec3{}, r1, hit.r2, inv_m, u, 1.0});
    min_gap_ = std::min(min_gap_, hit.h);
    if (hit.h >= law_.h_cut) return;
    ++contacts_;
    const PairLaw pl = body_law(r1, hit.r2, inv_m);
    const double f = pl.force(hit.h, u);
    Vec3 fp = f * hit.n;
    const Vec3 vt = v - u * hit.n;
    const double cf = friction_secant(f, vt, inv_m);  // (N s/m)
    if (cf > 0.0) fp = fp - cf * vt;
    F[static_cast<std::size_t>(a)] = F[static_cast<std::size_t>(a)] + wa * fp;
    if (B) F[static_cast<std::size_t>(b)] = F[static_cast<std::size_t>(b)] + wb * fp;
    eval_sum_ = eval_sum_ + fp;
    if (!J && !track_stiff_) return;
    const double dFdh = law_dh(pl, hit.h, u);
    if (track_stiff_) eval_stiff_ += std::max(0.0, -dFdh);
    if (!J) return;
    const double dFdu = law_du(pl, hit.h, u);
    // friction by its secant coefficient (the consistent derivative, measured: Newton failed in the
    // stick-slip tests of tests/test_static_bodies.cpp)
    double Kx[9], Cv[9];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        const double nn = hit.n[i] * hit.n[j];
        Kx[i * 3 + j] = dFdh * nn;
        Cv[i * 3 + j] = dFdu * nn - cf * ((i == j ? 1.0 : 0.0) - nn);
      }
    J->add(static_cast<std::size_t>(a), static_cast<std::size_t>(a), wa * wa, Kx, Cv);
    if (!B) return;
    J->add(static_cast<std::size_t>(a), static_cast<std::size_t>(b), wa * wb, Kx, Cv);
    J->add(static_cast<std::size_t>(b), static_cast<std::size_t>(a), wa * wb, Kx, Cv);
    J->add(static_cast<std::size_t>(b), static_cast<std::size_t>(b), wb * wb, Kx, Cv);
  }
  // act for an element whose gap has the node gradients ga, gb: the normal force fscale f g_k on
  // node k (fscale = 1 / |dh/dd|, dh/dd the gap's gradient at fixed contact points, >= 1: the
  // law's force per unit of it, so an end contact whose n runs nearly along the element, where
  // the extent is ill-defined and |dh/dd| large, keeps the law's force size), its rate
  // u = ga.v_a + gb.v_b, the tangent fscale dF/dh g g^T; friction as in act, normal to hit.n.
  void act_exact(const std::vector<rod::Node> &nodes, std::vector<Vec3> &F, rod::ForceJacobian *J, int a, int b,
                 const BodyHit &hit, Vec3 ga, Vec3 gb, double fscale) {
    const double wa = 1.0 - hit.s, wb = hit.s;
    const rod::Node &A = nodes[static_cast<std::size_t>(a)], &B = nodes[static_cast<std::size_t>(b)];
    const Vec3 v = wa * A.v + wb * B.v - hit.vb;
    const double inv_m = lever_inverse_mass(wa, rod::contact_mass(A), wb, rod::contact_mass(B));
    const double r1 = element_law_radius(A, B);
    const double u = dot(ga, A.v - hit.vb) + dot(gb, B.v - hit.vb);
    near_.push_back({a, b, wa, wb, hit.n, hit.h, true, ga, gb, r1, hit.r2, inv_m, u, fscale});
    min_gap_ = std::min(min_gap_, hit.h);
    if (hit.h >= law_.h_cut) return;
    ++contacts_;
    const PairLaw pl = body_law(r1, hit.r2, inv_m);
    const double f = fscale * pl.force(hit.h, u);
    Vec3 fa = f * ga, fb = f * gb;
    const Vec3 vt = v - dot(hit.n, v) * hit.n;
    const double cf = friction_secant(f, vt, inv_m);
    if (cf > 0.0) {
      fa = fa - (wa * cf) * vt;
      fb = fb - (wb * cf) * vt;
    }
    F[static_cast<std::size_t>(a)] = F[static_cast<std::size_t>(a)] + fa;
    F[static_cast<std::size_t>(b)] = F[static_cast<std::size_t>(b)] + fb;
    eval_sum_ = eval_sum_ + fa + fb;
    if (!J && !track_stiff_) return;
    const double dFdh = fscale * law_dh(pl, hit.h, u);
    if (track_stiff_) eval_stiff_ += std::max(0.0, -dFdh);
    if (!J) return;
    const double dFdu = fscale * law_du(pl, hit.h, u);
    const Vec3 g[2] = {ga, gb};
    const double w[2] = {wa, wb};
    const int node[2] = {a, b};
    double Kx[9], Cv[9];
    for (int p = 0; p < 2; ++p)
      for (int q = 0; q < 2; ++q) {
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            const double gg = g[p][i] * g[q][j];
            Kx[i * 3 + j] = dFdh * gg;
            Cv[i * 3 + j] = dFdu * gg - w[p] * w[q] * cf * ((i == j ? 1.0 : 0.0) - hit.n[i] * hit.n[j]);
          }
        J->add(static_cast<std::size_t>(node[p]), static_cast<std::size_t>(node[q]), 1.0, Kx, Cv);
      }
  }

  // the law between a fiber's contact point (law radius r1, reduced inverse mass inv_m) and a body
  // (radius r2, at rest in the law's mass sense)
  PairLaw body_law(double r1, double r2, double inv_m) const {
    PairLaw pl;
    pl.setup(law_, r1, r2, inv_m, 0.0, law_.effective_potential(r1), law_.effective_potential(r2));
    return pl;
  }
  double law_dh(const PairLaw &pl, double h, double u) const { return pair_law_dh(law_, pl, h, u); }
  static double law_du(const PairLaw &pl, double h, double u) { return pair_law_du(pl, h, u); }
  // the regularised Coulomb friction's secant coefficient (N s/m) at normal force f, tangential
  // velocity vt, reduced inverse mass inv_m: mu f / sqrt(|vt|^2 + v_eps^2), v_eps = mu f / c_stick,
  // c_stick = stick m / dt (0 without friction or without a compressive force)
  double friction_secant(double f, Vec3 vt, double inv_m) const {
    return regularized_friction_secant(mu_, f, dot(vt, vt), inv_m, stick_, h_);
  }

  const ContactLaw &law_;
  double mu_ = 0.0;
  double stick_ = kStick;
  double h_ = 0.0;
  double whole_ = 0.0;  // the whole step's length (begin_whole_step; 0: not told, no lag)
  double lag_ = 0.0;    // from the (sub-)step's end to the whole step's end (s)
  SectionFrames frames_;  // the rectangles' frames at the start of the step

 private:
  struct Near {
    int a, b;
    double wa, wb;
    Vec3 n;
    double h;
    bool exact;  // the gap's gradient ga, gb (element of a rectangle) instead of the weights times n
    Vec3 ga, gb;
    // the law's setup (body_law) and the rate at the evaluation, the force factor (act_exact)
    double r1, r2, inv_m, u, fscale;
  };
  // the gap change of contact c under the correction dx (linear)
  static double near_dh(const Near &c, const std::vector<Vec3> &dx) {
    if (c.exact) return dot(c.ga, dx[static_cast<std::size_t>(c.a)]) + dot(c.gb, dx[static_cast<std::size_t>(c.b)]);
    Vec3 d = c.wa * dx[static_cast<std::size_t>(c.a)];
    if (c.b >= 0) d = d + c.wb * dx[static_cast<std::size_t>(c.b)];
    return dot(c.n, d);
  }
  std::vector<Near> near_;
  int contacts_ = 0;
  double min_gap_ = 0.0;
  Vec3 eval_sum_{0, 0, 0}, total_{0, 0, 0};
  double eval_stiff_ = 0.0, total_stiff_ = 0.0;
  bool track_stiff_ = false;
  double total_min_gap_ = std::numeric_limits<double>::infinity();
  bool evaluated_ = false;
};

// Contact of one fiber with the static bodies inside its implicit step (see the file comment).
class StaticContactModel : public BodyContactModel {
 public:
  StaticContactModel(const StaticBodies &bodies, const ContactLaw &law, double friction,
                     double stick = kStick)
      : BodyContactModel(law, friction, stick), bodies_(bodies) {}

  // a solve of one fiber without its id: its lists are not kept
  void begin_fiber(int fiber) override {
    BodyContactModel::begin_fiber(fiber);
    fibers_.clear();
    offsets_.clear();
  }
  // the fibers of the next solve (ids, and their first nodes plus the end: FixFiberBeam)
  void begin_cluster(const std::vector<int> &fibers, const std::vector<int> &offsets) override {
    BodyContactModel::begin_cluster(fibers, offsets);
    fibers_ = fibers;
    offsets_ = offsets;
  }
  // per element the yarn segments that can come near it during this attempt (StaticBodies::
  // Candidates, within the element's reach of where the list was made; an element that moves
  // further is looked up in the bins as before): the Newton iterations then test a few segments
  // instead of the bin's list (the lookup was a fifth of a lay-down's time, docs/bench/laydown.md).
  // The lists are kept per fiber between steps and made again only when an end has moved by half
  // the reach since (StaticBodies::within; the hits are the same either way, bit for bit), so a
  // formed sheet does not rebuild them every step.
  void begin_step(const std::vector<rod::Node> &start, double t0, double h) override {
    BodyContactModel::begin_step(start, t0, h);
    const std::size_t n = start.size();
    cand_.assign(n, nullptr);
    if (bodies_.segments().empty()) return;
    const bool by_fiber = offsets_.size() == fibers_.size() + 1 && !fibers_.empty() && offsets_.front() == 0 &&
                          offsets_.back() == static_cast<int>(n);
    if (!by_fiber) {  // a solve without begin_cluster: lists of this attempt only
      own_.resize(n);
      for (std::size_t k = 0; k + 1 < n; ++k)
        if (start[k].next) cand_[k] = &list_for(start, k, own_[k], 0.0);
      return;
    }
    for (std::size_t f = 0; f < fibers_.size(); ++f) {
      const std::size_t o = static_cast<std::size_t>(offsets_[f]), e = static_cast<std::size_t>(offsets_[f + 1]);
      std::vector<StaticBodies::Candidates> &kept = by_fiber_[fibers_[f]];
      kept.resize(e - o);
      for (std::size_t k = o; k + 1 < e; ++k)
        if (start[k].next) cand_[k] = &list_for(start, k, kept[k - o], kKeepFraction);
    }
  }

  void evaluate(const std::vector<rod::Node> &nodes, std::vector<Vec3> &F, rod::ForceJacobian *J) override {
    reset();
    const std::size_t n = nodes.size();
    BodyHit hits[StaticBodies::kMaxHits];
    const double margin = law_.h_cut;
    for (std::size_t k = 0; k < n; ++k) {
      const rod::Node &a = nodes[k];
      const bool rect_a = rect_section(a);
      for (int p = 0; p < static_cast<int>(bodies_.planes().size()); ++p) {
        const Vec3 pn = bodies_.planes()[p].n;
        // the plane lag_ before the whole step's end: v lag back along its motion
        const double h = bodies_.plane_gap(p, a.x, rect_a ? node_extent(a, frames_.t2_of(nodes, k), frames_.t3_of(nodes, k), pn) : a.radius) +
                         lag_ * dot(bodies_.planes()[p].v, pn);
        if (h < a.radius + margin)
          act(nodes, F, J, static_cast<int>(k), -1, BodyHit{0.0, pn, h, INFINITY, bodies_.planes()[p].v, -1, 0.0});
      }
      if (bodies_.segments().empty()) continue;
      // nodes of several fibers may be solved together (a contact cluster): Node::next
      const bool has_next = k + 1 < n && a.next, has_prev = k > 0 && nodes[k - 1].next;
      // rectangles: the hits of the section's reach, the gaps then along each hit's normal
      if (!has_next && !has_prev) {  // a single-node fiber
        const double r = section_reach(a);
        const int nh = bodies_.node_hits(a.x, r, r + margin, hits);
        for (int q = 0; q < nh; ++q) {
          if (rect_a) hits[q].h += r - node_extent(a, frames_.t2_of(nodes, k), frames_.t3_of(nodes, k), hits[q].n);
          act(nodes, F, J, static_cast<int>(k), -1, hits[q]);
        }
      } else if (has_next) {
        const rod::Node &b = nodes[k + 1];
        const bool rect = rect_a || rect_section(b);
        const double r = element_reach(a, b);
        const int nh = bodies_.element_hits(a.x, b.x, r, r + margin, hits, k < cand_.size() ? cand_[k] : nullptr);
        for (int q = 0; q < nh; ++q) {
          if (rect) {
            // the gap from the rectangle's extent; its gradient with the contact points sliding
            // along the element and the yarn (gap_node_gradient: docs/models/contact.md section 9)
            Vec3 de;
            const double dist = hits[q].h + r + hits[q].r2;
            const Vec3 n = hits[q].n;
            hits[q].h += r - element_extent(a, b, frames_.t2_of(nodes, k), frames_.t2_of(nodes, k + 1), n, &de);
            hits[q].n = gap_gradient_dir(n, dist, de);
            const StaticBodies::Segment &sg = bodies_.segments()[static_cast<std::size_t>(hits[q].seg)];
            Vec3 grad[4];
            const Vec3 gd = gap_gradient(n, dist, de);
            gap_node_gradient(a.x, b.x, sg.a, sg.b, hits[q].s, hits[q].t, dist * n, gd, grad, kSlideFade);
            act(nodes, F, J, static_cast<int>(k), static_cast<int>(k + 1), hits[q], grad, 1.0 / norm(gd));
            continue;
          }
          act(nodes, F, J, static_cast<int>(k), static_cast<int>(k + 1), hits[q]);
        }
      }
    }
  }

  // a kept list is used again while both ends stay within this fraction of its skin
  static constexpr double kKeepFraction = 0.5;

 private:
  // list c for element k of start, made again unless it still serves (keep: StaticBodies::within's
  // fraction; 0: always made)
  StaticBodies::Candidates &list_for(const std::vector<rod::Node> &start, std::size_t k, StaticBodies::Candidates &c,
                                     double keep) const {
    const double r = element_reach(start[k], start[k + 1]);
    const double margin = law_.h_cut;
    if (!(keep > 0.0 && bodies_.within(c, start[k].x, start[k + 1].x, r, r + margin, keep)))
      bodies_.element_candidates(start[k].x, start[k + 1].x, r, r + margin, r, c);
    return c;
  }

  const StaticBodies &bodies_;
  std::vector<const StaticBodies::Candidates *> cand_;  // per element of the solve (begin_step)
  std::vector<StaticBodies::Candidates> own_;            // lists of a solve without begin_cluster
  std::unordered_map<int, std::vector<StaticBodies::Candidates>> by_fiber_;  // kept lists per fiber id
  std::vector<int> fibers_, offsets_;                    // of the next solve (begin_cluster)
};

}  // namespace fiberform::physics

#endif
