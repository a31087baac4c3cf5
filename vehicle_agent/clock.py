"""Time for the agent, injected: a monotonic clock for control and a wall clock (the car's
GPS-disciplined system clock) for the timestamps it reports.

A CAN frame carries the time it was received, in the wall clock's seconds since the epoch
(SocketCAN stamps each frame in the kernel, `SO_TIMESTAMPNS`). The agent dates a frame by it, not
by the pass that reads it: after a stalled pass the frames queued before the stall are as old as
they are, and a car gone silent meanwhile is seen to be. A wall clock stepped forward between
receipt and reading (NTP) makes the frames read across the step look old once: the agent then
hands back on stale inputs, the safe side.
"""

from __future__ import annotations

import threading
import time
from datetime import UTC, datetime, timedelta
from typing import Protocol


class Clock(Protocol):
    """Monotonic seconds for control, aware UTC datetimes for reports."""

    def monotonic(self) -> float:
        """Seconds from an arbitrary origin, never going backwards."""

    def now(self) -> datetime:
        """The wall-clock time (UTC)."""


def frame_age(now_epoch_s: float, received_epoch_s: float) -> float:
    """Seconds from a frame's receipt to `now_epoch_s` (the pass's wall-clock reading), both
    epoch seconds; 0 for a frame no interface stamped (python-can's default 0.0) and for one
    stamped after it (received during the pass, or the wall clock stepped back since): such a
    frame is as new as the pass reading it. An emulated car on a simulated clock stamps its
    frames with that clock's wall time (`sim.emulator.car.CarEmulator`'s `frame_epoch_s`)."""
    if received_epoch_s <= 0.0:
        return 0.0
    return max(0.0, now_epoch_s - received_epoch_s)


class SystemClock:
    """The machine's clocks."""

    def monotonic(self) -> float:
        """time.monotonic()."""
        return time.monotonic()

    def now(self) -> datetime:
        """datetime.now(UTC)."""
        return datetime.now(UTC)


class ManualClock:
    """A clock that moves only when told to (tests, simulation): both clocks move together."""

    def __init__(self, start: datetime | None = None, monotonic_s: float = 0.0) -> None:
        self._start_wall = start or datetime(2024, 1, 1, tzinfo=UTC)
        self._start_mono = monotonic_s
        self._mono = monotonic_s
        self._lock = threading.Lock()

    def monotonic(self) -> float:
        """The simulated monotonic time."""
        return self._mono

    def now(self) -> datetime:
        """The simulated wall time."""
        return self._start_wall + timedelta(seconds=self._mono - self._start_mono)

    def advance(self, seconds: float) -> None:
        """Move both clocks forward."""
        with self._lock:
            self._mono += seconds

    def step_wall(self, seconds: float) -> None:
        """Step the wall clock alone, as NTP does (backwards for negative seconds)."""
        with self._lock:
            self._start_wall += timedelta(seconds=seconds)

    def set(self, monotonic_s: float) -> None:
        """Jump to a monotonic time (never backwards)."""
        with self._lock:
            self._mono = max(self._mono, monotonic_s)
