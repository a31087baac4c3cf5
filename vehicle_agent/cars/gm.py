"""2022 Cadillac XT5 on opendbc's `gm_global_a_powertrain` DBC (actuation `acc`: button presses).

Read: ECMVehicleSpeed (mph), ECMEngineStatus (cruise main on and active, brake pressed),
ASCMActiveCruiseControlStatus (set speed in km/h, gap level 1-3, lead car present),
ASCMSteeringButton (the driver's ACC buttons; rolling counter and checksum), AcceleratorPedal2
(gas, and CruiseState: 4 is the standstill the ACC holds for the driver's resume, opendbc's value
table). No lead distance or relative speed (paper Table 2). Sent: ASCMSteeringButton with Resume
(+), Set (-) or the distance button.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

from contract.controllers import Actuation
from contract.units import KPH_PER_MPH, MPS_PER_MPH
from vehicle_agent.cars.base import (
    CarInterface,
    CarReading,
    CruiseButton,
    MessageRule,
    Signals,
)
from vehicle_agent.codec import Checksum, GmSteeringButtonChecksum

# Accelerator pedal counts above which the driver is pressing the gas.
GAS_PRESSED_COUNTS = 3
# AcceleratorPedal2 CruiseState while the ACC holds the car stopped for the driver to resume.
CRUISE_STATE_STANDSTILL = 4

# ACCButtons codes (DBC value table): 1 none, 2 resume, 3 set, 5 main, 6 cancel.
BUTTON_CODES = {
    CruiseButton.PLUS: 2,
    CruiseButton.MINUS: 3,
    CruiseButton.MAIN: 5,
    CruiseButton.CANCEL: 6,
}
NO_BUTTON = 1


class CadillacXT5(CarInterface):
    """GM Global A powertrain bus."""

    key = "cadillac_xt5"
    make = "Cadillac"
    model = "XT5"
    years = (2022,)
    dbc_name = "gm_global_a_powertrain"
    actuation: ClassVar[Actuation] = "acc"
    messages: ClassVar[dict[str, MessageRule]] = {
        "ECMVehicleSpeed": MessageRule(0.02),
        "ECMEngineStatus": MessageRule(0.05),
        "ASCMActiveCruiseControlStatus": MessageRule(0.1),
        "ASCMSteeringButton": MessageRule(0.05, "RollingCounter", 4),
        "AcceleratorPedal2": MessageRule(0.05),
    }
    checksums: ClassVar[dict[str, Checksum]] = {"ASCMSteeringButton": GmSteeringButtonChecksum()}
    command_message = "ASCMSteeringButton"
    command_period_s = 0.05
    press_inputs = ("ECMEngineStatus", "ASCMActiveCruiseControlStatus", "AcceleratorPedal2")
    command_counter_signal = "RollingCounter"
    command_counter_modulo = 4

    def interpret(self, signals: Mapping[str, Signals]) -> CarReading:
        """Speed, cruise state, ACC status and driver inputs."""
        engine = signals["ECMEngineStatus"]
        acc = signals["ASCMActiveCruiseControlStatus"]
        buttons_frame = signals["ASCMSteeringButton"]
        engaged = bool(engine["CruiseActive"])
        gap = int(acc["ACCGapLevel"])
        set_kph = float(acc["ACCSpeedSetpoint"])
        code = int(buttons_frame["ACCButtons"])
        buttons = {b for b, value in BUTTON_CODES.items() if value == code}
        if buttons_frame["DistanceButton"]:
            buttons.add(CruiseButton.GAP)
        pedal = signals["AcceleratorPedal2"]
        return CarReading(
            speed_mps=float(signals["ECMVehicleSpeed"]["VehicleSpeed"]) * MPS_PER_MPH,
            acc_available=bool(engine["CruiseMainOn"]),
            acc_engaged=engaged,
            acc_speed_setting_mph=(
                round(set_kph / KPH_PER_MPH, 1) if engaged and set_kph > 0 else None
            ),
            acc_gap_setting=gap if 1 <= gap <= 3 else None,
            lead_present=bool(acc["ACCLeadCar"]),
            brake_pressed=bool(engine["BrakePressed"]),
            gas_pressed=pedal["AcceleratorPedal2"] > GAS_PRESSED_COUNTS,
            buttons=frozenset(buttons),
            standstill_held=int(pedal["CruiseState"]) == CRUISE_STATE_STANDSTILL,
        )

    def button_signals(
        self, button: CruiseButton | None, latest: Mapping[str, Signals]
    ) -> dict[str, float]:
        """An ASCMSteeringButton frame pressing `button`."""
        return {
            "ACCButtons": BUTTON_CODES.get(button, NO_BUTTON) if button else NO_BUTTON,
            "DistanceButton": 1 if button is CruiseButton.GAP else 0,
            "ACCAlwaysOne": 1,
        }

    def foreign_inputs(self, signals: Signals) -> str | None:
        """A code of no known button, or the lane-keeping or drive-mode switch."""
        code = int(signals.get("ACCButtons", NO_BUTTON))
        if code != NO_BUTTON and code not in BUTTON_CODES.values():
            return f"ACCButtons code {code} is no known button"
        for switch in ("LKAButton", "DriveModeButton"):
            if signals.get(switch):
                return f"{switch} pressed"
        return None

    def pressed_buttons(self, signals: Signals) -> frozenset[CruiseButton]:
        """Buttons pressed in an ASCMSteeringButton frame."""
        code = int(signals.get("ACCButtons", NO_BUTTON))
        pressed = {b for b, value in BUTTON_CODES.items() if value == code}
        if signals.get("DistanceButton"):
            pressed.add(CruiseButton.GAP)
        return frozenset(pressed)
