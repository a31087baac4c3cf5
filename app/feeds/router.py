"""`POST /api/v1/feeds/inrix`: an INRIX segment-speed response, exactly as the provider sends it."""

from __future__ import annotations

from datetime import UTC, datetime

from fastapi import APIRouter, HTTPException

from app.auth import FeedWriterDep
from app.core.db import SessionDep
from app.core.errors import error_responses
from app.feeds.inrix import InrixFormatError, InrixResponse, readings_of
from app.feeds.schemas import InrixAnswer
from app.feeds.service import store_readings

router = APIRouter(prefix="/api/v1/feeds", tags=["feeds"])


@router.post("/inrix", responses=error_responses(401, 403, 413, 503))
async def post_inrix(
    response: InrixResponse, principal: FeedWriterDep, session: SessionDep
) -> InrixAnswer:
    """Store the snapshot's readings in SI units (feed or admin token).

    Codes not on any corridor are counted in `unknown_codes`, not stored; a resent snapshot
    stores nothing twice. Answered after the commit.
    """
    try:
        found = readings_of(response)
    except InrixFormatError as error:
        raise HTTPException(422, str(error)) from None
    result = await store_readings(session, found, datetime.now(UTC))
    return InrixAnswer(
        accepted=result.accepted,
        duplicates=result.duplicates,
        unknown_codes=result.unknown_codes,
        unknown=result.unknown,
        measured_at=result.measured_at,
    )
