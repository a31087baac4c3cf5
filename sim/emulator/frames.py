"""What each make's car puts on its bus, from the emulated car's physical state.

Written independently of the agent's decoding (vehicle_agent.cars) so the two check each other:
the emulator sets DBC signals from physics here, the agent reads them back there.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from contract.units import KPH_PER_MPH, KPH_PER_MPS, MPH_PER_MPS
from vehicle_agent.cars import CruiseButton


@dataclass(frozen=True)
class CarSnapshot:
    """The emulated car at one instant, as its ECUs would report it."""

    speed_mps: float
    acc_main_on: bool
    acc_engaged: bool
    set_speed_mph: int | None
    gap_setting: int
    lead_present: bool
    lead_distance_m: float | None
    lead_rel_speed_mps: float | None
    brake_pressed: bool
    gas_pressed: bool
    buttons: frozenset[CruiseButton]
    # the stock ACC's standstill: counting its 3 s, then holding the car for the driver
    standstill_timer: bool = False
    standstill_held: bool = False


SignalBuilder = Callable[[CarSnapshot], dict[str, float]]

# What the emulated RAV4's LEAD_INFO says with no leader: the field team's "252 = none" (data
# README), stated here apart from the agent's reading of it.
RAV4_NO_LEAD_DISTANCE_M = 252.0


def _nissan_wheels(s: CarSnapshot) -> dict[str, float]:
    kph = s.speed_mps * KPH_PER_MPS
    return {
        "WHEEL_SPEED_FL": kph,
        "WHEEL_SPEED_FR": kph,
        "WHEEL_SPEED_RL": kph,
        "WHEEL_SPEED_RR": kph,
    }


NISSAN_ROGUE_2018: dict[str, SignalBuilder] = {
    "WHEEL_SPEEDS_FRONT": _nissan_wheels,
    "WHEEL_SPEEDS_REAR": _nissan_wheels,
    "PRO_PILOT": lambda s: {
        "CRUISE_ON": int(s.acc_main_on),
        "CRUISE_ACTIVATED": int(s.acc_engaged),
    },
    "PROPILOT_HUD": lambda s: {
        "SET_SPEED": s.set_speed_mph if s.acc_engaged and s.set_speed_mph else 0,
        "FOLLOW_DISTANCE": s.gap_setting,
        "LEAD_CAR": int(s.lead_present),
    },
    "CRUISE_THROTTLE": lambda s: {
        "RES_BUTTON": int(CruiseButton.PLUS in s.buttons),
        "SET_BUTTON": int(CruiseButton.MINUS in s.buttons),
        "FOLLOW_DISTANCE_BUTTON": int(CruiseButton.GAP in s.buttons),
        "CANCEL_BUTTON": int(CruiseButton.CANCEL in s.buttons),
        "PROPILOT_BUTTON": int(CruiseButton.MAIN in s.buttons),
        "NO_BUTTON_PRESSED": int(not s.buttons),
        "USER_BRAKE_PRESSED": int(s.brake_pressed),
        "GAS_PEDAL": 200 if s.gas_pressed else 0,
    },
}


def _rogue_2023_cruise_state(s: CarSnapshot) -> int:
    """CRUISE_STATE on its 4 bits: 0 off, 6 on, 12 engaged, 14 engaged with the gas pressed, 4
    the standstill held for the driver (the states the field team's libpanda names)."""
    if not s.acc_main_on:
        return 0
    if not s.acc_engaged:
        return 6
    if s.standstill_held:
        return 4
    return 14 if s.gas_pressed else 12


def _rogue_2023_button(s: CarSnapshot) -> int:
    """ACC_BTNS: one code for the buttons held. The message has room for one; which of two held
    at once the car reports is not known, and the emulated car reports cancel and the main
    switch first (a driver's, as the agent's board presses neither)."""
    for button, code in (
        (CruiseButton.CANCEL, 4),
        (CruiseButton.MAIN, 5),
        (CruiseButton.PLUS, 1),
        (CruiseButton.MINUS, 2),
        (CruiseButton.GAP, 3),
    ):
        if button in s.buttons:
            return code
    return 0


NISSAN_ROGUE_2023: dict[str, SignalBuilder] = {
    "SPEED": lambda s: {"SPEED": s.speed_mps * KPH_PER_MPS},
    "CRUISE": lambda s: {
        "CRUISE_STATE": _rogue_2023_cruise_state(s),
        "CRUISE_ENGAGED": int(s.acc_engaged),
    },
    "WHEEL_BUTTONS": lambda s: {"ACC_BTNS": _rogue_2023_button(s)},
    "ACC_HUD": lambda s: {
        "SYSTEM_ON": int(s.acc_main_on),
        "MINICAR": int(s.lead_present),
        "SET_SPEED": s.set_speed_mph if s.acc_engaged and s.set_speed_mph else 0,
        "SET_DISTANCE": s.gap_setting,
    },
}


def _gm_buttons(s: CarSnapshot) -> dict[str, float]:
    code = 1
    for button, value in (
        (CruiseButton.PLUS, 2),
        (CruiseButton.MINUS, 3),
        (CruiseButton.MAIN, 5),
        (CruiseButton.CANCEL, 6),
    ):
        if button in s.buttons:
            code = value
    return {
        "ACCButtons": code,
        "DistanceButton": int(CruiseButton.GAP in s.buttons),
        "ACCAlwaysOne": 1,
    }


GM: dict[str, SignalBuilder] = {
    "ECMVehicleSpeed": lambda s: {
        "VehicleSpeed": s.speed_mps * MPH_PER_MPS,
        "VehicleSpeedLeft": s.speed_mps * MPH_PER_MPS,
    },
    "ECMEngineStatus": lambda s: {
        "CruiseActive": int(s.acc_engaged),
        "CruiseMainOn": int(s.acc_main_on),
        "BrakePressed": int(s.brake_pressed),
    },
    "ASCMActiveCruiseControlStatus": lambda s: {
        "ACCSpeedSetpoint": (s.set_speed_mph or 0) * KPH_PER_MPH if s.acc_engaged else 0,
        "ACCGapLevel": s.gap_setting,
        "ACCLeadCar": int(s.lead_present),
        "ACCCmdActive": int(s.acc_engaged),
        "ACCAlwaysOne": 1,
    },
    "ASCMSteeringButton": _gm_buttons,
    "AcceleratorPedal2": lambda s: {
        "AcceleratorPedal2": 120 if s.gas_pressed else 0,
        # opendbc's value table: 0 off, 1 active, 4 standstill (held for the driver)
        "CruiseState": (4 if s.standstill_held else 1) if s.acc_engaged else 0,
    },
}


def _toyota_cruise_state(s: CarSnapshot) -> int:
    """PCM_CRUISE CRUISE_STATE (opendbc's value table): 8 adaptive engaged, 11 the 3 s timer
    once stopped, 7 standstill (held for the driver), 0 off."""
    if not s.acc_engaged:
        return 0
    if s.standstill_held:
        return 7
    return 11 if s.standstill_timer else 8


TOYOTA: dict[str, SignalBuilder] = {
    "SPEED": lambda s: {"SPEED": s.speed_mps * KPH_PER_MPS},
    "PCM_CRUISE": lambda s: {
        "CRUISE_ACTIVE": int(s.acc_engaged),
        "GAS_RELEASED": int(not s.gas_pressed),
        "CRUISE_STATE": _toyota_cruise_state(s),
    },
    "PCM_CRUISE_2": lambda s: {
        "MAIN_ON": int(s.acc_main_on),
        "BRAKE_PRESSED": int(s.brake_pressed),
        "SET_SPEED": round((s.set_speed_mph or 0) * KPH_PER_MPH),
    },
    "BRAKE_MODULE": lambda s: {"BRAKE_PRESSED": int(s.brake_pressed)},
    "PCM_CRUISE_SM": lambda s: {
        "MAIN_ON": int(s.acc_main_on),
        "UI_SET_SPEED": s.set_speed_mph if s.acc_engaged and s.set_speed_mph else 0,
        "DISTANCE_LINES": s.gap_setting,
        "CRUISE_CONTROL_STATE": 6 if s.acc_engaged else 2,
    },
    "LEAD_INFO": lambda s: {
        "LEAD_LONG_DIST": s.lead_distance_m
        if s.lead_present and s.lead_distance_m
        else RAV4_NO_LEAD_DISTANCE_M,
        "LEAD_REL_SPEED": (s.lead_rel_speed_mps or 0.0) if s.lead_present else 0.0,
    },
}

FRAMES: dict[str, dict[str, SignalBuilder]] = {
    "nissan_rogue": NISSAN_ROGUE_2023,
    "nissan_rogue_2018": NISSAN_ROGUE_2018,
    "cadillac_xt5": GM,
    "toyota_rav4": TOYOTA,
}
