"""MicroAccel with its output turned into ACC set points (paper, "Candidate Controller Selection":
"the main controller described in Acceleration-Based Controller with modifications to output ACC
set points").

The acceleration the car should make is MicroAccel's a_cmd = min(a_safe, a_target, a_MPC) (the
leader terms only where the make measures the leader) and one more anticipation term built from
the plan instead of the leader, since the ACC cars see no space gap (paper Table 2): the constant
deceleration that brings the car from v to the target v_ahead found `lookahead_s` ahead,
    a_ahead = (v_ahead^2 - v^2) / (2 D)   when v_ahead < v   (D: distance to that point),
the same kinematics as a_MPC's a_lead - (v - v_lead)^2 / (2 (h - s0)) with the plan's slow zone as
the "leader". The stock ACC tracks its speed setting in speed-control mode roughly like a first
order lag, so a setting of v + a tau asks it for about a: tau = `acc_response_s`, and k tau = 1
makes the setting equal the target when only the target term acts.

Gap bars: the widest gap (the paper's ~2.0 s) while a slowdown lies ahead, so the car opens space
instead of braking with the wave; `free_gap_setting` otherwise. A gap change waits
`gap_dwell_s` after the previous one so the bars do not flap (each change is a button press).
"""

from __future__ import annotations

from contract.controllers import (
    Actuation,
    MicroAccelAccParams,
)
from contract.units import mps_to_mph
from vehicle_agent.controllers.base import AccSetPoint, Controller, Observation
from vehicle_agent.controllers.microaccel import LeadAccelEstimator, base_accel


def ahead_accel(speed_mps: float, ahead_speed_mps: float, distance_m: float) -> float:
    """a_ahead = (v_ahead^2 - v^2) / (2 D) when the plan ahead is slower, else no constraint."""
    if ahead_speed_mps >= speed_mps or distance_m <= 0.0:
        return float("inf")
    return (ahead_speed_mps**2 - speed_mps**2) / (2.0 * distance_m)


class MicroAccelAccController(Controller):
    """MicroAccel anticipation realised as a speed setting and gap bars (actuation `acc`)."""

    name = "microaccel_acc"

    def __init__(self, actuation: Actuation, params: MicroAccelAccParams) -> None:
        super().__init__(actuation)
        self.params = params
        self.lead_accel = LeadAccelEstimator(params.base.lead_accel_filter_s)
        self.reset()

    def reset(self) -> None:
        """Forget the leader and when the gap last changed."""
        self.lead_accel.reset()
        self._gap: int | None = None
        self._gap_changed_s = float("-inf")

    def desired_accel(self, observation: Observation) -> tuple[float, bool]:
        """The acceleration to ask of the ACC, and whether a slowdown lies ahead."""
        params = self.params
        speed = observation.speed_mps
        lead_accel = 0.0
        if observation.has_lead_state:
            lead_speed = speed + float(observation.lead_rel_speed_mps)  # type: ignore[arg-type]
            gap = float(observation.lead_distance_m)  # type: ignore[arg-type]
            lead_accel = self.lead_accel.update(observation.time_s, lead_speed, gap)
        else:
            self.lead_accel.reset()
        command = base_accel(observation, lead_accel, params.base)
        slowdown = False
        if observation.target is not None and observation.position_m is not None:
            distance = max(speed * params.lookahead_s, params.min_lookahead_m)
            ahead_speed = observation.target.at(observation.position_m + distance)
            anticipation = ahead_accel(speed, ahead_speed, distance)
            command = min(command, max(anticipation, params.base.min_accel_mps2))
            slowdown = (
                ahead_speed < speed - params.slowdown_mps
                or anticipation <= params.slowdown_accel_mps2
            )
        return command, slowdown

    def step(self, observation: Observation) -> AccSetPoint:
        """Speed setting v + a tau (mph) and the gap bars."""
        params = self.params
        command, slowdown = self.desired_accel(observation)
        requested = mps_to_mph(observation.speed_mps + command * params.acc_response_s)
        wanted_gap = params.congested_gap_setting if slowdown else params.free_gap_setting
        if self._gap is None:
            self._gap = observation.acc_gap_setting or wanted_gap
        if wanted_gap != self._gap and (
            observation.time_s - self._gap_changed_s >= params.gap_dwell_s
        ):
            self._gap = wanted_gap
            self._gap_changed_s = observation.time_s
        return AccSetPoint(round(requested), self._gap, requested_speed_mph=requested)
