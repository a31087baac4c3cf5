"""The stopping check: hand-worked braking needs against each actuation's authority."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import pytest

from vehicle_agent import engage
from vehicle_agent.cars import CarReading
from vehicle_agent.stopping import (
    STOCK_ACC_MAX_BRAKING_MPS2,
    STOP_NEED_RELEASE_SHARE,
    StoppingCheck,
    braking_authority_mps2,
    required_braking_mps2,
    stop_exceeds_authority,
)


def radar(speed: float, gap: float | None, lead_speed: float | None) -> CarReading:
    """An engaged car's reading with the leader its radar reports (None: only flagged)."""
    return CarReading(
        speed_mps=speed,
        acc_available=True,
        acc_engaged=True,
        acc_speed_setting_mph=60.0,
        acc_gap_setting=2,
        lead_present=True,
        lead_distance_m=gap,
        lead_rel_speed_mps=None if lead_speed is None else lead_speed - speed,
    )


def test_authority_per_actuation() -> None:
    # acceleration requests are limited to -3 m/s^2; a stock ACC brakes 3.5 m/s^2 (ISO 15622)
    assert braking_authority_mps2("accel") == 3.0
    assert braking_authority_mps2("acc") == STOCK_ACC_MAX_BRAKING_MPS2 == 3.5


def test_required_braking_hand_worked() -> None:
    # 28 m/s toward a stopped queue seen at 100 m: 28^2 / (2 x 98) = 4.0 m/s^2
    assert required_braking_mps2(28.0, 100.0, 0.0) == pytest.approx(4.0)
    # closing at 5 m/s with 27 m of gap: 25 / (2 x 25) = 0.5 m/s^2
    assert required_braking_mps2(25.0, 27.0, 20.0) == pytest.approx(0.5)
    # not closing: no braking needed; closing with the room gone: unbounded
    assert required_braking_mps2(20.0, 30.0, 22.0) == 0.0
    assert required_braking_mps2(20.0, 1.5, 10.0) == math.inf
    # a leader braking moderately (2.5 m/s^2) 30 m ahead, 20 against the ego's 30 m/s: it stops
    # in 20^2 / 5 = 80 m, so the ego must stop in 28 + 80 m: 900 / 216 = 4.17 m/s^2, more than
    # its closing speed alone asks (100 / 56 = 1.79) and than an accel car's authority
    assert required_braking_mps2(30.0, 30.0, 20.0, -2.5) == pytest.approx(900 / 216)
    assert stop_exceeds_authority(30.0, 30.0, 20.0, braking_authority_mps2("accel"), -2.5)
    # slowing by less than 0.5 m/s^2 is holding speed: the closing need alone
    assert required_braking_mps2(30.0, 30.0, 20.0, -0.4) == pytest.approx(100 / 56)


def test_the_crash_of_issue_12_hands_back_at_once() -> None:
    # the stale-plan case: 28 m/s, stopped queue first seen at 100 m
    assert stop_exceeds_authority(28.0, 100.0, 0.0, braking_authority_mps2("accel"))
    assert stop_exceeds_authority(28.0, 100.0, 0.0, braking_authority_mps2("acc"))
    # the same queue seen at 150 m needs 2.65 m/s^2: within both
    assert not stop_exceeds_authority(28.0, 150.0, 0.0, braking_authority_mps2("accel"))
    # a make that only flags a leader cannot be checked by the agent
    assert not stop_exceeds_authority(28.0, None, None, 3.0)


def test_from_a_car_reading() -> None:
    assert StoppingCheck("accel").needs_hand_back(0.0, radar(28.0, 100.0, 0.0))
    assert not StoppingCheck("acc").needs_hand_back(0.0, radar(28.0, None, None))
    assert not StoppingCheck("accel").needs_hand_back(0.0, None)


def test_a_leader_braking_hard_right_ahead() -> None:
    # both at 28 m/s, 37.6 m apart (an ACC's 1.2 s + 4 m), the leader braking at 8 m/s^2 and
    # already down to 25.6 m/s: it stops within 25.6^2 / 16 = 40.96 m, so the ego must stop
    # within 37.6 - 2 + 40.96 = 76.56 m: 28^2 / (2 x 76.56) = 5.12 m/s^2
    need = required_braking_mps2(28.0, 37.6, 25.6, lead_accel_mps2=-8.0)
    assert need == pytest.approx(784.0 / (2 * 76.56))
    assert need > braking_authority_mps2("acc")
    # holding its speed, the same closing needs only 2.4^2 / (2 x 35.6) = 0.08 m/s^2
    assert required_braking_mps2(28.0, 37.6, 25.6) == pytest.approx(5.76 / 71.2)


def test_the_agents_check_estimates_the_leaders_braking() -> None:
    check = StoppingCheck("accel")

    def reading(lead_speed: float) -> CarReading:
        return radar(28.0, 37.6, lead_speed)

    # steady, then the leader slows 0.8 m/s every 0.1 s: handed back within a few steps
    assert not check.needs_hand_back(0.0, reading(28.0))
    verdicts = [check.needs_hand_back(0.1 * k, reading(28.0 - 0.8 * k)) for k in range(1, 6)]
    assert verdicts[-1]
    assert not verdicts[0]


def test_a_car_cutting_in_is_a_new_leader_not_a_braking_one() -> None:
    check = StoppingCheck("accel")

    def reading(gap: float, lead_speed: float) -> CarReading:
        return radar(25.0, gap, lead_speed)

    assert not check.needs_hand_back(0.0, reading(80.0, 25.0))
    # a car cuts in 40 m ahead at 22 m/s: a 40 m gap jump and a 3 m/s speed step in 0.1 s,
    # which read as braking at 30 m/s^2 would hand back; it needs 0.12 m/s^2
    assert not any(
        check.needs_hand_back(0.1 * k, reading(40.0 - 0.3 * k, 22.0)) for k in range(1, 20)
    )


def test_a_stop_need_hovering_at_the_authority_hands_back_once_not_at_every_engage_wait() -> None:
    """The need near the threshold moves with the radar's range and the leader's estimated
    braking. Without hysteresis a need wandering 0.1 m/s^2 either side of the accel cars' 3 m/s^2
    for 1.5 s at a time engaged, handed back and engaged again at every engage wait; now the
    check passes again only once the need is down to STOP_NEED_RELEASE_SHARE of it."""
    check = StoppingCheck("accel")
    # 28 m/s closing at 14 m/s on a leader holding its speed: 14^2 / (2 (gap - 2)) m/s^2
    below, above = 2.0 + 196.0 / (2 * 2.9), 2.0 + 196.0 / (2 * 3.1)
    state = engage.INITIAL
    modes = []
    for step in range(150):
        now = 0.1 * step
        gap = below if int(now / 1.5) % 2 == 0 else above
        within = not check.needs_hand_back(now, radar(28.0, gap, 14.0))
        inputs = engage.EngageInputs(
            **{name: True for name, _ in engage.CHECKS},
            time_s=now,
            within_commandable_speed=True,
            driver_active=False,
        )
        state = engage.step(
            state, replace(inputs, stop_within_authority=within), engage.EngagePolicy()
        )
        modes.append(state.mode)
    takeovers = sum(
        1
        for was, now_mode in itertools.pairwise(modes)
        if now_mode is engage.Mode.ENGAGED and was is not engage.Mode.ENGAGED
    )
    assert takeovers == 1
    assert modes[-1] is engage.Mode.STOCK
    # above the release share the check still fails; below it the agent may take over again
    release = STOP_NEED_RELEASE_SHARE * 3.0
    assert check.needs_hand_back(15.1, radar(28.0, 2.0 + 196.0 / (2 * 1.05 * release), 14.0))
    assert not check.needs_hand_back(15.2, radar(28.0, 2.0 + 196.0 / (2 * 0.95 * release), 14.0))
