"""A stock ACC: set points from steering-wheel buttons, and the acceleration it makes.

Paper sidebar "Adaptive Cruise Control Modeling": two modes, speed control a = f_p(v, v_ref)
without a leader in range, gap control a = f_q(v, v_l, d, g_ref) with one, the car never going
faster than its speed setting. Our parametric forms (the paper fits its own to a Nissan Leaf and
does not print them):
- speed control: a_s = k_v (v_set - v), k_v = 0.4 1/s;
- gap control: constant time gap, a_g = k_1 (d - s_0 - T v) + k_2 (v_l - v) with k_1 = 0.23 1/s^2
  and k_2 = 0.07 1/s, the values Milanes & Shladover (2014) fitted to a production ACC, and
  T = 1.2, 1.5, 2.0 s for 1, 2, 3 bars (paper, ACC-Based Controller);
- the stock ACC's collision avoidance when closing: a_c = b_0 - (v - v_l)^2 / (2 (d - s_0)),
  the kinematic deceleration that matches the leader's speed at s_0, relaxed by b_0 = 0.5 m/s^2
  so that closing slowly on a distant leader does not pin the acceleration at zero;
a = min(a_s, a_g, a_c) in gap control, clipped to the ACC's authority [-3.5, 2.0] m/s^2.

Buttons behave as the fleet's cars: a short press of + (resume) or - (set) moves the setting by
1 mph on release; holding it moves it by 5 mph every 0.6 s held; - engages ACC at the current
speed, + resumes the last setting, the gap button cycles 3 -> 2 -> 1 -> 3 bars, cancel and the
brake pedal disengage.

`SimulatedAccCar` is the same ACC driven through the agent's own button sequencer, for the
simulator: set points in, acceleration out, with the presses' real delays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from contract.units import MPS_PER_MPH, mps_to_mph
from vehicle_agent.actuators import ButtonSequencer
from vehicle_agent.cars import CruiseButton
from vehicle_agent.controllers import AccSetPoint
from vehicle_agent.stopping import STOCK_ACC_MAX_BRAKING_MPS2

MIN_SET_SPEED_MPH = 20
MAX_SET_SPEED_MPH = 90
# The emulated car's buttons (paper, the ACC buttons' figure: +/- 1 mph a press, 5 mph held;
# the 0.6 s a hold takes per 5 mph step is our assumption). Stated here apart from what the
# agent believes of them (vehicle_agent.actuators), so that an agent wrong about the car is
# caught by its tests against this one, not matched by it.
PRESS_STEP_MPH = 1
HOLD_STEP_MPH = 5
HOLD_STEP_EVERY_S = 0.6
# The gap button's cycle of bars (interfaces.md: three settings of ~1.2, 1.5, 2.0 s).
NEXT_GAP_BARS = {3: 2, 2: 1, 1: 3}


@dataclass(frozen=True)
class StockAccParams:
    """The stock ACC model's parameters (see the module docstring)."""

    speed_gain: float = 0.4
    gap_gain: float = 0.23
    rel_speed_gain: float = 0.07
    standstill_gap_m: float = 4.0
    time_gaps_s: tuple[float, float, float] = (1.2, 1.5, 2.0)
    # The radar sees a leader within about 80-100 m (paper Table 2, "minicar").
    sensor_range_m: float = 100.0
    min_accel_mps2: float = -STOCK_ACC_MAX_BRAKING_MPS2
    max_accel_mps2: float = 2.0
    closing_slack_mps2: float = 0.5


def stock_acc_accel(
    speed_mps: ArrayLike,
    set_speed_mps: ArrayLike,
    time_gap_s: ArrayLike,
    lead_distance_m: ArrayLike,
    lead_speed_mps: ArrayLike,
    params: StockAccParams,
) -> NDArray[np.float64]:
    """The ACC's acceleration, vectorised over cars; a NaN lead distance means no leader."""
    v = np.asarray(speed_mps, dtype=np.float64)
    v_set = np.asarray(set_speed_mps, dtype=np.float64)
    gap = np.asarray(lead_distance_m, dtype=np.float64)
    v_lead = np.asarray(lead_speed_mps, dtype=np.float64)
    accel = params.speed_gain * (v_set - v)
    with np.errstate(invalid="ignore"):
        in_range = np.isfinite(gap) & (gap <= params.sensor_range_m)
    gap_safe = np.where(in_range, gap, params.sensor_range_m)
    lead = np.where(in_range, v_lead, v)
    gap_control = params.gap_gain * (
        gap_safe - params.standstill_gap_m - np.asarray(time_gap_s) * v
    ) + params.rel_speed_gain * (lead - v)
    margin = np.maximum(gap_safe - params.standstill_gap_m, 0.5)
    closing = np.where(
        lead < v, params.closing_slack_mps2 - (v - lead) ** 2 / (2.0 * margin), np.inf
    )
    accel = np.where(in_range, np.minimum(accel, np.minimum(gap_control, closing)), accel)
    clipped: NDArray[np.float64] = np.clip(accel, params.min_accel_mps2, params.max_accel_mps2)
    return clipped


def stock_acc_accel_one(
    speed_mps: float,
    set_speed_mps: float,
    time_gap_s: float,
    lead_distance_m: float | None,
    lead_speed_mps: float | None,
    params: StockAccParams,
) -> float:
    """`stock_acc_accel` for one car in plain floats (None: no leader).

    The emulated car evaluates its ACC at every 20 ms sub-step, and the demo runs a hundred of
    them: numpy's per-call overhead on scalars made this the largest cost of a fleet step
    (docs/performance.md, Demo fleet). Same equations as the vectorised form (tested equal).
    """
    accel = params.speed_gain * (set_speed_mps - speed_mps)
    if (
        lead_distance_m is not None
        and lead_speed_mps is not None
        and math.isfinite(lead_distance_m)
        and lead_distance_m <= params.sensor_range_m
    ):
        gap_control = params.gap_gain * (
            lead_distance_m - params.standstill_gap_m - time_gap_s * speed_mps
        ) + params.rel_speed_gain * (lead_speed_mps - speed_mps)
        accel = min(accel, gap_control)
        if lead_speed_mps < speed_mps:
            margin = max(lead_distance_m - params.standstill_gap_m, 0.5)
            closing = params.closing_slack_mps2 - (speed_mps - lead_speed_mps) ** 2 / (2.0 * margin)
            accel = min(accel, closing)
    return min(max(accel, params.min_accel_mps2), params.max_accel_mps2)


class StockAcc:
    """One car's ACC state machine: main switch, engaged, set speed (mph) and gap bars."""

    def __init__(self, params: StockAccParams | None = None, gap_setting: int = 3) -> None:
        self.params = params or StockAccParams()
        self.main_on = True
        self.engaged = False
        self.set_speed_mph: int | None = None
        self.gap_setting = gap_setting
        self._pressed: dict[CruiseButton, float] = {}
        self._long_steps: dict[CruiseButton, int] = {}

    def engage(self, speed_mps: float) -> None:
        """The driver sets ACC at the current speed."""
        if self.main_on:
            self.engaged = True
            self.set_speed_mph = _bounded(round(mps_to_mph(speed_mps)))

    def cancel(self) -> None:
        """Disengage (brake pedal, cancel button); the setting is kept for resume."""
        self.engaged = False

    def buttons(
        self,
        now: float,
        pressed: frozenset[CruiseButton],
        speed_mps: float,
        *,
        brake_pressed: bool = False,
    ) -> None:
        """Update from the buttons held at `now` (whoever holds them: driver or agent); with the
        brake pressed a set or resume does not engage, as no real ACC engages under the brake."""
        for button in pressed - set(self._pressed):
            self._pressed[button] = now
            self._long_steps[button] = 0
        for button in (CruiseButton.PLUS, CruiseButton.MINUS):
            if button in pressed and self.engaged and self.set_speed_mph is not None:
                steps = int((now - self._pressed[button]) // HOLD_STEP_EVERY_S)
                while self._long_steps[button] < steps:
                    self._long_steps[button] += 1
                    sign = 1 if button is CruiseButton.PLUS else -1
                    self.set_speed_mph = _bounded(self.set_speed_mph + sign * HOLD_STEP_MPH)
        for button in set(self._pressed) - pressed:
            del self._pressed[button]
            if not self._long_steps.pop(button, 0):
                self._short_press(button, speed_mps, brake_pressed)

    def _short_press(self, button: CruiseButton, speed_mps: float, brake_pressed: bool) -> None:
        if button is CruiseButton.MAIN:
            self.main_on = not self.main_on
            self.engaged = False
        elif button is CruiseButton.CANCEL:
            self.cancel()
        elif button is CruiseButton.GAP:
            self.gap_setting = NEXT_GAP_BARS[self.gap_setting]
        elif not self.engaged:
            if brake_pressed:
                return
            if button is CruiseButton.MINUS:
                self.engage(speed_mps)
            elif button is CruiseButton.PLUS and self.set_speed_mph is not None and self.main_on:
                self.engaged = True
        elif self.set_speed_mph is not None:
            sign = 1 if button is CruiseButton.PLUS else -1
            self.set_speed_mph = _bounded(self.set_speed_mph + sign * PRESS_STEP_MPH)

    def accel(
        self, speed_mps: float, lead_distance_m: float | None, lead_speed_mps: float | None
    ) -> float:
        """The acceleration the engaged ACC makes (0 when disengaged: the driver's business)."""
        if not self.engaged or self.set_speed_mph is None:
            return 0.0
        return stock_acc_accel_one(
            speed_mps,
            self.set_speed_mph * MPS_PER_MPH,
            self.params.time_gaps_s[self.gap_setting - 1],
            lead_distance_m,
            lead_speed_mps,
            self.params,
        )


def _bounded(speed_mph: int) -> int:
    return min(max(speed_mph, MIN_SET_SPEED_MPH), MAX_SET_SPEED_MPH)


class SimulatedAccCar:
    """A stock ACC driven by the agent's button sequencer, without CAN: what the simulator's
    `acc` AVs use (set points in, the ACC's acceleration out, presses taking their real time).
    The driver engages ACC at the car's speed on the first call."""

    def __init__(self, params: StockAccParams | None = None) -> None:
        self.acc = StockAcc(params)
        self.sequencer = ButtonSequencer()

    @property
    def speed_setting_mph(self) -> float | None:
        """The set speed the car shows."""
        return (
            float(self.acc.set_speed_mph) if self.acc.engaged and self.acc.set_speed_mph else None
        )

    @property
    def gap_setting(self) -> int | None:
        """The gap bars the car shows."""
        return self.acc.gap_setting

    def cancel(self) -> None:
        """The driver braked: ACC off until the next set point engages it at the car's speed."""
        self.acc.cancel()

    def hold_accel_mps2(
        self,
        time_s: float,
        speed_mps: float,
        gap_m: float | None,
        lead_speed_mps: float | None,
    ) -> float:
        """The agent has handed the car back: it presses nothing more (a button it held is
        released), and the ACC drives on the settings it shows; were it off, the driver sets
        it at the car's speed."""
        self.sequencer.stop()
        self.acc.buttons(time_s, frozenset(), speed_mps)
        if not self.acc.engaged:
            self.acc.engage(max(speed_mps, MIN_SET_SPEED_MPH * MPS_PER_MPH))
        return self.acc.accel(speed_mps, gap_m, lead_speed_mps)

    def accel_mps2(
        self,
        set_point: AccSetPoint,
        time_s: float,
        speed_mps: float,
        gap_m: float | None,
        lead_speed_mps: float | None,
    ) -> float:
        """Press towards `set_point`, then the ACC's acceleration this step."""
        if not self.acc.engaged:
            self.acc.engage(max(speed_mps, MIN_SET_SPEED_MPH * MPS_PER_MPH))
        self.sequencer.request(set_point.speed_setting_mph, set_point.gap_setting)
        held = self.sequencer.step(time_s, self.speed_setting_mph, self.gap_setting)
        self.acc.buttons(time_s, frozenset() if held is None else frozenset({held}), speed_mps)
        return self.acc.accel(speed_mps, gap_m, lead_speed_mps)
