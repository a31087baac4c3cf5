"""The analytics page: engagement per day, pings and vehicles per hour, plan adherence and the
Edie fields of the last hour with pings. The MOTION page (`dashboards.pages.motion`) sits
beside it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np
from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse
from sqlalchemy import RowMapping
from sqlalchemy.ext.asyncio import AsyncSession
from starlette.concurrency import run_in_threadpool

from app.core.sessions import SessionDep
from contract.units import METRES_PER_MILE, MPH_PER_MPS
from dashboards import data
from dashboards.auth import UserDep
from dashboards.charts import (
    AMOUNT_STOPS,
    Axis,
    ColourScale,
    Series,
    bar_figure,
    chart,
    drawn,
    heatmap_figure,
    over_time_figure,
)
from dashboards.rendering import display_zone, page, settings_of

router = APIRouter(include_in_schema=False)

ANALYTICS_DAYS = 30
ADHERENCE_DAYS = 7  # every ping looked up in its plan: a week is the page's budget
ANALYTICS_REFRESH_S = 60.0  # the analytics page's figures are recomputed at most this often


def engagement_chart(chart_id: str, title: str, rows: Any, zone: ZoneInfo) -> Any:
    """Engagement share per local day, as bars (vehicle and analytics pages)."""
    return chart(
        chart_id,
        bar_figure(
            title,
            [row["day"].strftime("%m-%d") for row in rows],
            [100.0 * row["engagement_share"] for row in rows],
            f"day ({zone.key})",
            Axis("time with controller engaged (%)", lower=0.0, upper=100.0),
            value_format="{:.0f} %",
        ),
    )


def local_days_ago(now: datetime, zone: ZoneInfo, days: int) -> datetime:
    """The start of the local day `days` days before `now`'s (charts per day begin there)."""
    day = now.astimezone(zone).date() - timedelta(days=days)
    return datetime.combine(day, datetime.min.time(), zone)


@router.get("/analytics")
@router.get("/analytics/live")
async def analytics_page(request: Request, user: UserDep, session: SessionDep) -> HTMLResponse:
    """Engagement per day, pings and vehicles per hour, plan adherence, Edie fields.

    The figures cover days and hours (and a week of plan adherence, the costly part), so each
    server process computes them at most once every ANALYTICS_REFRESH_S and serves that copy,
    which the page polls for as often; it says when the copy was computed.
    """
    cached: tuple[datetime, dict[str, Any]] | None = getattr(
        request.app.state, "analytics_page", None
    )
    now = datetime.now(UTC)
    if cached is None or (now - cached[0]).total_seconds() >= ANALYTICS_REFRESH_S:
        cached = (now, await _analytics_context(session, now, display_zone(settings_of(request))))
        request.app.state.analytics_page = cached
    computed_at, context = cached
    return page(
        request,
        user,
        "analytics",
        generated_at=computed_at,
        refresh_s=ANALYTICS_REFRESH_S,
        **context,
    )


async def _analytics_context(
    session: AsyncSession, now: datetime, zone: ZoneInfo
) -> dict[str, Any]:
    """What the analytics page shows, as of `now`."""
    engagement = await data.engagement_per_day(
        session, local_days_ago(now, zone, ANALYTICS_DAYS), zone
    )
    hourly_since = (now - timedelta(hours=48)).replace(minute=0, second=0, microsecond=0)
    hourly = await data.fleet_pings_hourly(session, hourly_since)
    adherence = await data.adherence_per_day(
        session, local_days_ago(now, zone, ADHERENCE_DAYS), zone
    )
    context: dict[str, Any] = {
        "page": "analytics",
        "zone_name": zone.key,
        "engagement": engagement,
        "hourly": hourly,
        "adherence": adherence,
        "charts": {},
        "edie_window": None,
    }
    charts = context["charts"]
    if engagement:
        charts["engagement"] = await run_in_threadpool(
            engagement_chart,
            "engagement-share",
            "Share of fleet time with the controller engaged, per day",
            engagement,
            zone,
        )
    if hourly:
        hours = [row["hour"].timestamp() + 1800.0 for row in hourly]  # middle of the hour
        charts["pings"] = await drawn(
            "pings-hourly",
            lambda: over_time_figure(
                "Pings per hour (the hour in progress at its rate so far)",
                Series("pings", hours, pings_per_hour(hourly), "#2563eb"),
                Axis("hour", "time"),
                Axis("pings per hour", lower=0.0),
                zone=zone,
                height=220,
            ),
        )
        charts["vehicles"] = await drawn(
            "vehicles-hourly",
            lambda: over_time_figure(
                "Vehicles heard per hour",
                Series("vehicles", hours, [float(r["vehicles"]) for r in hourly], "#16a34a"),
                Axis("hour", "time"),
                Axis("vehicles", lower=0.0),
                zone=zone,
                height=220,
            ),
        )
    if adherence:
        charts["adherence"] = await drawn(
            "plan-adherence",
            lambda: bar_figure(
                "Mean |speed − plan target| per day",
                [row["day"].strftime("%m-%d") for row in adherence],
                [row["mean_abs_speed_error_mps"] * MPH_PER_MPS for row in adherence],
                f"day ({zone.key})",
                Axis("mean |speed − target| (mph)", lower=0.0),
                value_format="{:.1f}",
                colour="#dc2626",
            ),
        )
    await _edie_charts(session, context, zone)
    return context


def pings_per_hour(hourly: Sequence[RowMapping]) -> list[float]:
    """Each hour's pings per hour: its mean rate (`analytics.fleet_ping_hourly.pings_per_s`)
    times 3,600 s.

    For an hour that is over this is its count of pings. The hour in progress is at its rate so
    far, as the view divides it by the seconds it has run (migration 0011): its count, plotted
    before, always ended the chart in a dip (half the fleet's pings at half past) that read as
    the fleet going quiet."""
    return [float(row["pings_per_s"]) * 3600.0 for row in hourly]


async def _edie_charts(session: SessionDep, context: dict[str, Any], zone: ZoneInfo) -> None:
    """Bulk speed and fuel per distance of the last hour with pings (paper, Results)."""
    newest = await data.newest_ping_ts(session)
    corridors = await data.corridors(session)
    if newest is None or not corridors:
        return
    corridor = corridors[0]
    until = newest + timedelta(seconds=1)
    since = until - timedelta(hours=1)
    boxes = await data.edie_field(session, since, until, corridor.corridor_id)
    if not boxes:
        return
    h_t, h_x = 10.0, 200.0
    t0 = math.floor(since.timestamp() / h_t) * h_t
    columns = math.ceil((until.timestamp() - t0) / h_t)
    rows = math.ceil(corridor.length_m / h_x)
    speed = np.full((rows, columns), np.nan)
    fuel = np.full((rows, columns), np.nan)
    for box in boxes:
        column = int(round((box["t_start"].timestamp() - t0) / h_t))
        row = int(round(box["x_start_m"] / h_x))
        if 0 <= row < rows and 0 <= column < columns:
            speed[row, column] = box["speed_mps"] * MPH_PER_MPS
            if box["fuel_per_distance_g_per_m"] is not None:
                fuel[row, column] = box["fuel_per_distance_g_per_m"] * 1000.0
    postmiles = (
        corridor.postmile_at_start,
        corridor.postmile_at_start + rows * h_x / METRES_PER_MILE,
    )
    x_range = (t0, t0 + columns * h_t)
    context["edie_window"] = (since, until, corridor.corridor_id)
    upper = math.ceil(corridor.speed_limit_mps * MPH_PER_MPS / 5) * 5
    context["charts"]["edie_speed"] = await drawn(
        "edie-speed",
        lambda: heatmap_figure(
            "Bulk speed u = q / ρ of the fleet's pings",
            speed,
            x_range,
            postmiles,
            Axis("time", "time"),
            Axis("postmile (direction of travel ↑)"),
            ColourScale(0.0, upper, "bulk speed (mph)"),
            zone=zone,
        ),
    )
    finite = fuel[np.isfinite(fuel)]
    fuel_upper = float(np.percentile(finite, 95)) if finite.size else 1.0
    context["charts"]["edie_fuel"] = await drawn(
        "edie-fuel",
        lambda: heatmap_figure(
            "Bulk fuel consumption ψ = f / q",
            fuel,
            x_range,
            postmiles,
            Axis("time", "time"),
            Axis("postmile (direction of travel ↑)"),
            ColourScale(0.0, max(fuel_upper, 1e-3), "fuel per distance (g/km)", AMOUNT_STOPS),
            zone=zone,
        ),
    )
