/* SPDX-License-Identifier: GPL-3.0-or-later
   fix fiber/beam: flexible fibers as chains of nodes joined by geometrically exact
   (Simo-Reissner) beam elements, thesis eq. 2.9-2.13, sections as in thesis sec. 3.4.

   Syntax (full page: docs/styles/fix_fiber_beam.md):
     fix ID group fiber/beam nodes FILE E <Pa> G <Pa> density <kg/m3> [keyword value ...]
       shear_factor k          Timoshenko shear correction (default 5/6)
       damping t_d             Kelvin-Voigt material damping time, s (default 0 = off)
       drag tau                mass-proportional background damping time, s (default 0 = off)
       stiffness_scale s       multiplies EA, GA1, GA2 (default 1)
       inertia_scale s         multiplies the nodes' rotary inertia (default 1)
       torque group Tx Ty Tz   constant external torque (N m, space frame) on the nodes of group
       dt_check error|warn     what to do when the timestep exceeds the critical step (default error)

   The fix integrates the fiber nodes itself (velocity Verlet for positions, symplectic splitting
   for the anisotropic rotation); do not apply fix nve/sphere to them.

   Public accessors (for contact styles, e.g. pair fiber/dlvo): valid for owned atoms and, after
   the fix's forward communication in pre_force, for ghost atoms. */
#ifndef LMP_FIX_FIBER_BEAM_H
#define LMP_FIX_FIBER_BEAM_H

#include <memory>
#include <string>
#include <vector>

#include "fix.h"

namespace fiberform::physics::rod {
class Stepper;
class NodeForceModel;
}

namespace LAMMPS_NS {
struct FiberTangents;  // factored tangents held from step to step (fix_fiber_beam.cpp)
}

namespace LAMMPS_NS {

class FixFiberBeam : public Fix {
 public:
  FixFiberBeam(class LAMMPS *lmp, int narg, char **arg);
  ~FixFiberBeam() override;
  int setmask() override;
  void init() override;
  void setup_pre_neighbor() override;
  void setup_pre_force(int vflag) override;
  void setup(int vflag) override;
  void pre_neighbor() override;
  void pre_force(int vflag) override;
  void initial_integrate(int vflag) override;
  void post_force(int vflag) override;
  void final_integrate() override;
  void reset_dt() override;
  double extend_cut_ghost() override;
  double compute_scalar() override;
  double compute_vector(int n) override;
  int modify_param(int narg, char **arg) override;

  void grow_arrays(int nmax) override;
  void copy_arrays(int i, int j, int delflag) override;
  void set_arrays(int i) override;
  int pack_exchange(int i, double *buf) override;
  int unpack_exchange(int nlocal, double *buf) override;
  int pack_restart(int i, double *buf) override;
  void unpack_restart(int nlocal, int nth) override;
  int size_restart(int i) override;
  int maxsize_restart() override;
  int pack_comm(int n, int *list, double *buf, int pbc_flag, int *pbc) override;
  void unpack_comm(int n, int first, double *buf) override;
  void write_restart(FILE *fp) override;
  void restart(char *buf) override;
  double memory_usage() override;

  // ---- public accessors (atom index i: owned or ghost) ----
  bool is_node(int i) const { return node_[i][FID] >= 0.0; }
  // The node dtag places along the fiber from local atom i (+1 the next, -1 the previous), as
  // the local copy closest to i (periodic boxes: the image next to it); -1 if none is here.
  int neighbour(int i, int dtag) const;
  int fiber_id(int i) const { return static_cast<int>(node_[i][FID]); }
  int node_index(int i) const { return static_cast<int>(node_[i][IDX]); }
  int node_count(int i) const { return static_cast<int>(node_[i][CNT]); }
  // unit quaternion (w, x, y, z) of the cross-section frame: t_I = R(q) e_I
  const double *quaternion(int i) const { return &node_[i][QW]; }
  // the frame vectors t1, t2 (principal axes of the section), t3 (tangent)
  void frame(int i, double t1[3], double t2[3], double t3[3]) const;
  // outer and inner semi-axes a1, a2, b1, b2 of the node's section, m
  void section_radii(int i, double r[4]) const;
  // ... of the element i -> j: the two nodes' averaged (beam::element_radii)
  void element_radii(int i, int j, double r[4]) const;
  // the larger outer half-axis (m): the convergence length of the Newton solve, and the radius of a
  // circular section in contacts inside it
  double contact_radius(int i) const { return node_[i][A1] > node_[i][A2] ? node_[i][A1] : node_[i][A2]; }
  // true for a collapsed section (a1 != a2): contacts inside the Newton solve see the thesis'
  // rectangle 2 a1 x 2 a2 (a1 along t1, a2 along t2; physics/static_bodies.h element_extent)
  bool contact_rect(int i) const { return node_[i][A1] != node_[i][A2]; }
  // the largest distance of the contact section's surface from the centre line (m): the radius
  // of a circle, the half-diagonal of a rectangle
  double contact_reach(int i) const;
  // the first fix fiber/beam defined in this LAMMPS instance, or nullptr
  static FixFiberBeam *find(class LAMMPS *lmp);
  // true if this fix comes before `other` in the fix list (its hooks run first)
  bool precedes(const Fix *other) const;

  // ---- time integration (docs/models/beam.md, "Implicit time integration") ----
  // true with `integrator implicit` (the default): positions, frames and velocities change only in
  // final_integrate, by one Newton solve per fiber of the generalized-alpha step.
  bool implicit() const { return implicit_; }
  // Effective Newmark coefficients of a force held constant over one step (implicit scheme):
  // dx(t+dt) = beta_eff dt^2 F/m, dv(t+dt) = gamma_eff dt F/m. Contact styles use beta_eff in the
  // averaged force of thesis eq. 2.22 and gamma_eff for velocity-level limiters (friction).
  // Explicit (velocity Verlet): 1/2 and 1/2.
  double beta_eff() const;
  double gamma_eff() const;
  // Implicit scheme only: adds D = -dF/dv (N s/m, symmetric 3x3 given as xx yy zz xy xz yz) of an
  // external force that a fix added to f this step, for local atom i. The Newton solve then treats
  // that force as F(v) ~ F(v_n) - D (v - v_n) (linearly implicit; fix fiber/drag uses it). Ignored
  // with the explicit integrator. Cleared after every step.
  void add_velocity_jacobian(int i, const double D[6]);
  // Implicit scheme only, after final_integrate of the step: a contact style that landed node i on
  // the end state of its own sub-integration (position through a constant force F in this step,
  // velocity set directly) takes F out of the scheme's acceleration history (dv/dt and the
  // pseudo-acceleration), so that the generalized-alpha memory does not deliver F's impulse a
  // second time in the following steps. F in N, spatial.
  void remove_from_history(int i, const double F[3]);
  // Implicit scheme only: a force model evaluated inside every fiber's Newton solve at the fiber's
  // end-of-step state (contact with static bodies: fix wall/fiber/yarns `implicit_force newton`). The
  // registering fix owns the model. use_force_model(m, true) registers m, (m, false) removes it
  // (idempotent; call it from init); release_force_model removes m from the fix fiber/beam of lmp
  // if there still is one (call it from the registering fix's destructor).
  void use_force_model(fiberform::physics::rod::NodeForceModel *m, bool on);
  // Implicit scheme only, for the next step: fibers solved together (contact clusters of pair_style
  // fiber/dlvo `implicit_force newton`): cluster[id] is the smallest fiber ID of fiber id's cluster
  // (the same on every rank). Empty: every fiber alone. Cleared after every step.
  void set_clusters(std::vector<int> cluster) { cluster_ = std::move(cluster); }
  static void release_force_model(class LAMMPS *lmp, fiberform::physics::rod::NodeForceModel *m);
  double youngs_modulus() const { return E_; }  // Pa
  double density() const { return rho_; }       // kg/m3
  // Implicit scheme: the internal (elastic) force and torque of local node i at the start of the
  // step (the last converged state); f and torque contain them after this fix's post_force.
  const double *internal_force(int i) const { return &node_[i][FIX]; }

  // column layout of the per-atom array (all doubles)
  enum Col {
    FID = 0, IDX, CNT,              // fiber ID (-1: not a fiber node), node index, node count
    QW, QX, QY, QZ,                 // current frame
    A1, A2, B1, B2,                 // section radii at the node
    X0, Y0, Z0, Q0W, Q0X, Q0Y, Q0Z, // stress-free reference position and frame
    HASREF,                         // 1 when the element to the next node is set up
    L0, G0X, G0Y, G0Z, K0X, K0Y, K0Z, // element to next node: length, Gamma0, kappa0
    CGX, CGY, CGZ, CKX, CKY, CKZ,   // element stiffness GA1 GA2 EA EI1 EI2 GJ
    NSTATIC,                        // columns below are not sent to ghosts
    JB1 = NSTATIC, JB2, JB3,        // rotary inertia of the node about t1, t2, t3, kg m^2
    // implicit integrator state (migrates with the atom, written to restart files)
    AX, AY, AZ, AWX, AWY, AWZ,      // generalized-alpha pseudo-accelerations (spatial, body)
    VDX, VDY, VDZ, VDWX, VDWY, VDWZ, // accelerations dv/dt (spatial), dW/dt (body)
    FIX, FIY, FIZ, TIX, TIY, TIZ,   // internal force/torque at the current state (spatial)
    ACCOK,                          // 1 once the accelerations above are initialised
    DJ0, DJ1, DJ2, DJ3, DJ4, DJ5,   // -dF/dv of this step's external forces (xx yy zz xy xz yz)
    SPLD, SPLN,                     // split memory of the node's fiber: start depth, calm steps (rod::SplitMemory)
    NCOL
  };

 private:
  void read_nodes_file(const char *path);
  void compute_reference();
  void compute_critical_steps(bool print);
  void element_section(int i, int j, double *area, double inertia[3], double stiff[6]) const;
  void internal_forces_local();    // element forces of the current state into acc_ (ghosts needed)
  void implicit_step();            // gather fibers to their owners, Newton solve, scatter
  void update_owners();            // rank of node 0 of every fiber (after atoms migrate)
  void wait_for_solvers(MPI_Request *req);  // the return exchange's wait, sleeping (patient_wait)

  double **node_ = nullptr;    // per-atom state, NCOL columns
  double **acc_ = nullptr;     // scratch: per-local-atom force/torque from prev (0-5), next (6-11)
  int nmax_acc_ = 0;

  double E_ = 0, G_ = 0, rho_ = 0, kshear_ = 5.0 / 6.0;
  double t_damp_ = 0, tau_drag_ = 0, stiff_scale_ = 1, inertia_scale_ = 1;
  int torque_groupbit_ = 0;
  double torque_[3] = {0, 0, 0};
  bool dt_check_error_ = true;
  bool implicit_ = true;
  double rho_inf_ = 0.5, newton_tol_ = 1e-8;
  // max_split 12 (was 8): a collapsed fiber's step on a yarn that stalled at 2^8 converged at
  // 2^10 (tests/test_laydown.py ribbons, session 22; converging runs are unchanged)
  int newton_max_ = 25, max_split_ = 12;
  int split_memory_ = 0;        // calm steps before a remembered split relaxes one level (keyword split_memory; 0: off)
  double start_depth_local_ = 0;  // deepest start depth of a fiber or cluster in the last step
  int anderson_ = 0;            // Anderson mixing depth of the Newton corrections (keyword anderson; 0: off)
  bool land_predict_ = false;   // landing predictor of the contact corrections (keyword landing predict|limit)
  int tangent_steps_ = 50;      // a factored tangent serves at most this many steps (keyword tangent_steps)
  bool contact_at_end_ = true;  // contact forces at the end of the step only (rod::contact_force_weight)
  int clamp_groupbit_ = 0;
  std::unique_ptr<fiberform::physics::rod::Stepper> stepper_;  // implicit solver workspace
  std::unique_ptr<FiberTangents> tangents_;  // per fiber/cluster on this rank; dropped when atoms migrate
  std::vector<fiberform::physics::rod::NodeForceModel *> models_;  // not owned
  std::vector<int> owner_;            // owner rank of fiber ID (index), -1 if absent
  std::vector<int> cluster_;          // set_clusters: smallest fiber ID of each fiber's cluster
  bool owners_valid_ = false;
  std::vector<double> sendbuf_, recvbuf_;
  std::vector<int> scount_, rcount_, sdispl_, rdispl_;
  double last_return_s_ = 0, step_period_s_ = 0;  // wait_for_solvers: the wall time between two steps' exchanges
  double stat_local_[5] = {0, 0, 0, 0, 0};  // Newton iterations, fibers solved, splits, max iterations, tangents
  double stat_total_splits_ = 0;
  double stat_run_[4] = {0, 0, 0, 0};  // since the fix was created: Newton iterations, fibers solved, tangents, limited iterations
  std::string nodes_path_;

  int ref_done_ = 0;
  int comm_mode_ = 0;  // 0: dynamic (q, v, omega), 1: static (columns 0..NSTATIC-1)
  double max_elem_len_ = 0;
  double dtv_ = 0, dtf_ = 0;
  double energy_local_ = 0, dissipation_local_ = 0;
  double dt_crit_[5] = {0, 0, 0, 0, 0};  // axial, shear, bending, torsion, min
  bigint nfibers_ = 0, nnodes_ = 0;
};

}  // namespace LAMMPS_NS

#endif
