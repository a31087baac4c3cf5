"""The answer to a posted INRIX snapshot."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, Field


class InrixAnswer(BaseModel):
    """Readings stored, already stored, and of codes not on any corridor."""

    accepted: int
    duplicates: int
    unknown_codes: int = Field(description="readings whose segment code is not in the roads")
    unknown: list[str] = Field(description="those codes (first 100, sorted)")
    measured_at: list[datetime] = Field(description="the provider timestamps in the snapshot")
