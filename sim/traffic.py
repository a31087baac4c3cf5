"""Simulated INRIX: the traffic state along the road, aggregated and delayed like the real feed.

A platoon simulation has one real vehicle ahead, the replayed leader; the road ahead of it is
known only through what the leader met. In congested traffic, speed changes travel upstream at a
nearly constant wave speed (about 15 km/h on I-24; paper section "TSE Enhancement" and the
planner's prediction), so the state at (t, x) is the one the leader met at the time tau when the
wave through (t, x) reached it:

    x_L(tau) = x - c (tau - t)    <=>    x_L(tau) + c tau = x + c t,

which has exactly one solution because x_L + c tau increases strictly. `wave_field_speed` gives
v(t, x) = v_L(tau) (held at the drive's first or last speed outside it). `inrix_snapshots`
averages that field like INRIX does: per segment (about 0.5 mi) and per minute, and each minute
becomes visible `latency_s` (paper Table 1: ~180 s) after it ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.drives import Drive

FloatArray = NDArray[np.float64]

# Speed at which congestion waves travel upstream on I-24 (15 km/h).
WAVE_SPEED_MPS = 15.0 / 3.6
# INRIX: one reading per segment every 60 s, about 3 minutes late, segments of about 0.5 mile.
INRIX_PERIOD_S = 60.0
INRIX_LATENCY_S = 180.0
INRIX_SEGMENT_M = 804.672
# Samples per minute and per segment when averaging the field (every 5 s, every 50 m).
SAMPLE_PERIOD_S = 5.0
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
    """Per-minute segment means of a traffic field: `speed_mps[minute, segment]`.

    `measured_at_s[m]` is the end of minute m (the time the reading describes, as the planner
    reads INRIX's timestamp); it becomes visible at `measured_at_s[m] + latency_s`.
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


def inrix_snapshots(
    drive: Drive,
    bounds_m: FloatArray,
    first_minute_s: float,
    last_minute_s: float,
    *,
    latency_s: float = INRIX_LATENCY_S,
    wave_speed_mps: float = WAVE_SPEED_MPS,
) -> InrixFeed:
    """Minute-by-segment means of the drive's wave field for minutes starting in the range."""
    starts = np.arange(first_minute_s, last_minute_s + 1e-9, INRIX_PERIOD_S)
    sample_t = np.arange(0.0, INRIX_PERIOD_S, SAMPLE_PERIOD_S) + 0.5 * SAMPLE_PERIOD_S
    speeds = np.empty((len(starts), len(bounds_m) - 1))
    wave_field = WaveField(drive, wave_speed_mps)
    for segment in range(len(bounds_m) - 1):
        low, high = float(bounds_m[segment]), float(bounds_m[segment + 1])
        count = max(1, int(round((high - low) / SAMPLE_SPACING_M)))
        sample_x = low + (np.arange(count) + 0.5) * (high - low) / count
        times = starts[:, None, None] + sample_t[None, :, None]
        field = wave_field.speed_mps(
            np.broadcast_to(times, (len(starts), len(sample_t), count)), sample_x
        )
        speeds[:, segment] = field.mean(axis=(1, 2))
    return InrixFeed(
        segment_start_m=bounds_m[:-1].copy(),
        segment_end_m=bounds_m[1:].copy(),
        measured_at_s=starts + INRIX_PERIOD_S,
        speed_mps=speeds,
        latency_s=latency_s,
    )
