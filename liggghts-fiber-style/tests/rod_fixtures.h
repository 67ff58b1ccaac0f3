/* SPDX-License-Identifier: GPL-3.0-or-later
   Test fixture shared by the ctest unit tests of the implicit fiber step with contacts: a straight
   fiber of real pulp-fiber properties (E = 10 GPa, G = 4 GPa, 1500 kg/m3, hollow circular section). */
#ifndef FIBERFORM_TESTS_ROD_FIXTURES_H
#define FIBERFORM_TESTS_ROD_FIXTURES_H

#include <vector>

#include "physics/implicit_rod.h"

namespace fiberform::testing {

using physics::beam::Vec3;
namespace rod = physics::rod;
namespace beam = physics::beam;

struct Fiber {
  std::vector<rod::Node> nodes;
  std::vector<rod::Element> els;
  double mass = 0;  // kg
};

// Straight fiber of ne elements and length L (m) centred at c, along x (or y), section radii
// r_out/r_in (m); node masses and rotary inertias lumped (half at the ends).
inline Fiber make_fiber(int ne, double L, double r_out, double r_in, Vec3 c, bool along_y = false) {
  const double E = 10e9, G = 4e9, rho = 1500, ks = 5.0 / 6.0;
  const beam::Section s = beam::hollow_ellipse(r_out, r_out, r_in, r_in);
  const beam::Stiffness C = beam::section_stiffness(s, E, G, ks);
  Fiber f;
  f.nodes.resize(static_cast<std::size_t>(ne + 1));
  f.els.resize(static_cast<std::size_t>(ne));
  const double le = L / ne;
  for (int k = 0; k <= ne; ++k) {
    rod::Node &nd = f.nodes[static_cast<std::size_t>(k)];
    const double w = (k == 0 || k == ne) ? 0.5 : 1.0;
    nd.m = rho * s.A * le * w;
    nd.J = {rho * le * w * s.I1, rho * le * w * s.I2, rho * le * w * s.Ip};
    const double a = -0.5 * L + k * le;
    nd.x = along_y ? c + Vec3{0, a, 0} : c + Vec3{a, 0, 0};
    // frame: t3 along the axis
    nd.q = along_y ? beam::qexp({-0.5 * beam::kPi, 0, 0}) : beam::qexp({0, 0.5 * beam::kPi, 0});
    nd.scale = r_out;
    nd.radius = r_out;
    f.mass += nd.m;
  }
  for (int k = 0; k < ne; ++k) {
    rod::Element &e = f.els[static_cast<std::size_t>(k)];
    e.ref = beam::element_reference(f.nodes[k].x, f.nodes[k].q, f.nodes[k + 1].x, f.nodes[k + 1].q);
    e.C = C;
  }
  return f;
}

// make_fiber's fiber with a collapsed fiber's rectangular contact section 2 a1 x 2 a2
// (rod::Node::rect, the thesis' rule; the beam section stays make_fiber's hollow circle of radius
// a1), lying flat: its thickness axis t2 vertical (along x the frame is turned about the axis).
inline Fiber make_ribbon(int ne, double L, double a1, double a2, Vec3 c, bool along_y = false) {
  Fiber f = make_fiber(ne, L, a1, 0.6 * a1, c, along_y);
  for (rod::Node &nd : f.nodes) {
    if (!along_y) nd.q = beam::qmul(nd.q, beam::qexp({0, 0, 0.5 * beam::kPi}));
    nd.rect[0] = a1;
    nd.rect[1] = a2;
  }
  for (std::size_t k = 0; k + 1 < f.nodes.size(); ++k) {
    rod::Element &e = f.els[k];
    e.ref = beam::element_reference(f.nodes[k].x, f.nodes[k].q, f.nodes[k + 1].x, f.nodes[k + 1].q);
  }
  return f;
}

}  // namespace fiberform::testing

#endif
