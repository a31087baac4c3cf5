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

    A segment without a reading keeps its previous snapshot's speed; one never read in the
    window takes the speed interpolated from its neighbours in the same snapshot. Snapshots with
    no reading at all are dropped. Raises NoInrixEstimate when the newest is too old.
    """
    recent = history.until(now_s)
    keep = recent.measured_at_s >= now_s - params.inrix_history_s
    times = recent.measured_at_s[keep]
    speeds = recent.speed_mps[keep].copy()
    has_reading = np.isfinite(speeds).any(axis=1)
    times, speeds = times[has_reading], speeds[has_reading]
    if len(times) == 0:
        raise NoInrixEstimate(f"no INRIX reading in the last {params.inrix_history_s:.0f} s")
    age_s = now_s - float(times[-1])
    if age_s > params.max_inrix_age_s:
        raise NoInrixEstimate(
            f"newest INRIX is {age_s:.0f} s old (limit {params.max_inrix_age_s:.0f} s)"
        )
    for row in range(1, len(speeds)):
        missing = np.isnan(speeds[row])
        speeds[row, missing] = speeds[row - 1, missing]
    centers = history.segment_center_x_m
    for row in range(len(speeds)):
        missing = np.isnan(speeds[row])
        if missing.any():
            speeds[row, missing] = np.interp(
                centers[missing], centers[~missing], speeds[row, ~missing]
            )
    return InrixHistory(times, speeds, centers)
