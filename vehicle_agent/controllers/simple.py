"""Simple: follow the plan's target speed at the vehicle's position, bounded (paper: "a
hand-designed logic-based controller that largely adheres to the Speed Planner suggestion").

On `acc` cars the speed setting is the target itself (the stock ACC keeps the gap). On `accel`
cars the stock ACC is out of the loop, so the command is the bounded target term together with
MicroAccel's safety term whenever the make measures the leader: min(a_target, a_safe).
"""

from __future__ import annotations

from contract.controllers import Actuation, SimpleParams
from contract.units import mps_to_mph
from vehicle_agent.controllers.base import (
    AccelCommand,
    AccSetPoint,
    Action,
    Controller,
    Observation,
)
from vehicle_agent.controllers.microaccel import LeadAccelEstimator, safety_term, target_accel


class SimpleController(Controller):
    """Target speed follower for both actuations."""

    name = "simple"

    def __init__(self, actuation: Actuation, params: SimpleParams) -> None:
        super().__init__(actuation)
        self.params = params
        self.lead_accel = LeadAccelEstimator(0.5)

    def reset(self) -> None:
        """Forget the leader's speed history."""
        self.lead_accel.reset()

    def step(self, observation: Observation) -> Action:
        """The target as a set point, or the bounded target acceleration."""
        params = self.params
        if self.actuation == "acc":
            requested = mps_to_mph(observation.target_speed_mps) + params.speed_offset_mph
            return AccSetPoint(round(requested), params.gap_setting, requested_speed_mph=requested)
        command = target_accel(observation.speed_mps, observation.target_speed_mps, params.k)
        if observation.has_lead_state:
            rel = float(observation.lead_rel_speed_mps)  # type: ignore[arg-type]
            lead_speed = max(observation.speed_mps + rel, 0.0)
            gap = float(observation.lead_distance_m)  # type: ignore[arg-type]
            lead_accel = self.lead_accel.update(observation.time_s, lead_speed, gap)
            safe = safety_term(
                observation.speed_mps,
                gap,
                rel,
                lead_accel,
                k=params.k,
                standstill_gap_m=params.standstill_gap_m,
                min_accel_mps2=params.safety_min_accel_mps2,
                lead_min_accel_mps2=params.lead_min_accel_mps2,
            )
            command = min(command, safe)
            return AccelCommand(
                min(max(command, params.safety_min_accel_mps2), params.max_accel_mps2)
            )
        self.lead_accel.reset()
        return AccelCommand(min(max(command, params.min_accel_mps2), params.max_accel_mps2))
