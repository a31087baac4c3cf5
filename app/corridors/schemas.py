"""A corridor as served to vehicles and tools."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class InrixSegmentOut(BaseModel):
    """An INRIX XD segment of the corridor (the grain of the speed feed)."""

    model_config = ConfigDict(from_attributes=True)

    xd_code: str
    seq: int
    start_x_m: float
    end_x_m: float
    length_m: float
    start_postmile: float
    end_postmile: float
    lanes: int
    start_lat: float
    start_lon: float
    end_lat: float
    end_lon: float


class SubSegmentOut(BaseModel):
    """A fine sub-segment (the planner's grid); `contract.corridor` builds on these."""

    model_config = ConfigDict(from_attributes=True)

    i24_segment_id: int
    seq: int
    xd_code: str
    start_x_m: float
    end_x_m: float
    start_postmile: float
    end_postmile: float
    lanes: int
    start_lat: float
    start_lon: float
    end_lat: float
    end_lon: float


class CorridorOut(BaseModel):
    """A directed road stretch: x_m grows along travel, lanes count from 1 at the left."""

    corridor_id: str
    name: str
    direction: str
    lanes: int
    length_m: float
    speed_limit_mps: float
    min_target_speed_mps: float
    postmile_at_start: float
    inrix_segments: list[InrixSegmentOut]
    segments: list[SubSegmentOut]
