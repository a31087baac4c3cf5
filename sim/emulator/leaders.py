"""Leaders for the emulated car: where the vehicle ahead is (its rear bumper) and how fast."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike


class Leader(Protocol):
    """The vehicle ahead, as a function of simulation time."""

    def state(self, time_s: float) -> tuple[float, float]:
        """(position of its rear bumper along the road in m, speed in m/s) at `time_s`."""


class ConstantSpeedLeader:
    """A leader at `position_m` at time `start_s`, driving at a constant speed."""

    def __init__(self, position_m: float, speed_mps: float, start_s: float = 0.0) -> None:
        self.position_m = position_m
        self.speed_mps = speed_mps
        self.start_s = start_s

    def state(self, time_s: float) -> tuple[float, float]:
        """Position and speed at `time_s`."""
        return self.position_m + self.speed_mps * (time_s - self.start_s), self.speed_mps


class SpeedProfileLeader:
    """A leader replaying a speed profile (e.g. a real I-24 drive at 10 Hz), starting at
    `position_m` at the profile's first time; it keeps its last speed past the end."""

    def __init__(self, times_s: ArrayLike, speeds_mps: ArrayLike, position_m: float) -> None:
        self.times = np.asarray(times_s, dtype=np.float64)
        self.speeds = np.asarray(speeds_mps, dtype=np.float64)
        if len(self.times) < 2 or np.any(np.diff(self.times) <= 0):
            raise ValueError("a speed profile needs two or more strictly increasing times")
        steps = np.diff(self.times) * (self.speeds[1:] + self.speeds[:-1]) / 2.0
        self.positions = position_m + np.concatenate([[0.0], np.cumsum(steps)])

    def state(self, time_s: float) -> tuple[float, float]:
        """Position (trapezoidal integral of the profile) and speed at `time_s`."""
        if time_s >= self.times[-1]:
            speed = float(self.speeds[-1])
            return float(self.positions[-1]) + speed * (time_s - float(self.times[-1])), speed
        speed = float(np.interp(time_s, self.times, self.speeds))
        index = int(np.clip(np.searchsorted(self.times, time_s, side="right") - 1, 0, None))
        before = float(self.times[index])
        position = (
            float(self.positions[index])
            + (time_s - before) * (float(self.speeds[index]) + speed) / 2.0
        )
        return position, speed
