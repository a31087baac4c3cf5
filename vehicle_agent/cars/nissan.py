"""2018-20 Nissan Rogue on opendbc's `nissan_x_trail_2017` DBC (actuation `acc`: button presses).

The paper's 2023 Rogue sends other frames (`nissan_canfd.py`); opendbc lists this DBC for the
2018-20 Rogue and X-Trail.

Read: wheel speeds (km/h, the mean of four), PRO_PILOT (cruise main on, ACC activated, 4-bit
counter), PROPILOT_HUD (set speed in mph on US cars, follow distance 1-3 bars, lead car icon =
the "minicar"), CRUISE_THROTTLE (the steering-wheel buttons, brake and gas; 2-bit counter). No
lead distance or relative speed (paper Table 2). Sent: CRUISE_THROTTLE with RES (+) or SET (-) or
the follow-distance button, the other signals copied from the car's latest frame. That frame
carries the driver's gas pedal and brake too, so a press is built only from one read at most 2
periods ago (`copies_command_frame`): the car state stays valid on one 10 periods old.

No frame of this DBC tells a stop the ACC holds for the driver's resume from a brief one
(opendbc, too, reads only the wheels' standstill), and RES (+) resumes a hold. So every stop
with the ACC engaged reads as held (`standstill_held`): the agent presses nothing while the car
stands, which costs nothing (a setting matters once the car moves) and never drives off a stop
that is the driver's to leave.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

from contract.controllers import Actuation
from contract.units import kph_to_mps
from vehicle_agent.cars.base import (
    CarInterface,
    CarReading,
    CruiseButton,
    MessageRule,
    Signals,
)

# Accelerator position above which the driver is pressing the gas (raw 0..1023 counts).
GAS_PRESSED_COUNTS = 3

BUTTON_SIGNALS = {
    CruiseButton.PLUS: "RES_BUTTON",
    CruiseButton.MINUS: "SET_BUTTON",
    CruiseButton.GAP: "FOLLOW_DISTANCE_BUTTON",
    CruiseButton.CANCEL: "CANCEL_BUTTON",
    CruiseButton.MAIN: "PROPILOT_BUTTON",
}


class NissanRogue2018(CarInterface):
    """The Rogue before the paper's: button frames on classic CAN."""

    key = "nissan_rogue_2018"
    make = "Nissan"
    model = "Rogue"
    years = (2018, 2019, 2020)
    dbc_name = "nissan_x_trail_2017"
    actuation: ClassVar[Actuation] = "acc"
    messages: ClassVar[dict[str, MessageRule]] = {
        "WHEEL_SPEEDS_FRONT": MessageRule(0.02),
        "WHEEL_SPEEDS_REAR": MessageRule(0.02),
        "PRO_PILOT": MessageRule(0.05, "COUNTER", 16),
        "PROPILOT_HUD": MessageRule(0.1),
        "CRUISE_THROTTLE": MessageRule(0.05, "COUNTER", 4),
    }
    command_message = "CRUISE_THROTTLE"
    command_period_s = 0.05
    press_inputs = ("PRO_PILOT", "PROPILOT_HUD", "CRUISE_THROTTLE")
    command_counter_signal = "COUNTER"
    command_counter_modulo = 4
    copies_command_frame = True

    def interpret(self, signals: Mapping[str, Signals]) -> CarReading:
        """Wheel speeds, cruise state, HUD set points and driver inputs."""
        front, rear = signals["WHEEL_SPEEDS_FRONT"], signals["WHEEL_SPEEDS_REAR"]
        speed_kph = (
            front["WHEEL_SPEED_FL"]
            + front["WHEEL_SPEED_FR"]
            + rear["WHEEL_SPEED_RL"]
            + rear["WHEEL_SPEED_RR"]
        ) / 4.0
        pilot, hud, throttle = (
            signals["PRO_PILOT"],
            signals["PROPILOT_HUD"],
            signals["CRUISE_THROTTLE"],
        )
        engaged = bool(pilot["CRUISE_ACTIVATED"])
        gap = int(hud["FOLLOW_DISTANCE"])
        set_speed = float(hud["SET_SPEED"])
        return CarReading(
            speed_mps=kph_to_mps(speed_kph),
            acc_available=bool(pilot["CRUISE_ON"]),
            acc_engaged=engaged,
            acc_speed_setting_mph=set_speed if engaged and set_speed > 0 else None,
            acc_gap_setting=gap if 1 <= gap <= 3 else None,
            lead_present=bool(hud["LEAD_CAR"]),
            standstill_held=engaged and speed_kph == 0.0,  # any stop (module docstring)
            brake_pressed=_brake_pressed(throttle),
            gas_pressed=_gas_pressed(throttle),
            buttons=frozenset(b for b, name in BUTTON_SIGNALS.items() if throttle[name]),
        )

    def button_signals(
        self, button: CruiseButton | None, latest: Mapping[str, Signals]
    ) -> dict[str, float]:
        """The car's latest CRUISE_THROTTLE with only `button` pressed."""
        values = dict(latest.get("CRUISE_THROTTLE", {}))
        for name in BUTTON_SIGNALS.values():
            values[name] = 0
        if button is not None:
            values[BUTTON_SIGNALS[button]] = 1
        values["NO_BUTTON_PRESSED"] = 0 if button is not None else 1
        return values

    def driver_inputs(self, signals: Signals) -> str | None:
        """The brake or the gas pedal a CRUISE_THROTTLE frame shows pressed (copied from the
        car's, `button_signals`), or None."""
        if _brake_pressed(signals):
            return "the brake pressed"
        if _gas_pressed(signals):
            return "the gas pedal pressed"
        return None

    def pressed_buttons(self, signals: Signals) -> frozenset[CruiseButton]:
        """Buttons set in a CRUISE_THROTTLE frame."""
        return frozenset(b for b, name in BUTTON_SIGNALS.items() if signals.get(name))


def _brake_pressed(throttle: Signals) -> bool:
    """The driver's brake in a CRUISE_THROTTLE frame, the car's or one the agent builds."""
    return bool(throttle.get("USER_BRAKE_PRESSED"))


def _gas_pressed(throttle: Signals) -> bool:
    """The driver's gas pedal in a CRUISE_THROTTLE frame, past the counts of a resting foot."""
    return float(throttle.get("GAS_PEDAL", 0.0)) > GAS_PRESSED_COUNTS
