"""`POST /api/v1/feeds/inrix`: an INRIX segment-speed response, exactly as the provider sends it."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from fastapi import APIRouter, HTTPException, Request

from app.auth import FeedWriterDep
from app.core.config import Settings
from app.core.errors import error_responses
from app.core.json_keys import RepeatedKeysRefused
from app.core.sessions import SessionDep
from app.feeds.inrix import InrixResponse, readings_of
from app.feeds.schemas import InrixAnswer, RefusedSegment
from app.feeds.service import SnapshotTimeRefused, refuse_future, store_readings

router = APIRouter(prefix="/api/v1/feeds", tags=["feeds"], route_class=RepeatedKeysRefused)


@router.post("/inrix", responses=error_responses(401, 403, 413, 503))
async def post_inrix(
    response: InrixResponse, request: Request, principal: FeedWriterDep, session: SessionDep
) -> InrixAnswer:
    """Store the snapshot's readings in SI units (feed or admin token).

    Codes not on any corridor are counted in `unknown_codes`, not stored; a resent snapshot
    stores nothing twice; a segment that is no valid reading, or a segment set with no time or
    no list of segments, is refused on its own (`refused`) and the others stored. Answered
    after the commit. A snapshot timestamped more than SMOOTHFLEET_PING_MAX_FUTURE_S ahead or
    SMOOTHFLEET_INRIX_MAX_AGE_DAYS back is refused (422).
    """
    received_at = datetime.now(UTC)
    found = readings_of(response)
    settings: Settings = request.app.state.settings
    try:
        refuse_future(found, received_at, settings.ping_max_future_s)
    except SnapshotTimeRefused as error:
        raise HTTPException(422, str(error)) from None
    earliest = received_at - timedelta(days=settings.inrix_max_age_days)
    for moment in sorted({reading.measured_at for reading in found.readings}):
        if moment < earliest:
            raise HTTPException(
                422,
                f"timestamp {moment.isoformat()} is older than {settings.inrix_max_age_days} "
                "days (SMOOTHFLEET_INRIX_MAX_AGE_DAYS; recordings go through `smoothfleet inrix "
                "replay`); nothing of this snapshot was stored",
            )
    result = await store_readings(session, found, received_at)
    return InrixAnswer(
        accepted=result.accepted,
        duplicates=result.duplicates,
        unknown_codes=result.unknown_codes,
        unknown=result.unknown,
        measured_at=result.measured_at,
        refused=[
            RefusedSegment.model_validate(refusal, from_attributes=True)
            for refusal in result.refused
        ],
    )
