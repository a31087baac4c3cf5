"""The star schema in one place: dimensions, facts, access."""

from app.models.access import ApiToken, OpsLoginFailure, OpsUser
from app.models.base import Base
from app.models.dimensions import (
    Corridor,
    I24Segment,
    InrixSegment,
    Policy,
    Vehicle,
    VehicleAssignment,
)
from app.models.facts import (
    InrixEstimate,
    PlanRun,
    SpeedPlan,
    VehicleChange,
    VehicleObservation,
    VehiclePing,
    VehicleStatus,
)

__all__ = [
    "ApiToken",
    "Base",
    "Corridor",
    "I24Segment",
    "InrixEstimate",
    "InrixSegment",
    "OpsLoginFailure",
    "OpsUser",
    "PlanRun",
    "Policy",
    "SpeedPlan",
    "Vehicle",
    "VehicleAssignment",
    "VehicleChange",
    "VehicleObservation",
    "VehiclePing",
    "VehicleStatus",
]
