"""The time-space page (the paper's view): a lane's fused speed field or plan targets over
the last hours, every fleet car's trajectory on top, and the share of time the fleet was
engaged.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Query, Request
from fastapi.responses import HTMLResponse
from sqlalchemy.ext.asyncio import AsyncSession
from starlette.concurrency import run_in_threadpool

from app.core.sessions import SessionDep
from contract.units import METRES_PER_MILE, MPH_PER_MPS
from dashboards import data
from dashboards.auth import PageError, UserDep
from dashboards.figures import time_space
from dashboards.pages.corridor_choice import LaneNumber, check_lane, chosen_corridor
from dashboards.rendering import display_zone, figure_refresh_s, page, settings_of

router = APIRouter(include_in_schema=False)

TIME_SPACE_COLUMNS = 360
TIME_SPACE_ROWS = 200
TIME_SPACE_FIELDS = {"tse": "fused TSE speed", "target": "plan target speed"}


async def _time_space_context(
    request: Request,
    session: AsyncSession,
    corridor_id: str | None,
    lane: int,
    hours: float,
    field_name: str,
) -> dict[str, Any]:
    if field_name not in TIME_SPACE_FIELDS:
        raise PageError(400, "Unknown field", f"Show 'tse' or 'target', not {field_name!r}.")
    settings = settings_of(request)
    now = datetime.now(UTC)
    corridors = await data.corridors(session)
    corridor = chosen_corridor(corridors, corridor_id)
    context: dict[str, Any] = {
        "page": "timespace",
        "corridors": corridors,
        "corridor": corridor,
        "lane": lane,
        "hours": hours,
        "field": field_name,
        "fields": TIME_SPACE_FIELDS,
        "generated_at": now,
        "refresh_s": figure_refresh_s(request),
        "figure": None,
        "cars": 0,
        "window_share": None,
        "day_share": None,
        "day_start": None,
    }
    if corridor is None:
        return context
    check_lane(corridor, lane)
    context["lanes"] = list(range(1, corridor.lanes + 1))
    since = now - timedelta(hours=hours)
    bucket_s = max(1.0, hours * 3600.0 / 720.0)
    trajectories = await data.fleet_trajectories(session, corridor, since, now, bucket_s)
    # The plan in force at `since` was published up to a planner period (and its lag) earlier.
    plans = await data.recent_plans(
        session, corridor.corridor_id, lane, since - timedelta(minutes=15), now
    )
    first = [t.times_s[0] for t in trajectories if len(t.times_s)]
    if plans is not None:
        first.append(float(plans.published_at[0]))
    if not first:
        return context
    start = max(since.timestamp(), min(first))  # the axis begins where the data does
    end = now.timestamp()
    low = corridor.postmile_at_start
    high = low + corridor.length_m / METRES_PER_MILE
    grid = None
    if plans is not None:
        values = plans.tse_mps if field_name == "tse" else plans.target_mps
        times = np.linspace(start, end, TIME_SPACE_COLUMNS, endpoint=False)
        times += (times[1] - times[0]) / 2
        postmiles = np.linspace(low, high, TIME_SPACE_ROWS, endpoint=False)
        postmiles += (postmiles[1] - postmiles[0]) / 2
        grid = data.sample_plans(plans, values, times, postmiles)
        if np.all(np.isnan(grid)):
            grid = None
    upper = math.ceil(corridor.speed_limit_mps * MPH_PER_MPS / 5) * 5
    zone = display_zone(settings)
    title = f"{corridor.corridor_id} lane {lane}: {TIME_SPACE_FIELDS[field_name]}, fleet on top"
    context["figure"] = await run_in_threadpool(
        time_space,
        "time-space",
        title,
        grid,
        (datetime.fromtimestamp(start, UTC), now),
        (low, high),
        trajectories,
        zone,
        upper,
        TIME_SPACE_FIELDS[field_name],
        3 * bucket_s,
    )
    context["has_field"] = grid is not None
    context["cars"] = len(trajectories)
    _, context["window_share"] = await data.engagement_share(
        session, corridor.corridor_id, since, now
    )
    day_start = datetime.combine(now.astimezone(zone).date(), datetime.min.time(), zone)
    context["day_start"] = day_start
    _, context["day_share"] = await data.engagement_share(
        session, corridor.corridor_id, day_start, now
    )
    return context


@router.get("/timespace")
@router.get("/timespace/live")
async def time_space_page(
    request: Request,
    user: UserDep,
    session: SessionDep,
    corridor: str | None = None,
    lane: LaneNumber = 1,
    hours: Annotated[float, Query(gt=0, le=24)] = 2.0,
    field: str = "tse",
) -> HTMLResponse:
    """The paper's time-space view: the speed field with every fleet car's trajectory on top."""
    context = await _time_space_context(request, session, corridor, lane, hours, field)
    return page(request, user, "timespace", **context)
