"""The answer to a posted INRIX snapshot."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, Field


class RefusedSegment(BaseModel):
    """A segment of the snapshot that was not stored, with its place and why."""

    segment_set: int = Field(description="its index in result.segmentspeeds")
    segment: int | None = Field(
        description="its index in that set's segments; null when the whole set was refused "
        "(no time to read, or no list of segments)"
    )
    code: str | None = Field(description="its code, when it had one")
    error: str


class InrixAnswer(BaseModel):
    """Readings stored, already stored, of codes not on any corridor, and refused."""

    accepted: int
    duplicates: int
    unknown_codes: int = Field(description="readings whose segment code is not in the roads")
    unknown: list[str] = Field(description="those codes (first 100, sorted)")
    measured_at: list[datetime] = Field(description="the provider timestamps in the snapshot")
    refused: list[RefusedSegment] = Field(
        default_factory=list,
        description="segments that are no valid reading, or a code already read at that "
        "timestamp, and segment sets with no time or no list of segments: not stored; the "
        "snapshot's other readings are",
    )
