"""The emulator's stock ACC: the two modes worked by hand, buttons, and the simulator adapter."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.emulator.acc import (
    SimulatedAccCar,
    StockAcc,
    StockAccParams,
    stock_acc_accel,
    stock_acc_accel_one,
)
from vehicle_agent.cars import CruiseButton
from vehicle_agent.controllers import AccSetPoint

PARAMS = StockAccParams()
MPH = 0.44704


def test_speed_control_mode_without_a_leader() -> None:
    # a_s = 0.4 (50 mph - 20 m/s) = 0.4 (22.352 - 20)
    accel = stock_acc_accel(20.0, 50 * MPH, 1.5, math.nan, math.nan, PARAMS)
    assert float(accel) == pytest.approx(0.9408)


def test_gap_control_mode_with_a_leader_in_range() -> None:
    # a_g = 0.23 (30 - 4 - 1.5 * 20) + 0.07 (20 - 20) = -0.92 < a_s
    assert float(stock_acc_accel(20.0, 50 * MPH, 1.5, 30.0, 20.0, PARAMS)) == pytest.approx(-0.92)
    # Closing at 10 m/s: a_g = 0.23 (30 - 4 - 37.5) + 0.07 (-10) = -3.345,
    # a_c = 0.5 - (10^2) / (2 * 26) = -1.423 -> -3.345.
    assert float(stock_acc_accel(25.0, 70 * MPH, 1.5, 30.0, 15.0, PARAMS)) == pytest.approx(-3.345)
    # Closing at 10 m/s from 90 m: a_g = 0.23 (90 - 4 - 37.5) - 0.7 = 10.455,
    # a_c = 0.5 - 100 / (2 * 86) = -0.0814 -> the kinematic term brakes.
    assert float(stock_acc_accel(25.0, 70 * MPH, 1.5, 90.0, 15.0, PARAMS)) == pytest.approx(
        0.5 - 100 / 172
    )
    # Beyond the 100 m radar range: speed control.
    assert float(stock_acc_accel(20.0, 50 * MPH, 1.5, 150.0, 0.0, PARAMS)) == pytest.approx(0.9408)


def test_the_model_is_vectorised_over_cars() -> None:
    accel = stock_acc_accel(
        np.array([20.0, 20.0]),
        np.array([50 * MPH, 50 * MPH]),
        np.array([1.5, 1.5]),
        np.array([math.nan, 30.0]),
        np.array([math.nan, 20.0]),
        PARAMS,
    )
    np.testing.assert_allclose(accel, [0.9408, -0.92])


@given(
    speed=st.floats(0.0, 40.0),
    set_speed=st.floats(8.0, 40.0),
    time_gap=st.sampled_from(PARAMS.time_gaps_s),
    lead=st.one_of(st.none(), st.tuples(st.floats(0.0, 150.0), st.floats(0.0, 40.0))),
)
def test_the_one_car_form_equals_the_vectorised_one(
    speed: float, set_speed: float, time_gap: float, lead: tuple[float, float] | None
) -> None:
    gap, lead_speed = lead if lead is not None else (None, None)
    expected = stock_acc_accel(
        speed,
        set_speed,
        time_gap,
        math.nan if gap is None else gap,
        math.nan if lead_speed is None else lead_speed,
        PARAMS,
    )
    one = stock_acc_accel_one(speed, set_speed, time_gap, gap, lead_speed, PARAMS)
    assert one == pytest.approx(float(expected), abs=1e-12)


def press(acc: StockAcc, button: CruiseButton, start: float, length: float) -> None:
    acc.buttons(start, frozenset({button}), 25.0)
    t = start
    while t < start + length:
        t += 0.05
        acc.buttons(min(t, start + length), frozenset({button}), 25.0)
    acc.buttons(start + length + 0.05, frozenset(), 25.0)


def test_buttons_set_resume_step_and_cycle() -> None:
    acc = StockAcc()
    press(acc, CruiseButton.MINUS, 0.0, 0.25)  # set: engages at 25 m/s = 55.9 mph
    assert acc.engaged
    assert acc.set_speed_mph == 56
    press(acc, CruiseButton.PLUS, 1.0, 0.25)
    assert acc.set_speed_mph == 57
    press(acc, CruiseButton.PLUS, 2.0, 0.9)  # one 5 mph step, no extra 1 mph on release
    assert acc.set_speed_mph == 62
    press(acc, CruiseButton.MINUS, 4.0, 1.3)  # two 5 mph steps
    assert acc.set_speed_mph == 52
    gaps = []
    for start in (6.0, 7.0, 8.0):
        press(acc, CruiseButton.GAP, start, 0.25)
        gaps.append(acc.gap_setting)
    assert gaps == [2, 1, 3]
    press(acc, CruiseButton.CANCEL, 9.0, 0.25)
    assert not acc.engaged
    press(acc, CruiseButton.PLUS, 10.0, 0.25)  # resume
    assert acc.engaged
    assert acc.set_speed_mph == 52


def test_no_set_or_resume_engages_under_the_brake() -> None:
    """The emulated ACC took the release of a + the agent held as the driver braked for a
    resume, and engaged with the brake pressed: no real ACC does, and the agent's brake
    override tests then saw the car taken back 4.6 s later."""
    acc = StockAcc()
    press(acc, CruiseButton.MINUS, 0.0, 0.25)
    acc.cancel()  # the driver brakes
    for button, start in ((CruiseButton.PLUS, 1.0), (CruiseButton.MINUS, 2.0)):
        acc.buttons(start, frozenset({button}), 25.0, brake_pressed=True)
        acc.buttons(start + 0.25, frozenset(), 25.0, brake_pressed=True)
        assert not acc.engaged
    acc.buttons(3.0, frozenset({CruiseButton.PLUS}), 25.0)  # brake released: resumes
    acc.buttons(3.25, frozenset(), 25.0)
    assert acc.engaged


def test_simulated_acc_car_reaches_the_set_point_through_presses() -> None:
    car = SimulatedAccCar()
    speed = 50 * MPH
    history = []
    time_s = 0.0
    while time_s < 15.0:
        car.accel_mps2(AccSetPoint(61, 1), time_s, speed, None, None)
        history.append((time_s, car.speed_setting_mph, car.gap_setting))
        time_s = round(time_s + 0.05, 3)
    assert history[0][1:] == (50.0, 3)
    assert history[-1][1:] == (61.0, 1)
    # Gap first (two presses, 3 -> 2 -> 1), then 50 -> 55 -> 60 (holds) -> 61 (a press).
    reached = next(t for t, speed_mph, gap in history if (speed_mph, gap) == (61.0, 1))
    assert 3.0 < reached < 7.0
    assert car.sequencer.presses == 5
    assert not car.sequencer.stalled
