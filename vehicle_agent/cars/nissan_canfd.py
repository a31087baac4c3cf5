"""2021-23 Nissan Rogue on its CAN-FD frames (actuation `acc`: button presses, by a GPIO board).

The paper's majority car (97 of the 100). opendbc's Nissan DBCs describe the 2018-20 frames
(`nissan.py`); the 2023 car puts what the agent reads on other ids, in CAN-FD frames of 12 to 64
bytes, which the agent decodes with the subset of the field team's DBC it ships
(`cars/dbc/nissan_rogue_2023.dbc`). Read (data README, paper Table 2): SPEED (303, km/h),
CRUISE (308: the cruise state and whether ACC is engaged), WHEEL_BUTTONS (1119: the
steering-wheel ACC buttons) and ACC_HUD (1487: set speed in mph, gap bars, the "minicar" lead
icon). No lead distance or relative speed, and no brake pedal: the brake cancels the stock ACC,
which the agent reads as ACC disengaged and hands the car back. The gas pedal shows as its own
cruise state (14, "engaged with the gas pressed", as the field team's libpanda reads it).

Nothing is sent on CAN: the car refused injected commands (paper, vehicle interface), so the
field team pressed its switches electrically, as the agent's GPIO board does, and the car's own
WHEEL_BUTTONS then reports the board's presses beside the driver's.

Periods: the field team replayed SPEED at 50 Hz (libpanda), so 20 ms. The others are not known;
the agent assumes 100 ms, which its staleness rule (10 periods) reads as a car gone quiet only
after a second without a frame, and which puts the server's CAN-rate check at 80 frames/s.
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

# CRUISE_STATE on its 4 bits (cars/dbc/nissan_rogue_2023.dbc's value table: also 6 on and 12
# engaged, which the agent reads from CRUISE_ENGAGED).
CRUISE_OFF = 0
CRUISE_STANDSTILL_HOLD = 4
CRUISE_ENGAGED_GAS_PRESSED = 14

# ACC_BTNS codes (the DBC's value table); 0 is no button.
BUTTONS_BY_CODE = {
    1: CruiseButton.PLUS,  # resume
    2: CruiseButton.MINUS,  # set
    3: CruiseButton.GAP,  # distance
    4: CruiseButton.CANCEL,
    5: CruiseButton.MAIN,  # system toggle
}


class NissanRogue(CarInterface):
    """The paper's majority car, the 2023 model."""

    key = "nissan_rogue"
    make = "Nissan"
    model = "Rogue"
    # the paper's cars are 2023s; the field team's DBC was made on a 2021 (its name), the first
    # year of this Rogue
    years = (2021, 2022, 2023)
    dbc_name = "nissan_rogue_2023"
    actuation: ClassVar[Actuation] = "acc"
    can_fd = True
    accepts_button_frames = False
    messages: ClassVar[dict[str, MessageRule]] = {
        "SPEED": MessageRule(0.02),
        "CRUISE": MessageRule(0.1),
        "WHEEL_BUTTONS": MessageRule(0.1),
        "ACC_HUD": MessageRule(0.1),
    }
    # The buttons' message, named for the safety layer, which refuses every frame of it (the
    # car takes none); the agent's loop runs at the 20 Hz of the other button cars.
    command_message = "WHEEL_BUTTONS"
    command_period_s = 0.05
    press_inputs = ("CRUISE", "ACC_HUD")

    def interpret(self, signals: Mapping[str, Signals]) -> CarReading:
        """Speed, cruise state, HUD set points and the wheel's buttons."""
        cruise, hud = signals["CRUISE"], signals["ACC_HUD"]
        state = int(cruise["CRUISE_STATE"])
        engaged = bool(cruise["CRUISE_ENGAGED"])
        gap = int(hud["SET_DISTANCE"])
        set_speed = float(hud["SET_SPEED"])
        button = BUTTONS_BY_CODE.get(int(signals["WHEEL_BUTTONS"]["ACC_BTNS"]))
        return CarReading(
            speed_mps=kph_to_mps(signals["SPEED"]["SPEED"]),
            acc_available=state != CRUISE_OFF,
            acc_engaged=engaged,
            acc_speed_setting_mph=set_speed if engaged and set_speed > 0 else None,
            acc_gap_setting=gap if 1 <= gap <= 3 else None,
            lead_present=bool(hud["MINICAR"]),
            gas_pressed=state == CRUISE_ENGAGED_GAS_PRESSED,
            buttons=frozenset() if button is None else frozenset({button}),
            standstill_held=state == CRUISE_STANDSTILL_HOLD,
        )
