"""Step 1 interface: estimate the lane-averaged speed *now* from the INRIX history.

INRIX arrives every ~60 s and is ~3 minutes late (paper Table 1, up to 10 minutes). A predictor
receives the usable history (gaps filled, nothing older than `inrix_history_s`) and returns the
speed at the requested positions at time `now_s`.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from planner.inputs import FloatArray, InrixHistory
from planner.params import PlannerParams


class NoInrixEstimate(Exception):
    """No INRIX snapshot recent enough to estimate the traffic state; the message says why."""


class Predictor(Protocol):
    """A prediction variant (registered in planner.predict.PREDICTORS)."""

    def __call__(
        self, history: InrixHistory, at_x_m: FloatArray, now_s: float, params: PlannerParams
    ) -> FloatArray:
        """Speed (m/s) at `at_x_m` at time `now_s`."""
        ...


def segment_profile(
    speed_by_segment: FloatArray, segment_center_x_m: FloatArray, at_x_m: FloatArray
) -> FloatArray:
    """Continuous profile through (segment centre, segment speed), paper eq. for the TSE pairs.

    Linear between centres and constant beyond the first and last: the paper's interpolation of
    the discrete pairs (x_j, v_j) into v(t, x).
    """
    profile: FloatArray = np.interp(at_x_m, segment_center_x_m, speed_by_segment)
    return profile


def usable_history(history: InrixHistory, now_s: float, params: PlannerParams) -> InrixHistory:
    """The snapshots a planner may use at `now_s`, with missing readings filled.

    A segment without a reading keeps its last reading for at most `max_inrix_age_s` (measured
    at each snapshot, and at `now_s` for the newest, which the nowcast starts from); one without
    a reading that recent takes the speed interpolated from its neighbours in the same snapshot.
    Snapshots with no reading at all are dropped. Raises NoInrixEstimate when the newest is too
    old, or when it reads too few segments (`min_inrix_coverage`): one fresh segment must not
    carry the whole corridor, nor a reading kept from many minutes ago stand for now. The result
    marks what was read (`is_reading`) apart from what was filled.
    """
    recent = history.until(now_s)
    keep = recent.measured_at_s >= now_s - params.inrix_history_s
    times = recent.measured_at_s[keep]
    speeds = recent.speed_mps[keep].copy()
    is_reading = recent.readings[keep] & np.isfinite(speeds)
    has_reading = is_reading.any(axis=1)
    times, speeds, is_reading = times[has_reading], speeds[has_reading], is_reading[has_reading]
    if len(times) == 0:
        raise NoInrixEstimate(f"no INRIX reading in the last {params.inrix_history_s:.0f} s")
    age_s = now_s - float(times[-1])
    if age_s > params.max_inrix_age_s:
        raise NoInrixEstimate(
            f"newest INRIX is {age_s:.0f} s old (limit {params.max_inrix_age_s:.0f} s)"
        )
    speeds[~is_reading] = np.nan
    read_at_s = np.where(is_reading, times[:, None], np.nan)
    for row in range(1, len(speeds)):
        missing = ~is_reading[row]
        speeds[row, missing] = speeds[row - 1, missing]
        read_at_s[row, missing] = read_at_s[row - 1, missing]
    as_of_s = times.copy()
    as_of_s[-1] = now_s
    with np.errstate(invalid="ignore"):
        too_old = as_of_s[:, None] - read_at_s > params.max_inrix_age_s
    speeds[too_old] = np.nan
    segments = speeds.shape[1]
    covered = int(np.isfinite(speeds[-1]).sum())
    if covered < params.min_inrix_coverage * segments:
        raise NoInrixEstimate(
            f"INRIX read only {covered} of {segments} segments in the last "
            f"{params.max_inrix_age_s:.0f} s (at least {params.min_inrix_coverage:.0%} needed)"
        )
    centers = history.segment_center_x_m
    for row in range(len(speeds)):
        missing = np.isnan(speeds[row])
        if missing.any():
            speeds[row, missing] = np.interp(
                centers[missing], centers[~missing], speeds[row, ~missing]
            )
    return InrixHistory(times, speeds, centers, is_reading)


def oldest_reading_used_s(usable: InrixHistory, now_s: float, params: PlannerParams) -> float:
    """When the oldest reading the newest snapshot still stands on was measured.

    In a `usable_history` a segment the newest snapshot did not read carries its last reading
    forward (for at most `max_inrix_age_s`); the plan's INRIX age is the newest snapshot's, so
    this is what tells an operator that most of the corridor is minutes older than that. A
    segment whose last reading is older than the limit is interpolated, not carried, and does
    not count. The newest snapshot's own time when it read every segment."""
    read_at = np.where(usable.readings, usable.measured_at_s[:, None], -np.inf)
    last_read_s = read_at.max(axis=0)
    carried = last_read_s[now_s - last_read_s <= params.max_inrix_age_s]
    return float(carried.min()) if len(carried) else float(usable.measured_at_s[-1])
