"""Lane-change recovery: smooth the base controller's output after a cut-in or cut-out.

Paper section "Acceleration-Based Controller: Lane-Change". The base controller is a black box
a_k; the output u_k equals a_k unless three criteria hold at a step:
1. a lane change is detected: the space gap jumps (a discontinuity beyond what the relative speed
   explains), or a leader appears;
2. it is significant: following a_k would take a jerk |a_k - u_{k-1}| / dt beyond a threshold;
3. it is safe: time to collision s/|dv| >= C_safe when closing (dv < 0), time gap s/v >= h_safe
   otherwise.
While active, u_k = alpha_k u_{k-1} + (1 - alpha_k) a_k with
alpha_k = c f1(s_k / v_k) + (1 - c) f2(dv_k, s_k), f1 = tanh(t* s/v), and the mechanism switches off
once |a_k - u_k| <= epsilon.

f2 for dv < 0. The printed form 1/2 tanh(dv* s/|dv|) + 1/2 is never below 1/2 (its argument is
positive), so it cannot be "close to 0 when the time to collision s/|dv| <= C_safe" as the text
requires. We implement that intent with the paper's parameters:
    f2 = 1/2 * (1/2 tanh(s/|dv| - dv*) + 1/2)      for dv < 0,
i.e. the printed tanh shifted so it is ~0 for any TTC <= C_safe = 4.5 s (4.5e-6 there) and 1/2 at
TTC = dv* = 10.3 s, then halved so f2 rises continuously to the dv >= 0 branch's value 1/2 at
dv = 0 and is non-decreasing in the relative speed, as the text asks of alpha_k.

Two additions, both on the side of safety: alpha is capped below 1 (`max_smoothing`, the paper
requires alpha < 1 but tanh rounds to 1.0 in floating point), and an active smoothing stops as
soon as the situation fails criterion 3, handing the base controller's own safety back at once.
"""

from __future__ import annotations

import math

from contract.controllers import LaneChangeParams
from vehicle_agent.controllers.base import Observation


def headway_factor(gap_m: float, speed_mps: float, t_star: float) -> float:
    """f1(s/v) = tanh(t* s/v); 1 when standing still."""
    if speed_mps <= 0.0:
        return 1.0
    return math.tanh(t_star * gap_m / speed_mps)


def relative_speed_factor(rel_speed_mps: float, gap_m: float, dv_star: float) -> float:
    """f2(dv, s): the stated intent for dv < 0 (see the module docstring), 1/2 tanh(dv) + 1/2
    for dv >= 0 as printed."""
    if rel_speed_mps < 0.0:
        ttc = gap_m / -rel_speed_mps
        return 0.5 * (0.5 * math.tanh(ttc - dv_star) + 0.5)
    return 0.5 * math.tanh(rel_speed_mps) + 0.5


def smoothing_factor(
    gap_m: float, speed_mps: float, rel_speed_mps: float, params: LaneChangeParams
) -> float:
    """alpha_k = c f1 + (1 - c) f2, capped at `max_smoothing`."""
    alpha = params.c * headway_factor(gap_m, speed_mps, params.t_star) + (
        1.0 - params.c
    ) * relative_speed_factor(rel_speed_mps, gap_m, params.dv_star)
    return min(alpha, params.max_smoothing)


def is_safe(gap_m: float, speed_mps: float, rel_speed_mps: float, params: LaneChangeParams) -> bool:
    """Criterion 3: TTC >= C_safe when closing, time gap >= h_safe otherwise."""
    if rel_speed_mps < 0.0:
        return gap_m / -rel_speed_mps >= params.safe_ttc_s
    if speed_mps <= 0.0:
        return True
    return gap_m / speed_mps >= params.safe_time_gap_s


class LaneChangeRecovery:
    """The stateful wrapper: feed it each step's observation and base command a_k, get u_k."""

    def __init__(self, params: LaneChangeParams) -> None:
        self.params = params
        self.reset()

    def reset(self) -> None:
        """Forget the previous step (no smoothing in progress)."""
        self.active = False
        self.activations = 0
        self._last_time_s: float | None = None
        self._last_gap_m: float | None = None
        self._last_rel_mps = 0.0
        self._last_output: float | None = None

    def is_gap_discontinuity(self, observation: Observation) -> bool:
        """Criterion 1: the gap jumped, or a leader appeared while we were driving."""
        if not observation.has_lead_state or self._last_time_s is None:
            return False
        if self._last_gap_m is None:
            return self._last_output is not None
        dt = max(observation.time_s - self._last_time_s, 0.0)
        expected = self._last_gap_m + self._last_rel_mps * dt
        return abs(float(observation.lead_distance_m) - expected) > self.params.gap_jump_m  # type: ignore[arg-type]

    def step(self, observation: Observation, command_mps2: float) -> float:
        """u_k for this step's base command a_k."""
        output = command_mps2
        if self.params.enabled and observation.has_lead_state and self._last_output is not None:
            gap = float(observation.lead_distance_m)  # type: ignore[arg-type]
            rel = float(observation.lead_rel_speed_mps)  # type: ignore[arg-type]
            speed = observation.speed_mps
            safe = is_safe(gap, speed, rel, self.params)
            if not self.active and self.is_gap_discontinuity(observation):
                last_time = observation.time_s if self._last_time_s is None else self._last_time_s
                dt = max(observation.time_s - last_time, 1e-3)
                jerk = abs(command_mps2 - self._last_output) / dt
                if jerk >= self.params.jerk_threshold_mps3 and safe:
                    self.active = True
                    self.activations += 1
            if self.active:
                if not safe:
                    self.active = False
                else:
                    alpha = smoothing_factor(gap, speed, rel, self.params)
                    output = alpha * self._last_output + (1.0 - alpha) * command_mps2
                    if abs(command_mps2 - output) <= self.params.epsilon_mps2:
                        self.active = False
        else:
            self.active = False
        self._last_time_s = observation.time_s
        if observation.has_lead_state:
            self._last_gap_m = float(observation.lead_distance_m)  # type: ignore[arg-type]
            self._last_rel_mps = float(observation.lead_rel_speed_mps)  # type: ignore[arg-type]
        else:
            self._last_gap_m = None
        self._last_output = output
        return output
