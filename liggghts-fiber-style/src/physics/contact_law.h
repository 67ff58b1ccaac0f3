/* SPDX-License-Identifier: GPL-3.0-or-later
   The complete fiber-fiber contact law between two contact points: extended DLVO (eq. 2.30-2.33)
   plus steric repulsion (eq. 2.34-2.39). A ContactLaw holds the material/solution parameters; a
   PairLaw is built once per interacting pair (radii and masses fixed) so that the per-evaluation
   work inside the ODE right-hand side is a handful of flops and one exp(). SI units; positive
   force = repulsive. */
#ifndef FIBERFORM_PHYSICS_CONTACT_LAW_H
#define FIBERFORM_PHYSICS_CONTACT_LAW_H

#include <cmath>
#include <limits>

#include "physics/dlvo.h"
#include "physics/steric.h"

namespace fiberform::physics {

enum Terms : unsigned { kVdw = 1u, kEs = 2u, kSteric = 4u };

struct ContactLaw {
  unsigned terms = kVdw | kEs | kSteric;
  // van der Waals
  double hamaker = 8.0e-21;   // J, cellulose | water | cellulose (Bergstrom et al. 1999)
  bool full_hamaker = false;  // eq. 2.23 instead of eq. 2.25
  // electrolyte and surfaces
  double temperature = 298.15;    // K
  double eps_r = 78.5;            // water at 25 C
  double ionic_strength = 1.0;    // mol/m^3 (= 1 mM)
  double valency = 1.0;           // z of the symmetric z:z electrolyte
  bool use_charge = false;        // surface given as charge (eq. 2.29) instead of potential
  double psi_d = -0.025;          // V, diffuse-layer potential of the fiber surface
  double sigma = -0.0;            // C/m^2, surface charge (when use_charge)
  // extension and range
  double h0 = 1.0e-9;     // m, DLVO formulas used for h >= h0, splines below
  double h_cut = 50e-9;   // m, interaction range: no force, no ODE work beyond h_cut
  // h0, h_R, h_S, t_R; h_cap 2 nm, h_D 6 nm, h_S4 1 nm (docs/models/contact.md section 3)
  StericParams steric{1.0e-9, 0.5e-9, 3.0e-8, 1.0e-7, 2.0e-9};

  double kappa() const { return inverse_debye_length(ionic_strength, temperature, eps_r); }
  double kT_e() const { return constants::kB * temperature / (valency * constants::e); }

  // reduced diffuse-layer potential y of a surface of radius r (inf: plane)
  double reduced_surface_potential(double r) const {
    const double k = kappa();
    if (!use_charge) return reduced_potential(psi_d, valency, temperature);
    const double s = reduced_charge(sigma, valency, k, temperature, eps_r);
    return potential_from_reduced_charge(s, std::isinf(r) ? r : k * r);
  }
  double effective_potential(double r) const {
    const double k = kappa();
    return effective_surface_potential(reduced_surface_potential(r), std::isinf(r) ? r : k * r);
  }
};

// The law specialised to one pair of contact points.
struct PairLaw {
  const ContactLaw *law = nullptr;
  double r1 = 0, r2 = 0, rsum = 0;
  double mu = 0;  // reduced mass, kg
  double scale = 1.0;  // weight of the pair (1: mutual closest points, 1/2: one-sided; see contact.md)
  ElectrostaticParams es{};
  double Y1 = 0, Y2 = 0;
  Spline spl_vdw{}, spl_es{};

  // m2 = inf (inverse mass 0) for walls and frozen bodies; r2 = inf for a plane.
  void setup(const ContactLaw &L, double radius1, double radius2, double inv_m1, double inv_m2,
             double Y1_, double Y2_) {
    law = &L;
    r1 = radius1;
    r2 = radius2;
    rsum = std::isinf(r2) ? r1 : r1 + r2;  // steric h_min = -rsum (plane: the point's own radius)
    mu = 1.0 / (inv_m1 + inv_m2);
    scale = 1.0;
    es = {L.eps_r * constants::eps0, L.kT_e(), L.kappa()};
    Y1 = Y1_;
    Y2 = Y2_;
    const double h0 = L.h0;
    if (L.terms & kVdw) {
      if (L.full_hamaker) {
        const ForceAndSlope f = hamaker_force(L.hamaker, r1, r2, h0);
        spl_vdw = make_spline(f.force, f.slope, h0);
      } else {
        spl_vdw = make_spline(vdw_force(L.hamaker, r1, r2, h0), vdw_force_slope(L.hamaker, r1, r2, h0), h0);
      }
    }
    if (L.terms & kEs) {
      const ForceAndSlope f = electrostatic_force(es, Y1, Y2, r1, r2, h0);
      spl_es = make_spline(f.force, f.slope, h0);
    }
  }

  double vdw(double h) const {
    if (h < law->h0) return spline_value(spl_vdw, h);
    return law->full_hamaker ? hamaker_force(law->hamaker, r1, r2, h).force : vdw_force(law->hamaker, r1, r2, h);
  }
  double electrostatic(double h) const {
    if (h < law->h0) return spline_value(spl_es, h);
    return electrostatic_force(es, Y1, Y2, r1, r2, h).force;
  }
  // Total normal force (N, repulsive positive) at separation h (m) and separation rate u (m/s).
  double force(double h, double u) const {
    if (h >= law->h_cut) return 0.0;
    double F = 0.0;
    if (law->terms & kVdw) F += vdw(h);
    if (law->terms & kEs) F += electrostatic(h);
    if ((law->terms & kSteric) && h < law->h0) F += steric_force(law->steric, h, u, mu, rsum);
    return scale * F;
  }
};

}  // namespace fiberform::physics

#endif
