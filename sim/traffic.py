"""Traffic along the road behind a real drive, and the INRIX feed's shape (segments, minutes).

A platoon simulation has one real vehicle ahead, the replayed leader; the road ahead of it is
known only through what the leader met. In congested traffic, speed changes travel upstream at a
nearly constant wave speed c, so the state at (t, x) is the one the leader met at the time tau
when the wave through (t, x) reached it:

    x_L(tau) = x - c (tau - t)    <=>    x_L(tau) + c tau = x + c t,

which has exactly one solution because x_L + c tau increases strictly. `WaveField` gives
v(t, x) = v_L(tau) (held at the drive's first or last speed outside it). The demo's traffic uses
it at I-24's 15 km/h (paper section "TSE Enhancement"); the simulated INRIX (`sim.inrix`) uses it
at a wave speed calibrated on the real feed, not the planner's, under a measurement model of the
real feed's errors. `InrixFeed` holds readings per minute and per segment (about 0.5 mi).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from contract.units import METRES_PER_MILE, WAVE_SPEED_MPS
from sim.drives import Drive

FloatArray = NDArray[np.float64]

# INRIX: one reading per segment every 60 s, about 3 minutes late, segments of about 0.5 mile.
INRIX_PERIOD_S = 60.0
INRIX_LATENCY_S = 180.0
INRIX_SEGMENT_M = METRES_PER_MILE / 2
# Samples per segment when averaging the field (every 50 m).
SAMPLE_SPACING_M = 50.0


class WaveField:
    """v(t, x) behind a drive, with the drive's characteristic x_L(tau) + c tau precomputed."""

    def __init__(self, drive: Drive, wave_speed_mps: float = WAVE_SPEED_MPS) -> None:
        self.drive_time = np.arange(drive.steps + 1, dtype=np.float64) * drive.dt_s
        self.characteristic = drive.position_m + wave_speed_mps * self.drive_time
        self.speed = drive.speed_mps
        self.wave_speed_mps = wave_speed_mps

    def speed_mps(self, time_s: ArrayLike, x_m: ArrayLike) -> FloatArray:
        """The leader's speed where the upstream-moving state through (t, x) met it."""
        key = np.asarray(x_m, dtype=np.float64) + self.wave_speed_mps * np.asarray(time_s)
        met_at = np.interp(key, self.characteristic, self.drive_time)
        speed: FloatArray = np.interp(met_at, self.drive_time, self.speed)
        return speed


def wave_field_speed(
    drive: Drive, time_s: ArrayLike, x_m: ArrayLike, wave_speed_mps: float = WAVE_SPEED_MPS
) -> FloatArray:
    """v(t, x) for one query (build a `WaveField` to ask many)."""
    return WaveField(drive, wave_speed_mps).speed_mps(time_s, x_m)


@dataclass(frozen=True)
class InrixFeed:
    """INRIX readings per minute and per segment: `speed_mps[minute, segment]`.

    Row m is stamped `measured_at_s[m]` and becomes visible at `measured_at_s[m] + latency_s`
    (0 for the recorded and the simulated feeds: their stamp is when the reading arrives, and
    the feed's lag is inside the readings).
    """

    segment_start_m: FloatArray
    segment_end_m: FloatArray
    measured_at_s: FloatArray
    speed_mps: FloatArray
    latency_s: float

    @property
    def segment_center_x_m(self) -> FloatArray:
        """Centre of each segment."""
        centers: FloatArray = 0.5 * (self.segment_start_m + self.segment_end_m)
        return centers

    def visible_rows(self, now_s: float) -> NDArray[np.bool_]:
        """The minutes a planner running at `now_s` has received."""
        visible: NDArray[np.bool_] = self.measured_at_s + self.latency_s <= now_s
        return visible


def segment_bounds(start_m: float, end_m: float, length_m: float = INRIX_SEGMENT_M) -> FloatArray:
    """Boundaries of equal segments covering [start_m, end_m] (the last one may be longer)."""
    count = max(1, int((end_m - start_m) // length_m))
    bounds: FloatArray = start_m + length_m * np.arange(count + 1, dtype=np.float64)
    bounds[-1] = max(bounds[-1], end_m)
    return bounds
