"""The planner history as served to analysts; the plan document itself is `contract.plans`."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import BaseModel, Field


class PlanRunOut(BaseModel):
    """One planner run in the history: published, skipped or failed, and why."""

    plan_id: int
    corridor: str
    status: str
    reason: str | None
    algorithm: str
    params: dict[str, Any]
    inputs: dict[str, Any]
    started_at: datetime
    published_at: datetime | None
    valid_until: datetime | None
    duration_ms: float | None


class PlanHistoryOut(BaseModel):
    """Planner runs, newest first."""

    plans: list[PlanRunOut]
    truncated: bool = Field(
        False,
        description="more runs lie in the window than `limit`: ask again with `until` set to "
        "the oldest run's started_at",
    )
