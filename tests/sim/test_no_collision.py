"""No registered controller, with any parameters the registry accepts, drives into a stopped
queue: the issue's crash (a stale plan holding 28 m/s, the queue first seen at 100 m) is handed
back to the driver, counted as a takeover, and nobody collides."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from sim.av import agent_policy
from sim.drives import drive_from_speeds
from sim.emulator.acc import SimulatedAccCar
from sim.energy import RAV4_2019
from sim.platoon import CutIns, HandBack, platoon_roles, simulate_platoon
from vehicle_agent.controllers import CONTROLLERS, TargetProfile

# Defaults, and the laziest braking each parameter model accepts.
RECKLESS: dict[str, dict[str, Any]] = {
    "simple": {
        "k": 0.01,
        "min_accel_mps2": -0.1,
        "safety_min_accel_mps2": -0.1,
        "standstill_gap_m": 0.0,
        "lead_min_accel_mps2": -0.1,
        "gap_setting": 1,
    },
    "microaccel": {
        "k": 0.01,
        "min_accel_mps2": -0.1,
        "standstill_gap_m": 0.0,
        "lead_min_accel_mps2": -0.1,
        "k2": 5.0,
        "max_accel_mps2": 4.0,
    },
    "microaccel_acc": {
        "base": {"k": 0.01, "min_accel_mps2": -0.1, "standstill_gap_m": 0.0},
        "acc_response_s": 20.0,
        "congested_gap_setting": 1,
        "free_gap_setting": 1,
    },
}


class StalePlan:
    """The plan the car holds: 28 m/s everywhere, whatever the road ahead does."""

    def profile(self, time_s: float) -> TargetProfile:
        return TargetProfile(np.array([-1e6, 1e6]), np.array([28.0, 28.0]))

    def record_ping(self, time_s: float, x_m: float, speed_mps: float) -> None:
        pass


def cases() -> list[tuple[str, str, dict[str, Any]]]:
    found = []
    for name, spec in CONTROLLERS.items():
        for actuation in sorted(spec.schema.actuations):
            found.append((name, actuation, {}))
            if name in RECKLESS:
                found.append((name, actuation, RECKLESS[name]))
    return found


def braking(from_mps: float, decel_mps2: float) -> np.ndarray:
    """Speeds at 10 Hz braking constantly from `from_mps` to a stop."""
    return np.arange(from_mps, 0.0, -decel_mps2 * 0.1)


LEADERS = {
    # the leader pulls away at 32 m/s while the stale plan holds the AV at 28; then the queue
    # forms (-4 m/s^2) far ahead of it: the AV's radar first sees it standing at 100 m
    "queue seen at 100 m": np.concatenate([np.full(600, 32.0), braking(32.0, 4.0), np.zeros(600)]),
    # the car ahead brakes as hard as tyres allow, from 28 m/s, the AV close behind
    "hard braking ahead": np.concatenate([np.full(300, 28.0), braking(28.0, 8.0), np.zeros(400)]),
}


@pytest.mark.parametrize("leader", sorted(LEADERS))
@pytest.mark.parametrize(("name", "actuation", "params"), cases())
def test_a_stopped_queue_behind_a_stale_plan(
    name: str, actuation: str, params: dict[str, Any], leader: str
) -> None:
    queue = drive_from_speeds("queue", LEADERS[leader])
    policy = agent_policy(
        name,
        actuation,
        StalePlan(),
        params,
        stock_acc=SimulatedAccCar() if actuation == "acc" else None,
    )
    run = simulate_platoon(
        queue,
        platoon_roles(humans=4, avs=1),
        [policy],
        av_max_accel=lambda v: float(RAV4_2019.max_accel_mps2(v)),
        hand_back=HandBack(),
        cut_ins=CutIns(),
    )
    assert run.collisions == 0, run.events
    assert float(np.nanmin(run.gap_m)) > 0.0
