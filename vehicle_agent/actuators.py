"""Acting on the car: ACC button presses (actuation `acc`) and acceleration requests (`accel`).

`ButtonSequencer` turns a requested (speed setting, gap bars) into presses, the way the field
team pressed the Rogue's buttons: gap first (it has priority over speed), then +/-5 mph holds
while 5 mph or more away, then +/-1 mph presses; about 0.25 s pressed and 0.25 s released per
press; every press is confirmed from the car's own CAN feedback (the set speed and gap bars it
reports) before the next, and after `max_retries` unconfirmed presses in a row it stops and says
so. It is pure: time and the car's feedback come in, the button to hold now goes out. A
`ButtonPort` realises the held button: as the make's button frames on CAN or on a GPIO button board
(ports.py), behind the safety layer.

`AccelLimiter` bounds acceleration requests to [-3, 1.5] m/s^2, keeps the car under the fleet's
top speed and limits jerk, before the safety layer re-checks every frame.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from contract.controllers import (
    AGENT_MAX_ACCEL_MPS2,
    AGENT_MIN_ACCEL_MPS2,
    FLEET_TOP_SPEED_MPS,
    MAX_GAP_SETTING,
    MIN_GAP_SETTING,
)
from vehicle_agent.cars import CruiseButton

# One press of the gap button moves to the next shorter gap, from the shortest back to the
# longest (3 -> 2 -> 1 -> 3), as the cars' steering-wheel button cycles its bars.


def next_gap_setting(gap: int) -> int:
    """The gap bars after one press of the gap button."""
    return MAX_GAP_SETTING if gap <= MIN_GAP_SETTING else gap - 1


# The cars' ACC: a press shorter than this changes the set speed by 1 mph on release; holding
# it this long changes it by 5 mph (and by 5 more every further LONG_PRESS_S held).
LONG_PRESS_S = 0.6
SHORT_STEP_MPH = 1
LONG_STEP_MPH = 5


@dataclass(frozen=True)
class SequencerTiming:
    """Press timing (s) and the retry bound."""

    press_s: float = 0.25
    release_s: float = 0.25
    # A hold for one 5 mph step: past LONG_PRESS_S, well before a second step at 2 x LONG_PRESS_S.
    hold_s: float = 0.9
    # After the release, how long to wait for the car to report the change.
    confirm_s: float = 0.5
    max_retries: int = 3


class Phase(enum.Enum):
    """Where the sequencer is in a press."""

    IDLE = "idle"
    PRESSED = "pressed"
    RELEASED = "released"


@dataclass(frozen=True)
class Expectation:
    """What the car should report after the current press."""

    speed_mph: float | None = None
    gap: int | None = None

    def met(self, speed_mph: float | None, gap: int | None) -> bool:
        """True once the car reports the expected set point."""
        if self.gap is not None:
            return gap == self.gap
        return (
            speed_mph is not None
            and self.speed_mph is not None
            and round(speed_mph) == round(self.speed_mph)
        )


class ButtonSequencer:
    """Requested set points -> the button to hold now (None: all released)."""

    def __init__(self, timing: SequencerTiming | None = None) -> None:
        self.timing = timing or SequencerTiming()
        self.target_speed_mph: int | None = None
        self.target_gap: int | None = None
        self.phase = Phase.IDLE
        self.button: CruiseButton | None = None
        self.presses = 0
        self.unconfirmed = 0
        self.stalled = False
        self._phase_started = 0.0
        self._press_length = 0.0
        self._expectation: Expectation | None = None

    def request(self, speed_mph: int, gap: int) -> None:
        """Aim at a new set point (a change also clears a stall)."""
        if (speed_mph, gap) != (self.target_speed_mph, self.target_gap):
            self.stalled = False
            self.unconfirmed = 0
        self.target_speed_mph = speed_mph
        self.target_gap = gap

    def stop(self) -> None:
        """Release at once and forget the request (hand back to the stock ACC)."""
        self.target_speed_mph = None
        self.target_gap = None
        self.phase = Phase.IDLE
        self.button = None
        self._expectation = None

    def pause(self) -> None:
        """Release at once and press nothing until `step` is called again, keeping the request
        and the count of unconfirmed presses: the car takes no press now (its ACC holds a
        standstill for the driver, who alone may resume it). A press cut short is neither
        confirmed nor counted."""
        self.phase = Phase.IDLE
        self.button = None
        self._expectation = None

    def step(self, now: float, speed_mph: float | None, gap: int | None) -> CruiseButton | None:
        """Advance to `now` given the car's reported set speed and gap; the button to hold."""
        if self.phase is Phase.PRESSED:
            if now - self._phase_started < self._press_length:
                return self.button
            self.phase, self._phase_started = Phase.RELEASED, now
            return None
        if self.phase is Phase.RELEASED:
            waited = now - self._phase_started
            expectation = self._expectation
            if (
                expectation is not None
                and expectation.met(speed_mph, gap)
                and (waited >= self.timing.release_s)
            ):
                self.unconfirmed = 0
            elif waited < self.timing.release_s + self.timing.confirm_s:
                return None
            else:
                self.unconfirmed += 1
                if self.unconfirmed >= self.timing.max_retries:
                    self.stalled = True
            self.phase, self.button, self._expectation = Phase.IDLE, None, None
        return self._start_press(now, speed_mph, gap)

    def _start_press(
        self, now: float, speed_mph: float | None, gap: int | None
    ) -> CruiseButton | None:
        if self.stalled or self.target_speed_mph is None or speed_mph is None or gap is None:
            return None
        if self.target_gap is not None and gap != self.target_gap:
            return self._press(
                now, CruiseButton.GAP, self.timing.press_s, Expectation(gap=next_gap_setting(gap))
            )
        difference = self.target_speed_mph - round(speed_mph)
        if difference == 0:
            return None
        button = CruiseButton.PLUS if difference > 0 else CruiseButton.MINUS
        sign = 1 if difference > 0 else -1
        if abs(difference) >= LONG_STEP_MPH:
            expected = round(speed_mph) + sign * LONG_STEP_MPH
            return self._press(now, button, self.timing.hold_s, Expectation(speed_mph=expected))
        expected = round(speed_mph) + sign * SHORT_STEP_MPH
        return self._press(now, button, self.timing.press_s, Expectation(speed_mph=expected))

    def _press(
        self, now: float, button: CruiseButton, length_s: float, expectation: Expectation
    ) -> CruiseButton:
        self.phase, self._phase_started, self._press_length = Phase.PRESSED, now, length_s
        self.button, self._expectation = button, expectation
        self.presses += 1
        return button


@dataclass(frozen=True)
class AccelLimits:
    """Acceleration request limits: the issue's [-3, 1.5] m/s^2, the fleet's top speed and
    comfort jerk limits."""

    min_accel_mps2: float = AGENT_MIN_ACCEL_MPS2
    max_accel_mps2: float = AGENT_MAX_ACCEL_MPS2
    # Jerk (m/s^3): rising gently (ISO 15622 ACC comfort ~2.5), falling twice as fast so a
    # safety braking reaches -3 m/s^2 within 0.6 s.
    max_jerk_up_mps3: float = 2.5
    max_jerk_down_mps3: float = 5.0
    # No request may take the car over the fleet's top speed: an `accel` car has no ACC setting
    # to hold it there, and a controller that asks to accelerate with nothing in radar range
    # (the shipped rl_accel asks +0.1 to +0.5 m/s^2 whatever the plan's target) would otherwise
    # drive on past it. Under the top a request is at most (top - v) / `top_speed_approach_s`,
    # so the car closes on the top as a first-order lag and settles on it instead of
    # overshooting; 2 s makes that 0.22 m/s^2 at 1 mph under it and leaves every request below
    # 66 mph untouched. Over it (downhill) the request slows the car back, by at most
    # `over_top_speed_decel_mps2`: returning to the top is no emergency, and any harder braking
    # a leader needs is the controller's own request, which the limiter keeps.
    top_speed_mps: float = FLEET_TOP_SPEED_MPS
    top_speed_approach_s: float = 2.0
    over_top_speed_decel_mps2: float = 1.0

    def speed_gain_while_easing_off_mps(self, accel_mps2: float) -> float:
        """The speed a car accelerating at `accel_mps2` may still gain once taken over, while
        the requests, starting from that acceleration, fall to 0 at `max_jerk_down_mps3`: the
        whole ramp's time at the starting acceleration, a^2 / jerk. That is twice what a car
        following its request at once gains, which covers the car's lag behind its request."""
        accelerating = max(accel_mps2, 0.0)
        return accelerating * accelerating / self.max_jerk_down_mps3

    def top_speed_accel_mps2(self, speed_mps: float) -> float:
        """The most a request may ask for at `speed_mps` to keep the car under the top speed."""
        toward_top = (self.top_speed_mps - speed_mps) / self.top_speed_approach_s
        return max(toward_top, -self.over_top_speed_decel_mps2)


class AccelLimiter:
    """Clamp and jerk-limit acceleration requests.

    A request that is not a number is a `ValueError`: the agent refuses one as its controller's
    failure before it gets here (`require_finite`), and inventing a value for it here would
    command the car with a figure no controller chose.
    """

    def __init__(self, limits: AccelLimits | None = None) -> None:
        self.limits = limits or AccelLimits()
        self._last: tuple[float, float] | None = None

    def reset(self, accel_mps2: float | None = None, now: float | None = None) -> None:
        """Start again from the car's current acceleration (None: from no reference)."""
        self._last = None if accel_mps2 is None or now is None else (now, accel_mps2)

    @property
    def reference_mps2(self) -> float | None:
        """The acceleration the next request's jerk limits start from: the last one let
        through, or the one `reset` started from (None: no reference)."""
        return None if self._last is None else self._last[1]

    def limit(self, now: float, requested_mps2: float, *, speed_mps: float) -> float:
        """The request as it may be sent now, with the car at `speed_mps`."""
        limits = self.limits
        if not math.isfinite(requested_mps2):
            raise ValueError(f"acceleration request {requested_mps2} m/s^2 is not a number")
        if not math.isfinite(speed_mps):
            raise ValueError(f"speed {speed_mps} m/s is not a number")
        value = min(requested_mps2, limits.top_speed_accel_mps2(speed_mps))
        value = min(max(value, limits.min_accel_mps2), limits.max_accel_mps2)
        if self._last is not None:
            last_time, last_value = self._last
            dt = max(now - last_time, 0.0)
            value = min(
                max(value, last_value - limits.max_jerk_down_mps3 * dt),
                last_value + limits.max_jerk_up_mps3 * dt,
            )
            # The range wins over the jerk limit: starting from a measured acceleration outside
            # it (a car accelerating hard when taken over) must not carry the request out too.
            value = min(max(value, limits.min_accel_mps2), limits.max_accel_mps2)
        self._last = (now, value)
        return value
