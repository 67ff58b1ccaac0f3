/* SPDX-License-Identifier: GPL-3.0-or-later
   Keyword parsing shared by pair_style fiber/dlvo, fix wall/fiber/dlvo and fix wall/fiber/yarns (SI
   units). */
#include <cmath>
#include <cstring>
#include <string>

#include "contact_engine.h"
#include "error.h"
#include "force.h"
#include "group.h"
#include "lammps.h"
#include "style_args.h"

using namespace LAMMPS_NS;

namespace fiberform {

namespace {
double number(LAMMPS *lmp, const char *style, const char *kw, int iarg, int narg, char **arg, bool positive) {
  if (iarg >= narg) {
    std::string m = std::string(style) + ": keyword '" + kw + "' needs a value";
    lmp->error->all(FLERR, error_text(m));
  }
  char *end = nullptr;
  const double v = std::strtod(arg[iarg], &end);
  if (end == arg[iarg] || *end != '\0' || !std::isfinite(v) || (positive && !(v > 0))) {
    std::string m = std::string(style) + ": keyword '" + kw + "': '" + arg[iarg] + "' is not " +
                    (positive ? "a finite number > 0" : "a finite number");
    lmp->error->all(FLERR, error_text(m));
  }
  return v;
}
bool yesno(LAMMPS *lmp, const char *style, const char *kw, int iarg, int narg, char **arg) {
  if (iarg < narg && std::strcmp(arg[iarg], "yes") == 0) return true;
  if (iarg < narg && std::strcmp(arg[iarg], "no") == 0) return false;
  std::string m = std::string(style) + ": keyword '" + kw + "' expects yes or no";
  lmp->error->all(FLERR, error_text(m));
  return false;
}
}  // namespace

int parse_contact_keyword(LAMMPS *lmp, const char *style, EngineConfig &c, int iarg, int narg, char **arg) {
  const char *kw = arg[iarg];
  auto num = [&](int off, bool pos = true) { return number(lmp, style, kw, iarg + off, narg, arg, pos); };
  physics::ContactLaw &L = c.law;
  if (!std::strcmp(kw, "integrator")) {
    if (iarg + 1 >= narg) lmp->error->all(FLERR, "integrator: expected cvode | substep N | none");
    const char *v = arg[iarg + 1];
    if (!std::strcmp(v, "cvode")) { c.integrator = IntegratorKind::Cvode; return 2; }
    if (!std::strcmp(v, "none")) { c.integrator = IntegratorKind::None; return 2; }
    if (!std::strcmp(v, "substep")) {
      c.integrator = IntegratorKind::Substep;
      if (iarg + 2 >= narg) lmp->error->all(FLERR, "integrator substep: expected the number of sub-steps N");
      c.nsub = static_cast<int>(parse_count(lmp->error, style, "integrator substep", arg[iarg + 2], 1, 1000000));
      return 3;
    }
    lmp->error->all(FLERR, "integrator: expected cvode | substep N | none");
  }
  if (!std::strcmp(kw, "implicit_force")) {
    if (iarg + 1 >= narg) lmp->error->all(FLERR, "implicit_force: expected position | impulse | newton");
    const char *v = arg[iarg + 1];
    c.implicit_newton = false;
    if (!std::strcmp(v, "position")) { c.implicit_impulse = false; return 2; }
    if (!std::strcmp(v, "impulse")) { c.implicit_impulse = true; return 2; }
    if (!std::strcmp(v, "newton")) { c.implicit_newton = true; return 2; }
    lmp->error->all(FLERR, "implicit_force: expected position | impulse | newton");
  }
  if (!std::strcmp(kw, "friction")) { c.friction = num(1, false); return 2; }
  if (!std::strcmp(kw, "friction_stick")) {
    c.friction_stick = num(1);
    c.friction_stick_set = true;
    return 2;
  }
  if (!std::strcmp(kw, "rtol")) { c.rtol = num(1); return 2; }
  if (!std::strcmp(kw, "atol")) { c.atol = num(1); return 2; }
  if (!std::strcmp(kw, "terms")) {
    if (iarg + 1 >= narg) lmp->error->all(FLERR, "terms: expected a comma list of vdw, es, steric");
    std::string list = arg[iarg + 1];
    unsigned t = 0;
    std::size_t pos = 0;
    while (pos <= list.size()) {
      const std::size_t e = list.find(',', pos);
      const std::string w = list.substr(pos, e == std::string::npos ? std::string::npos : e - pos);
      if (w == "vdw") t |= physics::kVdw;
      else if (w == "es") t |= physics::kEs;
      else if (w == "steric") t |= physics::kSteric;
      else if (w == "none") t |= 0;
      else lmp->error->all(FLERR, error_text("terms: unknown term '" + w + "' (vdw, es, steric, none)"));
      if (e == std::string::npos) break;
      pos = e + 1;
    }
    L.terms = t;
    return 2;
  }
  if (!std::strcmp(kw, "steric_terms")) {
    if (iarg + 1 >= narg) lmp->error->all(FLERR, "steric_terms: expected a comma list of s1..s4");
    // a comma list of distinct terms s1..s4 (an unknown or repeated word is an error: 'S1,s2' once
    // switched S1 off silently)
    bool on[4] = {false, false, false, false};
    const std::string list = arg[iarg + 1];
    std::size_t pos = 0;
    while (true) {
      const std::size_t end = list.find(',', pos);
      const std::string word = list.substr(pos, end == std::string::npos ? std::string::npos : end - pos);
      const int k = (word.size() == 2 && word[0] == 's' && word[1] >= '1' && word[1] <= '4') ? word[1] - '1' : -1;
      if (k < 0 || on[k])
        lmp->error->all(FLERR, error_text(std::string(style) + ": steric_terms: '" + list +
                                          "' is not a comma list of distinct terms s1, s2, s3, s4"));
      on[k] = true;
      if (end == std::string::npos) break;
      pos = end + 1;
    }
    L.steric.s1 = on[0];
    L.steric.s2 = on[1];
    L.steric.s3 = on[2];
    L.steric.s4 = on[3];
    return 2;
  }
  if (!std::strcmp(kw, "s1_damping")) { L.steric.s1_damping = yesno(lmp, style, kw, iarg + 1, narg, arg); return 2; }
  if (!std::strcmp(kw, "hamaker")) { L.hamaker = num(1, false); return 2; }
  if (!std::strcmp(kw, "hamaker_full")) { L.full_hamaker = yesno(lmp, style, kw, iarg + 1, narg, arg); return 2; }
  if (!std::strcmp(kw, "temperature")) { L.temperature = num(1); return 2; }
  if (!std::strcmp(kw, "eps_r")) { L.eps_r = num(1); return 2; }
  if (!std::strcmp(kw, "ionic_strength")) { L.ionic_strength = num(1); return 2; }
  if (!std::strcmp(kw, "valency")) { L.valency = num(1); return 2; }
  if (!std::strcmp(kw, "psi")) { L.psi_d = num(1, false); L.use_charge = false; return 2; }
  if (!std::strcmp(kw, "sigma")) { L.sigma = num(1, false); L.use_charge = true; return 2; }
  if (!std::strcmp(kw, "h0")) { L.h0 = num(1); return 2; }
  if (!std::strcmp(kw, "h_cut")) { L.h_cut = num(1); return 2; }
  if (!std::strcmp(kw, "h_R")) { L.steric.h_R = num(1); return 2; }
  if (!std::strcmp(kw, "h_S")) { L.steric.h_S = num(1); return 2; }
  if (!std::strcmp(kw, "t_R")) { L.steric.t_R = num(1); return 2; }
  if (!std::strcmp(kw, "h_cap")) { L.steric.h_cap = num(1); return 2; }
  if (!std::strcmp(kw, "h_D")) { L.steric.h_D = num(1); return 2; }
  if (!std::strcmp(kw, "h_S4")) { L.steric.h_S4 = num(1); return 2; }
  if (!std::strcmp(kw, "section")) {
    if (iarg + 1 < narg && !std::strcmp(arg[iarg + 1], "circle")) { c.section = Section::Circle; return 2; }
    if (iarg + 1 < narg && !std::strcmp(arg[iarg + 1], "rect")) {
      c.section = Section::Rect;
      c.width = num(2);
      c.thickness = num(3);
      return 4;
    }
    lmp->error->all(FLERR, "section: expected circle | rect W T");
  }
  if (!std::strcmp(kw, "up")) {
    c.up = {num(1, false), num(2, false), num(3, false)};
    if (physics::norm(c.up) == 0) lmp->error->all(FLERR, "up: the vector must not be zero");
    c.up = (1.0 / physics::norm(c.up)) * c.up;
    return 4;
  }
  if (!std::strcmp(kw, "points")) {
    if (iarg + 1 < narg && !std::strcmp(arg[iarg + 1], "auto")) {
      c.npoints = 0;
      c.h_match = num(2);
      return 3;
    }
    if (iarg + 1 >= narg) lmp->error->all(FLERR, "points: expected N or auto H");
    c.npoints = static_cast<int>(parse_count(lmp->error, style, "points", arg[iarg + 1], 1, 100000));
    return 2;
  }
  if (!std::strcmp(kw, "self")) { c.self_contact = yesno(lmp, style, kw, iarg + 1, narg, arg); return 2; }
  if (!std::strcmp(kw, "frozen")) {
    if (iarg + 1 >= narg) lmp->error->all(FLERR, "frozen: expected a group ID");
    const int g = lmp->group->find(arg[iarg + 1]);
    if (g < 0) lmp->error->all(FLERR, error_text(std::string("frozen: unknown group ") + arg[iarg + 1]));
    c.frozen_groupbit = lmp->group->bitmask[g];
    return 2;
  }
  return 0;
}

void validate_contact_config(LAMMPS *lmp, const char *style, EngineConfig &c) {
  physics::ContactLaw &L = c.law;
  L.steric.h0 = L.h0;
  auto fail = [&](const char *m) { lmp->error->all(FLERR, error_text(std::string(style) + ": " + m)); };
  if (!(L.steric.h_R > 0 && L.steric.h_R < L.h0)) fail("h_R must satisfy 0 < h_R < h0");
  if (!(L.h_cut > L.h0)) fail("h_cut must be larger than h0");
  if (c.section == Section::Rect && !(c.width > 0 && c.thickness > 0)) fail("section rect needs W > 0 and T > 0");
  if (!(c.rtol > 0 && c.rtol < 1)) fail("rtol must be in (0, 1)");
  if (c.npoints > 100000) fail("points: at most 100000 per element");
  if (!(c.friction >= 0)) fail("friction must be >= 0");
  if (!(c.friction_stick >= 1.0 && c.friction_stick <= 1.0e6)) fail("friction_stick must be in [1, 1e6]");
  if (c.friction_stick_set && !c.implicit_newton)
    fail("friction_stick acts inside the Newton solve only: it needs implicit_force newton");
}

}  // namespace fiberform
