"""`wave_trend`: the newest snapshot, plus its recent change carried upstream at the wave speed.

Standing features (a bottleneck's queue head) stay where they are, but *changes* in congestion
travel upstream at roughly 15 km/h. With the newest snapshot h seconds old, the change seen at
x + c h is the one arriving at x now:

    v(x, now) = v_last(x) + g * D(h) * dv/dt(x + c h),   D(h) = tau (1 - exp(-h / tau))

where dv/dt is the least-squares slope over the last `trend_snapshots` snapshots, g the share of
the trend trusted, and D a damped horizon (a trend is not extrapolated for ever). The result
stays within 0 and the fastest speed (any segment's) among the snapshots the trend is fitted
on: a corridor recovering towards a speed none of them reached is held at their fastest.
"""

from __future__ import annotations

import numpy as np

from planner.inputs import FloatArray, InrixHistory
from planner.params import PlannerParams
from planner.predict.base import segment_profile


def trend_mps2(history: InrixHistory, snapshots: int) -> FloatArray:
    """Least-squares slope (m/s per s) of each segment's speed over the newest snapshots,
    fitted on its readings only (`is_reading`): a speed carried forward or taken from the
    neighbours is no measurement of change, and a segment read fewer than twice has no trend."""
    times = history.measured_at_s[-snapshots:, None]
    read = history.readings[-snapshots:]
    speeds = np.where(read, history.speed_mps[-snapshots:], 0.0)
    count = read.sum(axis=0)
    enough = count >= 2
    per_reading = np.maximum(count, 1)
    mean_time = (read * times).sum(axis=0) / per_reading
    mean_speed = speeds.sum(axis=0) / per_reading
    centred = np.where(read, times - mean_time, 0.0)
    spread = (centred**2).sum(axis=0)
    fitted = enough & (spread > 0)
    slope: FloatArray = np.where(
        fitted,
        (centred * (speeds - mean_speed)).sum(axis=0) / np.where(fitted, spread, 1.0),
        0.0,
    )
    return slope


def predict_wave_trend(
    history: InrixHistory, at_x_m: FloatArray, now_s: float, params: PlannerParams
) -> FloatArray:
    """Nowcast of the speed at `at_x_m` (level of the newest snapshot + wave-carried trend)."""
    centers = history.segment_center_x_m
    horizon_s = max(0.0, now_s - float(history.measured_at_s[-1]))
    damped_s = params.trend_damping_s * (1.0 - np.exp(-horizon_s / params.trend_damping_s))
    level = segment_profile(history.speed_mps[-1], centers, at_x_m)
    slope = segment_profile(
        trend_mps2(history, params.trend_snapshots),
        centers,
        at_x_m + params.wave_speed_mps * horizon_s,
    )
    fastest = float(np.max(history.speed_mps[-params.trend_snapshots :]))
    predicted: FloatArray = np.clip(level + params.trend_weight * damped_s * slope, 0.0, fastest)
    return predicted
