/* SPDX-License-Identifier: GPL-3.0-or-later
   Implicit time step of one fiber (a chain of nodes joined by the Simo-Reissner elements of
   physics/beam.h): the generalized-alpha scheme on the rotation group, solved by Newton's method
   with a block-tridiagonal tangent. Pure functions/classes, SI units, no LIGGGHTS dependency.
   Used by fix fiber/beam (`integrator implicit`); unit-tested in tests/test_implicit_rod.cpp;
   documented in docs/models/beam.md ("Implicit time integration").

   Scheme (M. Arnold, O. Bruels, Multibody Syst. Dyn. 18 (2007) 185-202; O. Bruels, A. Cardona,
   M. Arnold, Mech. Mach. Theory 48 (2012) 121-137, "Lie group generalized-alpha"; the parameters
   of J. Chung, G.M. Hulbert, J. Appl. Mech. 60 (1993) 371-375). Per node the configuration is
   (x, R) in R^3 x SO(3), the velocities (v, W) with v spatial and W the BODY angular velocity,
   R' = R W^. The equations of motion hold exactly at t_{n+1}:
       m dv/dt            = F_int(x, R) + F_ext - D (v - v_n) - m v / tau
       J dW/dt + W x J W  = R^T (T_int(x, R) + T_ext) - J W / tau
   (F_ext, T_ext constant over the step: drag at t_n, gravity, contact averaged forces; D the
   velocity Jacobian of the drag: linearly implicit drag; tau the optional background drag.)
   Discretisation with pseudo-accelerations a (one per velocity component):
       q_{n+1} = q_n o exp(h dQ),  dQ = v_n + h (1/2 - beta) a_n + h beta a_{n+1}
       v_{n+1} = v_n + h (1 - gamma) a_n + h gamma a_{n+1}
       (1 - am) a_{n+1} + am a_n = (1 - af) vdot_{n+1} + af vdot_n
   with am = (2 rho - 1)/(rho + 1), af = rho/(rho + 1), gamma = 1/2 + af - am,
   beta = (gamma + 1/2)^2 / 4: second order, unconditionally stable for linear problems, high
   frequencies damped to the spectral radius rho_inf (1: no numerical dissipation, trapezoidal).
   Forces of the NodeForceModels (contact, evaluated at the end-of-step state) are NOT averaged with
   their value at t_n: they enter (1 - am) a_{n+1} + am a_n = ... + Fc_{n+1}/m directly
   (contact_force_weight; docs/models/contact.md section 10).
   Newton corrections d (6 per node: dx spatial, dtheta body) update
       dQ += d / h,  v += gamma' d,  vdot += beta' d,  gamma' = gamma/(h beta),
       beta' = (1 - am)/(h^2 beta (1 - af)).
   Iteration matrix S = beta' M + gamma' C_t + K_t (modified Newton: formed and factored at the
   first iteration of a step unless the caller's held one from earlier steps still serves (struct
   Tangent), again after every kRefresh iterations without convergence, and as soon as a
   correction is not below kContraction times the previous one, or, when that is larger, below
   kFreshSlack times the contraction the newest freshly formed tangent achieved, at most kSlowCap:
   with secant terms (friction in slip) a new tangent contracts no better than a held one, and
   forming one every iteration doubled the cost of a settled sheet). K_t: the tangent of the
   internal forces of the exact discrete elements: analytic (beam::ElementChordGradient; with
   Kelvin-Voigt damping the rotation columns are forward differences, 6 evaluations per element),
   multiplied by the right Jacobian of SO(3) at the current rotation increment (the
   tangent operator T(h dQ)); C_t: the gyroscopic, drag and damping tangents. S is block
   tridiagonal in the nodes (6 x 6 blocks); it is solved after a
   symmetric diagonal scaling by physics/block_tridiag.h.
   Anderson mixing (Options::anderson = m > 0; D.G. Anderson, J. ACM 12 (1965) 547; H.F. Walker,
   P. Ni, SIAM J. Numer. Anal. 49 (2011) 1715): with a held iteration matrix the corrections
   f_k = -S^-1 r(y_k) are a fixed-point iteration y_{k+1} = y_k + f_k that converges linearly
   (about 0.8 per iteration in a piled-up sheet with yarn friction). The step taken is
   f_k - (dY + dF) gamma, gamma = argmin |f_k - dF gamma| (2-norm of the weighted corrections:
   translations relative to the section radius), dY, dF the last m differences of iterates and of
   corrections. The history is dropped whenever a new iteration matrix is formed, after a
   backtracking and at the start of every attempt; the rotation and contact limiters act on the
   mixed step; convergence is still |f_k| (the unmixed correction) below the tolerance.
   A step whose iteration does not converge (tolerance on the corrections: translations relative
   to the section radius, rotations in radians) or produces non-finite numbers is restarted from
   the saved state as two half steps, recursively up to max_split levels; if that fails the step
   reports failure (the caller stops the run: never silently accepted).
   Split memory (Stepper::step's first_depth, SplitMemory): a step may start already divided into
   2^d equal sub-steps, each then split further as above. A step that fails whole and converges as
   two halves gives to the bit what a step started at d = 1 gives, without the failed attempt; the
   caller remembers that none of a step's sub-steps converged whole (remember_split: one level
   deeper) and starts the next ones there, trying one level coarser after a number of steps none
   of whose sub-steps failed. */
#ifndef FIBERFORM_PHYSICS_IMPLICIT_ROD_H
#define FIBERFORM_PHYSICS_IMPLICIT_ROD_H

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/SparseCore>
#include <Eigen/SparseLU>

#include "beam.h"
#include "block_tridiag.h"

namespace fiberform::physics::rod {

using beam::Quat;
using beam::Vec3;

// Generalized-alpha parameters from the spectral radius at infinite frequency.
struct GenAlpha {
  double rho_inf = 0.5, am = 0, af = 0, gamma = 0.5, beta = 0.25;
  // Effective Newmark coefficients of a force that is constant over one step and absent before:
  // x_{n+1} changes by beta_eff h^2 F/m, v_{n+1} by gamma_eff h F/m.
  double beta_eff() const { return beta * (1.0 - af) / (1.0 - am); }
  double gamma_eff() const { return gamma * (1.0 - af) / (1.0 - am); }
};

// Time weighting of the NodeForceModels' (contact) forces, docs/models/contact.md section 10.
// The scheme's pseudo-acceleration then follows
//     (1 - am) a_{n+1} + am a_n = (1 - af) vdot_s(t_{n+1}) + af vdot_s(t_n) + Fc(t_{n+1}) / m
// with vdot_s the acceleration of the smooth forces (internal, external, drag): the contact force
// is taken at the end of the step only, NOT alpha-averaged with the previous step's. Averaged, a
// contact that opened during the step kept pushing with af Fc(t_n) in the next one (measured: the
// released log-cabin stack gained energy, layer 3 hopped 340 nm). In the unknowns of the Stepper
// (vdot = vdot_pred + bp dx, the alpha-averaged acceleration) the equation of motion reads
//     m vdot - F_s - w Fc = 0,   w = 1 / (1 - af)
// and the acceleration the next step remembers is vdot_s = vdot - w Fc / m. A node at rest under a
// load balanced by Fc stays at rest; the impulse of a contact force over the steps is h Fc (total).
inline double contact_force_weight(const GenAlpha &g) { return 1.0 / (1.0 - g.af); }
inline GenAlpha gen_alpha(double rho_inf) {
  GenAlpha g;
  g.rho_inf = rho_inf;
  g.am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0);
  g.af = rho_inf / (rho_inf + 1.0);
  g.gamma = 0.5 + g.af - g.am;
  g.beta = 0.25 * (g.gamma + 0.5) * (g.gamma + 0.5);
  return g;
}

struct Node {
  // state at t_n on input, at t_{n+1} after a successful step
  Vec3 x;          // position (m)
  Quat q;          // frame (t_I = R(q) e_I)
  Vec3 v;          // velocity, spatial (m/s)
  Vec3 W;          // angular velocity, BODY frame (rad/s)
  Vec3 ax, aw;     // pseudo-accelerations (generalized-alpha), translational spatial, rotational body
  Vec3 vdx, vdw;   // accelerations dv/dt (spatial), dW/dt (body)
  // constant over the step
  double m = 0;    // mass (kg)
  Vec3 J;          // principal rotary inertia about t1, t2, t3 (kg m^2)
  Vec3 F, T;       // external force (N) and torque (N m), spatial
  double D[6] = {0, 0, 0, 0, 0, 0};  // -dF/dv (N s/m): xx yy zz xy xz yz
  double scale = 1e-5;               // length scale of the convergence test (m): the section radius
  bool fixed = false;                // clamped: position and frame held
  double radius = 0;                 // section radius seen by the force models (m)
  // a rectangular contact section 2 rect[0] x 2 rect[1] (half-sides along t1, t2, m) instead of the
  // circle of `radius` (then the larger half-side); 0, 0: the circle (physics/static_bodies.h)
  double rect[2] = {0, 0};
  bool next = true;  // an element joins this node to the next one in the vector; false at the last
                     // node of a fiber when several fibers are solved together (a contact cluster)
  // outputs (end of step)
  Vec3 Fint, Tint;  // internal (elastic + material damping) force and torque, spatial
  Vec3 Fmodel;      // force of the NodeForceModels at the end of the step (N), spatial
};

// A node's mass as the contact laws see it (kg): a clamped node (fixed) does not move: infinite.
inline double contact_mass(const Node &n) { return n.fixed ? std::numeric_limits<double>::infinity() : n.m; }

// Derivatives of node forces F_k with respect to node positions and velocities, block tridiagonal
// (3 x 3 blocks, row-major): d = (k, k), l = (k, k-1), u = (k, k+1).
struct ForceJacobian {
  std::vector<double> Kd, Kl, Ku, Cd, Cl, Cu;  // dF/dx (N/m), dF/dv (N s/m)
  // A force f(h, u) n between two points p = sum_i w_i x_i (i < 4 nodes, weights of both sides with
  // the sign of their side: + on the side the normal points to), gap h = n.p + const, rate u = n.dp/dt:
  // its derivatives are the rank-one terms dF_i/dx_j = w_i w_j dFdh n n^T, dF_i/dv_j = w_i w_j dFdu n n^T
  // for all i, j, also between nodes that are not neighbours (contact between two fibers of a
  // cluster). The Stepper solves with them by the Woodbury identity.
  struct Coupling {
    int node[4];
    double w[4];
    Vec3 n;
    double dFdh, dFdu;
  };
  std::vector<Coupling> couplings;
  void reset(std::size_t n) {
    for (std::vector<double> *v : {&Kd, &Kl, &Ku, &Cd, &Cl, &Cu}) v->assign(9 * n, 0.0);
    couplings.clear();
  }
  // adds w K (dF_row/dx_col) and w C (dF_row/dv_col); col must be row or a neighbour
  void add(std::size_t row, std::size_t col, double w, const double K[9], const double C[9]) {
    std::vector<double> *kk = col == row ? &Kd : (col + 1 == row ? &Kl : (col == row + 1 ? &Ku : nullptr));
    std::vector<double> *cc = col == row ? &Cd : (col + 1 == row ? &Cl : (col == row + 1 ? &Cu : nullptr));
    if (!kk) return;
    for (int i = 0; i < 9; ++i) {
      (*kk)[9 * row + i] += w * K[i];
      (*cc)[9 * row + i] += w * C[i];
    }
  }
};

// A contact that a Newton correction would carry from outside (h > 0) to deeper than the steric
// servo's linear range below h = 0 (the first case of the correction limiter, static_bodies.h
// landing_fraction), for the landing predictor (Options::land_predict; Stepper::predict_landings):
// its normal force phi g_i on node i (g_i: the gap's gradient with respect to node i, node -1:
// none; up to two nodes of each side), the gap h (m) and rate u = sum g_i . v_i (m/s) at the
// current iterate, phi (N) there, and phi, dphi/dh (N/m), dphi/du (N s/m) at (0, u).
struct Landing {
  int node[4] = {-1, -1, -1, -1};
  Vec3 g[4];
  double h = 0.0, phi = 0.0, phi0 = 0.0, dphidh0 = 0.0, dphidu0 = 0.0;
  const void *owner = nullptr;  // the model and its contact's index there (a contact is taken once)
  int index = -1;
};

// A force on the nodes that depends on their end-of-step state (positions, velocities) and is
// evaluated at every Newton iterate (contact with static bodies: physics/static_bodies.h).
class NodeForceModel {
 public:
  virtual ~NodeForceModel() = default;
  // called before the steps of one fiber (its id in the simulation; -1 when there is none)
  virtual void begin_fiber(int fiber) { (void)fiber; }
  // called before the steps of several fibers solved together (a contact cluster): their ids and
  // the index of each one's first node in the node vector (offsets.size() = fibers.size() + 1)
  virtual void begin_cluster(const std::vector<int> &fibers, const std::vector<int> &offsets) {
    (void)fibers;
    (void)offsets;
  }
  // called once per step, before its attempts, with the whole step's length H (s): its sub-steps
  // (begin_step's t0, h) span [t0, t0 + h] of [0, H]
  virtual void begin_whole_step(double H) { (void)H; }
  // called at the start of every attempt of a (sub-)step of length h (s) that begins t0 (s) after
  // the start of the whole step, with the nodes' state at the start of the sub-step
  virtual void begin_step(const std::vector<Node> &start, double t0, double h) {
    (void)start;
    (void)t0;
    (void)h;
  }
  // adds the forces at the nodes' current state to F (N); if J: their derivatives too
  virtual void evaluate(const std::vector<Node> &nodes, std::vector<Vec3> &F, ForceJacobian *J) = 0;
  // largest fraction in (0, 1] of the translational correction dx (m, per node) the model accepts
  // from the state of its last evaluation (a damped Newton step); 1 = no limit
  virtual double limit(const std::vector<Node> &nodes, const std::vector<Vec3> &dx) const {
    (void)nodes;
    (void)dx;
    return 1.0;
  }
  // appends to out the contacts that the correction dx (m, per node) would carry from outside to
  // deep inside (struct Landing), evaluated at the state of the model's last evaluation
  virtual void landings(const std::vector<Node> &nodes, const std::vector<Vec3> &dx, std::vector<Landing> &out) const {
    (void)nodes;
    (void)dx;
    (void)out;
  }
};

struct Element {  // between node k and k+1
  beam::ElementRef ref;
  beam::Stiffness C;
};

struct Options {
  double tol = 1e-8;      // convergence: max |dx|/scale and |dtheta| (rad) of the last correction
  int max_iter = 25;      // Newton iterations per attempt
  int max_split = 8;      // halvings of a step that does not converge
  double t_damp = 0.0;    // Kelvin-Voigt damping time of the elements (s)
  double tau_drag = 0.0;  // background drag time (s), 0 = off
  // the NodeForceModels' forces at the end of the step only (contact_force_weight); false: alpha-
  // averaged like the internal forces (the former scheme; kept for comparison)
  bool contact_at_end = true;
  // a factored tangent serves at most this many steps (with a Tangent passed to Stepper::step;
  // 1: formed anew in every step)
  int tangent_steps = 1;
  // Anderson mixing of the corrections (0: off; at most Stepper::kMaxAnderson): each correction
  // solved with the held iteration matrix is combined with the last `anderson` ones (see the file
  // comment); the convergence test is unchanged
  int anderson = 0;
  // landing predictor (Stepper::predict_landings): a correction that would carry contacts from
  // outside to deep inside is solved again with those contacts' forces linearised about their
  // landing gap, so several contacts land in one iteration; false: only the limiter, which scales
  // the whole correction so that the first of them lands (one contact per iteration)
  bool land_predict = false;
};

struct Stats {
  long iterations = 0;   // Newton iterations of this step (all attempts)
  long tangents = 0;     // tangent formations and factorisations
  long limited = 0;      // iterations whose correction a force model's limiter shortened (contact landings)
  long predicted = 0;    // contacts the landing predictor linearised (Options::land_predict)
  int splits = 0;        // sub-steps beyond one (0: the step converged whole)
  int depth = 0;         // deepest halving level used
  long start_failed = 0; // sub-steps of the level the step started at (first_depth) that were split
  bool ok = true;
  double energy = 0;     // elastic energy at the end (J)
  double dissipation = 0;
};

// The split memory of a fiber or contact cluster (Stepper::step's first_depth): the halving level
// its steps start at and how many steps in a row needed no deeper one.
struct SplitMemory {
  int depth = 0;
  int calm = 0;
};

// The memory after a step that started at m.depth, of whose 2^m.depth sub-steps `failed` did not
// converge whole (Stats::start_failed): one level deeper when none did (the step is too long
// throughout, as a press under load); unchanged but not calm when some did (a contact landing in
// one of them: it needs a tiny sub-step once, and starting every later step as deep would cost
// far more than the failed attempt saved); one level coarser after `relax_after` steps in a row
// without a failed sub-step (0: no memory, every step starts whole).
inline SplitMemory remember_split(SplitMemory m, long failed, int relax_after) {
  if (relax_after <= 0) return {};
  if (failed >= (1L << m.depth)) return {m.depth + 1, 0};
  if (failed > 0) return {m.depth, 0};
  if (++m.calm >= relax_after && m.depth > 0) return {m.depth - 1, 0};
  return m;
}

// The memory of fibers solved together: the deepest start, and of the fibers at that depth the
// shortest calm run (so the cluster relaxes no sooner than its most recently troubled fiber).
inline SplitMemory merge_split(SplitMemory a, SplitMemory b) {
  if (a.depth != b.depth) return a.depth > b.depth ? a : b;
  return {a.depth, std::min(a.calm, b.calm)};
}

// One column of the rank-one couplings of the iteration matrix (Stepper::build_couplings).
struct CouplingColumn {
  int node[4];
  double u[12];     // scaled g_c at the translational dofs of its nodes
  int lo[4], hi[4]; // node ranges (fibers) Z is computed on
  int nr = 0;
  std::vector<double> z;  // T^-1 g_c on those ranges, 6 values per node
  double zval(int k, int d) const {
    int off = 0;
    for (int r = 0; r < nr; ++r) {
      if (k >= lo[r] && k < hi[r]) return z[static_cast<std::size_t>(6 * (off + k - lo[r]) + d)];
      off += hi[r] - lo[r];
    }
    return 0.0;
  }
};

// The factored iteration matrix of one fiber (or contact cluster) and what it was formed with.
// Modified Newton ACROSS steps (docs/models/beam.md, "Cost"): the caller keeps one Tangent per
// fiber and passes it to Stepper::step; a step starts on it instead of forming a new one when
// it is younger than Options::tangent_steps steps, the step size, the scheme's coefficients, the
// clamped nodes and the damping/drag times are those it was formed with, no node has turned by
// more than Stepper::kReuseTurn since, and the velocity Jacobian D of the external forces and the
// derivatives of the NodeForceModels changed by at most Stepper::kModelChange times the matrix's
// translational diagonal. Inside the step the contraction test decides as before (a correction
// not below kContraction times the previous one forms a new tangent). Contents are private to the
// Stepper; a default-constructed Tangent holds none.
struct Tangent {
  int age = -1;  // successful steps since it was formed; -1: none held
  // step h (s) and the coefficients of the iteration matrix it was formed with (Stepper::attempt)
  std::array<double, 6> coef{};  // h, gp, bp, kfac, inv_tau, wc
  std::vector<char> fixed;     // clamped nodes
  std::vector<double> drag;    // D of every node (6 values), N s/m
  std::vector<Quat> q;         // frames of the nodes
  ForceJacobian jac;           // the models' derivatives
  std::vector<double> D, L, U, scale;  // scaled block factors, the symmetric diagonal scaling
  std::vector<int> piv;
  std::vector<CouplingColumn> cols;    // Woodbury couplings and their capacitance factors:
  std::vector<double> cap;             // dense LU (fewer than Stepper::sparse_from couplings)
  std::vector<int> cpiv;
  // sparse LU (Eigen, COLAMD ordering; from Stepper::sparse_from couplings on); immutable once
  // factored, so copies of a Tangent may share it
  std::shared_ptr<const Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>>> cap_sparse;
};

class Stepper {
 public:
  static constexpr double kMaxTurn = 0.5;      // rad: largest rotation correction of one iteration
  static constexpr double kMaxStepTurn = 1.0;  // rad: largest rotation of a node in one step
  static constexpr int kRefresh = 4;           // iterations on one tangent before it is formed again
  static constexpr double kContraction = 0.25; // a correction larger than this x the previous one: new tangent
  static constexpr double kFreshSlack = 1.25;  // ... or than this x what the newest fresh tangent achieved
  static constexpr double kSlowCap = 0.9;      // (at most this)
  static constexpr int kMaxBacktracks = 12;    // halvings of one correction whose residual grew
  static constexpr int kMaxAnderson = 8;       // largest history of Anderson mixing (Options::anderson)
  static constexpr double kReuseTurn = 0.1;    // rad: a node turned further since a held tangent: form anew
  static constexpr double kCosHalfReuseTurn = 0.99875026039496628;  // cos(kReuseTurn / 2)
  static constexpr double kModelChange = 0.1;  // model/drag derivatives changed by more than this x the
                                               // translational diagonal since a held tangent: form anew
  // Start of the integration. consistent = true: initial accelerations from all forces,
  // vdot = (F_int + F)/m, J Wdot = R^T (T_int + T) - W x J W, a = vdot (exact start; use it when
  // the step resolves every mode of the fiber). consistent = false: from the EXTERNAL loads only.
  // With a step that does not resolve the stiff modes, the internal forces of a pre-stressed start
  // would put h (1 - gamma) omega^2 x0 into the first velocities (measured 4.6e7 rad/s on a twisted
  // 9-node fiber released at dt = 1e-5 s), which drag and contact would see. Starting from zero
  // acceleration instead would leave a permanent velocity error (1 - gamma) h F/m. A fiber at rest
  // in its stress-free shape (every generated fiber) starts exactly either way.
  void initialise(std::vector<Node> &nodes, const std::vector<Element> &elems, const Options &opt,
                  bool consistent = false) {
    internal_forces(nodes, elems, opt, nullptr);
    for (Node &nd : nodes) {
      if (nd.fixed) {
        nd.vdx = nd.vdw = nd.ax = nd.aw = Vec3{};
        continue;
      }
      const Vec3 F = consistent ? nd.F + nd.Fint : nd.F;
      const Vec3 T = consistent ? nd.T + nd.Tint : nd.T;
      nd.vdx = (1.0 / nd.m) * F;
      const Vec3 tb = beam::qrot_t(nd.q, T) - beam::cross(nd.W, beam::hadamard(nd.J, nd.W));
      nd.vdw = {tb.x / nd.J.x, tb.y / nd.J.y, tb.z / nd.J.z};
      nd.ax = nd.vdx;
      nd.aw = nd.vdw;
    }
  }

  // One step of length h. On failure the nodes are left at their input state and ok = false.
  // models: forces evaluated inside the Newton iteration (may be null or empty).
  // keep: the fiber's factored tangent from earlier steps (may be null: a new one in every step);
  // the step starts on it when it still serves (struct Tangent) and leaves its last one there.
  // first_depth: start as 2^first_depth equal sub-steps (split memory; at most opt.max_split).
  Stats step(std::vector<Node> &nodes, const std::vector<Element> &elems, double h, const GenAlpha &g,
             const Options &opt, const std::vector<NodeForceModel *> *models = nullptr, Tangent *keep = nullptr,
             int first_depth = 0) {
    models_ = models;
    if (models)
      for (NodeForceModel *m : *models) m->begin_whole_step(h);
    if (keep) std::swap(tg_, *keep);
    else tg_.age = -1;
    Stats st;
    // the start of every halving level (allocated once: advance keeps references into it)
    if (starts_.size() < static_cast<std::size_t>(opt.max_split) + 1) starts_.resize(opt.max_split + 1);
    const int d0 = std::min(std::max(first_depth, 0), std::max(opt.max_split, 0));
    first_depth_ = d0;
    // the 2^d0 sub-steps and their start times (exact: powers of two; d0 = 0: the whole step)
    if (d0 > 0) starts_[0] = nodes;  // advance saves the start of level d0 only
    const long n = 1L << d0;
    const double hs = std::ldexp(h, -d0);
    st.splits = static_cast<int>(n - 1);
    for (long i = 0; i < n && st.ok; ++i) st.ok = advance(nodes, elems, static_cast<double>(i) * hs, hs, g, opt, d0, st);
    if (!st.ok) nodes = starts_[0];
    if (!st.ok) tg_.age = -1;
    else if (tg_.age >= 0) ++tg_.age;
    if (keep) std::swap(tg_, *keep);
    return st;
  }

  // Internal forces/torques of all nodes at their current state into Fint/Tint (and energy).
  static void internal_forces(std::vector<Node> &nodes, const std::vector<Element> &elems, const Options &opt,
                              Stats *st) {
    for (Node &nd : nodes) nd.Fint = nd.Tint = Vec3{};
    for (std::size_t e = 0; e < elems.size(); ++e) {
      if (!nodes[e].next) continue;
      Node &A = nodes[e], &B = nodes[e + 1];
      const beam::ElementForces f =
          beam::element_forces(state(A), state(B), elems[e].ref, elems[e].C, opt.t_damp);
      A.Fint = A.Fint + f.fA;
      A.Tint = A.Tint + f.tA;
      B.Fint = B.Fint + f.fB;
      B.Tint = B.Tint + f.tB;
      if (st) {
        st->energy += f.energy;
        st->dissipation += f.dissipation;
      }
    }
  }

 private:
  static beam::NodeState state(const Node &n) {
    beam::NodeState s;
    s.x = n.x;
    s.q = n.q;
    s.v = n.v;
    s.w = beam::qrot(n.q, n.W);
    return s;
  }

 public:
  // 12 residual components of one element's internal forces (sign: -force, rotations in the body
  // frame of each node); grad (optional): the forces' derivatives with respect to the chord, for
  // element_tangent.
  static void element_residual(const beam::NodeState &A, const beam::NodeState &B, const Element &el,
                               double t_damp, double out[12], beam::ElementChordGradient *grad = nullptr) {
    const beam::ElementForces f = beam::element_forces(A, B, el.ref, el.C, t_damp, grad);
    const Vec3 ta = beam::qrot_t(A.q, f.tA), tb = beam::qrot_t(B.q, f.tB);
    const Vec3 parts[4] = {f.fA, ta, f.fB, tb};
    for (int p = 0; p < 4; ++p)
      for (int c = 0; c < 3; ++c) out[3 * p + c] = -parts[p][c];
  }

  // Element tangent (12 x 12, row-major) d(residual)/d(dx_A, dth_A, dx_B, dth_B) at the current
  // state (translations spatial, rotations body-frame right perturbations). The element forces
  // depend on the translations only through the chord d = x_B - x_A (and v_B - v_A): the x_A
  // columns are the analytic chord derivatives g (beam::ElementChordGradient, with the residual's
  // sign and body frames: d r / d x_A = +d F / d d), the x_B columns minus them. The 6 rotation
  // columns: analytic for elastic elements (g.has_rot), else forward differences from the
  // residual r0 (6 element evaluations; truncation error O(step): relative 1e-7 here, far below
  // what modified Newton tolerates). Tested against central differences in test_implicit_rod.cpp.
  static void element_tangent(const beam::NodeState &A, const beam::NodeState &B, const Element &el,
                              double t_damp, const double r0[12], const beam::ElementChordGradient &g,
                              double K[144]) {
    for (int j = 0; j < 3; ++j) {
      const Vec3 col[4] = {g.dfA[j], beam::qrot_t(A.q, g.dtA[j]), -1.0 * g.dfA[j], beam::qrot_t(B.q, g.dtB[j])};
      for (int p = 0; p < 4; ++p)
        for (int c = 0; c < 3; ++c) {
          K[(3 * p + c) * 12 + j] = col[p][c];
          K[(3 * p + c) * 12 + 6 + j] = -col[p][c];
        }
    }
    if (g.has_rot) {
      // analytic rotation columns (elastic elements): r = -(f_A, R_A^T t_A, f_B, R_B^T t_B); the
      // node's own frame turns with it: d(R^T t) = R^T dt - e x (R^T t)
      const Vec3 ta{-r0[3], -r0[4], -r0[5]}, tb{-r0[9], -r0[10], -r0[11]};
      for (int node = 0; node < 2; ++node)
        for (int j = 0; j < 3; ++j) {
          Vec3 e{};
          e[j] = 1.0;
          const Vec3 &dfA = node == 0 ? g.rA_dfA[j] : g.rB_dfA[j];
          Vec3 dta = beam::qrot_t(A.q, node == 0 ? g.rA_dtA[j] : g.rB_dtA[j]);
          Vec3 dtb = beam::qrot_t(B.q, node == 0 ? g.rA_dtB[j] : g.rB_dtB[j]);
          if (node == 0) dta = dta - beam::cross(e, ta);
          else dtb = dtb - beam::cross(e, tb);
          const Vec3 col[4] = {-1.0 * dfA, -1.0 * dta, dfA, -1.0 * dtb};
          const int c = node == 0 ? 3 + j : 9 + j;
          for (int p = 0; p < 4; ++p)
            for (int q = 0; q < 3; ++q) K[(3 * p + q) * 12 + c] = col[p][q];
        }
      return;
    }
    const double hr = 1e-7;  // rad
    double rp[12];
    for (int c : {3, 4, 5, 9, 10, 11}) {
      beam::NodeState Ap = A, Bp = B;
      beam::NodeState &P = c < 6 ? Ap : Bp;
      Vec3 d{};
      d[c % 6 - 3] = hr;
      P.q = beam::qmul(P.q, beam::qexp(d));
      element_residual(Ap, Bp, el, t_damp, rp);
      const double inv = 1.0 / hr;
      for (int r = 0; r < 12; ++r) K[r * 12 + c] = (rp[r] - r0[r]) * inv;
    }
  }

 private:
  // K[:, c0..c0+2] <- K[:, c0..c0+2] J_r(th), J_r(th) = J_l(-th) = I - a th^ + b th^2 (12 x 12 K)
  static void right_jacobian_columns(double K[144], int c0, Vec3 th) {
    const double f = beam::norm(th);
    if (f < 1e-12) return;
    const beam::JacobianCoeffs k = beam::jacobian_coeffs(f);
    double Jr[9];
    for (int j = 0; j < 3; ++j) {
      Vec3 e{};
      e[j] = 1.0;
      const Vec3 col = beam::apply_so3(th, -k.a, k.b, e);  // J_r e_j
      for (int i = 0; i < 3; ++i) Jr[i * 3 + j] = col[i];
    }
    for (int r = 0; r < 12; ++r) {
      double row[3];
      for (int j = 0; j < 3; ++j) {
        row[j] = 0.0;
        for (int m = 0; m < 3; ++m) row[j] += K[r * 12 + c0 + m] * Jr[m * 3 + j];
      }
      for (int j = 0; j < 3; ++j) K[r * 12 + c0 + j] = row[j];
    }
  }

  // what the tangent just formed was formed with (struct Tangent); the models' derivatives only
  // when there are models (none: an empty jac, which model_change treats as changed)
  void remember_tangent(const std::vector<Node> &nodes, double h, double gp, double bp, double kfac,
                        double inv_tau, double wc, bool have_models) {
    const std::size_t n = nodes.size();
    tg_.age = 0;
    tg_.coef = {h, gp, bp, kfac, inv_tau, wc};
    tg_.fixed.resize(n);
    tg_.drag.resize(6 * n);
    tg_.q.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      tg_.fixed[k] = nodes[k].fixed;
      std::copy(nodes[k].D, nodes[k].D + 6, &tg_.drag[6 * k]);
      tg_.q[k] = nodes[k].q;
    }
    if (have_models) tg_.jac = jac_;
    else tg_.jac = ForceJacobian{};
  }

  // the held tangent may start this attempt (struct Tangent); the models are checked separately
  // (model_change) once they have been evaluated
  bool held_tangent_serves(const std::vector<Node> &nodes, double h, double gp, double bp, double kfac,
                           double inv_tau, double wc, const Options &opt, bool have_models) const {
    const std::size_t n = nodes.size();
    if (tg_.age < 0 || tg_.age >= opt.tangent_steps || tg_.fixed.size() != n) return false;
    if (have_models != !tg_.jac.Kd.empty()) return false;  // force models registered or removed since
    if (tg_.coef != std::array<double, 6>{h, gp, bp, kfac, inv_tau, wc}) return false;
    for (std::size_t k = 0; k < n; ++k) {
      if (static_cast<bool>(tg_.fixed[k]) != nodes[k].fixed) return false;
      if (nodes[k].fixed) continue;
      // turned by more than kReuseTurn: |q0 . q| = cos(angle / 2)
      const Quat &a = tg_.q[k], &b = nodes[k].q;
      if (std::fabs(a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z) < kCosHalfReuseTurn) return false;
      // drag: S += gp D (translational block)
      const double diag = translational_diagonal(k);
      for (int i = 0; i < 6; ++i)
        if (!(gp * std::fabs(nodes[k].D[i] - tg_.drag[6 * k + i]) <= kModelChange * diag)) return false;
    }
    return true;
  }

  // smallest translational diagonal entry of the held (unscaled) iteration matrix at node k
  double translational_diagonal(std::size_t k) const {
    double d = INFINITY;
    for (int i = 0; i < 3; ++i) d = std::min(d, 1.0 / (tg_.scale[6 * k + i] * tg_.scale[6 * k + i]));
    return d;
  }

  // largest change of the models' part of the iteration matrix, -wc (dF/dx + gp dF/dv), between
  // the held tangent's derivatives and jac_ (just evaluated), relative to the translational
  // diagonal of the held matrix; INFINITY when the set of couplings changed
  double model_change(const std::vector<Node> &nodes, double gp, double wc) const {
    const std::size_t n = nodes.size();
    const ForceJacobian &a = jac_, &b = tg_.jac;
    if (b.Kd.size() != a.Kd.size() || b.couplings.size() != a.couplings.size()) return INFINITY;
    double worst = 0.0;
    for (std::size_t k = 0; k < n; ++k) {
      if (nodes[k].fixed) continue;
      const double inv = 1.0 / translational_diagonal(k);
      for (std::size_t q = 9 * k; q < 9 * k + 9; ++q) {
        const double dd = (a.Kd[q] - b.Kd[q]) + gp * (a.Cd[q] - b.Cd[q]);
        const double dl = (a.Kl[q] - b.Kl[q]) + gp * (a.Cl[q] - b.Cl[q]);
        const double du = (a.Ku[q] - b.Ku[q]) + gp * (a.Cu[q] - b.Cu[q]);
        worst = std::max(worst, wc * std::max({std::fabs(dd), std::fabs(dl), std::fabs(du)}) * inv);
      }
    }
    for (std::size_t c = 0; c < a.couplings.size(); ++c) {
      const ForceJacobian::Coupling &ca = a.couplings[c], &cb = b.couplings[c];
      double w2 = 0.0, diag = INFINITY;
      for (int i = 0; i < 4; ++i) {
        if (ca.node[i] != cb.node[i]) return INFINITY;
        w2 = std::max({w2, ca.w[i] * ca.w[i], cb.w[i] * cb.w[i]});
        if (!nodes[ca.node[i]].fixed) diag = std::min(diag, translational_diagonal(ca.node[i]));
      }
      // kappa n n^T as it enters the matrix (kappa <= 0 is left out: build_couplings)
      const double ka = std::max(0.0, -wc * (ca.dFdh + gp * ca.dFdu));
      const double kb = std::max(0.0, -wc * (cb.dFdh + gp * cb.dFdu));
      double dm = 0.0;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) dm = std::max(dm, std::fabs(ka * ca.n[i] * ca.n[j] - kb * cb.n[i] * cb.n[j]));
      if (std::isfinite(diag)) worst = std::max(worst, dm * w2 / diag);
    }
    return worst;
  }

  // a Newton correction dx (m), dth (rad, body) of node k: increments and the scheme's relations
  void correct(Node &nd, std::size_t k, Vec3 dx, Vec3 dth, double h, double gp, double bp) {
    dQx_[k] = dQx_[k] + (1.0 / h) * dx;
    dQw_[k] = dQw_[k] + (1.0 / h) * dth;
    nd.v = nd.v + gp * dx;
    nd.W = nd.W + gp * dth;
    nd.vdx = nd.vdx + bp * dx;
    nd.vdw = nd.vdw + bp * dth;
  }

  void set_positions(std::vector<Node> &nodes, const std::vector<Node> &start, double h) {
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      if (nodes[k].fixed) continue;
      nodes[k].x = start[k].x + h * dQx_[k];
      nodes[k].q = beam::qnormalize(beam::qmul(start[k].q, beam::qexp(h * dQw_[k])));
    }
  }

  bool advance(std::vector<Node> &nodes, const std::vector<Element> &elems, double t0, double h,
               const GenAlpha &g, const Options &opt, int depth, Stats &st) {
    st.depth = std::max(st.depth, depth);
    std::vector<Node> &start = starts_[static_cast<std::size_t>(depth)];
    start = nodes;
    if (attempt(nodes, start, elems, t0, h, g, opt, st)) return true;
    if (started_held_) {
      // it started on a held tangent: once more with a new one before the step is split
      nodes = start;
      tg_.age = -1;
      if (attempt(nodes, start, elems, t0, h, g, opt, st)) return true;
    }
    if (depth == first_depth_) ++st.start_failed;
    if (depth >= opt.max_split) return false;
    nodes = start;
    ++st.splits;
    if (!advance(nodes, elems, t0, 0.5 * h, g, opt, depth + 1, st)) return false;
    return advance(nodes, elems, t0 + 0.5 * h, 0.5 * h, g, opt, depth + 1, st);
  }

  bool attempt(std::vector<Node> &nodes, const std::vector<Node> &start, const std::vector<Element> &elems,
               double t0, double h, const GenAlpha &g, const Options &opt, Stats &st) {
    const std::size_t n = nodes.size();
    const double bp = (1.0 - g.am) / (h * h * g.beta * (1.0 - g.af));
    const double gp = g.gamma / (h * g.beta);
    const double inv_tau = opt.tau_drag > 0 ? 1.0 / opt.tau_drag : 0.0;
    const bool have_models = models_ && !models_->empty();
    const double wc = have_models && opt.contact_at_end ? contact_force_weight(g) : 1.0;
    if (have_models)
      for (NodeForceModel *m : *models_) m->begin_step(start, t0, h);
    dQx_.assign(n, Vec3{});
    dQw_.assign(n, Vec3{});
    lastdx_.assign(n, Vec3{});
    lastdth_.assign(n, Vec3{});
    // predictor: the nodes stay where they are (dQ = 0), the other quantities from the scheme's
    // relations. (Extrapolating the acceleration or the velocity instead can rotate a node of tiny
    // rotary inertia by more than pi in one large step: the exponential map then aliases and Newton
    // converges to a spurious branch spinning at 2 pi k / h.)
    for (std::size_t k = 0; k < n; ++k) {
      Node &nd = nodes[k];
      const Node &s = start[k];
      if (nd.fixed) {
        nd.v = nd.W = nd.vdx = nd.vdw = Vec3{};
        continue;
      }
      const Vec3 ax1 = (-1.0 / (h * g.beta)) * (s.v + (h * (0.5 - g.beta)) * s.ax);
      const Vec3 aw1 = (-1.0 / (h * g.beta)) * (s.W + (h * (0.5 - g.beta)) * s.aw);
      nd.v = s.v + h * ((1.0 - g.gamma) * s.ax + g.gamma * ax1);
      nd.W = s.W + h * ((1.0 - g.gamma) * s.aw + g.gamma * aw1);
      nd.vdx = (1.0 / (1.0 - g.af)) * ((1.0 - g.am) * ax1 + g.am * s.ax - g.af * s.vdx);
      nd.vdw = (1.0 / (1.0 - g.af)) * ((1.0 - g.am) * aw1 + g.am * s.aw - g.af * s.vdw);
      dQx_[k] = dQw_[k] = Vec3{};
    }
    set_positions(nodes, start, h);

    rhs_.assign(n * 6, 0.0);
    const double kfac = 1.0 + gp * opt.t_damp;  // Kelvin-Voigt: damping tangent ~ t_d K
    // modified Newton across steps: start on the held tangent if it still serves (struct Tangent)
    bool reuse = held_tangent_serves(nodes, h, gp, bp, kfac, inv_tau, wc, opt, have_models);
    started_held_ = reuse;
    if (!reuse) tg_.scale.assign(n * 6, 1.0);
    double Ke[144], re[12];
    int since_tangent = 0;
    bool slow = false;         // the last correction did not shrink fast enough: form a new tangent
    double prev_err = INFINITY;
    double last_rn = INFINITY;  // scaled residual norm at the last accepted iterate
    double fresh_ratio = 0.0;   // contraction of the last correction solved with a tangent formed for it
    bool fresh = false;         // the last correction was solved with a tangent formed for it
    int backtracks = 0;
    const int aa_m = std::min(std::max(opt.anderson, 0), kMaxAnderson);
    aa_reset();
    for (int it = 0; it < opt.max_iter; ++it) {
      ++st.iterations;
      // modified Newton: the tangent is formed and factored at the first iteration (unless a held
      // one serves) and again whenever kRefresh iterations have not converged
      bool tangent = (it == 0 && !reuse) || since_tangent >= kRefresh || slow;
      // forces of the models at the current iterate (and their tangent); at the first iteration on
      // a held tangent their derivatives decide whether it still serves
      const bool want_jac = tangent || (it == 0 && have_models);
      Fc_.assign(n, Vec3{});
      if (want_jac) jac_.reset(n);
      if (have_models) {
        for (NodeForceModel *m : *models_) m->evaluate(nodes, Fc_, want_jac ? &jac_ : nullptr);
      }
      if (!tangent && it == 0 && have_models && !(model_change(nodes, gp, wc) <= kModelChange)) tangent = true;
      since_tangent = tangent ? 1 : since_tangent + 1;
      if (tangent) {
        aa_reset();  // Anderson mixing: the history belongs to one iteration matrix
        ++st.tangents;
        if (it == 0) started_held_ = false;
        tg_.age = -1;  // none held until this one is factored (remember_tangent)
        tg_.D.assign(n * blocktri::kBB, 0.0);
        tg_.L.assign(n * blocktri::kBB, 0.0);
        tg_.U.assign(n * blocktri::kBB, 0.0);
        tg_.piv.assign(n * 6, 0);
      }
      std::fill(rhs_.begin(), rhs_.end(), 0.0);
      // internal forces (and their tangent)
      ns_.resize(n);
      for (std::size_t k = 0; k < n; ++k) ns_[k] = state(nodes[k]);
      for (std::size_t e = 0; e + 1 < n; ++e) {
        if (!nodes[e].next) continue;  // the last node of a fiber in a cluster
        const beam::NodeState &A = ns_[e], &B = ns_[e + 1];
        element_residual(A, B, elems[e], opt.t_damp, re, tangent ? &chord_ : nullptr);
        for (int r = 0; r < 6; ++r) {
          rhs_[e * 6 + r] += re[r];
          rhs_[(e + 1) * 6 + r] += re[6 + r];
        }
        if (!tangent) continue;
        element_tangent(A, B, elems[e], opt.t_damp, re, chord_, Ke);
        // the rotation corrections act through q = q_n exp(h dQ): chain rule with the right
        // Jacobian of SO(3) at the current increment (the tangent operator T(h dQ) of Bruels et al.)
        right_jacobian_columns(Ke, 3, h * dQw_[e]);
        right_jacobian_columns(Ke, 9, h * dQw_[e + 1]);
        for (int r = 0; r < 6; ++r)
          for (int c = 0; c < 6; ++c) {
            tg_.D[e * 36 + r * 6 + c] += kfac * Ke[r * 12 + c];
            tg_.U[e * 36 + r * 6 + c] += kfac * Ke[r * 12 + 6 + c];
            tg_.L[(e + 1) * 36 + r * 6 + c] += kfac * Ke[(6 + r) * 12 + c];
            tg_.D[(e + 1) * 36 + r * 6 + c] += kfac * Ke[(6 + r) * 12 + 6 + c];
          }
      }
      // inertia, external forces, drag
      for (std::size_t k = 0; k < n; ++k) {
        Node &nd = nodes[k];
        const Node &s = start[k];
        double *Dk = &tg_.D[k * 36];
        double *rk = &rhs_[k * 6];
        if (nd.fixed) {
          for (int i = 0; i < 6; ++i) rk[i] = 0.0;
          if (tangent) {
            for (int i = 0; i < 36; ++i) Dk[i] = tg_.U[k * 36 + i] = tg_.L[k * 36 + i] = 0.0;
            for (int i = 0; i < 6; ++i) Dk[i * 7] = 1.0;
          }
          continue;
        }
        // translation: m vdot - F_ext + D (v - v_n) + m v / tau
        const Vec3 dv = nd.v - s.v;
        const double *D = nd.D;
        const Vec3 Ddv{D[0] * dv.x + D[3] * dv.y + D[4] * dv.z, D[3] * dv.x + D[1] * dv.y + D[5] * dv.z,
                       D[4] * dv.x + D[5] * dv.y + D[2] * dv.z};
        const Vec3 rx = nd.m * nd.vdx - nd.F - wc * Fc_[k] + Ddv + (nd.m * inv_tau) * nd.v;
        // rotation (body): J Wdot + W x J W - R^T T_ext + J W / tau
        const Vec3 JW = beam::hadamard(nd.J, nd.W);
        const Vec3 b = beam::qrot_t(nd.q, nd.T);
        const Vec3 rw = beam::hadamard(nd.J, nd.vdw) + beam::cross(nd.W, JW) - b + inv_tau * JW;
        for (int i = 0; i < 3; ++i) {
          rk[i] += rx[i];
          rk[3 + i] += rw[i];
        }
        if (!tangent) continue;
        const double Dfull[9] = {D[0], D[3], D[4], D[3], D[1], D[5], D[4], D[5], D[2]};
        // the skew matrices [W]x, [J W]x, [b]x (entry i, j: column j's component i)
        const physics::Mat3 SW = physics::skew(nd.W), SJW = physics::skew(JW), Sb = physics::skew(b);
        for (int i = 0; i < 3; ++i) {
          Dk[i * 6 + i] += bp * nd.m + gp * nd.m * inv_tau;
          Dk[(3 + i) * 6 + 3 + i] += bp * nd.J[i] + gp * inv_tau * nd.J[i];
          for (int j = 0; j < 3; ++j) {
            Dk[i * 6 + j] += gp * Dfull[i * 3 + j];
            Dk[(3 + i) * 6 + 3 + j] += gp * (SW.c[j][i] * nd.J[j] - SJW.c[j][i]) - Sb.c[j][i];
          }
        }
        if (!have_models) continue;
        // the models' forces: S += -wc (dF/dx + gp dF/dv) (translational blocks)
        double *Lk = &tg_.L[k * 36], *Uk = &tg_.U[k * 36];
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            const std::size_t q = 9 * k + 3 * i + j;
            Dk[i * 6 + j] -= wc * (jac_.Kd[q] + gp * jac_.Cd[q]);
            if (k > 0) Lk[i * 6 + j] -= wc * (jac_.Kl[q] + gp * jac_.Cl[q]);
            if (k + 1 < n) Uk[i * 6 + j] -= wc * (jac_.Ku[q] + gp * jac_.Cu[q]);
          }
      }
      // Backtracking (with force models only): a correction that made the residual grow (it stepped
      // across a kink of a contact law, e.g. the clip of the steric servo, and Newton would cycle
      // between both sides) is halved and the residual evaluated again. Norm: the residual scaled as
      // the system.
      if (have_models) {
        double rn = 0.0;
        for (std::size_t q = 0; q < n * 6; ++q) rn += rhs_[q] * rhs_[q] * tg_.scale[q] * tg_.scale[q];
        if (have_models && fresh && it > 0 && rn > last_rn * (1.0 + 1e-9) && backtracks < kMaxBacktracks &&
            std::isfinite(last_rn)) {
          ++backtracks;
          for (std::size_t k = 0; k < n; ++k) {
            if (nodes[k].fixed) continue;
            lastdx_[k] = 0.5 * lastdx_[k];
            lastdth_[k] = 0.5 * lastdth_[k];
            correct(nodes[k], k, -1.0 * lastdx_[k], -1.0 * lastdth_[k], h, gp, bp);
          }
          set_positions(nodes, start, h);
          aa_reset();
          slow = true;  // a new tangent at the shortened iterate
          continue;
        }
        backtracks = 0;
        last_rn = rn;
      }
      if (tangent) {
        // symmetric diagonal scaling, then the block factorisation
        for (std::size_t k = 0; k < n; ++k)
          for (int i = 0; i < 6; ++i) {
            const double dii = std::fabs(tg_.D[k * 36 + i * 7]);
            tg_.scale[k * 6 + i] = dii > 0 && std::isfinite(dii) ? 1.0 / std::sqrt(dii) : 1.0;
          }
        for (std::size_t k = 0; k < n; ++k) {
          const double *sk = &tg_.scale[k * 6];
          const double *sp = k > 0 ? &tg_.scale[(k - 1) * 6] : sk;
          const double *sn = k + 1 < n ? &tg_.scale[(k + 1) * 6] : sk;
          for (int i = 0; i < 6; ++i)
            for (int j = 0; j < 6; ++j) {
              tg_.D[k * 36 + i * 6 + j] *= sk[i] * sk[j];
              tg_.L[k * 36 + i * 6 + j] *= sk[i] * sp[j];
              tg_.U[k * 36 + i * 6 + j] *= sk[i] * sn[j];
            }
        }
        if (!blocktri::factor(static_cast<int>(n), tg_.D.data(), tg_.L.data(), tg_.U.data(), tg_.piv.data())) return false;
        if (!build_couplings(nodes, gp, wc)) return false;
        remember_tangent(nodes, h, gp, bp, kfac, inv_tau, wc, have_models);
      }
      // solve S d = -r with the (possibly older) factors
      for (std::size_t q = 0; q < n * 6; ++q) rhs_[q] *= -tg_.scale[q];
      blocktri::solve_factored(static_cast<int>(n), tg_.D.data(), tg_.L.data(), tg_.U.data(), tg_.piv.data(), rhs_.data());
      apply_couplings();
      double raw_full = -1.0;  // the modified-Newton correction's size when Anderson mixing changes the step
      if (aa_m > 0) raw_full = anderson(nodes, aa_m);
      // (with a tangent formed at this iterate only: on a held one the correction's prediction of the
      // gaps is too poor to linearise contacts on, measured: docs/bench/laydown.md "Landing predictor")
      if (have_models && opt.land_predict && tangent) st.predicted += predict_landings(nodes, gp, wc);
      // update; a correction that would rotate a node by more than kMaxTurn is shortened (damped
      // Newton), and a step that turns a node by more than kMaxStepTurn fails (and is split)
      double err = 0.0, turn = 0.0;
      for (std::size_t k = 0; k < n; ++k) {
        double t2 = 0.0;
        for (int i = 0; i < 3; ++i) t2 += std::pow(rhs_[k * 6 + 3 + i] * tg_.scale[k * 6 + 3 + i], 2);
        turn = std::max(turn, std::sqrt(t2));
      }
      if (!std::isfinite(turn)) return false;
      double damp = turn > kMaxTurn ? kMaxTurn / turn : 1.0;
      if (have_models) {
        // the models may shorten the correction further (contact gaps: static_bodies.h)
        correction_translations(nodes, damp);
        double frac = 1.0;
        for (NodeForceModel *m : *models_) frac = std::min(frac, m->limit(nodes, dxs_));
        if (!(frac > 0.0)) return false;
        if (frac < 1.0) ++st.limited;
        damp *= frac;
      }
      for (std::size_t k = 0; k < n; ++k) {
        Node &nd = nodes[k];
        if (nd.fixed) continue;
        Vec3 dx, dth;
        for (int i = 0; i < 3; ++i) {
          dx[i] = damp * rhs_[k * 6 + i] * tg_.scale[k * 6 + i];
          dth[i] = damp * rhs_[k * 6 + 3 + i] * tg_.scale[k * 6 + 3 + i];
        }
        if (!std::isfinite(dx.x + dx.y + dx.z + dth.x + dth.y + dth.z)) return false;
        err = std::max(err, std::max(beam::norm(dx) / nd.scale, beam::norm(dth)));
        lastdx_[k] = dx;
        lastdth_[k] = dth;
        if (aa_m > 0)
          for (int i = 0; i < 3; ++i) {
            aa_step_[6 * k + i] = dx[i] / nd.scale;
            aa_step_[6 * k + 3 + i] = dth[i];
          }
        correct(nd, k, dx, dth, h, gp, bp);
      }
      set_positions(nodes, start, h);
      // the size of the full (undamped) correction measures convergence
      const double full = raw_full >= 0.0 ? raw_full : (damp > 0.0 ? err / damp : err);
      // the contraction of the correction solved with a tangent formed for it: when forming anew
      // does not contract better (a secant tangent, e.g. friction in slip), a held tangent that
      // does about as well is kept instead of forming one every iteration
      if (tangent && it > 0 && std::isfinite(prev_err) && prev_err > 0.0) fresh_ratio = full / prev_err;
      slow = !(full <= std::max(kContraction, std::min(kSlowCap, kFreshSlack * fresh_ratio)) * prev_err);
      prev_err = full;
      fresh = tangent || (it == 0 && started_held_);  // a held tangent that passed the checks counts as new
      if (!(full <= opt.tol)) continue;
      for (std::size_t k = 0; k < n; ++k)
        if (h * beam::norm(dQw_[k]) > kMaxStepTurn) return false;
      // converged: end-of-step outputs and pseudo-accelerations
      Stats tmp;
      internal_forces(nodes, elems, opt, &tmp);
      st.energy = tmp.energy;
      st.dissipation = tmp.dissipation;
      for (std::size_t k = 0; k < n; ++k) {
        Node &nd = nodes[k];
        const Node &s = start[k];
        nd.Fmodel = Fc_[k];
        if (nd.fixed) continue;
        nd.ax = (1.0 / (1.0 - g.am)) * ((1.0 - g.af) * nd.vdx + g.af * s.vdx - g.am * s.ax);
        nd.aw = (1.0 / (1.0 - g.am)) * ((1.0 - g.af) * nd.vdw + g.af * s.vdw - g.am * s.aw);
        // the next step averages only the smooth forces' acceleration (contact_force_weight)
        if (wc != 1.0) nd.vdx = nd.vdx - (wc / nd.m) * Fc_[k];
        const double big = std::fabs(nd.x.x) + std::fabs(nd.v.x + nd.v.y + nd.v.z) +
                           std::fabs(nd.W.x + nd.W.y + nd.W.z);
        if (!std::isfinite(big)) return false;
      }
      return true;
    }
    return false;
  }

  // ---- rank-one couplings (ForceJacobian::Coupling) by the Woodbury identity. The iteration matrix is
  // S = T + sum_c kappa_c g_c g_c^T, T block tridiagonal (factored; block diagonal over the fibers of
  // a cluster), g_c the coupling's node weights times its normal, kappa_c = -(dF/dh + gp dF/du) > 0.
  // S^-1 r = y - Z (K^-1 + G^T Z)^-1 G^T y with y = T^-1 r, Z = T^-1 G: one solve per coupling over
  // the fibers it touches, and an LU of the (couplings x couplings) capacitance matrix (dense, or
  // sparse from sparse_from couplings on: build_couplings).
  // Terms with kappa <= 0 (attraction) are left out of the iteration matrix (modified Newton).

  // ---- Anderson mixing of the modified-Newton corrections (Options::anderson; see the file comment)
  void aa_reset() {
    aa_cols_ = 0;
    aa_have_prev_ = false;
  }
  // rhs_ * scale is the correction f_k (weighted: translations / node scale). Mixes it with the
  // last differences: step = f_k - (dX + dF) gamma, gamma = argmin |f_k - dF gamma|; writes the
  // step back into rhs_ and returns the largest node norm of f_k (the convergence measure).
  double anderson(const std::vector<Node> &nodes, int m) {
    const std::size_t n = nodes.size(), N = 6 * n;
    aa_f_.resize(N);
    double full = 0.0;
    for (std::size_t k = 0; k < n; ++k) {
      const double ws = nodes[k].fixed ? 0.0 : 1.0 / nodes[k].scale;
      const double wr = nodes[k].fixed ? 0.0 : 1.0;
      double t2 = 0.0, r2 = 0.0;
      for (int i = 0; i < 3; ++i) {
        aa_f_[6 * k + i] = ws * rhs_[6 * k + i] * tg_.scale[6 * k + i];
        aa_f_[6 * k + 3 + i] = wr * rhs_[6 * k + 3 + i] * tg_.scale[6 * k + 3 + i];
        t2 += aa_f_[6 * k + i] * aa_f_[6 * k + i];
        r2 += aa_f_[6 * k + 3 + i] * aa_f_[6 * k + 3 + i];
      }
      full = std::max(full, std::max(std::sqrt(t2), std::sqrt(r2)));
    }
    if (aa_dF_.size() != static_cast<std::size_t>(m) * N) {
      aa_dF_.assign(static_cast<std::size_t>(m) * N, 0.0);
      aa_dX_.assign(static_cast<std::size_t>(m) * N, 0.0);
      aa_cols_ = 0;
    }
    if (aa_have_prev_ && aa_prev_f_.size() == N && aa_step_.size() == N) {
      // shift the history: newest column first
      const int keep = std::min(aa_cols_, m - 1);
      for (int c = keep; c > 0; --c) {
        std::copy_n(&aa_dF_[(c - 1) * N], N, &aa_dF_[c * N]);
        std::copy_n(&aa_dX_[(c - 1) * N], N, &aa_dX_[c * N]);
      }
      for (std::size_t q = 0; q < N; ++q) {
        aa_dF_[q] = aa_f_[q] - aa_prev_f_[q];
        aa_dX_[q] = aa_step_[q];
      }
      aa_cols_ = keep + 1;
    }
    aa_prev_f_ = aa_f_;
    aa_have_prev_ = true;
    aa_step_.assign(N, 0.0);
    if (aa_cols_ == 0) return full;
    // normal equations with a small ridge
    const int c = aa_cols_;
    double G[64], b[8];
    for (int i = 0; i < c; ++i) {
      b[i] = 0.0;
      for (std::size_t q = 0; q < N; ++q) b[i] += aa_dF_[i * N + q] * aa_f_[q];
      for (int j = 0; j <= i; ++j) {
        double sum = 0.0;
        for (std::size_t q = 0; q < N; ++q) sum += aa_dF_[i * N + q] * aa_dF_[j * N + q];
        G[i * c + j] = G[j * c + i] = sum;
      }
    }
    double tr = 0.0;
    for (int i = 0; i < c; ++i) tr += G[i * c + i];
    if (!(tr > 0.0) || !std::isfinite(tr)) return full;
    for (int i = 0; i < c; ++i) G[i * c + i] += 1e-10 * tr;
    // Cholesky
    for (int j = 0; j < c; ++j) {
      double d = G[j * c + j];
      for (int k = 0; k < j; ++k) d -= G[j * c + k] * G[j * c + k];
      if (!(d > 0.0)) return full;
      d = std::sqrt(d);
      G[j * c + j] = d;
      for (int i = j + 1; i < c; ++i) {
        double v = G[i * c + j];
        for (int k = 0; k < j; ++k) v -= G[i * c + k] * G[j * c + k];
        G[i * c + j] = v / d;
      }
    }
    double gam[8];
    for (int i = 0; i < c; ++i) {
      double v = b[i];
      for (int k = 0; k < i; ++k) v -= G[i * c + k] * gam[k];
      gam[i] = v / G[i * c + i];
    }
    for (int i = c - 1; i >= 0; --i) {
      double v = gam[i];
      for (int k = i + 1; k < c; ++k) v -= G[k * c + i] * gam[k];
      gam[i] = v / G[i * c + i];
    }
    for (std::size_t k = 0; k < n; ++k) {
      if (nodes[k].fixed) continue;
      for (int i = 0; i < 6; ++i) {
        const std::size_t q = 6 * k + i;
        double st = aa_f_[q];
        for (int j = 0; j < c; ++j) st -= gam[j] * (aa_dX_[j * N + q] + aa_dF_[j * N + q]);
        const double w = i < 3 ? nodes[k].scale : 1.0;
        rhs_[q] = st * w / tg_.scale[q];
      }
    }
    return full;
  }
  std::vector<double> aa_f_, aa_prev_f_, aa_step_, aa_dF_, aa_dX_;
  int aa_cols_ = 0;
  bool aa_have_prev_ = false;

  bool build_couplings(const std::vector<Node> &nodes, double gp, double wc) {
    tg_.cols.clear();
    if (jac_.couplings.empty()) return true;
    const int n = static_cast<int>(nodes.size());
    // fiber ranges
    flo_.assign(static_cast<std::size_t>(n), 0);
    fhi_.assign(static_cast<std::size_t>(n), n);
    for (int k = 0, lo = 0; k < n; ++k) {
      flo_[k] = lo;
      if (!nodes[k].next || k + 1 == n) {
        for (int j = lo; j <= k; ++j) fhi_[j] = k + 1;
        lo = k + 1;
      }
    }
    std::vector<double> kinv;
    for (const ForceJacobian::Coupling &c : jac_.couplings) {
      const double kappa = -wc * (c.dFdh + gp * c.dFdu);
      if (!(kappa > 0.0) || !std::isfinite(kappa)) continue;
      CouplingColumn w;
      for (int i = 0; i < 4; ++i) {
        w.node[i] = c.node[i];
        for (int d = 0; d < 3; ++d)
          w.u[3 * i + d] = nodes[c.node[i]].fixed ? 0.0 : tg_.scale[6 * c.node[i] + d] * c.w[i] * c.n[d];
        bool have = false;
        for (int r = 0; r < w.nr; ++r) have = have || w.lo[r] == flo_[c.node[i]];
        if (!have) {
          w.lo[w.nr] = flo_[c.node[i]];
          w.hi[w.nr] = fhi_[c.node[i]];
          ++w.nr;
        }
      }
      for (int r = 0; r < w.nr; ++r) {
        const std::size_t off = w.z.size();
        w.z.resize(off + 6 * static_cast<std::size_t>(w.hi[r] - w.lo[r]), 0.0);
        for (int i = 0; i < 4; ++i)
          if (w.node[i] >= w.lo[r] && w.node[i] < w.hi[r])
            for (int d = 0; d < 3; ++d) w.z[off + 6 * (w.node[i] - w.lo[r]) + d] += w.u[3 * i + d];
        const std::size_t lo = static_cast<std::size_t>(w.lo[r]);
        blocktri::solve_factored(w.hi[r] - w.lo[r], &tg_.D[36 * lo], &tg_.L[36 * lo], &tg_.U[36 * lo], &tg_.piv[6 * lo],
                                 &w.z[off]);
      }
      tg_.cols.push_back(std::move(w));
      kinv.push_back(1.0 / kappa);
    }
    const std::size_t m = tg_.cols.size();
    const bool sparse = m > 0 && m >= sparse_from;  // (SparseLU divides by zero on an empty matrix)
    tg_.cap_sparse.reset();
    if (sparse) {
      tg_.cap.clear();
      trip_.clear();
    } else {
      tg_.cap.assign(m * m, 0.0);
    }
    // G^T Z: entry (a, b) is non-zero only where a node of column a lies on a fiber that column
    // b's z covers, so each a visits only the columns listed on its nodes' fibers (the same sums
    // in the same order as over all b: the other entries are exact zeros). In a pile that is one
    // cluster the matrix is sparse (contacts couple through the fibers they share): from
    // sparse_from couplings on it is factored as such (the dense LU was 45 % of the case-C pile's
    // time at 14 ms; docs/bench/laydown.md "Sparse capacitance matrix").
    if (by_fiber_.size() < static_cast<std::size_t>(n)) by_fiber_.resize(static_cast<std::size_t>(n));
    for (int k = 0; k < n; ++k) by_fiber_[static_cast<std::size_t>(k)].clear();  // keeps their storage
    for (std::size_t b = 0; b < m; ++b)
      for (int r = 0; r < tg_.cols[b].nr; ++r) by_fiber_[static_cast<std::size_t>(tg_.cols[b].lo[r])].push_back(b);
    seen_.assign(m, m);
    for (std::size_t a = 0; a < m; ++a) {
      if (sparse) trip_.emplace_back(static_cast<int>(a), static_cast<int>(a), kinv[a]);
      else tg_.cap[a * m + a] = kinv[a];
      near_.clear();
      for (int i = 0; i < 4; ++i)
        for (std::size_t b : by_fiber_[static_cast<std::size_t>(flo_[tg_.cols[a].node[i]])])
          if (seen_[b] != a) {
            seen_[b] = a;
            near_.push_back(b);
          }
      for (std::size_t b : near_) {
        double v = 0.0;
        for (int i = 0; i < 4; ++i)
          for (int d = 0; d < 3; ++d) v += tg_.cols[a].u[3 * i + d] * tg_.cols[b].zval(tg_.cols[a].node[i], d);
        if (sparse) trip_.emplace_back(static_cast<int>(a), static_cast<int>(b), v);  // (summed)
        else tg_.cap[a * m + b] += v;
      }
    }
    if (sparse) {
      Eigen::SparseMatrix<double> A(static_cast<Eigen::Index>(m), static_cast<Eigen::Index>(m));
      A.setFromTriplets(trip_.begin(), trip_.end());
      // The ordering (COLAMD) and the elimination tree depend on the pattern alone: a matrix with
      // the pattern of the previous one is factored on that analysis, which no held tangent shares
      // (the same factors as a fresh compute(); 5 % of the case-C pile's time went to analysing).
      const bool same = reuse_analysis && sparse_lu_ && sparse_lu_.use_count() == 1 && A.isCompressed() &&
                        pattern_outer_.size() == static_cast<std::size_t>(m + 1) &&
                        std::equal(pattern_outer_.begin(), pattern_outer_.end(), A.outerIndexPtr()) &&
                        pattern_inner_.size() == static_cast<std::size_t>(A.nonZeros()) &&
                        std::equal(pattern_inner_.begin(), pattern_inner_.end(), A.innerIndexPtr());
      if (!same) {
        if (!sparse_lu_ || sparse_lu_.use_count() != 1)
          sparse_lu_ = std::make_shared<Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>>>();
        sparse_lu_->analyzePattern(A);
        pattern_outer_.assign(A.outerIndexPtr(), A.outerIndexPtr() + m + 1);
        pattern_inner_.assign(A.innerIndexPtr(), A.innerIndexPtr() + A.nonZeros());
      } else {
        ++pattern_reused;
      }
      sparse_lu_->factorize(A);
      if (sparse_lu_->info() != Eigen::Success) {
        sparse_lu_.reset();  // analyse the next matrix afresh
        return false;
      }
      tg_.cap_sparse = sparse_lu_;
      return true;
    }
    tg_.cpiv.resize(m);
    return blocktri::lu_factor(static_cast<int>(m), tg_.cap.data(), tg_.cpiv.data());
  }

 public:
  // couplings from which the capacitance matrix is factored sparse (build_couplings); below it
  // the dense LU (the same numbers to round-off; tests/test_fiber_partners.cpp sets both)
  std::size_t sparse_from = 128;
  // a sparse capacitance matrix with the previous one's pattern is factored on its analysis
  // (false: every one analysed afresh; the same factors, tests/test_fiber_partners.cpp)
  bool reuse_analysis = true;
  // sparse capacitance factorisations that reused the previous matrix's analysis (diagnostics)
  long pattern_reused = 0;

 private:

  void apply_couplings() { apply_couplings(rhs_); }
  // the Woodbury correction of the couplings applied to T^-1 r held (scaled) in rhs
  void apply_couplings(std::vector<double> &rhs) {
    const std::size_t m = tg_.cols.size();
    if (m == 0) return;
    tw_.assign(m, 0.0);
    for (std::size_t a = 0; a < m; ++a)
      for (int i = 0; i < 4; ++i)
        for (int d = 0; d < 3; ++d) tw_[a] += tg_.cols[a].u[3 * i + d] * rhs[6 * tg_.cols[a].node[i] + d];
    ty_.resize(m);
    if (tg_.cap_sparse) {
      const Eigen::Map<const Eigen::VectorXd> b(tw_.data(), static_cast<Eigen::Index>(m));
      Eigen::Map<Eigen::VectorXd>(ty_.data(), static_cast<Eigen::Index>(m)) = tg_.cap_sparse->solve(b);
    } else {
      blocktri::lu_solve(static_cast<int>(m), tg_.cap.data(), tg_.cpiv.data(), tw_.data(), ty_.data());
    }
    for (std::size_t b = 0; b < m; ++b) {
      const CouplingColumn &w = tg_.cols[b];
      std::size_t off = 0;
      for (int r = 0; r < w.nr; ++r) {
        const std::size_t len = 6 * static_cast<std::size_t>(w.hi[r] - w.lo[r]);
        double *y = &rhs[6 * static_cast<std::size_t>(w.lo[r])];
        for (std::size_t q = 0; q < len; ++q) y[q] -= w.z[off + q] * ty_[b];
        off += len;
      }
    }
  }

  // dxs_: the nodes' translations of the current correction rhs_ (scaled back) times factor, zero
  // for fixed nodes; what the force models' limit() and landings() are asked about
  void correction_translations(const std::vector<Node> &nodes, double factor) {
    const std::size_t n = nodes.size();
    dxs_.assign(n, Vec3{});
    for (std::size_t k = 0; k < n; ++k)
      if (!nodes[k].fixed)
        for (int i = 0; i < 3; ++i) dxs_[k][i] = factor * rhs_[k * 6 + i] * tg_.scale[k * 6 + i];
  }

  // ---- landing predictor (Options::land_predict). The correction y0 = -S^-1 r in rhs_ (scaled)
  // would carry contacts c from outside to deep inside (NodeForceModel::landings). Their forces
  // phi_c g_c are replaced by the linearisation about the landing gap 0 at the iterate's rate,
  // phi0 + dphi/dh0 (h + g.d) + dphi/du0 gp (g.d), and the correction solved again:
  //   (S + G K G^T) d = -r - G beta,  kappa_c = -wc (dphi/dh0 + gp dphi/du0),
  //   beta_c = wc (phi_c - phi0_c - dphi/dh0_c h_c),
  // by the Woodbury identity on the factored S: d = y0 - Z a, Z = S^-1 G,
  // (I + K G^T Z) a = K G^T y0 + beta (one solve with S per contact, a dense system of their
  // number). The contact's own derivative at h in S (small outside the servo's range) is left in.
  // Contacts the new correction carries in are added, up to kLandRounds rounds and kMaxLandings
  // contacts; the limiter then acts on the result as before (a contact loaded beyond the servo's
  // linear range still lands by it). Called on iterations with a tangent formed for them only,
  // where Anderson mixing has no history yet: y0 is the plain Newton correction. Contacts whose
  // kappa is not positive (attraction) are left to the limiter. Returns the number of contacts
  // linearised.
  static constexpr int kLandRounds = 3;
  static constexpr std::size_t kMaxLandings = 64;
  long predict_landings(const std::vector<Node> &nodes, double gp, double wc) {
    const std::size_t n = nodes.size(), N = 6 * n;
    land_.clear();
    lz_.clear();
    lk_.clear();
    lb_.clear();
    ly0_.clear();
    for (int round = 0; round < kLandRounds; ++round) {
      correction_translations(nodes, 1.0);
      lfound_.clear();
      for (NodeForceModel *m : *models_) m->landings(nodes, dxs_, lfound_);
      std::size_t added = 0;
      for (const Landing &c : lfound_) {
        if (land_.size() >= kMaxLandings) break;
        bool have = false;
        for (const Landing &o : land_) have = have || (o.owner == c.owner && o.index == c.index);
        if (have) continue;
        const double kappa = -wc * (c.dphidh0 + gp * c.dphidu0);
        if (!(kappa > 0.0) || !std::isfinite(kappa) || !std::isfinite(c.phi + c.phi0)) continue;
        if (ly0_.empty()) ly0_ = rhs_;
        land_.push_back(c);
        lk_.push_back(kappa);
        lb_.push_back(wc * (c.phi - c.phi0 - c.dphidh0 * c.h));
        // z = S^-1 g in the scaled system: the scaled g, the block solve, the couplings
        std::vector<double> z(N, 0.0);
        for (int i = 0; i < 4; ++i) {
          const int k = c.node[i];
          if (k < 0 || nodes[static_cast<std::size_t>(k)].fixed) continue;
          for (int d = 0; d < 3; ++d) z[6 * k + d] += tg_.scale[6 * k + d] * c.g[i][d];
        }
        blocktri::solve_factored(static_cast<int>(n), tg_.D.data(), tg_.L.data(), tg_.U.data(), tg_.piv.data(), z.data());
        apply_couplings(z);
        lz_.push_back(std::move(z));
        ++added;
      }
      if (added == 0) break;
      // (I + K G^T Z) a = K G^T y0 + beta, G^T in the scaled system: the scaled g of each contact
      const std::size_t m = land_.size();
      auto gdot = [&](const Landing &c, const std::vector<double> &y) {
        double v = 0.0;
        for (int i = 0; i < 4; ++i) {
          const int k = c.node[i];
          if (k < 0 || nodes[static_cast<std::size_t>(k)].fixed) continue;
          for (int d = 0; d < 3; ++d) v += tg_.scale[6 * k + d] * c.g[i][d] * y[6 * k + d];
        }
        return v;
      };
      lA_.assign(m * m, 0.0);
      la_.assign(m, 0.0);
      std::vector<double> b(m);
      for (std::size_t p = 0; p < m; ++p) {
        for (std::size_t q = 0; q < m; ++q) lA_[p * m + q] = (p == q ? 1.0 : 0.0) + lk_[p] * gdot(land_[p], lz_[q]);
        b[p] = lk_[p] * gdot(land_[p], ly0_) + lb_[p];
      }
      lpiv_.resize(m);
      if (!blocktri::lu_factor(static_cast<int>(m), lA_.data(), lpiv_.data())) {
        rhs_ = ly0_;  // singular: the plain correction (the limiter acts on it)
        return 0;
      }
      blocktri::lu_solve(static_cast<int>(m), lA_.data(), lpiv_.data(), b.data(), la_.data());
      rhs_ = ly0_;
      for (std::size_t q = 0; q < m; ++q)
        for (std::size_t r = 0; r < N; ++r) rhs_[r] -= lz_[q][r] * la_[q];
    }
    return static_cast<long>(land_.size());
  }
  std::vector<Landing> land_, lfound_;
  std::vector<std::vector<double>> lz_;
  std::vector<double> lk_, lb_, ly0_, lA_, la_;
  std::vector<int> lpiv_;

  std::vector<double> tw_, ty_;
  std::vector<Eigen::Triplet<double>> trip_;  // build_couplings: the sparse capacitance matrix's entries
  // build_couplings: the newest sparse LU and the pattern it was analysed for (reused while no held
  // tangent shares it and the pattern repeats)
  std::shared_ptr<Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>>> sparse_lu_;
  std::vector<int> pattern_outer_, pattern_inner_;
  std::vector<int> flo_, fhi_;
  std::vector<std::vector<std::size_t>> by_fiber_;  // build_couplings: columns by fiber (first node)
  std::vector<std::size_t> seen_, near_;

  std::vector<std::vector<Node>> starts_;  // state at the start of the (sub-)step of each halving level
  const std::vector<NodeForceModel *> *models_ = nullptr;
  ForceJacobian jac_;
  std::vector<Vec3> Fc_, dxs_;
  std::vector<Vec3> dQx_, dQw_, lastdx_, lastdth_;
  std::vector<double> rhs_;
  std::vector<beam::NodeState> ns_;  // the nodes' states as the element sees them, at the current iterate
  beam::ElementChordGradient chord_;  // the element's chord derivatives when a tangent is formed
  bool started_held_ = false;  // the current attempt started on a held tangent
  int first_depth_ = 0;        // the halving level the current step started at (step's first_depth)
  Tangent tg_;  // the iteration matrix in use (exchanged with the caller's in step())
};

}  // namespace fiberform::physics::rod

#endif
