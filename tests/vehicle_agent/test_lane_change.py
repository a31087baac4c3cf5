"""Lane-change recovery: detection, significance, safety, smoothing and release, worked by hand
with the paper's h_safe = 2 s, C_safe = 4.5 s, t* = 1.32, dv* = 10.3, c = 0.75."""

from __future__ import annotations

import pytest

from contract.controllers import LaneChangeParams
from vehicle_agent.controllers import AccelCommand, Observation, build_controller
from vehicle_agent.controllers.lane_change import (
    LaneChangeRecovery,
    headway_factor,
    relative_speed_factor,
    smoothing_factor,
)
from vehicle_agent.controllers.microaccel import MicroAccelController

PARAMS = LaneChangeParams()


def following(time_s: float, gap_m: float, rel_mps: float, speed_mps: float = 20.0) -> Observation:
    return Observation(
        time_s=time_s,
        speed_mps=speed_mps,
        target_speed_mps=speed_mps,
        lead_present=True,
        lead_distance_m=gap_m,
        lead_rel_speed_mps=rel_mps,
    )


def test_headway_factor_is_near_one_beyond_h_safe() -> None:
    # tanh(1.32 * 30 / 20) = tanh(1.98)
    assert headway_factor(30.0, 20.0, 1.32) == pytest.approx(0.962587, abs=1e-6)
    assert headway_factor(40.0, 20.0, 1.32) > 0.98  # time headway = h_safe = 2 s: tanh(2.64)


def test_relative_speed_factor_is_near_zero_at_c_safe_and_continuous_at_zero() -> None:
    # TTC = 45 / 10 = 4.5 s = C_safe: 1/2 (1/2 tanh(4.5 - 10.3) + 1/2) = 4.6e-6.
    assert relative_speed_factor(-10.0, 45.0, 10.3) == pytest.approx(4.583e-6, rel=1e-3)
    # TTC = 15 s: 1/2 (1/2 tanh(4.7) + 1/2) = 0.499959.
    assert relative_speed_factor(-2.0, 30.0, 10.3) == pytest.approx(0.499959, abs=1e-6)
    # dv >= 0 as printed: 1/2 tanh(1) + 1/2.
    assert relative_speed_factor(1.0, 30.0, 10.3) == pytest.approx(0.880797, abs=1e-6)
    assert relative_speed_factor(-1e-9, 30.0, 10.3) == pytest.approx(0.5)
    assert relative_speed_factor(0.0, 30.0, 10.3) == pytest.approx(0.5)


def test_relative_speed_factor_never_decreases_with_relative_speed() -> None:
    values = [relative_speed_factor(dv / 10, 40.0, 10.3) for dv in range(-150, 50)]
    assert all(b >= a for a, b in zip(values, values[1:], strict=False))


def test_smoothing_factor_combines_both_and_stays_below_one() -> None:
    # s = 45, v = 20, dv = -1: 0.75 tanh(2.97) + 0.25 * 1/2 (1/2 tanh(34.7) + 1/2) = 0.871062
    assert smoothing_factor(45.0, 20.0, -1.0, PARAMS) == pytest.approx(0.871062, abs=1e-6)
    assert smoothing_factor(200.0, 20.0, 20.0, PARAMS) == PARAMS.max_smoothing


def test_cut_in_is_smoothed_then_released() -> None:
    recovery = LaneChangeRecovery(PARAMS)
    assert recovery.step(following(0.0, 80.0, 0.0), 0.3) == 0.3
    # A car cuts in 45 m ahead (jump of 35 m), closing at 1 m/s: TTC 45 s is safe, the base
    # command falls from 0.3 to -1.5 (jerk 18 m/s^3): u = 0.871062 * 0.3 + 0.128938 * -1.5.
    u1 = recovery.step(following(0.1, 45.0, -1.0), -1.5)
    assert recovery.active
    assert u1 == pytest.approx(0.067912, abs=1e-6)
    outputs = [u1]
    time_s, gap = 0.1, 45.0
    while recovery.active:
        time_s += 0.1
        gap -= 0.1
        previous = outputs[-1]
        alpha = smoothing_factor(gap, 20.0, -1.0, PARAMS)
        outputs.append(recovery.step(following(time_s, gap, -1.0), -1.5))
        assert outputs[-1] == pytest.approx(alpha * previous + (1 - alpha) * -1.5)
        assert time_s < 10.0
    assert abs(outputs[-1] - -1.5) <= PARAMS.epsilon_mps2
    # Released: the base command passes through unchanged.
    assert recovery.step(following(time_s + 0.1, gap - 0.1, -1.0), -1.5) == -1.5
    assert recovery.activations == 1


def test_unsafe_cut_in_passes_the_base_command_through() -> None:
    recovery = LaneChangeRecovery(PARAMS)
    recovery.step(following(0.0, 80.0, 0.0), 0.3)
    # Cut-in at 15 m closing at 5 m/s: TTC = 3 s < C_safe.
    assert recovery.step(following(0.1, 15.0, -5.0), -3.0) == -3.0
    assert not recovery.active


def test_small_jerk_is_not_significant() -> None:
    recovery = LaneChangeRecovery(PARAMS)
    recovery.step(following(0.0, 80.0, 0.0), 0.3)
    assert recovery.step(following(0.1, 60.0, 0.0), 0.25) == 0.25  # 0.5 m/s^3
    assert not recovery.active


def test_smoothing_stops_when_the_situation_turns_unsafe() -> None:
    recovery = LaneChangeRecovery(PARAMS)
    recovery.step(following(0.0, 80.0, 0.0), 0.3)
    recovery.step(following(0.1, 45.0, -1.0), -1.5)
    assert recovery.active
    # The new leader brakes hard: TTC = 44 / 12 = 3.7 s.
    assert recovery.step(following(0.2, 44.0, -12.0), -3.0) == -3.0
    assert not recovery.active


def cut_in_drive(controller_params: dict[str, object]) -> tuple[list[float], int, bool]:
    """Closed loop at 10 Hz: ego at 25 m/s on a 25 m/s target behind a leader 80 m ahead at
    25 m/s; at 1 s a car going 22 m/s cuts in 40 m ahead (TTC 13 s: a safe cut-in).
    Returns the commands, how often recovery engaged and whether it is still engaged."""
    controller = build_controller("microaccel", "accel", controller_params)
    assert isinstance(controller, MicroAccelController)
    speed, gap, lead_speed = 25.0, 80.0, 25.0
    outputs = []
    for step in range(150):
        if step == 10:
            gap, lead_speed = 40.0, 22.0
        observation = Observation(
            time_s=step * 0.1,
            speed_mps=speed,
            target_speed_mps=25.0,
            lead_present=True,
            lead_distance_m=gap,
            lead_rel_speed_mps=lead_speed - speed,
        )
        command = controller.step(observation)
        assert isinstance(command, AccelCommand)
        outputs.append(command.accel_mps2)
        speed = max(speed + command.accel_mps2 * 0.1, 0.0)
        gap += (lead_speed - speed) * 0.1
    return outputs, controller.recovery.activations, controller.recovery.active


def test_microaccel_controller_smooths_a_cut_in_and_releases() -> None:
    smoothed, activations, still_active = cut_in_drive({})
    raw, raw_activations, _ = cut_in_drive({"lane_change": {"enabled": False}})
    # Unsmoothed, the command drops from 0 to about -1.7 m/s^2 in one step (a_safe binds).
    assert raw[9] == pytest.approx(0.0)
    assert raw[10] < -1.5
    assert raw_activations == 0
    smoothed_jumps = [abs(b - a) for a, b in zip(smoothed, smoothed[1:], strict=False)]
    assert max(smoothed_jumps) < 0.3
    assert activations == 1
    assert not still_active
    assert min(smoothed) >= -3.0
