/* SPDX-License-Identifier: GPL-3.0-or-later
   The LIGGGHTS-side machinery shared by pair_style fiber/dlvo and fix wall/fiber/dlvo: fibers as
   chains of atoms, contact points on elements, the closest-point selection (thesis 2.4.3-2.4.4),
   the per-pair solve and the transfer of the averaged forces to the element nodes (2.4.2).

   Fiber topology: when a fix fiber/beam exists, its per-node fiber ID, node index and node count
   (accessors of FixFiberBeam) define the chains: the next node of node k < count-1 is atom ID
   tag+1. Atoms that are not fiber/beam nodes (or all atoms, without fix fiber/beam) fall back to
   molecule IDs: the molecule ID is the fiber ID and the atom with ID tag+1 and the same molecule
   ID is the next node. Element = (node, next node),
   owned by the rank that owns its first node. The mass of a node is shared equally by the
   elements it belongs to, so the contact points of a fiber carry exactly the fiber's mass:
   element mass = m_a/deg_a + m_b/deg_b, point mass = element mass / points per element. */
#ifndef FIBERFORM_CONTACT_ENGINE_H
#define FIBERFORM_CONTACT_ENGINE_H

#include <cstdint>
#include <limits>
#include <vector>

#include "contact_integrator.h"
#include "physics/contact_law.h"
#include "pointers.h"

namespace LAMMPS_NS {
class NeighList;
class FixFiberBeam;
}

namespace fiberform {

enum class IntegratorKind { Cvode, Substep, None };
enum class Section { Circle, Rect };

struct EngineConfig {
  physics::ContactLaw law;
  IntegratorKind integrator = IntegratorKind::Cvode;
  int nsub = 100;
  double rtol = 1e-6;
  double atol = 1e-13;  // m, on the contact-induced displacement
  Section section = Section::Circle;
  double width = 0, thickness = 0;  // rect cross-section (m)
  Vec3 up{0, 0, 1};                 // rect: thickness direction reference
  int npoints = 0;                  // points per element; 0 = auto from h_match
  double h_match = 1e-9;            // m, gap at which auto points match parallel cylinders
  bool self_contact = false;        // non-adjacent elements of the same fiber
  int frozen_groupbit = 0;          // atoms of this group have infinite mass
  // implicit fiber/beam only: which averaged force the implicit step receives (fiber_contact_fix.h):
  // position landing with the external loads as a0 (default), or the impulse with every force as a0
  bool implicit_impulse = false;
  bool implicit_newton = false;  // fix wall/fiber/dlvo: the plane inside the fibers' Newton solves
  // Coulomb friction coefficient against static bodies (fix wall/fiber/dlvo, fix wall/fiber/yarns;
  // physics/friction.h averaged, physics/static_bodies.h inside the Newton solve) and, with
  // implicit_force newton, between fibers (pair_style fiber/dlvo; physics/fiber_partners.h); 0: none
  double friction = 0.0;
  // inside the Newton solve only: the stick damping of the regularised friction, c_stick =
  // friction_stick m_eff / dt (physics/static_bodies.h); a stuck point creeps at F_t / c_stick
  double friction_stick = 100.0;
  bool friction_stick_set = false;
};

struct EngineStats {
  long candidates = 0, in_range = 0, solves = 0, cache_hits = 0, rhs_evals = 0, failures = 0, one_sided = 0;
  // smallest surface separation h (m) of the point pairs in range during the last pass (negative:
  // overlap); +infinity when none was in range. Reset by the contact fix before each pass.
  double min_h = std::numeric_limits<double>::infinity();
};

// Per-atom arrays the engine reads (local + ghost, index as atom arrays).
struct NodeData {
  double **v;      // velocity at t0
  double **acc;    // intrinsic (non-contact) acceleration at t0 (may be null: zero)
  double *share;   // node mass share m_i/deg_i (kg)
};
// Per-atom arrays the engine adds to (local + ghost).
struct NodeSinks {
  double **fpre, **fpost;  // forces (fpost null for the instantaneous mode)
  double **tpre, **tpost;  // torques (may be null)
};

struct Plane {
  Vec3 point, normal, velocity;
};

// Parses one keyword (and its values) of the contact law / integrator / geometry starting at
// arg[iarg]; returns the number of words consumed, 0 if the keyword is not one of ours. Errors name
// the keyword. `style` is used in messages.
int parse_contact_keyword(LAMMPS_NS::LAMMPS *lmp, const char *style, EngineConfig &cfg, int iarg, int narg,
                          char **arg);
// Checks the combination of parameters (after all keywords); calls error->all on nonsense.
void validate_contact_config(LAMMPS_NS::LAMMPS *lmp, const char *style, EngineConfig &cfg);

class ContactEngine : protected LAMMPS_NS::Pointers {
 public:
  explicit ContactEngine(LAMMPS_NS::LAMMPS *lmp);
  EngineConfig cfg;
  EngineStats stats;

  void init();  // integrator set-up; checks atom style
  // Next node of atom i (local or ghost; closest image), or -1 at a chain end.
  int next_node(int i) const;
  int prev_node(int i) const;
  // Fiber ID of atom i (fix fiber/beam's, else the molecule ID).
  int fiber_of(int i) const;
  // m_i/deg_i for the local atoms into share[0..nlocal).
  void compute_shares(double *share) const;
  // Largest element length over all ranks (m) and largest atom radius.
  void global_extents(double &max_len, double &max_rad) const;
  // Reach between first nodes of two interacting elements (for cut-offs).
  double reach(double max_len, double max_rad) const;

  // Fiber-fiber: loops over local elements with the full neighbour list. dt: fiber time step;
  // subintegrate false = instantaneous forces into sinks.fpre.
  void pairs(LAMMPS_NS::NeighList *list, double dt, bool subintegrate, const NodeData &nd,
             const NodeSinks &out);
  // Fiber-plane for local elements of atoms in groupbit.
  void wall(const Plane &pl, int groupbit, double dt, bool subintegrate, const NodeData &nd,
            const NodeSinks &out);

 private:
  struct Element {
    int a, b;             // node indices (local/ghost)
    int tag, mol;
    Vec3 xa, xb, axis;    // axis unit vector
    double len, radius, rep_radius;  // rep_radius: law radius (rect: min side / 2)
    double inv_mpt;       // 1 / point mass (0 = frozen)
    int n;                // contact points
    Vec3 e_t;             // rect thickness direction
    double vmax, amax;    // node speed / acceleration bounds (for the range test)
  };
  bool make_element(int i, const NodeData &nd, Element &e) const;
  // Largest node speed, acceleration and radius over local and ghost nodes (pairs()).
  struct RangeBounds {
    double vmax = 0.0, amax = 0.0, rmax = 0.0;
  };
  RangeBounds range_bounds(const NodeData &nd) const;
  // True when no contact point of B can come within h_cut of one of A's over the step, for any
  // element of B's fiber in B's place (see pairs()).
  bool element_out_of_reach(const Element &A, const Element &B, const RangeBounds &rb, double dt) const;
  // Is point k of element A the closest point of A's fiber to point q of element B (order: distance,
  // then point id)? Walks A's chain from A in both directions.
  bool mutual_closest(const Element &A, int k, const Element &B, int q, double dist) const;
  PointState point_state(const Element &e, int k, const NodeData &nd) const;
  void apply(const Element &e, int k, Vec3 r_off, Vec3 fpre, Vec3 fpost, const NodeSinks &out, bool post);
  int npoints_for(double len, double r) const;
  // the representative radius of the element of nodes i, j (m: a circle's mean node radius, a
  // rectangle's half thickness; thesis 2.4.3) and its number of contact points (length len)
  double rep_radius(int i, int j) const;

  ContactIntegrator integrator_;
  LAMMPS_NS::FixFiberBeam *beam_ = nullptr;
  struct Key {
    std::uint64_t a, b;
    bool operator==(const Key &o) const { return a == o.a && b == o.b; }
  };
  struct KeyHash {
    std::size_t operator()(const Key &k) const { return std::hash<std::uint64_t>()(k.a * 1000003u ^ k.b); }
  };
  // Per-step cache of mutual-pair solves: open addressing in a vector that is reused from step to
  // step (entries invalidated by a step stamp), so no allocation happens per contact; it only grows
  // (doubling) when a step has more mutual pairs than any step before.
  struct CacheSlot {
    Key key;
    PairResult r;
    unsigned stamp = 0;
  };
  std::vector<CacheSlot> cache_;
  unsigned cache_stamp_ = 0;
  std::size_t cache_used_ = 0;
  void cache_clear();
  const PairResult *cache_find(const Key &k) const;
  void cache_insert(const Key &k, const PairResult &r);
  struct Candidate {
    int k, mol, elem, q;
    double dist;
  };
  std::vector<Candidate> cand_;
  std::vector<Element> partners_;
};

}  // namespace fiberform

#endif
