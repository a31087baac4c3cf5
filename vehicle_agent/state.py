"""Car state from CAN frames: decode, check, keep the latest of each watched message, judge
freshness. Common to every make; the make's `CarInterface` says what the signals mean.

A watched message is usable when its last good frame is younger than 10 periods, and no bad
frame of it arrived since: a wrong length, checksum or counter marks the state invalid in the
next snapshot at least, and until a good frame of that message follows. Frames of ids the make
does not watch are counted and ignored: a car's bus carries many messages the agent has no use
for, and the bus filters keep most of them out.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field

import can

from vehicle_agent.cars import STALE_PERIODS, CarInterface, CarState, MessageRule
from vehicle_agent.codec import Codec, FrameError
from vehicle_agent.logs import ThrottledLog

log = logging.getLogger(__name__)

# Plausible ego speed range (m/s): beyond it a decoded value is garbage. 70 m/s (157 mph) is
# over the top speed of every make the agent drives, and under the RAV4 DBC's 250 km/h range.
MAX_PLAUSIBLE_SPEED_MPS = 70.0
# No car on tyres changes its speed faster than about 1 g (emergency braking on dry asphalt):
# a speed reading further from the last trusted one than this allows in the time between them
# is a bad value that passed its frame's checks (a valid checksum over a wrong number), not
# the car. The margin covers the signal's resolution and the frames' timing.
MAX_SPEED_CHANGE_MPS2 = 10.0
SPEED_CHANGE_MARGIN_MPS = 0.5


@dataclass
class CanStats:
    """Frame counters for telemetry and tests."""

    frames: int = 0
    used: int = 0
    unknown_ids: int = 0
    errors: Counter[str] = field(default_factory=Counter)


class CarStateReader:
    """Turns the frames of one make into `CarState` snapshots."""

    def __init__(self, car: CarInterface, codec: Codec) -> None:
        self.car = car
        self.codec = codec
        self._rules: dict[int, tuple[str, MessageRule]] = {
            codec.frame_id(name): (name, rule) for name, rule in car.messages.items()
        }
        self.latest: dict[str, dict[str, float]] = {}
        self._received_at: dict[str, float] = {}
        self._last_counter: dict[str, int] = {}
        self._problems: dict[str, str] = {}
        self._reported: set[str] = set()
        self._unknown_seen: set[int] = set()
        # The last speed reading within reach of the one before it: (time, m/s).
        self._trusted_speed: tuple[float, float] | None = None
        self.stats = CanStats()
        self._log = ThrottledLog(log)

    @property
    def watched_ids(self) -> list[int]:
        """Arbitration ids of the watched messages (for the bus filters)."""
        return sorted(self._rules)

    def can_filters(self) -> list[dict[str, int | bool]]:
        """python-can filters passing only the watched standard ids."""
        return [
            {"can_id": frame_id, "can_mask": 0x7FF, "extended": False}
            for frame_id in self.watched_ids
        ]

    def ingest(self, frame: can.Message, time_s: float) -> None:
        """Fold one received frame in (bad frames are counted, logged and not used)."""
        self.stats.frames += 1
        entry = self._rules.get(frame.arbitration_id)
        if entry is None or frame.is_extended_id:
            self.stats.unknown_ids += 1
            if frame.arbitration_id not in self._unknown_seen:
                self._unknown_seen.add(frame.arbitration_id)
                log.info("ignoring CAN id %#x (not a watched message)", frame.arbitration_id)
            return
        name, rule = entry
        if frame.is_error_frame or frame.is_remote_frame:
            self._refuse(name, "decode", f"{name}: error or remote frame")
            return
        try:
            _, signals = self.codec.decode(frame.arbitration_id, frame.data)
        except FrameError as error:
            self._refuse(name, error.kind, str(error))
            return
        if rule.counter_signal is not None:
            counter = int(signals[rule.counter_signal])
            last = self._last_counter.get(name)
            self._last_counter[name] = counter
            received = self._received_at.get(name)
            recent = received is not None and time_s - received <= STALE_PERIODS * rule.period_s
            if last is not None and recent and counter != (last + 1) % rule.counter_modulo:
                self._refuse(name, "counter", f"{name}: counter {counter} after {last}")
                return
        self.latest[name] = signals
        self._received_at[name] = time_s
        if name in self._reported:
            self._problems.pop(name, None)
            self._reported.discard(name)
        self.stats.used += 1

    def received_at(self, name: str) -> float | None:
        """When the frame now in `latest[name]` was read (None: none yet), for a command
        frame that copies it (`CarInterface.copies_command_frame`) to judge its age."""
        return self._received_at.get(name)

    def _refuse(self, name: str, kind: str, message: str) -> None:
        self.stats.errors[kind] += 1
        self._problems[name] = message
        self._reported.discard(name)
        self._log.warning(kind, f"bad CAN frame ({kind}): {message}")

    def snapshot(self, time_s: float) -> CarState:
        """The car now; invalid (with the first problem found) unless every input is fresh."""
        if self._problems:
            self._reported.update(self._problems)
            name = next(iter(self._problems))
            return CarState(time_s, False, self._problems[name], None)
        for name, rule in self.car.messages.items():
            received = self._received_at.get(name)
            if received is None:
                return CarState(time_s, False, f"{name} not received yet", None)
            age = time_s - received
            if age > STALE_PERIODS * rule.period_s:
                return CarState(time_s, False, f"{name} missing for {age:.2f} s", None)
        try:
            reading = self.car.interpret(self.latest)
        except (KeyError, ValueError, TypeError) as error:
            return CarState(time_s, False, f"cannot interpret signals: {error}", None)
        speed = reading.speed_mps
        if not (math.isfinite(speed) and 0.0 <= speed <= MAX_PLAUSIBLE_SPEED_MPS):
            return CarState(time_s, False, f"implausible speed {speed} m/s", None)
        unreachable = self._unreachable_speed(time_s, speed)
        if unreachable is not None:
            return CarState(time_s, False, unreachable, None)
        return CarState(time_s, True, None, reading, dict(self._received_at))

    def _unreachable_speed(self, time_s: float, speed: float) -> str | None:
        """Why `speed` cannot be the car's, given the last trusted reading (None: it can).

        A jump beyond `MAX_SPEED_CHANGE_MPS2` leaves the trusted reading where it was, so a wrong
        value that persists stays refused until the time since the last trusted reading could
        have taken the car there; the car drives on its stock ACC meanwhile, and an `accel` car
        is not taken over above the fleet's top speed (`EngageInputs.within_commandable_speed`).
        """
        trusted = self._trusted_speed
        if trusted is not None:
            since, last = trusted
            reach = MAX_SPEED_CHANGE_MPS2 * max(time_s - since, 0.0) + SPEED_CHANGE_MARGIN_MPS
            if abs(speed - last) > reach:
                return (
                    f"speed {speed:.1f} m/s is out of reach of {last:.1f} m/s "
                    f"{time_s - since:.2f} s before"
                )
        self._trusted_speed = (time_s, speed)
        return None
