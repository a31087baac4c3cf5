"""RL-ACC: the PPO-trained policy that sets the stock ACC (paper section "ACC-Based Controller").

Each control period the policy reads v, v_s (and the plan ahead), the minicar flag l and the ACC's
speed and gap settings s and g (`policy.acc_features`) and outputs a requested speed setting
around the plan's target (the clip's ceiling while no leader is detected, so the ACC closes up to
a leader it lost) and gap bars (`policy.requested_speed_mph`, `policy.requested_gap_setting`).
The registry wraps it in
the paper's clip (`AccClip`) like every `acc` controller; the agent's button sequencer realises the
set point (gap first), behind the safety layer: the output is only a request.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from contract.controllers import Actuation, RlParams
from contract.units import mps_to_mph
from vehicle_agent.controllers.base import AccSetPoint, Controller, Observation
from vehicle_agent.controllers.policy import (
    PLAN_LOOKAHEAD_M,
    PolicyFileError,
    PolicyNetwork,
    acc_features,
    load_policy,
    requested_gap_setting,
    requested_speed_mph,
)

# The policy the package ships (trained by `smoothfleet sim train`, manifest beside it).
BUNDLED_POLICIES = Path(__file__).resolve().parent / "policies"


def policy_path(params: RlParams, actuation: Actuation) -> Path:
    """The policy file the params name, or the bundled `rl_<actuation>.npz`."""
    if params.policy is not None:
        return Path(params.policy)
    return BUNDLED_POLICIES / f"rl_{actuation}.npz"


def load_assigned_policy(params: RlParams, actuation: Actuation) -> PolicyNetwork:
    """The policy the params name, refused (PolicyFileError) when its sha256 is not the
    `policy_sha256` they name: a car never runs a policy other than the one assigned."""
    path = policy_path(params, actuation)
    network = load_policy(path, actuation)
    if params.policy_sha256 is not None and network.sha256 != params.policy_sha256:
        raise PolicyFileError(
            str(path), f"sha256 {network.sha256}, the assignment names {params.policy_sha256}"
        )
    return network


def plan_ahead_mps(observation: Observation) -> float:
    """The plan's target PLAN_LOOKAHEAD_M ahead (the target here when the plan is not held)."""
    if observation.target is None or observation.position_m is None:
        return observation.target_speed_mps
    return observation.target.at(observation.position_m + PLAN_LOOKAHEAD_M)


class RlAccController(Controller):
    """The trained policy's speed setting and gap bars (actuation `acc`)."""

    name = "rl_acc"

    def __init__(self, actuation: Actuation, params: RlParams) -> None:
        super().__init__(actuation)
        self.network = load_assigned_policy(params, "acc")

    @property
    def policy_sha256(self) -> str:
        """The sha256 of the policy file evaluated."""
        return self.network.sha256

    def step(self, observation: Observation) -> AccSetPoint:
        """Features -> network -> set point (before the registry's clip)."""
        speed_mph = mps_to_mph(observation.speed_mps)
        setting = observation.acc_speed_setting_mph
        gap = observation.acc_gap_setting
        features = acc_features(
            observation.speed_mps,
            observation.target_speed_mps,
            plan_ahead_mps(observation),
            observation.lead_present,
            speed_mph if setting is None else setting,
            3 if gap is None else gap,
        )
        action = self.network.action(features)
        requested = float(
            requested_speed_mph(
                action[0], mps_to_mph(observation.target_speed_mps), observation.lead_present
            )
        )
        bars = int(requested_gap_setting(action[1]))
        if not np.isfinite(requested):
            raise ValueError(f"policy {self.network.sha256[:12]} gave a non-finite speed")
        return AccSetPoint(round(requested), bars, requested_speed_mph=requested)
