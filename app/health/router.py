"""`/healthz` (process alive), `/readyz` (database reachable, schema at head), `/metrics`."""

from __future__ import annotations

import logging

from fastapi import APIRouter, Request, Response
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.ext.asyncio import AsyncEngine

from app.core.metrics import exposition
from app.health.warehouse import warehouse_exposition
from app.migrate import current_revision, head_revision

log = logging.getLogger(__name__)

router = APIRouter(tags=["operations"])


@router.get("/healthz")
async def healthz() -> dict[str, str]:
    """The process is alive and serving."""
    return {"status": "ok"}


@router.get("/readyz", responses={503: {"description": "database unreachable or not migrated"}})
async def readyz(request: Request) -> JSONResponse:
    """Ready when the database answers and its schema is at the migrations' head."""
    engine: AsyncEngine = request.app.state.engine
    head = head_revision()
    try:
        async with engine.connect() as connection:
            current = await connection.run_sync(current_revision)
    except (SQLAlchemyError, OSError) as error:
        # the driver's words name the host, port, database and user to anyone who asks: they go
        # to the log, the unauthenticated answer says only what failed
        detail = str(error).strip().splitlines()[0] if str(error).strip() else "no detail"
        log.warning("readyz: database unreachable: %s", detail)
        return JSONResponse(
            {"status": "unavailable", "reason": "database unreachable"}, status_code=503
        )
    if current != head:
        return JSONResponse(
            {"status": "unavailable", "reason": f"schema at {current}, migrations at {head}"},
            status_code=503,
        )
    return JSONResponse({"status": "ready", "schema": current})


@router.get("/metrics", response_class=Response)
async def metrics(request: Request) -> Response:
    """Prometheus text exposition of this process's counters and histograms, and the
    warehouse's newest plan, run and INRIX reading per corridor (`app.health.warehouse`)."""
    engine: AsyncEngine = request.app.state.engine
    body = exposition() + await warehouse_exposition(engine)
    return Response(body, media_type=CONTENT_TYPE_LATEST)
