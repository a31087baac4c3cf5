"""The plan document a vehicle polls (docs/interfaces.md, "Plans")."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import BaseModel, Field


class BufferOut(BaseModel):
    """A deceleration region of one lane: targets are lowered from start_x_m to end_x_m."""

    start_x_m: float
    end_x_m: float
    target_speed_mps: float = Field(description="the lowest target inside the buffer")


class LanePlanOut(BaseModel):
    """One lane's targets: target_speed_mps[i] holds from x_m[i] up to end_x_m[i]."""

    lane: int
    x_m: list[float] = Field(description="start of each sub-segment along the corridor")
    end_x_m: list[float] = Field(description="end of each sub-segment")
    postmile: list[float] = Field(description="postmile at the start of each sub-segment")
    target_speed_mps: list[float]
    buffers: list[BufferOut]


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


class PlanOut(BaseModel):
    """A published plan, all lanes or the one asked for."""

    plan_id: int
    corridor: str
    published_at: datetime
    valid_until: datetime
    algorithm: str
    params: dict[str, Any]
    inputs: PlanInputsOut
    lanes: list[LanePlanOut]
