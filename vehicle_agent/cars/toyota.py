"""2020-21 Toyota RAV4 on opendbc's `toyota_nodsu_pt` DBC (actuation `accel`).

Read (the signals the field team used, README of ../shared/data/can): SPEED (km/h, checksum),
PCM_CRUISE (ACC active, gas released; checksum), PCM_CRUISE_2 (main on, brake pressed, the set
speed in km/h; checksum), PCM_CRUISE_SM (distance lines 1-3), BRAKE_MODULE (brake pressed),
LEAD_INFO (radar lead distance and relative speed; checksum). The brake is pressed when either
message says so: BRAKE_MODULE's bit is the one openpilot and panda read, and the only one the
field team's DBC defines (its PCM_CRUISE_2 has no BRAKE_PRESSED); opendbc's PCM_CRUISE_2 bit 3
was read alone until 2026-12-05. The set speed: PCM_CRUISE_SM's UI_SET_SPEED is in the unit
the car's display is set to (opendbc: "with the vehicle's unit", which openpilot reads from
BODY_CONTROL_STATE_2), and read as mph a car showing km/h reported 100 km/h as 100 mph; the
PCM's own (PCM_CRUISE_2's SET_SPEED) is always km/h, so the display's unit is the one the two
agree in (`set_speed_mph`). The RAV4 is the make that measures the leader (paper Table 2); a
distance of 252 m or more, or 0, means no leader, the field team's convention for "none".
Sent: ACC_CONTROL with ACCEL_CMD at ~30 Hz (checksum). The RAV4 has no button actuation, so a
change of the set speed or the distance lines is the driver's doing.

At the PCM's standstill (PCM_CRUISE CRUISE_STATE 7) the car stays stopped until the driver
resumes (RES or the gas pedal); ACC_CONTROL's RELEASE_STANDSTILL 1 releases that hold, as
openpilot sets it to drive off by itself. The agent never does: the field team's libpanda
released it only while the PCM was engaged (CRUISE_STATE 8 and above), and driving off from a
standstill the stock ACC holds is left to the driver. So a frame releases only while a
PCM_CRUISE read at most 2 of its periods ago shows no standstill
(`SafetyLayer.check_standstill_release`): the car state stays valid on one 10 periods (0.33 s)
old, time enough for the PCM to have stopped the car and held it since.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

from contract.controllers import Actuation
from contract.units import KPH_PER_MPH, kph_to_mps
from vehicle_agent.cars.base import (
    CarInterface,
    CarReading,
    MessageRule,
    Signals,
)
from vehicle_agent.codec import Checksum, ToyotaChecksum

NO_LEAD_DISTANCE_M = 252.0
# PCM_CRUISE CRUISE_STATE while the PCM holds the car stopped for the driver to resume
# (opendbc's value table: "standstill").
CRUISE_STATE_STANDSTILL = 7

_CHECKSUM = ToyotaChecksum()

# ACC_CONTROL's signals the agent sets to one value in every frame (`accel_signals`); every other
# but the request's own (`_REQUEST_SIGNALS`) it leaves 0. A frame with another value asks the
# car for something the agent never does: ACCEL_CMD_ALT is a second acceleration field, DISTANCE
# cycles the following distance, ACC_MALFUNCTION shows a fault on the dash, PERMIT_BRAKING 0
# forbids the brakes, ACC_TYPE 2 is a low-speed lockout.
_FIXED_COMMAND_SIGNALS = {"ACC_TYPE": 1.0, "ALLOW_LONG_PRESS": 1.0, "PERMIT_BRAKING": 1.0}
# What the request itself sets; CANCEL_REQ is the safety layer's own check.
_REQUEST_SIGNALS = frozenset({"ACCEL_CMD", "RELEASE_STANDSTILL", "CANCEL_REQ", "CHECKSUM"})


# How far the display's set speed, in its unit, and the PCM's may differ and still be the same
# setting: the field team's DBC notes "43 kph are shown as 28mph, so conversion isnt perfect"
# (45.1 km/h: 2.1 off).
UNIT_AGREEMENT_KPH = 2.5


def set_speed_mph(shown: float, pcm_kph: float) -> float:
    """The ACC's set speed in mph from the display's figure (`shown`, in the display's unit)
    and the PCM's (km/h, whole): the display's figure in the unit the PCM's agrees with, to
    `UNIT_AGREEMENT_KPH` (a set speed of 60 mph is the PCM's 97 km/h, 60.3 mph: the display's
    60 is the driver's); the PCM's when neither agrees. Both can agree only below 8 mph, no
    set speed."""
    if abs(shown * KPH_PER_MPH - pcm_kph) <= UNIT_AGREEMENT_KPH:
        return shown
    if abs(shown - pcm_kph) <= UNIT_AGREEMENT_KPH:
        return round(shown / KPH_PER_MPH, 1)
    return round(pcm_kph / KPH_PER_MPH, 1)


class ToyotaRav4(CarInterface):
    """TSS2 RAV4 without a separate DSU."""

    key = "toyota_rav4"
    make = "Toyota"
    model = "RAV4"
    years = (2020, 2021)
    dbc_name = "toyota_nodsu_pt"
    actuation: ClassVar[Actuation] = "accel"
    messages: ClassVar[dict[str, MessageRule]] = {
        "SPEED": MessageRule(0.02),
        "PCM_CRUISE": MessageRule(1 / 30),
        "PCM_CRUISE_2": MessageRule(1 / 30),
        "PCM_CRUISE_SM": MessageRule(0.1),
        "BRAKE_MODULE": MessageRule(0.025),  # 40 Hz (openpilot's Toyota car state)
        "LEAD_INFO": MessageRule(0.05),
    }
    checksums: ClassVar[dict[str, Checksum]] = dict.fromkeys(
        ("SPEED", "PCM_CRUISE", "PCM_CRUISE_2", "LEAD_INFO", "ACC_CONTROL"), _CHECKSUM
    )
    command_message = "ACC_CONTROL"
    command_period_s = 1 / 30
    standstill_message = "PCM_CRUISE"

    def interpret(self, signals: Mapping[str, Signals]) -> CarReading:
        """Speed, cruise state, set points, radar lead and pedals."""
        cruise, cruise_2, ui = (
            signals["PCM_CRUISE"],
            signals["PCM_CRUISE_2"],
            signals["PCM_CRUISE_SM"],
        )
        lead = signals["LEAD_INFO"]
        distance = float(lead["LEAD_LONG_DIST"])
        present = 0.0 < distance < NO_LEAD_DISTANCE_M
        engaged = bool(cruise["CRUISE_ACTIVE"])
        lines = int(ui["DISTANCE_LINES"])
        set_speed = set_speed_mph(float(ui["UI_SET_SPEED"]), float(cruise_2["SET_SPEED"]))
        return CarReading(
            speed_mps=kph_to_mps(float(signals["SPEED"]["SPEED"])),
            acc_available=bool(cruise_2["MAIN_ON"]),
            acc_engaged=engaged,
            acc_speed_setting_mph=set_speed if engaged and set_speed > 0 else None,
            acc_gap_setting=lines if 1 <= lines <= 3 else None,
            lead_present=present,
            lead_distance_m=distance if present else None,
            lead_rel_speed_mps=float(lead["LEAD_REL_SPEED"]) if present else None,
            brake_pressed=bool(cruise_2["BRAKE_PRESSED"])
            or bool(signals["BRAKE_MODULE"]["BRAKE_PRESSED"]),
            gas_pressed=not cruise["GAS_RELEASED"],
            standstill_held=self.holds_standstill(signals),
        )

    def holds_standstill(self, latest: Mapping[str, Signals]) -> bool:
        """The PCM's standstill (CRUISE_STATE 7): stopped until the driver's RES or gas."""
        return latest.get("PCM_CRUISE", {}).get("CRUISE_STATE") == CRUISE_STATE_STANDSTILL

    def releases_standstill(self, signals: Signals) -> bool:
        """ACC_CONTROL's RELEASE_STANDSTILL set."""
        return bool(signals.get("RELEASE_STANDSTILL"))

    def accel_signals(self, accel_mps2: float, *, release_standstill: bool) -> dict[str, float]:
        """An ACC_CONTROL frame requesting `accel_mps2` with braking permitted, releasing the
        standstill only when `release_standstill` (the module docstring says when)."""
        return {
            "ACCEL_CMD": accel_mps2,
            "ACC_TYPE": 1,
            "ALLOW_LONG_PRESS": 1,
            "PERMIT_BRAKING": 1,
            "RELEASE_STANDSTILL": int(release_standstill),
            "CANCEL_REQ": 0,
        }

    def foreign_inputs(self, signals: Signals) -> str | None:
        """An ACC_CONTROL signal, other than the request's, at a value `accel_signals` never
        sets (`_FIXED_COMMAND_SIGNALS`, else 0)."""
        for name, value in signals.items():
            if name in _REQUEST_SIGNALS:
                continue
            if float(value) != _FIXED_COMMAND_SIGNALS.get(name, 0.0):
                return f"{name} {float(value):g}"
        return None

    def commanded_accel(self, signals: Signals) -> float:
        """ACCEL_CMD of a decoded ACC_CONTROL frame."""
        return float(signals["ACCEL_CMD"])
