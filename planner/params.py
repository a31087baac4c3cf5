"""Every knob of the Speed Planner, validated, and stored with each plan (plan_run.params).

Defaults: the paper gives the 60 s period and ping window and the uniform kernel; the planner's
issue (issue 4) gives 15 km/h congestion waves, the 60 mph / 4 mph bottleneck test, 4 of the
last 5 cycles, the -0.1 m/s^2 ramp and a floor, as examples; the rest are this project's choices,
checked on the real drives of ../shared/data (docs/planner.md). The buffer step is not the
paper's (an RL-designed target evaluated in a PDE-ODE model) but a closed-form stand-in.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from contract.idm import I24_IDM
from contract.units import MPS_PER_MPH, WAVE_SPEED_MPS
from contract.values import first_problem
from planner.inputs import EngagedPings


class InvalidParams(ValueError):
    """Planner parameters that make no sense; the message names the parameter."""


class PlannerParams(BaseModel):
    """Parameters of all six steps; stage variants are chosen by registry name."""

    # allow_inf_nan: 1e999 (infinity in JSON) passed every `gt=0`, and the cycles then planned
    # NaN everywhere and failed to write it
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    # Step 1 - INRIX prediction.
    predictor: str = "wave_trend"
    max_inrix_age_s: float = Field(600.0, gt=0, description="older INRIX is no estimate at all")
    inrix_history_s: float = Field(900.0, gt=0, description="how far back the history reaches")
    # INRIX scores a reading 30 (real time), 20 (real time mixed with history) or 10 (history
    # alone, no probe on the segment): a score-10 speed is the usual traffic at that hour, no
    # measurement of this morning's wave, so by default it counts as no reading at all.
    min_inrix_score: int = Field(
        20, ge=0, le=30, description="readings INRIX scored lower are ignored and counted"
    )
    min_inrix_coverage: float = Field(
        0.5,
        gt=0,
        le=1,
        description="share of the segments INRIX must have read within max_inrix_age_s",
    )
    wave_speed_mps: float = Field(
        WAVE_SPEED_MPS, ge=0, le=15, description="speed at which changes travel upstream (15 km/h)"
    )
    trend_snapshots: int = Field(
        3, ge=2, le=30, description="snapshots (the newest included) the trend is fitted over"
    )
    trend_weight: float = Field(0.5, ge=0, le=1, description="share of the trend extrapolated")
    trend_damping_s: float = Field(120.0, gt=0, description="time constant the trend fades with")

    # Step 2 - fusion with the fleet's observations.
    fuser: str = "precedence"
    ping_window_s: float = Field(60.0, gt=0, le=600)
    # An engaged car with nothing in radar range drives the plan's own target, so its pings
    # report the plan back as the traffic's speed. "all" fuses every ping (the paper's design);
    # "behind_leader" keeps an engaged car's ping only while its radar sees a leader (the
    # paper's "minicar" flag), when traffic bounds its speed (`planner.inputs.traffic_pings`).
    engaged_pings: EngagedPings = "all"
    correction_length_m: float = Field(
        100.0, ge=0, description="distance over which an observation corrects unobserved cells"
    )
    other_lane_weight: float = Field(
        0.5, ge=0, le=1, description="weight of an observation for the corridor's other lanes"
    )

    # Step 3 - forward kernel smoothing (paper eq. for the desired speed profile).
    kernel: str = "uniform"
    window_m: float = Field(1500.0, gt=0, le=20_000, description="w, the estimation window")
    quadrature_step_m: float = Field(10.0, gt=0, le=100)

    # Step 4 - bottleneck identification.
    bottleneck_finder: str = "speed_rise"
    slow_speed_mps: float = Field(60 * MPS_PER_MPH, gt=0, description="at or below: a slow region")
    min_rise_mps: float = Field(
        4 * MPS_PER_MPH, gt=0, description="rise downstream that marks a head"
    )
    rise_distance_m: float = Field(500.0, gt=0, description="downstream distance of that rise")
    standing_cycles: int = Field(5, ge=1, le=60, description="recent cycles looked at")
    standing_required: int = Field(4, ge=1, le=60, description="cycles a standing one is seen in")
    match_distance_m: float = Field(300.0, ge=0, description="same bottleneck if this close")
    # Set from SMOOTHFLEET_PLANNER_PERIOD_S by the job that schedules the planner.
    cycle_period_s: float = Field(60.0, gt=0, description="the schedule's period")

    # Step 5 - buffer design.
    buffer_designer: str = "queue_storage"
    buffer_speed_margin_mps: float = Field(2.0, ge=0, description="above the slowest queue speed")
    ramp_decel_mps2: float = Field(0.1, gt=0, le=2, description="gentle approach to the buffer")
    floor_fraction: float = Field(0.8, ge=0, le=1, description="target >= this x smoothed speed")

    # Every target: the corridor's range, its top raised by this allowance. 0 keeps targets at
    # the posted limit; the paper's fleet allowed "modest speeds in excess of the posted speed
    # limit of 70 mph", up to 73 mph (its ACC clip, eq. v_final): 3 mph = 1.34112 m/s.
    speed_limit_allowance_mps: float = Field(
        0.0,
        ge=0,
        le=5 * MPS_PER_MPH,
        description="targets may exceed the posted limit by this much",
    )

    @model_validator(mode="after")
    def _standing_within_cycles(self) -> PlannerParams:
        if self.standing_required > self.standing_cycles:
            raise ValueError(
                f"standing_required ({self.standing_required}) cannot exceed standing_cycles "
                f"({self.standing_cycles})"
            )
        return self

    @model_validator(mode="after")
    def _buffer_below_free_flow(self) -> PlannerParams:
        # a queue's slowest cell is at most slow_speed_mps, so its buffer drives at most this
        # fast; at the IDM's desired speed the lane holds no queue (density 0), and a buffer
        # there could hold none of the queue's vehicles (planner.buffers.queue_storage)
        fastest_buffer = self.slow_speed_mps + self.buffer_speed_margin_mps
        if fastest_buffer >= I24_IDM.desired_speed_mps:
            raise ValueError(
                f"slow_speed_mps + buffer_speed_margin_mps ({fastest_buffer:.1f} m/s) must be "
                f"below the IDM's desired speed ({I24_IDM.desired_speed_mps:.1f} m/s), where a "
                "lane holds no queue"
            )
        return self

    @classmethod
    def parse(cls, values: dict[str, Any] | None) -> PlannerParams:
        """Validate user-given parameters, raising InvalidParams with one line naming the field."""
        try:
            return cls.model_validate(values or {})
        except ValidationError as error:
            problem = first_problem(error)
            name = problem.where or "params"
            raise InvalidParams(f"planner parameter {name}: {problem.message}") from None

    def stored(self) -> dict[str, Any]:
        """The parameters as stored with a plan (JSON-ready)."""
        return self.model_dump(mode="json")
