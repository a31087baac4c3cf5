"""MicroAccel's terms against values worked by hand from the paper's equations.

Parameters used throughout unless a test says otherwise: k = 0.5 1/s, s0 = 5 m, a_min = -3 m/s^2,
a_l,min = -5 m/s^2, k2 = 0.2, a_max = 1.5 m/s^2.
"""

from __future__ import annotations

import math

import pytest

from contract.controllers import MicroAccelParams
from vehicle_agent.controllers import AccelCommand, Observation, build_controller
from vehicle_agent.controllers.microaccel import (
    anticipation_accel,
    base_accel,
    min_brake_accel,
    safe_speed,
    safe_speed_rate,
    safety_accel,
    target_accel,
)

PARAMS = MicroAccelParams()
LIMITS = {"standstill_gap_m": 5.0, "k2": 0.2, "max_accel_mps2": 1.5}


def test_safe_speed_stops_behind_a_hard_braking_leader() -> None:
    # h = 30, v_lead = 20: room = 30 - 5 + 0.5 * 20^2 / 5 = 65; v_safe = sqrt(2 * 3 * 65).
    v_safe = safe_speed(
        30.0, 20.0, standstill_gap_m=5.0, min_accel_mps2=-3.0, lead_min_accel_mps2=-5.0
    )
    assert v_safe == pytest.approx(math.sqrt(390.0))
    assert v_safe == pytest.approx(19.748418, abs=1e-6)


def test_safe_speed_is_zero_inside_the_standstill_gap() -> None:
    assert (
        safe_speed(2.0, 0.0, standstill_gap_m=5.0, min_accel_mps2=-3, lead_min_accel_mps2=-5) == 0
    )


def test_safety_term_with_its_time_derivative() -> None:
    # v = 22, v_lead = 20 (dv = -2), a_lead = -1, v_safe = sqrt(390):
    # dv_safe/dt = |a_min| (dv + v_lead a_lead / |a_l,min|) / v_safe = 3 (-2 - 4) / 19.748418
    rate = safe_speed_rate(
        math.sqrt(390.0), -2.0, 20.0, -1.0, min_accel_mps2=-3.0, lead_min_accel_mps2=-5.0
    )
    assert rate == pytest.approx(-0.911465, abs=1e-6)
    # a_safe = -0.5 (22 - 19.748418) - 0.911465
    assert safety_accel(22.0, math.sqrt(390.0), rate, 0.5) == pytest.approx(-2.037257, abs=1e-6)


def test_target_term() -> None:
    assert target_accel(22.0, 25.0, 0.5) == pytest.approx(1.5)
    assert target_accel(30.0, 25.0, 0.5) == pytest.approx(-2.5)


def test_mpc_case_1_min_brake_when_p1_positive() -> None:
    # h = 30, v = 22, v_lead = 20, a_lead = -1: a_min.brake = -(22^2 / 2) / (25 + 200) = -1.075556;
    # P1 = -1.075556 - (-1 * 22 / 20) = 0.024444 > 0.
    assert min_brake_accel(30.0, 22.0, 20.0, -1.0, 5.0) == pytest.approx(-242 / 225)
    assert anticipation_accel(30.0, 22.0, 20.0, -1.0, **LIMITS) == pytest.approx(-1.075556, 1e-6)


def test_mpc_case_2_proportional_when_p1_not_positive_and_leader_not_slower() -> None:
    # h = 3 < s0, v = v_lead = 20, a_lead = -2: a_min.brake = -200 / (-2 + 100) = -2.040816,
    # a_lead v / v_lead = -2, P1 = -0.040816 <= 0, P2 = 0 >= 0 -> -2.
    assert anticipation_accel(3.0, 20.0, 20.0, -2.0, **LIMITS) == pytest.approx(-2.0)


def test_mpc_case_3_closing_on_a_braking_leader() -> None:
    # h = 10, v = 22, v_lead = 20, a_lead = -1: a_min.brake = -242 / 205 = -1.180488,
    # P1 = -1.180488 + 1.1 < 0, P2 = -2 < 0 -> a_lead - (v - v_lead)^2 / (2 (h - s0)) = -1 - 4/10.
    assert anticipation_accel(10.0, 22.0, 20.0, -1.0, **LIMITS) == pytest.approx(-1.4)


def test_mpc_case_4_closing_on_an_accelerating_leader() -> None:
    # a_lead = 0.5 >= 0, P2 = -2: 0.5 - 4 / (2 * 25) = 0.42.
    assert anticipation_accel(30.0, 22.0, 20.0, 0.5, **LIMITS) == pytest.approx(0.42)


def test_mpc_case_5_follows_an_accelerating_leader_up_to_a_max() -> None:
    # a_lead = 0.5, P2 = 2: min(1.5, 0.5 (1 + 0.2 * 2)) = 0.7.
    assert anticipation_accel(30.0, 20.0, 22.0, 0.5, **LIMITS) == pytest.approx(0.7)
    # a_lead = 1.2, P2 = 3: 1.2 * 1.6 = 1.92 -> capped at a_max = 1.5.
    assert anticipation_accel(30.0, 20.0, 23.0, 1.2, **LIMITS) == pytest.approx(1.5)


def test_command_is_the_minimum_of_the_three_terms() -> None:
    # a_target = +1.5, a_safe = -2.037257, a_MPC = -1.075556 (cases above) -> a_safe.
    observation = Observation(
        time_s=0.0,
        speed_mps=22.0,
        target_speed_mps=25.0,
        lead_present=True,
        lead_distance_m=30.0,
        lead_rel_speed_mps=-2.0,
    )
    assert base_accel(observation, -1.0, PARAMS) == pytest.approx(-2.037257, abs=1e-6)


def test_without_a_measured_leader_only_the_target_term_acts() -> None:
    observation = Observation(time_s=0.0, speed_mps=20.0, target_speed_mps=21.0, lead_present=True)
    assert base_accel(observation, 0.0, PARAMS) == pytest.approx(0.5)
    far_too_slow = Observation(time_s=0.0, speed_mps=5.0, target_speed_mps=30.0)
    assert base_accel(far_too_slow, 0.0, PARAMS) == pytest.approx(1.5)  # a_max


def test_controller_estimates_the_leaders_acceleration_from_its_speed() -> None:
    controller = build_controller("microaccel", "accel", {"lead_accel_filter_s": 0.0})
    # Leader at 20 m/s then 19.9 m/s 0.1 s later: a_lead = -1 m/s^2 (no filtering).
    first = Observation(
        0.0, 22.0, 25.0, lead_present=True, lead_distance_m=30.2, lead_rel_speed_mps=-2.0
    )
    second = Observation(
        0.1, 22.0, 25.0, lead_present=True, lead_distance_m=30.0, lead_rel_speed_mps=-2.1
    )
    controller.step(first)
    command = controller.step(second)
    assert isinstance(command, AccelCommand)
    lead_speed = 19.9
    v_safe = safe_speed(
        30.0, lead_speed, standstill_gap_m=5, min_accel_mps2=-3, lead_min_accel_mps2=-5
    )
    rate = safe_speed_rate(
        v_safe, -2.1, lead_speed, -1.0, min_accel_mps2=-3, lead_min_accel_mps2=-5
    )
    assert command.accel_mps2 == pytest.approx(safety_accel(22.0, v_safe, rate, 0.5), abs=1e-9)
