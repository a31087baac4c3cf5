"""Store INRIX readings in fact_inrix_estimate: known codes only, nothing twice.

Shared by `POST /api/v1/feeds/inrix`, `smoothfleet inrix poll` and `smoothfleet inrix replay`.
A code missing from dim_inrix_segment is counted and reported, not stored. A resent snapshot
finds its (corridor, code, measured_at) keys taken and stores nothing (ON CONFLICT DO NOTHING).
Segments the response's reading refused (app.feeds.inrix) are counted and passed on.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from datetime import datetime, timedelta

from sqlalchemy import select
from sqlalchemy.dialects.postgresql import insert
from sqlalchemy.ext.asyncio import AsyncSession

from app.core import metrics
from app.feeds.inrix import RefusedReading, SnapshotReadings
from app.models import InrixEstimate, InrixSegment

# Enough of the unknown codes to act on; the count covers them all.
MAX_UNKNOWN_LISTED = 100
# Readings per INSERT: 11 parameters each, and a statement takes at most 65,535 parameters.
READINGS_PER_INSERT = 2000


@dataclass(frozen=True)
class StoreResult:
    """What became of a snapshot's readings."""

    accepted: int
    duplicates: int
    unknown_codes: int
    unknown: list[str]
    measured_at: list[datetime]
    refused: list[RefusedReading]


async def store_readings(
    session: AsyncSession,
    snapshot: SnapshotReadings,
    received_at: datetime,
    fetched_at: datetime | None = None,
) -> StoreResult:
    """Store the readings of known segments; count the rest. The caller commits.

    `fetched_at`: when the answer was fetched from the provider, if earlier than now (the
    poller's backlog, a replay): the latency the analytics read is the provider's, not an
    outage's."""
    readings = snapshot.readings
    codes = sorted({reading.xd_code for reading in readings})
    found = await session.execute(
        select(InrixSegment.xd_code, InrixSegment.corridor_id).where(
            InrixSegment.xd_code.in_(codes)
        )
    )
    corridor_of = {row.xd_code: row.corridor_id for row in found}
    known = [reading for reading in readings if reading.xd_code in corridor_of]
    unknown = sorted({reading.xd_code for reading in readings} - set(corridor_of))
    accepted = 0
    for start in range(0, len(known), READINGS_PER_INSERT):
        statement = (
            insert(InrixEstimate)
            .values(
                [
                    {
                        "corridor_id": corridor_of[reading.xd_code],
                        "xd_code": reading.xd_code,
                        "measured_at": reading.measured_at,
                        "received_at": received_at,
                        "fetched_at": fetched_at,
                        "speed_mps": reading.speed_mps,
                        "average_speed_mps": reading.average_speed_mps,
                        "reference_speed_mps": reading.reference_speed_mps,
                        "travel_time_s": reading.travel_time_s,
                        "score": reading.score,
                        "c_value": reading.c_value,
                        "is_closed": reading.is_closed,
                    }
                    for reading in known[start : start + READINGS_PER_INSERT]
                ]
            )
            .on_conflict_do_nothing(index_elements=["corridor_id", "xd_code", "measured_at"])
            .returning(InrixEstimate.xd_code)
        )
        accepted += len((await session.execute(statement)).all())
    unknown_readings = len(readings) - len(known)
    metrics.INRIX_SEGMENTS.labels("stored").inc(accepted)
    metrics.INRIX_SEGMENTS.labels("duplicate").inc(len(known) - accepted)
    metrics.INRIX_SEGMENTS.labels("unknown").inc(unknown_readings)
    metrics.INRIX_SEGMENTS.labels("refused").inc(len(snapshot.refused))
    return StoreResult(
        accepted=accepted,
        duplicates=len(known) - accepted,
        unknown_codes=unknown_readings,
        unknown=unknown[:MAX_UNKNOWN_LISTED],
        measured_at=sorted({reading.measured_at for reading in readings}),
        refused=snapshot.refused,
    )


class SnapshotTimeRefused(ValueError):
    """A snapshot stamped where no feed can be: ahead of the server's clock, or (shifted for a
    replay) past the calendar's end. Nothing of it is stored; the message says which stamp."""


def shifted(snapshot: SnapshotReadings, by: timedelta) -> SnapshotReadings:
    """The readings with their provider timestamps moved by `by` (replaying old data as new)."""
    try:
        return replace(
            snapshot,
            readings=[
                replace(reading, measured_at=reading.measured_at + by)
                for reading in snapshot.readings
            ],
        )
    except OverflowError:
        raise SnapshotTimeRefused(
            f"a timestamp moved by {by} is past the calendar's range; nothing of this snapshot "
            "was stored"
        ) from None


def refuse_future(snapshot: SnapshotReadings, now: datetime, max_future_s: float) -> None:
    """SnapshotTimeRefused when a reading is stamped more than `max_future_s` after `now`.

    A feed cannot measure the future: such a stamp is a provider's or a recording's clock gone
    wrong, and stored it would sit in the warehouse as the newest reading (a negative latency
    in `analytics.inrix_latency`) and be read by the planner as current until the clock
    caught up. Every path that stores readings checks it: the API, `inrix poll` and
    `inrix replay`."""
    latest = now + timedelta(seconds=max_future_s)
    for moment in sorted({reading.measured_at for reading in snapshot.readings}):
        if moment > latest:
            raise SnapshotTimeRefused(
                f"timestamp {moment.isoformat()} is more than {max_future_s:g} s in the "
                "future; nothing of this snapshot was stored"
            )
