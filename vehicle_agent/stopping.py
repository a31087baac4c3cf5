"""Can the car still stop behind what it senses with the braking its actuation is allowed?

A stale plan can hold an AV at highway speed toward a stopped queue; when the radar first sees
the queue, the stop it needs may be harder than the controller may command (acceleration
requests are limited to -3 m/s^2, `AccelLimits`), or than a stock ACC brakes on its own. Then the
agent hands the car back at once: the driver (warned by the car's forward-collision alert) brakes
with the tyres' full grip. Checked every control step from the car's own sensors.

The braking a stop needs is the larger of two kinematic needs (constant decelerations):
- the leader holding its present speed v_l: the closing speed must vanish within the room left
  before the standstill margin, b_close = (v - v_l)^2 / (2 (d - s_margin)) when v > v_l;
- the leader braking at b_l > 0 (its speed's rate of change, as the radar measures it): the ego
  must stop behind where the leader stops, b_stop = v^2 / (2 (d - s_margin + v_l^2 / (2 b_l)))
  (the same kinematics as the paper's a_min.brake of MicroAccel).
Without the second, a leader braking hard right ahead is seen too late: the ego's ACC brakes
at its limit while the gap shrinks, and when the first need finally exceeds the authority the
closing speed is already more than the tyres can take back.
"""

from __future__ import annotations

import math

from contract.controllers import Actuation
from vehicle_agent.actuators import AccelLimits
from vehicle_agent.cars import CarReading
from vehicle_agent.controllers.microaccel import LeadAccelEstimator

# What the stock ACC brakes on its own (m/s^2): ISO 15622 limits an ACC's automatic
# deceleration to 3.5 m/s^2 (averaged over 2 s) at highway speed; harder stops are the
# driver's, after the forward-collision warning.
STOCK_ACC_MAX_BRAKING_MPS2 = 3.5
# Time constant (s) of the low-pass on the leader's finite-difference acceleration.
LEAD_ACCEL_FILTER_S = 0.5
# A stop aims to end this far short of the leader's bumper (m): the I-24 IDM's standstill gap.
STOP_MARGIN_M = 2.0


def braking_authority_mps2(actuation: Actuation) -> float:
    """The hardest braking (positive, m/s^2) the car makes while the agent drives it."""
    if actuation == "accel":
        return -AccelLimits().min_accel_mps2
    return STOCK_ACC_MAX_BRAKING_MPS2


# A leader slowing less than this (m/s^2) is not braking: its speed is held in the first need.
LEAD_BRAKING_MPS2 = 0.5
# Once a stop needed more than the authority, the check passes again only when the need is down
# to this share of it (hysteresis). The need near the threshold moves with the radar's range and
# the leader's braking estimated from successive speeds, and after the hand-back the stock ACC,
# braking up to 3.5 m/s^2 where an accel car's agent may 3, brings it down within the engage
# wait: without a margin, a need wandering 0.1 m/s^2 about 3 m/s^2 took the car back with a
# stop it could make only at its full authority and handed it back again (engage, hand back,
# engage, every engage wait: `test_a_stop_need_hovering_at_the_authority_...`). Half: the share
# the simulator's hand-back model has re-engaged at since it was written (`sim.platoon.HandBack`
# reads this constant), so the verdict's takeovers are the agent's; a car taken over has half
# its braking in hand (1.5 m/s^2 on an accel car, 1.75 on a button car).
STOP_NEED_RELEASE_SHARE = 0.5


def required_braking_mps2(
    speed_mps: float,
    lead_distance_m: float,
    lead_speed_mps: float,
    lead_accel_mps2: float = 0.0,
    margin_m: float = STOP_MARGIN_M,
) -> float:
    """max(b_close, b_stop) of the module docstring: inf when the room is gone while closing."""
    room = lead_distance_m - margin_m
    need = 0.0
    closing = speed_mps - lead_speed_mps
    if closing > 0.0:
        if room <= 0.0:
            return math.inf
        need = closing * closing / (2.0 * room)
    if lead_accel_mps2 < -LEAD_BRAKING_MPS2 and speed_mps > 0.0:
        lead_stop_m = lead_speed_mps * lead_speed_mps / (-2.0 * lead_accel_mps2)
        stop_room = room + lead_stop_m
        if stop_room <= 0.0:
            return math.inf
        need = max(need, speed_mps * speed_mps / (2.0 * stop_room))
    return need


def stop_exceeds_authority(
    speed_mps: float,
    lead_distance_m: float | None,
    lead_speed_mps: float | None,
    authority: float,
    lead_accel_mps2: float = 0.0,
) -> bool:
    """True when the leader the radar measures needs harder braking than `authority`.

    Makes that only flag a leader (no distance or speed decoded) cannot be checked here: their
    stock ACC does the braking, with its own warning to the driver.
    """
    if lead_distance_m is None or lead_speed_mps is None:
        return False
    if not (math.isfinite(lead_distance_m) and math.isfinite(lead_speed_mps)):
        return False
    need = required_braking_mps2(speed_mps, lead_distance_m, lead_speed_mps, lead_accel_mps2)
    return need > authority


class StoppingCheck:
    """The agent's check each control step: the radar's leader, its braking estimated from
    successive lead speeds (finite difference, low-passed as MicroAccel does), with hysteresis
    (STOP_NEED_RELEASE_SHARE) once a stop has exceeded the authority."""

    def __init__(self, actuation: Actuation) -> None:
        self.authority = braking_authority_mps2(actuation)
        self.lead_accel = LeadAccelEstimator(LEAD_ACCEL_FILTER_S)
        # A stop behind the leader measured now needed more than the authority, and its need
        # has not yet fallen to the release share.
        self.exceeded = False

    def needs_hand_back(self, time_s: float, reading: CarReading | None) -> bool:
        """True when the reading asks for a stop beyond the actuation's authority, or, after
        one did, beyond its release share. No leader (lost, gone) ends it: what follows is a
        new situation."""
        if reading is None or not reading.lead_present or reading.lead_rel_speed_mps is None:
            self.lead_accel.reset()
            self.exceeded = False
            return False
        lead_speed = reading.speed_mps + reading.lead_rel_speed_mps
        gap = reading.lead_distance_m
        limit = self.authority * (STOP_NEED_RELEASE_SHARE if self.exceeded else 1.0)
        self.exceeded = stop_exceeds_authority(
            reading.speed_mps,
            gap,
            lead_speed,
            limit,
            self.lead_accel.update(time_s, lead_speed, gap),
        )
        return self.exceeded
