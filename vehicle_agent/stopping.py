"""Can the car still stop behind what it senses with the braking its actuation is allowed?

A stale plan can hold an AV at highway speed toward a stopped queue; when the radar first sees
the queue, the stop it needs may be harder than the controller may command (acceleration
requests are limited to -3 m/s^2, `AccelLimits`), or than a stock ACC brakes on its own. Then the
agent hands the car back at once: the driver (warned by the car's forward-collision alert) brakes
with the tyres' full grip. Checked every control step from the car's own sensors.

The braking a stop needs, with the leader holding its present speed v_l and the ego braking
constantly from v: the closing speed v - v_l must vanish within the room left before the
standstill margin, so

    b_need = (v - v_l)^2 / (2 (d - s_margin))      when v > v_l, else 0.
"""

from __future__ import annotations

import math

from contract.controllers import Actuation
from vehicle_agent.actuators import AccelLimits
from vehicle_agent.cars import CarReading

# What the stock ACC brakes on its own (m/s^2): ISO 15622 limits an ACC's automatic
# deceleration to 3.5 m/s^2 (averaged over 2 s) at highway speed; harder stops are the
# driver's, after the forward-collision warning.
STOCK_ACC_MAX_BRAKING_MPS2 = 3.5
# A stop aims to end this far short of the leader's bumper (m): the I-24 IDM's standstill gap.
STOP_MARGIN_M = 2.0


def braking_authority_mps2(actuation: Actuation) -> float:
    """The hardest braking (positive, m/s^2) the car makes while the agent drives it."""
    if actuation == "accel":
        return -AccelLimits().min_accel_mps2
    return STOCK_ACC_MAX_BRAKING_MPS2


def required_braking_mps2(
    speed_mps: float, lead_distance_m: float, lead_speed_mps: float, margin_m: float = STOP_MARGIN_M
) -> float:
    """b_need (module docstring): inf when the room is already gone while closing."""
    closing = speed_mps - lead_speed_mps
    if closing <= 0.0:
        return 0.0
    room = lead_distance_m - margin_m
    if room <= 0.0:
        return math.inf
    return closing * closing / (2.0 * room)


def stop_exceeds_authority(
    speed_mps: float, lead_distance_m: float | None, lead_speed_mps: float | None, authority: float
) -> bool:
    """True when the leader the radar measures needs harder braking than `authority`.

    Makes that only flag a leader (no distance or speed decoded) cannot be checked here: their
    stock ACC does the braking, with its own warning to the driver.
    """
    if lead_distance_m is None or lead_speed_mps is None:
        return False
    if not (math.isfinite(lead_distance_m) and math.isfinite(lead_speed_mps)):
        return False
    return required_braking_mps2(speed_mps, lead_distance_m, lead_speed_mps) > authority


def reading_needs_hand_back(reading: CarReading | None, actuation: Actuation) -> bool:
    """True when the car's radar reading asks for a stop beyond the actuation's authority."""
    if reading is None or not reading.lead_present or reading.lead_rel_speed_mps is None:
        return False
    return stop_exceeds_authority(
        reading.speed_mps,
        reading.lead_distance_m,
        reading.speed_mps + reading.lead_rel_speed_mps,
        braking_authority_mps2(actuation),
    )
