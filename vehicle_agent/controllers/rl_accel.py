"""RL-Accel: the PPO-trained policy's acceleration request, for cars that take one (RAV4).

The policy reads v, v_s (and the plan ahead), the minicar flag and, as the RAV4 measures them
(paper Table 2), the space gap and the leader's relative speed (`policy.accel_features`); a
policy trained on the `commanded_accel` observation also the acceleration the agent's limiter
last let through, which the agent puts in every observation. Its
request is bounded by MicroAccel's safety term a_safe (paper eq. a_safe: never faster than the
speed from which braking at a_min stops behind a leader braking at a_l,min), the same bound the
training environment applies, then by the agent's limiter and safety layer like every request.
A policy trained with the `request_time_margin` action also sets a time margin the bound adds
to its gap (`policy.requested_time_margin_s`): the network moves the bound, not only its
request under it, and the bound with no margin still caps the command.
"""

from __future__ import annotations

import math

from contract.controllers import Actuation, MicroAccelParams, RlParams
from vehicle_agent.controllers.base import AccelCommand, Controller, Observation
from vehicle_agent.controllers.microaccel import LeadAccelEstimator, safety_term
from vehicle_agent.controllers.policy import (
    ACCEL_ACTION_MAX_MPS2,
    ACCEL_ACTION_MIN_MPS2,
    accel_features,
    requested_accel_mps2,
    requested_time_margin_s,
)
from vehicle_agent.controllers.rl_acc import load_assigned_policy, plan_ahead_mps

# The safety term's gains and limits: MicroAccel's defaults but the standstill distance. Its
# default 5 m lets a policy riding the bound close to 7 m at 5 m/s and below it when slower,
# outside the gap envelope the AV is judged against (`sim.gaps.GapBounds`: 7 m minimum); 8 m,
# the envelope's minimum and 1 m of margin, keeps the bound's gap above 7 m at every speed.
SAFETY = MicroAccelParams(standstill_gap_m=8.0)


def _safe_accel(speed_mps: float, gap_m: float, rel_speed_mps: float, lead_accel: float) -> float:
    return safety_term(
        speed_mps,
        gap_m,
        rel_speed_mps,
        lead_accel,
        k=SAFETY.k,
        standstill_gap_m=SAFETY.standstill_gap_m,
        min_accel_mps2=SAFETY.min_accel_mps2,
        lead_min_accel_mps2=SAFETY.lead_min_accel_mps2,
    )


def bounded_request(
    request_mps2: float,
    speed_mps: float,
    gap_m: float | None,
    rel_speed_mps: float | None,
    lead_accel_mps2: float,
    time_margin_s: float = 0.0,
) -> float:
    """min(request, a_safe(gap - h v), a_safe(gap)) within the action bounds, h the time margin;
    without a measured leader, the request.

    The margin's term is a_safe seen from h v further back: the speed it allows falls as the
    margin grows, and the unmargined term keeps the command under the bound a policy without a
    margin has, whatever the margin's bound does in its rate term.
    """
    command = request_mps2
    if gap_m is not None and rel_speed_mps is not None:
        command = min(command, _safe_accel(speed_mps, gap_m, rel_speed_mps, lead_accel_mps2))
        if time_margin_s > 0.0:
            margined_gap = gap_m - time_margin_s * speed_mps
            command = min(
                command, _safe_accel(speed_mps, margined_gap, rel_speed_mps, lead_accel_mps2)
            )
    return min(max(command, ACCEL_ACTION_MIN_MPS2), ACCEL_ACTION_MAX_MPS2)


class RlAccelController(Controller):
    """The trained policy's acceleration, bounded by a_safe (actuation `accel`)."""

    name = "rl_accel"

    def __init__(self, actuation: Actuation, params: RlParams) -> None:
        super().__init__(actuation)
        self.network = load_assigned_policy(params, "accel")
        self.lead_accel = LeadAccelEstimator(SAFETY.lead_accel_filter_s)

    @property
    def policy_sha256(self) -> str:
        """The sha256 of the policy file evaluated."""
        return self.network.sha256

    def reset(self) -> None:
        """Forget the leader's speed history."""
        self.lead_accel.reset()

    def step(self, observation: Observation) -> AccelCommand:
        """Features -> network -> request (and margin) -> min with a_safe."""
        gap: float | None = None
        rel: float | None = None
        lead_accel = 0.0
        if observation.has_lead_state:
            gap = float(observation.lead_distance_m)  # type: ignore[arg-type]
            rel = float(observation.lead_rel_speed_mps)  # type: ignore[arg-type]
            lead_accel = self.lead_accel.update(
                observation.time_s, observation.speed_mps + rel, gap
            )
        else:
            self.lead_accel.reset()
        commanded: float | None = None
        if self.network.accel_observation == "commanded_accel":
            commanded = observation.commanded_accel_mps2
            if commanded is None:
                raise ValueError(
                    f"policy {self.network.sha256[:12]} reads the commanded acceleration, "
                    "which this observation does not carry"
                )
        features = accel_features(
            observation.speed_mps,
            observation.target_speed_mps,
            plan_ahead_mps(observation),
            gap is not None,
            math.inf if gap is None else gap,
            0.0 if rel is None else rel,
            commanded,
        )
        action = self.network.action(features)
        request = float(requested_accel_mps2(action[0]))
        margin = 0.0
        if self.network.accel_action == "request_time_margin":
            margin = float(requested_time_margin_s(action[1]))
        command = bounded_request(request, observation.speed_mps, gap, rel, lead_accel, margin)
        if not math.isfinite(command):
            raise ValueError(f"policy {self.network.sha256[:12]} gave a non-finite request")
        return AccelCommand(command, requested_accel_mps2=request, time_margin_s=margin)
