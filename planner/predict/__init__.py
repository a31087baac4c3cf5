"""Step 1, INRIX prediction: the registered variants and the shared interface."""

from planner.predict.base import (
    NoInrixEstimate,
    Predictor,
    oldest_reading_used_s,
    segment_profile,
    usable_history,
)
from planner.predict.latest import predict_latest
from planner.predict.wave_trend import predict_wave_trend
from planner.registry import Registry

PREDICTORS: Registry[Predictor] = Registry("predictor")
PREDICTORS.register("latest", predict_latest)
PREDICTORS.register("wave_trend", predict_wave_trend)

__all__ = [
    "PREDICTORS",
    "NoInrixEstimate",
    "Predictor",
    "oldest_reading_used_s",
    "segment_profile",
    "usable_history",
]
