"""The feeds page: INRIX freshness and latency, pings per second, and the inputs the server
refused.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse
from sqlalchemy.ext.asyncio import AsyncSession

from app.core.sessions import SessionDep
from dashboards import data
from dashboards.auth import UserDep
from dashboards.charts import Axis, Series, drawn, over_time_figure
from dashboards.rendering import display_zone, figure_refresh_s, page, settings_of

router = APIRouter(include_in_schema=False)


@router.get("/feeds")
@router.get("/feeds/live")
async def feeds_page(request: Request, user: UserDep, session: SessionDep) -> HTMLResponse:
    """INRIX freshness and latency, pings per second, rejected inputs."""
    context = await _feeds_context(request, session)
    return page(request, user, "feeds", **context)


async def _feeds_context(request: Request, session: AsyncSession) -> dict[str, Any]:
    now = datetime.now(UTC)
    latest = await data.latest_inrix(session)
    inrix_since = now - timedelta(hours=6)
    ping_since = now - timedelta(hours=1)
    snapshots = await data.inrix_snapshots(session, inrix_since)
    # Only whole minutes of GPS time: the minute still running has a fraction of its pings.
    minutes = [
        row
        for row in await data.pings_per_minute(session, ping_since)
        if row["minute"] + timedelta(minutes=1) <= now
    ]
    context: dict[str, Any] = {
        "page": "feeds",
        "latest": latest,
        "latest_age_s": None if latest is None else (now - latest["measured_at"]).total_seconds(),
        "minutes": minutes,
        "rejected": data.rejected_inputs(),
        "inrix_chart": None,
        "ping_chart": None,
        "last_minute": minutes[-1] if minutes else None,
        # how long ago the newest whole minute with pings ended: a fleet silent for 50 minutes
        # must not read as a live feed
        "last_minute_age_s": (
            (now - minutes[-1]["minute"] - timedelta(minutes=1)).total_seconds()
            if minutes
            else None
        ),
        "generated_at": now,
        "refresh_s": figure_refresh_s(request),
    }
    zone = display_zone(settings_of(request))
    if snapshots:
        context["inrix_chart"] = await drawn(
            "inrix-latency",
            lambda: over_time_figure(
                "INRIX latency per snapshot (received − measured)",
                Series(
                    "latency",
                    [row["measured_at"].timestamp() for row in snapshots],
                    [row["latency_s"] for row in snapshots],
                    "#9333ea",
                ),
                Axis("INRIX measurement time", "time"),
                Axis("latency (s)", lower=0.0),
                zone=zone,
            ),
        )
    if minutes:
        context["ping_chart"] = await drawn(
            "ping-rate",
            lambda: over_time_figure(
                "Pings per second, per minute of GPS time",
                Series(
                    "pings per second",
                    [row["minute"].timestamp() for row in minutes],
                    [row["pings"] / 60.0 for row in minutes],
                    "#2563eb",
                ),
                Axis("time", "time"),
                Axis("pings per second", lower=0.0),
                zone=zone,
            ),
        )
    return context
