/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "contact_engine.h"

#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "atom.h"
#include "domain.h"
#include "error.h"
#include "fix_fiber_beam.h"
#include "lammps.h"
#include "neigh_list.h"
#include "physics/contact_geometry.h"
#include "physics/friction.h"

using namespace LAMMPS_NS;

namespace fiberform {

using physics::dot;
using physics::lerp;
using physics::norm;

namespace {
Vec3 vec(const double *p) { return {p[0], p[1], p[2]}; }
double vlen(const double *p) { return std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]); }
}  // namespace

ContactEngine::ContactEngine(LAMMPS *lmp) : Pointers(lmp) {}

void ContactEngine::init() {
  beam_ = FixFiberBeam::find(lmp);
  if (!atom->molecule_flag && !beam_)
    error->all(FLERR, "fiber/dlvo: needs fiber topology: a fix fiber/beam, or molecule IDs as fiber IDs "
                      "(atom_style hybrid sphere molecular)");
  if (!atom->radius_flag || !atom->rmass_flag)
    error->all(FLERR, "fiber/dlvo: needs per-atom radius and mass (atom_style sphere)");
  if (atom->map_style == 0) error->all(FLERR, "fiber/dlvo: needs 'atom_modify map array' (node look-up by ID)");
  integrator_.configure(cfg.integrator == IntegratorKind::Substep ? ContactIntegrator::Method::Substep
                                                                  : ContactIntegrator::Method::Cvode,
                        cfg.nsub, cfg.rtol, cfg.atol);
}

int ContactEngine::fiber_of(int i) const {
  if (beam_ && beam_->is_node(i)) return beam_->fiber_id(i);
  return atom->molecule_flag ? atom->molecule[i] : -1;
}

int ContactEngine::next_node(int i) const {
  if (beam_ && beam_->is_node(i)) {
    if (beam_->node_index(i) >= beam_->node_count(i) - 1) return -1;
    const int j = atom->map(atom->tag[i] + 1);
    if (j < 0 || !beam_->is_node(j) || beam_->fiber_id(j) != beam_->fiber_id(i)) return -1;
    return domain->closest_image(i, j);
  }
  if (!atom->molecule_flag) return -1;
  int j = atom->map(atom->tag[i] + 1);
  if (j < 0 || atom->molecule[j] != atom->molecule[i]) return -1;
  return domain->closest_image(i, j);
}
int ContactEngine::prev_node(int i) const {
  if (beam_ && beam_->is_node(i)) {
    if (beam_->node_index(i) <= 0) return -1;
    const int j = atom->map(atom->tag[i] - 1);
    if (j < 0 || !beam_->is_node(j) || beam_->fiber_id(j) != beam_->fiber_id(i)) return -1;
    return domain->closest_image(i, j);
  }
  if (!atom->molecule_flag || atom->tag[i] <= 1) return -1;
  int j = atom->map(atom->tag[i] - 1);
  if (j < 0 || atom->molecule[j] != atom->molecule[i]) return -1;
  return domain->closest_image(i, j);
}

void ContactEngine::compute_shares(double *share) const {
  for (int i = 0; i < atom->nlocal; ++i) {
    const int deg = (next_node(i) >= 0) + (prev_node(i) >= 0);
    share[i] = atom->rmass[i] / (deg > 0 ? deg : 1);
  }
}

void ContactEngine::global_extents(double &max_len, double &max_rad) const {
  double loc[2] = {0, 0}, glob[2];
  double **x = atom->x;
  for (int i = 0; i < atom->nlocal; ++i) {
    loc[1] = std::max(loc[1], atom->radius[i]);
    const int j = next_node(i);
    if (j < 0) continue;
    double d[3] = {x[j][0] - x[i][0], x[j][1] - x[i][1], x[j][2] - x[i][2]};
    domain->minimum_image(d);  // periodic x/y before the first ghosts exist (init): j may be the far image
    loc[0] = std::max(loc[0], vlen(d));
  }
  MPI_Allreduce(loc, glob, 2, MPI_DOUBLE, MPI_MAX, world);
  max_len = glob[0];
  max_rad = glob[1];
  if (cfg.section == Section::Rect) max_rad = std::max(max_rad, 0.5 * std::hypot(cfg.width, cfg.thickness));
}

double ContactEngine::reach(double max_len, double max_rad) const {
  // two segments of length <= L whose surfaces come within h_cut have first nodes within
  // 2L + 2r + h_cut; 20 % margin for element stretching
  return 1.2 * (2.0 * max_len + 2.0 * max_rad + cfg.law.h_cut);
}

int ContactEngine::npoints_for(double len, double r) const {
  if (cfg.npoints > 0) return cfg.npoints;
  return physics::points_per_element(len, r, r, cfg.h_match);
}

double ContactEngine::rep_radius(int i, int j) const {
  return cfg.section == Section::Circle ? 0.5 * (atom->radius[i] + atom->radius[j])
                                        : 0.5 * std::min(cfg.width, cfg.thickness);
}

bool ContactEngine::make_element(int i, const NodeData &nd, Element &e) const {
  const int j = next_node(i);
  if (j < 0) return false;
  double **x = atom->x;
  e.a = i;
  e.b = j;
  e.tag = atom->tag[i];
  e.mol = fiber_of(i);
  e.xa = vec(x[i]);
  e.xb = vec(x[j]);
  const Vec3 d = e.xb - e.xa;
  e.len = norm(d);
  e.axis = e.len > 0 ? (1.0 / e.len) * d : Vec3{1, 0, 0};
  e.rep_radius = rep_radius(i, j);
  if (cfg.section == Section::Circle) {
    e.radius = e.rep_radius;
  } else {
    e.radius = 0.0;
    e.e_t = physics::rect_thickness_dir(e.axis, cfg.up);
  }
  e.n = npoints_for(e.len, e.rep_radius);
  const bool frozen = cfg.frozen_groupbit && ((atom->mask[i] & cfg.frozen_groupbit) || (atom->mask[j] & cfg.frozen_groupbit));
  const double m = nd.share[i] + nd.share[j];
  e.inv_mpt = (frozen || !(m > 0)) ? 0.0 : e.n / m;
  e.vmax = std::max(vlen(nd.v[i]), vlen(nd.v[j]));
  e.amax = nd.acc ? std::max(vlen(nd.acc[i]), vlen(nd.acc[j])) : 0.0;
  return true;
}

PointState ContactEngine::point_state(const Element &e, int k, const NodeData &nd) const {
  const double s = physics::point_fraction(k, e.n);
  PointState p;
  p.p = lerp(e.xa, e.xb, s);
  p.v = lerp(vec(nd.v[e.a]), vec(nd.v[e.b]), s);
  p.a = nd.acc ? lerp(vec(nd.acc[e.a]), vec(nd.acc[e.b]), s) : Vec3{0, 0, 0};
  p.inv_m = e.inv_mpt;
  return p;
}

void ContactEngine::apply(const Element &e, int k, Vec3 r_off, Vec3 fpre, Vec3 fpost, const NodeSinks &out,
                          bool post) {
  const double s = physics::point_fraction(k, e.n);
  auto add = [&](double **f, double **t, Vec3 F) {
    const physics::NodeLoads L = physics::transfer_to_nodes(s, F, r_off);
    f[e.a][0] += L.fa.x; f[e.a][1] += L.fa.y; f[e.a][2] += L.fa.z;
    f[e.b][0] += L.fb.x; f[e.b][1] += L.fb.y; f[e.b][2] += L.fb.z;
    if (t) {
      t[e.a][0] += L.ta.x; t[e.a][1] += L.ta.y; t[e.a][2] += L.ta.z;
      t[e.b][0] += L.tb.x; t[e.b][1] += L.tb.y; t[e.b][2] += L.tb.z;
    }
  };
  add(out.fpre, out.tpre, fpre);
  if (post) add(out.fpost, out.tpost, fpost);
}

namespace {
inline std::uint64_t point_id(int tag, int k) { return (std::uint64_t(tag) << 20) | std::uint64_t(k); }
// distance from p to the segment a-b
double segment_distance(Vec3 a, Vec3 b, Vec3 p) {
  return norm(lerp(a, b, physics::closest_param_point_segment(a, b, p)) - p);
}
}  // namespace

ContactEngine::RangeBounds ContactEngine::range_bounds(const NodeData &nd) const {
  RangeBounds rb;
  const int nall = atom->nlocal + atom->nghost;
  for (int i = 0; i < nall; ++i) {
    rb.vmax = std::max(rb.vmax, vlen(nd.v[i]));
    if (nd.acc) rb.amax = std::max(rb.amax, vlen(nd.acc[i]));
    rb.rmax = std::max(rb.rmax, atom->radius[i]);
  }
  return rb;
}

bool ContactEngine::element_out_of_reach(const Element &A, const Element &B, const RangeBounds &rb,
                                         double dt) const {
  double s = 0.0, t = 0.0;
  physics::closest_params_segment_segment(A.xa, A.xb, B.xa, B.xb, s, t);
  const double seg = norm(lerp(B.xa, B.xb, t) - lerp(A.xa, A.xb, s));
  // circles: a point pair's surface gap is at least the centre-line distance minus both radii;
  // rectangles: minus the two half-diagonals (rect_surface_distance <= half the diagonal each)
  const double rr = cfg.section == Section::Circle ? A.radius + rb.rmax : std::hypot(cfg.width, cfg.thickness);
  const double allow = (A.vmax + rb.vmax) * dt + 0.5 * (A.amax + rb.amax) * dt * dt;
  const double reach = cfg.law.h_cut + rr + allow;
  return seg > reach * (1.0 + 1e-9) + 1e-15;  // margin: rounding cannot flip the exact argument
}

bool ContactEngine::mutual_closest(const Element &A, int k, const Element &B, int q, double dist) const {
  const Vec3 p = lerp(B.xa, B.xb, physics::point_fraction(q, B.n));
  const std::uint64_t idk = point_id(A.tag, k);
  const bool same_fiber = A.mol == B.mol;
  double **x = atom->x;
  // an element (i -> j) of A's fiber; false if one of its points beats (dist, idk)
  auto beats = [&](int i, int j, bool &further) {
    const Vec3 xa = vec(x[i]), xb = vec(x[j]);
    further = segment_distance(xa, xb, p) <= dist;
    if (!further) return false;
    const int tag = atom->tag[i];
    if (same_fiber && std::abs(tag - B.tag) < 2) return false;  // self contact: not adjacent elements
    const int n = npoints_for(norm(xb - xa), rep_radius(i, j));
    const int kk = physics::closest_point_index(xa, xb, n, p);
    const double d = norm(lerp(xa, xb, physics::point_fraction(kk, n)) - p);
    return d < dist || (d == dist && point_id(tag, kk) < idk);
  };
  bool further = true;
  // A itself: k is the closest point of A to p unless the projection says otherwise
  {
    const int kk = physics::closest_point_index(A.xa, A.xb, A.n, p);
    if (kk != k) {
      const double d = norm(lerp(A.xa, A.xb, physics::point_fraction(kk, A.n)) - p);
      if (d < dist || (d == dist && point_id(A.tag, kk) < idk)) return false;
    }
  }
  // backwards along the chain
  int cur = A.a;
  for (int steps = 0; steps < 100000; ++steps) {
    const int pv = prev_node(cur);
    if (pv < 0) break;
    if (beats(pv, cur, further)) return false;
    if (!further) break;
    cur = pv;
  }
  cur = A.b;
  for (int steps = 0; steps < 100000; ++steps) {
    const int nx = next_node(cur);
    if (nx < 0) break;
    if (beats(cur, nx, further)) return false;
    if (!further) break;
    cur = nx;
  }
  return true;
}

void ContactEngine::cache_clear() {
  cache_used_ = 0;
  if (++cache_stamp_ == 0) {  // stamp wrapped: invalidate explicitly
    for (CacheSlot &c : cache_) c.stamp = 0;
    cache_stamp_ = 1;
  }
}

const PairResult *ContactEngine::cache_find(const Key &k) const {
  if (cache_.empty()) return nullptr;
  const std::size_t mask = cache_.size() - 1;
  for (std::size_t i = KeyHash()(k) & mask;; i = (i + 1) & mask) {
    const CacheSlot &c = cache_[i];
    if (c.stamp != cache_stamp_) return nullptr;
    if (c.key == k) return &c.r;
  }
}

void ContactEngine::cache_insert(const Key &k, const PairResult &r) {
  if (2 * (cache_used_ + 1) > cache_.size()) {  // keep the load <= 1/2; grow (rare) and rehash
    std::vector<CacheSlot> old;
    old.swap(cache_);
    cache_.assign(old.empty() ? 1024 : 2 * old.size(), CacheSlot{});
    const unsigned stamp = cache_stamp_;
    cache_used_ = 0;
    for (const CacheSlot &c : old)
      if (c.stamp == stamp) cache_insert(c.key, c.r);
  }
  const std::size_t mask = cache_.size() - 1;
  std::size_t i = KeyHash()(k) & mask;
  while (cache_[i].stamp == cache_stamp_) i = (i + 1) & mask;
  cache_[i] = CacheSlot{k, r, cache_stamp_};
  ++cache_used_;
}

void ContactEngine::pairs(NeighList *list, double dt, bool subintegrate, const NodeData &nd, const NodeSinks &out) {
  cache_clear();
  const physics::ContactLaw &L = cfg.law;
  // effective potentials depend on the representative radius only: cache the last one
  double y_r = -1.0, y_val = 0.0;
  auto Yof = [&](double r) {
    if (!(L.terms & physics::kEs)) return 0.0;
    if (r != y_r) { y_r = r; y_val = L.effective_potential(r); }
    return y_val;
  };
  physics::PairLaw law;
  Element A, B;
  // Bounds over every node (local and ghost) for the exact element-level filter below.
  const RangeBounds rb = range_bounds(nd);
  for (int ii = 0; ii < list->inum; ++ii) {
    const int i = list->ilist[ii];
    if (!make_element(i, nd, A)) continue;
    cand_.clear();
    partners_.clear();
    const int *jl = list->firstneigh[i];
    for (int jj = 0; jj < list->numneigh[i]; ++jj) {
      const int j = jl[jj] & NEIGHMASK;
      if (!make_element(j, nd, B)) continue;
      if (B.mol == A.mol) {
        if (!cfg.self_contact) continue;
        if (std::abs(B.tag - A.tag) < 2) continue;  // the same or an adjacent element
      }
      // element-level range test: closest approach of the two centre-line segments
      const double allow = (A.vmax + B.vmax) * dt + 0.5 * (A.amax + B.amax) * dt * dt;
      const double rr = (cfg.section == Section::Circle ? A.radius + B.radius
                                                          : std::hypot(cfg.width, cfg.thickness));
      // cheap bound: distance between midpoints minus half lengths
      const Vec3 mA = 0.5 * (A.xa + A.xb), mB = 0.5 * (B.xa + B.xb);
      if (norm(mB - mA) - 0.5 * (A.len + B.len) - rr - allow > L.h_cut) continue;
      // exact segment distance against bounds valid for ANY element of B's fiber (largest radius,
      // speed and acceleration of all nodes): if B's closest point to one of A's points were the
      // selected candidate of that point and fiber, the next one (farther) fails the point-level
      // test below as well, so dropping B changes nothing but the work (about 80 % of the step in
      // a loose suspension before this filter).
      if (element_out_of_reach(A, B, rb, dt)) continue;
      const int eidx = static_cast<int>(partners_.size());
      partners_.push_back(B);
      for (int k = 0; k < A.n; ++k) {
        const Vec3 p = lerp(A.xa, A.xb, physics::point_fraction(k, A.n));
        const int q = physics::closest_point_index(B.xa, B.xb, B.n, p);
        const double d = norm(lerp(B.xa, B.xb, physics::point_fraction(q, B.n)) - p);
        ++stats.candidates;
        cand_.push_back({k, B.mol, eidx, q, d});
      }
    }
    if (cand_.empty()) continue;
    // for each point, only the closest point on each interacting fiber (thesis 2.4.4); ties by
    // point id, the same total order as in mutual_closest
    std::sort(cand_.begin(), cand_.end(), [this](const Candidate &x, const Candidate &y) {
      if (x.k != y.k) return x.k < y.k;
      if (x.mol != y.mol) return x.mol < y.mol;
      if (x.dist != y.dist) return x.dist < y.dist;
      return point_id(partners_[x.elem].tag, x.q) < point_id(partners_[y.elem].tag, y.q);
    });
    for (std::size_t c = 0; c < cand_.size(); ++c) {
      if (c > 0 && cand_[c].k == cand_[c - 1].k && cand_[c].mol == cand_[c - 1].mol) continue;
      const Candidate &cd = cand_[c];
      const Element &Bq = partners_[cd.elem];
      PointState s1 = point_state(A, cd.k, nd), s2 = point_state(Bq, cd.q, nd);
      if (s1.inv_m == 0.0 && s2.inv_m == 0.0) continue;
      PairGeometry g;
      Vec3 r_off{0, 0, 0}, r_offB{0, 0, 0};
      const Vec3 d = s2.p - s1.p;
      const double dist = norm(d);
      if (!(dist > 0)) continue;
      if (cfg.section == Section::Circle) {
        g.offset = A.radius + Bq.radius;
      } else {
        const Vec3 u = (1.0 / dist) * d;
        const double dA = physics::rect_surface_distance(A.axis, A.e_t, cfg.width, cfg.thickness, u);
        const double dB = physics::rect_surface_distance(Bq.axis, Bq.e_t, cfg.width, cfg.thickness, u);
        r_off = dA * u;
        r_offB = -dB * u;
        s1.p = s1.p + r_off;
        s2.p = s2.p + r_offB;
        g.offset = 0.0;
      }
      const double hs = cfg.section == Section::Circle ? dist - g.offset : norm(s2.p - s1.p);
      const double vrel = norm(s2.v - s1.v), arel = norm(s2.a - s1.a);
      if (hs - vrel * dt - 0.5 * arel * dt * dt > L.h_cut) continue;
      ++stats.in_range;
      stats.min_h = std::min(stats.min_h, hs);
      // momentum: a MUTUAL pair (each point the other's closest on the other fiber) is selected by
      // both sides; each side applies its own point's share of the one canonical solve. A
      // ONE-SIDED pair is selected by this side only: it is solved here with half the force (the
      // average of action on this side and no reaction) and applied to BOTH points.
      const bool mutual = mutual_closest(A, cd.k, Bq, cd.q, cd.dist);
      law.setup(L, A.rep_radius, Bq.rep_radius, s1.inv_m, s2.inv_m, Yof(A.rep_radius), Yof(Bq.rep_radius));
      if (!mutual) {
        law.scale = 0.5;
        ++stats.one_sided;
      }
      if (!subintegrate) {
        const Vec3 F = ContactIntegrator::instantaneous_force(law, g, s1, s2);
        apply(A, cd.k, r_off, F, F, out, false);
        if (!mutual) apply(Bq, cd.q, r_offB, -1.0 * F, -1.0 * F, out, false);
        continue;
      }
      if (!mutual) {
        const PairResult r = integrator_.solve(law, g, s1, s2, dt);
        ++stats.solves;
        stats.rhs_evals += r.rhs_evals;
        if (!r.ok) ++stats.failures;
        apply(A, cd.k, r_off, r.fpos1, r.fvel1, out, true);
        apply(Bq, cd.q, r_offB, r.fpos2, r.fvel2, out, true);
        continue;
      }
      // canonical order (lower point id first) makes both sides of a mutual pair run the
      // bit-identical solve; on one rank the second side is served from the cache
      const std::uint64_t idA = point_id(A.tag, cd.k);
      const std::uint64_t idB = point_id(Bq.tag, cd.q);
      const bool swap = idB < idA;
      const Key key{swap ? idB : idA, swap ? idA : idB};
      PairResult r;
      if (const PairResult *hit = cache_find(key)) {
        r = *hit;
        ++stats.cache_hits;
      } else {
        PairGeometry gg = g;
        r = swap ? integrator_.solve(law, gg, s2, s1, dt) : integrator_.solve(law, gg, s1, s2, dt);
        ++stats.solves;
        stats.rhs_evals += r.rhs_evals;
        if (!r.ok) ++stats.failures;
        cache_insert(key, r);
      }
      apply(A, cd.k, r_off, swap ? r.fpos2 : r.fpos1, swap ? r.fvel2 : r.fvel1, out, true);
    }
  }
}

void ContactEngine::wall(const Plane &pl, int groupbit, double dt, bool subintegrate, const NodeData &nd,
                         const NodeSinks &out) {
  const physics::ContactLaw &L = cfg.law;
  physics::PairLaw law;
  Element A;
  double y_r = -1.0, y_val = 0.0;
  const double Ywall = (L.terms & physics::kEs) ? L.effective_potential(std::numeric_limits<double>::infinity()) : 0.0;
  for (int i = 0; i < atom->nlocal; ++i) {
    if (!(atom->mask[i] & groupbit)) continue;
    if (!make_element(i, nd, A)) continue;
    if (A.inv_mpt == 0.0) continue;
    // element-level test: both end points' distance to the plane
    const double da = dot(A.xa - pl.point, pl.normal), db = dot(A.xb - pl.point, pl.normal);
    const double rr = cfg.section == Section::Circle ? A.radius : 0.5 * std::hypot(cfg.width, cfg.thickness);
    const double allow = (A.vmax + norm(pl.velocity)) * dt + 0.5 * A.amax * dt * dt;
    if (std::min(da, db) - rr - allow > L.h_cut) continue;
    if (L.terms & physics::kEs && A.rep_radius != y_r) { y_r = A.rep_radius; y_val = L.effective_potential(y_r); }
    for (int k = 0; k < A.n; ++k) {
      PointState s1 = point_state(A, k, nd);
      PointState s2{pl.point, pl.velocity, {0, 0, 0}, 0.0};
      PairGeometry g;
      g.plane = true;
      g.normal = pl.normal;
      Vec3 r_off{0, 0, 0};
      if (cfg.section == Section::Circle) {
        g.offset = A.radius;
      } else {
        const double dA = physics::rect_surface_distance(A.axis, A.e_t, cfg.width, cfg.thickness, -1.0 * pl.normal);
        r_off = -dA * pl.normal;
        s1.p = s1.p + r_off;
        g.offset = 0.0;
      }
      const double h = dot(s1.p - pl.point, pl.normal) - g.offset;
      const double un = std::fabs(dot(s1.v - pl.velocity, pl.normal));
      if (h - un * dt - 0.5 * norm(s1.a) * dt * dt > L.h_cut) continue;
      ++stats.in_range;
      stats.min_h = std::min(stats.min_h, h);
      law.setup(L, A.rep_radius, std::numeric_limits<double>::infinity(), s1.inv_m, 0.0, y_val, Ywall);
      if (!subintegrate) {
        const Vec3 F = ContactIntegrator::instantaneous_force(law, g, s1, s2);
        apply(A, k, r_off, F, F, out, false);
        continue;
      }
      const PairResult r = integrator_.solve(law, g, s1, s2, dt);
      ++stats.solves;
      stats.rhs_evals += r.rhs_evals;
      if (!r.ok) ++stats.failures;
      const double fn = dot(r.fvel1, pl.normal);
      if (cfg.friction > 0.0 && fn > 0.0) {
        // Coulomb friction of the point on the plane (physics/friction.h): the same tangential
        // force in both averages, an impulse ft dt over the step
        const Vec3 vrel = s1.v - pl.velocity;
        const double v[3] = {vrel.x, vrel.y, vrel.z}, a[3] = {s1.a.x, s1.a.y, s1.a.z};
        const double n[3] = {pl.normal.x, pl.normal.y, pl.normal.z};
        const double gamma = beam_ && beam_->implicit() ? beam_->gamma_eff() : 1.0;
        double ft[3];
        const double c = physics::coulomb_stick_slip(v, a, n, s1.inv_m, gamma * dt, cfg.friction * fn, ft);
        const Vec3 t{c * ft[0], c * ft[1], c * ft[2]};
        apply(A, k, r_off, r.fpos1 + t, r.fvel1 + t, out, true);
        continue;
      }
      apply(A, k, r_off, r.fpos1, r.fvel1, out, true);
    }
  }
}

}  // namespace fiberform
