"""`latest`: the newest INRIX snapshot as it is, resampled to the positions (no prediction).

This is "INRIX alone" in the quality report: what a planner that ignores the feed's latency uses.
"""

from __future__ import annotations

from planner.inputs import FloatArray, InrixHistory
from planner.params import PlannerParams
from planner.predict.base import segment_profile


def predict_latest(
    history: InrixHistory, at_x_m: FloatArray, now_s: float, params: PlannerParams
) -> FloatArray:
    """The newest snapshot's profile at `at_x_m`."""
    return segment_profile(history.speed_mps[-1], history.segment_center_x_m, at_x_m)
