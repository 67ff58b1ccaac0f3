# SPDX-License-Identifier: GPL-3.0-or-later
"""Section of the ``laydown`` stage."""

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from ._fields import _Section, choice, quantity, scene_problem
from .common import ContactTerm


class LaydownSection(_Section):
    """Lay-down of the generated fibers on the fabric in the frozen flow (stage ``laydown``)."""

    timestep_s: float = quantity("Fiber (DEM) time step", "s", default=1.0e-7, gt=0.0, le=1e-3)
    max_time_s: float = quantity(
        "Longest simulated time (the run ends earlier once settled)", "s", default=0.02,
        gt=0.0, le=10.0,
    )  # fmt: skip
    check_interval_s: float = quantity(
        "Simulated time between settle checks and sheet snapshots", "s", default=2.0e-4,
        gt=0.0, le=1.0,
    )  # fmt: skip
    settle_speed_m_s: float = quantity(
        "Settled when the largest node speed stays below this", "m/s", default=2.0e-3,
        gt=0.0, le=10.0,
    )  # fmt: skip
    settle_speed_fraction: float | None = quantity(
        "Settle threshold relative to the superficial velocity of the flow stage (replaces "
        "settle_speed_m_s when given)", "1", default=None, gt=0.0, le=10.0,
    )  # fmt: skip
    settle_measure: Literal["node", "fiber"] = choice(
        "Speed the settle criterion tests: node (largest node speed) or fiber (largest fiber "
        "centre-of-mass speed; free fiber ends fluttering in the flow do not count)",
        default="node",
    )
    settle_mass_fraction: float = quantity(
        "With settle_measure fiber: the fibers carrying this fraction of the mass must be slower "
        "than the threshold (the rest, e.g. a few fines fluttering in the flow, is ignored; 1: "
        "every fiber)", "1", default=1.0, gt=0.0, le=1.0,
    )  # fmt: skip
    settle_checks: int = quantity(
        "Consecutive checks below settle_speed_m_s that end the run", "1", default=5, ge=1,
        le=10000,
    )  # fmt: skip
    removal_height_m: float | None = quantity(
        "Fibers with a node below this height are removed (absent: fabric lower side - 50 um)",
        "m", default=None, ge=-10.0, le=10.0,
    )  # fmt: skip
    walls: Literal["fiber_yarns", "wall_fiber_dlvo", "wall_gran", "periodic"] = choice(
        "The lateral boundaries: four vertical side planes, fiber_yarns (fix wall/fiber/dlvo acting "
        "as the yarns do: their law terms, yarn_contact mode and friction), wall_fiber_dlvo (fix "
        "wall/fiber/dlvo with the law terms and contact integrator only) or wall_gran "
        "(stock LIGGGHTS fix wall/gran, Hertz, frictionless; for comparisons); or periodic: no side "
        "planes, the box is periodic in x and y, the fabric's yarns tiled over the neighbouring "
        "periodic images (needs a generated fabric of whole weave repeats, yarn_contact newton and "
        "coupling one_way; the frozen flow is not periodic at the box sides)",
        default="fiber_yarns",
    )
    terms: list[ContactTerm] = choice(
        "Terms of the fiber/dlvo law against yarns and walls (default: the thesis' law, van der "
        "Waals, electrostatics and steric repulsion, with the style's cited parameters for "
        "cellulose in process water; fewer terms are a speed option)",
        default=["vdw", "es", "steric"],
    )
    friction_coefficient: float = quantity(
        "Coulomb friction coefficient of fibers on yarns and fiber_yarns side planes (keyword "
        "friction of fix wall/fiber/yarns and fix wall/fiber/dlvo; 0: frictionless as the "
        "fiber/dlvo law)", "1", default=0.0,
        ge=0.0, le=10.0,
    )  # fmt: skip
    fiber_friction_coefficient: float = quantity(
        "Coulomb friction coefficient between fibers (keyword friction of pair_style fiber/dlvo, "
        "regularised as on the yarns, with friction_stick; needs fiber_contact newton). 0: "
        "frictionless, the thesis' law (sec. 2.4); > 0 departs from it (docs/models/contact.md "
        "section 9)", "1", default=0.0, ge=0.0, le=10.0, hashed_at_default=False,
    )  # fmt: skip
    friction_stick: float = quantity(
        "Stick damping factor k of the regularised friction inside the Newton solve (keyword "
        "friction_stick of fix wall/fiber/yarns, fix wall/fiber/dlvo and pair_style fiber/dlvo): "
        "a stuck contact point creeps at F_t / c_stick, c_stick = k m_eff / timestep_s. Smaller is "
        "a speed option (fewer Newton iterations, faster creep; docs/bench/laydown.md); only with "
        "yarn_contact newton and friction_coefficient > 0, or with fiber_friction_coefficient > 0",
        "1", default=100.0, ge=1.0, le=1.0e4,
    )  # fmt: skip
    contact_integrator: Literal["cvode", "substep"] = choice(
        "Sub-integration of each fiber-yarn and fiber-wall contact: cvode (as pair_style "
        "fiber/dlvo, the thesis' method) or substep (contact_substeps velocity-Verlet sub-steps)",
        default="cvode",
    )
    contact_substeps: int = quantity(
        "Velocity-Verlet sub-steps per step of each yarn/wall contact with contact_integrator "
        "substep (rejected with cvode)", "1", default=100, ge=1, le=100000,
    )  # fmt: skip
    restart_interval_s: float = quantity(
        "Simulated time between LIGGGHTS restart files of the lay-down (rounded to whole checks; "
        "`fiberform laydown SCENE --resume` continues a killed run from the last one; 0: none)",
        "s", default=5.0e-3, ge=0.0, le=1e3,
    )  # fmt: skip
    ranks: int = quantity(
        "MPI ranks of the lay-down (> 1 needs yarn_contact newton; at most the machine's cores "
        "unless --oversubscribe)", "1", default=1, ge=1, le=100000,
    )  # fmt: skip
    yarn_contact: Literal["newton", "averaged"] | None = choice(
        "How yarns and the fiber_yarns side planes act on implicit fibers: newton (the law inside "
        "each fiber's Newton solve, PD steric servo; docs/models/contact.md section 8) or averaged "
        "(the contact point sub-integrated with contact_integrator, its impulse handed to the step). "
        "Absent: newton with beam_integrator implicit, averaged with explicit",
        default=None,
    )
    fiber_contact: Literal["newton", "averaged"] | None = choice(
        "How fibers act on each other (contact section, pair_style fiber/dlvo): newton (fibers "
        "that may touch during a step are solved together in one Newton solve with the law inside; "
        "docs/models/contact.md section 9) or averaged (each contact point pair sub-integrated with "
        "contact.integrator, the averaged force handed to each fiber's step). Absent: newton with "
        "beam_integrator implicit, averaged with explicit",
        default=None,
    )
    inertia_scale: float = quantity(
        "fix fiber/beam inertia_scale (rotary inertia factor; speed option, 1 = real inertia)", "1",
        default=1.0, gt=0.0, le=1e8,
    )  # fmt: skip
    stiffness_scale: float = quantity(
        "fix fiber/beam stiffness_scale (EA, GA factor; speed option, 1 = real stiffness)", "1",
        default=1.0, gt=0.0, le=1.0,
    )  # fmt: skip
    beam_integrator: Literal["implicit", "explicit"] = choice(
        "fix fiber/beam integrator: implicit (generalized-alpha per fiber, steps set by accuracy; "
        "thesis sec. 2.2) or explicit (velocity Verlet below the critical step; comparison)",
        default="implicit",
    )
    rho_inf: float = quantity(
        "fix fiber/beam rho_inf: numerical dissipation of the implicit integrator (spectral "
        "radius at infinite frequency; 1 = none)", "1", default=0.5, ge=0.0, le=1.0,
    )  # fmt: skip
    newton_tolerance: float = quantity(
        "fix fiber/beam newton_tol: implicit convergence tolerance (translations relative to the "
        "section radius, rotations in rad)", "1", default=1.0e-8, gt=0.0, le=1e-2,
    )  # fmt: skip
    newton_max_iterations: int = quantity(
        "fix fiber/beam newton_max: Newton iterations per implicit step before it is split",
        "1", default=25, ge=1, le=1000,
    )  # fmt: skip
    tangent_steps: int = quantity(
        "fix fiber/beam tangent_steps: steps a fiber's factored Newton tangent may be reused (1: "
        "a new one every step, so a resumed lay-down equals an uninterrupted one exactly; more: "
        "faster, but a resumed run differs at the level of the Newton tolerance, as restart "
        "files do not hold the tangents)", "1", default=1, ge=1, le=100000,
    )  # fmt: skip
    anderson_depth: int = quantity(
        "fix fiber/beam anderson: Anderson mixing of the implicit Newton corrections over this many "
        "earlier ones (0: off; the convergence test is unchanged, so the sheet differs at the level "
        "of the Newton tolerance; docs/bench/laydown.md measures the speed-up)", "1", default=0, ge=0, le=8,
    )  # fmt: skip
    steric_cap_m: float | None = quantity(
        "Saturation h_cap of the steric servo's position error (term S1) in every contact of the "
        "lay-down (fibers, yarns, side planes), as press.steric_cap_m: the thesis' S1 (eq. 2.35) "
        "is not saturated; this implementation saturates it at h_cap (docs/models/contact.md "
        "section 3), which limits the load one contact carries to 2 mu h_cap / t_R^2, about "
        "1e-5 N at the law's 2 nm for a fiber node. Under a high-mass pile-up that is exceeded: a "
        "fiber end pressed into a yarn or another fiber (docs/validation/table41.md, case C seed "
        "2). Absent: the law's 2 nm. The press uses this value when press.steric_cap_m is absent",
        "m", default=None, ge=1e-9, le=1e-4,
    )  # fmt: skip
    split_memory_steps: int = quantity(
        "fix fiber/beam split_memory: a fiber (or contact cluster) whose implicit step had to be "
        "split starts its next steps split as deep, and tries one level coarser after this many "
        "steps that needed no deeper split (0: off, every step starts whole and pays the failed "
        "attempts first). Sub-steps are never longer than without it, so the accuracy is not "
        "reduced; the trajectory differs at the level of the step's time-discretisation error. "
        "docs/stages/press.md measures the cost under load", "1", default=0, ge=0, le=1000000,
    )  # fmt: skip
    newton_landing: Literal["limit", "predict"] = choice(
        "fix fiber/beam landing: a Newton correction that would carry contacts from outside to deep "
        "inside is shortened so that the first of them lands (limit), or solved again with those "
        "contacts' forces linearised about their landing gap, so that several land in one iteration "
        "(predict; the convergence test is unchanged; docs/bench/laydown.md measures the speed-up)",
        default="limit",
    )
    damping_time_s: float = quantity(
        "fix fiber/beam Kelvin-Voigt damping time", "s", default=0.0, ge=0.0, le=1.0
    )

    @model_validator(mode="after")
    def _check(self) -> LaydownSection:
        if self.settle_mass_fraction != 1.0 and self.settle_measure != "fiber":
            raise scene_problem("settle_mass_fraction", "only used with settle_measure fiber",
                                self.settle_mass_fraction)
        if self.timestep_s > self.check_interval_s:
            raise scene_problem("check_interval_s", "must be at least timestep_s",
                                self.check_interval_s)
        if self.check_interval_s > self.max_time_s:
            raise scene_problem("check_interval_s", "must not exceed max_time_s",
                                self.check_interval_s)
        if not self.terms:
            raise scene_problem("terms", "needs at least one of vdw, es, steric", [])
        if self.contact_integrator == "cvode" and "contact_substeps" in self.model_fields_set:
            raise scene_problem("contact_substeps", "only used with contact_integrator substep",
                                self.contact_substeps)
        if "friction_stick" in self.model_fields_set and not self.fiber_friction_coefficient > 0.0 and (
                self.yarn_contact_mode != "newton" or self.friction_coefficient == 0.0):
            raise scene_problem("friction_stick", "only used with yarn_contact newton and "
                                "friction_coefficient > 0, or with fiber_friction_coefficient > 0",
                                self.friction_stick)
        if self.fiber_friction_coefficient > 0.0 and self.fiber_contact_mode != "newton":
            raise scene_problem("fiber_friction_coefficient", "friction between fibers needs "
                                "fiber_contact newton (0 with averaged)",
                                self.fiber_friction_coefficient)
        if self.ranks > 1 and self.yarn_contact_mode != "newton":
            raise scene_problem("ranks", "more than one rank needs yarn_contact newton (the "
                                "sub-integrated yarn contact needs both nodes of an element on one "
                                "rank)", self.ranks)
        if 0.0 < self.restart_interval_s < self.check_interval_s:
            raise scene_problem("restart_interval_s", "must be 0 or at least check_interval_s",
                                self.restart_interval_s)
        if self.yarn_contact == "newton" and self.beam_integrator == "explicit":
            raise scene_problem("yarn_contact", "newton needs beam_integrator implicit (allowed "
                                "with explicit: averaged)", self.yarn_contact)
        if self.anderson_depth > 0 and self.beam_integrator == "explicit":
            raise scene_problem("anderson_depth", "only used with beam_integrator implicit (the "
                                "Newton solve it accelerates)", self.anderson_depth)
        if self.newton_landing != "limit" and self.beam_integrator == "explicit":
            raise scene_problem("newton_landing", "only used with beam_integrator implicit (the "
                                "Newton solve it accelerates)", self.newton_landing)
        if self.fiber_contact == "newton" and self.beam_integrator == "explicit":
            raise scene_problem("fiber_contact", "newton needs beam_integrator implicit (allowed "
                                "with explicit: averaged)", self.fiber_contact)
        if self.walls == "periodic" and self.yarn_contact_mode != "newton":
            raise scene_problem("yarn_contact", "walls periodic needs yarn_contact newton (the "
                                "averaged yarn contact needs both nodes of an element in one "
                                "periodic image; with beam_integrator explicit yarn_contact is "
                                "averaged)", self.yarn_contact_mode)
        if (self.yarn_contact_mode == "newton" and self.walls != "wall_fiber_dlvo"
                and "contact_integrator" in self.model_fields_set):
            raise scene_problem("contact_integrator", "only used with yarn_contact averaged or "
                                "walls wall_fiber_dlvo (yarn_contact newton solves the contacts "
                                "inside the fiber step)", self.contact_integrator)
        return self

    @property
    def fiber_contact_mode(self) -> str:
        """fiber_contact with its default resolved: newton (implicit) or averaged (explicit)."""
        if self.fiber_contact is not None:
            return self.fiber_contact
        return "newton" if self.beam_integrator == "implicit" else "averaged"

    @property
    def yarn_contact_mode(self) -> str:
        """yarn_contact with its default resolved: newton (implicit) or averaged (explicit)."""
        if self.yarn_contact is not None:
            return self.yarn_contact
        return "newton" if self.beam_integrator == "implicit" else "averaged"
