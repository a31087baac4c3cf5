"""The MOTION page: the paper's bulk-fuel figure of a day, every vehicle with the fleet on top.

`/analytics/motion?date=YYYY-MM-DD` shows the day (default: the latest imported) and links the
other imported days; `/analytics/motion.png?date=...` is the figure itself, made by the same code
as `smoothfleet motion plot` (app.motion.figure). A figure takes seconds (a whole day of points
aggregated, then drawn), so each process keeps the last few for FIGURE_CACHE_S.
"""

from __future__ import annotations

import time
from datetime import date
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import HTMLResponse, Response
from sqlalchemy.orm import Session

from app.core.sessions import SessionDep
from app.motion.edie import EdieWindow, day_window, edie_field
from app.motion.figure import window_figure
from app.motion.fleet import FleetDay, engagement_share, fleet_pings
from app.motion.store import MotionStoreEmpty, imported_days, motion_store
from contract.values import EARLIEST, LATEST
from dashboards.auth import PageError, UserDep
from dashboards.rendering import display_zone, render, settings_of

router = APIRouter(include_in_schema=False)

CORRIDOR_ID = "I-24-WB"
FIGURE_CACHE_S = 60.0
FIGURES_KEPT = 4


def _store(request: Request) -> Path:
    return motion_store(settings_of(request))


def _day(value: str | None, days: list[str]) -> date | None:
    if value is None:
        return date.fromisoformat(days[0]) if days else None
    try:
        chosen = date.fromisoformat(value)
    except ValueError:
        raise PageError(400, "Not a date", f"{value!r} is not a date (YYYY-MM-DD).") from None
    # the warehouse's days lie between 1970 and 2200 (contract.values.plausible_time): a day
    # past them has no data, and 9999-12-31's next day, the end of its window, overflowed (500)
    if not EARLIEST.date() <= chosen < LATEST.date():
        raise PageError(400, "Not a date", f"{value} is outside 1970-2199, where data can be.")
    return chosen


@router.get("/analytics/motion")
async def motion_page(
    request: Request,
    user: UserDep,
    session: SessionDep,
    day: Annotated[str | None, Query(alias="date")] = None,
) -> HTMLResponse:
    """The day's figure and engagement share, and the other days with MOTION data."""
    days = imported_days(_store(request))
    chosen = _day(day, days)
    share = None
    if chosen is not None:
        on_day = chosen
        share = await session.run_sync(
            lambda sync_session: engagement_share(sync_session.connection(), on_day)
        )
    return render(
        request,
        "motion.html",
        user,
        page="analytics",
        days=days,
        day=None if chosen is None else chosen.isoformat(),
        has_data=chosen is not None and chosen.isoformat() in days,
        engagement_share=share,
    )


@router.get("/analytics/motion.png")
async def motion_figure(
    request: Request,
    user: UserDep,
    session: SessionDep,
    day: Annotated[str, Query(alias="date")],
) -> Response:
    """The bulk-fuel figure of one day as a PNG."""
    chosen = _day(day, [])
    assert chosen is not None
    store = _store(request)
    cache: dict[date, tuple[float, bytes]] | None = getattr(
        request.app.state, "motion_figures", None
    )
    if cache is None:
        cache = request.app.state.motion_figures = {}
    cached = cache.get(chosen)
    if cached is not None and time.monotonic() - cached[0] < FIGURE_CACHE_S:
        return Response(cached[1], media_type="image/png")
    try:
        window: EdieWindow = await run_in_threadpool(day_window, store, chosen)
    except MotionStoreEmpty as error:
        raise PageError(404, "No MOTION data", str(error)) from None
    field = await run_in_threadpool(edie_field, store, window)

    def read_fleet(sync_session: Session) -> FleetDay:
        return fleet_pings(sync_session.connection(), CORRIDOR_ID, window.since, window.until)

    fleet = await session.run_sync(read_fleet)
    zone = display_zone(settings_of(request))
    png = await run_in_threadpool(window_figure, window, field, fleet, CORRIDOR_ID, zone)
    cache[chosen] = (time.monotonic(), png)
    for stale in sorted(cache, key=lambda key: cache[key][0])[:-FIGURES_KEPT]:
        del cache[stale]
    return Response(png, media_type="image/png")
