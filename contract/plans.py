"""The plan document a vehicle polls (docs/interfaces.md, "Plans").

`PlanTargets` and `LaneTargets` are what a car reads of it (the agent's `vehicle_agent.plan`
extends them with its checks and lookups); `PlanOut` and `LanePlanOut` are what the server
serves, the same fields and the provenance and postmiles an analyst reads.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Any

from pydantic import AwareDatetime, BaseModel, Field


class BufferOut(BaseModel):
    """A deceleration region of one lane: targets are lowered from start_x_m to end_x_m."""

    start_x_m: float
    end_x_m: float
    target_speed_mps: float = Field(description="the lowest target inside the buffer")


class LaneTargets(BaseModel):
    """One lane's targets: target_speed_mps[i] holds from x_m[i] up to end_x_m[i]."""

    lane: int = Field(ge=1)
    x_m: list[float] = Field(description="start of each sub-segment along the corridor")
    end_x_m: list[float] = Field(description="end of each sub-segment")
    target_speed_mps: list[float]
    buffers: list[BufferOut] = Field(default_factory=list)


class LanePlanOut(LaneTargets):
    """A lane as served, with the postmile of each sub-segment's start."""

    postmile: list[float] = Field(description="postmile at the start of each sub-segment")


class PlanInputsOut(BaseModel):
    """What the plan was made from (the full provenance is in GET /api/v1/plans)."""

    model_config = {"extra": "allow"}

    inrix_as_of: datetime | None
    inrix_age_s: float | None
    # Age of the oldest reading the newest snapshot carried forward for a segment it did not
    # read (a partial outage); inrix_age_s when it read them all. Absent on plans published
    # before it was recorded.
    inrix_oldest_reading_age_s: float | None = None
    ping_window_start: datetime
    ping_window_end: datetime
    vehicles: int
    pings: int


class PlanTargets(BaseModel):
    """A published plan as a car reads it: which plan, its lifetime, its lanes."""

    plan_id: int
    corridor: str
    published_at: AwareDatetime
    valid_until: AwareDatetime
    lanes: Sequence[LaneTargets]


class PlanOut(PlanTargets):
    """A published plan, all lanes or the one asked for, with what it was made from."""

    algorithm: str
    params: dict[str, Any]
    inputs: PlanInputsOut
    lanes: list[LanePlanOut]
