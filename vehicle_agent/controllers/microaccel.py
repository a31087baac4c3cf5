"""MicroAccel: the paper's acceleration-based base controller, a_cmd = min(a_safe, a_target, a_MPC).

Paper section "Acceleration-Based Controller: Base Control" (eq. a_cmd, eq. a_safe / v_safe,
eq. a_target, eq. a_MPC with a_min.brake, P1, P2). The terms are pure functions of floats so the
simulator and the tests can evaluate them directly; `MicroAccelController` adds the state they need
(the leader's acceleration, estimated from successive lead speeds) and the lane-change recovery
wrapper of `lane_change.py`.

Guards the printed equations leave open (each only matters in a degenerate state):
- a gap at or below the standstill distance s0 uses a 0.1 m margin instead of dividing by <= 0;
- the ratio v / v_lead uses a lead speed of at least 0.1 m/s.
"""

from __future__ import annotations

import math

from contract.controllers import Actuation, MicroAccelParams
from vehicle_agent.controllers.base import AccelCommand, Controller, Observation
from vehicle_agent.controllers.lane_change import LaneChangeRecovery

# Smallest gap margin h - s0 (m) and lead speed (m/s) used in divisions (see module docstring).
MIN_GAP_MARGIN_M = 0.1
MIN_LEAD_SPEED_MPS = 0.1
# A gap that jumps by more than this between two readings (m) is a new leader (a cut-in or a
# lane change), not a braking one: its speed step says nothing about its acceleration. The
# lane-change recovery's own discontinuity threshold (`LaneChangeParams.gap_jump_m`).
NEW_LEADER_GAP_JUMP_M = 4.0


def safe_speed(
    gap_m: float,
    lead_speed_mps: float,
    *,
    standstill_gap_m: float,
    min_accel_mps2: float,
    lead_min_accel_mps2: float,
) -> float:
    """v_safe: the fastest speed from which braking at a_min stops behind a leader braking at
    a_l,min (paper eq. a_safe, second line)."""
    room = gap_m - standstill_gap_m + 0.5 * lead_speed_mps**2 / abs(lead_min_accel_mps2)
    return math.sqrt(2.0 * abs(min_accel_mps2) * max(room, 0.0))


def safe_speed_rate(
    safe_speed_mps: float,
    rel_speed_mps: float,
    lead_speed_mps: float,
    lead_accel_mps2: float,
    *,
    min_accel_mps2: float,
    lead_min_accel_mps2: float,
) -> float:
    """d v_safe / dt, differentiated analytically from v_safe with dh/dt = v_lead - v.

    The analytic form avoids the spikes a finite difference would take from radar jumps.
    """
    if safe_speed_mps <= 0.0:
        return 0.0
    room_rate = rel_speed_mps + lead_speed_mps * lead_accel_mps2 / abs(lead_min_accel_mps2)
    return abs(min_accel_mps2) * room_rate / safe_speed_mps


def safety_accel(
    speed_mps: float, safe_speed_mps: float, safe_speed_rate_mps2: float, k: float
) -> float:
    """a_safe = -k (v - v_safe) + dv_safe/dt (paper eq. a_safe, first line)."""
    return -k * (speed_mps - safe_speed_mps) + safe_speed_rate_mps2


def safety_term(
    speed_mps: float,
    gap_m: float,
    rel_speed_mps: float,
    lead_accel_mps2: float,
    *,
    k: float,
    standstill_gap_m: float,
    min_accel_mps2: float,
    lead_min_accel_mps2: float,
) -> float:
    """a_safe from what the radar measures: v_safe, its rate, then -k (v - v_safe) + dv_safe/dt
    (paper eq. a_safe)."""
    lead_speed = max(speed_mps + rel_speed_mps, 0.0)
    v_safe = safe_speed(
        gap_m,
        lead_speed,
        standstill_gap_m=standstill_gap_m,
        min_accel_mps2=min_accel_mps2,
        lead_min_accel_mps2=lead_min_accel_mps2,
    )
    rate = safe_speed_rate(
        v_safe,
        rel_speed_mps,
        lead_speed,
        lead_accel_mps2,
        min_accel_mps2=min_accel_mps2,
        lead_min_accel_mps2=lead_min_accel_mps2,
    )
    return safety_accel(speed_mps, v_safe, rate, k)


def target_accel(speed_mps: float, target_speed_mps: float, k: float) -> float:
    """a_target = -k (v - v_target) (paper eq. a_target)."""
    return -k * (speed_mps - target_speed_mps)


def min_brake_accel(
    gap_m: float,
    speed_mps: float,
    lead_speed_mps: float,
    lead_accel_mps2: float,
    standstill_gap_m: float,
) -> float:
    """a_min.brake: the constant deceleration that stops the ego where a leader braking at
    a_lead (< 0) stops, s0 behind it (paper eq. for a_min.brake, P1, P2)."""
    room = gap_m - standstill_gap_m + 0.5 * lead_speed_mps**2 / (-lead_accel_mps2)
    return -(speed_mps**2 / 2.0) / max(room, MIN_GAP_MARGIN_M)


def anticipation_accel(
    gap_m: float,
    speed_mps: float,
    lead_speed_mps: float,
    lead_accel_mps2: float,
    *,
    standstill_gap_m: float,
    k2: float,
    max_accel_mps2: float,
) -> float:
    """a_MPC, the anticipation term: five cases on P1, P2 and the sign of a_lead (eq. a_MPC)."""
    closing = lead_speed_mps - speed_mps  # P2
    margin = max(gap_m - standstill_gap_m, MIN_GAP_MARGIN_M)
    match_decel = speed_mps - lead_speed_mps
    if lead_accel_mps2 < 0.0:
        brake = min_brake_accel(gap_m, speed_mps, lead_speed_mps, lead_accel_mps2, standstill_gap_m)
        proportional = lead_accel_mps2 * speed_mps / max(lead_speed_mps, MIN_LEAD_SPEED_MPS)
        p1 = brake - proportional
        if p1 > 0.0:
            return brake
        if closing >= 0.0:
            return proportional
        return lead_accel_mps2 - match_decel**2 / (2.0 * margin)
    if closing < 0.0:
        return lead_accel_mps2 - match_decel**2 / (2.0 * margin)
    return min(max_accel_mps2, lead_accel_mps2 * (1.0 + k2 * closing))


def is_new_leader(last_gap_m: float | None, gap_m: float | None) -> bool:
    """True when the gap jumped as it does when another car becomes the leader."""
    if last_gap_m is None or gap_m is None:
        return False
    return abs(gap_m - last_gap_m) > NEW_LEADER_GAP_JUMP_M


class LeadAccelEstimator:
    """The leader's acceleration from successive lead speeds: finite difference, then a first-order
    low-pass with time constant `filter_s` (the cars report lead speed, not its acceleration).

    One leader's: a gap that jumps (`is_new_leader`) starts the estimate afresh. Otherwise a car
    cutting in slower than the old leader reads as that leader braking hard, and a_safe's rate
    term brakes the AV for a car that is no threat."""

    def __init__(self, filter_s: float) -> None:
        self.filter_s = filter_s
        self.reset()

    def reset(self) -> None:
        """Forget the leader (a new one appeared or it was lost)."""
        self._last_time_s: float | None = None
        self._last_speed_mps = 0.0
        self._last_gap_m: float | None = None
        self.accel_mps2 = 0.0

    def update(self, time_s: float, lead_speed_mps: float, gap_m: float | None) -> float:
        """Fold in one sample of the leader's speed and gap (None: not measured); returns the
        filtered acceleration."""
        if is_new_leader(self._last_gap_m, gap_m):
            self.reset()
        self._last_gap_m = gap_m
        if self._last_time_s is not None and time_s > self._last_time_s:
            dt = time_s - self._last_time_s
            raw = (lead_speed_mps - self._last_speed_mps) / dt
            weight = dt / (self.filter_s + dt)
            self.accel_mps2 += weight * (raw - self.accel_mps2)
        self._last_time_s = time_s
        self._last_speed_mps = lead_speed_mps
        return self.accel_mps2


def base_accel(observation: Observation, lead_accel_mps2: float, params: MicroAccelParams) -> float:
    """a_cmd = min(a_safe, a_target, a_MPC), clipped to [a_min, a_max] (paper eq. a_cmd).

    Without a measured leader only the target term applies.
    """
    speed = observation.speed_mps
    command = target_accel(speed, observation.target_speed_mps, params.k)
    if observation.has_lead_state:
        gap = float(observation.lead_distance_m)  # type: ignore[arg-type]
        rel = float(observation.lead_rel_speed_mps)  # type: ignore[arg-type]
        lead_speed = max(speed + rel, 0.0)
        v_safe = safe_speed(
            gap,
            lead_speed,
            standstill_gap_m=params.standstill_gap_m,
            min_accel_mps2=params.min_accel_mps2,
            lead_min_accel_mps2=params.lead_min_accel_mps2,
        )
        v_safe_rate = safe_speed_rate(
            v_safe,
            rel,
            lead_speed,
            lead_accel_mps2,
            min_accel_mps2=params.min_accel_mps2,
            lead_min_accel_mps2=params.lead_min_accel_mps2,
        )
        command = min(
            command,
            safety_accel(speed, v_safe, v_safe_rate, params.k),
            anticipation_accel(
                gap,
                speed,
                lead_speed,
                lead_accel_mps2,
                standstill_gap_m=params.standstill_gap_m,
                k2=params.k2,
                max_accel_mps2=params.max_accel_mps2,
            ),
        )
    return min(max(command, params.min_accel_mps2), params.max_accel_mps2)


class MicroAccelController(Controller):
    """MicroAccel with lane-change recovery (actuation `accel`)."""

    name = "microaccel"

    def __init__(self, actuation: Actuation, params: MicroAccelParams) -> None:
        super().__init__(actuation)
        self.params = params
        self.lead_accel = LeadAccelEstimator(params.lead_accel_filter_s)
        self.recovery = LaneChangeRecovery(params.lane_change)

    def reset(self) -> None:
        """Forget the leader and any recovery in progress."""
        self.lead_accel.reset()
        self.recovery.reset()

    def step(self, observation: Observation) -> AccelCommand:
        """One control period: base command, then lane-change smoothing."""
        if observation.has_lead_state:
            if self.recovery.is_gap_discontinuity(observation):
                self.lead_accel.reset()
            lead_speed = observation.speed_mps + float(observation.lead_rel_speed_mps)  # type: ignore[arg-type]
            gap = float(observation.lead_distance_m)  # type: ignore[arg-type]
            lead_accel = self.lead_accel.update(observation.time_s, lead_speed, gap)
        else:
            self.lead_accel.reset()
            lead_accel = 0.0
        command = base_accel(observation, lead_accel, self.params)
        return AccelCommand(self.recovery.step(observation, command))
