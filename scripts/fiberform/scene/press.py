# SPDX-License-Identifier: GPL-3.0-or-later
"""Section of the ``press`` stage."""

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from ._fields import _Section, choice, quantity, scene_problem


class PressSection(_Section):
    """Pressing of the laid-down sheet by a rigid horizontal plate (stage ``press``, thesis sec.
    3.5): quiescent water (drag stays), static yarns, the plate under the fiber/dlvo law."""

    mode: Literal["velocity", "pressure"] = choice(
        "velocity: the plate moves down at plate_speed_m_s until the plate-to-fabric distance is "
        "target_thickness_m, then rests for hold_time_s (thesis sec. 3.5); pressure: a servo "
        "drives the plate so that the contact pressure follows a ramp to target_pressure_Pa at "
        "pressure_rate_Pa_s, a hold of hold_time_s, an unloading at the same rate and a release "
        "of release_time_s at zero pressure (spring-back)",
        default="pressure",
    )
    timestep_s: float | None = quantity(
        "Fiber (DEM) time step of the press (absent: laydown.timestep_s)", "s", default=None,
        gt=0.0, le=1e-3,
    )  # fmt: skip
    output_interval_s: float = quantity(
        "Simulated time between sheet snapshots, curve points and overlap-guard checks", "s",
        default=1.0e-4, gt=0.0, le=1.0,
    )  # fmt: skip
    plate_start_gap_m: float = quantity(
        "Gap between the plate and the highest fiber surface of the laid-down sheet at the start",
        "m", default=5.0e-6, gt=0.0, le=1e-3,
    )  # fmt: skip
    plate_speed_m_s: float = quantity(
        "velocity mode: the plate speed; pressure mode: the servo's speed limit (also the speed "
        "of the approach before the first contact)", "m/s", default=5.0e-3, gt=0.0, le=10.0,
    )  # fmt: skip
    target_thickness_m: float | None = quantity(
        "velocity mode (required): the plate stops at this distance above the fabric top (the "
        "highest point of the yarns; in both modes the plate never passes the fabric top)", "m",
        default=None, gt=0.0, le=1e-2,
    )  # fmt: skip
    target_pressure_Pa: float | None = quantity(
        "pressure mode (required): the pressure held (plate force / plate area, the domain's "
        "x-y cross-section)", "Pa", default=None, gt=0.0, le=1e9,
    )  # fmt: skip
    pressure_rate_Pa_s: float | None = quantity(
        "pressure mode: loading and unloading rate (absent: target_pressure_Pa per 1 ms)", "Pa/s",
        default=None, gt=0.0, le=1e15,
    )  # fmt: skip
    hold_time_s: float = quantity(
        "Time the plate holds its target position (velocity) or pressure (pressure)", "s",
        default=1.0e-3, ge=0.0, le=10.0,
    )  # fmt: skip
    release_time_s: float = quantity(
        "pressure mode: time at zero target pressure after unloading, while the sheet springs "
        "back (the servo keeps the plate at zero contact force)", "s", default=1.0e-3, ge=0.0,
        le=10.0,
    )  # fmt: skip
    servo_band_Pa: float | None = quantity(
        "pressure mode: the servo's proportional band p_ref: the plate moves at the full speed "
        "limit when the pressure is this far from its target (absent: 0.1 x target_pressure_Pa)",
        "Pa", default=None, gt=0.0, le=1e9,
    )  # fmt: skip
    overlap_limit: float = quantity(
        "Overlap guard: the press stops (exit status 1) when it has pushed an element into another "
        "fiber, a yarn or the plate by more than this fraction of the thinner fiber's thickness "
        "(beyond the overlaps the lay-down left)", "1",
        default=0.2, gt=0.0, le=1.0,
    )  # fmt: skip
    overlap_action: Literal["fail", "stop"] = choice(
        "What the overlap guard does when it trips: fail (the stage ends with exit status 1) or "
        "stop (the press ends there and the sheet of that moment is the pressed sheet, its plate "
        "thickness recorded as the thickness reached; thesis sec. 4.2: circular-section sheets "
        "could not be pressed to the experimental thickness, so their pressing was stopped earlier)",
        default="fail",
    )
    steric_cap_m: float | None = quantity(
        "Saturation h_cap of the steric servo's position error (term S1) in every contact of the "
        "press (fibers, yarns, side planes, plate). The thesis' S1 (eq. 2.35) is not saturated; "
        "this implementation saturates it at h_cap (docs/models/contact.md section 3), which "
        "limits the load one contact carries to 2 mu h_cap / t_R^2, about 1e-5 N at the law's "
        "2 nm: a press pushes fibers into each other beyond that. A larger value lets the "
        "contacts carry the plate's load (docs/stages/press.md, 'Load per contact'); absent: the "
        "lay-down's laydown.steric_cap_m, or the law's 2 nm when that is absent too", "m",
        default=None, ge=1e-9, le=1e-4,
    )  # fmt: skip
    restart_interval_s: float = quantity(
        "Simulated time between LIGGGHTS restart files of the press (rounded to whole "
        "output_interval_s; `fiberform press SCENE --resume` continues a killed press from the last "
        "one; 0: none)", "s", default=1.0e-3, ge=0.0, le=1e3, hashed_at_default=False,
    )  # fmt: skip
    ranks: int = quantity(
        "MPI ranks of the press (> 1 needs laydown.yarn_contact newton)", "1", default=1, ge=1,
        le=100000,
    )  # fmt: skip

    @model_validator(mode="after")
    def _check(self) -> PressSection:
        if 0.0 < self.restart_interval_s < self.output_interval_s:
            raise scene_problem("restart_interval_s", "must be 0 or at least output_interval_s",
                                self.restart_interval_s)
        if self.mode == "velocity":
            if self.target_thickness_m is None:
                raise scene_problem("target_thickness_m", "required with mode velocity", None)
            for name in ("target_pressure_Pa", "pressure_rate_Pa_s", "servo_band_Pa"):
                if getattr(self, name) is not None:
                    raise scene_problem(name, "only used with mode pressure", getattr(self, name))
            if "release_time_s" in self.model_fields_set:
                raise scene_problem("release_time_s", "only used with mode pressure",
                                    self.release_time_s)
        else:
            if self.target_pressure_Pa is None:
                raise scene_problem("target_pressure_Pa", "required with mode pressure", None)
            if self.target_thickness_m is not None:
                raise scene_problem("target_thickness_m", "only used with mode velocity",
                                    self.target_thickness_m)
        return self

    @property
    def rate(self) -> float:
        """The loading/unloading rate (Pa/s) with its default resolved (pressure mode)."""
        assert self.target_pressure_Pa is not None
        return (self.pressure_rate_Pa_s if self.pressure_rate_Pa_s is not None
                else self.target_pressure_Pa / 1.0e-3)

    @property
    def band(self) -> float:
        """The servo band p_ref (Pa) with its default resolved (pressure mode)."""
        assert self.target_pressure_Pa is not None
        return self.servo_band_Pa if self.servo_band_Pa is not None else 0.1 * self.target_pressure_Pa
