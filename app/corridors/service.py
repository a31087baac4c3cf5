"""Read a corridor with its segments from the dimensions."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from app.corridors.schemas import CorridorOut, InrixSegmentOut, SubSegmentOut
from app.models import Corridor, I24Segment, InrixSegment


async def corridor_geometry(session: AsyncSession, corridor_id: str) -> CorridorOut | None:
    """The corridor and its INRIX and fine segments in order of travel, or None if unknown."""
    corridor = await session.get(Corridor, corridor_id)
    if corridor is None:
        return None
    inrix = await session.scalars(
        select(InrixSegment)
        .where(InrixSegment.corridor_id == corridor_id)
        .order_by(InrixSegment.seq)
    )
    fine = await session.scalars(
        select(I24Segment).where(I24Segment.corridor_id == corridor_id).order_by(I24Segment.seq)
    )
    return CorridorOut(
        corridor_id=corridor.corridor_id,
        name=corridor.name,
        direction=corridor.direction,
        lanes=corridor.lanes,
        length_m=corridor.length_m,
        speed_limit_mps=corridor.speed_limit_mps,
        min_target_speed_mps=corridor.min_target_speed_mps,
        postmile_at_start=corridor.postmile_at_start,
        inrix_segments=[InrixSegmentOut.model_validate(s) for s in inrix],
        segments=[SubSegmentOut.model_validate(s) for s in fine],
    )
