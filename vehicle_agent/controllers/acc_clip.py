"""The paper's post-facto clip on every ACC speed setting (section "ACC-Based Controller").

v_lower = mean of the last 1 s of ego speeds (10 steps at 10 Hz, 0 mph and missing samples
omitted) - 15 mph, v_upper = that mean + 5 mph; v_clip = min(max(v_action, v_lower), v_upper);
v_final = min(max(v_clip, 20 mph), 73 mph). The printed sum is divided by 10; with samples
omitted we average the samples that remain, which is what "omitted" means for a mean. The car
takes whole mph, so v_final is rounded to the nearest mph after the clip (half up).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable

from contract.controllers import FLEET_TOP_SPEED_MPH
from contract.units import mps_to_mph
from vehicle_agent.controllers.base import (
    AccSetPoint,
    Action,
    Controller,
    NonFiniteAction,
    Observation,
)

CLIP_WINDOW_STEPS = 10  # the last 1 s at the 10 Hz control rate
# The window is also the last second by time: speeds from before a hand-back are not "the last
# second" at the next take-over (the controller steps only while it commands the car).
CLIP_WINDOW_S = 1.0
BELOW_MEAN_MPH = 15.0
ABOVE_MEAN_MPH = 5.0
MIN_SETTING_MPH = 20.0
# 73 mph: modest speeds above the 70 mph posted limit (paper).
MAX_SETTING_MPH = FLEET_TOP_SPEED_MPH


def clip_speed_setting(action_mph: float, recent_speeds_mph: Iterable[float | None]) -> int:
    """v_final for a requested speed setting, given the last second of ego speeds (paper eq.).

    A request that is not a number raises `NonFiniteAction`: the clip bounds a decision, it does
    not make one up.
    """
    if not math.isfinite(action_mph):
        raise NonFiniteAction(f"speed setting request {action_mph} mph")
    valid = [s for s in recent_speeds_mph if s is not None and math.isfinite(s) and s != 0.0]
    value = action_mph
    if valid:
        mean = sum(valid) / len(valid)
        value = min(max(value, mean - BELOW_MEAN_MPH), mean + ABOVE_MEAN_MPH)
    value = min(max(value, MIN_SETTING_MPH), MAX_SETTING_MPH)
    return int(math.floor(value + 0.5))


class AccClip(Controller):
    """Wraps any `acc` controller: records ego speeds and clips its speed setting."""

    name = "acc_clip"

    def __init__(self, inner: Controller) -> None:
        super().__init__(inner.actuation)
        self.inner = inner
        self._speeds: deque[tuple[float, float | None]] = deque(maxlen=CLIP_WINDOW_STEPS)

    def reset(self) -> None:
        """Reset the wrapped controller (the speed history ages out by itself: the window is
        the last second of measurements, whenever they were taken)."""
        self.inner.reset()

    @property
    def speeds_mph(self) -> list[float | None]:
        """The ego speeds of the clip's window, oldest first."""
        return [speed for _, speed in self._speeds]

    @property
    def policy_sha256(self) -> str | None:
        """The wrapped controller's policy."""
        return self.inner.policy_sha256

    def step(self, observation: Observation) -> Action:
        """The inner controller's set point with the paper's clip applied."""
        speed = observation.speed_mps
        now = observation.time_s
        while self._speeds and now - self._speeds[0][0] > CLIP_WINDOW_S + 1e-9:
            self._speeds.popleft()
        self._speeds.append((now, mps_to_mph(speed) if math.isfinite(speed) else None))
        action = self.inner.step(observation)
        if not isinstance(action, AccSetPoint):
            raise TypeError(f"controller {self.inner.name} returned {action!r} for actuation acc")
        return AccSetPoint(
            clip_speed_setting(action.requested_speed_mph, self.speeds_mph),
            action.gap_setting,
            requested_speed_mph=action.requested_speed_mph,
        )
